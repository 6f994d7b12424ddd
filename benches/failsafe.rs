//! How fast the GCS failsafe stops the thrusters.
//!
//! The spec: when the owner ground station falls silent, the vehicle stops
//! and disarms at FS_GCS_TIMEOUT + at most 50 ms after the owner's last sign
//! of life (HEARTBEAT or stick input).
//!
//! `neptunus --serial <pty>` runs as a child against a board emulator
//! ([`PtyBoard`]) inside this bench, with FS_GCS_TIMEOUT = 2 and
//! FS_PILOT_INPUT = 0 preset in `params.toml` (so only the GCS failsafe can
//! act). Trials alternate between two kinds:
//!
//! - **failsafe**: arm, drive forward for ~0.5 s with heartbeats and
//!   MANUAL_CONTROL at 25 Hz, then go silent. Reaction = the time the board
//!   executed the first neutral `go(1500,1500,1500)` after our last datagram,
//!   minus that datagram's send time, minus FS_GCS_TIMEOUT.
//! - **baseline**: arm, drive the same way, then send an explicit disarm
//!   COMMAND_LONG: the time from sending it to the board executing the
//!   neutral `go()` — the command path's own latency, which the failsafe
//!   path cannot beat.
//!
//! The board's times are the emulator's wake-up times ([`TimedRecord`]),
//! the same clock as ours. Figures are printed, never asserted.
//!
//! The binary is `$NEPTUNUS_BIN`, else `target/release/neptunus`, else
//! `target/debug/neptunus` (with a warning): `cargo build --release` first.
//! `FAILSAFE_TRIALS` trials of each kind (default 20; a smoke run of 2 when
//! not run by `cargo bench`, e.g. under `cargo test --all-targets`).
//!
//! [`PtyBoard`]: neptunus::firmware::emulator::PtyBoard
//! [`TimedRecord`]: neptunus::firmware::emulator::TimedRecord

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use common::{NEUTRAL_GO, Rig, Traffic};
use neptunus::dialect::neptunus::*;

const FS_GCS_TIMEOUT: Duration = Duration::from_secs(2);
const PARAMS: &str = "FS_GCS_TIMEOUT = 2.0\nFS_PILOT_INPUT = 0\n";
const TARGET_MS: f64 = 50.0;
const FORWARD: i16 = 1000;
const DRIVE: Duration = Duration::from_millis(500);
/// How long to wait for the neutral `go()`: far beyond any plausible reaction.
const GIVE_UP: Duration = Duration::from_secs(10);

fn trials() -> anyhow::Result<usize> {
    // `cargo bench` passes --bench; `cargo test --all-targets` runs this
    // binary without it: then a short smoke run shows the bench still works
    // without taking a minute of the test suite.
    let full = std::env::args().any(|a| a == "--bench");
    match std::env::var("FAILSAFE_TRIALS") {
        Ok(v) => v
            .trim()
            .parse::<usize>()
            .map(|n| n.max(1))
            .with_context(|| format!("FAILSAFE_TRIALS={v:?} is not a whole number")),
        Err(_) => Ok(if full { 20 } else { 2 }),
    }
}

fn main() -> anyhow::Result<()> {
    let trials = trials()?;
    let bin = common::neptunus_bin()?;
    println!("neptunus binary: {}", bin.display());
    println!(
        "{trials} trials of each kind; FS_GCS_TIMEOUT {} s, FS_PILOT_INPUT 0",
        FS_GCS_TIMEOUT.as_secs()
    );
    let mut rig = Rig::start(&bin, PARAMS)?;
    check_params(&mut rig)?;

    let mut failsafe = Samples::default();
    let mut statustext = Samples::default();
    let mut baseline = Samples::default();
    for i in 0..trials {
        let b = baseline_trial(&mut rig)?;
        let f = failsafe_trial(&mut rig)?;
        println!(
            "  trial {:>2}: disarm command → go() {}; silence → go() {}, → STATUSTEXT at the GCS {} after the timeout",
            i + 1,
            fmt_ms(b),
            fmt_ms(f.go),
            fmt_ms(f.statustext),
        );
        baseline.push(b);
        failsafe.push(f.go);
        statustext.push(f.statustext);
    }
    report(trials, &failsafe, &statustext, &baseline);
    Ok(())
}

fn check_params(rig: &mut Rig) -> anyhow::Result<()> {
    let Rig { vehicle, gcs, .. } = rig;
    let timeout = gcs.param(vehicle, "FS_GCS_TIMEOUT")?;
    let pilot = gcs.param(vehicle, "FS_PILOT_INPUT")?;
    if timeout != 2.0 || pilot != 0.0 {
        bail!(
            "params.toml not applied: FS_GCS_TIMEOUT {timeout}, FS_PILOT_INPUT {pilot}:\n{}",
            vehicle.stderr_tail()
        );
    }
    Ok(())
}

/// Arms and drives for [`DRIVE`] after the motors left neutral; forgets
/// what the board executed so far.
fn arm_and_drive(rig: &mut Rig) -> anyhow::Result<()> {
    rig.arm_and_drive(FORWARD)?;
    let Rig { vehicle, gcs, .. } = rig;
    gcs.run_until(vehicle, Traffic::Drive(FORWARD), DRIVE, |_| false)?;
    let _ = rig.executed.try_iter().count();
    Ok(())
}

