//! The MAVLink transport under attack, end to end: the built `neptunus`
//! binary, real sockets, and an attacker who records signed frames and
//! replays them after a restart, fills the peer tables with idle TCP
//! connections or chatty UDP ports, floods the telemetry log, or leaves no
//! writable place for the log file.
//!
//! Time is real (child processes), so every wait polls a condition against a
//! generous deadline; nothing here asserts how fast anything happens.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::io::{Read as _, Write as _};
use std::net::{TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use common::{
    GCS_SYSID, Gcs, NEUTRAL_US, Vehicle, board_runtime, executed_text, forward_records,
    free_udp_port, gcs_heartbeat, manual_control,
};
use neptunus::dialect::neptunus::*;
use neptunus::mavlink::signing::{Signer, SigningKey, timestamp_from_unix_us};
use neptunus::mavlink::{FrameDecoder, FrameStats, decode_datagram, encode_v2};
use nix::sys::signal::Signal;

const GENEROUS: Duration = Duration::from_secs(30);
const PASSPHRASE: &str = "replay test passphrase";
const STRANGER: u8 = 66;

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_micros() as u64
}

fn arm_command() -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: 1.0,
        command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        target_system: 1,
        target_component: 1,
        ..Default::default()
    })
}

fn prearm_ok(m: &MavMessage) -> bool {
    matches!(m, MavMessage::SYS_STATUS(s) if s.onboard_control_sensors_health.contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK))
}

fn arm_ack(m: &MavMessage) -> Option<MavResult> {
    match m {
        MavMessage::COMMAND_ACK(a) if a.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
            Some(a.result)
        }
        _ => None,
    }
}

fn heartbeat_armed(m: &MavMessage) -> Option<bool> {
    match m {
        MavMessage::HEARTBEAT(h) if h.mavtype == MavType::MAV_TYPE_SUBMARINE => {
            Some(common::armed(h))
        }
        _ => None,
    }
}

/// A free TCP port on loopback (for `tcpin:`).
fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

// ---------------------------------------------------------------------------
// a signing UDP ground station, and a TCP one
// ---------------------------------------------------------------------------

/// A UDP ground station (sysid 255) that signs every frame with the key of
/// [`PASSPHRASE`], timestamps from its clock, and can record what it sends.
struct SignedGcs {
    sock: UdpSocket,
    signer: Signer,
    seq: u8,
    recording: Option<Vec<Vec<u8>>>,
    next_heartbeat: Instant,
}

impl SignedGcs {
    fn connect(port: u16) -> Self {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.connect(("127.0.0.1", port)).unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(5)))
            .unwrap();
        Self {
            sock,
            signer: Signer::new(SigningKey::from_passphrase(PASSPHRASE), 0, None),
            seq: 0,
            recording: None,
            next_heartbeat: Instant::now(),
        }
    }

    fn send(&mut self, msg: &MavMessage) {
        let mut bytes = encode_v2(GCS_SYSID, 190, self.seq, msg);
        self.seq = self.seq.wrapping_add(1);
        self.signer
            .sign(&mut bytes, timestamp_from_unix_us(now_us()));
        let _ = self.sock.send(&bytes);
        if let Some(rec) = self.recording.as_mut() {
            rec.push(bytes);
        }
    }

    fn recv(&mut self) -> Vec<MavMessage> {
        if Instant::now() >= self.next_heartbeat {
            self.next_heartbeat = Instant::now() + Duration::from_secs(1);
            self.send(&gcs_heartbeat());
        }
        recv_udp(&self.sock)
    }

    /// Heartbeats and reads until `done`, or false after `within`.
    fn until(
        &mut self,
        vehicle: &mut Vehicle,
        within: Duration,
        mut done: impl FnMut(&mut Self, &[MavMessage]) -> bool,
    ) -> bool {
        let end = Instant::now() + within;
        while Instant::now() < end {
            vehicle.check_running().unwrap();
            let msgs = self.recv();
            if done(self, &msgs) {
                return true;
            }
        }
        false
    }
}

