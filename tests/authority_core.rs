//! Control authority, handover, failsafes, signing policy and the event log,
//! through the vehicle core with synthetic time.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, NEUTRAL, ack_of, gos, has_event, has_text, msgs, sends, texts};
use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::Command;
use neptunus::vehicle::machine::{
    FailsafeKind, HmiEvent, Identity, Input, Now, Output, Sender, To, Topic, Vehicle,
};
use neptunus::vehicle::params::ParamStore;

/// Primary station (SYSID_MYGCS 255), QGC-like.
const A: Sender = Sender::new(0, 1, 255, 190);
/// Second allowed station (NEPT_GCS_ALLOW2 = 254 in every rig).
const B: Sender = Sender::new(0, 2, 254, 190);
/// MAVSDK's default id, allowed by default (NEPT_GCS_ALLOW1 = 245).
const C: Sender = Sender::new(1, 3, 245, 190);
/// Not allowed.
const STRANGER: Sender = Sender::new(0, 4, 77, 190);

/// Two endpoints; NEPT_GCS_ALLOW2 = 254 (so that B is allowed) and `params`
/// on top of the defaults; started (board link up, ready to arm).
fn rig_with(params: &[(&str, f64)]) -> CoreRig {
    let mut p = ParamStore::defaults();
    p.set("NEPT_GCS_ALLOW2", 254.0).unwrap();
    for (n, v) in params {
        p.set(n, *v).unwrap();
    }
    CoreRig::new(Vehicle::new(Identity::Ardupilot, p, 2)).started()
}

fn rig() -> CoreRig {
    rig_with(&[])
}

/// Position of the first output matching `f`.
fn pos(out: &[Output], f: impl Fn(&Output) -> bool) -> usize {
    out.iter()
        .position(f)
        .unwrap_or_else(|| panic!("not found in {out:?}"))
}

/// A rig where `owner` has armed and is driving forward (x = 500).
fn driving(owner: Sender) -> CoreRig {
    driving_with(owner, &[])
}

