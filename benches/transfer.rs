//! File transfers beside the control loop, on the `neptunus` binary.
//!
//! `neptunus --serial <pty> --mavlink udpin:…` runs against a board
//! emulator in this bench (the real serial path), with a closed telemetry
//! log of `TRANSFER_MB` in its data directory. A station (sysid 255) arms
//! it and drives: MANUAL_CONTROL every `TRANSFER_PERIOD_US`, each changing
//! the thruster command, and the latency from each datagram to the `go()`
//! carrying its values on the board's pty is timed as `benches/latency.rs`
//! times it. Meanwhile another station (sysid 245, NEPT_GCS_ALLOW1), a
//! pymavlink client in its own process over loopback UDP
//! (`tests/interop/transfer_clients.py`), fetches the log:
//!
//! 1. **baseline**: no transfer (measured first, in the same run);
//! 2. **log download** as QGroundControl asks (LOG_REQUEST_DATA in chunks
//!    of 512 × 90 bytes, the next when one is complete);
//! 3. **FTP burst read** with pymavlink's MAVFTP client (`cmd_get`), packets
//!    of 239 bytes (`burst_read_size 239`), then of 80 (its default).
//!
//! Each download is compared with the file, byte for byte. Printed: MB/s
//! and the latency's p50/p99 before and during each transfer, the p99's
//! rise over the baseline, and the vehicle's CPU, against the targets
//! (≥ 1 MB/s, a rise of at most 0.5 ms). Figures are printed, never
//! asserted.
//!
//! The binary is `$NEPTUNUS_BIN`, else `target/release/neptunus`, else
//! `target/debug/neptunus`; the client runs on `$NEPTUNUS_PYTHON`, else
//! `target/interop-venv/bin/python` (tests/run_all.sh makes it). Without
//! either Python, `cargo bench` fails and the short run `cargo test` makes
//! says it skipped. Knobs: `TRANSFER_MB` (default 16; 1 in the short run),
//! `TRANSFER_PERIOD_US` (default 5000).

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use common::stick::{
    Outcome, Sent, collect_frames, learn_sticks, paced_send, paced_send_while, watch_go_frames,
};
use common::{Gcs, Vehicle, free_udp_port};

const TARGET_MB_S: f64 = 1.0;
const TARGET_P99_RISE_MS: f64 = 0.5;
/// The log's name in the tlogs folder (an earlier run's: closed).
const LOG_NAME: &str = "neptunus-20260101-000000.tlog";
/// The downloading station: NEPT_GCS_ALLOW1's default, so it may read logs.
const DOWNLOADER_SYSID: &str = "245";
const STICK_STEPS: usize = 64;

struct Config {
    bytes: usize,
    period: Duration,
    /// Datagrams of the baseline.
    baseline: usize,
}

fn config() -> anyhow::Result<(Config, bool)> {
    fn var(name: &str, default: u64) -> anyhow::Result<u64> {
        match std::env::var(name) {
            Ok(v) => v
                .trim()
                .parse()
                .with_context(|| format!("{name}={v:?} is not a whole number")),
            Err(_) => Ok(default),
        }
    }
    // `cargo bench` passes --bench; `cargo test --all-targets` runs a short one.
    let full = std::env::args().any(|a| a == "--bench");
    let mb = var("TRANSFER_MB", if full { 16 } else { 1 })?.max(1);
    Ok((
        Config {
            bytes: (mb * 1024 * 1024) as usize,
            period: Duration::from_micros(var("TRANSFER_PERIOD_US", 5_000)?.max(200)),
            baseline: if full { 2_000 } else { 200 },
        },
        full,
    ))
}

