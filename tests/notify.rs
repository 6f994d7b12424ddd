//! systemd's notify protocol, as systemd sees it: the vehicle is started with
//! `NOTIFY_SOCKET` pointing at a datagram socket of the test and
//! `WATCHDOG_USEC` set, against the board emulator on a real pty.
//!
//! It must say READY=1, keep saying WATCHDOG=1 at least twice per watchdog
//! period while its loop runs, say nothing while it is stopped (SIGSTOP: a
//! hung vehicle must let systemd's watchdog fire), and on SIGTERM say
//! STOPPING=1 only after the board has been given a neutral `go()`.
//! With the vehicle task alone hung (the debug build's
//! `NEPTUNUS_TEST_STALL_AFTER_S` hook) while the rest of the process runs,
//! the watchdog starves and the board's dead-man switch stops the thrusters.

mod common;

use std::os::unix::net::UnixDatagram;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use common::{
    Gcs, NEUTRAL_US, Traffic, Vehicle, board_runtime, executed_text, forward_records, spawn_board,
};
use nix::sys::signal::Signal;

const WATCHDOG: Duration = Duration::from_millis(1000);

/// Datagrams on the test's notify socket, each with when it arrived.
struct Systemd {
    sock: UnixDatagram,
}

impl Systemd {
    fn bind(path: &Path) -> anyhow::Result<Self> {
        let sock = UnixDatagram::bind(path)?;
        sock.set_read_timeout(Some(Duration::from_millis(20)))?;
        Ok(Self { sock })
    }

    /// Every message until `until`, with its arrival time.
    fn collect(&self, until: Instant) -> Vec<(Instant, String)> {
        let mut got = Vec::new();
        let mut buf = [0u8; 4096];
        while Instant::now() < until {
            if let Ok(n) = self.sock.recv(&mut buf) {
                got.push((
                    Instant::now(),
                    String::from_utf8_lossy(&buf[..n]).into_owned(),
                ));
            }
        }
        got
    }

    /// The messages waiting now, without blocking.
    fn drain(&self) -> Vec<String> {
        let mut got = Vec::new();
        let mut buf = [0u8; 4096];
        let _ = self.sock.set_nonblocking(true);
        while let Ok(n) = self.sock.recv(&mut buf) {
            got.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
        let _ = self.sock.set_nonblocking(false);
        got
    }

    /// Waits for a message with the line `line`; returns when it came.
    fn wait_for(
        &self,
        line: &str,
        within: Duration,
        vehicle: &mut Vehicle,
    ) -> anyhow::Result<Instant> {
        let end = Instant::now() + within;
        let mut buf = [0u8; 4096];
        loop {
            vehicle.check_running().or_else(|e| {
                // Exiting right after the message is fine; the message is still queued.
                if line == "STOPPING=1" { Ok(()) } else { Err(e) }
            })?;
            if let Ok(n) = self.sock.recv(&mut buf) {
                let text = String::from_utf8_lossy(&buf[..n]);
                if text.lines().any(|l| l == line) {
                    return Ok(Instant::now());
                }
            }
            if Instant::now() > end {
                bail!("no {line} within {within:?}:\n{}", vehicle.stderr_tail());
            }
        }
    }
}

fn watchdogs(msgs: &[(Instant, String)]) -> Vec<Instant> {
    msgs.iter()
        .filter(|(_, m)| m.lines().any(|l| l == "WATCHDOG=1"))
        .map(|(t, _)| *t)
        .collect()
}

#[test]
fn ready_watchdog_and_stopping_after_neutral() -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let sock_path = dir.path().join("notify.sock");
    let systemd = Systemd::bind(&sock_path)?;
    let rt = board_runtime()?;
    let board = spawn_board(&rt, None)?;
    let executed = forward_records(&rt, &board, executed_text);
    let (mut gcs, port) = Gcs::bind()?;
    let serial = board.path().to_string_lossy().into_owned();
    let endpoint = format!("udpout:127.0.0.1:{port}");
    let usec = WATCHDOG.as_micros().to_string();
    let mut vehicle = Vehicle::spawn_env(
        Path::new(env!("CARGO_BIN_EXE_neptunus")),
        &["--serial", &serial, "--mavlink", &endpoint],
        dir.path(),
        "",
        &[
            ("NOTIFY_SOCKET", sock_path.to_str().context("socket path")?),
            ("WATCHDOG_USEC", &usec),
        ],
    )?;

    // READY=1 once the vehicle task runs (it then talks to the station).
    systemd.wait_for("READY=1", Duration::from_secs(30), &mut vehicle)?;
    gcs.await_vehicle(&mut vehicle, Duration::from_secs(30))?;

    // WATCHDOG=1 at least twice per WatchdogSec, over four periods.
    let window = 4 * WATCHDOG;
    let start = Instant::now();
    let pings = watchdogs(&systemd.collect(start + window));
    assert!(
        pings.len() >= 8,
        "{} WATCHDOG=1 in {window:?} (WatchdogSec {WATCHDOG:?}): want at least 2 per period",
        pings.len()
    );
    let gaps = pings.windows(2).map(|w| w[1] - w[0]);
    let worst = gaps.max().unwrap_or(window);
    assert!(
        worst < WATCHDOG,
        "a gap of {worst:?} between WATCHDOG=1: systemd would have restarted the vehicle"
    );

