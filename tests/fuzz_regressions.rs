//! Inputs the fuzz targets (`fuzz/`) found, each kept as a test of the
//! property it broke, after the parser was fixed. The guide's Tests
//! chapter ("Fuzzing") says how a new one is added.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use neptunus::camera::h264::depay::Depay;
use neptunus::camera::{JpegFrame, JpegSplitter, SplitterStats};
use neptunus::dialect::neptunus::MavMessage;
use neptunus::firmware::codec::{Event, LineDecoder};
use neptunus::hmi::auth::parse_origin;
use neptunus::hmi::m2r::frame::{self, Reserved};

fn hex(s: &str) -> Vec<u8> {
    let s: String = s.split_whitespace().collect();
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn split(max: usize, stream: &[u8], chunk: usize) -> (Vec<JpegFrame>, SplitterStats, usize) {
    let mut s = JpegSplitter::with_max_frame_bytes(max);
    let mut frames = Vec::new();
    let mut held = 0;
    for piece in stream.chunks(chunk) {
        s.push(piece);
        while let Some(f) = s.next_frame() {
            frames.push(f);
        }
        held = held.max(s.buffered());
    }
    (frames, s.stats(), held)
}

/// `mjpeg_split`: a frame whose scan ran past the size limit was dropped
/// only when the next bytes came, so what the splitter held, and what it
/// had dropped, depended on how the stream was cut (here: 176 bytes held
/// with a limit of 144 when the stream came in one piece, the frame
/// dropped at once when it came a byte at a time).
#[test]
fn a_frame_over_the_limit_is_dropped_however_the_stream_is_cut() {
    let stream = hex(
        "b82b f60d 2600 0a0d ff00 0000 0000 0000 0000 0000 000b ffd8 ffff 01ff 0bff
         d8ff ff01 ffda 000b ffd8 ffff 00ff ffff ffff ffff ffff ffff ffff ffff ffff
         ffff ffff ffff ffff ffff ffff ff00 00ff ffff ffff ffff ffff ffff ffff ffff
         ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff
         ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff
         ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff ffff 0001 0000 0000 00fb",
    );
    let max = 9 * 16;
    let whole = split(max, &stream, stream.len());
    for chunk in [1, 2, 7, 64] {
        let cut = split(max, &stream, chunk);
        assert_eq!((&cut.0, cut.1), (&whole.0, whole.1), "chunk {chunk}");
        assert!(cut.2 <= max + 1, "{} bytes held, chunk {chunk}", cut.2);
    }
    assert!(whole.2 <= max + 1, "{} bytes held", whole.2);
    assert_eq!(whole.1.frames, 0);
}

/// An RTP packet of payload type 96 from SSRC 7.
fn rtp(seq: u16, ts: u32, marker: bool, payload: &[u8]) -> Vec<u8> {
    let mut p = vec![0x80, if marker { 0xe0 } else { 0x60 }];
    p.extend(seq.to_be_bytes());
    p.extend(ts.to_be_bytes());
    p.extend(7u32.to_be_bytes());
    p.extend(payload);
    p
}

/// `rtp_depay` (and the property `a_lost_rtp_packet_spoils_its_picture…`
/// in `tests/round_trips_media.rs`): when the packet lost was the first of
/// a picture (a slice, or the SPS and PPS before an IDR), the packets after
/// it were taken as a new picture, and a keyframe missing its start went
/// to the viewers as a whole one.
#[test]
fn a_picture_that_lost_its_first_packet_does_not_come_out() {
    let p_slice = [0x41, 0x9a, 0x02, 0x04];
    let idr = [0x65, 0x88, 0x84, 0x21];
    let mut d = Depay::new();
    assert_eq!(d.push(&rtp(10, 0, true, &idr)).len(), 1);
    // Picture 3000: a slice (seq 11, lost), then the IDR slice with the marker.
    assert!(
        d.push(&rtp(12, 3000, true, &idr)).is_empty(),
        "a truncated keyframe came out"
    );
    assert_eq!(d.stats().lost, 1);
    // The next whole keyframe comes out.
    let next = d.push(&rtp(13, 6000, true, &idr)).pop().unwrap();
    assert!(next.keyframe);
    assert_eq!(next.data, [&[0, 0, 0, 1][..], &idr].concat());
    // The same when the SPS went missing before an IDR in FU-A fragments.
    let sps = [0x67, 0x42, 0xc0, 0x1e];
    assert!(d.push(&rtp(14, 9000, false, &sps)).is_empty());
    // 15 (the first fragment) is lost.
    assert!(d.push(&rtp(16, 9000, true, &[0x7c, 0x45, 0x21])).is_empty());
    assert_eq!(d.stats().lost, 2);
    // A P picture that lost its first slice, after which all is well again.
    assert_eq!(d.push(&rtp(17, 12000, true, &idr)).len(), 1);
    assert!(d.push(&rtp(19, 15000, true, &p_slice)).is_empty());
    assert_eq!(d.push(&rtp(20, 18000, true, &idr)).len(), 1);
}

/// The other side of the same rule: a single lost packet that was the last
/// of an unfinished picture spoils that picture only; the next, whole from
/// its first packet, comes out.
#[test]
fn a_picture_after_a_lost_last_packet_comes_out() {
    let idr = [0x65, 0x88, 0x84, 0x21];
    let mut d = Depay::new();
    assert_eq!(d.push(&rtp(100, 0, true, &idr)).len(), 1);
    assert!(d.push(&rtp(101, 3000, false, &[0x41, 0x9a])).is_empty());
    // 102, the marker of picture 3000, is lost; 103 starts picture 6000.
    let k = d.push(&rtp(103, 6000, true, &idr)).pop().unwrap();
    assert!(k.keyframe);
    assert_eq!(d.stats().lost, 1);
}

/// `m2r_json`: a client's number parsed to a float 1 ulp away from the one
/// it wrote (serde_json's default number parsing), so a message written as
/// JSON did not read back the same (WHEEL_DISTANCE's `distance` here).
#[test]
fn a_float_from_a_client_is_the_one_it_wrote() {
    let text = r#"{"header":{"system_id":1,"component_id":37,"sequence":91},"message":{"type":"WHEEL_DISTANCE","time_usec":7222205907298057839,"distance":[6.783400123444753e-300,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0,0.0],"count":0}}"#;
    let f = frame::parse(text, Reserved::vehicle(200)).unwrap();
    let MavMessage::WHEEL_DISTANCE(w) = &f.message else {
        panic!("not a WHEEL_DISTANCE");
    };
    assert_eq!(w.distance[0], 6.783400123444753e-300);
    let json = frame::message_json(&f.message).unwrap();
    let again = frame::parse(&frame::frame_json(f.header, &json), Reserved::vehicle(200)).unwrap();
    assert_eq!(again, f);
}

/// `http_gate`: an allowed origin ending in a control character and a
/// slash (`https://x\v/`) parsed to a "normal form" that parsed to another
/// one; an origin holds no space nor control character, so it is refused.
#[test]
fn an_origin_with_a_control_character_is_refused() {
    for bad in [
        "https://x\u{b}/",
        "https://ippp\u{1a}pp\0i",
        "http://top side:8080",
    ] {
        assert!(parse_origin(bad).is_err(), "{bad:?}");
    }
    let o = parse_origin(" HTTPS://Topside.local:8443/ ").unwrap();
    assert_eq!(o, "https://topside.local:8443");
    assert_eq!(parse_origin(&o), Ok(o.clone()));
}

/// `telemetry_lines`: a line that named a tube's current again and again
/// (`BT1I:5` ten times among lines run together) summed every copy — 50 A,
/// past the two tubes' 40 — where a key twice is otherwise the last.
/// The first byte is the target's chunk size.
#[test]
fn a_tubes_current_repeated_on_a_line_stays_in_range() {
    let input = hex(
        "0100 ffff 3b76 6972 3a32 2e35 2e31 2d61 6263 3b42 5244 543a 3230 3b42 5431 493a 353b 4254
         3231 3a30 2c31 3530 303b 7669 723a 322e 352e 312d 6162 6336 4252 4454 6674 6872 3a30 2e30
         303b 0d0a 2e35 2e31 2d61 6263 3642 5244 543a 3235 2e30 3b42 5431 493a 353b 4254 3a32 352e
         303b 4254 3149 3a35 2e30 3b42 5431 493a 353b 4254 3231 3a30 2c31 3530 303b 7669 723a 322e
         352e 312d 6162 6336 4252 4454 3a32 352e 303b 5431 493a 353b 4254 3231 3a30 2c31 3530 303b
         7669 723a 322e 352e 312d 6162 6336 4252 4454 3a32 352e 303b 4254 3149 3a35 3b42 5442 543a
         3235 2e30 3b42 5431 493a 352e 303b 4254 3149 3a35 3b42 5431 493a 353b 4254 4254 3a32 352e
         303b 4254 3149 3a35 2e30 3b42 5431 493a 353b 6254 3231 3a30 2c31 3530 303b 7669 723a 322e
         352e 312d 6162 6336 4252 4454 3a32 353a 3235 2e30 3b42 5431 493a 353b 4254 3231 3a30 2e37
         3b0d 0a",
    );
    let stream = &input[1..];
    let mut d = LineDecoder::new();
    let mut events = Vec::new();
    d.push(stream, &mut events);
    let currents: Vec<f64> = events
        .iter()
        .filter_map(|e| match e {
            Event::Status(s) => s.battery_current_a,
            _ => None,
        })
        .collect();
    assert!(!currents.is_empty(), "{events:?}");
    for a in currents {
        assert!(
            (0.0..=40.0).contains(&a),
            "battery current {a} A from two tubes of 20 A"
        );
    }
}