fn recv_udp(sock: &UdpSocket) -> Vec<MavMessage> {
    let mut buf = [0u8; 4096];
    let mut out = Vec::new();
    if let Ok(n) = sock.recv(&mut buf) {
        decode_datagram(&buf[..n], &mut FrameStats::default(), &mut out);
    }
    out.into_iter()
        .filter(|f| f.sysid == 1 && f.compid == 1)
        .map(|f| f.msg)
        .collect()
}

/// A TCP ground station (sysid 255, unsigned).
struct TcpGcs {
    stream: TcpStream,
    decoder: FrameDecoder,
    seq: u8,
    next_heartbeat: Instant,
}

impl TcpGcs {
    fn connect(port: u16, vehicle: &mut Vehicle) -> Self {
        let end = Instant::now() + GENEROUS;
        let stream = loop {
            vehicle.check_running().unwrap();
            match TcpStream::connect(("127.0.0.1", port)) {
                Ok(s) => break s,
                Err(e) if Instant::now() < end => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(50));
                }
                Err(e) => panic!("cannot connect to tcpin:{port}: {e}"),
            }
        };
        stream
            .set_read_timeout(Some(Duration::from_millis(5)))
            .unwrap();
        Self {
            stream,
            decoder: FrameDecoder::new(),
            seq: 0,
            next_heartbeat: Instant::now(),
        }
    }

    fn send(&mut self, msg: &MavMessage) {
        let bytes = encode_v2(GCS_SYSID, 190, self.seq, msg);
        self.seq = self.seq.wrapping_add(1);
        self.stream.write_all(&bytes).unwrap();
    }

    fn until(
        &mut self,
        vehicle: &mut Vehicle,
        within: Duration,
        mut done: impl FnMut(&[MavMessage]) -> bool,
    ) -> bool {
        let end = Instant::now() + within;
        let mut buf = [0u8; 4096];
        while Instant::now() < end {
            vehicle.check_running().unwrap();
            if Instant::now() >= self.next_heartbeat {
                self.next_heartbeat = Instant::now() + Duration::from_secs(1);
                self.send(&gcs_heartbeat());
            }
            let mut frames = Vec::new();
            match self.stream.read(&mut buf) {
                Ok(0) => panic!("the vehicle closed our connection"),
                Ok(n) => self.decoder.push(&buf[..n], &mut frames),
                Err(_) => {}
            }
            let msgs: Vec<MavMessage> = frames
                .into_iter()
                .filter(|f| f.sysid == 1 && f.compid == 1)
                .map(|f| f.msg)
                .collect();
            if done(&msgs) {
                return true;
            }
        }
        false
    }

    fn arm(&mut self, vehicle: &mut Vehicle) -> MavResult {
        assert!(
            self.until(vehicle, GENEROUS, |m| m.iter().any(prearm_ok)),
            "no PREARM_CHECK over TCP:\n{}",
            vehicle.stderr_tail()
        );
        self.send(&arm_command());
        let mut result = None;
        self.until(vehicle, Duration::from_secs(10), |m| {
            result = m.iter().find_map(arm_ack);
            result.is_some()
        });
        result.expect("no COMMAND_ACK for the arm command over TCP")
    }
}

// ---------------------------------------------------------------------------
// H1: replay across a restart
// ---------------------------------------------------------------------------

