//! MAVLink 2 signing: golden frames signed by pymavlink, the verifier's
//! replay and staleness rules, the signer's timestamps and reservations
//! across a restart, the key and timestamp files, and fuzzing.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;

use mavlink_core::{MAVLinkV1MessageRaw, MavHeader};
use neptunus::dialect::neptunus::{
    COMMAND_LONG_DATA, HEARTBEAT_DATA, MavAutopilot, MavCmd, MavModeFlag, MavState, MavType,
};
use neptunus::mavlink::signing::{
    MAX_STREAMS, MAX_TIMESTAMP, NEW_STREAM_WINDOW, REPLAY_RESERVATION_AHEAD, RESERVATION_AHEAD,
    RESERVATION_MARGIN, ReplayState, Signer, SigningError, SigningKey, SigningStore,
    SigningWarning, Verdict, Verifier, is_signed, timestamp_from_unix_us,
};
use neptunus::mavlink::{FrameDecoder, FrameStats, MavMessage, decode_datagram, encode_v2};
use proptest::prelude::*;

// ---------------------------------------------------------------------------
// golden frames
// ---------------------------------------------------------------------------

// Produced once with pymavlink 2.4.50 (MAVLINK20=1, dialect common):
//   key = hashlib.sha256(b"neptunus golden vector").digest()
//   mav = MAVLink(None, srcSystem=255, srcComponent=190); mav.seq = 42 (43)
//   mav.signing.secret_key = key; mav.signing.sign_outgoing = True
//   mav.signing.link_id = 7; mav.signing.timestamp = TS (TS + 1)
//   MAVLink_heartbeat_message(MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE, 3).pack(mav)
//   MAVLink_command_long_message(1, 1, MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 21196.0, 0, 0, 0, 0, 0).pack(mav)
// and checked to be accepted by pymavlink's own decoder with that key.
// The unsigned frames are the same messages packed without signing.
const GOLDEN_PASSPHRASE: &str = "neptunus golden vector";
const GOLDEN_KEY: [u8; 32] = [
    0x59, 0x3d, 0x7b, 0x56, 0xc6, 0x96, 0xa8, 0x86, 0x73, 0x54, 0x06, 0xb2, 0x31, 0xaa, 0xd0, 0x0d,
    0xf8, 0x27, 0xb5, 0xfb, 0x82, 0x32, 0xe9, 0x36, 0x3b, 0x62, 0x39, 0xce, 0xb6, 0x5f, 0x33, 0xc7,
];
const GOLDEN_KEY_HEX: &str = "593d7b56c696a886735406b231aad00df827b5fb8232e9363b6239ceb65f33c7";
const GOLDEN_LINK_ID: u8 = 7;
/// 2026-01-01T00:00:00Z as a signing timestamp.
const TS: u64 = 34_715_520_000_000;
const UNIX_US_2026: u64 = 1_767_225_600_000_000;

const HEARTBEAT_UNSIGNED: [u8; 21] = [
    0xfd, 0x09, 0x00, 0x00, 0x2a, 0xff, 0xbe, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x06, 0x08,
    0x00, 0x04, 0x03, 0xc9, 0x47,
];
const HEARTBEAT_SIGNED: [u8; 34] = [
    0xfd, 0x09, 0x01, 0x00, 0x2a, 0xff, 0xbe, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x06, 0x08,
    0x00, 0x04, 0x03, 0x2e, 0xbf, 0x07, 0x00, 0xe0, 0x3c, 0xd6, 0x92, 0x1f, 0x17, 0xda, 0xbd, 0x7d,
    0x38, 0x4e,
];
const COMMAND_LONG_UNSIGNED: [u8; 44] = [
    0xfd, 0x20, 0x00, 0x00, 0x2b, 0xff, 0xbe, 0x4c, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x98,
    0xa5, 0x46, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x90, 0x01, 0x01, 0x01, 0x92, 0x3f,
];
const COMMAND_LONG_SIGNED: [u8; 57] = [
    0xfd, 0x20, 0x01, 0x00, 0x2b, 0xff, 0xbe, 0x4c, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x98,
    0xa5, 0x46, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x90, 0x01, 0x01, 0x01, 0x45, 0xa1, 0x07, 0x01, 0xe0, 0x3c,
    0xd6, 0x92, 0x1f, 0xa8, 0x42, 0x6f, 0x4a, 0xce, 0xf7,
];

fn golden_key() -> SigningKey {
    SigningKey::from_bytes(GOLDEN_KEY).unwrap()
}

fn other_key() -> SigningKey {
    SigningKey::from_passphrase("not the golden key")
}

fn golden_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

fn golden_command_long() -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: 1.0,
        param2: 21196.0,
        param3: 0.0,
        param4: 0.0,
        param5: 0.0,
        param6: 0.0,
        param7: 0.0,
        command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        target_system: 1,
        target_component: 1,
        confirmation: 0,
    })
}

