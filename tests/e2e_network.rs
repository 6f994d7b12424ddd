//! Safe to put on a network, end to end: the built `neptunus --sim` with
//! bare UDP ground stations.
//!
//! - A stranger (sysid 77, unsigned, not allowed) shares the owner's UDP
//!   endpoint and asks for HEARTBEAT and ATTITUDE off and everything at
//!   1000 Hz: denied, and the owner's telemetry goes on as before.
//! - A broken data directory: the vehicle starts anyway, a parameter change
//!   is acknowledged and announced as not saved (STATUSTEXT naming it,
//!   SYS_STATUS logging unhealthy), saved once the disk is back, and there
//!   after a restart.
//!
//! How to break a data directory when tests run as root: permission bits do
//! not stop root (CAP_DAC_OVERRIDE), and a read-only bind mount needs
//! CAP_SYS_ADMIN, which a test cannot count on. A regular file where the
//! data directory should be fails for everyone: creating the directory
//! gives EEXIST and every path inside it ENOTDIR — exactly what a read-only
//! or vanished SD card gives the vehicle (every write fails, reads find
//! nothing). Removing the file is "the disk is back".
//!
//! Time is real (a child process), so every wait is for a condition with a
//! generous deadline; rates are measured from the vehicle's own
//! `time_boot_ms`, not from when this process happens to read its socket.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::net::UdpSocket;
use std::path::Path;
use std::time::{Duration, Instant};

use common::{Gcs, Traffic, Vehicle, free_udp_port, statustext};
use neptunus::dialect::neptunus::*;
use neptunus::mavlink::frame::{FrameStats, decode_datagram, encode_v2};

const GENEROUS: Duration = Duration::from_secs(20);

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

/// A station with its own system id on the vehicle's udpin endpoint.
struct Station {
    sock: UdpSocket,
    sysid: u8,
    seq: u8,
}

impl Station {
    fn connect(port: u16, sysid: u8) -> Self {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.connect(("127.0.0.1", port)).unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(5)))
            .unwrap();
        Self {
            sock,
            sysid,
            seq: 0,
        }
    }
    fn send(&mut self, msg: &MavMessage) {
        let bytes = encode_v2(self.sysid, 190, self.seq, msg);
        self.seq = self.seq.wrapping_add(1);
        let _ = self.sock.send(&bytes);
    }
    fn recv(&self) -> Vec<MavMessage> {
        let mut buf = [0u8; 4096];
        let mut out = Vec::new();
        if let Ok(n) = self.sock.recv(&mut buf) {
            decode_datagram(&buf[..n], &mut FrameStats::default(), &mut out);
        }
        out.into_iter().map(|f| f.msg).collect()
    }
    fn set_interval(&mut self, msg_id: u32, interval_us: f32) {
        self.send(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: msg_id as f32,
            param2: interval_us,
            command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }));
    }
}

#[test]
fn a_stranger_on_the_owners_endpoint_cannot_silence_or_flood_it() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port().unwrap();
    let url = format!("udpin:127.0.0.1:{port}");
    let mut vehicle = Vehicle::spawn(bin(), &["--sim", "--mavlink", &url], dir.path(), "").unwrap();
    let mut owner = Gcs::connect(port).unwrap();
    // The owner is a peer and gets attitude.
    let seen = owner
        .run_until(&mut vehicle, Traffic::Heartbeats, GENEROUS, |m| {
            m.iter().any(|m| matches!(m, MavMessage::ATTITUDE(_)))
        })
        .unwrap();
    assert!(seen, "no ATTITUDE:\n{}", vehicle.stderr_tail());

    let mut stranger = Station::connect(port, 77);
    let mut asked = vec![0u32, 30];
    stranger.set_interval(0, -1.0);
    stranger.set_interval(30, -1.0);
    for (id, _) in neptunus::vehicle::telemetry::STREAMABLE {
        stranger.set_interval(*id, 1000.0);
        asked.push(*id);
    }
    stranger.send(&MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
        req_message_rate: 1000,
        target_system: 1,
        target_component: 1,
        req_stream_id: MavDataStream::MAV_DATA_STREAM_ALL,
        start_stop: 1,
    }));
    // Every SET_MESSAGE_INTERVAL is denied.
    let mut denied = 0;
    let mut other = Vec::new();
    let end = Instant::now() + GENEROUS;
    while denied < asked.len() && Instant::now() < end {
        owner.pump(Traffic::Heartbeats).unwrap();
        let _ = owner.recv();
        for m in stranger.recv() {
            if let MavMessage::COMMAND_ACK(a) = m
                && a.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL
            {
                if a.result == MavResult::MAV_RESULT_DENIED {
                    denied += 1;
                } else {
                    other.push(a.result);
                }
            }
        }
    }
    assert_eq!(denied, asked.len(), "not denied: {other:?}");

    // The owner's telemetry is as before: heartbeats keep coming, and
    // ATTITUDE stays at its 10 Hz by the vehicle's own clock.
    let mut heartbeats = 0;
    let mut stamps = Vec::new();
    let done = owner
        .run_until(&mut vehicle, Traffic::Heartbeats, GENEROUS, |msgs| {
            for m in msgs {
                match m {
                    MavMessage::HEARTBEAT(_) => heartbeats += 1,
                    MavMessage::ATTITUDE(a) => stamps.push(a.time_boot_ms),
                    _ => {}
                }
            }
            heartbeats >= 3 && stamps.len() >= 30
        })
        .unwrap();
    assert!(
        done,
        "owner starved: {heartbeats} heartbeats, {} attitudes",
        stamps.len()
    );
    let span_ms = f64::from(stamps[stamps.len() - 1] - stamps[0]);
    let mean_ms = span_ms / (stamps.len() - 1) as f64;
    assert!(
        (80.0..=130.0).contains(&mean_ms),
        "ATTITUDE every {mean_ms:.1} ms (10 Hz = 100 ms; the stranger asked 1 ms)"
    );
}

