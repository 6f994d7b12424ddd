//! The camera component (id 100) and the camera tilt as a gimbal, on the
//! core rig: what QGroundControl's camera discovery and gimbal controller
//! see, and that only the station in control moves the tilt.

#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, ack_of, board_commands, has_text, msgs};
use mavlink_core::MessageData;
use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::Command;
use neptunus::vehicle::machine::{
    CAMERA_COMPONENT_ID, CameraSpec, GIMBAL_DEVICE_ID, Identity, Input, Output, Sender, To,
    Vehicle, VideoStreamInfo,
};
use neptunus::vehicle::params::ParamStore;

const A: Sender = Sender::new(0, 1, 255, 190);
const B: Sender = Sender::new(0, 2, 254, 190);
const SPEC: CameraSpec = CameraSpec {
    width: 640,
    height: 480,
    fps: 15.0,
};

fn rig_with(camera: Option<CameraSpec>, params: &[(&str, f64)]) -> CoreRig {
    let mut p = ParamStore::defaults();
    p.set("NEPT_GCS_ALLOW2", 254.0).unwrap();
    for (n, v) in params {
        p.set(n, *v).unwrap();
    }
    CoreRig::new(Vehicle::new(Identity::Ardupilot, p, 2).with_camera(camera)).started()
}

fn rig() -> CoreRig {
    rig_with(Some(SPEC), &[])
}

/// What the camera component sent: (to, message), in order.
fn from_camera(out: &[Output]) -> Vec<(To, MavMessage)> {
    out.iter()
        .filter_map(|o| match o {
            Output::SendAs { to, compid, msg } if *compid == CAMERA_COMPONENT_ID => {
                Some((*to, msg.clone()))
            }
            _ => None,
        })
        .collect()
}

/// COMMAND_LONG to system 1, component `compid`.
fn command_to(compid: u8, command: MavCmd, params: &[f32]) -> MavMessage {
    let mut p = [0.0; 7];
    p[..params.len()].copy_from_slice(params);
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        command,
        target_system: 1,
        target_component: compid,
        confirmation: 0,
    })
}

/// The camera's answer to a command: its ack's result and the messages after it.
fn camera_answer(
    r: &mut CoreRig,
    compid: u8,
    cmd: MavCmd,
    p: &[f32],
) -> (MavResult, Vec<MavMessage>) {
    let out = r.msg(A, command_to(compid, cmd, p));
    let sent = from_camera(&out);
    assert!(
        sent.iter()
            .all(|(to, _)| *to == To::Peer(A.endpoint, A.peer)),
        "the camera answers the asker alone: {sent:?}"
    );
    let Some((_, MavMessage::COMMAND_ACK(ack))) = sent.first() else {
        panic!("the camera's first answer must be its COMMAND_ACK: {out:?}");
    };
    assert_eq!(ack.command, cmd);
    assert_eq!(
        (ack.target_system, ack.target_component),
        (A.sysid, A.compid)
    );
    (
        ack.result,
        sent[1..].iter().map(|(_, m)| m.clone()).collect(),
    )
}

fn char_str(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).into_owned()
}

#[test]
fn camera_heartbeat_once_a_second_on_every_endpoint() {
    let mut r = rig();
    let out = r.run(Duration::from_secs(5));
    let beats: Vec<_> = from_camera(&out)
        .into_iter()
        .filter_map(|(to, m)| match m {
            MavMessage::HEARTBEAT(h) => Some((to, h)),
            _ => None,
        })
        .collect();
    assert!(
        (5..=6).contains(&beats.len()),
        "{} camera heartbeats in 5 s",
        beats.len()
    );
    for (to, h) in beats {
        assert_eq!(to, To::All);
        assert_eq!(h.mavtype, MavType::MAV_TYPE_CAMERA);
        assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
        assert_eq!(h.system_status, MavState::MAV_STATE_STANDBY);
    }
    // The autopilot's own heartbeat is unchanged.
    assert!(
        msgs!(&out, HEARTBEAT)
            .iter()
            .all(|h| h.mavtype == MavType::MAV_TYPE_SUBMARINE)
    );
}

