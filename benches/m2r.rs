//! What the mavlink2rest API (Cockpit's connection) costs and how fresh its
//! messages are.
//!
//! `neptunus --serial <pty>` runs as a child against a board emulator that
//! this bench drives itself (as `benches/hmi.rs` does: every navigation line
//! gets a distinct heading, 0.1° apart, so a heading seen in a WebSocket
//! frame names the line it came from).
//!
//! Each client speaks Cockpit's frames on `/mavlink2rest/ws/mavlink`: at
//! connect it sets the interval of 38 message types (ATTITUDE, AHRS2 and
//! VFR_HUD at 16 Hz, the rest at 1–5 Hz, as Cockpit's 36 plus
//! NAMED_VALUE_FLOAT and our NEPTUNUS_ESTIMATE at ATTITUDE's rate), then
//! sends a HEARTBEAT every second and a neutral MANUAL_CONTROL every 40 ms,
//! and reads everything.
//!
//! - **CPU**: the child's utime + stime from `/proc/<pid>/stat` over a fixed
//!   window with no client (the baseline, same run), 1 client and 10
//!   clients, as % of one core; per client = (loaded − baseline) / n.
//! - **Delay**: board line written → the first NEPTUNUS_ESTIMATE frame that
//!   carries its heading (`heading_measured`), received on the WebSocket
//!   (p50/p99 over all clients). A line's messages leave the core with the
//!   line, at most at the asked 16 Hz: a line that comes sooner waits for
//!   the interval, as Cockpit's ATTITUDE does.
//!
//! Figures are printed, never asserted. The binary is `$NEPTUNUS_BIN`, else
//! `target/release/neptunus`, else `target/debug/neptunus` (with a warning).
//! `cargo bench --bench m2r` measures 10 s windows; under `cargo test` (no
//! `--bench`) a 2 s smoke run shows the bench still works.

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
use futures_util::{SinkExt as _, StreamExt as _};
use neptunus::firmware::emulator::{Board, EmulatorOptions};
use neptunus::firmware::pty::PtyPair;
use serde_json::json;
use tokio::sync::watch;
use tokio_tungstenite::tungstenite::Message;

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

fn frame(message: serde_json::Value) -> Message {
    Message::text(
        json!({"header": {"system_id": 255, "component_id": 240, "sequence": 0}, "message": message})
            .to_string(),
    )
}

