//! Driving through the vehicle core with synthetic time: stick to `go()`.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, acks, gos, statustexts};
use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::Command;
use neptunus::vehicle::machine::{Identity, Input, Output, Sender, Vehicle};
use neptunus::vehicle::params::ParamStore;

const GCS: Sender = Sender::new(0, 1, 255, 190);
const STRANGER: Sender = Sender::new(0, 2, 77, 190);

/// Board link up and telemetry flowing for 1.2 s: ready to arm. One endpoint.
fn rig() -> CoreRig {
    CoreRig::new(Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 1))
        .unix_epoch(0)
        .started()
}

/// Arms from the GCS, and checks it did.
fn arm(r: &mut CoreRig) {
    let out = r.arm(GCS);
    assert!(r.v.armed(), "{out:?}");
}

#[test]
fn ardusub_worked_example_half_stick_at_half_gain_is_a_quarter_thrust() {
    let mut r = rig();
    arm(&mut r);
    let out = r.manual(GCS, 500, 500, 0, 0);
    // Port wired reversed (MOT_2_DIRECTION = -1): 1500 − 0.25·400; starboard 1500 + 0.25·400.
    assert_eq!(gos(&out), vec![[1400, 1500, 1600]]);
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
}

#[test]
fn yaw_to_starboard_drives_port_forward_and_starboard_back() {
    let mut r = rig();
    arm(&mut r);
    let out = r.manual(GCS, 0, 500, 1000, 0);
    // u_port = k·M = 0.5 → reversed wiring → 1300; u_star = −0.5 → 1300.
    assert_eq!(gos(&out), vec![[1300, 1500, 1300]]);
    let out = r.manual(GCS, 0, 0, 0, 0);
    // z = 0 is full down in the 0..1000 convention: heave +1 (down) · gain 0.5.
    assert_eq!(gos(&out), vec![[1500, 1700, 1500]]);
}

#[test]
fn disarmed_input_never_moves_a_thruster() {
    let mut r = rig();
    let mut out = r.manual(GCS, 1000, 1000, -1000, 0);
    out.extend(r.run(Duration::from_millis(200)));
    assert!(gos(&out).iter().all(|g| *g == [1500; 3]), "{:?}", gos(&out));
}

#[test]
fn a_station_not_allowed_cannot_drive_and_is_reported_once() {
    let mut r = rig();
    arm(&mut r);
    let mut out = Vec::new();
    for _ in 0..50 {
        out.extend(r.manual(STRANGER, 1000, 500, 0, 0));
        out.extend(r.run(Duration::from_millis(40)));
    }
    assert!(gos(&out).iter().all(|g| *g == [1500; 3]));
    assert_eq!(r.v.refused_inputs(), 50);
    let reports = statustexts(&out)
        .iter()
        .filter(|t| t.contains("sysid 77"))
        .count();
    assert_eq!(reports, 1, "rate-limited: {:?}", statustexts(&out));
}

#[test]
fn lost_pilot_input_goes_neutral_after_fs_pilot_timeout() {
    let mut r = rig();
    arm(&mut r);
    r.manual(GCS, 1000, 500, 0, 0);
    assert_ne!(r.v.motors_us(), [1500; 3]);
    r.run(Duration::from_millis(2900));
    assert_ne!(
        r.v.motors_us(),
        [1500; 3],
        "still fresh before FS_PILOT_TIMEOUT (3 s)"
    );
    let out = r.run(Duration::from_millis(200));
    assert_eq!(r.v.motors_us(), [1500; 3]);
    assert!(gos(&out).contains(&[1500; 3]));
}

#[test]
fn disarm_is_neutral_within_one_command_cycle() {
    let mut r = rig();
    arm(&mut r);
    r.manual(GCS, 1000, 500, 0, 0);
    let out = r.cmd(GCS, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0; 7]);
    assert_eq!(gos(&out).last(), Some(&[1500; 3]));
    let out = r.manual(GCS, 1000, 500, 0, 0);
    assert!(gos(&out).iter().all(|g| *g == [1500; 3]));
}