#[test]
fn no_camera_no_component() {
    let mut r = rig_with(None, &[]);
    let out = r.run(Duration::from_secs(3));
    assert!(from_camera(&out).is_empty());
    let id = CAMERA_INFORMATION_DATA::ID as f32;
    let out = r.msg(
        A,
        command_to(CAMERA_COMPONENT_ID, MavCmd::MAV_CMD_REQUEST_MESSAGE, &[id]),
    );
    assert!(
        out.iter().all(|o| o.message().is_none()) && from_camera(&out).is_empty(),
        "{out:?}"
    );
}

#[test]
fn discovery_camera_information_then_video_stream() {
    let mut r = rig();
    let (res, m) = camera_answer(
        &mut r,
        CAMERA_COMPONENT_ID,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        &[CAMERA_INFORMATION_DATA::ID as f32],
    );
    assert_eq!(res, MavResult::MAV_RESULT_ACCEPTED);
    let [MavMessage::CAMERA_INFORMATION(info)] = m.as_slice() else {
        panic!("CAMERA_INFORMATION expected: {m:?}")
    };
    assert!(
        info.flags
            .contains(CameraCapFlags::CAMERA_CAP_FLAGS_HAS_VIDEO_STREAM)
    );
    assert_eq!(char_str(&info.vendor_name), "Neptunus");
    assert_eq!(char_str(&info.model_name), "OpenROV camera");
    assert_eq!((info.resolution_h, info.resolution_v), (640, 480));
    assert_eq!(char_str(info.cam_definition_uri.as_ref()), "");

    // No stream yet: stream 1 described, not running, no uri.
    let (res, m) = camera_answer(
        &mut r,
        CAMERA_COMPONENT_ID,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        &[VIDEO_STREAM_INFORMATION_DATA::ID as f32, 0.0],
    );
    assert_eq!(res, MavResult::MAV_RESULT_ACCEPTED);
    let [MavMessage::VIDEO_STREAM_INFORMATION(vs)] = m.as_slice() else {
        panic!("VIDEO_STREAM_INFORMATION expected: {m:?}")
    };
    assert_eq!((vs.stream_id, vs.count), (1, 1));
    assert_eq!(vs.mavtype, VideoStreamType::VIDEO_STREAM_TYPE_RTPUDP);
    assert!(
        !vs.flags
            .contains(VideoStreamStatusFlags::VIDEO_STREAM_STATUS_FLAGS_RUNNING)
    );
    assert_eq!(char_str(vs.uri.as_ref()), "");
    assert_eq!(vs.encoding, VideoStreamEncoding::VIDEO_STREAM_ENCODING_H264);

    // The RTP side reports a stream: it is advertised as running, with its uri.
    r.input(Input::VideoStream(Some(VideoStreamInfo {
        uri: "udp://192.168.2.1:5600".into(),
        width: 1280,
        height: 720,
        fps: 30.0,
        bitrate_kbps: 2000,
    })));
    let (_, m) = camera_answer(
        &mut r,
        CAMERA_COMPONENT_ID,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        &[VIDEO_STREAM_INFORMATION_DATA::ID as f32, 0.0],
    );
    let [MavMessage::VIDEO_STREAM_INFORMATION(vs)] = m.as_slice() else {
        panic!("VIDEO_STREAM_INFORMATION expected: {m:?}")
    };
    assert!(
        vs.flags
            .contains(VideoStreamStatusFlags::VIDEO_STREAM_STATUS_FLAGS_RUNNING)
    );
    assert_eq!(char_str(vs.uri.as_ref()), "udp://192.168.2.1:5600");
    assert_eq!(
        (vs.resolution_h, vs.resolution_v, vs.framerate),
        (1280, 720, 30.0)
    );
    assert_eq!(vs.bitrate, 2_000_000);
    assert_eq!(char_str(vs.name.as_ref()), "Neptunus video");

    // It stops: not running again.
    r.input(Input::VideoStream(None));
    let (_, m) = camera_answer(
        &mut r,
        CAMERA_COMPONENT_ID,
        MavCmd::MAV_CMD_REQUEST_VIDEO_STREAM_STATUS,
        &[1.0],
    );
    let [MavMessage::VIDEO_STREAM_STATUS(st)] = m.as_slice() else {
        panic!("VIDEO_STREAM_STATUS expected: {m:?}")
    };
    assert!(st.flags.is_empty());
}

