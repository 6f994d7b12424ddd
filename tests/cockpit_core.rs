//! What Cockpit asks of an ArduSub vehicle, on the core with synthetic
//! time: every SET_MESSAGE_INTERVAL it sends at connect is ACCEPTED (as
//! ArduSub answers), the instruments it reads (AHRS2, EKF_STATUS_REPORT,
//! SCALED_PRESSURE/2) are produced from the board's readings, HOME_POSITION
//! is answered without inventing one, camera zoom/focus get one
//! UNSUPPORTED, and its once-a-second PARAM_SET of an unchanged value costs
//! no parameter save.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, ack_of, acks, count_sent, msgs, saves, sent};
use mavlink_core::{Message as _, MessageData};
use neptunus::dialect::neptunus::*;
use neptunus::vehicle::machine::{Identity, Sender, To, Vehicle};
use neptunus::vehicle::params::ParamStore;

/// Cockpit's header: system 255, component 240.
const COCKPIT: Sender = Sender::new(0, 3, 255, 240);
/// Not an allowed station: may not change rates.
const STRANGER: Sender = Sender::new(0, 4, 77, 190);

fn rig() -> CoreRig {
    CoreRig::new(Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 2)).started()
}

/// The 27 ids Cockpit's SET_MESSAGE_INTERVAL got UNSUPPORTED for before
/// (as measured against Cockpit) and the 9 we already streamed.
const COCKPIT_IDS: [u32; 36] = [
    22, 24, 27, 29, 35, 65, 100, 116, 124, 125, 127, 128, 129, 132, 143, 152, 162, 163, 173, 178,
    191, 192, 193, 194, 241, 242, 285, // then the ones streamed all along
    0, 1, 2, 30, 33, 36, 74, 137, 147,
];

#[test]
fn every_interval_cockpit_sets_is_accepted_and_strangers_are_denied() {
    let mut r = rig();
    use MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL as SET;
    for id in COCKPIT_IDS {
        let hz = if id == ATTITUDE_DATA::ID || id == AHRS2_DATA::ID {
            16.0
        } else {
            4.0
        };
        let out = r.cmd(COCKPIT, SET, &[id as f32, 1e6 / hz]);
        assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_ACCEPTED, "id {id}");
        assert!(
            msgs!(&out, STATUSTEXT).is_empty(),
            "id {id}: a text Cockpit would show"
        );
    }
    // Unknown to ArduPilot and to us: still UNSUPPORTED; a stranger: DENIED.
    let out = r.cmd(COCKPIT, SET, &[9999.0, 1e5]);
    assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_UNSUPPORTED);
    let out = r.cmd(STRANGER, SET, &[VIBRATION_DATA::ID as f32, 1e5]);
    assert_eq!(ack_of(&out, SET), MavResult::MAV_RESULT_DENIED);
    // GET_MESSAGE_INTERVAL says "not available" (0 µs) for what we cannot send.
    let out = r.cmd(
        COCKPIT,
        MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL,
        &[RAW_IMU_DATA::ID as f32],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(msgs!(&out, MESSAGE_INTERVAL)[0].interval_us, 0);

    // At the asked rates: AHRS2 at 16 Hz, with the depth as altitude.
    let out = r.run(Duration::from_secs(2));
    // (On Cockpit's endpoint; the other keeps ArduSub's default 3 Hz.) A
    // navigation-line message goes out as each 10-Hz line arrives and is
    // repeated in between to keep the asked rate; its clock follows the
    // lines, so between one and two lines' rate it runs up to a
    // line-alignment short (15 Hz here), never above the asked rate.
    let n = count_sent(&out, AHRS2_DATA::ID, To::Endpoint(0));
    assert!((29..=33).contains(&n), "AHRS2 in 2 s: {n}");
    let a = msgs!(&out, AHRS2).last().cloned().unwrap();
    assert!(
        (a.altitude + 1.0).abs() < 0.05,
        "altitude {} at 1 m deep",
        a.altitude
    );
    assert!(
        (a.yaw.to_degrees() - 10.0).abs() < 1.0,
        "yaw {}",
        a.yaw.to_degrees()
    );
    // Nothing is invented for the messages we have nothing for.
    for (_, m) in sent(&out) {
        let id = m.message_id();
        assert!(
            !neptunus::vehicle::telemetry::nothing_to_send(id),
            "{} sent though we have nothing for it",
            m.message_name()
        );
    }
}

