//! Recording on the vehicle, on the core rig: who may start and stop it
//! (the authority check), what the camera component says while it records
//! (CAMERA_INFORMATION, CAMERA_CAPTURE_STATUS, STORAGE_INFORMATION), the
//! telemetry rows it hands the recorder, and that a recording stopped by
//! the storage floor says so and changes nothing else: the dive goes on.

#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, gos, statustexts, texts_to};
use mavlink_core::MessageData;
use neptunus::dialect::neptunus::*;
use neptunus::vehicle::machine::{
    CAMERA_COMPONENT_ID, CameraSpec, Identity, Input, Output, RecordControl, RecorderEvent, Sender,
    StorageReport, To, Vehicle,
};
use neptunus::vehicle::params::ParamStore;

/// The pilot (SYSID_MYGCS), another allowed station, and a stranger.
const A: Sender = Sender::new(0, 1, 255, 190);
const B: Sender = Sender::new(0, 2, 254, 190);
const STRANGER: Sender = Sender::new(0, 3, 77, 190);
const SPEC: CameraSpec = CameraSpec {
    width: 640,
    height: 480,
    fps: 15.0,
};
const MIB: u64 = 1024 * 1024;

fn rig(recording: bool) -> CoreRig {
    let mut p = ParamStore::defaults();
    p.set("NEPT_GCS_ALLOW2", 254.0).unwrap();
    let v = Vehicle::new(Identity::Ardupilot, p, 2)
        .with_camera(Some(SPEC))
        .with_recording(recording);
    CoreRig::new(v).alive(A).started()
}

fn to_camera(cmd: MavCmd, p: &[f32]) -> MavMessage {
    let mut q = [0.0; 7];
    q[..p.len()].copy_from_slice(p);
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: q[0],
        param2: q[1],
        param3: q[2],
        param4: q[3],
        param5: q[4],
        param6: q[5],
        param7: q[6],
        command: cmd,
        target_system: 1,
        target_component: CAMERA_COMPONENT_ID,
        confirmation: 0,
    })
}

/// The camera's ack to `cmd` in `out`.
fn camera_ack(out: &[Output], cmd: MavCmd) -> MavResult {
    out.iter()
        .find_map(|o| match o {
            Output::SendAs {
                compid: CAMERA_COMPONENT_ID,
                msg: MavMessage::COMMAND_ACK(a),
                ..
            } if a.command == cmd => Some(a.result),
            _ => None,
        })
        .unwrap_or_else(|| panic!("no ack for {cmd:?} in {out:?}"))
}

fn records(out: &[Output]) -> Vec<RecordControl> {
    out.iter()
        .filter_map(|o| match o {
            Output::Record(c) => Some(*c),
            _ => None,
        })
        .collect()
}

/// The CAMERA_CAPTURE_STATUS messages to everyone in `out`.
fn capture_statuses(out: &[Output]) -> Vec<CAMERA_CAPTURE_STATUS_DATA> {
    out.iter()
        .filter_map(|o| match o {
            Output::SendAs {
                to: To::All,
                compid: CAMERA_COMPONENT_ID,
                msg: MavMessage::CAMERA_CAPTURE_STATUS(c),
            } => Some(c.clone()),
            _ => None,
        })
        .collect()
}

fn request(r: &mut CoreRig, id: u32) -> MavMessage {
    let out = r.msg(A, to_camera(MavCmd::MAV_CMD_REQUEST_MESSAGE, &[id as f32]));
    out.iter()
        .find_map(|o| match o {
            Output::SendAs {
                compid: CAMERA_COMPONENT_ID,
                msg,
                ..
            } if mavlink_core::Message::message_id(msg) == id => Some(msg.clone()),
            _ => None,
        })
        .unwrap()
}

#[test]
fn the_camera_says_it_records_only_with_a_recorder() {
    for recording in [false, true] {
        let mut r = rig(recording);
        let MavMessage::CAMERA_INFORMATION(info) = request(&mut r, CAMERA_INFORMATION_DATA::ID)
        else {
            panic!()
        };
        assert_eq!(
            info.flags
                .contains(CameraCapFlags::CAMERA_CAP_FLAGS_CAPTURE_VIDEO),
            recording
        );
        let out = r.msg(A, to_camera(MavCmd::MAV_CMD_VIDEO_START_CAPTURE, &[0.0]));
        let expected = if recording {
            MavResult::MAV_RESULT_ACCEPTED
        } else {
            MavResult::MAV_RESULT_UNSUPPORTED
        };
        assert_eq!(
            camera_ack(&out, MavCmd::MAV_CMD_VIDEO_START_CAPTURE),
            expected
        );
    }
}