fn replay_after_restart(stop: Signal) {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let status = std::process::Command::new(bin())
        .args(["signing", "set-passphrase", PASSPHRASE, "--data-dir"])
        .arg(&data)
        .stdout(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());

    let rt = board_runtime().unwrap();
    let board = common::spawn_board(&rt, None).unwrap();
    let executed = forward_records(&rt, &board, executed_text);
    let serial = board.path().to_string_lossy().into_owned();
    let port = free_udp_port().unwrap();
    let endpoint = format!("udpin:127.0.0.1:{port}");
    let args = ["--serial", serial.as_str(), "--mavlink", endpoint.as_str()];
    let mut vehicle = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();

    // The real station arms and drives, signed; the attacker records it all.
    let mut station = SignedGcs::connect(port);
    assert!(
        station.until(&mut vehicle, GENEROUS, |_, m| m.iter().any(prearm_ok)),
        "not ready:\n{}",
        vehicle.stderr_tail()
    );
    station.recording = Some(Vec::new());
    station.send(&arm_command());
    let mut acked = None;
    station.until(&mut vehicle, Duration::from_secs(10), |_, m| {
        acked = m.iter().find_map(arm_ack);
        acked.is_some()
    });
    assert_eq!(
        acked,
        Some(MavResult::MAV_RESULT_ACCEPTED),
        "{}",
        vehicle.stderr_tail()
    );
    let control = board.control();
    let mut next_stick = Instant::now();
    let moved = station.until(&mut vehicle, GENEROUS, |s, _| {
        if Instant::now() >= next_stick {
            next_stick = Instant::now() + Duration::from_millis(40);
            s.send(&manual_control(1000));
        }
        control.snapshot().motors_us != NEUTRAL_US
    });
    assert!(
        moved,
        "the signed station could not drive:\n{}",
        vehicle.stderr_tail()
    );
    let recorded = station.recording.take().unwrap();

    // Stop: gracefully, or as a crash / power cut.
    vehicle.signal(stop).unwrap();
    let end = Instant::now() + GENEROUS;
    while vehicle.child.try_wait().unwrap().is_none() {
        assert!(Instant::now() < end, "neptunus did not exit on {stop}");
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(vehicle);
    // The board's dead-man brings the motors back to neutral on its own.
    let end = Instant::now() + GENEROUS;
    while control.snapshot().motors_us != NEUTRAL_US {
        assert!(Instant::now() < end, "the board never went neutral");
        std::thread::sleep(Duration::from_millis(20));
    }

    let mut vehicle = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();
    let mut attacker = Gcs::connect(port).unwrap();
    attacker.wait_ready(&mut vehicle).unwrap();
    while executed.try_recv().is_ok() {}
    // The replay: every recorded byte, in order, at the pace recorded (fast).
    for frame in &recorded {
        attacker.sock.send(frame).unwrap();
    }
    // Watch 3 vehicle heartbeats after the last replayed frame.
    let mut heartbeats = 0;
    let mut armed_seen = false;
    let mut acks = Vec::new();
    let watched = attacker
        .run_until(&mut vehicle, common::Traffic::Heartbeats, GENEROUS, |m| {
            for msg in m {
                if let Some(a) = heartbeat_armed(msg) {
                    heartbeats += 1;
                    armed_seen |= a;
                }
                acks.extend(arm_ack(msg));
            }
            heartbeats >= 3
        })
        .unwrap();
    assert!(watched);
    assert!(!armed_seen, "the replayed ARM armed the vehicle");
    assert!(
        !acks.contains(&MavResult::MAV_RESULT_ACCEPTED),
        "the replayed ARM was accepted: {acks:?}"
    );
    let moves: Vec<String> = executed
        .try_iter()
        .map(|(_, c)| c)
        .filter(|c| c.starts_with("go(") && c != common::NEUTRAL_GO)
        .collect();
    assert!(
        moves.is_empty(),
        "thrusters moved on replayed frames: {moves:?}"
    );
    assert_eq!(control.snapshot().motors_us, NEUTRAL_US);
    let log = vehicle.stderr_text();
    assert!(
        log.contains("signature rejected") && log.contains("replayed"),
        "the rejections are not logged:\n{log}"
    );

    // The real station, with fresh frames, gets control back (after a
    // crash, once its clock passes the persisted reservation: ≤ 5 s).
    let mut accepted = false;
    let mut next_arm = Instant::now();
    station.until(&mut vehicle, GENEROUS, |s, m| {
        accepted |= m
            .iter()
            .any(|m| arm_ack(m) == Some(MavResult::MAV_RESULT_ACCEPTED));
        if !accepted && Instant::now() >= next_arm {
            next_arm = Instant::now() + Duration::from_millis(500);
            s.send(&arm_command());
        }
        accepted
    });
    assert!(
        accepted,
        "the real station's fresh signed ARM was never accepted:\n{}",
        vehicle.stderr_tail()
    );
    drop(vehicle);
    drop(board);
}

#[test]
fn signed_frames_recorded_before_a_clean_restart_do_not_replay_after_it() {
    replay_after_restart(Signal::SIGTERM);
}

#[test]
fn signed_frames_recorded_before_a_crash_do_not_replay_after_it() {
    replay_after_restart(Signal::SIGKILL);
}

#[test]
fn a_corrupt_replay_file_is_said_loudly_and_does_not_stop_the_vehicle() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let status = std::process::Command::new(bin())
        .args(["signing", "set-passphrase", PASSPHRASE, "--data-dir"])
        .arg(&data)
        .stdout(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    std::fs::write(data.join("signing.replay"), "garbage\n").unwrap();
    let port = free_udp_port().unwrap();
    let endpoint = format!("udpin:127.0.0.1:{port}");
    let mut vehicle =
        Vehicle::spawn(bin(), &["--sim", "--mavlink", &endpoint], dir.path(), "").unwrap();
    // An unsigned station may still watch: the vehicle runs.
    Gcs::connect(port)
        .unwrap()
        .wait_ready(&mut vehicle)
        .unwrap();
    let log = vehicle.stderr_text();
    assert!(
        log.contains("signing.replay")
            && log.contains("REPLAY PROTECTION ACROSS THE RESTART IS LOST"),
        "{log}"
    );
}

// ---------------------------------------------------------------------------
// H3: full peer tables
// ---------------------------------------------------------------------------

#[test]
fn seventy_idle_tcp_connections_do_not_shut_out_an_allowed_station() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_tcp_port();
    let endpoint = format!("tcpin:127.0.0.1:{port}");
    let mut vehicle =
        Vehicle::spawn(bin(), &["--sim", "--mavlink", &endpoint], dir.path(), "").unwrap();
    let first = TcpGcs::connect(port, &mut vehicle).stream;
    let mut idle = vec![first];
    for _ in 0..69 {
        idle.push(TcpStream::connect(("127.0.0.1", port)).unwrap());
    }
    let mut station = TcpGcs::connect(port, &mut vehicle);
    assert!(
        station.until(&mut vehicle, GENEROUS, |m| m
            .iter()
            .any(|m| heartbeat_armed(m).is_some())),
        "no HEARTBEAT for the allowed station:\n{}",
        vehicle.stderr_tail()
    );
    assert_eq!(station.arm(&mut vehicle), MavResult::MAV_RESULT_ACCEPTED);
    assert!(
        vehicle.stderr_text().contains("evicting"),
        "the table never filled: the test proves nothing:\n{}",
        vehicle.stderr_tail()
    );
    drop(idle);
}

