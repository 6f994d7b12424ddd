//! Driving through the vehicle core with synthetic time: stick to `go()`.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

use std::time::Duration;

use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::{Command, Event, NavSample, StatusSample};
use neptunus::firmware::link::LinkState;
use neptunus::vehicle::machine::{Identity, Input, Now, Output, Sender, Vehicle};
use neptunus::vehicle::params::ParamStore;

const GCS: Sender = Sender::new(0, 1, 255, 190);
const STRANGER: Sender = Sender::new(0, 2, 77, 190);

struct Rig {
    v: Vehicle,
    t: Duration,
}

impl Rig {
    fn new() -> Self {
        let mut r = Self {
            v: Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 1),
            t: Duration::ZERO,
        };
        r.input(Input::Link {
            state: LinkState::Up,
            reason: None,
        });
        r.run(Duration::from_millis(1200));
        r
    }
    fn input(&mut self, i: Input) -> Vec<Output> {
        let mut out = Vec::new();
        let now = Now {
            mono: self.t,
            unix_us: 0,
        };
        self.v.handle(i, now, &mut out);
        out
    }
    /// Ticks at 100 Hz with board telemetry at 10 Hz / 1 Hz.
    fn run(&mut self, d: Duration) -> Vec<Output> {
        let end = self.t + d;
        let mut all = Vec::new();
        while self.t < end {
            self.t += Duration::from_millis(10);
            if self.t.as_millis().is_multiple_of(100) {
                all.extend(self.input(Input::Board(Event::Nav(NavSample {
                    heading_deg: Some(10.0),
                    depth_m: Some(1.0),
                    pitch_deg: Some(0.0),
                    roll_deg: Some(0.0),
                    yaw_deg: Some(10.0),
                    fthr_pct: Some(0.0),
                }))));
            }
            if self.t.as_millis().is_multiple_of(1000) {
                all.extend(self.input(Input::Board(Event::Status(StatusSample {
                    vout_v: Some(12.0),
                    btti_a: Some(0.5),
                    pres_mbar: Some(1113.0),
                    ..Default::default()
                }))));
            }
            all.extend(self.input(Input::Tick));
        }
        all
    }
    fn arm(&mut self) {
        let out = self.cmd(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert!(self.v.armed(), "{out:?}");
    }
    fn cmd(&mut self, command: MavCmd, p: [f32; 7]) -> Vec<Output> {
        self.input(Input::Mavlink {
            from: GCS,
            msg: MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: p[0],
                param2: p[1],
                param3: p[2],
                param4: p[3],
                command,
                target_system: 1,
                target_component: 1,
                ..Default::default()
            }),
        })
    }
    fn stick(&mut self, from: Sender, x: i16, z: i16, r: i16, buttons: u16) -> Vec<Output> {
        self.input(Input::Mavlink {
            from,
            msg: MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
                x,
                y: 0,
                z,
                r,
                buttons,
                target: 1,
                ..Default::default()
            }),
        })
    }
}

fn gos(out: &[Output]) -> Vec<[u16; 3]> {
    out.iter()
        .filter_map(|o| match o {
            Output::Board(Command::Go {
                port_us,
                vertical_us,
                starboard_us,
            }) => Some([*port_us, *vertical_us, *starboard_us]),
            _ => None,
        })
        .collect()
}

fn texts(out: &[Output]) -> Vec<String> {
    out.iter()
        .filter_map(|o| match o {
            Output::Send {
                msg: MavMessage::STATUSTEXT(s),
                ..
            } => {
                let b: &[u8] = s.text.as_ref();
                Some(String::from_utf8_lossy(b).trim_end_matches('\0').to_owned())
            }
            _ => None,
        })
        .collect()
}

#[test]
fn ardusub_worked_example_half_stick_at_half_gain_is_a_quarter_thrust() {
    let mut r = Rig::new();
    r.arm();
    let out = r.stick(GCS, 500, 500, 0, 0);
    // Port wired reversed (MOT_2_DIRECTION = -1): 1500 − 0.25·400; starboard 1500 + 0.25·400.
    assert_eq!(gos(&out), vec![[1400, 1500, 1600]]);
    assert_eq!(r.v.motors_us(), [1400, 1500, 1600]);
}

