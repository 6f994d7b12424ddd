//! The vehicle core with synthetic time: identity, telemetry, commands,
//! parameters, missions and FTP — every rule a ground station relies on.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::time::Duration;

use common::core_rig::{BoardFeed, CoreRig, acks, count_sent, msgs, sent, statustexts};
use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::{Command, NavSample, StatusSample};
use neptunus::vehicle::machine::{Identity, Input, Now, Output, Sender, To, Vehicle};
use neptunus::vehicle::params::ParamStore;

const QGC: Sender = Sender::new(0, 7, 255, 190);

/// What the board reports here: heading east at 1.5 m, pitched 1° and
/// rolled −2°, 12 V, with its uptime.
fn east_at_1_5_m() -> BoardFeed {
    BoardFeed {
        nav: NavSample {
            heading_deg: Some(90.0),
            depth_m: Some(1.5),
            pitch_deg: Some(1.0),
            roll_deg: Some(-2.0),
            yaw_deg: Some(90.0),
            fthr_pct: Some(0.0),
        },
        status: StatusSample {
            vout_v: Some(12.0),
            iout_a: Some(0.3),
            battery_current_a: Some(0.3),
            pres_mbar: Some(1162.0),
            temp_c: Some(18.0),
            ..Default::default()
        },
        uptime: true,
    }
}

/// Two endpoints, one tick at t = 0: the board link is still down.
fn rig() -> CoreRig {
    let mut r = CoreRig::new(Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 2))
        .unix_epoch(1_700_000_000_000_000)
        .feed(east_at_1_5_m());
    r.input(Input::Tick);
    r
}

/// Board link up, then 1.1 s of telemetry.
fn link_up(r: &mut CoreRig) {
    r.link_up();
    r.run(Duration::from_millis(1100));
}

const NAN7: [f32; 7] = [f32::NAN; 7];

#[test]
fn heartbeat_at_1_hz_on_every_endpoint_as_ardusub() {
    let mut r = rig();
    let out = r.run_board_silent(Duration::from_secs(5));
    for ep in [0, 1] {
        let n = count_sent(&out, 0, To::Endpoint(ep));
        assert!((5..=6).contains(&n), "endpoint {ep}: {n} heartbeats in 5 s");
    }
    let hb = &msgs!(&out, HEARTBEAT)[0];
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
    let hb = &msgs!(&out, HEARTBEAT)[0];
    assert_eq!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_GENERIC);
}

