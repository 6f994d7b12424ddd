//! End-to-end latency, CPU and memory of the `neptunus` binary.
//!
//! Three measurements, printed as a table with the targets:
//!
//! 1. **Receive → `go()`**: `neptunus --serial <pty> --mavlink udpin:…` runs
//!    as a child process against a board emulator ([`PtyBoard`]) inside this
//!    bench, so the real serial path runs. The bench arms it and sends
//!    MANUAL_CONTROL datagrams over loopback UDP, each changing the thruster
//!    command, and timestamps every send; the latency of a datagram is the
//!    time until the emulator reads the `go()` frame carrying *its* values
//!    (matched by content, not by order).
//! 2. **Floor**: the same datagrams to a minimal forwarder thread in this
//!    bench (UDP receive → one fixed-size `go()` frame written to a second
//!    emulator's pty), measured the same way. What Neptunus adds is its
//!    figures minus the floor's.
//! 3. **CPU and RSS**: `neptunus --sim` driven at 25 Hz for `LATENCY_SOAK_S`
//!    seconds (default 60), read from `/proc/<pid>/stat` and `/status`.
//!
//! The binary under test is `$NEPTUNUS_BIN`, else `target/release/neptunus`,
//! else `target/debug/neptunus` (with a warning): build it first with
//! `cargo build --release`. Figures are printed, never asserted.
//!
//! Knobs (environment): `LATENCY_COUNT` datagrams per path (default
//! 10000), `LATENCY_PERIOD_US` between datagrams (default 5000),
//! `LATENCY_SOAK_S` (default 60).

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::io::Write as _;
use std::net::UdpSocket;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use common::stick::{
    Outcome, Sent, collect_frames, go_text, line_busy, paced_send, watch_go_frames,
};
use common::{Gcs, Vehicle, free_udp_port, gcs_heartbeat, manual_control, pct_ms};
use neptunus::firmware::codec::{self, Framing};

const TARGET_ADDED_P99_MS: f64 = 0.2;
const TARGET_CPU_PCT: f64 = 2.0;
const TARGET_RSS_MB: f64 = 20.0;
/// Stick positions cycled through; every one maps to a distinct `go()`, and
/// neighbours differ, so every datagram changes the thruster command.
const STICK_STEPS: usize = 64;

struct Config {
    count: usize,
    period: Duration,
    soak: Duration,
}

impl Config {
    fn from_env() -> anyhow::Result<Self> {
        fn var(name: &str, default: u64) -> anyhow::Result<u64> {
            match std::env::var(name) {
                Ok(v) => v
                    .trim()
                    .parse()
                    .with_context(|| format!("{name}={v:?} is not a whole number")),
                Err(_) => Ok(default),
            }
        }
        // `cargo bench` passes --bench; `cargo test --all-targets` runs this
        // binary without it: then a short smoke run shows the bench still
        // works without taking minutes of the test suite.
        let full = std::env::args().any(|a| a == "--bench");
        let (count, soak) = if full { (10_000, 60) } else { (300, 3) };
        Ok(Self {
            count: var("LATENCY_COUNT", count)? as usize,
            period: Duration::from_micros(var("LATENCY_PERIOD_US", 5_000)?.max(100)),
            soak: Duration::from_secs(var("LATENCY_SOAK_S", soak)?.max(1)),
        })
    }
}

fn main() -> anyhow::Result<()> {
    let cfg = Config::from_env()?;
    let bin = common::neptunus_bin()?;
    println!("neptunus binary: {}", bin.display());
    println!(
        "{} datagrams per path, one every {:.1} ms; soak {} s",
        cfg.count,
        cfg.period.as_secs_f64() * 1e3,
        cfg.soak.as_secs()
    );
    // The emulators run here; one worker keeps the bench off the second core
    // as much as it can (the machine may have only two).
    let rt = common::board_runtime()?;

    println!("\n[1/3] floor: UDP → forwarder thread → pty …");
    let floor = floor_run(&rt, &cfg)?;
    floor.print("floor");
    println!("\n[2/3] neptunus --serial <pty> …");
    let (nep, stream_cpu) = neptunus_run(&rt, &bin, &cfg)?;
    nep.print("neptunus");
    println!("\n[3/3] neptunus --sim, MANUAL_CONTROL at 25 Hz …");
    let soak = soak_run(&bin, &cfg)?;

    report(&cfg, &floor, &nep, stream_cpu, &soak);
    Ok(())
}

// ---------------------------------------------------------------------------
// The ground station side (the binary, the process and the station itself
// are in tests/common, shared with the other end-to-end tests and benches)
// ---------------------------------------------------------------------------

// ---------------------------------------------------------------------------
// 1. Floor
// ---------------------------------------------------------------------------