#[test]
fn every_camera_request_is_acked_then_answered() {
    use MavCmd as C;
    let mut r = rig();
    let legacy = [
        (
            C::MAV_CMD_REQUEST_CAMERA_INFORMATION,
            CAMERA_INFORMATION_DATA::ID,
        ),
        (C::MAV_CMD_REQUEST_CAMERA_SETTINGS, CAMERA_SETTINGS_DATA::ID),
        (
            C::MAV_CMD_REQUEST_STORAGE_INFORMATION,
            STORAGE_INFORMATION_DATA::ID,
        ),
        (
            C::MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS,
            CAMERA_CAPTURE_STATUS_DATA::ID,
        ),
        (
            C::MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION,
            VIDEO_STREAM_INFORMATION_DATA::ID,
        ),
        (
            C::MAV_CMD_REQUEST_VIDEO_STREAM_STATUS,
            VIDEO_STREAM_STATUS_DATA::ID,
        ),
    ];
    for (cmd, id) in legacy {
        for (c, p) in [(cmd, 1.0), (C::MAV_CMD_REQUEST_MESSAGE, id as f32)] {
            let (res, m) = camera_answer(&mut r, CAMERA_COMPONENT_ID, c, &[p]);
            assert_eq!(res, MavResult::MAV_RESULT_ACCEPTED, "{c:?} {p}");
            assert_eq!(m.len(), 1, "{c:?}: {m:?}");
            assert_eq!(mavlink_core::Message::message_id(&m[0]), id, "{c:?}");
        }
    }
    let (_, m) = camera_answer(
        &mut r,
        CAMERA_COMPONENT_ID,
        C::MAV_CMD_REQUEST_STORAGE_INFORMATION,
        &[0.0],
    );
    let [MavMessage::STORAGE_INFORMATION(s)] = m.as_slice() else {
        panic!("{m:?}")
    };
    assert_eq!(s.storage_count, 0);
    assert_eq!(s.status, StorageStatus::STORAGE_STATUS_NOT_SUPPORTED);
}

#[test]
fn unknown_camera_commands_are_unsupported_and_other_streams_denied() {
    use MavCmd as C;
    let mut r = rig();
    for (cmd, p) in [
        (C::MAV_CMD_IMAGE_START_CAPTURE, vec![0.0, 1.0, 1.0]),
        (C::MAV_CMD_VIDEO_START_CAPTURE, vec![0.0]),
        (C::MAV_CMD_COMPONENT_ARM_DISARM, vec![1.0]),
        (
            C::MAV_CMD_REQUEST_MESSAGE,
            vec![GIMBAL_MANAGER_INFORMATION_DATA::ID as f32],
        ),
    ] {
        let (res, m) = camera_answer(&mut r, CAMERA_COMPONENT_ID, cmd, &p);
        assert_eq!(res, MavResult::MAV_RESULT_UNSUPPORTED, "{cmd:?}");
        assert!(m.is_empty());
    }
    assert!(
        !r.v.armed(),
        "an arm command to the camera must not arm the vehicle"
    );
    let (res, _) = camera_answer(
        &mut r,
        CAMERA_COMPONENT_ID,
        C::MAV_CMD_REQUEST_MESSAGE,
        &[VIDEO_STREAM_INFORMATION_DATA::ID as f32, 7.0],
    );
    assert_eq!(res, MavResult::MAV_RESULT_DENIED);
    // A command number the dialect does not know, aimed at the camera.
    let out = r.input(Input::UnknownCommand {
        from: A,
        command: 65000,
        target_system: 1,
        target_component: CAMERA_COMPONENT_ID,
    });
    assert!(
        matches!(
            out.as_slice(),
            [Output::AckUnknown {
                compid: CAMERA_COMPONENT_ID,
                result: MavResult::MAV_RESULT_UNSUPPORTED,
                ..
            }]
        ),
        "{out:?}"
    );
}

#[test]
fn broadcast_camera_requests_are_answered_by_the_camera_alone() {
    let mut r = rig();
    let (res, m) = camera_answer(
        &mut r,
        0,
        MavCmd::MAV_CMD_REQUEST_CAMERA_INFORMATION,
        &[1.0],
    );
    assert_eq!(res, MavResult::MAV_RESULT_ACCEPTED);
    assert!(matches!(m.as_slice(), [MavMessage::CAMERA_INFORMATION(_)]));
    let out = r.msg(
        A,
        command_to(0, MavCmd::MAV_CMD_REQUEST_CAMERA_INFORMATION, &[1.0]),
    );
    assert!(
        msgs!(&out, COMMAND_ACK).is_empty(),
        "the autopilot stays silent: {out:?}"
    );
    // A broadcast that is not a camera request stays the autopilot's.
    let out = r.msg(
        A,
        command_to(
            0,
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            &[AUTOPILOT_VERSION_DATA::ID as f32],
        ),
    );
    assert!(from_camera(&out).is_empty());
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_MESSAGE),
        MavResult::MAV_RESULT_ACCEPTED
    );
}