#[test]
fn no_attitude_or_depth_while_the_board_link_is_down() {
    let mut r = rig();
    link_up(&mut r);
    let out = r.run(Duration::from_secs(1));
    assert!(
        count_sent(&out, 30, To::Endpoint(0)) >= 9,
        "ATTITUDE at 10 Hz while up"
    );
    assert!(count_sent(&out, 33, To::Endpoint(0)) >= 2);
    let out = r.link_down("device closed");
    assert!(
        statustexts(&out)
            .iter()
            .any(|t| t.contains("Board link down") && t.contains("device closed")),
        "{:?}",
        statustexts(&out)
    );
    let out = r.run_board_silent(Duration::from_secs(2));
    assert_eq!(
        count_sent(&out, 30, To::Endpoint(0)),
        0,
        "stale attitude must not be re-sent"
    );
    assert_eq!(count_sent(&out, 33, To::Endpoint(0)), 0);
    assert_eq!(count_sent(&out, 74, To::Endpoint(0)), 0);
    let sys = msgs!(&out, SYS_STATUS).pop().unwrap();
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

/// A board whose power lines stop (the rest of its telemetry still
/// coming): the last voltage is not reported as live — MAVLink's "unknown"
/// in SYS_STATUS and BATTERY_STATUS once it is older than a second and a
/// half.
#[test]
fn a_board_that_stops_its_power_lines_reports_the_battery_unknown() {
    let mut r = rig();
    link_up(&mut r);
    let out = r.run(Duration::from_secs(1));
    assert_eq!(
        msgs!(&out, SYS_STATUS).pop().unwrap().voltage_battery,
        12000
    );
    r.feed.status.vout_v = None;
    r.feed.status.iout_a = None;
    r.feed.status.battery_current_a = None;
    let out = r.run(Duration::from_secs(3));
    let sys = msgs!(&out, SYS_STATUS).pop().unwrap();
    assert_eq!(sys.voltage_battery, u16::MAX, "{sys:?}");
    assert_eq!(sys.current_battery, -1, "{sys:?}");
    assert_eq!(sys.battery_remaining, -1, "{sys:?}");
    let bat = msgs!(&out, BATTERY_STATUS).pop().unwrap();
    assert_eq!(bat.voltages[0], u16::MAX, "{bat:?}");
    assert_eq!(bat.current_battery, -1, "{bat:?}");
    assert_eq!(bat.battery_remaining, -1, "{bat:?}");
    // Navigation kept coming: attitude is still live.
    assert!(count_sent(&out, 30, To::Endpoint(0)) > 0);
}

#[test]
fn ready_when_link_up_and_fresh() {
    let mut r = rig();
    link_up(&mut r);
    let out = r.run(Duration::from_secs(1));
    let sys = msgs!(&out, SYS_STATUS).pop().unwrap();
    assert!(
        sys.onboard_control_sensors_health
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK)
    );
    assert!(
        sys.onboard_control_sensors_enabled
            .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK)
    );
    assert_eq!(sys.voltage_battery, 12000);
    let gpi = &msgs!(&out, GLOBAL_POSITION_INT)[0];
    assert_eq!(gpi.relative_alt, -1500);
    assert_eq!(gpi.hdg, 9000);
    let hud = &msgs!(&out, VFR_HUD)[0];
    assert!((hud.alt + 1.5).abs() < 1e-6);
    let att = &msgs!(&out, ATTITUDE)[0];
    assert!((att.yaw - std::f32::consts::FRAC_PI_2).abs() < 1e-4);
}

#[test]
fn arming_refused_with_a_reason_while_link_down_even_forced() {
    let mut r = rig();
    let out = r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0, 2989.0]);
    let a = acks(&out);
    assert_eq!(a.len(), 1);
    assert_eq!(a[0].result, MavResult::MAV_RESULT_FAILED);
    assert!(
        statustexts(&out)
            .iter()
            .any(|t| t.contains("board link down")),
        "{:?}",
        statustexts(&out)
    );
    assert!(!r.v.armed());
}

#[test]
fn arm_and_disarm_are_acknowledged_once_and_idempotent() {
    let mut r = rig();
    link_up(&mut r);
    for _ in 0..2 {
        let out = r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]);
        let a = acks(&out);
        assert_eq!(a.len(), 1);
        assert_eq!(a[0].result, MavResult::MAV_RESULT_ACCEPTED);
        assert_eq!((a[0].target_system, a[0].target_component), (255, 190));
        assert_eq!(a[0].command, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
    }
    assert!(r.v.armed());
    let out = r.run(Duration::from_millis(1100));
    let hb = &msgs!(&out, HEARTBEAT)[0];
    assert!(
        hb.base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
    );
    assert_eq!(hb.system_status, MavState::MAV_STATE_ACTIVE);
    let out = r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[0.0]);
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
    let mut r = rig();
    link_up(&mut r);
    r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]);
    assert!(r.v.armed());
    let out = r.link_down("read failed");
    assert!(!r.v.armed());
    assert!(statustexts(&out).iter().any(|t| t.contains("Disarmed")));
}

#[test]
fn a_board_dead_man_trip_disarms_only_what_was_armed_before_it() {
    use neptunus::firmware::codec::Event;
    let mut r = rig();
    link_up(&mut r);
    r.alive = vec![QGC];
    // Armed for longer than the board's 2-s dead-man: its trip is this
    // arming's, and disarms.
    r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]);
    r.run(Duration::from_millis(2500));
    assert!(r.v.armed());
    let out = r.input(Input::Board(Event::InternalCommand("stop()".into())));
    assert!(!r.v.armed());
    assert!(
        statustexts(&out)
            .iter()
            .any(|t| t.contains("Board dead-man tripped"))
    );
    r.input(Input::Board(Event::InternalCommand("start()".into())));
    // A trip read just after arming happened before it (a vehicle that
    // stood still finds the board's lines waiting): the arming stands.
    r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]);
    assert!(r.v.armed());
    r.run(Duration::from_millis(20));
    let out = r.input(Input::Board(Event::InternalCommand("stop()".into())));
    assert!(r.v.armed(), "{:?}", statustexts(&out));
    assert!(
        statustexts(&out)
            .iter()
            .any(|t| t.contains("had tripped before arming")),
        "{:?}",
        statustexts(&out)
    );
}

