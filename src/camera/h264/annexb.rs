//! An H.264 Annex B byte stream (start codes between NAL units, what a UVC
//! camera's buffers and `ffmpeg -f h264` hold) cut into access units, one
//! picture each, sans-IO.
//!
//! Bytes go in with [`UnitSplitter::push`]; a source that knows where a
//! picture ends (a V4L2 buffer is one) says so with
//! [`UnitSplitter::end_unit`], and a byte stream (a file, a pipe) lets the
//! next picture's first NAL unit end the one before (H.264 7.4.1.2.3: an
//! access unit delimiter, SPS, PPS or SEI after a picture's slices, or a
//! slice whose `first_mb_in_slice` is 0).
//!
//! Every keyframe (IDR) goes out with the SPS and PPS in front, the last
//! ones seen, even when the camera sends them once at the start: a
//! receiver that joins late (QGroundControl, a WebRTC viewer) has no other
//! way to learn them. Parameter sets or SEI in a buffer of their own wait
//! for the picture they belong to.
//!
//! Garbage never panics: bytes before the first start code, NAL units with
//! the forbidden bit, and pictures over [`MAX_UNIT_BYTES`] are counted and
//! dropped; memory stays bounded.

/// A picture larger than this is dropped (a 1080p keyframe is a few
/// hundred KiB).
pub const MAX_UNIT_BYTES: usize = 4 * 1024 * 1024;

const START: [u8; 4] = [0, 0, 0, 1];

/// One picture, NAL units with 4-byte start codes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unit {
    pub data: Vec<u8>,
    /// Holds an IDR slice (and, from here, the SPS and PPS).
    pub keyframe: bool,
}

/// What went by, for the log and the tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SplitterStats {
    pub units: u64,
    pub keyframes: u64,
    /// Keyframes that went out with parameter sets the camera had sent
    /// earlier.
    pub headers_added: u64,
    /// NAL units dropped: the forbidden bit set, or empty.
    pub bad_nal_units: u64,
    /// Bytes dropped: before the first start code, or of a picture over
    /// [`MAX_UNIT_BYTES`].
    pub dropped_bytes: u64,
}

/// Bytes in, access units out.
#[derive(Debug, Default)]
pub struct UnitSplitter {
    /// Bytes not yet cut into NAL units; starts at a start code once one
    /// was seen.
    pending: Vec<u8>,
    /// Where the search for the next start code goes on in `pending`.
    scanned: usize,
    synced: bool,
    unit: Vec<u8>,
    has_picture: bool,
    keyframe: bool,
    has_sps: bool,
    has_pps: bool,
    sps: Option<Vec<u8>>,
    pps: Option<Vec<u8>>,
    out: std::collections::VecDeque<Unit>,
    stats: SplitterStats,
}

/// The offset of the next start code (`00 00 01`) in `b` at or after
/// `from`, and its length (3, or 4 with a zero in front).
fn next_start(b: &[u8], from: usize) -> Option<(usize, usize)> {
    let mut i = from;
    while i + 3 <= b.len() {
        // Look for the 01 first: it is rarer than zeros in coded slices.
        let one = b[i + 2..].iter().position(|&x| x == 1)? + i + 2;
        if b[one - 1] == 0 && b[one - 2] == 0 {
            let at = one - 2;
            return Some(if at > from && b[at - 1] == 0 {
                (at - 1, 4)
            } else {
                (at, 3)
            });
        }
        i = one - 1;
    }
    None
}

impl UnitSplitter {
    pub fn new() -> Self {
        UnitSplitter::default()
    }

    pub fn stats(&self) -> SplitterStats {
        self.stats
    }

    /// The last SPS seen (without its start code).
    pub fn sps(&self) -> Option<&[u8]> {
        self.sps.as_deref()
    }

    /// Feeds bytes of the stream.
    pub fn push(&mut self, bytes: &[u8]) {
        self.pending.extend_from_slice(bytes);
        loop {
            if !self.synced {
                match next_start(&self.pending, 0) {
                    Some((at, _)) => {
                        self.stats.dropped_bytes += at as u64;
                        self.pending.drain(..at);
                        self.synced = true;
                        self.scanned = 0;
                    }
                    None => {
                        // Keep what could be the start of a start code.
                        let keep = self.pending.len().min(3);
                        let drop = self.pending.len() - keep;
                        self.stats.dropped_bytes += drop as u64;
                        self.pending.drain(..drop);
                        return;
                    }
                }
            }
            // `pending` begins with a start code: find the one after it.
            let first = next_start(&self.pending, 0).map_or(0, |(_, n)| n);
            let from = self.scanned.max(first);
            match next_start(&self.pending, from) {
                Some((at, _)) => {
                    let nal = self.pending[first..at].to_vec();
                    self.pending.drain(..at);
                    self.scanned = 0;
                    self.nal(&nal);
                }
                None => {
                    // Bounded: a NAL unit that never ends is dropped.
                    if self.pending.len() > MAX_UNIT_BYTES {
                        self.stats.dropped_bytes += self.pending.len() as u64;
                        self.pending.clear();
                        self.synced = false;
                        self.discard_unit();
                    } else {
                        self.scanned = self.pending.len().saturating_sub(3).max(first);
                    }
                    return;
                }
            }
        }
    }

