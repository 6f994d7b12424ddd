//! What the browser HMI costs and how fresh its telemetry is.
//!
//! `neptunus --serial <pty>` runs as a child against a board emulator that
//! this bench drives itself (the sans-IO [`Board`] behind a [`PtyPair`], so
//! it knows the moment each telemetry line is written to the pty). Every
//! navigation line gets a distinct heading (0.1° apart, a slow 2°/s turn at
//! 20 Hz), so a heading seen in a WebSocket `telemetry` message names the
//! line it came from.
//!
//! - **CPU**: the child's utime + stime from `/proc/<pid>/stat` over a fixed
//!   window, with no browser session and then with 20 protocol clients
//!   (tokio-tungstenite) connected, as % of one core. The difference is what
//!   the HMI adds per session (telemetry pushed as the vehicle sends it).
//! - **Delay**: board line written → WebSocket message received, for the
//!   first message that carries each line's heading (p50/p99 over all 20
//!   clients). A line's NEPTUNUS_ESTIMATE leaves the core with the line (the
//!   HMI asks for it at 10 Hz, so every other one of these 20 Hz lines) and
//!   each session pushes at once.
//!
//! Figures are printed, never asserted. The binary is `$NEPTUNUS_BIN`, else
//! `target/release/neptunus`, else `target/debug/neptunus` (with a warning).
//! `cargo bench --bench hmi` measures 10 s windows; under `cargo test` (no
//! `--bench`) a 2 s smoke run shows the bench still works.
//!
//! [`Board`]: neptunus::firmware::emulator::Board
//! [`PtyPair`]: neptunus::firmware::pty::PtyPair

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::bail;
use futures_util::StreamExt as _;
use neptunus::firmware::emulator::{Board, EmulatorOptions};
use neptunus::firmware::pty::PtyPair;
use tokio::sync::watch;
use tokio_tungstenite::tungstenite::Message;

const CLIENTS: usize = 20;
const NAV_PERIOD_MS: u64 = 50;

/// Heading (in 0.01°) → when the line carrying it was written.
type Written = Arc<Mutex<HashMap<i64, Instant>>>;

fn key(heading_deg: f64) -> i64 {
    (heading_deg * 100.0).round() as i64 % 36000
}

/// The board on our own pty: writes what the emulator prints, with each
/// nav line's heading replaced by the next distinct one, and notes when.
async fn run_board(pty: PtyPair, written: Written, mut stop: watch::Receiver<bool>) {
    let opts = EmulatorOptions {
        nav_period_ms: NAV_PERIOD_MS,
        ..EmulatorOptions::default()
    };
    let mut board = Board::new(opts);
    let origin = tokio::time::Instant::now();
    let now = || tokio::time::Instant::now() - origin;
    let mut out = Vec::with_capacity(4096);
    board.start(now(), &mut out);
    let mut buf = [0u8; 512];
    let mut line_no: u64 = 0;
    loop {
        if !out.is_empty() {
            let text = String::from_utf8_lossy(&out).into_owned();
            let mut rewritten = String::with_capacity(text.len());
            let mut keys = Vec::new();
            let mut rest = text.as_str();
            while let Some(i) = rest.find("hdgd:") {
                rewritten.push_str(&rest[..i + 5]);
                let after = &rest[i + 5..];
                let end = after.find(';').unwrap_or(after.len());
                line_no += 1;
                let h = (line_no as f64 * 0.1) % 360.0;
                let _ = write!(rewritten, "{h:.2}");
                keys.push(key(h));
                rest = &after[end..];
            }
            rewritten.push_str(rest);
            let _ = pty.try_write(rewritten.as_bytes());
            let at = Instant::now();
            if !keys.is_empty()
                && let Ok(mut w) = written.lock()
            {
                for k in keys {
                    w.insert(k, at);
                }
            }
            out.clear();
        }
        let deadline = origin + board.next_deadline();
        tokio::select! {
            _ = stop.changed() => break,
            read = pty.read(&mut buf) => match read {
                Ok(n) => board.receive(&buf[..n], now(), &mut out),
                Err(_) => break,
            },
            _ = tokio::time::sleep_until(deadline) => {}
        }
        board.tick(now(), &mut out);
        let _ = board.take_records();
    }
}