#[test]
fn only_a_station_that_may_control_starts_or_stops_a_recording() {
    let mut r = rig(true);
    // A stranger may not, even with nobody in control.
    let out = r.msg(
        STRANGER,
        to_camera(MavCmd::MAV_CMD_VIDEO_START_CAPTURE, &[0.0]),
    );
    assert_eq!(
        camera_ack(&out, MavCmd::MAV_CMD_VIDEO_START_CAPTURE),
        MavResult::MAV_RESULT_NOT_IN_CONTROL
    );
    assert!(records(&out).is_empty());
    assert!(
        capture_statuses(&out).is_empty(),
        "a refusal changes nothing others see"
    );
    assert!(
        !texts_to(&out, STRANGER).is_empty(),
        "the reason, to it alone"
    );
    // A takes control by arming; B (allowed, not in control) is refused.
    r.arm(A);
    let out = r.msg(B, to_camera(MavCmd::MAV_CMD_VIDEO_START_CAPTURE, &[0.0]));
    assert_eq!(
        camera_ack(&out, MavCmd::MAV_CMD_VIDEO_START_CAPTURE),
        MavResult::MAV_RESULT_NOT_IN_CONTROL
    );
    assert!(records(&out).is_empty());
    // The pilot starts it: ack first, then everyone hears it records.
    let out = r.msg(
        A,
        to_camera(MavCmd::MAV_CMD_VIDEO_START_CAPTURE, &[0.0, 0.0]),
    );
    assert_eq!(records(&out), [RecordControl::Start]);
    let ack_at = out
        .iter()
        .position(|o| {
            matches!(
                o,
                Output::SendAs {
                    msg: MavMessage::COMMAND_ACK(_),
                    ..
                }
            )
        })
        .unwrap();
    let status_at = out
        .iter()
        .position(|o| {
            matches!(
                o,
                Output::SendAs {
                    msg: MavMessage::CAMERA_CAPTURE_STATUS(_),
                    ..
                }
            )
        })
        .unwrap();
    assert!(ack_at < status_at, "{out:?}");
    assert_eq!(capture_statuses(&out)[0].video_status, 1);
    assert!(r.v.recording());
    // B cannot stop the pilot's recording.
    let out = r.msg(B, to_camera(MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE, &[0.0]));
    assert_eq!(
        camera_ack(&out, MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE),
        MavResult::MAV_RESULT_NOT_IN_CONTROL
    );
    assert!(records(&out).is_empty() && r.v.recording());
    // The pilot can.
    let out = r.msg(A, to_camera(MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE, &[0.0]));
    assert_eq!(records(&out), [RecordControl::Stop]);
    assert_eq!(capture_statuses(&out)[0].video_status, 0);
    assert!(!r.v.recording());
    // Another stream than ours (1) is denied.
    let out = r.msg(A, to_camera(MavCmd::MAV_CMD_VIDEO_START_CAPTURE, &[3.0]));
    assert_eq!(
        camera_ack(&out, MavCmd::MAV_CMD_VIDEO_START_CAPTURE),
        MavResult::MAV_RESULT_DENIED
    );
}