/// Waits with `traffic` for the first neutral `go()` the board executed
/// after `after`; also notes when a failsafe STATUSTEXT arrives.
fn neutral_go_after(
    rig: &mut Rig,
    after: Instant,
    traffic: Traffic,
) -> anyhow::Result<(Option<Instant>, Option<Instant>)> {
    let Rig {
        vehicle,
        gcs,
        executed,
        ..
    } = rig;
    let mut go = None;
    let mut text = None;
    gcs.run_until(vehicle, traffic, GIVE_UP, |msgs| {
        for m in msgs {
            if let MavMessage::STATUSTEXT(s) = m
                && common::statustext(s).starts_with("Failsafe: GCS 255 heartbeat lost")
            {
                text.get_or_insert_with(Instant::now);
            }
        }
        for (at, cmd) in executed.try_iter() {
            if cmd == NEUTRAL_GO && at > after {
                go.get_or_insert(at);
            }
        }
        go.is_some() && (traffic != Traffic::Silent || text.is_some())
    })?;
    Ok((go, text))
}

/// Explicit disarm → neutral `go()` at the board.
fn baseline_trial(rig: &mut Rig) -> anyhow::Result<Option<Duration>> {
    arm_and_drive(rig)?;
    let sent = rig
        .gcs
        .send_command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0.0)?;
    // The board's records wait in their channel while we read the ACK.
    let result = rig
        .gcs
        .await_ack(&mut rig.vehicle, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM)?;
    if result != MavResult::MAV_RESULT_ACCEPTED {
        bail!("disarm refused: {result:?}");
    }
    let (go, _) = neutral_go_after(rig, sent, Traffic::Heartbeats)?;
    Ok(go.map(|t| t - sent))
}

struct FailsafeTrial {
    /// Neutral `go()` at the board, minus last message, minus the timeout.
    go: Option<Duration>,
    /// The failsafe STATUSTEXT at our socket, likewise.
    statustext: Option<Duration>,
}

/// Silence → neutral `go()` at the board.
fn failsafe_trial(rig: &mut Rig) -> anyhow::Result<FailsafeTrial> {
    arm_and_drive(rig)?;
    let last = rig.gcs.last_life.context("no heartbeat or stick sent")?;
    let (go, text) = neutral_go_after(rig, last, Traffic::Silent)?;
    let after_timeout = |t: Instant| (t - last).saturating_sub(FS_GCS_TIMEOUT);
    if let Some(g) = go
        && g - last < FS_GCS_TIMEOUT
    {
        println!(
            "  WARNING: the thrusters stopped {:.1} ms after our last message, before FS_GCS_TIMEOUT",
            (g - last).as_secs_f64() * 1e3
        );
    }
    Ok(FailsafeTrial {
        go: go.map(after_timeout),
        statustext: text.map(after_timeout),
    })
}

/// Durations of one kind of trial; `None` where nothing happened within [`GIVE_UP`].
#[derive(Default)]
struct Samples {
    all: Vec<Duration>,
    missed: usize,
}

impl Samples {
    fn push(&mut self, d: Option<Duration>) {
        match d {
            Some(d) => self.all.push(d),
            None => self.missed += 1,
        }
    }
    fn sorted(&self) -> Vec<Duration> {
        let mut v = self.all.clone();
        v.sort();
        v
    }
}

fn fmt_ms(d: Option<Duration>) -> String {
    match d {
        Some(d) => format!("{:.1} ms", d.as_secs_f64() * 1e3),
        None => "none".into(),
    }
}

fn report(trials: usize, failsafe: &Samples, statustext: &Samples, baseline: &Samples) {
    let yes = |ok: bool| if ok { "yes" } else { "NO" };
    let f = failsafe.sorted();
    let b = baseline.sorted();
    let t = statustext.sorted();
    let pct = common::pct_ms;
    println!();
    println!("Stop at the board (first neutral go() executed), {trials} trials each");
    println!(
        "  {:<46} {:>9} {:>9} {:>9} {:>7}",
        "path", "p50 ms", "p99 ms", "max ms", "missed"
    );
    let row = |name: &str, v: &[Duration], missed: usize| {
        println!(
            "  {:<46} {:>9.1} {:>9.1} {:>9.1} {:>7}",
            name,
            pct(v, 0.5),
            pct(v, 0.99),
            pct(v, 1.0),
            missed
        );
    };
    row(
        "GCS failsafe: silence → go(), minus 2 s timeout",
        &f,
        failsafe.missed,
    );
    row(
        "  failsafe STATUSTEXT at the GCS, minus 2 s",
        &t,
        statustext.missed,
    );
    row("baseline: disarm COMMAND_LONG → go()", &b, baseline.missed);
    println!(
        "  {:<46} {:>9.1} {:>9.1} {:>9.1}",
        "failsafe reaction minus baseline",
        pct(&f, 0.5) - pct(&b, 0.5),
        pct(&f, 0.99) - pct(&b, 0.99),
        pct(&f, 1.0) - pct(&b, 1.0)
    );
    println!();
    println!(
        "  {:<46} {:>11} {:>9} {:>4}",
        "target", "measured", "limit", "met"
    );
    let worst = pct(&f, 1.0);
    let met = failsafe.missed == 0 && worst <= TARGET_MS;
    println!(
        "  {:<46} {:>8.1} ms {:>6.0} ms {:>4}",
        "GCS failsafe stop after FS_GCS_TIMEOUT, worst",
        worst,
        TARGET_MS,
        yes(met)
    );
    let p99 = pct(&f, 0.99);
    println!(
        "  {:<46} {:>8.1} ms {:>6.0} ms {:>4}",
        "  … p99",
        p99,
        TARGET_MS,
        yes(failsafe.missed == 0 && p99 <= TARGET_MS)
    );
    if failsafe.missed > 0 {
        println!(
            "  {} failsafe trial(s) saw no neutral go() within {} s",
            failsafe.missed,
            GIVE_UP.as_secs()
        );
    }
}