fn driving_with(owner: Sender, params: &[(&str, f64)]) -> CoreRig {
    let mut r = rig_with(params);
    r.alive.push(owner);
    r.heartbeat(owner);
    assert_eq!(
        ack_of(&r.arm(owner), MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
    r.stick(owner, 500);
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
    r
}

// ---- authority ----

#[test]
fn the_first_allowed_station_to_arm_claims_and_control_status_says_so() {
    let mut r = rig();
    assert_eq!(r.v.owner(), None);
    let out = r.arm(A);
    assert_eq!(r.v.owner(), Some(255));
    let cs = msgs!(&out, CONTROL_STATUS);
    assert_eq!(
        cs.last().map(|c| c.gcs_main),
        Some(255),
        "sent at once on change"
    );
    assert!(
        cs.last()
            .unwrap()
            .flags
            .contains(GcsControlStatusFlags::GCS_CONTROL_STATUS_FLAGS_SYSTEM_MANAGER)
    );
    assert!(has_event(&out, "control_claimed", Some(255)));
    assert!(has_event(&out, "armed", Some(255)));
    // And at 1 Hz on the telemetry schedule of each endpoint.
    let out: Vec<Output> = r
        .run(Duration::from_secs(3))
        .into_iter()
        .filter(|o| {
            matches!(
                o,
                Output::Send {
                    to: To::Endpoint(0),
                    ..
                }
            )
        })
        .collect();
    let n = msgs!(&out, CONTROL_STATUS).len();
    assert!((3..=4).contains(&n), "{n} CONTROL_STATUS in 3 s");
}

#[test]
fn stick_input_claims_a_disarmed_vehicle_without_pick_up() {
    let mut r = rig();
    r.stick(B, 500);
    assert_eq!(r.v.owner(), Some(254));
    assert!(
        !r.v.pickup_pending(),
        "disarmed: arming is the deliberate act"
    );
    r.arm(B);
    r.stick(B, 500);
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
}

#[test]
fn a_non_owner_cannot_move_a_thruster_or_change_state_but_may_watch() {
    let mut r = driving(A);
    let mut out = Vec::new();
    for _ in 0..20 {
        out.extend(r.stick(B, -1000));
        out.extend(r.run(Duration::from_millis(40)));
        out.extend(r.stick(A, 500));
    }
    assert!(
        gos(&out).iter().all(|g| *g == [1400, 1500, 1600]),
        "only A's input drives: {:?}",
        gos(&out)
    );
    assert!(has_text(
        &out,
        "Ignoring MANUAL_CONTROL from sysid 254: GCS 255 is in control"
    ));
    assert!(has_event(&out, "input_rejected", Some(254)));
    use MavCmd as C;
    for (cmd, p) in [
        (
            C::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
        (
            C::MAV_CMD_DO_SET_MODE,
            [1.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
        (
            C::MAV_CMD_DO_MOTOR_TEST,
            [1.0, 1.0, 1700.0, 1.0, 0.0, 0.0, 0.0],
        ),
        (
            C::MAV_CMD_ILLUMINATOR_ON_OFF,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
        (
            C::MAV_CMD_DO_MOUNT_CONTROL,
            [2000.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
        (
            C::MAV_CMD_DO_SET_SERVO,
            [7.0, 1800.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
    ] {
        let out = r.cmd(B, cmd, &p);
        assert_eq!(
            ack_of(&out, cmd),
            MavResult::MAV_RESULT_NOT_IN_CONTROL,
            "{cmd:?}"
        );
        assert!(
            !out.iter().any(|o| matches!(o, Output::Board(_))),
            "{cmd:?} reached the board: {out:?}"
        );
        r.t += Duration::from_secs(1); // past the report rate limit
    }
    assert_eq!(r.v.mode().number(), 19);
    // PARAM_SET: answered with the unchanged value.
    let out = r.msg(
        B,
        MavMessage::PARAM_SET(PARAM_SET_DATA {
            param_value: 0.9,
            target_system: 1,
            target_component: 1,
            param_id: "JS_GAIN_DEFAULT".into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }),
    );
    let echoed = out.iter().find_map(|o| match o {
        Output::Send {
            msg: MavMessage::PARAM_VALUE(p),
            ..
        } => Some(p.param_value),
        _ => None,
    });
    assert_eq!(echoed, Some(0.5));
    assert!(!out.contains(&Output::SaveParams));
    // Watching is open to everyone.
    let out = r.cmd(
        B,
        C::MAV_CMD_SET_MESSAGE_INTERVAL,
        &[30.0, 100_000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(
        ack_of(&out, C::MAV_CMD_SET_MESSAGE_INTERVAL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let out = r.msg(
        B,
        MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system: 1,
            target_component: 1,
            param_id: "SYSID_MYGCS".into(),
        }),
    );
    assert!(out.iter().any(|o| matches!(
        o,
        Output::Send {
            msg: MavMessage::PARAM_VALUE(_),
            ..
        }
    )));
    // Disarm is open to every station: stopping is never wrong.
    let out = r.cmd(B, C::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0; 7]);
    assert_eq!(
        ack_of(&out, C::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(!r.v.armed());
    assert_eq!(r.v.owner(), Some(255), "disarming does not take control");
}

#[test]
fn a_station_not_allowed_is_denied_control_and_never_claims() {
    let mut r = rig();
    let out = r.request_control(STRANGER, 1.0, 0.0, 10.0);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL),
        MavResult::MAV_RESULT_DENIED
    );
    let out = r.arm(STRANGER);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_NOT_IN_CONTROL
    );
    r.stick(STRANGER, 1000);
    assert_eq!(r.v.owner(), None);
    assert!(!r.v.armed());
}

#[test]
fn with_explicit_claim_only_a_request_gives_control() {
    let mut r = rig_with(&[("NEPT_CTRL_CLAIM", 1.0)]);
    let out = r.arm(A);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_NOT_IN_CONTROL
    );
    assert!(has_text(&out, "request control first"));
    r.stick(A, 500);
    assert_eq!(r.v.owner(), None);
    let out = r.request_control(A, 1.0, 0.0, 10.0);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(has_event(&out, "control_granted", Some(255)));
    assert_eq!(
        ack_of(&r.arm(A), MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
}

#[test]
fn takeover_allowed_grants_requests_at_once() {
    let mut r = rig();
    let out = r.request_control(B, 1.0, 1.0, 10.0);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let cs = msgs!(&out, CONTROL_STATUS);
    let last = cs.last().unwrap();
    assert_eq!(last.gcs_main, 254);
    assert!(
        last.flags
            .contains(GcsControlStatusFlags::GCS_CONTROL_STATUS_FLAGS_TAKEOVER_ALLOWED)
    );
    let out = r.request_control(C, 1.0, 0.0, 10.0);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(r.v.owner(), Some(245));
    let last = msgs!(&out, CONTROL_STATUS).pop().unwrap();
    assert!(
        !last
            .flags
            .contains(GcsControlStatusFlags::GCS_CONTROL_STATUS_FLAGS_TAKEOVER_ALLOWED)
    );
}

#[test]
fn a_request_is_forwarded_and_the_owners_release_hands_over_with_pick_up() {
    let mut r = driving(A);
    r.alive.push(B);
    let out = r.request_control(B, 1.0, 0.0, 10.0);
    let (to, ack) = sends!(&out, COMMAND_ACK).remove(0);
    let result = ack.result;
    assert_eq!(result, MavResult::MAV_RESULT_FAILED);
    assert_eq!(to, To::Peer(0, 2), "the requester gets FAILED");
    let fwd = out
        .iter()
        .find_map(|o| match o {
            Output::Send {
                to,
                msg: MavMessage::COMMAND_LONG(c),
            } => Some((*to, c.clone())),
            _ => None,
        })
        .expect("forwarded to the owner");
    assert_eq!(fwd.0, To::Peer(0, 1));
    assert_eq!(fwd.1.command, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL);
    assert_eq!((fwd.1.target_system, fwd.1.target_component), (255, 190));
    assert_eq!((fwd.1.param1, fwd.1.param4), (1.0, 254.0));
    assert!(has_event(&out, "control_forwarded", Some(254)));
    // While pending the owner still drives.
    r.run(Duration::from_secs(2));
    let out = r.stick(A, 1000);
    assert_eq!(gos(&out), vec![[1300, 1500, 1700]]);
    assert_eq!(r.v.owner(), Some(255));
    // The owner says yes by releasing.
    let out = r.request_control(A, 0.0, 0.0, 0.0);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(r.v.owner(), Some(254));
    assert_eq!(gos(&out).last(), Some(&NEUTRAL), "neutral at the transfer");
    assert_eq!(msgs!(&out, CONTROL_STATUS).last().unwrap().gcs_main, 254);
    assert!(has_event(&out, "control_released", Some(255)));
    assert!(has_event(&out, "control_granted", Some(254)));
    assert!(r.v.armed(), "armed state is kept");
    // Pick-up: B's deflected sticks are ignored until centred once.
    let out = r.stick(B, 500);
    assert!(gos(&out).iter().all(|g| *g == NEUTRAL));
    assert!(has_text(&out, "Centre the sticks"));
    assert!(r.v.pickup_pending());
    r.stick(B, 0);
    assert!(!r.v.pickup_pending());
    let out = r.stick(B, 500);
    assert_eq!(gos(&out), vec![[1400, 1500, 1600]]);
    // A is a watcher now.
    let out = r.stick(A, -1000);
    assert!(gos(&out).is_empty());
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
}

#[test]
fn re_requesting_with_takeover_allowed_is_the_owners_yes() {
    let mut r = driving(A);
    r.request_control(B, 1.0, 0.0, 10.0);
    let out = r.request_control(A, 1.0, 1.0, 10.0);
    assert_eq!(r.v.owner(), Some(254));
    assert_eq!(gos(&out).last(), Some(&NEUTRAL));
    assert!(r.v.pickup_pending());
}

#[test]
fn the_owners_refusal_leaves_control_where_it_was() {
    let mut r = driving(A);
    r.request_control(B, 1.0, 0.0, 10.0);
    let out = r.msg(
        A,
        MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
            result: MavResult::MAV_RESULT_DENIED,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }),
    );
    assert!(has_text(&out, "refused by GCS 255"), "{:?}", texts(&out));
    assert!(has_event(&out, "control_refused", Some(254)));
    assert_eq!(r.v.owner(), Some(255));
    assert!(gos(&out).is_empty(), "nothing stops");
    // A later release does not hand over to the refused request.
    r.request_control(A, 0.0, 0.0, 0.0);
    assert_eq!(r.v.owner(), None);
}

#[test]
fn an_acknowledgement_alone_is_not_an_answer_and_silence_times_out() {
    let mut r = driving(A);
    r.request_control(B, 1.0, 0.0, 3.0);
    r.msg(
        A,
        MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
            result: MavResult::MAV_RESULT_ACCEPTED,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }),
    );
    let mut out = Vec::new();
    for _ in 0..40 {
        out.extend(r.run(Duration::from_millis(100)));
        out.extend(r.stick(A, 500));
    }
    assert!(has_text(
        &out,
        "Control request from GCS 254 timed out: GCS 255 keeps control"
    ));
    assert!(has_event(&out, "control_refused", Some(254)));
    assert_eq!(r.v.owner(), Some(255));
    assert_eq!(
        r.v.motors_us(),
        [1400, 1500, 1600],
        "the owner drove on throughout"
    );
    // Releasing after the timeout no longer hands over.
    r.request_control(A, 0.0, 0.0, 0.0);
    assert_eq!(r.v.owner(), None);
}

#[test]
fn a_request_while_the_owner_is_mid_command_lets_the_command_finish_until_handover() {
    let mut r = driving(A);
    let test = [1.0, 1.0, 1700.0, 1.0, 0.0, 0.0, 0.0];
    r.cmd(A, MavCmd::MAV_CMD_DO_MOTOR_TEST, &test);
    assert_eq!(r.v.motors_us(), [1500, 1500, 1700]);
    r.request_control(B, 1.0, 0.0, 10.0);
    let out = r.cmd(A, MavCmd::MAV_CMD_DO_MOTOR_TEST, &test);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_DO_MOTOR_TEST),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(r.v.motors_us(), [1500, 1500, 1700]);
    let out = r.request_control(A, 0.0, 0.0, 0.0);
    assert_eq!(
        gos(&out).last(),
        Some(&NEUTRAL),
        "the motor test ends at the transfer"
    );
    let out = r.cmd(A, MavCmd::MAV_CMD_DO_MOTOR_TEST, &test);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_DO_MOTOR_TEST),
        MavResult::MAV_RESULT_NOT_IN_CONTROL
    );
    assert_eq!(r.v.motors_us(), NEUTRAL);
}

#[test]
fn two_requests_the_later_replaces_the_earlier() {
    let mut r = driving(A);
    r.request_control(B, 1.0, 0.0, 10.0);
    r.request_control(C, 1.0, 0.0, 10.0);
    r.request_control(A, 0.0, 0.0, 0.0);
    assert_eq!(r.v.owner(), Some(245));
}

#[test]
fn the_primary_takes_over_without_asking_after_warning_the_owner() {
    let mut r = rig();
    r.alive.push(B);
    r.request_control(B, 1.0, 0.0, 10.0);
    r.arm(B);
    r.stick(B, 500);
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
    let out = r.request_control(A, 1.0, 0.0, 10.0);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(r.v.owner(), Some(255));
    let warn = pos(&out, |o| {
        matches!(o, Output::Text { msg: MavMessage::STATUSTEXT(s), .. }
            if s.severity == MavSeverity::MAV_SEVERITY_WARNING
            && String::from_utf8_lossy(s.text.as_ref()).contains("taken over by primary GCS 255 from GCS 254"))
    });
    let cs = pos(
        &out,
        |o| matches!(o, Output::Send { msg: MavMessage::CONTROL_STATUS(c), .. } if c.gcs_main == 255),
    );
    assert!(warn < cs, "the warning comes first");
    assert!(has_event(&out, "control_takeover", Some(255)));
    assert_eq!(gos(&out).last(), Some(&NEUTRAL));
    assert!(r.v.pickup_pending());
    let out = r.stick(B, 500);
    assert!(gos(&out).is_empty(), "B watches now");
    assert!(has_text(&out, "GCS 255 is in control"));
}

#[test]
fn a_request_naming_another_station_is_denied() {
    let mut r = rig();
    let out = r.cmd(
        B,
        MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
        &[1.0, 0.0, 10.0, 255.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL),
        MavResult::MAV_RESULT_DENIED
    );
    assert_eq!(r.v.owner(), None);
}

// ---- failsafes ----

#[test]
fn owner_lost_stops_disarms_and_only_its_own_heartbeats_count() {
    let mut r = driving_with(A, &[("FS_PILOT_INPUT", 0.0)]);
    // A's heartbeats stop; B, an onboard helper and a non-GCS sender using
    // A's sysid keep sending heartbeats.
    r.alive.clear();
    r.alive.push(B);
    let helper = Sender::new(0, 9, 1, 191);
    let mut out = Vec::new();
    let t0 = r.t;
    for _ in 0..70 {
        out.extend(r.heartbeat(helper));
        out.extend(r.msg(
            Sender::new(0, 10, 255, 191),
            MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                ..Default::default()
            }),
        ));
        out.extend(r.run(Duration::from_millis(100)));
        if !r.v.armed() {
            break;
        }
    }
    let took = r.t - t0;
    assert!(!r.v.armed(), "{:?}", texts(&out));
    // The owner's last life was the stick at t0 (and a heartbeat ≤ 1 s before).
    assert!(
        took >= Duration::from_millis(4900) && took <= Duration::from_millis(5200),
        "FS_GCS_TIMEOUT 5 s, took {took:?}"
    );
    assert!(
        has_text(&out, "Failsafe: GCS 255 heartbeat lost"),
        "{:?}",
        texts(&out)
    );
    assert!(has_event(&out, "failsafe_raised", Some(255)));
    assert!(has_event(&out, "disarmed", None));
    assert_eq!(gos(&out).last(), Some(&NEUTRAL));
    let out = r.run(Duration::from_millis(1100));
    assert_eq!(r.v.owner(), None);
    assert_eq!(
        msgs!(&out, HEARTBEAT).pop().unwrap().system_status,
        MavState::MAV_STATE_CRITICAL,
        "active until a station takes control"
    );
    // A comes back and claims: the failsafe clears.
    r.alive.push(A);
    r.heartbeat(A);
    r.stick(A, 0);
    let out = r.run(Duration::from_millis(1100));
    assert!(has_text(&out, "Failsafe cleared"));
    assert_eq!(
        msgs!(&out, HEARTBEAT).pop().unwrap().system_status,
        MavState::MAV_STATE_STANDBY
    );
}

#[test]
fn gcs_failsafe_warn_only_keeps_the_vehicle_armed_with_thrusters_neutral() {
    let mut r = rig_with(&[("FS_GCS_ENABLE", 1.0), ("FS_PILOT_INPUT", 0.0)]);
    r.alive.push(A);
    r.arm(A);
    r.stick(A, 500);
    r.alive.clear();
    let out = r.run(Duration::from_secs(7));
    assert!(r.v.armed());
    assert!(has_text(&out, "Failsafe: GCS 255 heartbeat lost"));
    assert_eq!(
        r.v.motors_us(),
        NEUTRAL,
        "the owner is gone: no input drives"
    );
    assert_eq!(r.v.owner(), None);
    // Claiming an armed vehicle needs pick-up.
    r.alive.push(B);
    r.heartbeat(B);
    let out = r.stick(B, 500);
    assert_eq!(r.v.owner(), Some(254));
    assert!(gos(&out).iter().all(|g| *g == NEUTRAL));
    r.stick(B, 0);
    r.stick(B, 500);
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
}

#[test]
fn owner_lost_during_a_request_failsafe_first_then_the_requester_gets_control() {
    let mut r = driving_with(A, &[("FS_PILOT_INPUT", 0.0)]);
    r.alive.push(B);
    r.request_control(B, 1.0, 0.0, 60.0);
    r.alive.retain(|s| *s != A);
    let out = r.run(Duration::from_secs(7));
    assert_eq!(r.v.owner(), Some(254));
    assert!(!r.v.armed());
    let disarmed = pos(
        &out,
        |o| matches!(o, Output::Log(e) if e.kind == "disarmed"),
    );
    let granted = pos(
        &out,
        |o| matches!(o, Output::Log(e) if e.kind == "control_granted" && e.sysid == Some(254)),
    );
    assert!(disarmed < granted);
    assert!(has_text(&out, "Failsafe: GCS 255 heartbeat lost"));
    assert!(has_event(&out, "control_lost", Some(255)));
}

#[test]
fn pilot_input_lost_goes_neutral_first_then_disarms() {
    let mut r = driving(A);
    let out = r.run(Duration::from_millis(3200));
    assert!(!r.v.armed());
    let neutral = pos(&out, |o| {
        matches!(
            o,
            Output::Board(Command::Go {
                port_us: 1500,
                vertical_us: 1500,
                starboard_us: 1500
            })
        )
    });
    let disarm = pos(
        &out,
        |o| matches!(o, Output::Log(e) if e.kind == "disarmed"),
    );
    assert!(neutral < disarm);
    assert!(has_text(&out, "Failsafe: lost manual control"));
    // Cleared by input again.
    let out = r.stick(A, 0);
    let mut out2 = out;
    out2.extend(r.run(Duration::from_millis(20)));
    assert!(
        has_text(&out2, "Failsafe cleared: lost manual control"),
        "{:?}",
        texts(&out2)
    );
}

#[test]
fn pilot_input_failsafe_warn_keeps_armed_and_timer_starts_at_arming() {
    let mut r = rig_with(&[("FS_PILOT_INPUT", 1.0)]);
    r.alive.push(A);
    r.arm(A);
    let out = r.run(Duration::from_millis(2900));
    assert!(!has_text(&out, "Failsafe"), "timer starts at arming");
    let out = r.run(Duration::from_millis(300));
    assert!(has_text(&out, "Failsafe: lost manual control"));
    assert!(r.v.armed());
    assert_eq!(
        msgs!(&r.run(Duration::from_secs(1)), HEARTBEAT)
            .pop()
            .unwrap()
            .system_status,
        MavState::MAV_STATE_CRITICAL
    );
}

#[test]
fn board_link_lost_disarms_at_once_and_refuses_arming_until_back() {
    let mut r = driving(A);
    let out = r.link_down("telemetry stale");
    assert!(!r.v.armed());
    assert!(has_text(
        &out,
        "Failsafe: board link lost (telemetry stale)"
    ));
    assert!(has_event(&out, "link_down", None));
    assert!(has_event(&out, "failsafe_raised", Some(255)));
    let out = r.arm(A);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_FAILED
    );
    let out = r.link_up();
    assert!(has_text(&out, "Failsafe cleared: board link lost"));
    r.run(Duration::from_millis(1200));
    assert_eq!(
        ack_of(&r.arm(A), MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
}

#[test]
fn battery_low_acts_after_ten_seconds_and_clears_after_ten_above() {
    let mut r = rig_with(&[("BATT_FS_LOW_ACT", 2.0), ("FS_PILOT_INPUT", 0.0)]);
    r.alive.push(A);
    r.arm(A);
    r.feed.status.vout_v = Some(10.2);
    let out = r.run(Duration::from_secs(9));
    assert!(
        r.v.armed() && !has_text(&out, "Failsafe"),
        "debounced: {:?}",
        texts(&out)
    );
    let out = r.run(Duration::from_secs(2));
    assert!(!r.v.armed());
    assert!(has_text(&out, "Failsafe: battery low 10.2 V"));
    r.feed.status.vout_v = Some(12.0);
    let out = r.run(Duration::from_secs(9));
    assert!(!has_text(&out, "Failsafe cleared"));
    let out = r.run(Duration::from_secs(2));
    assert!(has_text(&out, "Failsafe cleared: battery low"));
}

#[test]
fn depth_hold_action_holds_depth_and_keeps_the_dead_man_fed() {
    let mut r = rig_with(&[("FS_GCS_ENABLE", 3.0), ("FS_PILOT_INPUT", 0.0)]);
    r.arm(A);
    // No heartbeats, but stick input is a sign of life too.
    for _ in 0..60 {
        r.stick(A, 0);
        r.run(Duration::from_millis(100));
    }
    assert!(r.v.armed(), "stick input counts as the owner's life");
    let out = r.run(Duration::from_secs(6));
    assert!(has_text(&out, "Failsafe"), "{:?}", texts(&out));
    assert_eq!(
        r.v.mode().number(),
        2,
        "the GCS failsafe put the vehicle in ALT_HOLD"
    );
    assert!(r.v.armed());
    // The failsafe's own mode needs thrust: the board's dead-man stays fed.
    let out = r.run(Duration::from_secs(3));
    assert!(out.iter().any(|o| matches!(o, Output::Healthy)));
}

#[test]
fn depth_hold_action_disarms_when_depth_hold_is_impossible() {
    let mut r = rig_with(&[("FS_GCS_ENABLE", 3.0), ("FS_PILOT_INPUT", 0.0)]);
    r.arm(A);
    for _ in 0..60 {
        r.stick(A, 0);
        r.run(Duration::from_millis(100));
    }
    // The board link goes down: no depth hold without it.
    r.link_down("test");
    assert!(!r.v.armed(), "the board-link failsafe disarms at once");
}

// ---- the board's dead-man ----

fn healthy(out: &[Output]) -> usize {
    out.iter().filter(|o| matches!(o, Output::Healthy)).count()
}

#[test]
fn the_dead_man_is_fed_by_the_owners_life_while_armed() {
    let mut r = rig_with(&[("FS_PILOT_INPUT", 0.0)]);
    // Disarmed: on every tick (the rig ticks every 10 ms; a navigation line
    // runs the idle tick's work too).
    let fed = healthy(&r.run(Duration::from_secs(1)));
    assert!(fed >= 100, "disarmed: always, fed {fed} times in 1 s");
    r.alive.push(A);
    r.arm(A);
    assert_eq!(
        healthy(&r.run(Duration::from_secs(3))),
        300,
        "owner heartbeats at 1 Hz"
    );
    r.alive.clear();
    let out = r.run(Duration::from_secs(3));
    let fed = healthy(&out);
    assert!(
        (40..=160).contains(&fed),
        "fed for ≤ 1.5 s after the last heartbeat: {fed}"
    );
    assert!(r.v.armed(), "the vehicle's own failsafe comes at 5 s");
    assert_eq!(healthy(&out[out.len() - 100..]), 0);
}

// ---- safety-mode stops from the HMI ----

#[test]
fn a_request_dies_with_its_requesters_hmi_session() {
    // Page A (255) drives, page B (254) asks for control, B's page closes,
    // then A's: nobody may end up in control, least of all the closed B.
    let mut r = driving(A);
    r.alive.push(B);
    r.request_control(B, 1.0, 0.0, 30.0);
    let out = r.input(Input::Hmi {
        sysid: 254,
        event: HmiEvent::Disconnected,
    });
    assert!(
        has_event(&out, "control_request_withdrawn", Some(254)),
        "{out:?}"
    );
    r.alive.retain(|s| s.sysid != 254);
    let out = r.input(Input::Hmi {
        sysid: 255,
        event: HmiEvent::Disconnected,
    });
    assert_eq!(r.v.owner(), None);
    assert!(!has_event(&out, "control_granted", Some(254)));
    assert_eq!(msgs!(&out, CONTROL_STATUS).last().unwrap().gcs_main, 0);
}

#[test]
fn an_owner_leaving_while_armed_raises_the_gcs_failsafe_at_once() {
    // The owner's page closes while armed: the vehicle knows control is
    // gone now, not FS_GCS_TIMEOUT later (nor when the board's dead-man
    // trips because nobody feeds it).
    let mut r = driving(A);
    r.stick(A, 500);
    let mut out = r.input(Input::Hmi {
        sysid: 255,
        event: HmiEvent::Disconnected,
    });
    out.extend(r.run(Duration::from_millis(100)));
    let raised = out.iter().find_map(|o| match o {
        Output::Text {
            topic,
            msg: MavMessage::STATUSTEXT(s),
            ..
        } if *topic == Topic::FailsafeChange(FailsafeKind::Gcs, true) => Some((
            s.severity,
            String::from_utf8_lossy(s.text.as_ref()).into_owned(),
        )),
        _ => None,
    });
    let (severity, text) = raised.expect("the GCS failsafe raised");
    assert_eq!(severity, MavSeverity::MAV_SEVERITY_CRITICAL);
    assert!(
        text.starts_with("Failsafe: GCS 255 left (HMI session closed)"),
        "{text}"
    );
    // FS_GCS_ENABLE's default: disarm.
    assert!(!r.v.armed());
    assert_eq!(r.v.motors_us(), NEUTRAL);

    // Releasing control while armed is the same: nobody drives an armed ROV.
    let mut r = driving(A);
    let mut out = r.request_control(A, 0.0, 0.0, 0.0);
    out.extend(r.run(Duration::from_millis(100)));
    assert!(has_text(&out, "Failsafe: GCS 255 left"), "{out:?}");
    assert!(!r.v.armed());

    // Handed over to a live requester instead: no failsafe.
    let mut r = driving(A);
    r.alive.push(B);
    r.request_control(B, 1.0, 0.0, 30.0);
    let mut out = r.input(Input::Hmi {
        sysid: 255,
        event: HmiEvent::Disconnected,
    });
    out.extend(r.run(Duration::from_millis(500)));
    assert_eq!(r.v.owner(), Some(254));
    assert!(!has_text(&out, "Failsafe:"), "{out:?}");
}

#[test]
fn a_silent_requester_is_not_handed_control() {
    let mut r = driving(A);
    r.alive.push(B);
    r.request_control(B, 1.0, 0.0, 60.0);
    // B's heartbeats stop; A keeps driving.
    r.alive.retain(|s| s.sysid != 254);
    // FS_GCS_TIMEOUT is 5 s.
    let out = r.run(Duration::from_secs(6));
    assert!(has_event(&out, "control_request_withdrawn", Some(254)));
    assert!(has_text(&out, "withdrawn"));
    // The owner releases: nobody had a live request, so nobody gets control.
    let out = r.request_control(A, 0.0, 0.0, 0.0);
    assert_eq!(r.v.owner(), None);
    assert!(!has_event(&out, "control_granted", Some(254)));
}

#[test]
fn hmi_focus_loss_of_the_owner_stops_and_needs_pick_up() {
    let mut r = driving(A);
    let out = r.input(Input::Hmi {
        sysid: 255,
        event: HmiEvent::FocusLost,
    });
    assert_eq!(gos(&out).last(), Some(&NEUTRAL));
    assert!(has_event(&out, "hmi_focus_lost", Some(255)));
    r.stick(A, 500);
    assert_eq!(r.v.motors_us(), NEUTRAL);
    r.stick(A, 0);
    r.stick(A, 500);
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
    // Another session losing focus changes nothing.
    let out = r.input(Input::Hmi {
        sysid: 200,
        event: HmiEvent::FocusLost,
    });
    assert!(gos(&out).is_empty());
    let out = r.input(Input::Hmi {
        sysid: 255,
        event: HmiEvent::Disconnected,
    });
    assert_eq!(r.v.owner(), None);
    assert_eq!(gos(&out).last(), Some(&NEUTRAL));
    assert!(has_event(&out, "control_released", Some(255)));
}

// ---- signing ----

#[test]
fn with_signing_on_unsigned_control_is_refused_and_unsigned_heartbeats_are_no_life() {
    let mut r = rig();
    r.v.set_signing_active(true);
    let signed = Sender { signed: true, ..A };
    let out = r.arm(A);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_DENIED
    );
    assert!(has_text(&out, "unsigned"));
    r.stick(A, 500);
    assert_eq!(r.v.owner(), None);
    let out = r.arm(signed);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
    r.stick(signed, 500);
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
    // Unsigned frames claiming to be A: no effect, and no life.
    let mut out = Vec::new();
    for _ in 0..60 {
        out.extend(r.heartbeat(A));
        out.extend(r.stick(A, -1000));
        out.extend(r.run(Duration::from_millis(100)));
    }
    assert!(!r.v.armed(), "only A's signed traffic keeps it in control");
    assert!(gos(&out).iter().all(|g| g[0] >= 1400));
    // Unsigned watchers still read.
    let out = r.cmd(
        B,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        &[148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_MESSAGE),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let out = r.cmd(A, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0; 7]);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_DENIED
    );
}

fn setup_signing(key: [u8; 32]) -> MavMessage {
    MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
        initial_timestamp: 42,
        target_system: 1,
        target_component: 1,
        secret_key: key,
    })
}

