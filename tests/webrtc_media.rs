//! The WebRTC media path without a socket or a clock: the encoder's RTP
//! read back into pictures (`depay`: single NAL units, STAP-A, FU-A, loss,
//! a restarted encoder, garbage), and one viewer's peer connection
//! (`peer`) against a second str0m standing in for the browser — offer,
//! answer, ICE, DTLS and the pictures themselves, on synthetic time with
//! the datagrams carried by hand.
#![allow(clippy::unwrap_used)]

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use neptunus::camera::h264::depay::{AccessUnit, Depay};
use neptunus::camera::webrtc::peer::{Datagram, Peer};
use proptest::prelude::*;
use str0m::change::SdpOffer;
use str0m::net::{Protocol, Receive};
use str0m::{Candidate, Event, Input, Output, Rtc};

/// An RTP packet of payload type 96.
fn rtp(seq: u16, ts: u32, marker: bool, ssrc: u32, payload: &[u8]) -> Vec<u8> {
    let mut p = vec![0x80, if marker { 0xe0 } else { 0x60 }];
    p.extend(seq.to_be_bytes());
    p.extend(ts.to_be_bytes());
    p.extend(ssrc.to_be_bytes());
    p.extend(payload);
    p
}

const SPS: &[u8] = &[0x67, 0x42, 0xc0, 0x1e, 0xda, 0x02, 0x80];
const PPS: &[u8] = &[0x68, 0xce, 0x3c, 0x80];

fn idr(len: usize) -> Vec<u8> {
    let mut n = vec![0x65];
    n.extend((0..len).map(|i| (i % 251) as u8 | 1));
    n
}

fn p_slice(len: usize) -> Vec<u8> {
    let mut n = vec![0x41];
    n.extend((0..len).map(|i| (i % 241) as u8 | 1));
    n
}

/// Annex B of NAL units.
fn annex_b(nals: &[&[u8]]) -> Vec<u8> {
    nals.iter()
        .flat_map(|n| [&[0, 0, 0, 1][..], n].concat())
        .collect()
}

