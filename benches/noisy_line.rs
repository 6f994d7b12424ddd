//! Stick steps through a damaged serial line to the genuine OpenROV
//! firmware: what a long or wet cable to the board costs the pilot.
//!
//! `neptunus --serial <relay>` runs as a child; the project's damaging pty
//! relay ([`NoisyRelay`]) sits between it and the genuine 30.0.2 firmware
//! in simavr, and a ground station alternates the forward stick between
//! pushed (x = 700) and released every second (MANUAL_CONTROL at 25 Hz).
//! Three lines, one after the other, each for `NOISY_LINE_MINUTES`
//! (default 10 under `cargo bench`, 1 otherwise): the noisy line (each
//! way one byte in 400 with a bit flipped, one in 2,000 lost), the same
//! ten times rarer, and a clean line (the relay in place, damaging
//! nothing) — the baseline, in the same run. For each:
//!
//! - **push → pulse**: the station's first MANUAL_CONTROL of the push to
//!   the ESC pins (port and starboard) at the pushed widths;
//! - **release → neutral**: the same to all three ESCs at neutral;
//! - **false dead-man trips**: the board's own `icmd:stop()` reports while
//!   the vehicle ran and pinged (every one is false);
//! - the link's downs, the vehicle's disarms, the board's `crc:fail`
//!   reports and the relay's damage.
//!
//! Times are on the board's simulated clock (the station's send mapped to
//! the simulated time then; the pin's edge in simulated cycles), for the
//! steps through which the board kept pace (`tests/common/noisy.rs`); the
//! wall clock's p99 is printed beside. Figures are printed, never
//! asserted; the targets are printed with them (push p99 ≤ 200 ms,
//! release p99 ≤ 150 ms and never above 300 ms, no false trip).
//!
//! The binary is `$NEPTUNUS_BIN`, else `target/release/neptunus`; the
//! firmware `$OPENROV_FIRMWARE_DIR/30.0.2` (default
//! `../shared/openrov-firmware`); the relay's dice are seeded with
//! `NOISY_LINE_SEED` (default 37). `NOISY_LINE_LINES` picks lines by
//! number (`2,3`: the rarer damage and the clean line), all by default.
//!
//! [`NoisyRelay`]: neptunus::hil::NoisyRelay

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;
#[path = "../tests/common/noisy.rs"]
mod noisy;

use std::path::Path;
use std::time::Duration;

use anyhow::Context as _;
use neptunus::hil::Damage;
use noisy::{NoisyRig, Run, quantile_ms};

fn env_u64(name: &str, default: u64) -> anyhow::Result<u64> {
    match std::env::var(name) {
        Ok(v) => v
            .trim()
            .parse()
            .with_context(|| format!("{name}={v:?} is not a whole number")),
        Err(_) => Ok(default),
    }
}

fn ms(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{v:.0}"))
}

fn row(name: &str, run: &Run) {
    let board = |push: bool| -> Vec<Duration> {
        run.steps
            .iter()
            .filter(|s| s.push == push && s.judged)
            .filter_map(|s| s.board)
            .collect()
    };
    let wall = |push: bool| -> Vec<Duration> {
        run.steps
            .iter()
            .filter(|s| s.push == push)
            .filter_map(|s| s.wall)
            .collect()
    };
    let missed = |push: bool| {
        run.steps
            .iter()
            .filter(|s| s.push == push && s.board.is_none())
            .count()
    };
    let (push, release) = (board(true), board(false));
    let judged = run.steps.iter().filter(|s| s.judged).count();
    println!(
        "| {name} | {} / {} | {} / {} / {} | {} | {} / {} | {} | {} | {} | {judged} of {} | {:.2}×, {} |",
        ms(quantile_ms(&push, 0.5)),
        ms(quantile_ms(&push, 0.99)),
        ms(quantile_ms(&release, 0.5)),
        ms(quantile_ms(&release, 0.99)),
        ms(quantile_ms(&release, 1.0)),
        run.dead_man_trips,
        ms(quantile_ms(&wall(true), 0.99)),
        ms(quantile_ms(&wall(false), 0.99)),
        missed(true) + missed(false),
        run.link_downs,
        run.board_crc_fails,
        run.steps.len(),
        run.realtime_min,
        run.slips,
    );
    println!(
        "|   relay: to the board {} bytes, {} flipped, {} lost; from it {} bytes, {} flipped, {} lost; disarmed heartbeats {}; SYS_STATUS drop_rate_comm/errors_comm at the end {:?} |",
        run.to_board.bytes,
        run.to_board.flipped,
        run.to_board.dropped,
        run.from_board.bytes,
        run.from_board.flipped,
        run.from_board.dropped,
        run.disarmed_heartbeats,
        run.comm,
    );
}

fn main() -> anyhow::Result<()> {
    let full = std::env::args().any(|a| a == "--bench");
    let minutes = env_u64("NOISY_LINE_MINUTES", if full { 10 } else { 1 })?;
    let seed = env_u64("NOISY_LINE_SEED", 37)?;
    let bin = common::neptunus_bin()?;
    let firmware = common::firmware_dir("30.0.2");
    let cache = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/openrov-firmware");
    println!("neptunus binary: {}", bin.display());
    println!(
        "{minutes} min per line of stick steps (pushed x=700 / released, 1 s each), relay seed {seed}; \
         times on the board's clock, judged steps only"
    );
    println!(
        "targets: push p99 <= 200 ms; release p99 <= 150 ms, max <= 300 ms; no false dead-man trip"
    );
    println!();
    println!(
        "| line (each way) | push → pulse p50 / p99 ms | release → neutral p50 / p99 / max ms | false dead-man trips | wall p99 push / release ms | steps not reached | link downs | board crc:fail | judged | simavr min, slips |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let noisy = Damage::new(400, 2000);
    let lines = [
        ("1/400 flipped, 1/2,000 lost", noisy),
        ("1/4,000 flipped, 1/20,000 lost", noisy.rarer(10)),
        ("clean (the baseline)", Damage::NONE),
    ];
    let picked: Vec<usize> = match std::env::var("NOISY_LINE_LINES") {
        Ok(v) => v
            .split(',')
            .map(|n| match n.trim().parse::<usize>() {
                Ok(i @ 1..=3) => Ok(i),
                _ => anyhow::bail!("NOISY_LINE_LINES={v:?}: line numbers 1 to 3, e.g. 2,3"),
            })
            .collect::<anyhow::Result<_>>()?,
        Err(_) => vec![1, 2, 3],
    };
    for (i, (name, damage)) in lines.into_iter().enumerate() {
        if !picked.contains(&(i + 1)) {
            continue;
        }
        let mut rig = NoisyRig::start(&bin, &firmware, &cache, damage, seed)?;
        let run = rig.run(Duration::from_secs(60 * minutes), Duration::from_secs(1))?;
        row(name, &run);
    }
    Ok(())
}