/// The Python with pymavlink the client runs on.
fn python() -> Option<PathBuf> {
    let p = std::env::var_os("NEPTUNUS_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("target/interop-venv/bin/python")
        });
    let ok = Command::new(&p)
        .args(["-c", "import pymavlink.mavftp"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    ok.then_some(p)
}

/// What one phase measured.
struct Phase {
    name: String,
    outcome: Outcome,
    /// Bytes and seconds the client reported.
    transfer: Option<(u64, f64)>,
    cpu_pct: f64,
}

fn main() -> anyhow::Result<()> {
    let (cfg, full) = config()?;
    let Some(python) = python() else {
        if full {
            bail!(
                "no Python with pymavlink: run tests/run_all.sh once (it makes target/interop-venv) or set NEPTUNUS_PYTHON"
            );
        }
        println!(
            "transfer bench skipped: no Python with pymavlink (target/interop-venv or NEPTUNUS_PYTHON)"
        );
        return Ok(());
    };
    let bin = common::neptunus_bin()?;
    println!("neptunus binary: {}", bin.display());
    println!(
        "a {:.1} MB closed tlog; MANUAL_CONTROL every {:.1} ms; client: {}",
        cfg.bytes as f64 / 1e6,
        cfg.period.as_secs_f64() * 1e3,
        python.display()
    );
    let rt = common::board_runtime()?;
    let dir = tempfile::tempdir()?;
    let tlogs = dir.path().join("data").join("tlogs");
    std::fs::create_dir_all(&tlogs)?;
    let log: Vec<u8> = (0..cfg.bytes)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(tlogs.join(LOG_NAME), &log)?;

    let link = dir.path().join("board");
    let board = common::spawn_board(&rt, Some(link.clone()))?;
    let frames_rx = watch_go_frames(&rt, &board);
    let port = free_udp_port()?;
    let link_arg = link.to_string_lossy().into_owned();
    let endpoint = format!("udpin:127.0.0.1:{port}");
    let mut vehicle = Vehicle::spawn(
        &bin,
        &["--serial", &link_arg, "--mavlink", &endpoint],
        dir.path(),
        "",
    )?;
    let mut gcs = Gcs::connect(port)?;
    gcs.arm(&mut vehicle)?;
    let stop = Arc::new(AtomicBool::new(false));
    let drain = gcs.drain(stop.clone())?;
    let (sticks, learned) = learn_sticks(&mut gcs, &frames_rx, STICK_STEPS)?;
    let key = |s: &Sent| learned[s.stick].clone();
    // Warm-up at the measured pacing, not measured.
    paced_send(&mut gcs, &sticks, 200, cfg.period, true)?;
    let _ = collect_frames(&frames_rx);

    let mut phases = Vec::new();
    println!("\n[1/4] baseline: driving, no transfer …");
    let cpu0 = common::proc_cpu_ticks(vehicle.pid())?;
    let t0 = Instant::now();
    let sent = paced_send(&mut gcs, &sticks, cfg.baseline, cfg.period, true)?;
    let cpu = cpu_pct(&vehicle, cpu0, t0)?;
    let outcome = Outcome::match_up(&sent, key, &collect_frames(&frames_rx));
    outcome.print("baseline");
    phases.push(Phase {
        name: "baseline (no transfer)".into(),
        outcome,
        transfer: None,
        cpu_pct: cpu,
    });

    let clients: [(&str, Vec<String>); 3] = [
        ("log download (QGroundControl's way)", vec!["log".into()]),
        (
            "FTP burst read, 239-byte packets",
            vec![
                "ftp".into(),
                format!("/logs/tlogs/{LOG_NAME}"),
                "239".into(),
            ],
        ),
        (
            "FTP burst read, 80-byte packets",
            vec!["ftp".into(), format!("/logs/tlogs/{LOG_NAME}"), "80".into()],
        ),
    ];
    for (i, (name, args)) in clients.iter().enumerate() {
        println!("\n[{}/4] {name} …", i + 2);
        let out = dir.path().join(format!("download-{i}"));
        let mut child = client(&python, port, args, &out)?;
        let cpu0 = common::proc_cpu_ticks(vehicle.pid())?;
        let t0 = Instant::now();
        let sent = paced_send_while(&mut gcs, &sticks, usize::MAX, cfg.period, true, || {
            matches!(child.try_wait(), Ok(None))
        })?;
        let cpu = cpu_pct(&vehicle, cpu0, t0)?;
        let result = child.wait_with_output()?;
        if !result.status.success() {
            bail!(
                "the client failed ({}): {}\n{}",
                result.status,
                String::from_utf8_lossy(&result.stderr),
                vehicle.stderr_tail()
            );
        }
        let report: serde_json::Value = serde_json::from_slice(
            result
                .stdout
                .split(|&b| b == b'\n')
                .rfind(|l| l.starts_with(b"{"))
                .unwrap_or_default(),
        )
        .context("the client printed no result")?;
        let got = std::fs::read(&out)?;
        if got != log {
            bail!(
                "{name}: the download differs from the file ({} of {} bytes)",
                got.len(),
                log.len()
            );
        }
        let bytes = report["bytes"].as_u64().unwrap_or(0);
        let seconds = report["seconds"].as_f64().unwrap_or(f64::NAN);
        let outcome = Outcome::match_up(&sent, key, &collect_frames(&frames_rx));
        outcome.print(name);
        println!(
            "  {:.2} MB/s ({bytes} bytes in {seconds:.2} s, {} retries), bytes identical",
            bytes as f64 / seconds / 1e6,
            report["retries"]
        );
        phases.push(Phase {
            name: (*name).into(),
            outcome,
            transfer: Some((bytes, seconds)),
            cpu_pct: cpu,
        });
    }
    stop.store(true, Ordering::Relaxed);
    let _ = drain.join();
    vehicle.check_running()?;
    drop(vehicle);
    drop(board);
    report(&cfg, &phases);
    Ok(())
}

/// Starts the client: `transfer_clients.py KIND PORT SYSID [PATH] OUT [BURST]`.
fn client(python: &Path, port: u16, args: &[String], out: &Path) -> anyhow::Result<Child> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/interop/transfer_clients.py");
    let mut cmd = Command::new(python);
    cmd.arg(script)
        .arg(&args[0])
        .arg(port.to_string())
        .arg(DOWNLOADER_SYSID);
    if args[0] == "ftp" {
        cmd.arg(&args[1]).arg(out).arg(&args[2]);
    } else {
        cmd.arg(out);
    }
    cmd.stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("cannot start the pymavlink client")
}