#[test]
fn yaw_to_starboard_drives_port_forward_and_starboard_back() {
    let mut r = Rig::new();
    r.arm();
    let out = r.stick(GCS, 0, 500, 1000, 0);
    // u_port = k·M = 0.5 → reversed wiring → 1300; u_star = −0.5 → 1300.
    assert_eq!(gos(&out), vec![[1300, 1500, 1300]]);
    let out = r.stick(GCS, 0, 0, 0, 0);
    // z = 0 is full down in the 0..1000 convention: heave +1 (down) · gain 0.5.
    assert_eq!(gos(&out), vec![[1500, 1700, 1500]]);
}

#[test]
fn disarmed_input_never_moves_a_thruster() {
    let mut r = Rig::new();
    let mut out = r.stick(GCS, 1000, 1000, -1000, 0);
    out.extend(r.run(Duration::from_millis(200)));
    assert!(gos(&out).iter().all(|g| *g == [1500; 3]), "{:?}", gos(&out));
}

#[test]
fn a_station_not_allowed_cannot_drive_and_is_reported_once() {
    let mut r = Rig::new();
    r.arm();
    let mut out = Vec::new();
    for _ in 0..50 {
        out.extend(r.stick(STRANGER, 1000, 500, 0, 0));
        out.extend(r.run(Duration::from_millis(40)));
    }
    assert!(gos(&out).iter().all(|g| *g == [1500; 3]));
    assert_eq!(r.v.refused_inputs(), 50);
    let reports = texts(&out)
        .iter()
        .filter(|t| t.contains("sysid 77"))
        .count();
    assert_eq!(reports, 1, "rate-limited: {:?}", texts(&out));
}

#[test]
fn lost_pilot_input_goes_neutral_after_fs_pilot_timeout() {
    let mut r = Rig::new();
    r.arm();
    r.stick(GCS, 1000, 500, 0, 0);
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
    let mut r = Rig::new();
    r.arm();
    r.stick(GCS, 1000, 500, 0, 0);
    let out = r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]);
    assert_eq!(gos(&out).last(), Some(&[1500; 3]));
    let out = r.stick(GCS, 1000, 500, 0, 0);
    assert!(gos(&out).iter().all(|g| *g == [1500; 3]));
}