#[test]
fn idle_tcp_connections_are_closed_after_peer_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("neptunus.toml");
    // Heartbeats come at 1 Hz: 3 s leaves the talker a margin.
    std::fs::write(&config, "[mavlink]\npeer_timeout_s = 3.0\n").unwrap();
    let port = free_tcp_port();
    let endpoint = format!("tcpin:127.0.0.1:{port}");
    let config = config.to_string_lossy().into_owned();
    let mut vehicle = Vehicle::spawn(
        bin(),
        &["--sim", "--config", &config, "--mavlink", &endpoint],
        dir.path(),
        "",
    )
    .unwrap();
    let mut idle = TcpGcs::connect(port, &mut vehicle).stream;
    let mut talker = TcpGcs::connect(port, &mut vehicle);
    let end = Instant::now() + GENEROUS;
    let mut buf = [0u8; 4096];
    loop {
        assert!(Instant::now() < end, "the idle connection was never closed");
        // The talker keeps talking (heartbeats) and keeps its connection.
        talker.until(&mut vehicle, Duration::from_millis(50), |_| false);
        match idle.read(&mut buf) {
            Ok(0) => break,
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break,
            _ => {}
        }
    }
    assert!(talker.until(&mut vehicle, Duration::from_secs(5), |m| {
        m.iter().any(|m| heartbeat_armed(m).is_some())
    }));
}