// ---- the gimbal ----

fn tilts(out: &[Output]) -> Vec<u16> {
    board_commands(out)
        .into_iter()
        .filter_map(|c| match c {
            Command::Tilt(us) => Some(us),
            _ => None,
        })
        .collect()
}

/// A rig where A controls the vehicle.
fn owned() -> CoreRig {
    let mut r = rig();
    r.alive.push(A);
    let out = r.request_control(A, 1.0, 0.0, 10.0);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(r.v.owner(), Some(255));
    r
}

fn pitch_of(q: [f32; 4]) -> f32 {
    let [w, x, y, z] = q;
    (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin().to_degrees()
}

#[test]
fn gimbal_manager_information_on_request() {
    let mut r = rig_with(
        Some(SPEC),
        &[("NEPT_TILT_MIN_US", 1100.0), ("NEPT_TILT_MAX_US", 1900.0)],
    );
    let out = r.cmd(
        A,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        &[GIMBAL_MANAGER_INFORMATION_DATA::ID as f32],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_REQUEST_MESSAGE),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let [ref info] = msgs!(&out, GIMBAL_MANAGER_INFORMATION)[..] else {
        panic!("{out:?}")
    };
    assert_eq!(info.gimbal_device_id, GIMBAL_DEVICE_ID);
    assert!(
        info.cap_flags
            .contains(GimbalManagerCapFlags::GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_AXIS)
    );
    assert!(
        !info
            .cap_flags
            .contains(GimbalManagerCapFlags::GIMBAL_MANAGER_CAP_FLAGS_HAS_YAW_AXIS)
    );
    // ±400 µs around neutral at 500 µs per 90°: ±72°.
    assert!(
        (info.pitch_min.to_degrees() + 72.0).abs() < 0.01,
        "{}",
        info.pitch_min.to_degrees()
    );
    assert!((info.pitch_max.to_degrees() - 72.0).abs() < 0.01);
    assert_eq!((info.yaw_min, info.yaw_max), (0.0, 0.0));
}

#[test]
fn gimbal_status_and_attitude_are_streamed_with_the_owner() {
    let mut r = owned();
    let out = r.run(Duration::from_secs(2));
    let status = msgs!(&out, GIMBAL_MANAGER_STATUS);
    let att = msgs!(&out, GIMBAL_DEVICE_ATTITUDE_STATUS);
    // Two endpoints: 1 Hz and 5 Hz on each.
    assert!(
        (4..=6).contains(&status.len()),
        "{} GIMBAL_MANAGER_STATUS in 2 s",
        status.len()
    );
    assert!(
        (18..=22).contains(&att.len()),
        "{} GIMBAL_DEVICE_ATTITUDE_STATUS in 2 s",
        att.len()
    );
    let s = status.last().unwrap();
    assert_eq!(
        (
            s.gimbal_device_id,
            s.primary_control_sysid,
            s.primary_control_compid
        ),
        (1, 255, 190)
    );
    let a = att.last().unwrap();
    assert_eq!(a.gimbal_device_id, GIMBAL_DEVICE_ID);
    assert!(pitch_of(a.q).abs() < 0.01);
}

#[test]
fn owner_sets_pitch_by_command_and_messages() {
    let mut r = owned();
    let out = r.cmd(
        A,
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        &[-30.0, f32::NAN, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW),
        MavResult::MAV_RESULT_ACCEPTED
    );
    // -30° at 500 µs per 90°: 1500 - 166.7.
    assert_eq!(tilts(&out), vec![1333]);
    assert_eq!(r.v.tilt_us(), 1333);
    let out = r.cmd(
        A,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        &[GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID as f32],
    );
    let [ref a] = msgs!(&out, GIMBAL_DEVICE_ATTITUDE_STATUS)[..] else {
        panic!("{out:?}")
    };
    assert!(
        (pitch_of(a.q) + 30.0).abs() < 0.2,
        "pitch {}",
        pitch_of(a.q)
    );

    // GIMBAL_MANAGER_SET_PITCHYAW (radians), then SET_ATTITUDE (quaternion).
    let out = r.msg(
        A,
        MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(GIMBAL_MANAGER_SET_PITCHYAW_DATA {
            target_system: 1,
            target_component: 1,
            flags: GimbalManagerFlags::empty(),
            gimbal_device_id: 0,
            pitch: 45f32.to_radians(),
            yaw: f32::NAN,
            pitch_rate: f32::NAN,
            yaw_rate: f32::NAN,
        }),
    );
    assert_eq!(tilts(&out), vec![1750]);
    let half = (-45f32).to_radians() / 2.0;
    let out = r.msg(
        A,
        MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(GIMBAL_MANAGER_SET_ATTITUDE_DATA {
            target_system: 1,
            target_component: 1,
            flags: GimbalManagerFlags::empty(),
            gimbal_device_id: GIMBAL_DEVICE_ID,
            q: [half.cos(), 0.0, half.sin(), 0.0],
            ..Default::default()
        }),
    );
    assert_eq!(tilts(&out), vec![1250]);
    // Beyond the servo's range: clamped to NEPT_TILT_MIN_US.
    let out = r.cmd(A, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, &[-120.0]);
    assert_eq!(tilts(&out), vec![1000]);
    // Another gimbal device id: not ours.
    let out = r.cmd(
        A,
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        &[10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.0],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW),
        MavResult::MAV_RESULT_DENIED
    );
    assert!(tilts(&out).is_empty());
    // Garbage (NaN quaternion) moves nothing and does not panic.
    let out = r.msg(
        A,
        MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(GIMBAL_MANAGER_SET_ATTITUDE_DATA {
            target_system: 1,
            target_component: 1,
            flags: GimbalManagerFlags::empty(),
            q: [f32::NAN; 4],
            ..Default::default()
        }),
    );
    assert!(tilts(&out).is_empty());
    assert_eq!(r.v.tilt_us(), 1000);
    // The NEUTRAL flag centres the tilt.
    let out = r.msg(
        A,
        MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(GIMBAL_MANAGER_SET_PITCHYAW_DATA {
            target_system: 1,
            target_component: 1,
            flags: GimbalManagerFlags::GIMBAL_MANAGER_FLAGS_NEUTRAL,
            pitch: f32::NAN,
            ..Default::default()
        }),
    );
    assert_eq!(tilts(&out), vec![1500]);
}