/// One protocol client: reads telemetry and records each new heading's delay.
async fn client(
    addr: std::net::SocketAddr,
    written: Written,
    delays: Arc<Mutex<Vec<Duration>>>,
    mut stop: watch::Receiver<bool>,
) -> anyhow::Result<u64> {
    let (mut ws, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws")).await?;
    let mut messages = 0;
    let mut last = None;
    loop {
        let m = tokio::select! {
            _ = stop.changed() => break,
            m = ws.next() => m,
        };
        let Some(Ok(Message::Text(text))) = m else {
            if m.is_none() {
                break;
            }
            continue;
        };
        let at = Instant::now();
        messages += 1;
        let v: serde_json::Value = serde_json::from_str(text.as_str())?;
        if v["type"] != "telemetry" {
            continue;
        }
        // The raw board reading beside the estimate (the heading shown is
        // the Kalman estimate, which no longer equals any line's value).
        let Some(h) = v["estimate"]["heading_measured_deg"].as_f64() else {
            continue;
        };
        let k = key(h);
        if last == Some(k) {
            continue;
        }
        last = Some(k);
        let sent = written.lock().ok().and_then(|w| w.get(&k).copied());
        if let Some(sent) = sent
            && let Ok(mut d) = delays.lock()
        {
            d.push(at.saturating_duration_since(sent));
        }
    }
    Ok(messages)
}

fn cpu_percent(pid: u32, window: Duration, ticks_per_s: f64) -> anyhow::Result<f64> {
    let t0 = common::proc_cpu_ticks(pid)?;
    let start = Instant::now();
    std::thread::sleep(window);
    let t1 = common::proc_cpu_ticks(pid)?;
    let secs = start.elapsed().as_secs_f64();
    Ok((t1 - t0) as f64 / ticks_per_s / secs * 100.0)
}

fn main() -> anyhow::Result<()> {
    let full = std::env::args().any(|a| a == "--bench");
    let window = Duration::from_secs(if full { 10 } else { 2 });
    let bin = common::neptunus_bin()?;
    println!("neptunus binary: {}", bin.display());
    println!(
        "{CLIENTS} WebSocket clients, telemetry pushed as it comes, board nav lines at {} Hz, CPU windows of {} s",
        1000 / NAV_PERIOD_MS,
        window.as_secs()
    );
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let written: Written = Arc::default();
    let (stop_tx, stop_rx) = watch::channel(false);
    let pty = {
        let _g = rt.enter();
        PtyPair::open()?
    };
    let serial = pty.slave_path().to_string_lossy().into_owned();
    let board = rt.spawn(run_board(pty, Arc::clone(&written), stop_rx.clone()));
    let dir = tempfile::tempdir()?;
    let mut vehicle = common::Vehicle::spawn(
        &bin,
        &["--serial", &serial, "--mavlink", "udpin:127.0.0.1:0"],
        dir.path(),
        "",
    )?;
    let addr = vehicle.http_addr(Duration::from_secs(30))?;
    // Let the link come up and settle before measuring.
    std::thread::sleep(Duration::from_secs(2));
    vehicle.check_running()?;
    let ticks = common::clock_ticks_per_s();
    let idle = cpu_percent(vehicle.pid(), window, ticks)?;

    let delays: Arc<Mutex<Vec<Duration>>> = Arc::default();
    let clients: Vec<_> = (0..CLIENTS)
        .map(|_| {
            rt.spawn(client(
                addr,
                Arc::clone(&written),
                Arc::clone(&delays),
                stop_rx.clone(),
            ))
        })
        .collect();
    std::thread::sleep(Duration::from_secs(1));
    if let Ok(mut d) = delays.lock() {
        d.clear(); // connection warm-up is not steady state
    }
    let loaded = cpu_percent(vehicle.pid(), window, ticks)?;
    vehicle.check_running()?;
    let _ = stop_tx.send(true);
    let mut messages = 0;
    for c in clients {
        messages += rt.block_on(c)??;
    }
    let _ = rt.block_on(board);
    drop(vehicle);

    let mut d = delays.lock().map(|d| d.clone()).unwrap_or_default();
    d.sort();
    if d.is_empty() {
        bail!("no telemetry message carried a board line's heading");
    }
    println!("neptunus CPU, no session:        {idle:6.1} % of a core");
    println!("neptunus CPU, {CLIENTS} sessions:     {loaded:6.1} % of a core");
    println!(
        "CPU the HMI adds ({CLIENTS} sessions):  {:6.1} % of a core ({:.2} % per session)",
        loaded - idle,
        (loaded - idle) / CLIENTS as f64
    );
    println!(
        "board line -> WebSocket telemetry: p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms ({} samples, {} messages received)",
        common::pct_ms(&d, 0.50),
        common::pct_ms(&d, 0.99),
        common::pct_ms(&d, 1.0),
        d.len(),
        messages
    );
    Ok(())
}