#[test]
fn seventy_chatty_udp_ports_do_not_shut_out_an_allowed_station() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port().unwrap();
    let endpoint = format!("udpin:127.0.0.1:{port}");
    let mut vehicle =
        Vehicle::spawn(bin(), &["--sim", "--mavlink", &endpoint], dir.path(), "").unwrap();
    // 70 source ports, each a heartbeat every 2 s: none ever times out.
    let stop = Arc::new(AtomicBool::new(false));
    let chatter = {
        let stop = Arc::clone(&stop);
        let socks: Vec<UdpSocket> = (0..70)
            .map(|_| {
                let s = UdpSocket::bind("127.0.0.1:0").unwrap();
                s.connect(("127.0.0.1", port)).unwrap();
                s
            })
            .collect();
        std::thread::spawn(move || {
            let hb = encode_v2(STRANGER, 190, 0, &gcs_heartbeat());
            while !stop.load(Ordering::Relaxed) {
                for s in &socks {
                    let _ = s.send(&hb);
                }
                for _ in 0..40 {
                    if stop.load(Ordering::Relaxed) {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        })
    };
    // Wait until the strangers fill the table (the vehicle says so), then come in.
    let end = Instant::now() + GENEROUS;
    while !vehicle.stderr_text().contains("peer table full") {
        vehicle.check_running().unwrap();
        assert!(
            Instant::now() < end,
            "the table never filled:\n{}",
            vehicle.stderr_tail()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut gcs = Gcs::connect(port).unwrap();
    gcs.arm(&mut vehicle).unwrap();
    // It keeps getting telemetry while the strangers go on.
    let mut heartbeats = 0;
    let mut disarmed = 0;
    // (Sticks at neutral keep the pilot-input failsafe quiet.)
    let kept = gcs
        .run_until(&mut vehicle, common::Traffic::Drive(0), GENEROUS, |m| {
            heartbeats += m
                .iter()
                .filter(|m| heartbeat_armed(m) == Some(true))
                .count();
            disarmed += m
                .iter()
                .filter(|m| heartbeat_armed(m) == Some(false))
                .count();
            heartbeats >= 5
        })
        .unwrap();
    assert!(
        kept,
        "{heartbeats} armed and {disarmed} disarmed heartbeats:\n{}",
        vehicle.stderr_text()
    );
    stop.store(true, Ordering::Relaxed);
    chatter.join().unwrap();
}

// ---------------------------------------------------------------------------
// H6: disk bounds
// ---------------------------------------------------------------------------

fn tlog_records(path: &Path) -> Vec<Vec<u8>> {
    let data = std::fs::read(path).unwrap();
    let mut records = Vec::new();
    let mut at = 0;
    while at + 10 < data.len() {
        at += 8;
        let len = match data[at] {
            0xFE => 6 + usize::from(data[at + 1]) + 2,
            _ => {
                let signed = data[at + 2] & 1 != 0;
                10 + usize::from(data[at + 1]) + 2 + if signed { 13 } else { 0 }
            }
        };
        records.push(data[at..(at + len).min(data.len())].to_vec());
        at += len;
    }
    records
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|r| r.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn a_100k_frame_flood_from_a_stranger_neither_fills_the_disk_nor_hides_the_pilot() {
    let dir = tempfile::tempdir().unwrap();
    let tlogs = dir.path().join("data/tlogs");
    std::fs::create_dir_all(&tlogs).unwrap();
    // An old session beyond the cap: deleted at start, oldest first.
    let old = tlogs.join("neptunus-20200101-000000.tlog");
    std::fs::write(&old, vec![0u8; 900 * 1024]).unwrap();
    let config = dir.path().join("neptunus.toml");
    std::fs::write(&config, "[mavlink]\ntlog_total_mb = 1\n").unwrap();
    let config = config.to_string_lossy().into_owned();
    let udp = free_udp_port().unwrap();
    let tcp = free_tcp_port();
    let udp_ep = format!("udpin:127.0.0.1:{udp}");
    let tcp_ep = format!("tcpin:127.0.0.1:{tcp}");
    let started = Instant::now();
    let mut vehicle = Vehicle::spawn(
        bin(),
        &[
            "--sim",
            "--config",
            &config,
            "--mavlink",
            &udp_ep,
            "--mavlink",
            &tcp_ep,
        ],
        dir.path(),
        "",
    )
    .unwrap();
    let mut pilot = Gcs::connect(udp).unwrap();
    pilot.wait_ready(&mut vehicle).unwrap();
    assert!(!old.exists(), "the old tlog beyond the cap was kept");

    // The flood: 100 000 frames over TCP (every one reaches the vehicle).
    let mut stranger = TcpGcs::connect(tcp, &mut vehicle).stream;
    stranger.set_read_timeout(None).unwrap();
    let flood: Vec<u8> = (0..100_000u32)
        .flat_map(|i| encode_v2(STRANGER, 1, i as u8, &gcs_heartbeat()))
        .collect();
    let flooding = std::thread::spawn(move || {
        stranger.write_all(&flood).unwrap();
        stranger
    });
    // Meanwhile the pilot sends 100 heartbeats.
    let first_seq = pilot.seq;
    for _ in 0..100 {
        pilot.send(&gcs_heartbeat()).unwrap();
        pilot.recv();
    }
    let _stranger = flooding.join().unwrap();
    // A round trip after everything: the vehicle has handled all before it.
    pilot.param(&mut vehicle, "SYSID_MYGCS").unwrap();
    drop(vehicle); // SIGTERM: the tlog is flushed
    let elapsed = started.elapsed().as_secs_f64();

    let total: u64 = files_in(&tlogs)
        .iter()
        .map(|p| std::fs::metadata(p).unwrap().len())
        .sum();
    assert!(
        total <= 1024 * 1024,
        "tlogs/ holds {total} bytes, over the 1 MiB cap"
    );
    let records: Vec<Vec<u8>> = files_in(&tlogs)
        .iter()
        .flat_map(|p| tlog_records(p))
        .collect();
    // Every frame the pilot sent during the flood is in the log (by its
    // sequence numbers: fewer than 256 frames in all, so they are unique).
    let pilot_seqs: std::collections::HashSet<u8> = records
        .iter()
        .filter(|r| r.len() > 5 && r[5] == GCS_SYSID)
        .map(|r| r[4])
        .collect();
    let missing: Vec<u8> = (0..100u8)
        .map(|i| first_seq.wrapping_add(i))
        .filter(|s| !pilot_seqs.contains(s))
        .collect();
    assert!(
        missing.is_empty(),
        "pilot frames missing from the tlog: seq {missing:?}"
    );
    let stranger_logged = records
        .iter()
        .filter(|r| r.len() > 5 && r[5] == STRANGER)
        .count();
    let bound = 40.0 + 20.0 * elapsed;
    assert!(
        (stranger_logged as f64) <= bound,
        "{stranger_logged} flood frames logged in {elapsed:.1} s (rate limit bound {bound:.0})"
    );
}

#[test]
fn neptunus_log_rotates_and_stays_under_its_cap() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data).unwrap();
    const MIB: u64 = 1024 * 1024;
    // A full live file and four full old ones, left by earlier runs (sparse).
    let live = data.join("neptunus.log");
    std::fs::File::create(&live)
        .unwrap()
        .set_len(10 * MIB)
        .unwrap();
    for n in 1..=4 {
        std::fs::File::create(data.join(format!("neptunus.log.{n}")))
            .unwrap()
            .set_len(10 * MIB - n)
            .unwrap();
    }
    let port = free_udp_port().unwrap();
    let endpoint = format!("udpin:127.0.0.1:{port}");
    let mut vehicle =
        Vehicle::spawn(bin(), &["--sim", "--mavlink", &endpoint], dir.path(), "").unwrap();
    Gcs::connect(port)
        .unwrap()
        .wait_ready(&mut vehicle)
        .unwrap();
    drop(vehicle);
    let logs: Vec<(String, u64)> = files_in(&data)
        .iter()
        .filter_map(|p| {
            let name = p.file_name()?.to_string_lossy().into_owned();
            name.starts_with("neptunus.log")
                .then(|| (name, std::fs::metadata(p).unwrap().len()))
        })
        .collect();
    let names: Vec<&str> = logs.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "neptunus.log",
            "neptunus.log.1",
            "neptunus.log.2",
            "neptunus.log.3",
            "neptunus.log.4"
        ]
    );
    // The full live file became .1; the oldest (.4) was dropped.
    assert_eq!(logs[1].1, 10 * MIB);
    assert_eq!(logs[4].1, 10 * MIB - 3);
    assert!(logs[0].1 > 0 && logs[0].1 < MIB, "{logs:?}");
    assert!(logs.iter().map(|(_, l)| l).sum::<u64>() <= 50 * MIB);
}

#[test]
fn starts_without_a_writable_log_file_or_tlog_folder_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data).unwrap();
    // Directories and files where the logs should go: refused even to root.
    std::fs::create_dir(data.join("neptunus.log")).unwrap();
    std::fs::write(data.join("tlogs"), b"not a folder").unwrap();
    let port = free_udp_port().unwrap();
    let endpoint = format!("udpin:127.0.0.1:{port}");
    let mut vehicle =
        Vehicle::spawn(bin(), &["--sim", "--mavlink", &endpoint], dir.path(), "").unwrap();
    let mut gcs = Gcs::connect(port).unwrap();
    gcs.arm(&mut vehicle).unwrap();
    let log = vehicle.stderr_text();
    assert!(log.contains("CANNOT OPEN THE LOG FILE"), "{log}");
    assert!(log.contains("RUNNING WITHOUT A TELEMETRY LOG"), "{log}");
    // Ground stations see it too: logging unhealthy in SYS_STATUS.
    let logging = MavSysStatusSensor::MAV_SYS_STATUS_LOGGING;
    let shown = gcs
        .run_until(&mut vehicle, common::Traffic::Heartbeats, GENEROUS, |m| {
            m.iter().any(|m| {
                matches!(m, MavMessage::SYS_STATUS(s)
                    if s.onboard_control_sensors_present.contains(logging)
                        && !s.onboard_control_sensors_health.contains(logging))
            })
        })
        .unwrap();
    assert!(shown, "SYS_STATUS does not show the missing telemetry log");
}

