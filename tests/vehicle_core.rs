//! The vehicle core with synthetic time: identity, telemetry, commands,
//! parameters, missions and FTP — every rule a ground station relies on.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

use std::time::Duration;

use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::{Command, Event, NavSample, StatusSample};
use neptunus::firmware::link::LinkState;
use neptunus::vehicle::machine::{Identity, Input, Now, Output, Sender, To, Vehicle};
use neptunus::vehicle::params::ParamStore;

const QGC: Sender = Sender::new(0, 7, 255, 190);

struct Rig {
    v: Vehicle,
    t: Duration,
    out: Vec<Output>,
}

impl Rig {
    fn new() -> Self {
        let mut r = Self {
            v: Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 2),
            t: Duration::ZERO,
            out: Vec::new(),
        };
        r.input(Input::Tick);
        r
    }
    fn now(&self) -> Now {
        Now {
            mono: self.t,
            unix_us: 1_700_000_000_000_000 + self.t.as_micros() as u64,
        }
    }
    fn input(&mut self, i: Input) -> Vec<Output> {
        let mut out = Vec::new();
        let now = self.now();
        self.v.handle(i, now, &mut out);
        self.out.extend(out.iter().cloned());
        out
    }
    /// Advances time in 10 ms ticks, feeding board telemetry at 10 Hz / 1 Hz if `board` is on.
    fn run(&mut self, d: Duration, board: bool) -> Vec<Output> {
        let end = self.t + d;
        let mut all = Vec::new();
        while self.t < end {
            self.t += Duration::from_millis(10);
            if board && self.t.as_millis().is_multiple_of(100) {
                all.extend(self.input(Input::Board(Event::Nav(NavSample {
                    heading_deg: Some(90.0),
                    depth_m: Some(1.5),
                    pitch_deg: Some(1.0),
                    roll_deg: Some(-2.0),
                    yaw_deg: Some(90.0),
                    fthr_pct: Some(0.0),
                }))));
            }
            if board && self.t.as_millis().is_multiple_of(1000) {
                all.extend(self.input(Input::Board(Event::Status(StatusSample {
                    vout_v: Some(12.0),
                    iout_a: Some(0.3),
                    btti_a: Some(0.3),
                    pres_mbar: Some(1162.0),
                    temp_c: Some(18.0),
                    time_ms: Some(self.t.as_millis() as u64),
                    ..Default::default()
                }))));
            }
            all.extend(self.input(Input::Tick));
        }
        all
    }
    fn link_up(&mut self) {
        self.input(Input::Link {
            state: LinkState::Up,
            reason: None,
        });
        self.run(Duration::from_millis(1100), true);
    }
    fn cmd(&mut self, command: MavCmd, p: [f32; 7]) -> Vec<Output> {
        self.input(Input::Mavlink {
            from: QGC,
            msg: MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: p[0],
                param2: p[1],
                param3: p[2],
                param4: p[3],
                param5: p[4],
                param6: p[5],
                param7: p[6],
                command,
                target_system: 1,
                target_component: 1,
                confirmation: 0,
            }),
        })
    }
    fn msg(&mut self, msg: MavMessage) -> Vec<Output> {
        self.input(Input::Mavlink { from: QGC, msg })
    }
}

fn sent(out: &[Output]) -> Vec<(To, MavMessage)> {
    out.iter()
        .filter_map(|o| match o {
            Output::Send { to, msg } => Some((*to, msg.clone())),
            _ => None,
        })
        .collect()
}

fn acks(out: &[Output]) -> Vec<COMMAND_ACK_DATA> {
    sent(out)
        .into_iter()
        .filter_map(|(_, m)| match m {
            MavMessage::COMMAND_ACK(a) => Some(a),
            _ => None,
        })
        .collect()
}

fn texts(out: &[Output]) -> Vec<String> {
    sent(out)
        .into_iter()
        .filter_map(|(_, m)| match m {
            MavMessage::STATUSTEXT(s) => {
                let b: &[u8] = s.text.as_ref();
                Some(String::from_utf8_lossy(b).trim_end_matches('\0').to_owned())
            }
            _ => None,
        })
        .collect()
}

