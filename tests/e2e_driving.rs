//! Driving end to end: `neptunus --sim` over real UDP, the board emulator on
//! its pty and the simulator — stick in, thrusters and motion out.
//!
//! The ground station here is a bare UDP socket speaking MAVLink 2 through
//! our own dialect (it also knows NEPTUNUS_THRUSTERS); the interop suite does
//! the same with pymavlink, MAVProxy and MAVSDK.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use neptunus::dialect::neptunus::*;
use neptunus::mavlink::frame::{Frame, decode_datagram, encode_v2};

struct Sim {
    child: Child,
    sock: UdpSocket,
    seq: u8,
    _dir: tempfile::TempDir,
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Sim {
    fn start() -> Self {
        let dir = tempfile::tempdir().unwrap();
        // The vehicle sends to our socket (udpout): no port guessing on its side.
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        let port = sock.local_addr().unwrap().port();
        let child = Command::new(env!("CARGO_BIN_EXE_neptunus"))
            .args([
                "--sim",
                "--mavlink",
                &format!("udpout:127.0.0.1:{port}"),
                "--http",
                "127.0.0.1:0",
                "--data-dir",
            ])
            .arg(dir.path())
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut sim = Self {
            child,
            sock,
            seq: 0,
            _dir: dir,
        };
        // The vehicle's first datagram tells us where it is.
        let mut buf = [0u8; 2048];
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            assert!(Instant::now() < deadline, "no heartbeat from neptunus");
            if let Ok((n, from)) = sim.sock.recv_from(&mut buf) {
                sim.sock.connect(from).unwrap();
                let _ = n;
                break;
            }
        }
        sim.wait_for(Duration::from_secs(20), |m| {
            matches!(m, MavMessage::SYS_STATUS(s) if s.onboard_control_sensors_health.contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK))
        })
        .expect("vehicle ready");
        sim
    }

    fn send(&mut self, msg: MavMessage) {
        let bytes = encode_v2(255, 190, self.seq, &msg);
        self.seq = self.seq.wrapping_add(1);
        self.sock.send(&bytes).unwrap();
    }

    fn frames(&mut self) -> Vec<Frame> {
        let mut buf = [0u8; 4096];
        let mut out = Vec::new();
        let mut stats = Default::default();
        if let Ok(n) = self.sock.recv(&mut buf) {
            decode_datagram(&buf[..n], &mut stats, &mut out);
        }
        out
    }

    fn wait_for(
        &mut self,
        within: Duration,
        mut f: impl FnMut(&MavMessage) -> bool,
    ) -> Option<MavMessage> {
        let end = Instant::now() + within;
        while Instant::now() < end {
            for fr in self.frames() {
                if fr.sysid == 1 && fr.compid == 1 && f(&fr.msg) {
                    return Some(fr.msg);
                }
            }
        }
        None
    }

    fn command(&mut self, command: MavCmd, p: [f32; 7]) -> MavResult {
        self.send(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            command,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }));
        match self.wait_for(
            Duration::from_secs(5),
            |m| matches!(m, MavMessage::COMMAND_ACK(a) if a.command == command),
        ) {
            Some(MavMessage::COMMAND_ACK(a)) => a.result,
            _ => panic!("no ack for {command:?}"),
        }
    }

    /// Sends one stick position at 25 Hz for `d`, collecting what arrives.
    fn drive(&mut self, x: i16, z: i16, r: i16, d: Duration) -> Vec<MavMessage> {
        let end = Instant::now() + d;
        let mut next = Instant::now();
        let mut seen = Vec::new();
        while Instant::now() < end {
            if Instant::now() >= next {
                next += Duration::from_millis(40);
                self.send(MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
                    x,
                    y: 0,
                    z,
                    r,
                    target: 1,
                    ..Default::default()
                }));
            }
            seen.extend(
                self.frames()
                    .into_iter()
                    .filter(|f| f.sysid == 1 && f.compid == 1)
                    .map(|f| f.msg),
            );
        }
        seen
    }
}