// ---------------------------------------------------------------------------
// H5: out of file descriptors
// ---------------------------------------------------------------------------

#[test]
fn out_of_descriptors_the_connected_station_keeps_fresh_telemetry() {
    let Ok(prlimit) = which_prlimit() else {
        // util-linux's prlimit sets the child's limit without unsafe code here.
        eprintln!("SKIPPED: no prlimit on this machine");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let port = free_tcp_port();
    let endpoint = format!("tcpin:127.0.0.1:{port}");
    let bin = bin().to_string_lossy().into_owned();
    // About 20 descriptors at rest: 40 runs out well before the peer table.
    let mut vehicle = Vehicle::spawn(
        &prlimit,
        &[
            "--nofile=40:40",
            "--",
            &bin,
            "--sim",
            "--mavlink",
            &endpoint,
        ],
        dir.path(),
        "",
    )
    .unwrap();
    let mut station = TcpGcs::connect(port, &mut vehicle);
    assert!(station.until(&mut vehicle, GENEROUS, |m| m.iter().any(prearm_ok)));
    // The attacker takes every descriptor left, and keeps knocking.
    let mut held = Vec::new();
    for _ in 0..60 {
        match TcpStream::connect(("127.0.0.1", port)) {
            Ok(s) => held.push(s),
            Err(_) => break,
        }
    }
    let end = Instant::now() + GENEROUS;
    while !vehicle.stderr_text().contains("os error 24") {
        assert!(
            Instant::now() < end,
            "descriptors never ran out:\n{}",
            vehicle.stderr_tail()
        );
        station.until(&mut vehicle, Duration::from_millis(50), |_| false);
    }
    // A round trip still works: the station's telemetry queue is served
    // while accepting is impossible (it used to stall behind the accept loop).
    for _ in 0..3 {
        station.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system: 1,
            target_component: 1,
            param_id: "SYSID_MYGCS".into(),
        }));
        assert!(
            station.until(&mut vehicle, Duration::from_secs(5), |m| m
                .iter()
                .any(|m| matches!(m, MavMessage::PARAM_VALUE(_)))),
            "no answer while out of descriptors:\n{}",
            vehicle.stderr_tail()
        );
    }
    // The idle connections go; new clients get in again.
    drop(held);
    let mut late = TcpGcs::connect(port, &mut vehicle);
    assert!(
        late.until(&mut vehicle, GENEROUS, |m| m
            .iter()
            .any(|m| heartbeat_armed(m).is_some())),
        "a new client never got in after the descriptors came back:\n{}",
        vehicle.stderr_tail()
    );
}

fn which_prlimit() -> Result<PathBuf, ()> {
    ["/usr/bin/prlimit", "/bin/prlimit"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.is_file())
        .ok_or(())
}