fn count(out: &[Output], id: u32, to: To) -> usize {
    sent(out)
        .iter()
        .filter(|(t, m)| *t == to && neptunus::dialect::neptunus::MavMessage::message_id(m) == id)
        .count()
}

use mavlink_core::Message as _;

const NAN7: [f32; 7] = [f32::NAN; 7];

fn p(v: &[f32]) -> [f32; 7] {
    let mut a = [0.0; 7];
    a[..v.len()].copy_from_slice(v);
    a
}

#[test]
fn heartbeat_at_1_hz_on_every_endpoint_as_ardusub() {
    let mut r = Rig::new();
    let out = r.run(Duration::from_secs(5), false);
    for ep in [0, 1] {
        let n = count(&out, 0, To::Endpoint(ep));
        assert!((5..=6).contains(&n), "endpoint {ep}: {n} heartbeats in 5 s");
    }
    let hb = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::HEARTBEAT(h) = m {
                Some(h)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!(hb.mavtype, MavType::MAV_TYPE_SUBMARINE);
    assert_eq!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    assert_eq!(hb.custom_mode, 19);
    assert_eq!(hb.mavlink_version, 3);
    assert!(
        hb.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
    );
    assert!(
        !hb.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
    );
    // Board link down at start: critical.
    assert_eq!(hb.system_status, MavState::MAV_STATE_CRITICAL);
}

#[test]
fn generic_identity_changes_the_autopilot_field() {
    let mut v = Vehicle::new(Identity::Generic, ParamStore::defaults(), 1);
    let mut out = Vec::new();
    v.handle(Input::Tick, Now::default(), &mut out);
    let hb = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::HEARTBEAT(h) = m {
                Some(h)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_GENERIC);
}

#[test]
fn no_attitude_or_depth_while_the_board_link_is_down() {
    let mut r = Rig::new();
    r.link_up();
    let out = r.run(Duration::from_secs(1), true);
    assert!(
        count(&out, 30, To::Endpoint(0)) >= 9,
        "ATTITUDE at 10 Hz while up"
    );
    assert!(count(&out, 33, To::Endpoint(0)) >= 2);
    let out = r.input(Input::Link {
        state: LinkState::Down,
        reason: Some("device closed".into()),
    });
    assert!(
        texts(&out)
            .iter()
            .any(|t| t.contains("Board link down") && t.contains("device closed")),
        "{:?}",
        texts(&out)
    );
    let out = r.run(Duration::from_secs(2), false);
    assert_eq!(
        count(&out, 30, To::Endpoint(0)),
        0,
        "stale attitude must not be re-sent"
    );
    assert_eq!(count(&out, 33, To::Endpoint(0)), 0);
    assert_eq!(count(&out, 74, To::Endpoint(0)), 0);
    let sys = sent(&out)
        .into_iter()
        .rev()
        .find_map(|(_, m)| {
            if let MavMessage::SYS_STATUS(s) = m {
                Some(s)
            } else {
                None
            }
        })
        .unwrap();
    assert!(
        !sys.onboard_control_sensors_health
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK)
    );
    assert!(
        !sys.onboard_control_sensors_health
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE)
    );
    assert!(
        sys.onboard_control_sensors_present
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK)
    );
    // No fence: GEOFENCE healthy (as ArduPilot), else MAVProxy reports a breach.
    assert!(
        sys.onboard_control_sensors_health
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_GEOFENCE)
    );
    assert!(
        !sys.onboard_control_sensors_present
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_GEOFENCE)
    );
}

#[test]
fn ready_when_link_up_and_fresh() {
    let mut r = Rig::new();
    r.link_up();
    let out = r.run(Duration::from_secs(1), true);
    let sys = sent(&out)
        .into_iter()
        .rev()
        .find_map(|(_, m)| {
            if let MavMessage::SYS_STATUS(s) = m {
                Some(s)
            } else {
                None
            }
        })
        .unwrap();
    assert!(
        sys.onboard_control_sensors_health
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK)
    );
    assert!(
        sys.onboard_control_sensors_enabled
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK)
    );
    assert_eq!(sys.voltage_battery, 12000);
    let gpi = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::GLOBAL_POSITION_INT(g) = m {
                Some(g)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!(gpi.relative_alt, -1500);
    assert_eq!(gpi.hdg, 9000);
    let hud = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::VFR_HUD(h) = m {
                Some(h)
            } else {
                None
            }
        })
        .unwrap();
    assert!((hud.alt + 1.5).abs() < 1e-6);
    let att = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::ATTITUDE(a) = m {
                Some(a)
            } else {
                None
            }
        })
        .unwrap();
    assert!((att.yaw - std::f32::consts::FRAC_PI_2).abs() < 1e-4);
}