fn key_outputs(out: &[Output]) -> Vec<([u8; 32], u64)> {
    out.iter()
        .filter_map(|o| match o {
            Output::SetSigningKey {
                key,
                initial_timestamp,
            } => Some((*key, *initial_timestamp)),
            _ => None,
        })
        .collect()
}

#[test]
fn setup_signing_only_over_a_trusted_endpoint_and_then_only_signed() {
    let mut r = rig();
    let out = r.msg(A, setup_signing([7; 32]));
    assert!(key_outputs(&out).is_empty());
    assert!(has_text(&out, "not trusted"));
    assert!(has_event(&out, "signing_refused", Some(255)));
    assert!(!r.v.signing_active());
    let trusted = Sender { trusted: true, ..A };
    let out = r.msg(trusted, setup_signing([7; 32]));
    assert_eq!(key_outputs(&out), vec![([7; 32], 42)]);
    assert!(r.v.signing_active());
    assert!(has_event(&out, "signing_key_set", Some(255)));
    for o in &out {
        if let Output::Log(e) = o {
            assert!(!e.detail.contains("7, 7"), "no key in the log: {e:?}");
        }
    }
    // Changing the key now needs a signed frame.
    let out = r.msg(trusted, setup_signing([9; 32]));
    assert!(key_outputs(&out).is_empty());
    let out = r.msg(
        Sender {
            signed: true,
            ..trusted
        },
        setup_signing([0; 32]),
    );
    assert_eq!(key_outputs(&out), vec![([0; 32], 42)]);
    assert!(!r.v.signing_active());
    assert!(has_event(&out, "signing_key_cleared", Some(255)));
}