/// A frame from (sysid, compid) signed with `key` on `link_id` at exactly `ts`.
fn signed_frame(key: &SigningKey, link_id: u8, sysid: u8, compid: u8, ts: u64) -> Vec<u8> {
    let mut frame = encode_v2(sysid, compid, 0, &golden_heartbeat());
    Signer::new(key.clone(), link_id, None).sign(&mut frame, ts);
    assert!(is_signed(&frame));
    frame
}

fn v1_frame() -> Vec<u8> {
    let mut raw = MAVLinkV1MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: 0,
        },
        &golden_heartbeat(),
    );
    raw.raw_bytes().to_vec()
}

#[test]
fn timestamps_count_10_us_since_2015() {
    assert_eq!(timestamp_from_unix_us(UNIX_US_2026), TS);
    assert_eq!(timestamp_from_unix_us(1_420_070_400_000_000), 0);
    assert_eq!(timestamp_from_unix_us(1_420_070_400_000_010), 1);
    assert_eq!(timestamp_from_unix_us(1_420_070_400_000_019), 1);
    assert_eq!(timestamp_from_unix_us(0), 0, "before 2015 saturates");
    assert_eq!(
        timestamp_from_unix_us(u64::MAX),
        (u64::MAX - 1_420_070_400_000_000) / 10
    );
}

#[test]
fn passphrase_gives_the_same_key_as_qgc_and_mavproxy() {
    // Both take SHA-256 of the UTF-8 passphrase; pymavlink's hashlib gave GOLDEN_KEY.
    assert_eq!(
        SigningKey::from_passphrase(GOLDEN_PASSPHRASE).as_bytes(),
        &GOLDEN_KEY
    );
    assert_ne!(
        SigningKey::from_passphrase("a"),
        SigningKey::from_passphrase("b")
    );
}

#[test]
fn all_zero_key_means_signing_off() {
    assert!(SigningKey::from_bytes([0; 32]).is_none());
    let mut one = [0; 32];
    one[31] = 1;
    assert!(SigningKey::from_bytes(one).is_some());
}

#[test]
fn our_unsigned_encoding_matches_pymavlink() {
    // The signer's input must be the same bytes pymavlink signed.
    assert_eq!(
        encode_v2(255, 190, 42, &golden_heartbeat()),
        HEARTBEAT_UNSIGNED
    );
    assert_eq!(
        encode_v2(255, 190, 43, &golden_command_long()),
        COMMAND_LONG_UNSIGNED
    );
}

#[test]
fn verifier_accepts_frames_signed_by_pymavlink() {
    let mut v = Verifier::new(golden_key());
    assert_eq!(
        v.check(&HEARTBEAT_SIGNED, TS),
        Verdict::Valid {
            link_id: GOLDEN_LINK_ID,
            timestamp: TS
        }
    );
    assert_eq!(
        v.check(&COMMAND_LONG_SIGNED, TS),
        Verdict::Valid {
            link_id: GOLDEN_LINK_ID,
            timestamp: TS + 1
        }
    );
    let mut wrong = Verifier::new(other_key());
    assert_eq!(wrong.check(&HEARTBEAT_SIGNED, TS), Verdict::BadSignature);
}

#[test]
fn signer_produces_the_bytes_pymavlink_produces() {
    let mut s = Signer::new(golden_key(), GOLDEN_LINK_ID, None);
    let mut hb = encode_v2(255, 190, 42, &golden_heartbeat());
    s.sign(&mut hb, TS);
    assert_eq!(hb, HEARTBEAT_SIGNED);
    assert_eq!(s.last_timestamp(), TS);

    // Same clock reading: the timestamp still moves on by one, as pymavlink's does.
    let mut cl = encode_v2(255, 190, 43, &golden_command_long());
    s.sign(&mut cl, TS);
    assert_eq!(cl, COMMAND_LONG_SIGNED);
    assert_eq!(s.last_timestamp(), TS + 1);
}

#[test]
fn our_signed_frames_decode_as_signed() {
    let mut s = Signer::new(golden_key(), GOLDEN_LINK_ID, None);
    let mut hb = encode_v2(255, 190, 42, &golden_heartbeat());
    let mut cl = encode_v2(255, 190, 43, &golden_command_long());
    s.sign(&mut hb, TS);
    s.sign(&mut cl, TS);
    let stream: Vec<u8> = [hb.as_slice(), &cl].concat();

    let mut decoder = FrameDecoder::new();
    let mut frames = Vec::new();
    // Byte by byte, to cross the 13-byte trailer at every position.
    for b in &stream {
        decoder.push(std::slice::from_ref(b), &mut frames);
    }
    assert_eq!(decoder.stats().malformed(), 0);
    assert_eq!(frames.len(), 2);
    assert!(frames.iter().all(|f| f.signed));
    assert_eq!(frames[0].msg, golden_heartbeat());
    assert_eq!(frames[1].msg, golden_command_long());
    assert_eq!(frames[0].raw, hb);
    assert_eq!(frames[1].raw, cl);

    let mut stats = FrameStats::default();
    let mut frames = Vec::new();
    decode_datagram(&stream, &mut stats, &mut frames);
    assert_eq!(stats.malformed(), 0);
    assert_eq!(frames.len(), 2);
    assert!(frames.iter().all(|f| f.signed));
    assert_eq!(frames[1].raw, COMMAND_LONG_SIGNED);
}