fn last_servo(msgs: &[MavMessage]) -> Option<SERVO_OUTPUT_RAW_DATA> {
    msgs.iter().rev().find_map(|m| {
        if let MavMessage::SERVO_OUTPUT_RAW(s) = m {
            Some(s.clone())
        } else {
            None
        }
    })
}

fn last_sim(msgs: &[MavMessage]) -> Option<NEPTUNUS_SIM_STATE_DATA> {
    msgs.iter().rev().find_map(|m| {
        if let MavMessage::NEPTUNUS_SIM_STATE(s) = m {
            Some(s.clone())
        } else {
            None
        }
    })
}

#[test]
fn forward_stick_moves_the_simulated_rov_forward_and_disarm_stops_it() {
    let mut sim = Sim::start();
    assert_eq!(
        sim.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let seen = sim.drive(1000, 500, 0, Duration::from_secs(4));
    let servo = last_servo(&seen).expect("SERVO_OUTPUT_RAW");
    // Full forward at the default gain 0.5: starboard (1) 1700, port (2) 1300 (wired reversed).
    assert_eq!(
        (servo.servo1_raw, servo.servo2_raw, servo.servo3_raw),
        (1700, 1300, 1500)
    );
    let s = last_sim(&seen).expect("NEPTUNUS_SIM_STATE");
    assert!(s.u > 0.4, "surge speed {}", s.u);
    assert!(s.x.hypot(s.y) > 0.5, "moved {} m", s.x.hypot(s.y));
    assert_eq!(
        sim.command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let seen = sim.drive(1000, 500, 0, Duration::from_millis(1200));
    let servo = last_servo(&seen).unwrap();
    assert_eq!(
        (servo.servo1_raw, servo.servo2_raw, servo.servo3_raw),
        (1500, 1500, 1500),
        "disarmed: neutral"
    );
}

#[test]
fn yaw_to_starboard_increases_heading() {
    let mut sim = Sim::start();
    sim.command(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    let start = sim.wait_for(Duration::from_secs(3), |m| {
        matches!(m, MavMessage::NEPTUNUS_SIM_STATE(_))
    });
    let Some(MavMessage::NEPTUNUS_SIM_STATE(start)) = start else {
        panic!("no sim state")
    };
    let seen = sim.drive(0, 500, 1000, Duration::from_secs(3));
    let end = last_sim(&seen).unwrap();
    assert!(end.r > 0.05, "yaw rate {}", end.r);
    let turned = (end.psi - start.psi).rem_euclid(std::f32::consts::TAU);
    assert!(
        turned > 0.1 && turned < std::f32::consts::PI,
        "heading change {turned} rad"
    );
}

#[test]
fn per_thruster_message_spins_only_that_thruster() {
    let mut sim = Sim::start();
    sim.command(
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(
        sim.command(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let end = Instant::now() + Duration::from_secs(2);
    let mut seen = Vec::new();
    while Instant::now() < end {
        sim.send(MavMessage::NEPTUNUS_THRUSTERS(NEPTUNUS_THRUSTERS_DATA {
            port: 0.0,
            vertical: 1.0,
            starboard: 0.0,
            target_system: 1,
            target_component: 1,
        }));
        seen.extend(
            sim.frames()
                .into_iter()
                .filter(|f| f.sysid == 1 && f.compid == 1)
                .map(|f| f.msg),
        );
    }
    let servo = last_servo(&seen).unwrap();
    assert_eq!(
        (servo.servo1_raw, servo.servo2_raw),
        (1500, 1500),
        "port and starboard idle"
    );
    assert_eq!(servo.servo3_raw, 1700, "vertical at full × gain 0.5");
    let s = last_sim(&seen).unwrap();
    assert!(s.w > 0.05, "going down: w = {}", s.w);
    assert!(s.u.abs() < 0.01, "no surge: u = {}", s.u);
}
