//! Round trips of the media parsers that face the network, as properties
//! (the fuzz targets `stun_answers`, `rtp_depay` and `mjpeg_split` check
//! the same on arbitrary bytes): what a STUN server writes is read back,
//! the RTP the encoder sends comes back as its pictures byte for byte, and
//! the JPEGs of an MJPEG stream come out of the splitter whatever the
//! envelope and the chunking.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::net::{IpAddr, SocketAddr};

use jpeg_encoder::{ColorType, Encoder};
use neptunus::camera::JpegSplitter;
use neptunus::camera::h264::depay::{AccessUnit, Depay};
use neptunus::fuzzing::{binding_request, parse_binding_success, stun_binding_success};
use proptest::prelude::*;

fn socket_addr() -> impl Strategy<Value = SocketAddr> {
    prop_oneof![
        any::<[u8; 4]>().prop_map(IpAddr::from),
        any::<[u8; 16]>().prop_map(IpAddr::from),
    ]
    .prop_flat_map(|ip| any::<u16>().prop_map(move |port| SocketAddr::new(ip, port)))
}

proptest! {
    /// A binding success answer, with any other attributes before its
    /// XOR-MAPPED-ADDRESS, gives back its transaction and address; cut or
    /// lengthened by a byte it is no answer, and no request is one.
    #[test]
    fn a_stun_answer_reads_back(
        id in any::<[u8; 12]>(),
        addr in socket_addr(),
        before in prop::collection::vec(
            (any::<u16>().prop_filter("not XOR-MAPPED-ADDRESS", |k| *k != 0x0020),
             prop::collection::vec(any::<u8>(), 0..40)),
            0..5),
    ) {
        let answer = stun_binding_success(id, addr, &before);
        prop_assert_eq!(parse_binding_success(&answer), Some((id, addr)));
        prop_assert_eq!(parse_binding_success(&answer[..answer.len() - 1]), None);
        let mut long = answer.clone();
        long.push(0);
        prop_assert_eq!(parse_binding_success(&long), None);
        prop_assert_eq!(parse_binding_success(&binding_request(id)), None);
    }
}

/// How a picture's NAL units are put into RTP payloads.
#[derive(Debug, Clone, Copy)]
enum Packing {
    /// One NAL unit per packet, FU-A fragments of this size for longer ones.
    Single(usize),
    /// All in one STAP-A (when they fit).
    StapA,
}

#[derive(Debug, Clone)]
struct Picture {
    nals: Vec<Vec<u8>>,
    packing: Packing,
    step_90khz: u32,
}

impl Picture {
    fn keyframe(&self) -> bool {
        self.nals.iter().any(|n| n[0] & 0x1f == 5)
    }

    fn annex_b(&self) -> Vec<u8> {
        self.nals
            .iter()
            .flat_map(|n| [&[0, 0, 0, 1][..], n].concat())
            .collect()
    }

    fn payloads(&self) -> Vec<Vec<u8>> {
        let fits = self.nals.iter().map(|n| n.len() + 2).sum::<usize>() < 1400;
        match self.packing {
            Packing::StapA if fits => {
                let mut p = vec![24];
                for n in &self.nals {
                    p.extend((n.len() as u16).to_be_bytes());
                    p.extend(n);
                }
                vec![p]
            }
            Packing::StapA => Picture {
                packing: Packing::Single(1200),
                ..self.clone()
            }
            .payloads(),
            Packing::Single(size) => self.nals.iter().flat_map(|n| fu_a(n, size)).collect(),
        }
    }
}

fn fu_a(nal: &[u8], size: usize) -> Vec<Vec<u8>> {
    if nal.len() <= size + 1 {
        return vec![nal.to_vec()];
    }
    let chunks: Vec<&[u8]> = nal[1..].chunks(size).collect();
    chunks
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut fu = vec![(nal[0] & 0x60) | 28, nal[0] & 0x1f];
            if i == 0 {
                fu[1] |= 0x80;
            }
            if i == chunks.len() - 1 {
                fu[1] |= 0x40;
            }
            fu.extend(*c);
            fu
        })
        .collect()
}

fn nal() -> impl Strategy<Value = Vec<u8>> {
    (1u8..=23, 0u8..4, prop::collection::vec(any::<u8>(), 0..600))
        .prop_map(|(kind, nri, body)| [vec![nri << 5 | kind], body].concat())
}

fn picture() -> impl Strategy<Value = Picture> {
    (
        prop::collection::vec(nal(), 1..4),
        prop_oneof![
            (1usize..1300).prop_map(Packing::Single),
            Just(Packing::StapA)
        ],
        0u32..4000,
    )
        .prop_map(|(nals, packing, step_90khz)| Picture {
            nals,
            packing,
            step_90khz,
        })
}