#[test]
fn mode_change_is_a_safety_stop() {
    let mut r = Rig::new();
    r.arm();
    r.stick(GCS, 1000, 500, 0, 0);
    let out = r.cmd(
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(gos(&out).last(), Some(&[1500; 3]));
}

#[test]
fn buttons_act_on_the_press_edge_only() {
    let mut r = Rig::new();
    // Default map: button 6 = arm, 4 = disarm, 11 = gain_inc.
    r.stick(GCS, 0, 500, 0, 1 << 6);
    assert!(r.v.armed());
    let out = r.stick(GCS, 0, 500, 0, 1 << 11);
    assert!(
        texts(&out).contains(&"#Gain is 75%".to_owned()),
        "{:?}",
        texts(&out)
    );
    // Held: no repeat.
    let out = r.stick(GCS, 0, 500, 0, 1 << 11);
    assert!(texts(&out).is_empty());
    r.stick(GCS, 0, 500, 0, 0);
    let out = r.stick(GCS, 500, 500, 0, 0);
    // Gain 0.75 now: 0.5 · 0.75 · 400 = 150.
    assert_eq!(gos(&out), vec![[1350, 1500, 1650]]);
    r.stick(GCS, 0, 500, 0, 1 << 4);
    assert!(!r.v.armed());
}

#[test]
fn lights_buttons_step_the_board_lights() {
    let mut r = Rig::new();
    // 14 = lights1_brighter, 13 = dimmer; JS_LIGHTS_STEPS 8 over 0..255.
    let out = r.stick(GCS, 0, 500, 0, 1 << 14);
    assert!(out.contains(&Output::Board(Command::Lights(31))), "{out:?}");
    r.stick(GCS, 0, 500, 0, 0);
    let out = r.stick(GCS, 0, 500, 0, 1 << 13);
    assert!(out.contains(&Output::Board(Command::Lights(0))));
}

#[test]
fn rc_override_forward_drives_and_release_stops() {
    let mut r = Rig::new();
    r.arm();
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
    let mut r = Rig::new();
    r.arm();
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
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    let out = r.input(Input::Mavlink { from: GCS, msg });
    // Port full forward at gain 0.5, reversed wiring: 1500 − 0.5·400.
    assert_eq!(gos(&out), vec![[1300, 1500, 1500]]);
}

#[test]
fn motor_test_needs_arming_and_stops_without_repeats() {
    let mut r = Rig::new();
    let out = r.cmd(
        MavCmd::MAV_CMD_DO_MOTOR_TEST,
        [1.0, 1.0, 1600.0, 2.0, 0.0, 0.0, 0.0],
    );
    assert!(texts(&out).iter().any(|t| t.contains("arm")));
    assert!(gos(&out).iter().all(|g| *g == [1500; 3]), "{:?}", gos(&out));
    r.arm();
    let out = r.cmd(
        MavCmd::MAV_CMD_DO_MOTOR_TEST,
        [1.0, 1.0, 1600.0, 2.0, 0.0, 0.0, 0.0],
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
    let mut r = Rig::new();
    r.arm();
    r.stick(GCS, 500, 500, 0, 1 << 8);
    r.stick(GCS, 0, 500, 0, 0);
    assert_eq!(
        r.v.motors_us(),
        [1400, 1500, 1600],
        "held forward with the stick released"
    );
    r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]);
    r.arm();
    r.stick(GCS, 0, 500, 0, 0);
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
            let mut r = Rig::new();
            for (ch, arm, wait_ms) in steps {
                let mut out = if arm {
                    r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
                } else {
                    r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7])
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
            let mut r = Rig::new();
            for (x, z, yaw, buttons, sysid, wait_ms) in inputs {
                let from = Sender::new(0, u64::from(sysid), sysid, 190);
                let mut out = r.stick(from, x, z, yaw, buttons);
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
    let mut r = Rig::new();
    r.arm();
    for timeout_s in [1e30f32, f32::INFINITY, f32::NAN, -5.0, f32::MAX] {
        r.cmd(
            MavCmd::MAV_CMD_DO_MOTOR_TEST,
            [3.0, 0.0, 75.0, timeout_s, 0.0, 0.0, 0.0],
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
    let mut r = Rig::new();
    let as_stranger = |r: &mut Rig, command: MavCmd, p: [f32; 7]| {
        r.input(Input::Mavlink {
            from: STRANGER,
            msg: MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: p[0],
                param2: p[1],
                param3: p[2],
                command,
                target_system: 1,
                target_component: 1,
                ..Default::default()
            }),
        })
    };
    let ack = |out: &[Output]| {
        out.iter()
            .find_map(|o| match o {
                Output::Send {
                    msg: MavMessage::COMMAND_ACK(a),
                    ..
                } => Some(a.result),
                _ => None,
            })
            .unwrap()
    };
    let out = as_stranger(
        &mut r,
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(ack(&out), MavResult::MAV_RESULT_NOT_IN_CONTROL);
    assert!(!r.v.armed());
    r.arm();
    let out = as_stranger(
        &mut r,
        MavCmd::MAV_CMD_DO_MOTOR_TEST,
        [1.0, 1.0, 1700.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(ack(&out), MavResult::MAV_RESULT_NOT_IN_CONTROL);
    assert!(gos(&out).is_empty());
    assert_eq!(r.v.motors_us(), [1500; 3]);
    let out = as_stranger(&mut r, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]);
    assert_eq!(ack(&out), MavResult::MAV_RESULT_ACCEPTED);
    assert!(!r.v.armed());
}
