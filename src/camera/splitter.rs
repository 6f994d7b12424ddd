//! Splitting a byte stream into whole JPEG frames.
//!
//! Used on ffmpeg's MJPEG stdout and on the body of an MJPEG HTTP stream
//! (the multipart boundaries and part headers are bytes between frames).
//! Sans-IO: bytes go in with [`JpegSplitter::push`] in chunks of any size,
//! frames come out of [`JpegSplitter::next_frame`].
//!
//! It walks the JPEG marker structure instead of searching for the
//! end-of-image bytes: segment payloads are skipped by their length, so an
//! EXIF thumbnail (a whole JPEG inside an APP1 segment) or a table that
//! happens to contain `FF D9` does not cut a frame short. Inside
//! entropy-coded data `FF` is always followed by `00` (stuffing), a restart
//! marker or a real marker. Malformed input never panics: a frame whose
//! structure breaks is dropped and the search resumes just after its start,
//! so a real frame hidden behind a false start is still found; a new
//! start-of-image inside a frame (a truncated frame) drops the partial one.
//! Memory is bounded by `max_frame_bytes`.

use bytes::{Buf, Bytes, BytesMut};

/// Larger than any JPEG a 4096×4096 camera gives at sane quality.
pub const DEFAULT_MAX_FRAME_BYTES: usize = 16 << 20;

/// One whole JPEG (from start-of-image to end-of-image inclusive) and the
/// size its frame header declares.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JpegFrame {
    pub jpeg: Bytes,
    pub width: u32,
    pub height: u32,
}

/// What the splitter did with the bytes it was given.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SplitterStats {
    pub frames: u64,
    /// Frames started but broken, truncated, oversized or without a frame
    /// header.
    pub dropped_frames: u64,
    /// Bytes outside any frame (multipart headers, garbage).
    pub skipped_bytes: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Looking for a start-of-image; nothing of a frame is buffered.
    Seek,
    /// `buf` starts with a frame; `pos` is where the next marker must be.
    Marker,
    /// Inside entropy-coded data; `pos` is the next byte to scan.
    Entropy,
}

#[derive(Debug)]
pub struct JpegSplitter {
    buf: BytesMut,
    pos: usize,
    state: State,
    size: Option<(u32, u32)>,
    max_frame_bytes: usize,
    stats: SplitterStats,
}

impl Default for JpegSplitter {
    fn default() -> Self {
        Self::new()
    }
}

impl JpegSplitter {
    pub fn new() -> Self {
        Self::with_max_frame_bytes(DEFAULT_MAX_FRAME_BYTES)
    }

    pub fn with_max_frame_bytes(max_frame_bytes: usize) -> Self {
        JpegSplitter {
            buf: BytesMut::with_capacity(64 * 1024),
            pos: 0,
            state: State::Seek,
            size: None,
            max_frame_bytes: max_frame_bytes.max(4),
            stats: SplitterStats::default(),
        }
    }

    pub fn push(&mut self, data: &[u8]) {
        self.buf.extend_from_slice(data);
    }

    pub fn stats(&self) -> SplitterStats {
        self.stats
    }

