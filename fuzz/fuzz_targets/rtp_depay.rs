//! Fuzzes the RTP depacketiser (the encoder's packets read back into
//! pictures for the WebRTC viewers).
//!
//! The input twice:
//! - as datagrams (each a 2-byte big-endian length, then its bytes): never
//!   a panic, the counters add up, the media clock only goes forward, the
//!   first picture is a keyframe and every picture is Annex B;
//! - as a description of a stream (pictures of NAL units; single NAL unit
//!   packets, STAP-A or FU-A; CSRCs, header extensions and padding in the
//!   RTP headers; at most one packet lost): the pictures come back byte for
//!   byte from the first keyframe on, none that lost a packet comes out,
//!   and after a loss every picture from the next keyframe whose start
//!   was received whole on comes out.
#![no_main]

use libfuzzer_sys::fuzz_target;
use neptunus::camera::h264::depay::{AccessUnit, Depay};

/// The input read a byte at a time; zeros once it runs out.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        let Some((&b, rest)) = self.0.split_first() else {
            return 0;
        };
        self.0 = rest;
        b
    }
    fn u16(&mut self) -> u16 {
        u16::from_be_bytes([self.u8(), self.u8()])
    }
    fn take(&mut self, n: usize) -> Vec<u8> {
        let n = n.min(self.0.len());
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        a.to_vec()
    }
    fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

fn datagrams(data: &[u8]) {
    let mut d = Depay::new();
    let mut input = Bytes(data);
    let mut pushed = 0u64;
    let mut units: Vec<AccessUnit> = Vec::new();
    while !input.is_empty() {
        let n = usize::from(input.u16());
        let datagram = input.take(n);
        pushed += 1;
        units.extend(d.push(&datagram));
    }
    let s = d.stats();
    assert_eq!(s.packets, pushed);
    assert_eq!(s.units, units.len() as u64);
    assert!(s.bad <= s.packets);
    if let Some(first) = units.first() {
        assert!(first.keyframe, "the first picture out is not a keyframe");
    }
    for u in &units {
        assert!(u.data.starts_with(&[0, 0, 0, 1]), "not Annex B");
    }
    for w in units.windows(2) {
        assert!(
            w[0].time_90khz < w[1].time_90khz,
            "the media clock went back"
        );
    }
}

/// One picture as the encoder made it, and as its packets' payloads.
struct Picture {
    annex_b: Vec<u8>,
    keyframe: bool,
    timestamp: u32,
    payloads: Vec<Vec<u8>>,
}

fn picture(input: &mut Bytes, timestamp: u32) -> Picture {
    let how = input.u8();
    let mut nals = Vec::new();
    for _ in 0..=(how & 3) {
        let header = input.u8();
        // Forbidden bit clear, NAL unit types 1..=23 (5: IDR).
        let kind = 1 + (header & 0x1f) % 23;
        let mut nal = vec![(header & 0x60) | kind];
        let len = usize::from(input.u8()) * 8;
        let seed = input.u8();
        nal.extend((0..len).map(|i| seed.wrapping_add((i * 31 % 251) as u8)));
        nals.push(nal);
    }
    let keyframe = nals.iter().any(|n| n[0] & 0x1f == 5);
    let annex_b = nals
        .iter()
        .flat_map(|n| [&[0, 0, 0, 1][..], n].concat())
        .collect();
    let mut payloads = Vec::new();
    let stap = (how >> 2) & 1 == 1 && nals.iter().map(|n| n.len() + 2).sum::<usize>() < 1400;
    if stap {
        let mut p = vec![24];
        for n in &nals {
            p.extend((n.len() as u16).to_be_bytes());
            p.extend(n);
        }
        payloads.push(p);
    } else {
        let fragment = 1 + usize::from(how >> 3) * 40;
        for n in &nals {
            if n.len() <= fragment + 1 {
                payloads.push(n.clone());
                continue;
            }
            let chunks: Vec<&[u8]> = n[1..].chunks(fragment).collect();
            for (i, c) in chunks.iter().enumerate() {
                let mut fu = vec![(n[0] & 0x60) | 28, n[0] & 0x1f];
                if i == 0 {
                    fu[1] |= 0x80;
                }
                if i == chunks.len() - 1 {
                    fu[1] |= 0x40;
                }
                fu.extend(*c);
                payloads.push(fu);
            }
        }
    }
    Picture {
        annex_b,
        keyframe,
        timestamp,
        payloads,
    }
}