    // Stopped (as a hung vehicle task would be): nothing for two periods.
    vehicle.signal(Signal::SIGSTOP)?;
    let stopped_at = Instant::now();
    let while_stopped = systemd.collect(stopped_at + 2 * WATCHDOG);
    vehicle.signal(Signal::SIGCONT)?;
    assert!(
        while_stopped.is_empty(),
        "the stopped vehicle still notified systemd: {while_stopped:?}"
    );
    // And it feeds the watchdog again once it runs.
    systemd.wait_for("WATCHDOG=1", 2 * WATCHDOG, &mut vehicle)?;

    // Driving (motors off neutral), then SIGTERM: neutral first, then
    // STOPPING=1. The board link went stale while stopped and comes back
    // by itself: arming is refused until it has.
    let end = Instant::now() + Duration::from_secs(20);
    loop {
        gcs.wait_ready(&mut vehicle)?;
        match gcs.arm(&mut vehicle) {
            Ok(()) => break,
            Err(e) if Instant::now() > end => return Err(e),
            Err(_) => {}
        }
    }
    let control = board.control();
    let moving = gcs.run_until(
        &mut vehicle,
        Traffic::Drive(600),
        Duration::from_secs(10),
        |_| control.snapshot().motors_us != NEUTRAL_US,
    )?;
    assert!(
        moving,
        "the motors never left neutral: {:?}\n{}",
        control.snapshot(),
        vehicle.stderr_tail()
    );
    while executed.try_recv().is_ok() {}
    let term_at = Instant::now();
    vehicle.signal(Signal::SIGTERM)?;
    let stopping_at = systemd.wait_for("STOPPING=1", Duration::from_secs(10), &mut vehicle)?;
    let neutral_at = executed
        .try_iter()
        .find(|(_, text)| text == common::NEUTRAL_GO)
        .map(|(t, _)| t);
    match neutral_at {
        Some(t) => assert!(
            t >= term_at && t <= stopping_at,
            "the neutral go() was executed {:?} after SIGTERM, STOPPING=1 came {:?} after",
            t.saturating_duration_since(term_at),
            stopping_at - term_at
        ),
        None => bail!(
            "STOPPING=1 came before the board executed {} (motors {:?})",
            common::NEUTRAL_GO,
            control.snapshot().motors_us
        ),
    }
    Ok(())
}

#[test]
fn a_hung_vehicle_task_starves_the_watchdog_and_the_board_stops_the_thrusters() -> anyhow::Result<()>
{
    let dir = tempfile::tempdir()?;
    let sock_path = dir.path().join("notify.sock");
    let systemd = Systemd::bind(&sock_path)?;
    let rt = board_runtime()?;
    let board = spawn_board(&rt, None)?;
    let (mut gcs, port) = Gcs::bind()?;
    let serial = board.path().to_string_lossy().into_owned();
    let endpoint = format!("udpout:127.0.0.1:{port}");
    let usec = WATCHDOG.as_micros().to_string();
    let mut vehicle = Vehicle::spawn_env(
        Path::new(env!("CARGO_BIN_EXE_neptunus")),
        &["--serial", &serial, "--mavlink", &endpoint],
        dir.path(),
        "",
        &[
            ("NOTIFY_SOCKET", sock_path.to_str().context("socket path")?),
            ("WATCHDOG_USEC", &usec),
            ("NEPTUNUS_TEST_STALL_AFTER_S", "8"),
        ],
    )?;
    systemd.wait_for("READY=1", Duration::from_secs(30), &mut vehicle)?;
    gcs.await_vehicle(&mut vehicle, Duration::from_secs(30))?;
    gcs.wait_ready(&mut vehicle)?;
    gcs.arm(&mut vehicle)?;
    // Drive on, as a pilot would, until the watchdog has been silent for a
    // whole period: the vehicle task hangs (8 s after start).
    let control = board.control();
    let mut last_watchdog = Instant::now();
    let mut moved = false;
    let starved = gcs.run_until(
        &mut vehicle,
        Traffic::Drive(600),
        Duration::from_secs(30),
        |_| {
            moved |= control.snapshot().motors_us != NEUTRAL_US;
            if systemd
                .drain()
                .iter()
                .any(|m| m.lines().any(|l| l == "WATCHDOG=1"))
            {
                last_watchdog = Instant::now();
            }
            last_watchdog.elapsed() > 2 * WATCHDOG
        },
    )?;
    assert!(moved, "the thrusters never moved before the stall");
    assert!(
        starved,
        "WATCHDOG=1 never stopped: the hook did not hang the vehicle task"
    );
    // The process is alive (sockets, the link still run): only systemd's
    // watchdog can tell, and the board's dead-man has acted on its own.
    vehicle.check_running()?;
    let stopped = gcs.run_until(
        &mut vehicle,
        Traffic::Drive(600),
        Duration::from_secs(5),
        |_| {
            let s = control.snapshot();
            s.dead_man_tripped && s.motors_us == NEUTRAL_US
        },
    )?;
    assert!(
        stopped,
        "the board's dead-man did not stop the thrusters: {:?}",
        control.snapshot()
    );
    let late: Vec<String> = systemd.drain();
    assert!(
        late.iter().all(|m| !m.lines().any(|l| l == "WATCHDOG=1")),
        "WATCHDOG=1 from a hung vehicle task: {late:?}"
    );
    Ok(())
}