fn floor_run(rt: &tokio::runtime::Runtime, cfg: &Config) -> anyhow::Result<Outcome> {
    let dir = tempfile::tempdir()?;
    let link = dir.path().join("floor-board");
    let board = common::spawn_board(rt, Some(link.clone()))?;
    let frames_rx = watch_go_frames(rt, &board);

    // The forwarder: one datagram in, one go() frame out, nothing else. The
    // datagram's MAVLink sequence number (byte 4) picks the frame's values,
    // so the frame can be matched to the datagram by content.
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.set_read_timeout(Some(Duration::from_millis(100)))?;
    let port = sock.local_addr()?.port();
    let mut tty = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&link)
        .with_context(|| format!("cannot open the floor pty {}", link.display()))?;
    let stop = Arc::new(AtomicBool::new(false));
    let forwarded = Arc::new(AtomicU64::new(0));
    let forwarder = {
        let stop = stop.clone();
        let forwarded = forwarded.clone();
        thread::spawn(move || -> std::io::Result<()> {
            let mut buf = [0u8; 512];
            let mut frame = Vec::with_capacity(32);
            while !stop.load(Ordering::Relaxed) {
                let Ok(n) = sock.recv(&mut buf) else { continue };
                if n < 5 {
                    continue;
                }
                frame.clear();
                codec::encode(&floor_go(buf[4]), Framing::Crc8, &mut frame);
                tty.write_all(&frame)?;
                forwarded.fetch_add(1, Ordering::Relaxed);
            }
            Ok(())
        })
    };
    // The board's echoes to the forwarder pile up unread in the tty; the
    // emulator drops what does not fit, as a UART nobody reads would.

    let mut gcs = Gcs::connect(port)?;
    // Warm-up: the same pacing, not measured.
    paced_send(&mut gcs, &[0], 200, cfg.period, false)?;
    let _ = collect_frames(&frames_rx);
    let sent = paced_send(&mut gcs, &[0], cfg.count, cfg.period, false)?;
    let frames = collect_frames(&frames_rx);
    stop.store(true, Ordering::Relaxed);
    match forwarder.join() {
        Ok(r) => r.context("floor forwarder")?,
        Err(_) => bail!("floor forwarder panicked"),
    }
    drop(board);
    let key = |s: &Sent| {
        let mut f = Vec::new();
        codec::encode(&floor_go(s.seq), Framing::Crc8, &mut f);
        go_text(&f).unwrap_or_default()
    };
    Ok(Outcome::match_up(&sent, key, &frames))
}

fn floor_go(seq: u8) -> codec::Command {
    codec::Command::Go {
        port_us: 1500,
        vertical_us: 1500,
        starboard_us: 1000 + u16::from(seq),
    }
}

// ---------------------------------------------------------------------------
// 2. Neptunus on a pty
// ---------------------------------------------------------------------------

fn neptunus_run(
    rt: &tokio::runtime::Runtime,
    bin: &Path,
    cfg: &Config,
) -> anyhow::Result<(Outcome, Option<f64>)> {
    let dir = tempfile::tempdir()?;
    let link = dir.path().join("board");
    let board = common::spawn_board(rt, Some(link.clone()))?;
    let frames_rx = watch_go_frames(rt, &board);
    let port = free_udp_port()?;
    let link_arg = link.to_string_lossy().into_owned();
    let endpoint = format!("udpin:127.0.0.1:{port}");
    let mut vehicle = Vehicle::spawn(
        bin,
        &["--serial", &link_arg, "--mavlink", &endpoint],
        dir.path(),
        "",
    )?;
    let mut gcs = Gcs::connect(port)?;
    gcs.arm(&mut vehicle)?;
    let stop = Arc::new(AtomicBool::new(false));
    let drain = gcs.drain(stop.clone())?;

    // Learn which go() each stick position produces (full forward at gain
    // 0.5 is go(1300,1500,1700)); forward only, away from any deadzone.
    let sticks: Vec<i16> = (0..STICK_STEPS).map(|k| 1000 - 10 * k as i16).collect();
    let _ = collect_frames(&frames_rx);
    let mut learned: Vec<String> = Vec::with_capacity(sticks.len());
    for &x in &sticks {
        gcs.send(&manual_control(x))?;
        let (_, text) = frames_rx
            .recv_timeout(Duration::from_secs(2))
            .with_context(|| format!("no go() on the serial line after MANUAL_CONTROL x={x}"))?;
        if learned.contains(&text) {
            bail!("MANUAL_CONTROL x={x} gave {text}, as another stick position did");
        }
        learned.push(text);
        thread::sleep(Duration::from_millis(20));
    }
    println!(
        "  stick → go(): x={} → {}, …, x={} → {}",
        sticks[0],
        learned[0],
        sticks[STICK_STEPS - 1],
        learned[STICK_STEPS - 1]
    );
    // Warm-up at the measured pacing, not measured.
    paced_send(&mut gcs, &sticks, 200, cfg.period, true)?;
    let _ = collect_frames(&frames_rx);

    let cpu_before = common::proc_cpu_ticks(vehicle.pid())?;
    let t0 = Instant::now();
    let sent = paced_send(&mut gcs, &sticks, cfg.count, cfg.period, true)?;
    let cpu = common::proc_cpu_ticks(vehicle.pid())?.saturating_sub(cpu_before) as f64
        / common::clock_ticks_per_s()
        / t0.elapsed().as_secs_f64()
        * 100.0;
    let frames = collect_frames(&frames_rx);
    stop.store(true, Ordering::Relaxed);
    let _ = drain.join();
    if let Ok(Some(status)) = vehicle.child.try_wait() {
        bail!(
            "neptunus exited ({status}) during the run:\n{}",
            vehicle.stderr_tail()
        );
    }
    drop(vehicle);
    drop(board);
    let key = |s: &Sent| learned[s.stick].clone();
    Ok((Outcome::match_up(&sent, key, &frames), Some(cpu)))
}

