//! Safe to put on a network, in the vehicle core with synthetic time: what a
//! stranger on the owner's link (unsigned, sysid 77, not allowed) can and
//! cannot do to what others see, and how parameters are kept — saved when
//! they change, never behind the station's back.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::time::Duration;

use common::core_rig::{
    BoardFeed, CoreRig, ack_of, count_reaching, msgs, saves, sends, sent, texts_to,
};
use common::statustext;
use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::StatusSample;
use neptunus::vehicle::machine::{Identity, Input, Output, Sender, To, Vehicle};
use neptunus::vehicle::params::ParamStore;

/// The owner's ground station (QGC-like, SYSID_MYGCS) on endpoint 0.
const OWNER: Sender = Sender::new(0, 1, 255, 190);
/// A stranger on the same UDP endpoint: unsigned, sysid not allowed.
const STRANGER: Sender = Sender::new(0, 9, 77, 190);
/// An allowed station (MAVSDK's 245) on the same endpoint.
const MAVSDK: Sender = Sender::new(0, 3, 245, 190);

/// What the board reports here: level at 1 m, 12 V, with its uptime.
fn feed() -> BoardFeed {
    BoardFeed {
        status: StatusSample {
            vout_v: Some(12.0),
            iout_a: Some(0.3),
            battery_current_a: Some(0.3),
            pres_mbar: Some(1100.0),
            temp_c: Some(15.0),
            ..Default::default()
        },
        uptime: true,
        ..BoardFeed::level_at_1_m()
    }
}

/// Two endpoints, `params`; the owner's heartbeat at 1 Hz; started.
fn rig_with(params: ParamStore) -> CoreRig {
    CoreRig::new(Vehicle::new(Identity::Ardupilot, params, 2))
        .feed(feed())
        .alive(OWNER)
        .started()
}

fn rig() -> CoreRig {
    rig_with(ParamStore::defaults())
}

const HEARTBEAT: f32 = 0.0;
const ATTITUDE: f32 = 30.0;

// ---- H2: nobody changes what others see --------------------------------

#[test]
fn a_stranger_can_neither_silence_nor_flood_the_owners_telemetry() {
    let mut r = rig();
    use MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL as SET;
    // Silence: HEARTBEAT and ATTITUDE off.
    for id in [HEARTBEAT, ATTITUDE] {
        let out = r.cmd(STRANGER, SET, &[id, -1.0]);
        assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_DENIED, "msg {id}");
    }
    // Flood: every streamable message at 1000 Hz.
    for (id, _) in neptunus::vehicle::telemetry::STREAMABLE {
        let out = r.cmd(STRANGER, SET, &[*id as f32, 1000.0]);
        assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_DENIED, "msg {id}");
    }
    // The legacy way, which has no ack: off, and 1000 Hz.
    for (rate, start) in [(1000, 0), (1000, 1)] {
        r.msg(
            STRANGER,
            MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
                req_message_rate: rate,
                target_system: 1,
                target_component: 1,
                req_stream_id: MavDataStream::MAV_DATA_STREAM_ALL,
                start_stop: start,
            }),
        );
    }
    let streamable = neptunus::vehicle::telemetry::STREAMABLE.len() as u64;
    assert_eq!(r.v.refused_rate_requests(), 2 + streamable + 2);
    let out = r.run(Duration::from_secs(5));
    let hb = count_reaching(&out, 0, OWNER);
    let att = count_reaching(&out, 30, OWNER);
    assert!((5..=6).contains(&hb), "owner's HEARTBEAT in 5 s: {hb}");
    assert!((49..=51).contains(&att), "owner's ATTITUDE in 5 s: {att}");
    // The owner's own request still works (it may control).
    let out = r.cmd(OWNER, SET, &[ATTITUDE, 50_000.0]);
    assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_ACCEPTED);
    let att = count_reaching(&r.run(Duration::from_secs(5)), 30, OWNER);
    assert!((99..=101).contains(&att), "20 Hz asked by the owner: {att}");
}