/// The program stood still while armed: the board held its last command.
/// A gap short of the board's dead-man (the link's doubt included) is what
/// a late tether does too — told to the pilot, the dive goes on; one that
/// may have let the dead-man act leaves the board's state unknown, and
/// disarms.
#[test]
fn a_stall_short_of_the_board_dead_man_is_a_warning_and_a_longer_one_disarms() {
    let mut r = rig();
    link_up(&mut r);
    r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]);
    r.run(Duration::from_millis(200));
    assert!(r.v.armed());

    // The core's clock jumps: nothing was handled for `ms`; its texts.
    let stall = |r: &mut CoreRig, ms: u64| {
        r.t += Duration::from_millis(ms);
        statustexts(&r.input(Input::Tick))
    };

    let texts = stall(&mut r, 1200);
    assert!(r.v.armed(), "a 1.2-s stall disarmed: {texts:?}");
    assert!(
        texts
            .iter()
            .any(|t| t.contains("Vehicle stood still 1.2 s")),
        "{texts:?}"
    );
    r.run(Duration::from_millis(200));

    let texts = stall(&mut r, 1600);
    assert!(!r.v.armed(), "a 1.6-s stall left it armed");
    assert!(
        texts.iter().any(|t| t.contains("Vehicle stalled 1.6 s")),
        "{texts:?}"
    );

    // Disarmed, a stall says nothing.
    r.run(Duration::from_millis(200));
    let texts = stall(&mut r, 3000);
    assert!(!texts.iter().any(|t| t.contains("Vehicle st")), "{texts:?}");
}