// ---------------------------------------------------------------------------
// verifier
// ---------------------------------------------------------------------------

#[test]
fn sign_then_check_is_valid() {
    let key = other_key();
    let mut s = Signer::new(key.clone(), 3, None);
    let mut v = Verifier::new(key);
    for (seq, now) in [(0, TS), (1, TS + 5), (2, TS + 5)] {
        let mut frame = encode_v2(1, 1, seq, &golden_command_long());
        s.sign(&mut frame, now);
        let ts = s.last_timestamp();
        assert_eq!(
            v.check(&frame, now),
            Verdict::Valid {
                link_id: 3,
                timestamp: ts
            }
        );
    }
}

#[test]
fn every_single_bit_flip_is_refused() {
    for frame in [&HEARTBEAT_SIGNED[..], &COMMAND_LONG_SIGNED[..]] {
        for pos in 0..frame.len() {
            for bit in 0..8 {
                let mut bad = frame.to_vec();
                bad[pos] ^= 1 << bit;
                // A fresh verifier each time, so no answer is a replay verdict.
                let verdict = Verifier::new(golden_key()).check(&bad, TS);
                // The magic byte, the length and the signed flag change the
                // frame's shape; everything else is covered by the signature.
                let want = if pos < 2 || (pos == 2 && bit == 0) {
                    Verdict::Malformed
                } else {
                    Verdict::BadSignature
                };
                assert_eq!(verdict, want, "byte {pos} bit {bit}");
            }
        }
    }
}

#[test]
fn the_same_frame_twice_is_a_replay() {
    let mut v = Verifier::new(golden_key());
    assert!(matches!(
        v.check(&HEARTBEAT_SIGNED, TS),
        Verdict::Valid { .. }
    ));
    assert_eq!(v.check(&HEARTBEAT_SIGNED, TS), Verdict::Replayed);
    // An older frame of the same stream, too.
    let older = signed_frame(&golden_key(), GOLDEN_LINK_ID, 255, 190, TS - 1);
    assert_eq!(v.check(&older, TS), Verdict::Replayed);
    // A newer one is fine.
    assert!(matches!(
        v.check(&COMMAND_LONG_SIGNED, TS),
        Verdict::Valid { .. }
    ));
    assert_eq!(v.check(&HEARTBEAT_SIGNED, TS), Verdict::Replayed);
}

#[test]
fn a_new_stream_more_than_a_minute_behind_is_too_old() {
    let key = golden_key();
    let s61 = signed_frame(&key, 0, 1, 1, TS - 6_100_000);
    let s59 = signed_frame(&key, 0, 2, 1, TS - 5_900_000);
    let mut v = Verifier::new(key.clone());
    assert_eq!(v.check(&s61, TS), Verdict::TooOld);
    assert!(matches!(v.check(&s59, TS), Verdict::Valid { .. }));

    // The boundary: exactly a minute behind is still accepted.
    let edge = signed_frame(&key, 0, 3, 1, TS - NEW_STREAM_WINDOW);
    let past = signed_frame(&key, 0, 4, 1, TS - NEW_STREAM_WINDOW - 1);
    assert!(matches!(v.check(&edge, TS), Verdict::Valid { .. }));
    assert_eq!(v.check(&past, TS), Verdict::TooOld);
}

#[test]
fn too_old_is_measured_against_the_newest_valid_timestamp_too() {
    // Our clock may be behind (no RTC on the board): a minute behind the
    // newest frame seen is too old even if it is ahead of our clock.
    let key = golden_key();
    let mut v = Verifier::new(key.clone());
    let newest = signed_frame(&key, 0, 1, 1, TS);
    assert!(matches!(v.check(&newest, 0), Verdict::Valid { .. }));
    let behind = signed_frame(&key, 0, 2, 1, TS - 6_100_000);
    assert_eq!(v.check(&behind, 0), Verdict::TooOld);
}

#[test]
fn streams_are_independent() {
    let key = golden_key();
    let mut v = Verifier::new(key.clone());
    let a_new = signed_frame(&key, 0, 1, 1, TS + 100);
    let b_old = signed_frame(&key, 0, 2, 1, TS);
    let a_link1 = signed_frame(&key, 1, 1, 1, TS);
    let a_comp2 = signed_frame(&key, 0, 1, 2, TS);
    assert!(matches!(v.check(&a_new, TS), Verdict::Valid { .. }));
    // Older than stream A's last, but each is its own stream.
    assert!(matches!(v.check(&b_old, TS), Verdict::Valid { .. }));
    assert!(matches!(v.check(&a_link1, TS), Verdict::Valid { .. }));
    assert!(matches!(v.check(&a_comp2, TS), Verdict::Valid { .. }));
    // And accepting those did not move stream A.
    let a_next = signed_frame(&key, 0, 1, 1, TS + 101);
    assert!(matches!(v.check(&a_next, TS), Verdict::Valid { .. }));
    assert_eq!(v.check(&a_next, TS), Verdict::Replayed);
    assert_eq!(v.stream_count(), 4);
}