#[test]
fn with_signing_on_an_unsigned_allowed_id_only_watches() {
    let mut r = rig();
    r.v.set_signing_active(true);
    let unsigned_255 = Sender::new(0, 5, 255, 190);
    let out = r.cmd(
        unsigned_255,
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        &[HEARTBEAT, -1.0],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL),
        MavResult::MAV_RESULT_DENIED
    );
    let signed = Sender {
        signed: true,
        ..OWNER
    };
    let out = r.cmd(
        signed,
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        &[ATTITUDE, 100_000.0],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL),
        MavResult::MAV_RESULT_ACCEPTED
    );
}

#[test]
fn one_shot_requests_stay_open_to_watchers_and_answer_only_them() {
    let mut r = rig();
    let out = r.cmd(STRANGER, MavCmd::MAV_CMD_REQUEST_MESSAGE, &[148.0]);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_MESSAGE),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let out = r.cmd(STRANGER, MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL, &[ATTITUDE]);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(
        sent(&out)
            .iter()
            .all(|(to, _)| *to == To::Peer(STRANGER.endpoint, STRANGER.peer)),
        "{out:?}"
    );
}

#[test]
fn rates_are_capped_at_50_hz_and_heartbeat_never_below_1_hz_even_for_the_owner() {
    let mut r = rig();
    use MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL as SET;
    let out = r.cmd(MAVSDK, SET, &[ATTITUDE, 1000.0]);
    assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_ACCEPTED);
    let att = count_reaching(&r.run(Duration::from_secs(2)), 30, OWNER);
    assert!(
        (99..=101).contains(&att),
        "1000 Hz asked, 50 Hz given: {att}"
    );
    // REQUEST_DATA_STREAM at 65535 Hz: the same cap.
    r.msg(
        OWNER,
        MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
            req_message_rate: u16::MAX,
            target_system: 1,
            target_component: 1,
            req_stream_id: MavDataStream::MAV_DATA_STREAM_EXTRA2,
            start_stop: 1,
        }),
    );
    let hud = count_reaching(&r.run(Duration::from_secs(2)), 74, OWNER);
    assert!((99..=101).contains(&hud), "VFR_HUD capped at 50 Hz: {hud}");
    // HEARTBEAT cannot be turned off, nor slowed below 1 Hz.
    let out = r.cmd(OWNER, SET, &[HEARTBEAT, -1.0]);
    assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_DENIED);
    let out = r.cmd(OWNER, SET, &[HEARTBEAT, 10_000_000.0]);
    assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_ACCEPTED);
    let hb = count_reaching(&r.run(Duration::from_secs(5)), 0, OWNER);
    assert!((5..=6).contains(&hb), "HEARTBEAT stays at 1 Hz: {hb}");
    let out = r.cmd(OWNER, MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL, &[HEARTBEAT]);
    let iv = sent(&out)
        .into_iter()
        .find_map(|(_, m)| match m {
            MavMessage::MESSAGE_INTERVAL(i) => Some(i.interval_us),
            _ => None,
        })
        .unwrap();
    assert_eq!(iv, 1_000_000, "GET_MESSAGE_INTERVAL tells the truth");
    // Other messages may still be turned off by an allowed station.
    let out = r.cmd(OWNER, SET, &[ATTITUDE, -1.0]);
    assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(count_reaching(&r.run(Duration::from_secs(1)), 30, OWNER), 0);
}

// ---- M1: replies to bad requests go to the asker, rate-limited ----------