/// A NAL unit cut into FU-A fragments of at most `size` bytes.
fn fu_a(nal: &[u8], size: usize) -> Vec<Vec<u8>> {
    let (head, body) = (nal[0], &nal[1..]);
    let chunks: Vec<&[u8]> = body.chunks(size).collect();
    chunks
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut fu = vec![(head & 0xe0) | 28, head & 0x1f];
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

/// A STAP-A of NAL units.
fn stap_a(nals: &[&[u8]]) -> Vec<u8> {
    let mut p = vec![24];
    for n in nals {
        p.extend((n.len() as u16).to_be_bytes());
        p.extend(*n);
    }
    p
}

/// The one picture a packet ended, if any (these streams always end a
/// picture with its marker: never two at once).
fn one(mut units: Vec<AccessUnit>) -> Option<AccessUnit> {
    assert!(units.len() <= 1, "{} pictures from one packet", units.len());
    units.pop()
}

#[test]
fn pictures_come_back_whole_and_start_at_a_keyframe() {
    let mut d = Depay::new();
    let ssrc = 7;
    // A P picture before any keyframe cannot be decoded: skipped.
    assert_eq!(one(d.push(&rtp(10, 1000, true, ssrc, &p_slice(50)))), None);
    assert_eq!(d.stats().skipped, 1);
    // SPS and PPS in a STAP-A, then the IDR in FU-A fragments.
    let big = idr(3000);
    assert_eq!(
        one(d.push(&rtp(11, 4000, false, ssrc, &stap_a(&[SPS, PPS])))),
        None
    );
    let frags = fu_a(&big, 1100);
    assert_eq!(frags.len(), 3);
    let mut out = None;
    for (i, f) in frags.iter().enumerate() {
        out = one(d.push(&rtp(12 + i as u16, 4000, i == frags.len() - 1, ssrc, f)));
        assert_eq!(out.is_some(), i == frags.len() - 1);
    }
    let key = out.unwrap();
    assert!(key.keyframe);
    assert_eq!(key.data, annex_b(&[SPS, PPS, &big]));
    // The next picture 3000 ticks later (30 fps at 90 kHz).
    let p = one(d.push(&rtp(15, 7000, true, ssrc, &p_slice(80)))).unwrap();
    assert_eq!(
        p,
        AccessUnit {
            data: annex_b(&[&p_slice(80)]),
            time_90khz: key.time_90khz + 3000,
            keyframe: false,
        }
    );
    assert_eq!(d.stats().lost, 0);
    assert_eq!(d.stats().units, 2);
}

#[test]
fn a_lost_packet_spoils_everything_up_to_the_next_keyframe() {
    let mut d = Depay::new();
    let ssrc = 9;
    assert!(one(d.push(&rtp(100, 0, true, ssrc, &idr(100)))).is_some());
    // Packet 101 (the first half of a picture) never comes.
    assert_eq!(one(d.push(&rtp(102, 3000, true, ssrc, &p_slice(40)))), None);
    assert_eq!(one(d.push(&rtp(103, 6000, true, ssrc, &p_slice(40)))), None);
    assert_eq!(d.stats().lost, 1);
    let k = one(d.push(&rtp(104, 9000, true, ssrc, &idr(100)))).unwrap();
    assert!(k.keyframe);
    assert!(one(d.push(&rtp(105, 12000, true, ssrc, &p_slice(40)))).is_some());
}

#[test]
fn a_restarted_encoder_starts_over_and_the_clock_never_goes_back() {
    let mut d = Depay::new();
    let a = one(d.push(&rtp(65535, u32::MAX - 1000, true, 1, &idr(10)))).unwrap();
    // Sequence and timestamp wrap around: still one stream.
    let b = one(d.push(&rtp(0, 2000, true, 1, &p_slice(10)))).unwrap();
    assert_eq!(b.time_90khz, a.time_90khz + 3001);
    // The encoder restarts: a new SSRC, its own sequence and clock.
    assert_eq!(one(d.push(&rtp(500, 10, true, 2, &p_slice(10)))), None);
    let c = one(d.push(&rtp(501, 3010, true, 2, &idr(10)))).unwrap();
    assert!(c.keyframe && c.time_90khz > b.time_90khz);
    // A picture whose marker packet was lost ends when the next begins.
    assert_eq!(one(d.push(&rtp(502, 6010, false, 2, &p_slice(10)))), None);
    // 503 (the marker) is lost; 504 is a new picture: 502's is spoilt.
    assert_eq!(one(d.push(&rtp(504, 9010, true, 2, &p_slice(10)))), None);
    assert!(d.stats().lost >= 1);
}

#[test]
fn what_is_not_rtp_is_counted_and_dropped() {
    let mut d = Depay::new();
    for bad in [
        vec![],
        vec![0x80],
        vec![0x40; 20],                                      // version 1
        rtp(1, 0, true, 1, &[]),                             // no payload
        [vec![0x90], vec![0; 11], vec![0; 2]].concat(),      // extension cut short
        [vec![0xa0], vec![0; 11], vec![0x65, 200]].concat(), // padding longer than the packet
        rtp(2, 0, true, 1, &[28]),                           // FU-A without its header
        rtp(3, 0, true, 1, &[24, 0, 50, 0x65]),              // STAP-A longer than the packet
    ] {
        assert_eq!(one(d.push(&bad)), None, "{bad:?}");
    }
    assert!(d.stats().bad >= 7, "{:?}", d.stats());
}

proptest! {
    #[test]
    fn garbage_never_panics(packets in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..64), 0..50)) {
        let mut d = Depay::new();
        for p in packets {
            if let Some(au) = one(d.push(&p)) {
                prop_assert!(au.keyframe || d.stats().units > 1);
            }
        }
    }
}

/// Carries datagrams between our peer and a str0m viewer until `done`
/// or 30 s of synthetic time; returns the viewer's events.
fn run(
    now: &mut Instant,
    peer: &mut Peer,
    viewer: &mut Rtc,
    events: &mut Vec<Event>,
    mut done: impl FnMut(&Peer, &[Event]) -> bool,
) {
    let end = *now + Duration::from_secs(30);
    while *now < end {
        let mut to_peer: Vec<Datagram> = Vec::new();
        let viewer_next = loop {
            match viewer.poll_output().unwrap() {
                Output::Timeout(t) => break t,
                Output::Transmit(t) => to_peer.push(Datagram {
                    from: t.source,
                    to: t.destination,
                    data: t.contents.into(),
                }),
                Output::Event(e) => events.push(e),
            }
        };
        for d in peer.take_transmits() {
            let r = Receive::new(Protocol::Udp, d.from, d.to, &d.data).unwrap();
            viewer.handle_input(Input::Receive(*now, r)).unwrap();
        }
        for d in to_peer {
            peer.receive(*now, d.from, d.to, &d.data);
        }
        if done(peer, events) {
            return;
        }
        let next = viewer_next.min(peer.next_timeout()).max(*now);
        *now = next
            .min(*now + Duration::from_millis(10))
            .max(*now + Duration::from_micros(100));
        viewer.handle_input(Input::Timeout(*now)).unwrap();
        if peer.next_timeout() <= *now {
            peer.timeout(*now);
        }
    }
}