#[test]
fn only_valid_frames_change_the_state() {
    let key = golden_key();
    let mut v = Verifier::new(key.clone());
    // A forgery from the far future must not make genuine new streams "too old"…
    let forged = signed_frame(&other_key(), 0, 1, 1, TS + 1_000_000_000);
    assert_eq!(v.check(&forged, TS), Verdict::BadSignature);
    // …nor take the stream's place.
    let genuine = signed_frame(&key, 0, 1, 1, TS);
    assert!(matches!(v.check(&genuine, TS), Verdict::Valid { .. }));

    // A refused stale frame does not create its stream: once the clock is
    // no longer ahead, the same frame is judged afresh.
    let stale = signed_frame(&key, 0, 9, 9, TS - 7_000_000);
    let mut v = Verifier::new(key);
    assert_eq!(v.check(&stale, TS), Verdict::TooOld);
    assert_eq!(v.stream_count(), 0);
    assert!(matches!(
        v.check(&stale, TS - 7_000_000),
        Verdict::Valid { .. }
    ));
}

#[test]
fn unsigned_frames_are_unsigned() {
    let mut v = Verifier::new(golden_key());
    assert_eq!(v.check(&v1_frame(), TS), Verdict::Unsigned);
    assert_eq!(v.check(&HEARTBEAT_UNSIGNED, TS), Verdict::Unsigned);
    assert_eq!(v.check(&COMMAND_LONG_UNSIGNED, TS), Verdict::Unsigned);
    assert!(!is_signed(&HEARTBEAT_UNSIGNED));
    assert!(is_signed(&HEARTBEAT_SIGNED));
}

#[test]
fn anything_but_one_whole_frame_is_malformed() {
    let mut v = Verifier::new(golden_key());
    assert_eq!(v.check(&[], TS), Verdict::Malformed);
    assert_eq!(v.check(&[0xfd], TS), Verdict::Malformed);
    assert_eq!(v.check(&[0x00; 40], TS), Verdict::Malformed);
    assert_eq!(
        v.check(&HEARTBEAT_SIGNED[..HEARTBEAT_SIGNED.len() - 1], TS),
        Verdict::Malformed
    );
    let two = [HEARTBEAT_SIGNED.as_slice(), &COMMAND_LONG_SIGNED].concat();
    assert_eq!(v.check(&two, TS), Verdict::Malformed);
    let v1 = v1_frame();
    assert_eq!(v.check(&v1[..v1.len() - 1], TS), Verdict::Malformed);
}

#[test]
fn replay_state_is_bounded_and_keeps_the_recently_used_streams() {
    let key = golden_key();
    let mut v = Verifier::new(key.clone());
    let stream0 = signed_frame(&key, 0, 0, 0, TS);
    assert!(matches!(v.check(&stream0, TS), Verdict::Valid { .. }));
    let stream1 = signed_frame(&key, 0, 1, 0, TS);
    assert!(matches!(v.check(&stream1, TS), Verdict::Valid { .. }));
    for sysid in 2..MAX_STREAMS {
        let f = signed_frame(&key, 0, sysid as u8, 0, TS);
        assert!(matches!(v.check(&f, TS), Verdict::Valid { .. }));
    }
    assert_eq!(v.stream_count(), MAX_STREAMS);
    // Stream 0 is used again, so stream 1 is now the least recently used.
    let stream0_next = signed_frame(&key, 0, 0, 0, TS + 1);
    assert!(matches!(v.check(&stream0_next, TS), Verdict::Valid { .. }));

    let newcomer = signed_frame(&key, 1, 0, 0, TS);
    assert!(matches!(v.check(&newcomer, TS), Verdict::Valid { .. }));
    assert_eq!(v.stream_count(), MAX_STREAMS);
    // Stream 0 kept its replay state…
    assert_eq!(v.check(&stream0_next, TS), Verdict::Replayed);
    // …while stream 1 was evicted: its last frame now counts as a new stream
    // (and is within the minute, so accepted — the documented cost of the bound).
    assert!(matches!(v.check(&stream1, TS), Verdict::Valid { .. }));
    assert_eq!(v.stream_count(), MAX_STREAMS);
}

// ---------------------------------------------------------------------------
// signer
// ---------------------------------------------------------------------------

fn sign_one(s: &mut Signer, now: u64) -> (Vec<u8>, Option<u64>) {
    let mut frame = encode_v2(1, 1, 0, &golden_heartbeat());
    let r = s.sign(&mut frame, now);
    (frame, r)
}