/// An RTP packet of payload type 96, its header shaped by `shape`: CSRCs,
/// a header extension, padding.
fn rtp(shape: u8, seq: u16, ts: u32, marker: bool, payload: &[u8]) -> Vec<u8> {
    let csrcs = shape & 0x0f;
    let extension = shape & 0x10 != 0;
    let padding = shape & 0x20 != 0;
    let mut p =
        vec![0x80 | csrcs | if extension { 0x10 } else { 0 } | if padding { 0x20 } else { 0 }];
    p.push(if marker { 0x80 | 96 } else { 96 });
    p.extend(seq.to_be_bytes());
    p.extend(ts.to_be_bytes());
    p.extend(0x5eed_u32.to_be_bytes());
    for c in 0..csrcs {
        p.extend(u32::from(c).to_be_bytes());
    }
    if extension {
        let words = shape >> 6;
        p.extend([0xbe, 0xde, 0, words]);
        p.extend(std::iter::repeat_n(0xee, 4 * usize::from(words)));
    }
    p.extend(payload);
    if padding {
        let n = 1 + (shape >> 6);
        p.extend(std::iter::repeat_n(0, usize::from(n - 1)));
        p.push(n);
    }
    p
}

fn stream(data: &[u8]) {
    let mut input = Bytes(data);
    let mut seq = input.u16();
    let mut ts = u32::from(input.u16()) << 16 | u32::from(input.u16());
    let lose = input.u16();
    let mut pictures = Vec::new();
    while !input.is_empty() && pictures.len() < 64 {
        ts = ts.wrapping_add(u32::from(input.u16()) * 8);
        pictures.push(picture(&mut input, ts));
    }
    // Packets as sent: (picture, datagram); one may be lost.
    let mut packets = Vec::new();
    for (i, p) in pictures.iter().enumerate() {
        for (j, payload) in p.payloads.iter().enumerate() {
            let shape = payload.first().map_or(0, |b| b.rotate_left(3)) ^ (j as u8);
            packets.push((
                i,
                rtp(shape, seq, p.timestamp, j == p.payloads.len() - 1, payload),
            ));
            seq = seq.wrapping_add(1);
        }
    }
    // Not the first packet: a receiver cannot know of packets before the
    // first it gets (the encoder's first packet starts its stream).
    let lost =
        (lose > 0 && usize::from(lose) < packets.len() && lose % 3 == 0).then(|| usize::from(lose));
    let spoiled = lost.map(|l| packets[l].0);
    let mut d = Depay::new();
    let mut out = Vec::new();
    for (k, (_, datagram)) in packets.iter().enumerate() {
        if Some(k) != lost {
            out.extend(d.push(datagram));
        }
    }
    assert_eq!(d.stats().bad, 0);
    assert_eq!(
        d.stats().lost,
        u64::from(lost.is_some_and(|l| l + 1 < packets.len()))
    );
    // What must come out: from the first keyframe on; after a loss, from the
    // first keyframe after the picture that follows the spoiled one.
    let first_key = pictures.iter().position(|p| p.keyframe);
    let must: Vec<usize> = (0..pictures.len())
        .filter(|&i| first_key.is_some_and(|f| i >= f))
        .filter(|&i| match spoiled {
            None => true,
            Some(s) if i < s => true,
            Some(s) => pictures
                .iter()
                .enumerate()
                .skip(s + 2)
                .find(|(_, p)| p.keyframe)
                .is_some_and(|(k, _)| i >= k),
        })
        .collect();
    // What came out: pictures as they were sent, in order, none spoiled.
    let mut next = 0;
    let mut came = Vec::new();
    for u in &out {
        let i = (next..pictures.len())
            .find(|&i| Some(i) != spoiled && pictures[i].annex_b == u.data)
            .unwrap_or_else(|| {
                panic!(
                    "a picture that was not sent (or was spoiled): {} bytes",
                    u.data.len()
                )
            });
        assert_eq!(u.keyframe, pictures[i].keyframe);
        came.push(i);
        next = i + 1;
    }
    for i in &must {
        assert!(
            came.contains(i),
            "picture {i} did not come out: {came:?}, expected at least {must:?}"
        );
    }
    if let Some(&first) = came.first() {
        assert!(pictures[first].keyframe);
    }
}

fuzz_target!(|data: &[u8]| {
    datagrams(data);
    stream(data);
});