#[test]
fn a_flood_of_unknown_param_sets_reaches_only_the_stranger_and_only_a_few() {
    let mut r = rig();
    let mut out = Vec::new();
    // 5,000 in 0.6 s, as in the attack report.
    for i in 0..5000u32 {
        r.t += Duration::from_micros(120);
        out.extend(r.param_set(
            STRANGER,
            &format!("NOPE_{i}"),
            1.0,
            MavParamType::MAV_PARAM_TYPE_REAL32,
        ));
    }
    let owner_texts = texts_to(&out, OWNER);
    assert!(owner_texts.is_empty(), "the owner saw {owner_texts:?}");
    let to_stranger = texts_to(&out, STRANGER);
    assert_eq!(to_stranger.len(), 1, "{to_stranger:?}");
    assert!(to_stranger[0].contains("no such parameter"));
    // And a refused PARAM_SET of a real parameter: the unchanged value and
    // the reason to the stranger alone, nothing to anyone else.
    let mut out = Vec::new();
    for _ in 0..3000 {
        r.t += Duration::from_millis(1);
        out.extend(r.param_set(
            STRANGER,
            "FS_GCS_ENABLE",
            0.0,
            MavParamType::MAV_PARAM_TYPE_INT8,
        ));
    }
    assert!(texts_to(&out, OWNER).is_empty());
    let n = texts_to(&out, STRANGER).len();
    assert!((3..=4).contains(&n), "one per second over 3 s: {n}");
    assert!(
        sends!(&out, PARAM_VALUE)
            .iter()
            .all(|(to, v)| *to == To::Peer(0, STRANGER.peer) && v.param_value == 2.0)
    );
    assert_eq!(r.v.params().get("FS_GCS_ENABLE"), Some(2.0));
}

#[test]
fn refused_commands_and_control_requests_answer_the_asker_alone() {
    let mut r = rig();
    let mut out = Vec::new();
    for _ in 0..1000 {
        r.t += Duration::from_millis(1);
        out.extend(r.cmd(STRANGER, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]));
        out.extend(r.cmd(STRANGER, MavCmd::MAV_CMD_DO_SET_MODE, &[1.0, 2.0]));
        out.extend(r.cmd(
            STRANGER,
            MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
            &[1.0, 0.0, 10.0],
        ));
        out.extend(r.cmd(
            STRANGER,
            MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
            &[1.0, 0.0, 10.0, 200.0],
        ));
        out.extend(r.msg(
            STRANGER,
            MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
                initial_timestamp: 1,
                target_system: 1,
                target_component: 1,
                secret_key: [7; 32],
            }),
        ));
    }
    assert!(
        texts_to(&out, OWNER).is_empty(),
        "{:?}",
        texts_to(&out, OWNER)
    );
    let n = texts_to(&out, STRANGER).len();
    assert!(n <= 4, "at most one per kind in 1 s: {n}");
    assert!(!r.v.armed());
    assert!(!r.v.signing_active());
}