#[test]
fn timestamps_strictly_increase_when_the_clock_goes_backwards() {
    let mut s = Signer::new(golden_key(), 0, None);
    let mut v = Verifier::new(golden_key());
    let mut last = 0;
    for now in [TS, TS - 500, TS - 500, TS + 10, 0, TS + 10, TS + 9] {
        let (frame, _) = sign_one(&mut s, now);
        let ts = s.last_timestamp();
        assert!(ts > last, "{ts} after {last} (now {now})");
        assert!(ts >= now);
        // The receiving end agrees: nothing is a replay.
        assert_eq!(
            v.check(&frame, TS),
            Verdict::Valid {
                link_id: 0,
                timestamp: ts
            }
        );
        last = ts;
    }
}

#[test]
fn raise_floor_lifts_timestamps_and_never_lowers_them() {
    let mut s = Signer::new(golden_key(), 0, None);
    sign_one(&mut s, TS);
    s.raise_floor(TS + 1_000_000);
    sign_one(&mut s, TS);
    assert_eq!(s.last_timestamp(), TS + 1_000_000);
    s.raise_floor(5);
    sign_one(&mut s, TS);
    assert_eq!(s.last_timestamp(), TS + 1_000_001);
    // A floor below the clock changes nothing.
    sign_one(&mut s, TS + 2_000_000);
    assert_eq!(s.last_timestamp(), TS + 2_000_000);
}

#[test]
fn timestamps_saturate_at_48_bits() {
    let mut s = Signer::new(golden_key(), 0, None);
    s.raise_floor(u64::MAX);
    let (frame, reservation) = sign_one(&mut s, TS);
    assert_eq!(s.last_timestamp(), MAX_TIMESTAMP);
    assert!(reservation.unwrap() >= MAX_TIMESTAMP);
    let mut v = Verifier::new(golden_key());
    assert_eq!(
        v.check(&frame, TS),
        Verdict::Valid {
            link_id: 0,
            timestamp: MAX_TIMESTAMP
        }
    );
}

#[test]
fn reservations_stay_ahead_of_every_timestamp() {
    let mut s = Signer::new(golden_key(), 0, None);
    let (_, first) = sign_one(&mut s, TS);
    assert_eq!(
        first,
        Some(TS + RESERVATION_AHEAD),
        "first sign always reserves"
    );
    let mut reserved = first.unwrap();
    let mut handed_out = 1;
    // Five minutes of 100 Hz traffic, with the clock jumping ahead once.
    for i in 1..30_000u64 {
        let now = if i == 20_000 {
            TS + 900_000_000
        } else {
            TS + i * 1_000
        };
        let (_, r) = sign_one(&mut s, now);
        let ts = s.last_timestamp();
        if let Some(r) = r {
            assert!(r > reserved, "reservations only grow");
            assert!(
                ts + RESERVATION_MARGIN >= reserved,
                "reserved again only near the old one"
            );
            assert_eq!(r, ts + RESERVATION_AHEAD);
            reserved = r;
            handed_out += 1;
        }
        assert!(
            reserved >= ts,
            "timestamp {ts} beyond reservation {reserved}"
        );
    }
    // Roughly one write per 30 s, not one per frame.
    assert!((5..=20).contains(&handed_out), "{handed_out} reservations");
}

#[test]
fn after_a_restart_timestamps_continue_above_everything_used() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(dir.path());
    assert_eq!(store.load_reservation(), None);

    // A SETUP_SIGNING put the timestamps ten minutes ahead of our clock.
    let mut before = Signer::new(golden_key(), 0, store.load_reservation());
    before.raise_floor(TS + 60_000_000);
    let mut used = Vec::new();
    for i in 0..5_000u64 {
        if let Some(r) = sign_one(&mut before, TS + i * 1_000).1 {
            store.save_reservation(r).unwrap();
        }
        used.push(before.last_timestamp());
    }
    let max_used = *used.iter().max().unwrap();

    // Restart with the clock back at (before) the start.
    let mut after = Signer::new(golden_key(), 0, store.load_reservation());
    let (frame, r) = sign_one(&mut after, TS - 100);
    assert!(after.last_timestamp() > max_used);
    assert!(r.unwrap() > after.last_timestamp(), "reserves at once");
    // A ground station that saw all the earlier frames accepts the new one.
    let mut gcs = Verifier::new(golden_key());
    for i in 0..3u64 {
        let mut old = encode_v2(1, 1, 0, &golden_heartbeat());
        Signer::new(golden_key(), 0, None).sign(&mut old, max_used - 2 + i);
        assert!(matches!(gcs.check(&old, TS), Verdict::Valid { .. }));
    }
    assert!(matches!(gcs.check(&frame, TS), Verdict::Valid { .. }));
}

#[test]
fn frames_that_cannot_be_signed_are_left_alone() {
    let mut s = Signer::new(golden_key(), 0, None);
    let untouched = |s: &mut Signer, frame: &[u8]| {
        let mut f = frame.to_vec();
        assert_eq!(s.sign(&mut f, TS), None);
        assert_eq!(f, frame);
    };
    untouched(&mut s, &v1_frame());
    untouched(&mut s, &HEARTBEAT_SIGNED);
    untouched(&mut s, &HEARTBEAT_UNSIGNED[..20]);
    untouched(&mut s, &[]);
    let mut bad_crc = HEARTBEAT_UNSIGNED.to_vec();
    bad_crc[15] ^= 0x40;
    untouched(&mut s, &bad_crc);
    // A message id our dialect does not know: its CRC cannot be recomputed.
    let mut unknown = HEARTBEAT_UNSIGNED.to_vec();
    unknown[9] = 0xee;
    untouched(&mut s, &unknown);
    assert_eq!(s.last_timestamp(), 0, "no timestamp was used");
}