fn sys_status_logging(m: &MavMessage) -> Option<bool> {
    let logging = MavSysStatusSensor::MAV_SYS_STATUS_LOGGING;
    match m {
        MavMessage::SYS_STATUS(s) if s.onboard_control_sensors_present.contains(logging) => {
            Some(s.onboard_control_sensors_health.contains(logging))
        }
        _ => None,
    }
}

#[test]
fn a_broken_data_directory_degrades_reports_unsaved_changes_and_recovers() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    // See the module docs: a file where the directory should be.
    std::fs::write(&data, b"not a directory").unwrap();
    let port = free_udp_port().unwrap();
    let url = format!("udpin:127.0.0.1:{port}");
    // The HMI writes DATA_DIR/http.addr at start; it is off here (that file
    // belongs to the HMI's own degraded-start handling).
    let args = ["--sim", "--mavlink", url.as_str(), "--http", "off"];
    let mut vehicle = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();
    let mut gcs = Gcs::connect(port).unwrap();

    // It runs, and says storage is unhealthy.
    let mut unhealthy = false;
    let started = gcs
        .run_until(&mut vehicle, Traffic::Heartbeats, GENEROUS, |msgs| {
            unhealthy |= msgs.iter().any(|m| sys_status_logging(m) == Some(false));
            unhealthy
        })
        .unwrap();
    assert!(
        started,
        "no SYS_STATUS with logging unhealthy:\n{}",
        vehicle.stderr_tail()
    );

    // A change is acknowledged, and everyone is told it is not saved.
    gcs.send(&MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: 0.7,
        target_system: 1,
        target_component: 1,
        param_id: "JS_GAIN_DEFAULT".into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    }))
    .unwrap();
    let mut echoed = false;
    let mut warning = String::new();
    let told = gcs
        .run_until(&mut vehicle, Traffic::Heartbeats, GENEROUS, |msgs| {
            for m in msgs {
                match m {
                    MavMessage::PARAM_VALUE(v) if v.param_id.to_str() == Ok("JS_GAIN_DEFAULT") => {
                        echoed |= (v.param_value - 0.7).abs() < 1e-6;
                    }
                    MavMessage::STATUSTEXT(s)
                        if s.severity == MavSeverity::MAV_SEVERITY_WARNING =>
                    {
                        warning.push_str(&statustext(s));
                    }
                    _ => {}
                }
            }
            echoed && warning.contains("JS_GAIN_DEFAULT")
        })
        .unwrap();
    assert!(
        told,
        "echoed {echoed}, warning {warning:?}:\n{}",
        vehicle.stderr_tail()
    );
    assert!(warning.contains("NOT SAVED"), "{warning}");

    // The disk is back: the retry saves, and says so.
    std::fs::remove_file(&data).unwrap();
    let mut info = String::new();
    let mut healthy = false;
    let saved = gcs
        .run_until(&mut vehicle, Traffic::Heartbeats, GENEROUS, |msgs| {
            for m in msgs {
                if let MavMessage::STATUSTEXT(s) = m {
                    info.push_str(&statustext(s));
                }
                healthy |= sys_status_logging(m) == Some(true);
            }
            info.contains("Parameters saved") && healthy
        })
        .unwrap();
    assert!(saved, "texts {info:?}, healthy {healthy}");
    let file = std::fs::read_to_string(data.join("params.toml")).unwrap();
    assert!(file.contains("JS_GAIN_DEFAULT = 0.7"), "{file}");

    // And it is there after a restart.
    drop(gcs);
    drop(vehicle);
    let mut vehicle = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();
    let mut gcs = Gcs::connect(port).unwrap();
    let value = gcs.param(&mut vehicle, "JS_GAIN_DEFAULT");
    let value = match value {
        Ok(v) => v,
        // The first request may go out before the port is bound.
        Err(_) => gcs.param(&mut vehicle, "JS_GAIN_DEFAULT").unwrap(),
    };
    assert!((value - 0.7).abs() < 1e-6, "{value}");
}