fn addr(s: &str) -> SocketAddr {
    s.parse().unwrap()
}

#[test]
fn a_viewer_gets_the_pictures_from_its_first_keyframe_on() {
    let mut now = Instant::now();
    let vehicle = Candidate::host(addr("10.0.0.1:5000"), "udp").unwrap();
    let (mut peer, offer) = Peer::offer(now, &[vehicle]).unwrap();
    assert!(offer.contains("profile-level-id=42e01f"), "{offer}");
    assert!(offer.contains("a=sendonly"), "{offer}");
    assert!(offer.contains("10.0.0.1 5000 typ host"), "{offer}");
    // The browser's part: str0m with its default codecs, receiving.
    let mut viewer = Rtc::builder().build(now);
    viewer.add_local_candidate(Candidate::host(addr("10.0.0.2:6000"), "udp").unwrap());
    let answer = viewer
        .sdp_api()
        .accept_offer(SdpOffer::from_sdp_string(&offer).unwrap())
        .unwrap();
    peer.accept_answer(now, &answer.to_sdp_string()).unwrap();
    assert!(
        peer.accept_answer(now, &answer.to_sdp_string()).is_err(),
        "one answer"
    );
    let mut events = Vec::new();
    run(&mut now, &mut peer, &mut viewer, &mut events, |p, _| {
        p.is_connected()
    });
    assert!(peer.is_connected(), "ICE and DTLS through: {events:?}");
    // A P picture first: the viewer could not decode it, it is not sent.
    let pictures = [
        AccessUnit {
            data: annex_b(&[&p_slice(500)]),
            time_90khz: 0,
            keyframe: false,
        },
        AccessUnit {
            data: annex_b(&[SPS, PPS, &idr(4000)]),
            time_90khz: 3000,
            keyframe: true,
        },
        AccessUnit {
            data: annex_b(&[&p_slice(700)]),
            time_90khz: 6000,
            keyframe: false,
        },
        AccessUnit {
            data: annex_b(&[&p_slice(300)]),
            time_90khz: 9000,
            keyframe: false,
        },
    ];
    for au in &pictures {
        let data: Arc<[u8]> = Arc::from(au.data.as_slice());
        peer.send(now, au, &data);
        run(&mut now, &mut peer, &mut viewer, &mut events, |_, _| true);
    }
    run(&mut now, &mut peer, &mut viewer, &mut events, |_, e| {
        e.iter()
            .filter(|e| matches!(e, Event::MediaData(_)))
            .count()
            >= 3
    });
    let got: Vec<_> = events
        .iter()
        .filter_map(|e| match e {
            Event::MediaData(m) => Some(m),
            _ => None,
        })
        .collect();
    assert_eq!(got.len(), 3, "the keyframe and the two after it");
    assert_eq!(peer.frames(), 3);
    for (m, au) in got.iter().zip(&pictures[1..]) {
        assert_eq!(&m.data[..], &au.data[..], "the picture as sent");
    }
    assert!(got[0].is_keyframe());
    assert_eq!(peer.ended(), None);
}

#[test]
fn a_viewer_that_never_connects_is_given_up_with_the_reason() {
    let now = Instant::now();
    let vehicle = Candidate::host(addr("10.0.0.1:5000"), "udp").unwrap();
    let (mut peer, _offer) = Peer::offer(now, &[vehicle]).unwrap();
    let later = now + Duration::from_secs(21);
    assert!(peer.next_timeout() <= later);
    peer.timeout(later);
    assert!(peer.ended().unwrap().contains("no connection within 20 s"));
    // A bad answer or candidate is an error, never a panic.
    let (mut other, _) = Peer::offer(
        now,
        &[Candidate::host(addr("10.0.0.1:5001"), "udp").unwrap()],
    )
    .unwrap();
    assert!(other.accept_answer(now, "not sdp").is_err());
    assert!(other.add_remote_candidate(now, "candidate:x").is_err());
    assert!(
        other
            .add_remote_candidate(now, "candidate:1 1 udp 1 a5b3-1c.local 5000 typ host")
            .is_err()
    );
    assert!(Peer::offer(now, &[]).is_err(), "no address, no offer");
}