// ---------------------------------------------------------------------------
// files
// ---------------------------------------------------------------------------

fn mode(path: &Path) -> u32 {
    fs::metadata(path).unwrap().permissions().mode() & 0o7777
}

#[test]
fn key_file_roundtrip_is_0600_hex() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(&dir.path().join("data"));
    assert!(store.load_key().unwrap().is_none(), "no file, no key");
    store.save_key(Some(&golden_key())).unwrap();
    let path = dir.path().join("data").join(SigningStore::KEY_FILE);
    assert_eq!(path, store.key_path());
    assert_eq!(mode(&path), 0o600);
    assert_eq!(
        fs::read_to_string(&path).unwrap(),
        format!("{GOLDEN_KEY_HEX}\n")
    );
    let (key, warnings) = store.load_key_checked().unwrap();
    assert_eq!(key, Some(golden_key()));
    assert!(warnings.is_empty());

    // Replacing a key keeps 0600, and leaves no temporary file behind.
    store.save_key(Some(&other_key())).unwrap();
    assert_eq!(mode(&path), 0o600);
    assert_eq!(store.load_key().unwrap(), Some(other_key()));
    let names: Vec<_> = fs::read_dir(dir.path().join("data"))
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, [SigningStore::KEY_FILE]);
}

#[test]
fn saving_none_removes_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(dir.path());
    store.save_key(Some(&golden_key())).unwrap();
    store.save_key(None).unwrap();
    assert!(!store.key_path().exists());
    assert_eq!(store.load_key().unwrap(), None);
    store.save_key(None).unwrap();
}

#[test]
fn key_file_is_0600_even_over_a_world_readable_file_or_leftover() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(dir.path());
    fs::write(store.key_path(), "00\n").unwrap();
    fs::set_permissions(store.key_path(), fs::Permissions::from_mode(0o644)).unwrap();
    let tmp = dir.path().join("signing.key.tmp");
    fs::write(&tmp, "junk").unwrap();
    fs::set_permissions(&tmp, fs::Permissions::from_mode(0o666)).unwrap();
    store.save_key(Some(&golden_key())).unwrap();
    assert_eq!(mode(&store.key_path()), 0o600);
    assert!(!tmp.exists());
}

#[test]
fn a_key_file_others_can_read_loads_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(dir.path());
    store.save_key(Some(&golden_key())).unwrap();
    fs::set_permissions(store.key_path(), fs::Permissions::from_mode(0o640)).unwrap();
    let (key, warnings) = store.load_key_checked().unwrap();
    assert_eq!(key, Some(golden_key()));
    assert_eq!(
        warnings,
        [SigningWarning::KeyFileExposed {
            path: store.key_path(),
            mode: 0o640
        }]
    );
    let text = warnings[0].to_string();
    assert!(
        text.contains(&store.key_path().display().to_string()),
        "{text}"
    );
    assert!(text.contains("chmod 600"), "{text}");
    assert!(!text.contains(GOLDEN_KEY_HEX), "{text}");
}

#[test]
fn a_corrupt_key_file_is_an_error_that_names_the_file_and_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(dir.path());
    let almost = &GOLDEN_KEY_HEX[..62];
    for content in [
        String::new(),
        format!("{almost}\n"),
        format!("{GOLDEN_KEY_HEX}00\n"),
        format!("{almost}xy\n"),
        "ü".repeat(32),
        "a".repeat(10_000),
    ] {
        fs::write(store.key_path(), &content).unwrap();
        let err = store.load_key().unwrap_err();
        let msg = err.to_string();
        assert!(
            matches!(
                err,
                SigningError::BadKeyFile { .. } | SigningError::Read { .. }
            ),
            "{err:?}"
        );
        assert!(
            msg.contains(&store.key_path().display().to_string()),
            "{msg}"
        );
        assert!(msg.contains("remove"), "{msg}");
        assert!(
            !msg.contains(almost),
            "the message quotes the key file: {msg}"
        );
    }
    fs::write(store.key_path(), format!("{almost}xy\n")).unwrap();
    let msg = store.load_key().unwrap_err().to_string();
    assert!(msg.contains("64 hex digits"), "{msg}");
    assert!(msg.contains("signing set-passphrase"), "{msg}");
}

#[test]
fn key_files_in_other_hands_still_load() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(dir.path());
    // Upper case, no newline, surrounding spaces: written by hand.
    fs::write(
        store.key_path(),
        format!("  {}  ", GOLDEN_KEY_HEX.to_uppercase()),
    )
    .unwrap();
    fs::set_permissions(store.key_path(), fs::Permissions::from_mode(0o600)).unwrap();
    assert_eq!(store.load_key().unwrap(), Some(golden_key()));
    // The all-zero key is "signing off", as over SETUP_SIGNING.
    fs::write(store.key_path(), format!("{}\n", "0".repeat(64))).unwrap();
    assert_eq!(store.load_key().unwrap(), None);
}