/// The vehicle's CPU since `ticks0` at `t0`, in % of one core.
fn cpu_pct(vehicle: &Vehicle, ticks0: u64, t0: Instant) -> anyhow::Result<f64> {
    let ticks = common::proc_cpu_ticks(vehicle.pid())?.saturating_sub(ticks0);
    Ok(ticks as f64 / common::clock_ticks_per_s() / t0.elapsed().as_secs_f64() * 100.0)
}

fn report(cfg: &Config, phases: &[Phase]) {
    let yes = |ok: bool| if ok { "yes" } else { "NO" };
    let base = &phases[0].outcome;
    println!();
    println!(
        "File transfers to pymavlink over loopback UDP ({:.1} MB log), stick → go() with MANUAL_CONTROL every {:.1} ms",
        cfg.bytes as f64 / 1e6,
        cfg.period.as_secs_f64() * 1e3
    );
    println!(
        "  {:<38} {:>7} {:>8} {:>8} {:>9} {:>8} {:>6} {:>5}",
        "phase", "MB/s", "p50 ms", "p99 ms", "p99 rise", "matched", "lost", "CPU%"
    );
    for p in phases {
        let rate = p.transfer.map_or("-".to_owned(), |(b, s)| {
            format!("{:.2}", b as f64 / s / 1e6)
        });
        println!(
            "  {:<38} {:>7} {:>8.3} {:>8.3} {:>9.3} {:>8} {:>6} {:>5.1}",
            p.name,
            rate,
            p.outcome.pct_ms(0.5),
            p.outcome.pct_ms(0.99),
            p.outcome.pct_ms(0.99) - base.pct_ms(0.99),
            p.outcome.latencies.len(),
            p.outcome.lost,
            p.cpu_pct
        );
    }
    println!();
    println!(
        "  {:<52} {:>10} {:>9} {:>4}",
        "target", "measured", "limit", "met"
    );
    for p in &phases[1..] {
        if let Some((b, s)) = p.transfer {
            let rate = b as f64 / s / 1e6;
            println!(
                "  {:<52} {:>5.2} MB/s {:>4.1} MB/s {:>4}",
                format!("{}: rate", p.name),
                rate,
                TARGET_MB_S,
                yes(rate >= TARGET_MB_S)
            );
        }
        let rise = p.outcome.pct_ms(0.99) - base.pct_ms(0.99);
        println!(
            "  {:<52} {:>7.3} ms {:>6.1} ms {:>4}",
            format!("{}: p99 rise", p.name),
            rise,
            TARGET_P99_RISE_MS,
            yes(rise <= TARGET_P99_RISE_MS)
        );
    }
}