#[test]
fn autopilot_version_announces_gcs_control() {
    let r = rig();
    let msgs = r.v.build(148, Now::default());
    let MavMessage::AUTOPILOT_VERSION(v) = &msgs[0] else {
        panic!()
    };
    assert!(
        v.capabilities
            .contains(MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_COMPONENT_ACCEPTS_GCS_CONTROL)
    );
}

/// The layout pinned in dialect/neptunus.xml: development.xml of mavlink
/// 0.21.0 (after the April 2026 change): id 512, `flags`, `gcs_main`,
/// `gcs_secondary[10]`, 12-byte payload, CRC_EXTRA 21 (computed from that
/// field list with MAVLink's X.25 rule). A crate update that changes the
/// layout fails here instead of silently talking to a different revision.
#[test]
fn control_status_layout_is_the_pinned_revision() {
    use mavlink_core::Message as _;
    assert_eq!(CONTROL_STATUS_DATA::ENCODED_LEN, 12);
    assert_eq!(MavMessage::extra_crc(512), 21);
    assert_eq!(MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL as u32, 32100);
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    const STATIONS: [Sender; 4] = [A, B, C, STRANGER];

    #[derive(Debug, Clone)]
    enum Act {
        Stick(usize, i16),
        Thrusters(usize, f32),
        MotorTest(usize, f32),
        Arm(usize),
        Disarm(usize),
        Mode(usize, u32),
        Request(usize, bool, f32),
        Release(usize),
        Deny(usize),
        Heartbeat(usize),
        FocusLost(usize),
        Run(u64),
    }

    fn act() -> impl Strategy<Value = Act> {
        let s = 0..STATIONS.len();
        prop_oneof![
            4 => (s.clone(), prop_oneof![Just(0i16), Just(500), Just(-1000), Just(1000), Just(-250)]).prop_map(|(s, x)| Act::Stick(s, x)),
            1 => (s.clone(), prop_oneof![Just(0.0f32), Just(0.5), -1.0f32..1.0]).prop_map(|(s, v)| Act::Thrusters(s, v)),
            1 => (s.clone(), 1100.0f32..1900.0).prop_map(|(s, v)| Act::MotorTest(s, v)),
            2 => s.clone().prop_map(Act::Arm),
            1 => s.clone().prop_map(Act::Disarm),
            1 => (s.clone(), prop_oneof![Just(19u32), Just(100)]).prop_map(|(s, m)| Act::Mode(s, m)),
            2 => (s.clone(), any::<bool>(), 3.0f32..20.0).prop_map(|(s, t, d)| Act::Request(s, t, d)),
            1 => s.clone().prop_map(Act::Release),
            1 => s.clone().prop_map(Act::Deny),
            2 => s.clone().prop_map(Act::Heartbeat),
            1 => s.clone().prop_map(Act::FocusLost),
            3 => (10u64..4000).prop_map(Act::Run),
        ]
    }

    /// What the test itself believes may drive, from what the vehicle published.
    #[derive(Default)]
    struct Model {
        owner: Option<u8>,
        picked_up: bool,
        /// Who may be moving the thrusters now (a station's accepted input).
        motion_from: Option<u8>,
    }

    impl Model {
        /// Follows CONTROL_STATUS and checks every go(): non-neutral only when
        /// armed and the motion came from the published owner after pick-up.
        fn observe(
            &mut self,
            out: &[Output],
            armed_before: bool,
            armed_after: bool,
        ) -> Result<(), TestCaseError> {
            for o in out {
                match o {
                    Output::Send {
                        msg: MavMessage::CONTROL_STATUS(c),
                        ..
                    } => {
                        let new = (c.gcs_main != 0).then_some(c.gcs_main);
                        if new != self.owner {
                            // Pick-up is waived only for claiming a disarmed, unowned vehicle.
                            self.picked_up = self.owner.is_none() && new.is_some() && !armed_before;
                            self.owner = new;
                            self.motion_from = None;
                        }
                    }
                    Output::Board(Command::Go {
                        port_us,
                        vertical_us,
                        starboard_us,
                    }) => {
                        let g = [*port_us, *vertical_us, *starboard_us];
                        if g != NEUTRAL {
                            prop_assert!(armed_after, "non-neutral {g:?} while disarmed");
                            prop_assert!(self.owner.is_some(), "non-neutral {g:?} with no owner");
                            prop_assert_eq!(
                                self.motion_from,
                                self.owner,
                                "non-neutral {:?} not from the owner",
                                g
                            );
                        }
                    }
                    _ => {}
                }
            }
            Ok(())
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        #[test]
        fn thrusters_move_only_for_the_owner_after_pick_up_while_armed(acts in prop::collection::vec(act(), 1..80)) {
            let mut r = rig();
            let mut m = Model::default();
            for a in acts {
                let armed_before = r.v.armed();
                let (out, motion) = match a.clone() {
                    Act::Stick(i, x) => {
                        let out = r.stick(STATIONS[i], x);
                        (out, Some((STATIONS[i].sysid, x == 0, false)))
                    }
                    Act::Thrusters(i, v) => {
                        let out = r.msg(STATIONS[i], MavMessage::NEPTUNUS_THRUSTERS(NEPTUNUS_THRUSTERS_DATA {
                            target_system: 1, target_component: 1, port: v, vertical: v, starboard: v,
                        }));
                        (out, Some((STATIONS[i].sysid, v == 0.0, false)))
                    }
                    Act::MotorTest(i, pwm) => {
                        let out = r.cmd(STATIONS[i], MavCmd::MAV_CMD_DO_MOTOR_TEST, &[1.0, 1.0, pwm, 1.0, 0.0, 0.0, 0.0]);
                        (out, Some((STATIONS[i].sysid, false, true)))
                    }
                    Act::Arm(i) => (r.arm(STATIONS[i]), None),
                    Act::Disarm(i) => (r.cmd(STATIONS[i], MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0; 7]), None),
                    Act::Mode(i, mode) => (r.cmd(STATIONS[i], MavCmd::MAV_CMD_DO_SET_MODE, &[1.0, mode as f32, 0.0, 0.0, 0.0, 0.0, 0.0]), None),
                    Act::Request(i, t, d) => (r.request_control(STATIONS[i], 1.0, if t { 1.0 } else { 0.0 }, d), None),
                    Act::Release(i) => (r.request_control(STATIONS[i], 0.0, 0.0, 0.0), None),
                    Act::Deny(i) => (r.msg(STATIONS[i], MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                        command: MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
                        result: MavResult::MAV_RESULT_DENIED,
                        target_system: 1, target_component: 1, ..Default::default()
                    })), None),
                    Act::Heartbeat(i) => (r.heartbeat(STATIONS[i]), None),
                    Act::FocusLost(i) => {
                        let out = r.input(Input::Hmi { sysid: STATIONS[i].sysid, event: HmiEvent::FocusLost });
                        if m.owner == Some(STATIONS[i].sysid) {
                            m.picked_up = false;
                            m.motion_from = None;
                        }
                        (out, None)
                    }
                    Act::Run(ms) => {
                        // Observed tick by tick: the armed state changes within a run.
                        for _ in 0..ms / 10 {
                            let before = r.v.armed();
                            let out = r.run(Duration::from_millis(10));
                            m.observe(&out, before, r.v.armed())?;
                            if !r.v.armed() {
                                m.motion_from = None;
                            }
                        }
                        (Vec::new(), None)
                    }
                };
                // Outputs up to the input's own go() follow the model's
                // state before the input; then the input itself counts.
                let cs_end = out.iter().rposition(|o| matches!(o, Output::Send { msg: MavMessage::CONTROL_STATUS(_), .. })).map_or(0, |p| p + 1);
                m.observe(&out[..cs_end], armed_before, r.v.armed())?;
                if let Some((sysid, neutral, is_test)) = motion
                    && m.owner == Some(sysid)
                {
                    // Sticks drive in MANUAL, the per-thruster message in
                    // MANUAL_THRUSTERS; each is ignored in the other mode.
                    let thrusters_msg = matches!(a, Act::Thrusters(..));
                    let counts = is_test || thrusters_msg == (r.v.mode().number() == 100);
                    if !counts {
                        // Not this mode's input: no effect on the model.
                    } else if is_test {
                        m.motion_from = Some(sysid);
                    } else if neutral {
                        m.picked_up = true;
                        m.motion_from = None;
                    } else if m.picked_up {
                        m.motion_from = Some(sysid);
                    }
                }
                m.observe(&out[cs_end..], armed_before, r.v.armed())?;
                if !r.v.armed() {
                    m.motion_from = None;
                }
            }
        }
    }
}