    /// The bytes pushed so far end a picture (a V4L2 buffer did): it goes
    /// out now rather than when the next one begins.
    pub fn end_unit(&mut self) {
        if self.synced {
            let first = next_start(&self.pending, 0).map_or(0, |(_, n)| n);
            let nal = self.pending.get(first..).unwrap_or_default().to_vec();
            self.pending.clear();
            self.scanned = 0;
            self.synced = false;
            self.nal(&nal);
        }
        self.finish();
    }

    /// The next picture cut, if any.
    pub fn next_unit(&mut self) -> Option<Unit> {
        self.out.pop_front()
    }

    fn nal(&mut self, nal: &[u8]) {
        // Zeros before a start code belong to neither NAL unit.
        let end = nal.iter().rposition(|&b| b != 0).map_or(0, |i| i + 1);
        let nal = &nal[..end];
        let Some(&head) = nal.first() else {
            self.stats.bad_nal_units += 1;
            return;
        };
        if head & 0x80 != 0 {
            self.stats.bad_nal_units += 1;
            return;
        }
        let kind = head & 0x1f;
        let begins_picture = match kind {
            // Access unit delimiter, SPS, PPS, SEI, prefix and reserved.
            6..=9 | 14..=18 => self.has_picture,
            // A slice whose first macroblock is 0 (ue(v) 0 is the bit 1).
            1 | 5 => self.has_picture && nal.get(1).is_some_and(|b| b & 0x80 != 0),
            _ => false,
        };
        if begins_picture {
            self.finish();
        }
        match kind {
            7 => {
                self.sps = Some(nal.to_vec());
                self.has_sps = true;
            }
            8 => {
                self.pps = Some(nal.to_vec());
                self.has_pps = true;
            }
            5 => {
                self.keyframe = true;
                self.has_picture = true;
            }
            1 => self.has_picture = true,
            _ => {}
        }
        if self.unit.len() + nal.len() + START.len() > MAX_UNIT_BYTES {
            self.stats.dropped_bytes += nal.len() as u64;
            self.discard_unit();
            return;
        }
        self.unit.extend_from_slice(&START);
        self.unit.extend_from_slice(nal);
    }

    /// Ends the picture being put together. Without a slice it is not one
    /// yet: its parameter sets and SEI wait for the slices.
    fn finish(&mut self) {
        if !self.has_picture {
            return;
        }
        let mut data = std::mem::take(&mut self.unit);
        let keyframe = self.keyframe;
        if keyframe {
            self.stats.keyframes += 1;
            let mut front = Vec::new();
            for (have, set) in [(self.has_sps, &self.sps), (self.has_pps, &self.pps)] {
                if let (false, Some(set)) = (have, set) {
                    front.extend_from_slice(&START);
                    front.extend_from_slice(set);
                }
            }
            if !front.is_empty() {
                self.stats.headers_added += 1;
                front.extend_from_slice(&data);
                data = front;
            }
        }
        self.stats.units += 1;
        self.out.push_back(Unit { data, keyframe });
        self.reset_unit();
    }

    /// Drops the picture being put together (a part of it was too large).
    fn discard_unit(&mut self) {
        self.stats.dropped_bytes += self.unit.len() as u64;
        self.unit.clear();
        self.reset_unit();
    }

    fn reset_unit(&mut self) {
        self.has_picture = false;
        self.keyframe = false;
        self.has_sps = false;
        self.has_pps = false;
    }
}