#[test]
fn mode_change_is_a_safety_stop() {
    let mut r = rig();
    arm(&mut r);
    r.manual(GCS, 1000, 500, 0, 0);
    let out = r.cmd(
        GCS,
        MavCmd::MAV_CMD_DO_SET_MODE,
        &[1.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(gos(&out).last(), Some(&[1500; 3]));
}

#[test]
fn buttons_act_on_the_press_edge_only() {
    let mut r = rig();
    // Default map: button 6 = arm, 4 = disarm, 11 = gain_inc.
    r.manual(GCS, 0, 500, 0, 1 << 6);
    assert!(r.v.armed());
    let out = r.manual(GCS, 0, 500, 0, 1 << 11);
    assert!(
        statustexts(&out).contains(&"#Gain is 75%".to_owned()),
        "{:?}",
        statustexts(&out)
    );
    // Held: no repeat.
    let out = r.manual(GCS, 0, 500, 0, 1 << 11);
    assert!(statustexts(&out).is_empty());
    r.manual(GCS, 0, 500, 0, 0);
    let out = r.manual(GCS, 500, 500, 0, 0);
    // Gain 0.75 now: 0.5 · 0.75 · 400 = 150.
    assert_eq!(gos(&out), vec![[1350, 1500, 1650]]);
    r.manual(GCS, 0, 500, 0, 1 << 4);
    assert!(!r.v.armed());
}

#[test]
fn lights_buttons_step_the_board_lights() {
    let mut r = rig();
    // 14 = lights1_brighter, 13 = dimmer; JS_LIGHTS_STEPS 8 over 0..255.
    let out = r.manual(GCS, 0, 500, 0, 1 << 14);
    assert!(out.contains(&Output::Board(Command::Lights(31))), "{out:?}");
    r.manual(GCS, 0, 500, 0, 0);
    let out = r.manual(GCS, 0, 500, 0, 1 << 13);
    assert!(out.contains(&Output::Board(Command::Lights(0))));
}

#[test]
fn rc_override_forward_drives_and_release_stops() {
    let mut r = rig();
    arm(&mut r);
    let mut ch = RC_CHANNELS_OVERRIDE_DATA {
        target_system: 1,
        target_component: 1,
        ..Default::default()
    };
    for c in [
        &mut ch.chan1_raw,
        &mut ch.chan2_raw,
        &mut ch.chan3_raw,
        &mut ch.chan4_raw,
        &mut ch.chan6_raw,
        &mut ch.chan7_raw,
        &mut ch.chan8_raw,
    ] {
        *c = u16::MAX;
    }
    ch.chan5_raw = 1700;
    let out = r.input(Input::Mavlink {
        from: GCS,
        msg: MavMessage::RC_CHANNELS_OVERRIDE(ch.clone()),
    });
    // (1700−1500)/400 = 0.5 forward · gain 0.5.
    assert_eq!(gos(&out), vec![[1400, 1500, 1600]]);
    ch.chan5_raw = 0;
    let out = r.input(Input::Mavlink {
        from: GCS,
        msg: MavMessage::RC_CHANNELS_OVERRIDE(ch),
    });
    assert_eq!(gos(&out), vec![[1500; 3]]);
}

#[test]
fn per_thruster_message_spins_only_the_named_thruster_in_its_mode() {
    let mut r = rig();
    arm(&mut r);
    let msg = MavMessage::NEPTUNUS_THRUSTERS(NEPTUNUS_THRUSTERS_DATA {
        port: 1.0,
        vertical: f32::NAN,
        starboard: 0.0,
        target_system: 1,
        target_component: 1,
    });
    let out = r.input(Input::Mavlink {
        from: GCS,
        msg: msg.clone(),
    });
    assert!(
        gos(&out).iter().all(|g| *g == [1500; 3]),
        "ignored outside MANUAL_THRUSTERS"
    );
    r.cmd(
        GCS,
        MavCmd::MAV_CMD_DO_SET_MODE,
        &[1.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    let out = r.input(Input::Mavlink { from: GCS, msg });
    // Port full forward at gain 0.5, reversed wiring: 1500 − 0.5·400.
    assert_eq!(gos(&out), vec![[1300, 1500, 1500]]);
}

#[test]
fn motor_test_needs_arming_and_stops_without_repeats() {
    let mut r = rig();
    let out = r.cmd(
        GCS,
        MavCmd::MAV_CMD_DO_MOTOR_TEST,
        &[1.0, 1.0, 1600.0, 2.0, 0.0, 0.0, 0.0],
    );
    assert!(statustexts(&out).iter().any(|t| t.contains("arm")));
    assert!(gos(&out).iter().all(|g| *g == [1500; 3]), "{:?}", gos(&out));
    arm(&mut r);
    let out = r.cmd(
        GCS,
        MavCmd::MAV_CMD_DO_MOTOR_TEST,
        &[1.0, 1.0, 1600.0, 2.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(
        gos(&out),
        vec![[1500, 1500, 1600]],
        "motor 1 is the starboard thruster"
    );
    r.run(Duration::from_millis(400));
    assert_eq!(r.v.motors_us(), [1500, 1500, 1600]);
    r.run(Duration::from_millis(200));
    assert_eq!(
        r.v.motors_us(),
        [1500; 3],
        "stops 0.5 s after the last command"
    );
}

#[test]
fn input_hold_latches_and_disarm_clears_it() {
    let mut r = rig();
    arm(&mut r);
    r.manual(GCS, 500, 500, 0, 1 << 8);
    r.manual(GCS, 0, 500, 0, 0);
    assert_eq!(
        r.v.motors_us(),
        [1400, 1500, 1600],
        "held forward with the stick released"
    );
    r.cmd(GCS, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0; 7]);
    arm(&mut r);
    r.manual(GCS, 0, 500, 0, 0);
    assert_eq!(r.v.motors_us(), [1500; 3]);
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    fn rc(ch: [u16; 10]) -> MavMessage {
        MavMessage::RC_CHANNELS_OVERRIDE(RC_CHANNELS_OVERRIDE_DATA {
            chan1_raw: ch[0],
            chan2_raw: ch[1],
            chan3_raw: ch[2],
            chan4_raw: ch[3],
            chan5_raw: ch[4],
            chan6_raw: ch[5],
            chan7_raw: ch[6],
            chan8_raw: ch[7],
            chan9_raw: ch[8],
            chan10_raw: ch[9],
            target_system: 1,
            target_component: 1,
            ..Default::default()
        })
    }

    fn channel() -> impl Strategy<Value = u16> {
        prop_oneof![
            Just(0u16),
            Just(u16::MAX),
            Just(65534),
            900u16..2100,
            any::<u16>()
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// RC overrides with any channel values, mixed with arming: go() stays
        /// within MOT_PWM_MIN..MAX and is neutral whenever disarmed.
        #[test]
        fn rc_override_values_stay_in_range(
            steps in prop::collection::vec((prop::array::uniform10(channel()), any::<bool>(), 0u64..300), 1..40)
        ) {
            let mut r = rig();
            for (ch, arm, wait_ms) in steps {
                let mut out = if arm {
                    r.cmd(GCS, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
                } else {
                    r.cmd(GCS, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0; 7])
                };
                out.extend(r.input(Input::Mavlink { from: GCS, msg: rc(ch) }));
                out.extend(r.run(Duration::from_millis(wait_ms)));
                for g in gos(&out) {
                    prop_assert!(g.iter().all(|us| (1100..=1900).contains(us)), "{:?}", g);
                    if !arm {
                        prop_assert_eq!(g, [1500; 3]);
                    }
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Whatever the sticks, buttons and senders: every go() is within
        /// MOT_PWM_MIN..MAX, and neutral whenever the vehicle is disarmed.
        #[test]
        fn go_is_in_range_and_neutral_when_disarmed(
            inputs in prop::collection::vec((any::<i16>(), any::<i16>(), any::<i16>(), any::<u16>(), prop_oneof![Just(255u8), Just(245), Just(77)], 0u64..200), 1..60)
        ) {
            let mut r = rig();
            for (x, z, yaw, buttons, sysid, wait_ms) in inputs {
                let from = Sender::new(0, u64::from(sysid), sysid, 190);
                let mut out = r.manual(from, x, z, yaw, buttons);
                let armed_after_input = r.v.armed();
                out.extend(r.run(Duration::from_millis(wait_ms)));
                for g in gos(&out) {
                    prop_assert!(g.iter().all(|us| (1100..=1900).contains(us)), "{:?}", g);
                }
                if !r.v.armed() && !armed_after_input {
                    prop_assert!(gos(&out).iter().all(|g| *g == [1500; 3]));
                }
            }
        }
    }
}

#[test]
fn motor_test_with_absurd_timeouts_is_capped_not_a_panic() {
    let mut r = rig();
    arm(&mut r);
    for timeout_s in [1e30f32, f32::INFINITY, f32::NAN, -5.0, f32::MAX] {
        r.cmd(
            GCS,
            MavCmd::MAV_CMD_DO_MOTOR_TEST,
            &[3.0, 0.0, 75.0, timeout_s, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            r.v.motors_us(),
            [1500, 1700, 1500],
            "motor 3 is the vertical thruster (p4 {timeout_s})"
        );
        r.run(Duration::from_millis(600));
        assert_eq!(
            r.v.motors_us(),
            [1500; 3],
            "stopped 0.5 s later whatever p4 said ({timeout_s})"
        );
    }
}

#[test]
fn a_station_not_allowed_can_neither_arm_nor_motor_test_but_can_disarm() {
    let mut r = rig();
    // The result of the first COMMAND_ACK.
    let ack = |out: &[Output]| acks(out)[0].result;
    let out = r.cmd(
        STRANGER,
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(ack(&out), MavResult::MAV_RESULT_NOT_IN_CONTROL);
    assert!(!r.v.armed());
    arm(&mut r);
    let out = r.cmd(
        STRANGER,
        MavCmd::MAV_CMD_DO_MOTOR_TEST,
        &[1.0, 1.0, 1700.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(ack(&out), MavResult::MAV_RESULT_NOT_IN_CONTROL);
    assert!(gos(&out).is_empty());
    assert_eq!(r.v.motors_us(), [1500; 3]);
    let out = r.cmd(STRANGER, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0; 7]);
    assert_eq!(ack(&out), MavResult::MAV_RESULT_ACCEPTED);
    assert!(!r.v.armed());
}