// ---------------------------------------------------------------------------
// 3. CPU and memory
// ---------------------------------------------------------------------------

struct Soak {
    cpu_pct: f64,
    rss_mb: f64,
    hwm_mb: f64,
    telemetry_per_s: f64,
    window: Duration,
}

fn soak_run(bin: &Path, cfg: &Config) -> anyhow::Result<Soak> {
    let dir = tempfile::tempdir()?;
    let port = free_udp_port()?;
    let endpoint = format!("udpin:127.0.0.1:{port}");
    let mut vehicle = Vehicle::spawn(bin, &["--sim", "--mavlink", &endpoint], dir.path(), "")?;
    let mut gcs = Gcs::connect(port)?;
    gcs.arm(&mut vehicle)?;
    let stop = Arc::new(AtomicBool::new(false));
    let drain = gcs.drain(stop.clone())?;

    // A pilot sweeping the stick slowly: the thruster command changes often,
    // as it does when driving.
    let stick = |t: f64| (600.0 * (std::f64::consts::TAU * t / 10.0).sin()) as i16;
    let period = Duration::from_millis(40);
    let start = Instant::now();
    let mut i: u32 = 0;
    let mut next_hb = start;
    let mut drive_until = |until: Instant, gcs: &mut Gcs| -> anyhow::Result<()> {
        loop {
            let due = start + period * i;
            if due >= until {
                return Ok(());
            }
            let now = Instant::now();
            if due > now {
                thread::sleep(due - now);
            }
            if Instant::now() >= next_hb {
                next_hb += Duration::from_secs(1);
                gcs.send(&gcs_heartbeat())?;
            }
            gcs.send(&manual_control(stick((due - start).as_secs_f64())))?;
            i += 1;
        }
    };
    // Settle (start-up allocations, first telemetry), then the window.
    drive_until(start + Duration::from_secs(2), &mut gcs)?;
    let ticks_before = common::proc_cpu_ticks(vehicle.pid())?;
    let t0 = Instant::now();
    drive_until(t0 + cfg.soak, &mut gcs)?;
    let ticks = common::proc_cpu_ticks(vehicle.pid())?.saturating_sub(ticks_before);
    let window = t0.elapsed();
    let (rss_kb, hwm_kb) = proc_memory_kb(vehicle.pid())?;
    stop.store(true, Ordering::Relaxed);
    let datagrams = drain.join().unwrap_or(0);
    if let Ok(Some(status)) = vehicle.child.try_wait() {
        bail!(
            "neptunus --sim exited ({status}) during the soak:\n{}",
            vehicle.stderr_tail()
        );
    }
    let soak = Soak {
        cpu_pct: ticks as f64 / common::clock_ticks_per_s() / window.as_secs_f64() * 100.0,
        rss_mb: rss_kb as f64 / 1024.0,
        hwm_mb: hwm_kb as f64 / 1024.0,
        telemetry_per_s: datagrams as f64 / start.elapsed().as_secs_f64(),
        window,
    };
    println!(
        "  {:.0} s window: CPU {:.2} % of one core, VmRSS {:.1} MB, VmHWM {:.1} MB, {:.0} telemetry datagrams/s",
        soak.window.as_secs_f64(),
        soak.cpu_pct,
        soak.rss_mb,
        soak.hwm_mb,
        soak.telemetry_per_s
    );
    Ok(soak)
}