#[test]
fn vehicle_events_still_reach_everyone() {
    let mut r = rig();
    let out = r.cmd(OWNER, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(
        texts_to(&out, STRANGER).iter().any(|t| t == "Armed"),
        "arming is everyone's business"
    );
}

// ---- ASCII ---------------------------------------------------------------

#[test]
fn statustext_is_ascii_with_units_spelled_out() {
    use neptunus::vehicle::machine::ascii_text;
    assert_eq!(ascii_text("1500 µs"), "1500 us");
    assert_eq!(ascii_text("62 °C"), "62 degC");
    assert_eq!(ascii_text("640×480"), "640x480");
    assert_eq!(ascii_text("café\n"), "caf? ");
    // A real text: DO_SET_SERVO out of range names µs.
    let mut r = rig();
    let out = r.cmd(OWNER, MavCmd::MAV_CMD_DO_SET_SERVO, &[7.0, 3000.0]);
    let t = texts_to(&out, OWNER);
    assert!(
        t.iter().any(|t| t.contains("3000 us out of range")),
        "{t:?}"
    );
    // MOT_PWM_MIN's refusal (a ParamError naming µs).
    let out = r.param_set(
        OWNER,
        "MOT_PWM_MIN",
        1600.0,
        MavParamType::MAV_PARAM_TYPE_INT16,
    );
    let t = texts_to(&out, OWNER);
    assert!(t.iter().any(|t| t.contains("1500 us neutral")), "{t:?}");
}

mod every_text_is_ascii {
    use super::*;
    use proptest::prelude::*;

    fn any_input() -> impl Strategy<Value = (u8, Vec<u8>, u16, [f32; 3], u32)> {
        (
            0u8..6,
            proptest::collection::vec(any::<u8>(), 0..16),
            any::<u16>(),
            (any::<f32>(), -5000.0f32..5000.0, any::<f32>()).prop_map(|(a, b, c)| [a, b, c]),
            0u32..3000,
        )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Whatever stations send (names with any bytes, any command,
        /// any values, from owners and strangers), every STATUSTEXT the core
        /// emits is printable ASCII.
        #[test]
        fn property(inputs in proptest::collection::vec(any_input(), 1..60)) {
            let mut r = rig();
            let mut out = Vec::new();
            for (kind, name, cmd, p, dt_ms) in inputs {
                r.t += Duration::from_millis(u64::from(dt_ms));
                let from = if kind % 2 == 0 { OWNER } else { STRANGER };
                let mut id = [0u8; 16];
                id[..name.len()].copy_from_slice(&name);
                match kind {
                    0 | 1 => out.extend(r.msg(from, MavMessage::PARAM_SET(PARAM_SET_DATA {
                        param_value: p[1],
                        target_system: 1,
                        target_component: 1,
                        param_id: id.into(),
                        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
                    }))),
                    2 | 3 => {
                        let c = [400u16, 176, 183, 205, 209, 511, 512, 32100, 44200, 44201]
                            .get(usize::from(cmd) % 10)
                            .and_then(|n| <MavCmd as num_traits::FromPrimitive>::from_u16(*n))
                            .unwrap_or(MavCmd::MAV_CMD_DO_SET_SERVO);
                        out.extend(r.cmd(from, c, &[p[0], p[1], p[2]]));
                    }
                    _ => {
                        out.extend(r.input(Input::ParamsSaved(Err(String::from_utf8_lossy(&name).into_owned()))));
                        out.extend(r.run(Duration::from_millis(50)));
                    }
                }
            }
            for o in &out {
                if let Output::Text { msg: MavMessage::STATUSTEXT(s), .. } = o {
                    let b: &[u8] = s.text.as_ref();
                    prop_assert!(b.iter().all(|&c| c == 0 || (b' '..=b'~').contains(&c)), "{:?}", statustext(s));
                }
            }
        }
    }
}

// ---- M3 / H7: saved when changed, off the vehicle task, or the station is told

fn owner_rig() -> CoreRig {
    rig()
}

#[test]
fn fifty_thousand_sets_of_the_same_value_write_nothing() {
    let mut r = owner_rig();
    let mut out = Vec::new();
    for _ in 0..50_000 {
        r.t += Duration::from_micros(100);
        out.extend(r.param_set(
            OWNER,
            "JS_GAIN_DEFAULT",
            0.5,
            MavParamType::MAV_PARAM_TYPE_REAL32,
        ));
    }
    out.extend(r.run(Duration::from_secs(3)));
    assert_eq!(saves(&out), 0);
    assert!(!r.v.params_unsaved());
    // Each was still acknowledged.
    assert_eq!(sends!(&out, PARAM_VALUE).len(), 50_000);
}

#[test]
fn a_dragged_slider_is_one_write_after_it_settles() {
    let mut r = owner_rig();
    let mut out = Vec::new();
    // 30 changes over 0.6 s (a slider), then quiet.
    for i in 0..30 {
        out.extend(r.param_set(
            OWNER,
            "JS_GAIN_DEFAULT",
            0.3 + 0.01 * i as f32,
            MavParamType::MAV_PARAM_TYPE_REAL32,
        ));
        out.extend(r.run(Duration::from_millis(20)));
    }
    assert_eq!(saves(&out), 0, "not while it moves");
    let settle = r.run(Duration::from_millis(600));
    assert_eq!(saves(&settle), 1);
    // At most one in flight: no second request before the answer.
    r.param_set(
        OWNER,
        "JS_GAIN_DEFAULT",
        0.9,
        MavParamType::MAV_PARAM_TYPE_REAL32,
    );
    assert_eq!(saves(&r.run(Duration::from_secs(2))), 0);
    r.input(Input::ParamsSaved(Ok(())));
    assert_eq!(saves(&r.run(Duration::from_secs(1))), 1);
    r.input(Input::ParamsSaved(Ok(())));
    assert!(!r.v.params_unsaved());
}

#[test]
fn a_never_ending_stream_of_changes_still_saves_within_two_seconds() {
    let mut r = owner_rig();
    let mut out = Vec::new();
    for i in 0..40 {
        out.extend(r.param_set(
            OWNER,
            "JS_GAIN_DEFAULT",
            if i % 2 == 0 { 0.6 } else { 0.7 },
            MavParamType::MAV_PARAM_TYPE_REAL32,
        ));
        out.extend(r.run(Duration::from_millis(100)));
    }
    assert!(saves(&out) >= 1);
}

#[test]
fn a_failed_save_is_told_to_everyone_shown_in_sys_status_and_retried_until_it_works() {
    let mut r = owner_rig();
    let logging = MavSysStatusSensor::MAV_SYS_STATUS_LOGGING;
    let s = msgs!(&r.run(Duration::from_secs(1)), SYS_STATUS)
        .pop()
        .unwrap();
    assert!(s.onboard_control_sensors_present.contains(logging));
    assert!(s.onboard_control_sensors_health.contains(logging));

    r.param_set(
        OWNER,
        "FS_GCS_TIMEOUT",
        9.0,
        MavParamType::MAV_PARAM_TYPE_REAL32,
    );
    assert_eq!(saves(&r.run(Duration::from_millis(600))), 1);
    let why = "could not write params.toml.tmp: No space left on device (os error 28)";
    let out = r.input(Input::ParamsSaved(Err(why.into())));
    let warn: Vec<_> = sent(&out)
        .into_iter()
        .filter_map(|(to, m)| match m {
            MavMessage::STATUSTEXT(s) => Some((to, s)),
            _ => None,
        })
        .collect();
    let joined: String = warn.iter().map(|(_, s)| statustext(s)).collect();
    assert!(
        warn.iter()
            .all(|(to, s)| *to == To::All && s.severity == MavSeverity::MAV_SEVERITY_WARNING)
    );
    assert!(joined.contains("FS_GCS_TIMEOUT"), "{joined}");
    assert!(joined.contains("No space left"), "{joined}");
    assert!(r.v.params_save_error().is_some());
    // Health shows it; the value is in use all the same.
    let s = msgs!(&r.run(Duration::from_millis(600)), SYS_STATUS)
        .pop()
        .unwrap();
    assert!(!s.onboard_control_sensors_health.contains(logging));
    assert_eq!(r.v.params().get("FS_GCS_TIMEOUT"), Some(9.0));
    // Retried with backoff: 1 s, then 2 s.
    let retry = r.run(Duration::from_millis(500));
    assert_eq!(saves(&retry), 1, "first retry within 1 s of the failure");
    r.input(Input::ParamsSaved(Err(why.into())));
    assert_eq!(saves(&r.run(Duration::from_millis(1900))), 0);
    assert_eq!(
        saves(&r.run(Duration::from_millis(200))),
        1,
        "then after 2 s"
    );
    let out = r.input(Input::ParamsSaved(Ok(())));
    let t = texts_to(&out, STRANGER);
    assert!(t.iter().any(|t| t.contains("Parameters saved")), "{t:?}");
    let s = msgs!(&r.run(Duration::from_secs(1)), SYS_STATUS)
        .pop()
        .unwrap();
    assert!(s.onboard_control_sensors_health.contains(logging));
    assert!(!r.v.params_unsaved());
    assert_eq!(r.v.params_save_error(), None);
}

#[test]
fn a_storage_problem_at_start_shows_in_sys_status() {
    let mut r = owner_rig();
    r.v.set_storage_problem(Some("data directory read-only".into()));
    let logging = MavSysStatusSensor::MAV_SYS_STATUS_LOGGING;
    let s = msgs!(&r.run(Duration::from_secs(1)), SYS_STATUS)
        .pop()
        .unwrap();
    assert!(!s.onboard_control_sensors_health.contains(logging));
    // A save that works proves the directory works again.
    r.param_set(
        OWNER,
        "FS_GCS_TIMEOUT",
        8.0,
        MavParamType::MAV_PARAM_TYPE_REAL32,
    );
    assert_eq!(saves(&r.run(Duration::from_millis(600))), 1);
    r.input(Input::ParamsSaved(Ok(())));
    let s = msgs!(&r.run(Duration::from_secs(1)), SYS_STATUS)
        .pop()
        .unwrap();
    assert!(s.onboard_control_sensors_health.contains(logging));
}

// ---- L2: param_type --------------------------------------------------------

#[test]
fn a_param_set_with_the_wrong_type_is_answered_with_the_current_value() {
    let mut r = owner_rig();
    // INT8 for a REAL32 parameter: 0.7 would become 0.
    let out = r.param_set(
        OWNER,
        "JS_GAIN_DEFAULT",
        0.7,
        MavParamType::MAV_PARAM_TYPE_INT8,
    );
    let pv = sends!(&out, PARAM_VALUE);
    assert_eq!(pv.len(), 1);
    assert_eq!(pv[0].0, To::Peer(0, OWNER.peer));
    assert_eq!(pv[0].1.param_value, 0.5);
    assert_eq!(pv[0].1.param_type, MavParamType::MAV_PARAM_TYPE_REAL32);
    assert_eq!(r.v.bad_param_types(), 1);
    // INT8 cannot carry 300.
    let out = r.param_set(
        OWNER,
        "MOT_PWM_MAX",
        1950.0,
        MavParamType::MAV_PARAM_TYPE_INT8,
    );
    assert_eq!(sends!(&out, PARAM_VALUE)[0].1.param_value, 1900.0);
    assert_eq!(r.v.bad_param_types(), 2);
    // Its own type, REAL32 (pymavlink's default), or an integer type that
    // holds the value: accepted.
    for (v, ty) in [
        (1950.0, MavParamType::MAV_PARAM_TYPE_INT16),
        (1940.0, MavParamType::MAV_PARAM_TYPE_REAL32),
        (1930.0, MavParamType::MAV_PARAM_TYPE_INT32),
    ] {
        let out = r.param_set(OWNER, "MOT_PWM_MAX", v, ty);
        assert_eq!(sends!(&out, PARAM_VALUE)[0].1.param_value, v, "{ty:?}");
    }
    // Not a MAV_PARAM_TYPE at all (the frame decoder hands these over raw).
    let mut id = [0u8; 16];
    id[..15].copy_from_slice(b"JS_GAIN_DEFAULT");
    let out = r.input(Input::BadParamSet {
        from: OWNER,
        target_system: 1,
        target_component: 1,
        param_id: id,
        param_type: 0,
    });
    let pv = sends!(&out, PARAM_VALUE);
    assert_eq!(pv.len(), 1);
    assert_eq!(pv[0].1.param_value, 0.5);
    assert_eq!(r.v.bad_param_types(), 3);
}

// ---- L3: INT32 extremes ----------------------------------------------------

#[test]
fn int32_maximum_sent_as_a_float_sets_exactly_the_maximum() {
    let mut r = owner_rig();
    // What a ground station sends for 2147483647: the nearest f32, 2^31.
    let sent_value = i32::MAX as f32;
    assert_eq!(f64::from(sent_value), 2_147_483_648.0);
    let out = r.param_set(
        OWNER,
        "ARMING_CHECK",
        sent_value,
        MavParamType::MAV_PARAM_TYPE_INT32,
    );
    assert_eq!(r.v.params().get("ARMING_CHECK"), Some(2_147_483_647.0));
    // Reported back as ArduPilot's C-cast encoding does: (float)2147483647.
    let pv = sends!(&out, PARAM_VALUE);
    assert_eq!(pv[0].0, To::All);
    assert_eq!(pv[0].1.param_value, 2_147_483_648.0_f32);
    assert_eq!(pv[0].1.param_type, MavParamType::MAV_PARAM_TYPE_INT32);
    // One past it as a float is still out of range.
    let out = r.param_set(
        OWNER,
        "ARMING_CHECK",
        2_147_483_904.0,
        MavParamType::MAV_PARAM_TYPE_INT32,
    );
    assert!(texts_to(&out, OWNER).iter().any(|t| t.contains("outside")));
    // And it survives the file.
    let toml = r.v.params().to_toml();
    assert!(toml.contains("ARMING_CHECK = 2147483647"), "{toml}");
    let (back, warnings) = ParamStore::from_toml(&toml).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(back.get("ARMING_CHECK"), Some(2_147_483_647.0));
}

// ---- M2: SYSID_THISMAV -----------------------------------------------------

#[test]
fn sysid_thismav_takes_effect_at_the_next_start_and_disarm_to_system_1_still_works() {
    let mut r = owner_rig();
    let out = r.cmd(OWNER, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let out = r.param_set(
        OWNER,
        "SYSID_THISMAV",
        2.0,
        MavParamType::MAV_PARAM_TYPE_INT16,
    );
    assert_eq!(sends!(&out, PARAM_VALUE)[0].1.param_value, 2.0, "stored");
    let t = texts_to(&out, OWNER);
    assert!(t.iter().any(|t| t.contains("next start")), "{t:?}");
    assert_eq!(r.v.sysid(), 1, "the live id does not change");
    // The owner disarms system 1, as its ground station still knows it.
    let out = r.cmd(OWNER, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0]);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(!r.v.armed());
    // The next start uses it.
    let next = Vehicle::new(Identity::Ardupilot, r.v.params().clone(), 2);
    assert_eq!(next.sysid(), 2);
}

#[test]
fn sysid_thismav_is_never_a_ground_stations_id() {
    let mut r = owner_rig();
    let mut p = ParamStore::defaults();
    p.set("NEPT_GCS_ALLOW2", 254.0).unwrap();
    r.v = Vehicle::new(Identity::Ardupilot, p, 2).with_hmi_sysids(200, 209);
    for id in [255.0, 254.0, 245.0, 200.0, 209.0] {
        let out = r.param_set(
            OWNER,
            "SYSID_THISMAV",
            id,
            MavParamType::MAV_PARAM_TYPE_INT16,
        );
        let pv = sends!(&out, PARAM_VALUE);
        assert_eq!(pv[0].1.param_value, 1.0, "{id} refused");
        assert_eq!(pv[0].0, To::Peer(0, OWNER.peer));
        r.t += Duration::from_secs(1);
    }
    assert_eq!(r.v.params().get("SYSID_THISMAV"), Some(1.0));
    // Nor a ground station the vehicle's id.
    let out = r.param_set(
        OWNER,
        "SYSID_MYGCS",
        1.0,
        MavParamType::MAV_PARAM_TYPE_INT16,
    );
    assert_eq!(sends!(&out, PARAM_VALUE)[0].1.param_value, 255.0);
    // The file is held to the same rule.
    let (s, warnings) = ParamStore::from_toml("SYSID_THISMAV = 255\n").unwrap();
    assert_eq!(s.get("SYSID_THISMAV"), Some(1.0));
    assert_eq!(warnings.len(), 1, "{warnings:?}");
}
