//! An hour's dive: does anything grow, leak or drop?
//!
//! `neptunus --serial <pty>` runs as a child against the genuine 30.0.2
//! firmware in simavr, armed, with a ground station driving it at 25 Hz
//! (MANUAL_CONTROL with the sticks moving slowly through forward, turn
//! and heave, HEARTBEAT at 1 Hz) and the browser page open in headless
//! Chromium (Debian's `/usr/bin/chromium`, or `$CHROMIUM`: the real page,
//! its WebSocket and telemetry at its own pace). Every minute it prints
//! the vehicle process's resident memory, open descriptors and threads,
//! the board link's drops so far (STATUSTEXT "Board link down"), whether
//! it is still armed, and the simulator's pace. The vehicle logs at info,
//! as the packaged service does. At the end: the vehicle's warnings
//! (STATUSTEXT; a disarm says why), the growth of
//! each after the first five minutes (flat is the target), and the tlog
//! read whole by pymavlink (`target/interop-venv`, or `$SOAK_PYTHON`)
//! after a clean stop: every frame decoded, none bad.
//!
//! `SOAK_MINUTES` sets the length (default 60 under `cargo bench`, 2
//! otherwise). The binary is `$NEPTUNUS_BIN`, else
//! `target/release/neptunus`. Figures are printed, never asserted.

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use common::{Gcs, Traffic, Vehicle};
use neptunus::dialect::neptunus::*;
use neptunus::hil::{GenuineBoard, Wiring, prepare};
use nix::sys::signal::Signal;

/// Run by `cargo bench` (the full length and checks), not as a smoke run.
fn full_run() -> bool {
    std::env::args().any(|a| a == "--bench")
}

fn minutes() -> anyhow::Result<u64> {
    let full = full_run();
    match std::env::var("SOAK_MINUTES") {
        Ok(v) => v
            .trim()
            .parse()
            .with_context(|| format!("SOAK_MINUTES={v:?} is not a whole number")),
        Err(_) => Ok(if full { 60 } else { 2 }),
    }
}

/// (resident set MB, descriptors, threads) of `pid`.
fn footprint(pid: u32) -> anyhow::Result<(f64, usize, usize)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let field = |key: &str| -> Option<u64> {
        status
            .lines()
            .find(|l| l.starts_with(key))?
            .split_whitespace()
            .nth(1)?
            .parse()
            .ok()
    };
    let rss_kb = field("VmRSS:").context("no VmRSS")?;
    let threads = field("Threads:").context("no Threads")? as usize;
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd"))?.count();
    Ok((rss_kb as f64 / 1024.0, fds, threads))
}

/// Headless Chromium on the page at `addr`.
fn browser(addr: std::net::SocketAddr, profile: &Path) -> anyhow::Result<Child> {
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    Command::new(&chromium)
        .args([
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--mute-audio",
            "--no-first-run",
            &format!("--user-data-dir={}", profile.display()),
            &format!("http://{addr}/"),
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("cannot start {chromium}"))
}

fn python() -> PathBuf {
    std::env::var_os("SOAK_PYTHON").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("target/interop-venv/bin/python"),
        PathBuf::from,
    )
}

/// pymavlink reads every tlog through: (frames, bad frames, bytes).
const READ_TLOG: &str = r#"
import sys
from pymavlink import mavutil
frames = bad = size = 0
for path in sys.argv[1:]:
    m = mavutil.mavlink_connection(path, robust_parsing=True)
    while True:
        msg = m.recv_match()
        if msg is None:
            break
        if msg.get_type() == 'BAD_DATA':
            bad += 1
        else:
            frames += 1
    size += m.f.tell()
print(frames, bad, size)
"#;

