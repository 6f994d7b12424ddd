//! Fuzzes the MAVLink endpoint input path: any bytes, as a stream in any
//! chunking and as a UDP datagram, must never panic; chunking must not change
//! what comes out; every delivered frame must re-decode to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use neptunus::mavlink::{FrameDecoder, FrameStats, decode_datagram};

fuzz_target!(|data: &[u8]| {
    // The first byte picks the chunk size, the rest is the input.
    let Some((&chunk, input)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);

    let mut whole = FrameDecoder::new();
    let mut whole_frames = Vec::new();
    whole.push(input, &mut whole_frames);

    let mut chunked = FrameDecoder::new();
    let mut chunked_frames = Vec::new();
    for piece in input.chunks(chunk) {
        chunked.push(piece, &mut chunked_frames);
    }
    // Compare bytes, not messages: a float field may be NaN, and NaN != NaN.
    let raw = |frames: &[neptunus::mavlink::Frame]| -> Vec<Vec<u8>> {
        frames.iter().map(|f| f.raw.clone()).collect()
    };
    assert_eq!(raw(&whole_frames), raw(&chunked_frames));
    assert_eq!(whole.stats(), chunked.stats());
    assert_eq!(whole.stats().frames, whole_frames.len() as u64);

    let mut stats = FrameStats::default();
    let mut datagram_frames = Vec::new();
    decode_datagram(input, &mut stats, &mut datagram_frames);
    assert_eq!(stats.frames, datagram_frames.len() as u64);

    for frame in whole_frames.iter().chain(&datagram_frames) {
        let mut again = Vec::new();
        let mut stats = FrameStats::default();
        decode_datagram(&frame.raw, &mut stats, &mut again);
        assert_eq!(again.len(), 1);
        assert_eq!(again[0].raw, frame.raw);
        assert_eq!(again[0].msg_id, frame.msg_id);
    }
});