#[test]
fn modes_follow_ardusub_numbers_and_unavailable_ones_are_refused_with_a_reason() {
    let mut r = rig();
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_SET_MODE, &[1.0, 19.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_SET_MODE, &[1.0, 16.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_FAILED);
    assert!(
        statustexts(&out)
            .iter()
            .any(|t| t.contains("POSHOLD") && t.contains("position")),
        "{:?}",
        statustexts(&out)
    );
    // ALT_HOLD needs a depth estimate: refused with the reason before telemetry.
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_SET_MODE, &[1.0, 2.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_FAILED);
    assert!(
        statustexts(&out)
            .iter()
            .any(|t| t.contains("ALT_HOLD") && t.contains("depth")),
        "{:?}",
        statustexts(&out)
    );
    assert_eq!(r.v.mode().number(), 19);
    // SET_MODE message: acknowledged with command 11.
    let out = r.msg(
        QGC,
        MavMessage::SET_MODE(SET_MODE_DATA {
            custom_mode: 19,
            target_system: 1,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        }),
    );
    let a = acks(&out);
    assert_eq!(a.len(), 1);
    assert_eq!(a[0].command as u32, 11);
    assert_eq!(a[0].result, MavResult::MAV_RESULT_ACCEPTED);
}

#[test]
fn unknown_commands_are_unsupported_at_once_and_nan_means_not_given() {
    let mut r = rig();
    let out = r.cmd(QGC, MavCmd::MAV_CMD_NAV_TAKEOFF, &NAN7);
    let a = acks(&out);
    assert_eq!(a.len(), 1);
    assert_eq!(a[0].result, MavResult::MAV_RESULT_UNSUPPORTED);
    let out = r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &NAN7);
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
    let mut r = rig();
    link_up(&mut r);
    let out = r.cmd(QGC, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, &[30.0, 50_000.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let out = r.run(Duration::from_secs(10));
    let n = count_sent(&out, 30, To::Endpoint(0));
    assert!((199..=201).contains(&n), "20 Hz over 10 s: {n}");
    // The other endpoint keeps its own default.
    let n1 = count_sent(&out, 30, To::Endpoint(1));
    assert!((99..=101).contains(&n1), "10 Hz on endpoint 1: {n1}");
    let out = r.cmd(QGC, MavCmd::MAV_CMD_GET_MESSAGE_INTERVAL, &[30.0]);
    let iv = &msgs!(&out, MESSAGE_INTERVAL)[0];
    assert_eq!((iv.message_id, iv.interval_us), (30, 50_000));
    r.cmd(QGC, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, &[30.0, -1.0]);
    assert_eq!(
        count_sent(&r.run(Duration::from_secs(2)), 30, To::Endpoint(0)),
        0
    );
    r.cmd(QGC, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, &[30.0, 0.0]);
    let n = count_sent(&r.run(Duration::from_secs(2)), 30, To::Endpoint(0));
    assert!((19..=21).contains(&n), "default 10 Hz: {n}");
    let out = r.cmd(QGC, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, &[9999.0, 1000.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_UNSUPPORTED);
}

#[test]
fn request_data_stream_sets_group_rates() {
    let mut r = rig();
    link_up(&mut r);
    r.msg(
        QGC,
        MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
            req_message_rate: 4,
            target_system: 1,
            target_component: 1,
            req_stream_id: MavDataStream::MAV_DATA_STREAM_ALL,
            start_stop: 1,
        }),
    );
    let out = r.run(Duration::from_secs(5));
    let n = count_sent(&out, 30, To::Endpoint(0));
    assert!((19..=21).contains(&n), "ATTITUDE at 4 Hz: {n}");
}

#[test]
fn request_message_answers_every_request() {
    let mut r = rig();
    let out = r.cmd(QGC, MavCmd::MAV_CMD_REQUEST_MESSAGE, &[148.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let av = &msgs!(&out, AUTOPILOT_VERSION)[0];
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
    let out = r.cmd(QGC, MavCmd::MAV_CMD_REQUEST_MESSAGE, &[435.0, 0.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let modes = sent(&out)
        .into_iter()
        .filter(|(_, m)| matches!(m, MavMessage::AVAILABLE_MODES(_)))
        .count();
    assert!(modes >= 9);
    // The component metadata, in MAVLink's form and QGroundControl's older
    // one: each names the general metadata file over MAVLink FTP.
    let out = r.cmd(QGC, MavCmd::MAV_CMD_REQUEST_MESSAGE, &[397.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let meta = &msgs!(&out, COMPONENT_METADATA)[0];
    assert!(
        meta.uri.to_str().unwrap().starts_with("mftp://"),
        "{:?}",
        meta.uri
    );
    let out = r.cmd(QGC, MavCmd::MAV_CMD_REQUEST_MESSAGE, &[395.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    let info = &msgs!(&out, COMPONENT_INFORMATION)[0];
    assert!(
        info.general_metadata_uri
            .to_str()
            .unwrap()
            .starts_with("mftp://"),
        "{:?}",
        info.general_metadata_uri
    );
    let out = r.cmd(QGC, MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, &[1.0]);
    assert!(
        sent(&out)
            .iter()
            .any(|(_, m)| matches!(m, MavMessage::AUTOPILOT_VERSION(_)))
    );
    let out = r.cmd(QGC, MavCmd::MAV_CMD_REQUEST_PROTOCOL_VERSION, &[1.0]);
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
    let mut r = rig();
    let total = ParamStore::defaults().len();
    r.msg(
        QGC,
        MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 0,
        }),
    );
    let out = r.run_board_silent(Duration::from_secs(3));
    let mut seen: Vec<u16> = msgs!(&out, PARAM_VALUE)
        .into_iter()
        .map(|v| {
            assert_eq!(v.param_count as usize, total);
            v.param_index
        })
        .collect();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), total, "every index arrives");

    let out = r.msg(
        QGC,
        MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system: 1,
            target_component: 1,
            param_id: "SYSID_MYGCS".into(),
        }),
    );
    let v = &msgs!(&out, PARAM_VALUE)[0];
    assert_eq!(v.param_value, 255.0);
    assert_eq!(v.param_type, MavParamType::MAV_PARAM_TYPE_INT16);

    let out = r.msg(
        QGC,
        MavMessage::PARAM_SET(PARAM_SET_DATA {
            param_value: 0.7,
            target_system: 1,
            target_component: 1,
            param_id: "JS_GAIN_DEFAULT".into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }),
    );
    // Saved off the vehicle task, once the changes settle (0.5 s).
    assert!(!out.contains(&Output::SaveParams));
    assert!(
        r.run_board_silent(Duration::from_millis(600))
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
    let out = r.msg(
        QGC,
        MavMessage::PARAM_SET(PARAM_SET_DATA {
            param_value: 7.0,
            target_system: 1,
            target_component: 1,
            param_id: "JS_GAIN_DEFAULT".into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }),
    );
    assert!(!out.contains(&Output::SaveParams));
    let v = &msgs!(&out, PARAM_VALUE)[0];
    assert!((v.param_value - 0.7).abs() < 1e-6);
    assert!(
        statustexts(&out)
            .iter()
            .any(|t| t.contains("JS_GAIN_DEFAULT")),
        "{:?}",
        statustexts(&out)
    );
}

#[test]
fn missions_are_empty_and_a_path_outside_the_ftp_tree_is_not_found() {
    let mut r = rig();
    for ty in [
        MavMissionType::MAV_MISSION_TYPE_MISSION,
        MavMissionType::MAV_MISSION_TYPE_FENCE,
        MavMissionType::MAV_MISSION_TYPE_RALLY,
    ] {
        let out = r.msg(
            QGC,
            MavMessage::MISSION_REQUEST_LIST(MISSION_REQUEST_LIST_DATA {
                target_system: 1,
                target_component: 1,
                mission_type: ty,
            }),
        );
        let c = &msgs!(&out, MISSION_COUNT)[0];
        assert_eq!((c.count, c.mission_type, c.target_system), (0, ty, 255));
    }
    let out = r.msg(
        QGC,
        MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
            count: 3,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }),
    );
    let a = &msgs!(&out, MISSION_ACK)[0];
    assert_eq!(a.mavtype, MavMissionResult::MAV_MISSION_UNSUPPORTED);
    // MAVLink FTP answers at once, to the asker alone: a path outside the
    // tree is not found.
    let mut payload = [0u8; 251];
    payload[0] = 5; // seq 5
    payload[3] = 4; // OpenFileRO
    payload[4] = 9; // size
    payload[12..21].copy_from_slice(b"/etc/x.db");
    let out = r.msg(
        QGC,
        MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
            target_network: 0,
            target_system: 1,
            target_component: 1,
            payload,
        }),
    );
    let f = out
        .iter()
        .find_map(|o| match o {
            Output::Bulk {
                msg: MavMessage::FILE_TRANSFER_PROTOCOL(f),
                ..
            } => Some(f),
            _ => None,
        })
        .expect("an FTP reply");
    assert_eq!(f.target_system, 255);
    assert_eq!(u16::from_le_bytes([f.payload[0], f.payload[1]]), 6);
    assert_eq!(f.payload[3], 129, "NAK");
    assert_eq!(f.payload[5], 4, "req_opcode");
    assert_eq!(f.payload[12], 10, "FileNotFound");
}

