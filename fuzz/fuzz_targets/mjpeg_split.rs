//! Fuzzes the MJPEG splitter (ffmpeg's MJPEG output, and the body of an
//! MJPEG stream over HTTP from a `url` camera or mjpg-streamer — hyper reads
//! the HTTP, the splitter everything in the body).
//!
//! Any bytes, in any chunking, with any frame size limit: never a panic;
//! the chunking changes nothing that comes out; every frame runs from a
//! start-of-image to an end-of-image, has a size and stays under the limit;
//! what is held while waiting for more stays within the limit (and a
//! marker's header); and the frames
//! that came out, sent again as a multipart body, come out again the same.
#![no_main]

use libfuzzer_sys::fuzz_target;
use neptunus::camera::{JpegFrame, JpegSplitter};

fn split(max: usize, stream: &[u8], chunk: usize) -> (Vec<JpegFrame>, JpegSplitter) {
    let mut s = JpegSplitter::with_max_frame_bytes(max);
    let mut frames = Vec::new();
    for piece in stream.chunks(chunk) {
        s.push(piece);
        while let Some(f) = s.next_frame() {
            frames.push(f);
        }
        // Waiting at the limit for a marker and its length: 3 bytes more.
        assert!(
            s.buffered() <= max + 3,
            "{} bytes held with a limit of {max}",
            s.buffered()
        );
    }
    (frames, s)
}

fuzz_target!(|data: &[u8]| {
    // The first byte picks the chunk size, the second the frame size limit.
    let Some((&[chunk, limit], stream)) = data.split_first_chunk::<2>() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);
    let max = if limit == 0 {
        1 << 20
    } else {
        usize::from(limit) * 16
    };

    let (whole, whole_s) = split(max, stream, stream.len().max(1));
    let (chunked, chunked_s) = split(max, stream, chunk);
    assert_eq!(whole, chunked);
    assert_eq!(whole_s.stats(), chunked_s.stats());
    assert_eq!(whole_s.stats().frames, whole.len() as u64);

    for f in &whole {
        assert!(f.jpeg.starts_with(&[0xFF, 0xD8]) && f.jpeg.ends_with(&[0xFF, 0xD9]));
        assert!(f.width > 0 && f.height > 0);
        assert!(
            f.jpeg.len() <= max + 2,
            "a frame of {} bytes over the limit {max}",
            f.jpeg.len()
        );
    }

    // The frames again, as mjpg-streamer sends them.
    let mut body = Vec::new();
    for f in &whole {
        body.extend_from_slice(
            format!(
                "--boundarydonotcross\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
                f.jpeg.len()
            )
            .as_bytes(),
        );
        body.extend_from_slice(&f.jpeg);
        body.extend_from_slice(b"\r\n");
    }
    let (again, again_s) = split(max, &body, chunk);
    assert_eq!(
        again, whole,
        "the frames did not come out the same the second time"
    );
    assert_eq!(again_s.stats().dropped_frames, 0);
});