fn main() -> anyhow::Result<()> {
    let minutes = minutes()?;
    let bin = common::neptunus_bin()?;
    println!("neptunus binary: {}", bin.display());
    let cache = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/openrov-firmware");
    let firmware = prepare(&common::firmware_dir("30.0.2"), &cache)?;
    let board = GenuineBoard::spawn(firmware, Wiring::default(), None)?;
    let control = board.control();
    let dir = tempfile::tempdir()?;
    let (mut gcs, port) = Gcs::bind()?;
    let device = board.path().to_string_lossy().into_owned();
    let endpoint = format!("udpout:127.0.0.1:{port}");
    // Logging at info, as the packaged service does: the 5-s link line and
    // every event go to stderr and neptunus.log for the whole hour.
    let mut vehicle = Vehicle::spawn_env(
        &bin,
        &["--serial", &device, "--mavlink", &endpoint],
        dir.path(),
        "",
        &[("RUST_LOG", "info")],
    )?;
    gcs.await_vehicle(&mut vehicle, Duration::from_secs(30))?;
    let addr = vehicle.http_addr(Duration::from_secs(10))?;
    let mut page = browser(addr, &dir.path().join("chromium"))?;
    gcs.wait_ready(&mut vehicle)?;
    gcs.arm(&mut vehicle)?;
    println!(
        "{minutes} min: the genuine 30.0.2 firmware, a station driving at 25 Hz, the page open in headless Chromium"
    );
    println!();
    println!(
        "| minute | resident MB | descriptors | threads | link drops | armed | simavr × real time, slips | page |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let pid = vehicle.pid();
    let start = Instant::now();
    let (mut drops, mut armed, mut was_down) = (0usize, true, false);
    let mut lines = Vec::new();
    // What the vehicle warned of, with its minute: a disarm says why here.
    let mut warnings: Vec<(u64, String)> = Vec::new();
    for minute in 1..=minutes {
        let end = start + Duration::from_secs(60 * minute);
        while Instant::now() < end {
            // The sticks wander slowly: forward, a turn, a little heave.
            let t = start.elapsed().as_secs_f64();
            let x = (500.0 * (t / 7.0).sin()) as i16;
            let r = (300.0 * (t / 11.0).sin()) as i16;
            let z = 500 + (150.0 * (t / 13.0).sin()) as i16;
            gcs.pump(Traffic::Sticks { x, z, r })?;
            for m in gcs.recv() {
                match m {
                    MavMessage::HEARTBEAT(h) => armed = common::armed(&h),
                    MavMessage::STATUSTEXT(s) => {
                        let text = common::statustext(&s);
                        if s.severity as u8 <= MavSeverity::MAV_SEVERITY_WARNING as u8 {
                            // A long text comes in chunks of one id.
                            match warnings.last_mut() {
                                Some((_, t)) if s.id != 0 && s.chunk_seq > 0 => t.push_str(&text),
                                _ => warnings.push((minute, text.clone())),
                            }
                        }
                        let down = text.contains("link down");
                        if down && !was_down {
                            drops += 1;
                        }
                        was_down = down || (was_down && !text.contains("link up"));
                    }
                    _ => {}
                }
            }
            vehicle.check_running()?;
        }
        let (rss, fds, threads) = footprint(pid)?;
        let snap = control.snapshot();
        let page_alive = page.try_wait()?.is_none();
        println!(
            "| {minute} | {rss:.1} | {fds} | {threads} | {drops} | {} | {:.2}×, {} | {} |",
            if armed { "yes" } else { "NO" },
            snap.realtime_ratio,
            snap.slips,
            if page_alive { "open" } else { "GONE" },
        );
        lines.push((minute, rss, fds, threads));
    }
    let _ = page.kill();
    let _ = page.wait();
    // A clean stop closes the tlog.
    vehicle.signal(Signal::SIGTERM)?;
    let stop_end = Instant::now() + Duration::from_secs(10);
    while vehicle.child.try_wait()?.is_none() {
        if Instant::now() > stop_end {
            bail!("neptunus did not stop within 10 s of SIGTERM");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(board);
    let settled: Vec<_> = lines.iter().filter(|l| l.0 > 5).collect();
    if let (Some(first), Some(last)) = (settled.first(), settled.last()) {
        let span = |f: fn(&&(u64, f64, usize, usize)) -> f64| {
            let v: Vec<f64> = settled.iter().map(f).collect();
            (
                v.iter().copied().fold(f64::INFINITY, f64::min),
                v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            )
        };
        let (rss_lo, rss_hi) = span(|l| l.1);
        let (fd_lo, fd_hi) = span(|l| l.2 as f64);
        let (th_lo, th_hi) = span(|l| l.3 as f64);
        println!();
        println!(
            "after minute 5 (minutes {}..{}): resident {rss_lo:.1}–{rss_hi:.1} MB ({:+.1} MB first to last), descriptors {fd_lo}–{fd_hi}, threads {th_lo}–{th_hi}",
            first.0,
            last.0,
            last.1 - first.1
        );
    } else {
        println!("\n(shorter than six minutes: no growth after minute 5 to report)");
    }
    println!("board link drops: {drops}");
    if warnings.is_empty() {
        println!("the vehicle's warnings (STATUSTEXT, warning or worse): none");
    } else {
        println!("the vehicle's warnings (STATUSTEXT, warning or worse):");
        for (minute, text) in &warnings {
            println!("- minute {minute}: {text}");
        }
    }
    let mut tlogs: Vec<PathBuf> = std::fs::read_dir(vehicle.data_dir().join("tlogs"))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "tlog"))
        .collect();
    tlogs.sort();
    if !python().exists() && !full_run() {
        // The smoke run under `cargo test` comes before the test command
        // has made the clients' venv on a fresh machine.
        println!(
            "tlog: not read back (skipped: no {}; the test command makes it after the cargo tests)",
            python().display()
        );
        return Ok(());
    }
    let out = Command::new(python())
        .arg("-c")
        .arg(READ_TLOG)
        .args(&tlogs)
        .output()
        .with_context(|| format!("cannot run {}", python().display()))?;
    if !out.status.success() {
        bail!(
            "pymavlink could not read the tlog: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let said = String::from_utf8_lossy(&out.stdout);
    let mut it = said
        .split_whitespace()
        .map(|w| w.parse::<u64>().unwrap_or(0));
    let (frames, bad, bytes) = (
        it.next().unwrap_or(0),
        it.next().unwrap_or(0),
        it.next().unwrap_or(0),
    );
    println!(
        "tlog: {} file(s), {:.1} MB, read whole by pymavlink: {frames} frames, {bad} bad",
        tlogs.len(),
        bytes as f64 / 1e6
    );
    Ok(())
}
