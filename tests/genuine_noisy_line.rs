//! A noisy line to the genuine board: 60 s of stick steps, armed, through
//! the project's damaging relay (one byte in 400 with a bit flipped, one
//! in 2,000 lost, each way) between Neptunus and the genuine 30.0.2
//! firmware in simavr. The link never goes down, the board's dead-man
//! never trips, every push reaches the ESC pins within 1 s and every
//! release brings them to neutral within 0.5 s — deadlines on the board's
//! own simulated clock, judged for the steps through which the board kept
//! pace (`common/noisy.rs` says why and how).
#![cfg(feature = "hil")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
#[path = "common/noisy.rs"]
mod noisy;

use std::path::Path;
use std::time::Duration;

use neptunus::hil::Damage;
use noisy::{NoisyRig, Step};

const PUSH_DEADLINE: Duration = Duration::from_secs(1);
const RELEASE_DEADLINE: Duration = Duration::from_millis(500);

fn describe(steps: &[&Step]) -> String {
    steps
        .iter()
        .map(|s| {
            format!(
                "{} wall {:?} board {:?}{}",
                if s.push { "push" } else { "release" },
                s.wall,
                s.board,
                if s.judged { "" } else { " (not judged)" }
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn a_noisy_line_loses_no_stop_no_push_and_no_dive() {
    let firmware = common::firmware_dir("30.0.2");
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("openrov-firmware");
    let bin = Path::new(env!("CARGO_BIN_EXE_neptunus"));
    let mut rig = NoisyRig::start(bin, &firmware, &cache, Damage::new(400, 2000), 37).unwrap();
    let run = rig
        .run(Duration::from_secs(60), Duration::from_secs(1))
        .unwrap();
    let late = |s: &&Step| {
        let deadline = if s.push {
            PUSH_DEADLINE
        } else {
            RELEASE_DEADLINE
        };
        s.board.is_none_or(|b| b > deadline)
    };
    let judged = run.steps.iter().filter(|s| s.judged).count();
    let missed: Vec<&Step> = run.steps.iter().filter(|s| s.judged).filter(late).collect();
    let unjudged_late: Vec<&Step> = run
        .steps
        .iter()
        .filter(|s| !s.judged)
        .filter(late)
        .collect();
    eprintln!(
        "noisy line: {} steps ({judged} judged), to the board {:?}, from it {:?}; the board rejected {} frames; \
         simavr at least {:.2}x real time, {} slips; SYS_STATUS drop_rate_comm/errors_comm {:?}",
        run.steps.len(),
        run.to_board,
        run.from_board,
        run.board_crc_fails,
        run.realtime_min,
        run.slips,
        run.comm,
    );
    for (what, push, deadline) in [
        ("pushes", true, PUSH_DEADLINE),
        ("releases", false, RELEASE_DEADLINE),
    ] {
        let steps: Vec<&Step> = run.steps.iter().filter(|s| s.push == push).collect();
        let slow = steps
            .iter()
            .filter(|s| s.board.is_none_or(|b| b > deadline))
            .count();
        let never = steps.iter().filter(|s| s.board.is_none()).count();
        let reached: Vec<Duration> = steps.iter().filter_map(|s| s.board).collect();
        eprintln!(
            "{what}: {} in all, {slow} past {deadline:?} on the board's clock ({never} not within the step); p50 {:?} ms, p99 {:?} ms, slowest {:?} ms",
            steps.len(),
            noisy::quantile_ms(&reached, 0.5),
            noisy::quantile_ms(&reached, 0.99),
            noisy::quantile_ms(&reached, 1.0),
        );
    }
    eprintln!(
        "link downs {}, the board's dead-man trips {}, disarmed heartbeats {}",
        run.link_downs, run.dead_man_trips, run.disarmed_heartbeats
    );
    eprintln!(
        "late steps the board did not keep pace through (not judged):\n{}",
        describe(&unjudged_late)
    );
    if judged < run.steps.len() / 2 {
        eprintln!(
            "FEW STEPS JUDGED: the machine let the board keep pace through {judged} of {} steps",
            run.steps.len()
        );
    }
    assert!(
        run.to_board.flipped > 0 && run.from_board.flipped > 0 && run.board_crc_fails > 0,
        "the relay damaged nothing the board noticed: {run:?}"
    );
    assert_eq!(
        run.link_downs,
        0,
        "the board link went down: {:?}\n{}",
        run.texts,
        rig.vehicle.stderr_tail()
    );
    assert_eq!(
        run.dead_man_trips, 0,
        "the board's dead-man tripped: {:?}",
        run.texts
    );
    assert_eq!(
        run.disarmed_heartbeats, 0,
        "the vehicle disarmed during the dive: {:?}",
        run.texts
    );
    assert!(
        missed.is_empty(),
        "{} of {judged} judged steps missed their deadline (push {PUSH_DEADLINE:?}, release {RELEASE_DEADLINE:?}):\n{}\ntexts: {:?}",
        missed.len(),
        describe(&missed),
        run.texts
    );
    let (drop_rate, errors) = run.comm.expect("a SYS_STATUS during the run");
    assert!(
        errors > 0 && drop_rate > 0,
        "SYS_STATUS says the line is clean (drop_rate_comm {drop_rate}, errors_comm {errors}) while the board rejected {} frames",
        run.board_crc_fails
    );
}