#[test]
fn while_recording_the_status_and_the_telemetry_rows_come_on_their_clocks() {
    let mut r = rig(true);
    r.input(Input::Recorder(RecorderEvent::Storage(StorageReport {
        total_bytes: 1000 * MIB,
        used_bytes: 100 * MIB,
        available_bytes: 900 * MIB,
        blocked: None,
    })));
    r.msg(A, to_camera(MavCmd::MAV_CMD_VIDEO_START_CAPTURE, &[0.0]));
    let out = r.input(Input::Recorder(RecorderEvent::Started {
        name: "rec-20261129-063500".into(),
    }));
    assert!(
        statustexts(&out)
            .iter()
            .any(|t| t.contains("Recording on the vehicle: rec-20261129-063500")),
        "{out:?}"
    );
    let out = r.run(Duration::from_secs(10));
    let statuses = capture_statuses(&out);
    assert!(
        (9..=11).contains(&statuses.len()),
        "about 1 Hz: {}",
        statuses.len()
    );
    let last = statuses.last().unwrap();
    assert_eq!(last.video_status, 1);
    assert!(
        (9000..=10_000).contains(&last.recording_time_ms),
        "{last:?}"
    );
    assert!((last.available_capacity - 900.0).abs() < 0.01);
    let samples: Vec<_> = out
        .iter()
        .filter_map(|o| match o {
            Output::RecordSample(s) => Some(s.clone()),
            _ => None,
        })
        .collect();
    assert!(
        (48..=52).contains(&samples.len()),
        "5 a second: {}",
        samples.len()
    );
    let s = &samples[samples.len() - 1];
    assert!(s.depth_m.is_some_and(|d| (d - 1.0).abs() < 0.2), "{s:?}");
    assert!(s.heading_deg.is_some() && s.mode == "MANUAL" && !s.armed);
    for w in samples.windows(2) {
        let gap = w[1].mono - w[0].mono;
        assert!(
            gap >= Duration::from_millis(100) && gap <= Duration::from_millis(300),
            "{gap:?}"
        );
    }
    // STORAGE_INFORMATION from the recorder's measures.
    let MavMessage::STORAGE_INFORMATION(si) = request(&mut r, STORAGE_INFORMATION_DATA::ID) else {
        panic!()
    };
    assert_eq!(si.status, StorageStatus::STORAGE_STATUS_READY);
    assert_eq!((si.storage_count, si.storage_id), (1, 1));
    assert!((si.total_capacity - 1000.0).abs() < 0.01 && (si.used_capacity - 100.0).abs() < 0.01);
    // Stale readings are written empty, never as if live.
    let out = r.run_board_silent(Duration::from_secs(3));
    let last = out
        .iter()
        .rev()
        .find_map(|o| match o {
            Output::RecordSample(s) => Some(s.clone()),
            _ => None,
        })
        .unwrap();
    assert_eq!((last.depth_m, last.heading_deg), (None, None));
}

#[test]
fn at_the_floor_a_recording_stops_with_a_message_and_the_dive_goes_on() {
    let mut r = rig(true);
    let out = r.arm(A);
    assert!(r.v.armed(), "{out:?}");
    r.msg(A, to_camera(MavCmd::MAV_CMD_VIDEO_START_CAPTURE, &[0.0]));
    r.input(Input::Recorder(RecorderEvent::Started {
        name: "rec-20261129-063500".into(),
    }));
    // Driving for 2 s, the sticks repeated as a ground station does.
    for _ in 0..20 {
        r.stick(A, 600);
        r.run(Duration::from_millis(100));
    }
    assert_ne!(r.v.motors_us(), [1500; 3]);
    let why = "free space 255 MiB is at the floor of 256 MiB ([storage] min_free_mb)";
    r.input(Input::Recorder(RecorderEvent::Storage(StorageReport {
        blocked: Some(why.into()),
        ..StorageReport::default()
    })));
    let out = r.input(Input::Recorder(RecorderEvent::Stopped {
        name: Some("rec-20261129-063500".into()),
        duration_s: 2.0,
        why: Some(why.into()),
    }));
    let texts = statustexts(&out);
    assert!(
        texts
            .iter()
            .any(|t| t.starts_with("Recording stopped: free space 255 MiB")),
        "{texts:?}"
    );
    assert_eq!(capture_statuses(&out)[0].video_status, 0);
    assert!(!r.v.recording());
    // Still armed and driving: the sticks still move the thrusters, and
    // back to neutral when centred.
    r.stick(A, 600);
    r.run(Duration::from_millis(100));
    assert!(r.v.armed());
    assert_ne!(r.v.motors_us(), [1500; 3]);
    let out = r.stick(A, 0);
    assert_eq!(gos(&out).last(), Some(&[1500; 3]), "{out:?}");
    // No new recording while the floor is reached: refused with the reason.
    let out = r.msg(A, to_camera(MavCmd::MAV_CMD_VIDEO_START_CAPTURE, &[0.0]));
    assert_eq!(
        camera_ack(&out, MavCmd::MAV_CMD_VIDEO_START_CAPTURE),
        MavResult::MAV_RESULT_DENIED
    );
    assert!(records(&out).is_empty());
    assert!(texts_to(&out, A).iter().any(|t| t.contains("min_free_mb")));
}