    /// Bytes held waiting for the rest of a frame.
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// The next whole frame, or `None` when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<JpegFrame> {
        loop {
            match self.state {
                State::Seek => {
                    if let Some(i) = self.buf.windows(2).position(|w| w == [0xFF, 0xD8]) {
                        self.stats.skipped_bytes += i as u64;
                        self.buf.advance(i);
                        self.start_frame();
                    } else {
                        // Keep a trailing FF: it may be the first half of a start.
                        let keep = usize::from(self.buf.last() == Some(&0xFF));
                        let skip = self.buf.len() - keep;
                        self.stats.skipped_bytes += skip as u64;
                        self.buf.advance(skip);
                        return None;
                    }
                }
                State::Marker => {
                    if self.pos > self.max_frame_bytes {
                        self.drop_frame();
                        continue;
                    }
                    let (Some(&lead), Some(&marker)) =
                        (self.buf.get(self.pos), self.buf.get(self.pos + 1))
                    else {
                        return None;
                    };
                    if lead != 0xFF {
                        self.drop_frame();
                        continue;
                    }
                    match marker {
                        // Fill byte before a marker.
                        0xFF => self.pos += 1,
                        // A new image before this one ended: keep the new one.
                        0xD8 => {
                            self.stats.dropped_frames += 1;
                            self.buf.advance(self.pos);
                            self.start_frame();
                        }
                        0xD9 => {
                            let jpeg = self.buf.split_to(self.pos + 2).freeze();
                            self.state = State::Seek;
                            self.pos = 0;
                            match self.size.take() {
                                Some((width, height)) => {
                                    self.stats.frames += 1;
                                    return Some(JpegFrame {
                                        jpeg,
                                        width,
                                        height,
                                    });
                                }
                                None => self.stats.dropped_frames += 1,
                            }
                        }
                        // Markers without a length.
                        0x01 | 0xD0..=0xD7 => self.pos += 2,
                        0x00 => self.drop_frame(),
                        _ => {
                            let len = self.buf.get(self.pos + 2..self.pos + 4)?;
                            let len = usize::from(u16::from_be_bytes([len[0], len[1]]));
                            // A segment that would end past the limit is not waited for.
                            if len < 2 || self.pos + 2 + len > self.max_frame_bytes {
                                self.drop_frame();
                                continue;
                            }
                            if is_frame_header(marker) {
                                // P, Y, X: precision, then height and width.
                                let seg = self.buf.get(self.pos + 4..self.pos + 2 + len)?;
                                let dims = (seg.len() >= 5).then(|| {
                                    let h = u16::from_be_bytes([seg[1], seg[2]]);
                                    let w = u16::from_be_bytes([seg[3], seg[4]]);
                                    (u32::from(w), u32::from(h))
                                });
                                match dims {
                                    Some((w, h)) if w > 0 && h > 0 => self.size = Some((w, h)),
                                    _ => {
                                        self.drop_frame();
                                        continue;
                                    }
                                }
                            }
                            self.pos += 2 + len;
                            if marker == 0xDA {
                                self.state = State::Entropy;
                            }
                        }
                    }
                }
                State::Entropy => {
                    if self.pos > self.max_frame_bytes {
                        self.drop_frame();
                        continue;
                    }
                    let rest = self.buf.get(self.pos..)?;
                    // Waiting for more of a frame already over the limit
                    // would make what is dropped, and when, depend on how
                    // the bytes were cut: it is dropped now.
                    let Some(off) = rest.iter().position(|&b| b == 0xFF) else {
                        self.pos = self.buf.len();
                        if self.pos > self.max_frame_bytes {
                            continue;
                        }
                        return None;
                    };
                    let i = self.pos + off;
                    let Some(&next) = self.buf.get(i + 1) else {
                        self.pos = i;
                        if self.pos > self.max_frame_bytes {
                            continue;
                        }
                        return None;
                    };
                    match next {
                        // Stuffed FF and restart markers belong to the data.
                        0x00 | 0xD0..=0xD7 => self.pos = i + 2,
                        0xFF => self.pos = i + 1,
                        _ => {
                            self.pos = i;
                            self.state = State::Marker;
                        }
                    }
                }
            }
        }
    }

    /// `buf` starts with FF D8.
    fn start_frame(&mut self) {
        self.pos = 2;
        self.state = State::Marker;
        self.size = None;
    }

    /// Gives up the frame at the start of `buf`; the search resumes right
    /// after its start-of-image, so nothing after it is lost.
    fn drop_frame(&mut self) {
        self.stats.dropped_frames += 1;
        self.stats.skipped_bytes += 2;
        self.buf.advance(2);
        self.pos = 0;
        self.state = State::Seek;
        self.size = None;
    }
}

/// SOF0–SOF15, without DHT (C4), JPG (C8) and DAC (CC).
fn is_frame_header(marker: u8) -> bool {
    matches!(marker, 0xC0..=0xCF) && !matches!(marker, 0xC4 | 0xC8 | 0xCC)
}

#[cfg(test)]
mod tests {
    use super::*;
    use jpeg_encoder::{ColorType, Encoder};

    fn jpeg(w: u16, h: u16, tweak: impl FnOnce(&mut Encoder<&mut Vec<u8>>)) -> Vec<u8> {
        let rgb: Vec<u8> = (0..usize::from(w) * usize::from(h) * 3)
            .map(|i| (i * 7 % 251) as u8)
            .collect();
        let mut out = Vec::new();
        let mut enc = Encoder::new(&mut out, 75);
        tweak(&mut enc);
        enc.encode(&rgb, w, h, ColorType::Rgb).expect("encode");
        out
    }