/// The pictures' RTP packets: (picture, datagram).
fn packets(pictures: &[Picture], mut seq: u16, mut ts: u32) -> Vec<(usize, Vec<u8>)> {
    let mut out = Vec::new();
    for (i, p) in pictures.iter().enumerate() {
        ts = ts.wrapping_add(p.step_90khz);
        let payloads = p.payloads();
        for (j, payload) in payloads.iter().enumerate() {
            let marker = j == payloads.len() - 1;
            let mut d = vec![0x80, if marker { 0x80 | 96 } else { 96 }];
            d.extend(seq.to_be_bytes());
            d.extend(ts.to_be_bytes());
            d.extend(77u32.to_be_bytes());
            d.extend(payload);
            out.push((i, d));
            seq = seq.wrapping_add(1);
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// Every picture from the first keyframe on comes back byte for byte,
    /// whatever the packing, with a media clock that follows the encoder's.
    #[test]
    fn rtp_pictures_come_back_whole(
        pictures in prop::collection::vec(picture(), 1..12),
        seq in any::<u16>(),
        ts in any::<u32>(),
    ) {
        let mut d = Depay::new();
        let mut out: Vec<AccessUnit> = Vec::new();
        for (_, datagram) in packets(&pictures, seq, ts) {
            out.extend(d.push(&datagram));
        }
        let first = pictures.iter().position(Picture::keyframe);
        let expected: Vec<&Picture> = pictures.iter().skip(first.unwrap_or(pictures.len())).collect();
        prop_assert_eq!(out.len(), expected.len());
        for (u, p) in out.iter().zip(&expected) {
            prop_assert_eq!(&u.data, &p.annex_b());
            prop_assert_eq!(u.keyframe, p.keyframe());
        }
        for (w, p) in out.windows(2).zip(expected.iter().skip(1)) {
            let step = u64::from(p.step_90khz).max(1);
            prop_assert_eq!(w[1].time_90khz - w[0].time_90khz, step);
        }
        prop_assert_eq!(d.stats().lost, 0);
        prop_assert_eq!(d.stats().bad, 0);
    }

    /// One packet lost: the picture it belonged to never comes out, nothing
    /// that comes out differs from what was sent, and every picture from
    /// the first keyframe after the next whole picture comes out.
    #[test]
    fn a_lost_rtp_packet_spoils_its_picture_only_up_to_a_keyframe(
        pictures in prop::collection::vec(picture(), 2..12),
        lose in any::<prop::sample::Index>(),
    ) {
        let packets = packets(&pictures, 65_530, 0);
        // Not the first: nothing tells a receiver of packets before the first
        // it gets (the encoder's first packet starts its stream).
        let lost = 1 + lose.index(packets.len() - 1);
        let spoiled = packets[lost].0;
        let mut d = Depay::new();
        let mut out = Vec::new();
        for (k, (_, datagram)) in packets.iter().enumerate() {
            if k != lost {
                out.extend(d.push(datagram));
            }
        }
        let mut next = 0;
        let mut came = Vec::new();
        for u in &out {
            let i = (next..pictures.len())
                .find(|&i| i != spoiled && pictures[i].annex_b() == u.data);
            prop_assert!(i.is_some(), "a picture that was not sent whole came out");
            let i = i.unwrap();
            came.push(i);
            next = i + 1;
        }
        let first_key = pictures.iter().position(Picture::keyframe);
        let resume = pictures
            .iter()
            .enumerate()
            .skip(spoiled + 2)
            .find(|(_, p)| p.keyframe())
            .map(|(i, _)| i);
        for i in 0..pictures.len() {
            let must = first_key.is_some_and(|f| i >= f)
                && (i < spoiled || resume.is_some_and(|r| i >= r));
            if must {
                prop_assert!(came.contains(&i), "picture {} did not come out: {:?}", i, came);
            }
        }
    }
}

fn jpeg(w: u16, h: u16, progressive: bool, restart: u16) -> Vec<u8> {
    let rgb: Vec<u8> = (0..usize::from(w) * usize::from(h) * 3)
        .map(|i| (i * 13 % 251) as u8)
        .collect();
    let mut out = Vec::new();
    let mut enc = Encoder::new(&mut out, 50);
    enc.set_progressive(progressive);
    enc.set_restart_interval(restart);
    enc.encode(&rgb, w, h, ColorType::Rgb).unwrap();
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// JPEGs in a multipart body (or bare, or with garbage without FF D8
    /// between them), in chunks of any size, come out as they went in,
    /// with their sizes.
    #[test]
    fn mjpeg_frames_come_out_whatever_the_envelope(
        frames in prop::collection::vec((1u16..40, 1u16..40, any::<bool>(), 0u16..3), 1..5),
        envelope in 0u8..3,
        garbage in prop::collection::vec(any::<u8>(), 0..64),
        chunk in 1usize..700,
    ) {
        let garbage: Vec<u8> = garbage.into_iter().map(|b| if b == 0xFF { 0 } else { b }).collect();
        let jpegs: Vec<Vec<u8>> = frames.iter().map(|&(w, h, p, r)| jpeg(w, h, p, r)).collect();
        let mut body = Vec::new();
        for j in &jpegs {
            match envelope {
                0 => body.extend(format!("--frame\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n", j.len()).as_bytes()),
                1 => body.extend(&garbage),
                _ => {}
            }
            body.extend(j);
            if envelope == 0 {
                body.extend(b"\r\n");
            }
        }
        let mut s = JpegSplitter::new();
        let mut out = Vec::new();
        for piece in body.chunks(chunk) {
            s.push(piece);
            while let Some(f) = s.next_frame() {
                out.push(f);
            }
        }
        prop_assert_eq!(out.len(), jpegs.len());
        for ((f, j), &(w, h, _, _)) in out.iter().zip(&jpegs).zip(&frames) {
            prop_assert_eq!(&f.jpeg[..], &j[..]);
            prop_assert_eq!((f.width, f.height), (u32::from(w), u32::from(h)));
        }
        prop_assert_eq!(s.stats().dropped_frames, 0);
    }
}