/// The NAL unit types of an Annex B picture, in order (for tests and logs).
pub fn nal_types(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut at = 0;
    while let Some((start, n)) = next_start(data, at) {
        if let Some(b) = data.get(start + n) {
            out.push(b & 0x1f);
        }
        at = start + n;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng, rngs::SmallRng};

    fn nal(kind: u8, body: &[u8]) -> Vec<u8> {
        let mut v = vec![0, 0, 0, 1, 0x60 | kind];
        v.extend_from_slice(body);
        v
    }

    /// A stream like a camera's: SPS/PPS once, then IDR, P, P, IDR, P; each
    /// slice's first macroblock is 0 (the 0x80 bit).
    fn stream() -> Vec<Vec<u8>> {
        let mut sps_pps_idr = nal(7, &[0x42, 0xc0, 0x1e, 0xaa]);
        sps_pps_idr.extend(nal(8, &[0xce, 0x3c, 0x80]));
        sps_pps_idr.extend(nal(5, &[0x88, 1, 2, 3, 0, 0, 3, 1]));
        vec![
            sps_pps_idr,
            nal(1, &[0x9a, 4, 5]),
            nal(1, &[0x9a, 6, 0, 0, 0, 7]),
            nal(5, &[0x88, 8]),
            nal(1, &[0x9a, 9]),
        ]
    }

    #[test]
    fn buffers_are_pictures_and_every_keyframe_gets_the_parameter_sets() {
        let mut s = UnitSplitter::new();
        let mut got = Vec::new();
        for b in stream() {
            s.push(&b);
            s.end_unit();
            while let Some(u) = s.next_unit() {
                got.push(u);
            }
        }
        let kinds: Vec<Vec<u8>> = got.iter().map(|u| nal_types(&u.data)).collect();
        assert_eq!(
            kinds,
            [vec![7, 8, 5], vec![1], vec![1], vec![7, 8, 5], vec![1]]
        );
        assert_eq!(
            got.iter().map(|u| u.keyframe).collect::<Vec<_>>(),
            [true, false, false, true, false]
        );
        // The picture as the camera gave it, zeros inside it kept.
        assert_eq!(got[2].data, stream()[2]);
        let st = s.stats();
        assert_eq!((st.units, st.keyframes, st.headers_added), (5, 2, 1));
        assert_eq!(st.dropped_bytes, 0);
    }

    #[test]
    fn a_byte_stream_is_cut_where_the_next_picture_begins_in_any_chunks() {
        let whole: Vec<u8> = [vec![0xff, 0x00, 0x17], stream().concat()].concat();
        let mut rng = SmallRng::seed_from_u64(7);
        for _ in 0..200 {
            let mut s = UnitSplitter::new();
            let mut got = Vec::new();
            let mut rest = &whole[..];
            while !rest.is_empty() {
                let n = rng.random_range(1..=rest.len().min(9));
                s.push(&rest[..n]);
                rest = &rest[n..];
                while let Some(u) = s.next_unit() {
                    got.push(u);
                }
            }
            s.end_unit();
            while let Some(u) = s.next_unit() {
                got.push(u);
            }
            let kinds: Vec<Vec<u8>> = got.iter().map(|u| nal_types(&u.data)).collect();
            assert_eq!(
                kinds,
                [vec![7, 8, 5], vec![1], vec![1], vec![7, 8, 5], vec![1]]
            );
            assert_eq!(s.stats().dropped_bytes, 3, "the garbage in front");
        }
    }

    #[test]
    fn parameter_sets_in_a_buffer_of_their_own_wait_for_their_picture() {
        let mut s = UnitSplitter::new();
        let mut headers = nal(7, &[0x4d, 0x40, 0x28]);
        headers.extend(nal(8, &[0xee]));
        s.push(&headers);
        s.end_unit();
        assert_eq!(s.next_unit(), None);
        s.push(&nal(5, &[0x88, 1]));
        s.end_unit();
        let u = s.next_unit().expect("a picture");
        assert_eq!(nal_types(&u.data), [7, 8, 5]);
        assert_eq!(s.stats().headers_added, 0);
        assert_eq!(s.sps(), Some(&[0x67, 0x4d, 0x40, 0x28][..]));
    }

    #[test]
    fn a_picture_of_several_slices_is_one_unit() {
        let mut s = UnitSplitter::new();
        // Two slices of one picture: the second's first macroblock is not 0.
        let pic = [nal(1, &[0x9a, 1]), nal(1, &[0x40, 2])].concat();
        s.push(&[pic.clone(), nal(9, &[0xf0]), pic.clone()].concat());
        s.end_unit();
        assert_eq!(nal_types(&s.next_unit().expect("first").data), [1, 1]);
        assert_eq!(nal_types(&s.next_unit().expect("second").data), [9, 1, 1]);
        assert_eq!(s.next_unit(), None);
    }

    #[test]
    fn garbage_never_panics_and_memory_stays_bounded() {
        let mut rng = SmallRng::seed_from_u64(11);
        let mut s = UnitSplitter::new();
        for _ in 0..2000 {
            let n = rng.random_range(0..64);
            let mut b: Vec<u8> = (0..n).map(|_| rng.random_range(0..4u8)).collect();
            if rng.random_bool(0.3) {
                b.extend(nal(rng.random_range(0..32), &[rng.random(), rng.random()]));
            }
            s.push(&b);
            if rng.random_bool(0.2) {
                s.end_unit();
            }
            while s.next_unit().is_some() {}
            assert!(s.pending.len() <= MAX_UNIT_BYTES + 64);
            assert!(s.unit.len() <= MAX_UNIT_BYTES);
        }
        // One endless NAL unit is dropped, and the stream goes on after it.
        s.end_unit();
        while s.next_unit().is_some() {}
        s.push(&nal(5, &[0x88]));
        s.push(&vec![0x55; MAX_UNIT_BYTES + 10]);
        s.push(&nal(5, &[0x88, 1]));
        s.end_unit();
        let u = s.next_unit().expect("the picture after the oversized one");
        // With the parameter sets seen among the garbage in front.
        assert!(u.data.ends_with(&nal(5, &[0x88, 1])), "{:?}", u.data);
        assert_eq!(nal_types(&u.data).last(), Some(&5));
        assert!(u.keyframe);
        assert!(s.stats().dropped_bytes > MAX_UNIT_BYTES as u64);
    }
}
