//! Fuzzes mavlink2rest's JSON (the Cockpit API): a client's frame, and
//! every message of the dialect as the vehicle writes it.
//!
//! First byte even: the rest is a client's text (a WebSocket frame or a
//! POST body). Never a panic; a frame that converts does not speak as the
//! vehicle, as the broadcast address or as an HMI session; written back as
//! the vehicle writes frames it parses to the same message (floats that
//! JSON cannot hold, which only a number out of `f32`'s range gives, are
//! written as `null` and are the one exception); and it makes a MAVLink 2
//! frame that decodes to the same message.
//!
//! First byte odd: the next two bytes pick a message of the dialect and the
//! rest is its MAVLink payload. A message that decodes is written as JSON,
//! which parses back to the same message (unless it holds a NaN or an
//! infinity, written `null`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use mavlink_core::{MavlinkVersion, Message as _};
use neptunus::dialect::neptunus::MavMessage;
use neptunus::hmi::m2r::frame::{self, ClientFrame, Header, Reserved};
use neptunus::mavlink::{FrameStats, decode_datagram, encode_v2};

/// The message's MAVLink 2 payload: compared instead of the message, as a
/// float field may be NaN and NaN != NaN.
fn payload(msg: &MavMessage) -> Vec<u8> {
    encode_v2(255, 190, 0, msg)
}

/// JSON written from the message parses back to it, or holds a `null`.
fn json_round_trip(header: Header, msg: &MavMessage) {
    let json = frame::message_json(msg).expect("every message serialises");
    let text = frame::frame_json(header, &json);
    let wide_open = Reserved {
        vehicle_sysid: 0,
        hmi_sysids: (1, 0),
    };
    match frame::parse(&text, wide_open) {
        Ok(ClientFrame { header: h, message }) => {
            assert_eq!(h, header);
            assert_eq!(
                payload(&message),
                payload(msg),
                "changed on the way back: {text}"
            );
        }
        Err(e) => assert!(json.contains("null"), "{e}: {text}"),
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    if mode & 1 == 0 {
        let reserved = Reserved {
            vehicle_sysid: 1 + (mode >> 1) % 8,
            hmi_sysids: (200, 209),
        };
        let text = String::from_utf8_lossy(rest);
        let Ok(f) = frame::parse(&text, reserved) else {
            return;
        };
        let s = f.header.system_id;
        assert!(s != 0 && s != reserved.vehicle_sysid && !(200..=209).contains(&s));
        json_round_trip(f.header, &f.message);
        // What the station hands to the vehicle core, as a frame.
        let raw = encode_v2(s, f.header.component_id, f.header.sequence, &f.message);
        let mut stats = FrameStats::default();
        let mut frames = Vec::new();
        decode_datagram(&raw, &mut stats, &mut frames);
        assert_eq!(frames.len(), 1, "{stats:?} for {text}");
        assert_eq!(frames[0].msg_id, f.message.message_id());
        assert_eq!(payload(&frames[0].msg), payload(&f.message));
    } else {
        let Some((&[hi, lo], body)) = rest.split_first_chunk::<2>() else {
            return;
        };
        let all = MavMessage::all_messages();
        let &(_, id) = &all[usize::from(u16::from_be_bytes([hi, lo])) % all.len()];
        let Ok(msg) = MavMessage::parse(MavlinkVersion::V2, id, body) else {
            return;
        };
        let header = Header {
            system_id: 1,
            component_id: mode,
            sequence: hi,
        };
        json_round_trip(header, &msg);
    }
});