/// One Cockpit-like client; returns the frames it received.
async fn client(
    addr: std::net::SocketAddr,
    written: Written,
    delays: Arc<Mutex<Vec<Duration>>>,
    mut stop: watch::Receiver<bool>,
) -> anyhow::Result<u64> {
    let (ws, _) =
        tokio_tungstenite::connect_async(format!("ws://{addr}/mavlink2rest/ws/mavlink")).await?;
    let (mut tx, mut rx) = ws.split();
    for (id, hz) in common::COCKPIT_RATES {
        tx.send(frame(
            json!({"type": "COMMAND_LONG", "param1": id, "param2": 1e6 / hz,
            "param3": 0, "param4": 0, "param5": 0, "param6": 0, "param7": 0,
            "command": {"type": "MAV_CMD_SET_MESSAGE_INTERVAL"},
            "target_system": 1, "target_component": 1, "confirmation": 0}),
        ))
        .await?;
    }
    let heartbeat = json!({"type": "HEARTBEAT", "custom_mode": 0, "mavtype": {"type": "MAV_TYPE_GCS"},
        "autopilot": {"type": "MAV_AUTOPILOT_INVALID"}, "base_mode": {"bits": 192},
        "system_status": {"type": "MAV_STATE_ACTIVE"}, "mavlink_version": 2});
    let sticks = json!({"type": "MANUAL_CONTROL", "target": 1, "x": 0, "y": 0, "z": 500, "r": 0,
        "s": 0, "t": 0, "buttons": 0, "buttons2": 0, "enabled_extensions": 0});
    let mut beat = tokio::time::interval(Duration::from_secs(1));
    let mut stick = tokio::time::interval(Duration::from_millis(40));
    let mut frames = 0;
    let mut last = None;
    loop {
        let m = tokio::select! {
            _ = stop.changed() => break,
            _ = beat.tick() => {
                tx.send(frame(heartbeat.clone())).await?;
                continue;
            }
            _ = stick.tick() => {
                tx.send(frame(sticks.clone())).await?;
                continue;
            }
            m = rx.next() => m,
        };
        let Some(Ok(Message::Text(text))) = m else {
            if m.is_none() {
                break;
            }
            continue;
        };
        let at = Instant::now();
        frames += 1;
        if !text.as_str().contains("NEPTUNUS_ESTIMATE") {
            continue;
        }
        let v: serde_json::Value = serde_json::from_str(text.as_str())?;
        let Some(h) = v["message"]["heading_measured"].as_f64() else {
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
    Ok(frames)
}

fn cpu_percent(pid: u32, window: Duration, ticks_per_s: f64) -> anyhow::Result<f64> {
    let t0 = common::proc_cpu_ticks(pid)?;
    let start = Instant::now();
    std::thread::sleep(window);
    let t1 = common::proc_cpu_ticks(pid)?;
    let secs = start.elapsed().as_secs_f64();
    Ok((t1 - t0) as f64 / ticks_per_s / secs * 100.0)
}

/// CPU with `n` clients connected, their delays and frames per client per second.
fn measure(
    rt: &tokio::runtime::Runtime,
    vehicle: &mut common::Vehicle,
    addr: std::net::SocketAddr,
    written: &Written,
    n: usize,
    window: Duration,
    ticks: f64,
) -> anyhow::Result<(f64, Vec<Duration>, f64)> {
    let (stop_tx, stop_rx) = watch::channel(false);
    let delays: Arc<Mutex<Vec<Duration>>> = Arc::default();
    let clients: Vec<_> = (0..n)
        .map(|_| {
            rt.spawn(client(
                addr,
                Arc::clone(written),
                Arc::clone(&delays),
                stop_rx.clone(),
            ))
        })
        .collect();
    // Connected and at Cockpit's rates before measuring.
    std::thread::sleep(Duration::from_secs(2));
    if let Ok(mut d) = delays.lock() {
        d.clear();
    }
    let start = Instant::now();
    let cpu = cpu_percent(vehicle.pid(), window, ticks)?;
    let secs = start.elapsed().as_secs_f64() + 2.0;
    vehicle.check_running()?;
    let _ = stop_tx.send(true);
    let mut frames = 0;
    for c in clients {
        frames += rt.block_on(c)??;
    }
    let mut d = delays.lock().map(|d| d.clone()).unwrap_or_default();
    d.sort();
    Ok((cpu, d, frames as f64 / n as f64 / secs))
}

fn main() -> anyhow::Result<()> {
    let full = std::env::args().any(|a| a == "--bench");
    let window = Duration::from_secs(if full { 10 } else { 2 });
    let bin = common::neptunus_bin()?;
    println!("neptunus binary: {}", bin.display());
    println!(
        "mavlink2rest clients at Cockpit's rates ({} message types, ATTITUDE/AHRS2/VFR_HUD 16 Hz), board nav lines at {} Hz, CPU windows of {} s",
        common::COCKPIT_RATES.len(),
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
    std::thread::sleep(Duration::from_secs(2));
    vehicle.check_running()?;
    let ticks = common::clock_ticks_per_s();
    let idle = cpu_percent(vehicle.pid(), window, ticks)?;
    println!("neptunus CPU, no client (baseline): {idle:6.1} % of a core");
    for n in [1, 10] {
        let (cpu, d, fps) = measure(&rt, &mut vehicle, addr, &written, n, window, ticks)?;
        if d.is_empty() {
            bail!("no NEPTUNUS_ESTIMATE frame carried a board line's heading");
        }
        println!(
            "{n:2} client(s): neptunus CPU {cpu:6.1} % of a core, {:.2} % per client over the baseline; {fps:.0} frames/s per client",
            (cpu - idle) / n as f64
        );
        println!(
            "{n:2} client(s): board line -> WebSocket frame p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms ({} samples)",
            common::pct_ms(&d, 0.50),
            common::pct_ms(&d, 0.99),
            common::pct_ms(&d, 1.0),
            d.len()
        );
    }
    let _ = stop_tx.send(true);
    let _ = rt.block_on(board);
    drop(vehicle);
    Ok(())
}