#[test]
fn attitude_reports_where_the_board_says_the_servo_is() {
    let mut r = owned();
    r.cmd(A, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, &[-30.0]);
    // The board reports its servo still on the way (1400 µs = -18°).
    r.feed.status.servo_us = Some(1400);
    r.run(Duration::from_millis(1100));
    let out = r.cmd(
        A,
        MavCmd::MAV_CMD_REQUEST_MESSAGE,
        &[GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID as f32],
    );
    let [ref a] = msgs!(&out, GIMBAL_DEVICE_ATTITUDE_STATUS)[..] else {
        panic!("{out:?}")
    };
    assert!(
        (pitch_of(a.q) + 18.0).abs() < 0.2,
        "pitch {}",
        pitch_of(a.q)
    );
}

#[test]
fn non_owner_cannot_move_the_gimbal() {
    let mut r = owned();
    let before = r.v.tilt_us();
    let out = r.cmd(B, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, &[-30.0]);
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW),
        MavResult::MAV_RESULT_NOT_IN_CONTROL
    );
    assert!(tilts(&out).is_empty());
    let refused_before = r.v.refused_inputs();
    let out = r.msg(
        B,
        MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(GIMBAL_MANAGER_SET_PITCHYAW_DATA {
            target_system: 1,
            target_component: 1,
            flags: GimbalManagerFlags::empty(),
            pitch: -0.5,
            ..Default::default()
        }),
    );
    assert!(tilts(&out).is_empty());
    assert_eq!(r.v.refused_inputs(), refused_before + 1, "counted");
    assert!(has_text(&out, "GIMBAL_MANAGER_SET_PITCHYAW"), "{out:?}");
    assert_eq!(r.v.tilt_us(), before);
    // Taking gimbal control (what QGC sends first) is taking the vehicle's.
    let configure = MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE;
    let out = r.cmd(B, configure, &[-2.0, -2.0, -1.0, -1.0]);
    assert_eq!(
        ack_of(&out, configure),
        MavResult::MAV_RESULT_NOT_IN_CONTROL
    );
    assert_eq!(r.v.owner(), Some(255));
    let out = r.cmd(A, configure, &[-2.0, -2.0, -1.0, -1.0]);
    assert_eq!(ack_of(&out, configure), MavResult::MAV_RESULT_ACCEPTED);
}