#[test]
fn a_write_error_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let not_a_dir = dir.path().join("file");
    fs::write(&not_a_dir, "").unwrap();
    let store = SigningStore::new(&not_a_dir);
    let msg = store.save_key(Some(&golden_key())).unwrap_err().to_string();
    assert!(msg.contains(&not_a_dir.display().to_string()), "{msg}");
    assert!(msg.contains("--data-dir"), "{msg}");
    let msg = store.save_reservation(1).unwrap_err().to_string();
    assert!(msg.contains(&not_a_dir.display().to_string()), "{msg}");
}

#[test]
fn debug_never_shows_the_key() {
    let key = golden_key();
    assert_eq!(format!("{key:?}"), "SigningKey(<redacted>)");
    for text in [
        format!("{key:?}"),
        format!("{key:#?}"),
        format!("{:?}", Some(&key)),
        format!("{:?}", Verifier::new(key.clone())),
        format!("{:?}", Signer::new(key.clone(), 0, None)),
    ] {
        assert!(!text.contains(GOLDEN_KEY_HEX), "{text}");
        assert!(!text.contains("593d"), "{text}");
        assert!(!text.contains("89, 61"), "{text}"); // decimal bytes
    }
}

#[test]
fn reservation_file_roundtrip() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(dir.path());
    assert_eq!(store.load_reservation(), None);
    store.save_reservation(TS).unwrap();
    assert_eq!(
        fs::read_to_string(store.timestamp_path()).unwrap(),
        format!("{TS}\n")
    );
    assert_eq!(store.load_reservation(), Some(TS));
    store.save_reservation(u64::MAX).unwrap();
    assert_eq!(store.load_reservation(), Some(u64::MAX));
    fs::write(store.timestamp_path(), "soon\n").unwrap();
    assert_eq!(
        store.load_reservation(),
        None,
        "a corrupt file is no reservation"
    );
}

// ---------------------------------------------------------------------------
// replay state across restarts
// ---------------------------------------------------------------------------

/// Checks `frame`, persisting (into `persisted`) whatever reservation it asks
/// for before acting on it, as the vehicle does.
fn accept(v: &mut Verifier, frame: &[u8], persisted: &mut ReplayState) -> Verdict {
    let verdict = v.check(frame, TS);
    if let Some(state) = v.take_reservation() {
        *persisted = state;
    }
    verdict
}

#[test]
fn frames_accepted_before_a_restart_are_refused_after_it_even_after_a_crash() {
    let key = golden_key();
    let mut persisted = ReplayState::default();
    let mut v = Verifier::new(key.clone());
    let mut recorded = Vec::new();
    for i in 0..50 {
        let frame = signed_frame(&key, 0, 255, 190, TS + i * 20_000); // 200 ms apart
        assert!(matches!(
            accept(&mut v, &frame, &mut persisted),
            Verdict::Valid { .. }
        ));
        recorded.push(frame);
    }
    // Crash: only what was persisted on the way survives.
    let mut after = Verifier::with_replay_state(key.clone(), &persisted);
    for frame in &recorded {
        assert_eq!(after.check(frame, TS), Verdict::Replayed);
    }
    // The station's next frames pass once its clock is past the reservation.
    let reserved = persisted.streams[&(0, 255, 190)];
    let last = TS + 49 * 20_000;
    assert!(reserved >= last && reserved <= last + REPLAY_RESERVATION_AHEAD);
    assert_eq!(
        after.check(&signed_frame(&key, 0, 255, 190, reserved), TS),
        Verdict::Replayed
    );
    assert!(matches!(
        after.check(&signed_frame(&key, 0, 255, 190, reserved + 1), TS),
        Verdict::Valid { .. }
    ));

    // A graceful stop persists the exact last timestamps: nothing genuine is refused.
    let clean = Verifier::with_replay_state(key.clone(), &v.replay_state());
    let mut clean = clean;
    assert_eq!(clean.check(&recorded[49], TS), Verdict::Replayed);
    assert!(matches!(
        clean.check(&signed_frame(&key, 0, 255, 190, last + 1), TS),
        Verdict::Valid { .. }
    ));
}