#[test]
fn instruments_come_from_the_board_readings() {
    let mut r = rig();
    let out = r.run(Duration::from_secs(2));
    let ekf = msgs!(&out, EKF_STATUS_REPORT);
    assert!(!ekf.is_empty(), "EKF_STATUS_REPORT streamed by default");
    let f = ekf.last().unwrap().flags;
    use EkfStatusFlags as F;
    assert!(
        f.contains(F::EKF_ATTITUDE | F::EKF_VELOCITY_VERT | F::EKF_POS_VERT_ABS),
        "{f:?}"
    );
    assert!(
        f.contains(F::EKF_CONST_POS_MODE) && !f.contains(F::EKF_UNINITIALIZED),
        "{f:?}"
    );
    assert!(!f.intersects(F::EKF_POS_HORIZ_ABS | F::EKF_POS_HORIZ_REL | F::EKF_VELOCITY_HORIZ));
    let e = ekf.last().unwrap();
    assert!(
        e.pos_vert_variance > 0.0 && e.pos_vert_variance < 0.25,
        "{e:?}"
    );
    let p1 = msgs!(&out, SCALED_PRESSURE);
    let p2 = msgs!(&out, SCALED_PRESSURE2);
    assert!(!p1.is_empty() && !p2.is_empty());
    assert_eq!(p1.last().unwrap().press_abs, p2.last().unwrap().press_abs);
    assert_eq!(p1.last().unwrap().press_abs, 1113.0);

    // Board silent: no AHRS2 nor pressure from stale readings; the EKF
    // report stays (it says what is not valid any more).
    let out = r.run_board_silent(Duration::from_secs(3));
    let late = |id: u32| {
        sent(&out)
            .iter()
            .rev()
            .take(40)
            .any(|(_, m)| m.message_id() == id)
    };
    assert!(!late(AHRS2_DATA::ID) && !late(SCALED_PRESSURE_DATA::ID));
    let f = msgs!(&out, EKF_STATUS_REPORT).last().unwrap().flags;
    assert!(!f.contains(EkfStatusFlags::EKF_POS_VERT_ABS), "{f:?}");
}

#[test]
fn home_position_is_accepted_and_nothing_is_invented() {
    let mut r = rig();
    let out = r.cmd(
        COCKPIT,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        &[HOME_POSITION_DATA::ID as f32],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_MESSAGE),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(msgs!(&out, HOME_POSITION).is_empty());
}

#[test]
fn camera_zoom_and_focus_get_one_unsupported() {
    let mut r = rig();
    for cmd in [
        MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
        MavCmd::MAV_CMD_SET_CAMERA_FOCUS,
    ] {
        for target_component in [0u8, 1] {
            let msg = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: 1.0,
                param2: 1.0,
                command: cmd,
                target_system: 1,
                target_component,
                ..Default::default()
            });
            let out = r.msg(COCKPIT, msg);
            let a = acks(&out);
            assert_eq!(a.len(), 1, "{cmd:?} to component {target_component}: {a:?}");
            assert_eq!(a[0].result, MavResult::MAV_RESULT_UNSUPPORTED);
        }
    }
}

#[test]
fn a_param_set_that_changes_nothing_costs_no_save() {
    let mut r = rig();
    r.alive.push(COCKPIT);
    let out = r.param_set(
        COCKPIT,
        "BTN5_SFUNCTION",
        7.0,
        MavParamType::MAV_PARAM_TYPE_INT8,
    );
    assert_eq!(msgs!(&out, PARAM_VALUE).len(), 1);
    let mut all = r.run(Duration::from_secs(5));
    assert_eq!(saves(&all), 1, "the change is saved once");
    // Cockpit re-sends it every second.
    for _ in 0..10 {
        let out = r.param_set(
            COCKPIT,
            "BTN5_SFUNCTION",
            7.0,
            MavParamType::MAV_PARAM_TYPE_INT8,
        );
        assert_eq!(msgs!(&out, PARAM_VALUE)[0].param_value, 7.0);
        all = r.run(Duration::from_secs(1));
        assert_eq!(saves(&all), 0, "an unchanged value is not written again");
    }
}