#[test]
fn arming_refused_with_a_reason_while_link_down_even_forced() {
    let mut r = Rig::new();
    let out = r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, p(&[1.0, 2989.0]));
    let a = acks(&out);
    assert_eq!(a.len(), 1);
    assert_eq!(a[0].result, MavResult::MAV_RESULT_FAILED);
    assert!(
        texts(&out).iter().any(|t| t.contains("board link down")),
        "{:?}",
        texts(&out)
    );
    assert!(!r.v.armed());
}

#[test]
fn arm_and_disarm_are_acknowledged_once_and_idempotent() {
    let mut r = Rig::new();
    r.link_up();
    for _ in 0..2 {
        let out = r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, p(&[1.0]));
        let a = acks(&out);
        assert_eq!(a.len(), 1);
        assert_eq!(a[0].result, MavResult::MAV_RESULT_ACCEPTED);
        assert_eq!((a[0].target_system, a[0].target_component), (255, 190));
        assert_eq!(a[0].command, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
    }
    assert!(r.v.armed());
    let out = r.run(Duration::from_millis(1100), true);
    let hb = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::HEARTBEAT(h) = m {
                Some(h)
            } else {
                None
            }
        })
        .unwrap();
    assert!(
        hb.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
    );
    assert_eq!(hb.system_status, MavState::MAV_STATE_ACTIVE);
    let out = r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, p(&[0.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    assert!(!r.v.armed());
    assert!(out.contains(&Output::Board(Command::Go {
        port_us: 1500,
        vertical_us: 1500,
        starboard_us: 1500
    })));
}

#[test]
fn board_link_loss_disarms() {
    let mut r = Rig::new();
    r.link_up();
    r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, p(&[1.0]));
    assert!(r.v.armed());
    let out = r.input(Input::Link {
        state: LinkState::Down,
        reason: Some("read failed".into()),
    });
    assert!(!r.v.armed());
    assert!(texts(&out).iter().any(|t| t.contains("Disarmed")));
}