#[test]
fn timesync_and_ping_are_answered() {
    let mut r = rig();
    r.t = Duration::from_secs(3);
    let out = r.msg(
        QGC,
        MavMessage::TIMESYNC(TIMESYNC_DATA {
            tc1: 0,
            ts1: 42,
            target_system: 0,
            target_component: 0,
        }),
    );
    let t = &msgs!(&out, TIMESYNC)[0];
    assert_eq!(t.ts1, 42);
    assert_eq!(t.tc1, 3_000_000_000);
    assert_eq!(t.target_system, 255);
    let out = r.msg(
        QGC,
        MavMessage::PING(PING_DATA {
            time_usec: 9,
            seq: 3,
            target_system: 0,
            target_component: 0,
        }),
    );
    assert!(
        sent(&out)
            .iter()
            .any(|(_, m)| matches!(m, MavMessage::PING(p) if p.seq == 3 && p.target_system == 255))
    );
}

#[test]
fn lights_laser_and_tilt_by_servo_mount_and_illuminator_commands() {
    let mut r = rig();
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_SET_SERVO, &[7.0, 1900.0]);
    assert_eq!(acks(&out)[0].result, MavResult::MAV_RESULT_ACCEPTED);
    assert!(out.contains(&Output::Board(Command::Lights(255))));
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_SET_SERVO, &[6.0, 1900.0]);
    assert!(out.contains(&Output::Board(Command::Laser(255))));
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_SET_SERVO, &[8.0, 1700.0]);
    assert!(out.contains(&Output::Board(Command::Tilt(1700))));
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_SET_SERVO, &[1.0, 1700.0]);
    assert_eq!(
        acks(&out)[0].result,
        MavResult::MAV_RESULT_DENIED,
        "thrusters are not servos"
    );
    assert!(
        !out.iter()
            .any(|o| matches!(o, Output::Board(Command::Go { .. })))
    );
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_MOUNT_CONTROL, &[-4500.0]);
    assert!(out.contains(&Output::Board(Command::Tilt(1250))));
    let out = r.cmd(QGC, MavCmd::MAV_CMD_ILLUMINATOR_ON_OFF, &[0.0]);
    assert!(out.contains(&Output::Board(Command::Lights(0))));
    let out = r.cmd(QGC, MavCmd::MAV_CMD_ILLUMINATOR_ON_OFF, &[1.0]);
    assert!(out.contains(&Output::Board(Command::Lights(255))));
    let out = r.cmd(QGC, MavCmd::MAV_CMD_DO_ILLUMINATOR_CONFIGURE, &[1.0, 50.0]);
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
            let mut r = rig();
            link_up(&mut r);
            for (c, params) in cmds {
                let Some(cmd) = MavCmd::from_u16(c) else { continue };
                let mut out = r.cmd(QGC, cmd, &params);
                out.extend(r.run(Duration::from_millis(30)));
                if !r.v.armed() {
                    for o in &out {
                        if let Output::Board(Command::Go { port_us, vertical_us, starboard_us }) = o {
                            prop_assert_eq!((*port_us, *vertical_us, *starboard_us), (1500, 1500, 1500));
                        }
                    }
                }
            }
        }
    }
}