/// VmRSS and VmHWM in kB.
fn proc_memory_kb(pid: u32) -> anyhow::Result<(u64, u64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let field = |name: &str| -> anyhow::Result<u64> {
        let line = status
            .lines()
            .find(|l| l.starts_with(name))
            .with_context(|| format!("no {name} in /proc/{pid}/status"))?;
        Ok(line
            .split_whitespace()
            .nth(1)
            .context("empty field")?
            .parse()?)
    };
    Ok((field("VmRSS:")?, field("VmHWM:")?))
}

// ---------------------------------------------------------------------------
// The table
// ---------------------------------------------------------------------------

fn report(cfg: &Config, floor: &Outcome, nep: &Outcome, stream_cpu: Option<f64>, soak: &Soak) {
    let yes = |ok: bool| if ok { "yes" } else { "NO" };
    println!();
    println!(
        "Receive → go() on the board's pty, {} MANUAL_CONTROL datagrams each, one every {:.1} ms",
        cfg.count,
        cfg.period.as_secs_f64() * 1e3
    );
    println!(
        "  {:<28} {:>9} {:>9} {:>9} {:>8} {:>9} {:>5}",
        "path", "p50 ms", "p99 ms", "max ms", "matched", "coalesced", "lost"
    );
    for (name, o) in [
        ("floor (UDP→pty forwarder)", floor),
        ("neptunus --serial", nep),
    ] {
        println!(
            "  {:<28} {:>9.3} {:>9.3} {:>9.3} {:>8} {:>9} {:>5}",
            name,
            o.pct_ms(0.5),
            o.pct_ms(0.99),
            o.pct_ms(1.0),
            o.latencies.len(),
            o.coalesced,
            o.lost
        );
    }
    for (name, o) in [
        ("  floor, line free", floor),
        ("  neptunus, line free", nep),
    ] {
        println!(
            "  {:<28} {:>9.3} {:>9.3} {:>9.3} {:>8}",
            name,
            pct_ms(&o.line_free, 0.5),
            pct_ms(&o.line_free, 0.99),
            pct_ms(&o.line_free, 1.0),
            o.line_free.len(),
        );
    }
    let added_p50 = nep.pct_ms(0.5) - floor.pct_ms(0.5);
    let added_p99 = nep.pct_ms(0.99) - floor.pct_ms(0.99);
    println!(
        "  {:<28} {:>9.3} {:>9.3}   (neptunus p50 {:.1}× the floor's)",
        "added by neptunus",
        added_p50,
        added_p99,
        nep.pct_ms(0.5) / floor.pct_ms(0.5)
    );
    println!(
        "  line free: sent >= {:.2} ms after the previous datagram (a go() frame's wire time at 115200 baud + the link's frame gap), so nothing waited for the serial line",
        line_busy().as_secs_f64() * 1e3
    );
    println!(
        "  added over the floor, line free: p50 {:.3} ms, p99 {:.3} ms",
        pct_ms(&nep.line_free, 0.5) - pct_ms(&floor.line_free, 0.5),
        pct_ms(&nep.line_free, 0.99) - pct_ms(&floor.line_free, 0.99)
    );
    if let Some(cpu) = stream_cpu {
        println!(
            "  neptunus CPU while streaming at {:.0} Hz: {cpu:.1} % of one core",
            1.0 / cfg.period.as_secs_f64()
        );
    }
    println!();
    println!(
        "  {:<44} {:>14} {:>10} {:>4}",
        "target", "measured", "limit", "met"
    );
    println!(
        "  {:<44} {:>11.3} ms {:>7.1} ms {:>4}",
        "p99 latency added over the floor",
        added_p99,
        TARGET_ADDED_P99_MS,
        yes(added_p99 <= TARGET_ADDED_P99_MS)
    );
    println!(
        "  {:<44} {:>12.2} % {:>8.0} % {:>4}",
        format!(
            "CPU, --sim, 25 Hz MANUAL_CONTROL, {:.0} s",
            soak.window.as_secs_f64()
        ),
        soak.cpu_pct,
        TARGET_CPU_PCT,
        yes(soak.cpu_pct <= TARGET_CPU_PCT)
    );
    println!(
        "  {:<44} {:>11.1} MB {:>7.0} MB {:>4}",
        "RSS at the end of the soak (VmRSS)",
        soak.rss_mb,
        TARGET_RSS_MB,
        yes(soak.rss_mb <= TARGET_RSS_MB)
    );
    println!(
        "  {:<44} {:>11.1} MB {:>7.0} MB {:>4}",
        "peak RSS (VmHWM)",
        soak.hwm_mb,
        TARGET_RSS_MB,
        yes(soak.hwm_mb <= TARGET_RSS_MB)
    );
}