    fn split_all(s: &mut JpegSplitter, data: &[u8], chunk: usize) -> Vec<JpegFrame> {
        let mut out = Vec::new();
        for c in data.chunks(chunk.max(1)) {
            s.push(c);
            while let Some(f) = s.next_frame() {
                out.push(f);
            }
        }
        out
    }

    #[test]
    fn one_frame_whole_and_byte_by_byte() {
        let j = jpeg(33, 17, |_| {});
        for chunk in [j.len(), 1, 2, 3, 7] {
            let mut s = JpegSplitter::new();
            let frames = split_all(&mut s, &j, chunk);
            assert_eq!(frames.len(), 1, "chunk {chunk}");
            assert_eq!(frames[0].jpeg, j);
            assert_eq!((frames[0].width, frames[0].height), (33, 17));
            assert_eq!(s.buffered(), 0);
        }
    }

    #[test]
    fn markers_inside_segments_and_scans_do_not_cut_frames() {
        // An APP segment carrying FF D9 / FF D8 (as an EXIF thumbnail does),
        // progressive scans (several SOS and DHT after the first scan) and
        // restart markers in the entropy data.
        let app = vec![0xFF, 0xD8, 0xFF, 0xD9, 0x00, 0xFF, 0xD9, 0xFF];
        let frames = [
            jpeg(40, 30, |e| e.add_app_segment(3, app.clone()).expect("app")),
            jpeg(40, 30, |e| e.set_progressive(true)),
            jpeg(40, 30, |e| e.set_restart_interval(1)),
        ];
        let stream: Vec<u8> = frames.concat();
        let mut s = JpegSplitter::new();
        let out = split_all(&mut s, &stream, 5);
        assert_eq!(out.len(), 3);
        for (got, want) in out.iter().zip(&frames) {
            assert_eq!(got.jpeg, want[..]);
        }
        assert_eq!(s.stats().dropped_frames, 0);
        assert_eq!(s.stats().skipped_bytes, 0);
    }

    #[test]
    fn truncated_frames_and_false_starts_are_dropped_not_the_next_frame() {
        let a = jpeg(20, 20, |_| {});
        let b = jpeg(24, 16, |_| {});
        let mut stream = Vec::new();
        stream.extend_from_slice(b"--boundary\r\nContent-Type: image/jpeg\r\n\r\n");
        stream.extend_from_slice(&[0xFF, 0xD8, 0x12, 0x34]); // a false start
        stream.extend_from_slice(&a[..a.len() - 40]); // cut inside the scan
        stream.extend_from_slice(&b);
        stream.extend_from_slice(&a[..30]); // cut inside the headers
        stream.extend_from_slice(&a);
        let mut s = JpegSplitter::new();
        let out = split_all(&mut s, &stream, 3);
        assert_eq!(
            out.iter().map(|f| &f.jpeg[..]).collect::<Vec<_>>(),
            [&b[..], &a[..]]
        );
        assert_eq!(s.stats().frames, 2);
        assert_eq!(s.stats().dropped_frames, 3);
    }

    #[test]
    fn oversized_frames_are_dropped_and_memory_stays_bounded() {
        let big = jpeg(64, 64, |_| {});
        let small = jpeg(8, 8, |_| {});
        assert!(
            big.len() > 1000 && small.len() < 1000,
            "{} {}",
            big.len(),
            small.len()
        );
        let mut s = JpegSplitter::with_max_frame_bytes(1000);
        let stream = [big.clone(), small.clone(), big].concat();
        let out = split_all(&mut s, &stream, 64);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].jpeg, small);
        assert!(s.buffered() < 1100);
    }

    #[test]
    fn frames_without_a_frame_header_are_dropped() {
        let mut s = JpegSplitter::new();
        s.push(&[0xFF, 0xD8, 0xFF, 0xD9]);
        assert_eq!(s.next_frame(), None);
        assert_eq!(s.stats().dropped_frames, 1);
    }

    #[test]
    fn garbage_alone_is_skipped() {
        let mut s = JpegSplitter::new();
        let garbage: Vec<u8> = (0..10_000u32).map(|i| (i * 37 % 256) as u8).collect();
        assert!(split_all(&mut s, &garbage, 100).is_empty());
        assert!(s.buffered() <= 1);
    }
}