/// Every text the core writes says what it is about (the browser HMI files
/// it by that, not by its wording): the board link's under `BoardLink`,
/// arming's under `Stop`, and a reply to one station under its kind.
#[test]
fn every_text_carries_the_topic_chosen_where_it_was_written() {
    use neptunus::vehicle::machine::Topic;
    let topics = |out: &[Output]| -> Vec<(Topic, String)> {
        out.iter()
            .filter_map(|o| match o {
                Output::Text {
                    topic,
                    msg: MavMessage::STATUSTEXT(s),
                    ..
                } => Some((*topic, common::statustext(s))),
                _ => None,
            })
            .collect()
    };
    let mut r = CoreRig::new(Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 1));
    let up = r.link_up();
    assert_eq!(
        topics(&up),
        vec![(Topic::BoardLink, "Board link up".into())]
    );
    let out = r.cmd(QGC, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0]);
    // Arming claims control first (a control text), then fails its checks
    // (an arming text).
    let t = topics(&out);
    assert!(
        t.iter()
            .any(|(topic, text)| *topic == Topic::Control && text.contains("in control")),
        "{t:?}"
    );
    assert!(
        t.iter()
            .any(|(topic, text)| *topic == Topic::Stop && text.starts_with("PreArm")),
        "{t:?}"
    );
    let down = r.link_down("unplugged");
    assert!(
        topics(&down)
            .iter()
            .any(|(topic, text)| *topic == Topic::BoardLink && text.contains("unplugged")),
        "{:?}",
        topics(&down)
    );
    // No STATUSTEXT leaves the core without a topic.
    for out in [&up, &out, &down] {
        assert!(!out.iter().any(|o| matches!(
            o,
            Output::Send {
                msg: MavMessage::STATUSTEXT(_),
                ..
            }
        )));
    }
}