#[test]
fn reservations_are_written_once_per_margin_and_always_cover_every_accepted_frame() {
    let key = golden_key();
    let mut v = Verifier::new(key.clone());
    let mut persisted = ReplayState::default();
    let mut writes = 0;
    // Two stations, 10 Hz each, for 60 s of their clocks.
    for i in 0..600u64 {
        for (sysid, offset) in [(255u8, 0u64), (254, 3_333)] {
            let ts = TS + i * 10_000 + offset;
            let frame = signed_frame(&key, 0, sysid, 190, ts);
            assert!(matches!(v.check(&frame, TS), Verdict::Valid { .. }));
            if let Some(state) = v.take_reservation() {
                writes += 1;
                persisted = state;
            }
            assert!(
                persisted.streams[&(0, sysid, 190)] >= ts,
                "accepted a frame beyond what is on disk"
            );
        }
    }
    // 60 s at one write per margin (5 s), shared by both streams, plus the first.
    assert!(
        writes <= 2 + 60 * 100_000 / REPLAY_RESERVATION_AHEAD as usize * 2,
        "{writes} writes"
    );
    assert!(
        writes >= 60 * 100_000 / REPLAY_RESERVATION_AHEAD as usize / 2,
        "{writes} writes"
    );
}

#[test]
fn a_restored_verifier_measures_new_streams_against_the_persisted_newest() {
    let key = golden_key();
    let mut state = ReplayState::default();
    state.streams.insert((0, 255, 190), TS);
    let mut v = Verifier::with_replay_state(key.clone(), &state);
    // A stream never seen, recorded 2 min before the newest persisted frame.
    let old = signed_frame(&key, 0, 250, 190, TS - 2 * NEW_STREAM_WINDOW);
    assert_eq!(v.check(&old, 0), Verdict::TooOld);
    // Other streams are untouched by the restored one.
    assert!(matches!(
        v.check(&signed_frame(&key, 1, 255, 190, TS - 10), 0),
        Verdict::Valid { .. }
    ));
}

#[test]
fn replay_file_roundtrip_and_corruption() {
    let dir = tempfile::tempdir().unwrap();
    let store = SigningStore::new(dir.path());
    assert_eq!(store.load_replay().unwrap(), None);
    let mut state = ReplayState::default();
    state.streams.insert((0, 255, 190), TS);
    state.streams.insert((3, 1, 1), MAX_TIMESTAMP);
    store.save_replay(&state).unwrap();
    assert_eq!(store.load_replay().unwrap(), Some(state));

    for bad in [
        "0 255 190 12\n",
        "# neptunus signing replay state v1: link_id sysid compid timestamp\n0 255 190\n",
        "# neptunus signing replay state v1: link_id sysid compid timestamp\n0 256 190 1\n",
        "# neptunus signing replay state v1: link_id sysid compid timestamp\n0 255 190 281474976710656\n",
    ] {
        fs::write(store.replay_path(), bad).unwrap();
        let err = store.load_replay().expect_err(bad).to_string();
        assert!(err.contains("signing.replay"), "{err}");
    }
    fs::write(store.replay_path(), vec![b'0'; 20_000]).unwrap();
    assert!(store.load_replay().is_err(), "an oversized file is refused");
}

// ---------------------------------------------------------------------------
// fuzzing
// ---------------------------------------------------------------------------

proptest! {
    #[test]
    fn check_never_panics_on_any_bytes(
        bytes in proptest::collection::vec(any::<u8>(), 0..300),
        now in any::<u64>(),
    ) {
        let mut v = Verifier::new(golden_key());
        let verdict = v.check(&bytes, now);
        prop_assert!(!matches!(verdict, Verdict::Valid { .. }), "{:?}", verdict);
    }

    #[test]
    fn check_never_panics_on_a_mutated_signed_frame(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in proptest::option::of(any::<prop::sample::Index>()),
        extra in proptest::collection::vec(any::<u8>(), 0..4),
        now in any::<u64>(),
    ) {
        let mut frame = COMMAND_LONG_SIGNED.to_vec();
        for (at, x) in &edits {
            let i = at.index(frame.len());
            frame[i] ^= x;
        }
        if let Some(cut) = cut {
            frame.truncate(cut.index(frame.len()));
        }
        frame.extend_from_slice(&extra);
        let mut v = Verifier::new(golden_key());
        let verdict = v.check(&frame, now);
        if frame != COMMAND_LONG_SIGNED {
            prop_assert!(!matches!(verdict, Verdict::Valid { .. }), "{:?}", verdict);
        }
    }

    #[test]
    fn sign_either_leaves_bytes_alone_or_makes_a_valid_frame(
        bytes in prop_oneof![
            proptest::collection::vec(any::<u8>(), 0..300),
            (any::<u8>(), any::<u8>(), any::<u8>(), any::<f32>())
                .prop_map(|(sysid, compid, seq, p1)| {
                    let mut msg = golden_command_long();
                    if let MavMessage::COMMAND_LONG(data) = &mut msg {
                        data.param1 = p1;
                    }
                    encode_v2(sysid, compid, seq, &msg)
                }),
        ],
        now in 0..MAX_TIMESTAMP,
    ) {
        let mut s = Signer::new(golden_key(), 5, None);
        let mut frame = bytes.clone();
        let reservation = s.sign(&mut frame, now);
        if frame == bytes {
            prop_assert_eq!(reservation, None);
        } else {
            prop_assert!(reservation.is_some());
            let mut v = Verifier::new(golden_key());
            prop_assert_eq!(v.check(&frame, now), Verdict::Valid { link_id: 5, timestamp: now.max(1) });
        }
    }
}