#[test]
fn modes_follow_ardusub_numbers_and_unavailable_ones_are_refused_with_a_reason() {
    let mut r = Rig::new();
    let out = r.cmd(MavCmd::MAV_CMD_DO_SET_MODE, p(&[1.0, 19.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let out = r.cmd(MavCmd::MAV_CMD_DO_SET_MODE, p(&[1.0, 16.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_FAILED);
    assert!(
        texts(&out)
            .iter()
            .any(|t| t.contains("POSHOLD") && t.contains("position")),
        "{:?}",
        texts(&out)
    );
    // ALT_HOLD needs a depth estimate: refused with the reason before telemetry.
    let out = r.cmd(MavCmd::MAV_CMD_DO_SET_MODE, p(&[1.0, 2.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_FAILED);
    assert!(
        texts(&out)
            .iter()
            .any(|t| t.contains("ALT_HOLD") && t.contains("depth")),
        "{:?}",
        texts(&out)
    );
    assert_eq!(r.v.mode(), 19);
    // SET_MODE message: acknowledged with command 11.
    let out = r.msg(MavMessage::SET_MODE(SET_MODE_DATA {
        custom_mode: 19,
        target_system: 1,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    }));
    let a = acks(&out);
    assert_eq!(a.len(), 1);
    assert_eq!(a[0].command as u32, 11);
    assert_eq!(a[0].result, MavResult::MAV_RESULT_ACCEPTED);
}

#[test]
fn unknown_commands_are_unsupported_at_once_and_nan_means_not_given() {
    let mut r = Rig::new();
    let out = r.cmd(MavCmd::MAV_CMD_NAV_TAKEOFF, NAN7);
    let a = acks(&out);
    assert_eq!(a.len(), 1);
    assert_eq!(a[0].result, MavResult::MAV_RESULT_UNSUPPORTED);
    let out = r.cmd(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, NAN7);
    assert_eq!(
        acks(&out)[0].result,
        MavResult::MAV_RESULT_ACCEPTED,
        "NaN p1 = disarm"
    );
    // Addressed to another system: not ours, no answer.
    let out = r.input(Input::Mavlink {
        from: QGC,
        msg: MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_NAV_TAKEOFF,
            target_system: 9,
            target_component: 1,
            ..Default::default()
        }),
    });
    assert!(acks(&out).is_empty());
}

#[test]
fn message_interval_set_get_off_and_default() {
    let mut r = Rig::new();
    r.link_up();
    let out = r.cmd(MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, p(&[30.0, 50_000.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let out = r.run(Duration::from_secs(10), true);
    let n = count(&out, 30, To::Endpoint(0));
    assert!((199..=201).contains(&n), "20 Hz over 10 s: {n}");
    // The other endpoint keeps its own default.
    let n1 = count(&out, 30, To::Endpoint(1));
    assert!((99..=101).contains(&n1), "10 Hz on endpoint 1: {n1}");
    let out = r.cmd(MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL, p(&[30.0]));
    let iv = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::MESSAGE_INTERVAL(i) = m {
                Some(i)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!((iv.message_id, iv.interval_us), (30, 50_000));
    r.cmd(MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, p(&[30.0, -1.0]));
    assert_eq!(
        count(&r.run(Duration::from_secs(2), true), 30, To::Endpoint(0)),
        0
    );
    r.cmd(MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, p(&[30.0, 0.0]));
    let n = count(&r.run(Duration::from_secs(2), true), 30, To::Endpoint(0));
    assert!((19..=21).contains(&n), "default 10 Hz: {n}");
    let out = r.cmd(MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, p(&[9999.0, 1000.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_UNSUPPORTED);
}

#[test]
fn request_data_stream_sets_group_rates() {
    let mut r = Rig::new();
    r.link_up();
    r.msg(MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
        req_message_rate: 4,
        target_system: 1,
        target_component: 1,
        req_stream_id: MavDataStream::MAV_DATA_STREAM_ALL,
        start_stop: 1,
    }));
    let out = r.run(Duration::from_secs(5), true);
    let n = count(&out, 30, To::Endpoint(0));
    assert!((19..=21).contains(&n), "ATTITUDE at 4 Hz: {n}");
}

#[test]
fn request_message_answers_every_request() {
    let mut r = Rig::new();
    let out = r.cmd(MavCmd::MAV_CMD_REQUEST_MESSAGE, p(&[148.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let av = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::AUTOPILOT_VERSION(a) = m {
                Some(a)
            } else {
                None
            }
        })
        .unwrap();
    assert!(
        av.capabilities
            .contains(MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2)
    );
    assert!(
        av.capabilities
            .contains(MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)
    );
    assert!(
        !av.capabilities
            .contains(MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MISSION_FENCE)
    );
    assert_eq!(av.flight_sw_version >> 16, (4 << 8) | 5);
    let out = r.cmd(MavCmd::MAV_CMD_REQUEST_MESSAGE, p(&[435.0, 0.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let modes = sent(&out)
        .into_iter()
        .filter(|(_, m)| matches!(m, MavMessage::AVAILABLE_MODES(_)))
        .count();
    assert!(modes >= 9);
    for id in [397.0, 395.0] {
        let out = r.cmd(MavCmd::MAV_CMD_REQUEST_MESSAGE, p(&[id]));
        let a = acks(&out);
        assert_eq!(a.len(), 1);
        assert_eq!(a[0].result, MavResult::MAV_RESULT_UNSUPPORTED);
    }
    let out = r.cmd(MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, p(&[1.0]));
    assert!(
        sent(&out)
            .iter()
            .any(|(_, m)| matches!(m, MavMessage::AUTOPILOT_VERSION(_)))
    );
    let out = r.cmd(MavCmd::MAV_CMD_REQUEST_PROTOCOL_VERSION, p(&[1.0]));
    assert!(
        sent(&out)
            .iter()
            .any(|(_, m)| matches!(m, MavMessage::PROTOCOL_VERSION(_)))
    );
    // Replies go to the requester only.
    assert!(sent(&out).iter().all(|(to, _)| *to == To::Peer(0, 7)));
}

#[test]
fn parameter_list_read_and_set() {
    let mut r = Rig::new();
    let total = ParamStore::defaults().len();
    r.msg(MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
        target_system: 1,
        target_component: 0,
    }));
    let out = r.run(Duration::from_secs(3), false);
    let mut seen: Vec<u16> = sent(&out)
        .into_iter()
        .filter_map(|(_, m)| {
            if let MavMessage::PARAM_VALUE(v) = m {
                Some(v)
            } else {
                None
            }
        })
        .map(|v| {
            assert_eq!(v.param_count as usize, total);
            v.param_index
        })
        .collect();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), total, "every index arrives");

    let out = r.msg(MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
        param_index: -1,
        target_system: 1,
        target_component: 1,
        param_id: "SYSID_MYGCS".into(),
    }));
    let v = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::PARAM_VALUE(v) = m {
                Some(v)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!(v.param_value, 255.0);
    assert_eq!(v.param_type, MavParamType::MAV_PARAM_TYPE_INT16);

    let out = r.msg(MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: 0.7,
        target_system: 1,
        target_component: 1,
        param_id: "JS_GAIN_DEFAULT".into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    }));
    // Saved off the vehicle task, once the changes settle (0.5 s).
    assert!(!out.contains(&Output::SaveParams));
    assert!(
        r.run(Duration::from_millis(600), false)
            .contains(&Output::SaveParams)
    );
    let echo = sent(&out)
        .into_iter()
        .find(|(_, m)| matches!(m, MavMessage::PARAM_VALUE(_)))
        .unwrap();
    assert_eq!(echo.0, To::All, "echo is broadcast");
    if let MavMessage::PARAM_VALUE(v) = echo.1 {
        assert!((v.param_value - 0.7).abs() < 1e-6);
    }
    // Out of range: the old value comes back, with the reason.
    let out = r.msg(MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: 7.0,
        target_system: 1,
        target_component: 1,
        param_id: "JS_GAIN_DEFAULT".into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    }));
    assert!(!out.contains(&Output::SaveParams));
    let v = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::PARAM_VALUE(v) = m {
                Some(v)
            } else {
                None
            }
        })
        .unwrap();
    assert!((v.param_value - 0.7).abs() < 1e-6);
    assert!(
        texts(&out).iter().any(|t| t.contains("JS_GAIN_DEFAULT")),
        "{:?}",
        texts(&out)
    );
}

#[test]
fn missions_are_empty_and_ftp_is_refused_fast() {
    let mut r = Rig::new();
    for ty in [
        MavMissionType::MAV_MISSION_TYPE_MISSION,
        MavMissionType::MAV_MISSION_TYPE_FENCE,
        MavMissionType::MAV_MISSION_TYPE_RALLY,
    ] {
        let out = r.msg(MavMessage::MISSION_REQUEST_LIST(
            MISSION_REQUEST_LIST_DATA {
                target_system: 1,
                target_component: 1,
                mission_type: ty,
            },
        ));
        let c = sent(&out)
            .into_iter()
            .find_map(|(_, m)| {
                if let MavMessage::MISSION_COUNT(c) = m {
                    Some(c)
                } else {
                    None
                }
            })
            .unwrap();
        assert_eq!((c.count, c.mission_type, c.target_system), (0, ty, 255));
    }
    let out = r.msg(MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
        count: 3,
        target_system: 1,
        target_component: 1,
        ..Default::default()
    }));
    let a = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::MISSION_ACK(a) = m {
                Some(a)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!(a.mavtype, MavMissionResult::MAV_MISSION_UNSUPPORTED);
    let mut payload = [0u8; 251];
    payload[0] = 5; // seq 5
    payload[3] = 4; // OpenFileRO
    let out = r.msg(MavMessage::FILE_TRANSFER_PROTOCOL(
        FILE_TRANSFER_PROTOCOL_DATA {
            target_network: 0,
            target_system: 1,
            target_component: 1,
            payload,
        },
    ));
    let f = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::FILE_TRANSFER_PROTOCOL(f) = m {
                Some(f)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!(u16::from_le_bytes([f.payload[0], f.payload[1]]), 6);
    assert_eq!(f.payload[3], 129, "NAK");
    assert_eq!(f.payload[5], 4, "req_opcode");
    assert_eq!(f.payload[12], 10, "FileNotFound");
}

#[test]
fn timesync_and_ping_are_answered() {
    let mut r = Rig::new();
    r.t = Duration::from_secs(3);
    let out = r.msg(MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: 0,
        ts1: 42,
        target_system: 0,
        target_component: 0,
    }));
    let t = sent(&out)
        .into_iter()
        .find_map(|(_, m)| {
            if let MavMessage::TIMESYNC(t) = m {
                Some(t)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!(t.ts1, 42);
    assert_eq!(t.tc1, 3_000_000_000);
    assert_eq!(t.target_system, 255);
    let out = r.msg(MavMessage::PING(PING_DATA {
        time_usec: 9,
        seq: 3,
        target_system: 0,
        target_component: 0,
    }));
    assert!(
        sent(&out)
            .iter()
            .any(|(_, m)| matches!(m, MavMessage::PING(p) if p.seq == 3 && p.target_system == 255))
    );
}

#[test]
fn lights_laser_and_tilt_by_servo_mount_and_illuminator_commands() {
    let mut r = Rig::new();
    let out = r.cmd(MavCmd::MAV_CMD_DO_SET_SERVO, p(&[7.0, 1900.0]));
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    assert!(out.contains(&Output::Board(Command::Lights(255))));
    let out = r.cmd(MavCmd::MAV_CMD_DO_SET_SERVO, p(&[6.0, 1900.0]));
    assert!(out.contains(&Output::Board(Command::Laser(255))));
    let out = r.cmd(MavCmd::MAV_CMD_DO_SET_SERVO, p(&[8.0, 1700.0]));
    assert!(out.contains(&Output::Board(Command::Tilt(1700))));
    let out = r.cmd(MavCmd::MAV_CMD_DO_SET_SERVO, p(&[1.0, 1700.0]));
    assert_eq!(
        acks(&out)[0].result,
        MavResult::MAV_RESULT_DENIED,
        "thrusters are not servos"
    );
    assert!(
        !out.iter()
            .any(|o| matches!(o, Output::Board(Command::Go { .. })))
    );
    let out = r.cmd(MavCmd::MAV_CMD_DO_MOUNT_CONTROL, p(&[-4500.0]));
    assert!(out.contains(&Output::Board(Command::Tilt(1250))));
    let out = r.cmd(MavCmd::MAV_CMD_ILLUMINATOR_ON_OFF, p(&[0.0]));
    assert!(out.contains(&Output::Board(Command::Lights(0))));
    let out = r.cmd(MavCmd::MAV_CMD_ILLUMINATOR_ON_OFF, p(&[1.0]));
    assert!(out.contains(&Output::Board(Command::Lights(255))));
    let out = r.cmd(MavCmd::MAV_CMD_DO_ILLUMINATOR_CONFIGURE, p(&[1.0, 50.0]));
    assert!(out.contains(&Output::Board(Command::Lights(128))));
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    fn any_cmd() -> impl Strategy<Value = (u16, [f32; 7])> {
        (
            prop_oneof![
                Just(400u16),
                Just(176),
                Just(183),
                Just(205),
                Just(511),
                Just(512),
                Just(405),
                Just(406)
            ],
            prop::array::uniform7(prop_oneof![
                any::<f32>(),
                Just(f32::NAN),
                -3000.0f32..3000.0
            ]),
        )
    }

    proptest! {
        /// Whatever commands arrive, while disarmed every go() is neutral.
        #[test]
        fn disarmed_means_neutral(cmds in prop::collection::vec(any_cmd(), 1..40)) {
            use num_traits::FromPrimitive;
            let mut r = Rig::new();
            r.link_up();
            for (c, params) in cmds {
                let Some(cmd) = MavCmd::from_u16(c) else { continue };
                r.out.clear();
                r.cmd(cmd, params);
                r.run(Duration::from_millis(30), true);
                if !r.v.armed() {
                    for o in &r.out {
                        if let Output::Board(Command::Go { port_us, vertical_us, starboard_us }) = o {
                            prop_assert_eq!((*port_us, *vertical_us, *starboard_us), (1500, 1500, 1500));
                        }
                    }
                }
            }
        }
    }
}