#[test]
fn nobody_in_control_nobody_moves_the_gimbal_unless_allowed_to_claim() {
    // With no owner, a station that may not control is refused.
    let mut r = rig();
    let stranger = Sender::new(0, 9, 77, 190);
    let out = r.cmd(
        stranger,
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        &[-30.0],
    );
    assert_ne!(
        ack_of(&out, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(tilts(&out).is_empty());
}

#[test]
fn a_pitch_rate_slews_while_repeated_and_stops_after_a_second() {
    let mut r = owned();
    let rate = |pitch_rate_dps: f32| {
        MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(GIMBAL_MANAGER_SET_PITCHYAW_DATA {
            target_system: 1,
            target_component: 1,
            flags: GimbalManagerFlags::empty(),
            gimbal_device_id: 0,
            pitch: f32::NAN,
            yaw: f32::NAN,
            pitch_rate: pitch_rate_dps.to_radians(),
            yaw_rate: f32::NAN,
        })
    };
    // 18 deg/s = 100 us/s, repeated every 0.5 s for 2 s.
    for _ in 0..4 {
        r.msg(A, rate(18.0));
        r.run(Duration::from_millis(500));
    }
    let moved = r.v.tilt_us();
    assert!(
        (1695..=1701).contains(&moved),
        "after 2 s at 100 us/s: {moved}"
    );
    // No repeat: it stops within the hold (1 s).
    r.run(Duration::from_secs(3));
    let stopped = r.v.tilt_us();
    assert!(stopped - moved <= 101, "{moved} -> {stopped}");
    r.run(Duration::from_secs(1));
    assert_eq!(
        r.v.tilt_us(),
        stopped,
        "the rate must stop without its repeats"
    );
    // A stop (rate 0) stops at once; a non-owner's rate does nothing.
    r.msg(A, rate(-18.0));
    r.run(Duration::from_millis(300));
    r.msg(A, rate(0.0));
    let here = r.v.tilt_us();
    r.run(Duration::from_millis(500));
    assert_eq!(r.v.tilt_us(), here);
    r.msg(B, rate(-90.0));
    let out = r.run(Duration::from_millis(500));
    assert!(tilts(&out).is_empty(), "a non-owner's rate moved the tilt");
    // By command: p3 the pitch rate, p1 NaN.
    let out = r.cmd(
        A,
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        &[f32::NAN, f32::NAN, -18.0],
    );
    assert_eq!(
        ack_of(&out, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW),
        MavResult::MAV_RESULT_ACCEPTED
    );
    r.run(Duration::from_millis(500));
    assert!(r.v.tilt_us() < here - 40, "{here} -> {}", r.v.tilt_us());
}

#[test]
fn a_pitch_rate_ends_at_a_safety_stop() {
    let mut r = owned();
    r.msg(
        A,
        MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(GIMBAL_MANAGER_SET_PITCHYAW_DATA {
            target_system: 1,
            target_component: 1,
            flags: GimbalManagerFlags::empty(),
            gimbal_device_id: 0,
            pitch: f32::NAN,
            yaw: f32::NAN,
            pitch_rate: 18.0_f32.to_radians(),
            yaw_rate: f32::NAN,
        }),
    );
    r.run(Duration::from_millis(300));
    let moving = r.v.tilt_us();
    assert!(moving > 1500, "the rate moves the tilt: {moving}");
    // The owner lets go: a safety stop, so its rate ends with it.
    let release = MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL;
    let out = r.cmd(A, release, &[0.0]);
    assert_eq!(ack_of(&out, release), MavResult::MAV_RESULT_ACCEPTED);
    let here = r.v.tilt_us();
    r.run(Duration::from_millis(800));
    assert_eq!(
        r.v.tilt_us(),
        here,
        "the tilt kept slewing after the release"
    );
}