#[test]
fn a_stale_params_tmp_is_removed_at_start() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data).unwrap();
    // What a kill between write and rename leaves behind.
    std::fs::write(data.join("params.toml.tmp"), "JS_GAIN_DEFAULT = 0.9\n").unwrap();
    let port = free_udp_port().unwrap();
    let url = format!("udpin:127.0.0.1:{port}");
    let mut vehicle = Vehicle::spawn(
        bin(),
        &["--sim", "--mavlink", &url],
        dir.path(),
        "JS_GAIN_DEFAULT = 0.6\n",
    )
    .unwrap();
    let mut gcs = Gcs::connect(port).unwrap();
    // Once it answers, start-up is over.
    let value = match gcs.param(&mut vehicle, "JS_GAIN_DEFAULT") {
        Ok(v) => v,
        Err(_) => gcs.param(&mut vehicle, "JS_GAIN_DEFAULT").unwrap(),
    };
    assert!((value - 0.6).abs() < 1e-6, "params.toml wins: {value}");
    assert!(!data.join("params.toml.tmp").exists());
}

/// A PARAM_SET whose `param_type` is no MAV_PARAM_TYPE at all (0, 200)
/// cannot be decoded into a message, yet it is answered with the
/// parameter's unchanged value (as ArduPilot does), never dropped silently.
#[test]
fn a_param_set_with_an_invalid_type_is_answered_with_the_current_value() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port().unwrap();
    let url = format!("udpin:127.0.0.1:{port}");
    let mut vehicle = Vehicle::spawn(bin(), &["--sim", "--mavlink", &url], dir.path(), "").unwrap();
    let mut owner = Gcs::connect(port).unwrap();
    owner.wait_ready(&mut vehicle).unwrap();
    let before = owner.param(&mut vehicle, "JS_GAIN_DEFAULT").unwrap();
    for bad_type in [0u8, 200] {
        let mut frame = encode_v2(
            255,
            190,
            0,
            &MavMessage::PARAM_SET(PARAM_SET_DATA {
                param_value: 0.9,
                target_system: 1,
                target_component: 1,
                param_id: "JS_GAIN_DEFAULT".into(),
                param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
            }),
        );
        // param_type is the last payload byte (22); the CRC follows it.
        let crc_at = frame.len() - 2;
        assert_eq!(crc_at, 10 + 23, "PARAM_SET is sent whole");
        frame[crc_at - 1] = bad_type;
        let crc = mavlink_core::calculate_crc(
            &frame[1..crc_at],
            <MavMessage as mavlink_core::Message>::extra_crc(23),
        );
        frame[crc_at..].copy_from_slice(&crc.to_le_bytes());
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.connect(("127.0.0.1", port)).unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let end = Instant::now() + GENEROUS;
        let mut answer = None;
        let mut buf = [0u8; 4096];
        while answer.is_none() && Instant::now() < end {
            sock.send(&frame).unwrap();
            let until = Instant::now() + Duration::from_millis(300);
            while answer.is_none() && Instant::now() < until {
                let Ok(n) = sock.recv(&mut buf) else { continue };
                let mut frames = Vec::new();
                decode_datagram(&buf[..n], &mut FrameStats::default(), &mut frames);
                answer = frames.into_iter().find_map(|f| match f.msg {
                    MavMessage::PARAM_VALUE(p)
                        if p.param_id.to_str().ok() == Some("JS_GAIN_DEFAULT") =>
                    {
                        Some(p.param_value)
                    }
                    _ => None,
                });
            }
        }
        assert_eq!(
            answer,
            Some(before),
            "type {bad_type}: not answered with the current value\n{}",
            vehicle.stderr_tail()
        );
    }
    assert_eq!(
        owner.param(&mut vehicle, "JS_GAIN_DEFAULT").unwrap(),
        before
    );
}
