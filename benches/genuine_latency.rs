//! Stick to thruster through the genuine OpenROV firmware: the delay a
//! pilot actually feels.
//!
//! `neptunus --serial <pty>` runs as a child against the genuine 30.0.2
//! firmware in simavr ([`GenuineBoard`], built with the `hil` feature), and
//! a ground station alternates the forward stick between neutral and
//! forward (MANUAL_CONTROL at 25 Hz, a step every 0.6 s). For each step:
//!
//! - **stick → go()**: from sending the first MANUAL_CONTROL of the step to
//!   the first byte of the `go()` frame that carries it reaching the board's
//!   UART (the runner's record of the serial line);
//! - **go() → ESC**: from there to the falling edge of the first port ESC
//!   pulse at the new width, measured on the firmware's pin and mapped from
//!   simulated cycles to the wall clock (the firmware writes its servos
//!   every 50 ms and a servo frame lasts 20 ms: most of this is the board's);
//! - **stick → ESC**: the sum, what the pilot feels.
//!
//! The baseline, measured in the same run: the same steps against the
//! project's board emulator ([`PtyBoard`]), stick to the emulator executing
//! the `go()` — the vehicle's own path without the board. Figures are
//! printed, never asserted.
//!
//! The binary is `$NEPTUNUS_BIN`, else `target/release/neptunus`, else the
//! debug build with a warning; the firmware is `$OPENROV_FIRMWARE_DIR/30.0.2`
//! (default `../shared/openrov-firmware`). `GENUINE_STEPS` steps (default
//! 100; a smoke run of 4 when not run by `cargo bench`).
//!
//! [`GenuineBoard`]: neptunus::hil::GenuineBoard
//! [`PtyBoard`]: neptunus::firmware::emulator::PtyBoard

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use common::{Gcs, Rig, Traffic, Vehicle, pct_ms};
use neptunus::hil::{GenuineBoard, Output, Wiring, prepare};

const FORWARD: i16 = 800;
const STEP: Duration = Duration::from_millis(600);

fn steps() -> anyhow::Result<usize> {
    let full = std::env::args().any(|a| a == "--bench");
    match std::env::var("GENUINE_STEPS") {
        Ok(v) => v
            .trim()
            .parse::<usize>()
            .map(|n| n.max(2))
            .with_context(|| format!("GENUINE_STEPS={v:?} is not a whole number")),
        Err(_) => Ok(if full { 100 } else { 4 }),
    }
}

fn firmware_dir() -> PathBuf {
    std::env::var_os("OPENROV_FIRMWARE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/openrov-firmware"))
        .join("30.0.2")
}

fn line(name: &str, mut v: Vec<Duration>) {
    v.sort();
    println!(
        "{name:<34} p50 {:>7.1} ms   p99 {:>7.1} ms   (n={})",
        pct_ms(&v, 0.5),
        pct_ms(&v, 0.99),
        v.len()
    );
}

fn main() -> anyhow::Result<()> {
    let steps = steps()?;
    let bin = common::neptunus_bin()?;
    println!("neptunus binary: {}", bin.display());
    println!("{steps} stick steps (neutral <-> x={FORWARD}), {STEP:?} each");

    // Baseline: the emulator.
    let mut rig = Rig::start(&bin, "")?;
    rig.gcs.arm(&mut rig.vehicle)?;
    let mut baseline = Vec::new();
    for i in 0..steps {
        let x = if i % 2 == 0 { FORWARD } else { 0 };
        for _ in rig.executed.try_iter() {}
        let sent = rig.gcs.send(&common::manual_control(x))?;
        let end = sent + STEP;
        let mut got = None;
        while Instant::now() < end {
            rig.gcs.pump(Traffic::Drive(x))?;
            let _ = rig.gcs.recv();
            for (at, text) in rig.executed.try_iter() {
                let moved = text.starts_with("go(") && text != common::NEUTRAL_GO;
                if got.is_none() && (moved == (x != 0)) && text.starts_with("go(") {
                    got = Some(at.saturating_duration_since(sent));
                }
            }
        }
        if let Some(d) = got {
            baseline.push(d);
        }
    }
    drop(rig);

    // The genuine firmware.
    let cache = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/openrov-firmware");
    let firmware = prepare(&firmware_dir(), &cache)?;
    let board = GenuineBoard::spawn(firmware, Wiring::default(), None)?;
    let control = board.control();
    let serial = control.serial();
    let changes = control.changes();
    let dir = tempfile::tempdir()?;
    let (mut gcs, port) = Gcs::bind()?;
    let device = board.path().to_string_lossy().into_owned();
    let endpoint = format!("udpout:127.0.0.1:{port}");
    let mut vehicle = Vehicle::spawn(
        &bin,
        &["--serial", &device, "--mavlink", &endpoint],
        dir.path(),
        "",
    )?;
    gcs.await_vehicle(&mut vehicle, Duration::from_secs(30))?;
    gcs.arm(&mut vehicle)?;
    let (mut to_wire, mut to_esc, mut total) = (Vec::new(), Vec::new(), Vec::new());
    let mut missed = 0;
    for i in 0..steps {
        let x = if i % 2 == 0 { FORWARD } else { 0 };
        for _ in serial.try_iter() {}
        for _ in changes.try_iter() {}
        let sent = gcs.send(&common::manual_control(x))?;
        let end = sent + STEP;
        let (mut wire, mut esc) = (None, None);
        while Instant::now() < end {
            gcs.pump(Traffic::Drive(x))?;
            let _ = gcs.recv();
            for c in serial.try_iter() {
                if wire.is_none() && c.to_board && c.bytes.windows(3).any(|w| w == b"go(") {
                    wire = Some(c.at);
                }
            }
            for c in changes.try_iter() {
                let moved = c.change.to_us.is_some_and(|u| (u - 1500.0).abs() > 40.0);
                if esc.is_none() && c.change.output == Output::EscPort && moved == (x != 0) {
                    esc = Some(c.at);
                }
            }
        }
        match (wire, esc) {
            (Some(w), Some(e)) => {
                to_wire.push(w.saturating_duration_since(sent));
                to_esc.push(e.saturating_duration_since(w));
                total.push(e.saturating_duration_since(sent));
            }
            _ => missed += 1,
        }
    }
    let snap = control.snapshot();
    drop(vehicle);
    drop(board);
    if total.is_empty() {
        bail!("no step reached the ESC pin ({missed} missed)");
    }
    println!("-- genuine 30.0.2 firmware in simavr ({missed} steps missed)");
    let p50 = |v: &[Duration]| {
        let mut v = v.to_vec();
        v.sort();
        pct_ms(&v, 0.5)
    };
    let ratio = p50(&total) / p50(&baseline).max(0.001);
    line("stick -> go() on the board's UART", to_wire);
    line("go() -> ESC pulse at the new width", to_esc);
    line("stick -> ESC pulse (what the pilot feels)", total);
    println!("-- baseline: the board emulator, same run");
    line("stick -> emulator executes go()", baseline);
    println!("ratio stick->ESC / baseline (p50): {ratio:.1}x");
    println!(
        "simulator: {:.2}x real time over the last second, {:.1}x headroom, {} slips",
        snap.realtime_ratio, snap.speed_ratio, snap.slips
    );
    Ok(())
}
