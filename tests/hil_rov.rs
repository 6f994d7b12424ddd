//! The whole ROV with the genuine firmware in the loop (`neptunus --hil`):
//! the 30.0.2 firmware in simavr reads the simulator's depth sensor and
//! IMU and drives the simulator with its own ESC pulses; a ground station
//! dives, turns, holds and surfaces the vehicle over UDP, and what Neptunus
//! reports is compared with the simulator's truth (NEPTUNUS_SIM_STATE).
//!
//! Held at 2 m and 90°, the vehicle is nearly at rest: the median
//! difference between telemetry and truth over the hold must be within
//! 0.05 m and 3° — a depth of the wrong sign, in the wrong unit or with an
//! offset, or a heading mirrored or shifted, fails it (at 0 m and 0° most
//! such errors would not show). Deadlines are generous for a shared
//! machine; nothing here measures how fast it is.
#![cfg(feature = "hil")]
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

mod common;

use std::path::Path;
use std::time::Duration;

use common::{Gcs, Traffic, Vehicle};
use neptunus::dialect::neptunus::*;
use neptunus::hil::prepare;

const TARGET_DEPTH_M: f64 = 2.0;
const TARGET_HEADING_DEG: f64 = 90.0;
/// The hold the acceptance asks for.
const HOLD: Duration = Duration::from_secs(30);
const DEPTH_BAND_M: f64 = 0.15;
const HEADING_BAND_DEG: f64 = 5.0;
/// Telemetry against truth, at rest.
const DEPTH_AGREE_M: f64 = 0.05;
const ANGLE_AGREE_DEG: f64 = 3.0;
/// Inside the bands this long counts as reached.
const SETTLE: Duration = Duration::from_secs(5);
/// Deadlines for a shared machine.
const REACH: Duration = Duration::from_secs(180);
const NEUTRAL_STICKS: Traffic = Traffic::Sticks { x: 0, z: 500, r: 0 };
/// A hold is judged when simavr kept at least this share of real time
/// (its runner's every report in the hold), did not slip …
const MIN_REALTIME_RATIO: f64 = 0.85;
/// … and the coupling of board and plant never waited longer than this.
const MAX_COUPLING_GAP_MS: u64 = 250;
/// Holds taken before giving up on a machine too busy to judge one.
const HOLD_TRIES: usize = 4;

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

/// `a − b` wrapped into (−180, 180].
fn angle_diff_deg(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    if d > 180.0 { d - 360.0 } else { d }
}

fn median(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty());
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// What the vehicle last said, and the truth just before it.
#[derive(Default)]
struct Seen {
    truth: Option<NEPTUNUS_SIM_STATE_DATA>,
    texts: Vec<String>,
    /// (telemetry − truth) pairs: depth m, yaw, roll, pitch deg.
    depth: Vec<f64>,
    yaw: Vec<f64>,
    roll: Vec<f64>,
    pitch: Vec<f64>,
    /// Truth outside the hold bands during the hold.
    out_of_band: Vec<String>,
}

impl Seen {
    fn take(&mut self, msgs: &[MavMessage], recording: bool) {
        for m in msgs {
            match m {
                MavMessage::NEPTUNUS_SIM_STATE(s) => {
                    if recording {
                        let depth_err = f64::from(s.z) - TARGET_DEPTH_M;
                        let hdg_err =
                            angle_diff_deg(f64::from(s.psi).to_degrees(), TARGET_HEADING_DEG);
                        if depth_err.abs() > DEPTH_BAND_M || hdg_err.abs() > HEADING_BAND_DEG {
                            self.out_of_band.push(format!(
                                "t {} ms: depth {:.3} m, heading {:.1}°",
                                s.time_boot_ms,
                                s.z,
                                f64::from(s.psi).to_degrees().rem_euclid(360.0)
                            ));
                        }
                    }
                    self.truth = Some(s.clone());
                }
                MavMessage::ATTITUDE(a) if recording => {
                    if let Some(t) = &self.truth {
                        self.yaw.push(angle_diff_deg(
                            f64::from(a.yaw).to_degrees(),
                            f64::from(t.psi).to_degrees(),
                        ));
                        self.roll.push(angle_diff_deg(
                            f64::from(a.roll).to_degrees(),
                            f64::from(t.phi).to_degrees(),
                        ));
                        self.pitch.push(angle_diff_deg(
                            f64::from(a.pitch).to_degrees(),
                            f64::from(t.theta).to_degrees(),
                        ));
                    }
                }
                MavMessage::GLOBAL_POSITION_INT(g) if recording => {
                    if let Some(t) = &self.truth {
                        // relative_alt: mm, negative below the surface.
                        let depth = -f64::from(g.relative_alt) / 1000.0;
                        self.depth.push(depth - f64::from(t.z));
                    }
                }
                MavMessage::STATUSTEXT(s) => {
                    self.texts
                        .push(String::from_utf8_lossy(s.text.as_ref()).into_owned());
                }
                _ => {}
            }
        }
    }
}

/// One report of the board runner's (every 10 s): simavr's share of real
/// time over its last second, its slips so far (each a fall more than
/// 250 ms behind, let go), and the longest the coupling of board and plant
/// waited between passes since the report before.
#[derive(Debug, Clone, Copy)]
struct RunnerReport {
    realtime_ratio: f64,
    slips: u64,
    widest_gap_ms: u64,
}

impl RunnerReport {
    /// The world around the board kept pace with the vehicle's clock.
    fn kept_pace(&self) -> bool {
        self.realtime_ratio >= MIN_REALTIME_RATIO && self.widest_gap_ms <= MAX_COUPLING_GAP_MS
    }
}

/// The board runner's reports in `log`, oldest first.
fn runner_reports(log: &str) -> Vec<RunnerReport> {
    // Without the terminal's colour codes (`ESC [ … m`) around the fields.
    let mut plain = String::with_capacity(log.len());
    let mut chars = log.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for c in chars.by_ref() {
                if c == 'm' {
                    break;
                }
            }
        } else {
            plain.push(c);
        }
    }
    let field = |line: &str, name: &str| -> Option<f64> {
        let at = line.find(name)? + name.len();
        let digits: String = line[at..]
            .chars()
            .take_while(|c| c.is_ascii_digit() || *c == '.')
            .collect();
        digits.parse().ok()
    };
    plain
        .lines()
        .filter(|l| l.contains("genuine board in simavr"))
        .filter_map(|l| {
            Some(RunnerReport {
                realtime_ratio: field(l, "realtime_ratio=")?,
                slips: field(l, "slips=")? as u64,
                widest_gap_ms: field(l, "widest_gap_ms=")? as u64,
            })
        })
        .collect()
}

/// Until the truth is inside both bands for SETTLE of the vehicle's time
/// (passing through on the way is not reaching), or panics.
fn reach(gcs: &mut Gcs, vehicle: &mut Vehicle, seen: &mut Seen) {
    let mut inside_since: Option<u32> = None;
    let settle_ms = SETTLE.as_millis() as u32;
    let reached = gcs
        .run_until(vehicle, NEUTRAL_STICKS, REACH, |msgs| {
            seen.take(msgs, false);
            let Some(t) = seen.truth.as_ref() else {
                return false;
            };
            let inside = (f64::from(t.z) - TARGET_DEPTH_M).abs() < DEPTH_BAND_M
                && angle_diff_deg(f64::from(t.psi).to_degrees(), TARGET_HEADING_DEG).abs()
                    < HEADING_BAND_DEG;
            if !inside {
                inside_since = None;
                return false;
            }
            let since = *inside_since.get_or_insert(t.time_boot_ms);
            t.time_boot_ms.saturating_sub(since) >= settle_ms
        })
        .unwrap();
    assert!(
        reached,
        "2 m and 90° not reached (and kept for {SETTLE:?}) within {REACH:?}: truth {:?}\ntexts {:?}\n{}",
        seen.truth,
        seen.texts,
        vehicle.stderr_tail()
    );
}

fn set_mode(gcs: &mut Gcs, vehicle: &mut Vehicle, mode: u32) {
    let r = gcs
        .command_with(
            vehicle,
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, mode as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .unwrap();
    assert_eq!(
        r,
        MavResult::MAV_RESULT_ACCEPTED,
        "mode {mode}\n{}",
        vehicle.stderr_tail()
    );
}

#[test]
fn the_genuine_firmware_dives_turns_holds_and_surfaces_the_simulated_rov() {
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("openrov-firmware");
    let firmware = prepare(&common::firmware_dir("30.0.2"), &cache)
        .unwrap_or_else(|e| panic!("building the 30.0.2 firmware: {e}"));
    let elf = firmware.elf.to_string_lossy().into_owned();
    let dir = tempfile::tempdir().unwrap();
    let (mut gcs, port) = Gcs::bind().unwrap();
    let endpoint = format!("udpout:127.0.0.1:{port}");
    // The board runner's report (simavr's speed against real time, every
    // 10 s) is what tells a hold the machine let run from one it did not.
    let mut vehicle = Vehicle::spawn_env(
        bin(),
        &[
            "--hil",
            &elf,
            "--mavlink",
            &endpoint,
            "--http",
            "127.0.0.1:0",
            "--video-rtp",
            "off",
        ],
        dir.path(),
        "",
        &[("RUST_LOG", "warn,neptunus::hil=info")],
    )
    .unwrap();
    gcs.await_vehicle(&mut vehicle, Duration::from_secs(60))
        .unwrap();
    gcs.wait_ready(&mut vehicle).unwrap();
    gcs.arm(&mut vehicle).unwrap();
    // ALT_HOLD, then the depth and heading to hold.
    set_mode(&mut gcs, &mut vehicle, 2);
    let r = gcs
        .command_with(
            &mut vehicle,
            MavCmd::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET,
            [
                TARGET_DEPTH_M as f32,
                TARGET_HEADING_DEG as f32,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        )
        .unwrap();
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);

    // Reached, then held for 30 s — judged in a hold the machine let the
    // board run at (nearly) real time. The plant moves on the board's
    // time, the autopilot on the vehicle's: a machine too busy for simavr
    // to keep up slows the ROV under an autopilot that does not slow, a
    // world the vehicle never meets on the ROV. Such a hold is reported and
    // taken again (reached anew first).
    let mut seen = Seen::default();
    let mut judged = None;
    let mut not_judged = Vec::new();
    for _ in 0..HOLD_TRIES {
        reach(&mut gcs, &mut vehicle, &mut seen);
        let mark = vehicle.stderr_text().len();
        seen.out_of_band.clear();
        // Held for 30 s (of the vehicle's own clock: the truth's stamps).
        let start_ms = seen.truth.as_ref().map(|t| t.time_boot_ms).unwrap();
        let hold_ms = HOLD.as_millis() as u32;
        let held = gcs
            .run_until(&mut vehicle, NEUTRAL_STICKS, HOLD + REACH, |msgs| {
                seen.take(msgs, true);
                seen.truth
                    .as_ref()
                    .is_some_and(|t| t.time_boot_ms.saturating_sub(start_ms) >= hold_ms)
            })
            .unwrap();
        assert!(held, "the hold did not last 30 s of vehicle time");
        let log = vehicle.stderr_text();
        // The log read before the hold may have ended inside a character.
        let mut mark = mark.min(log.len());
        while !log.is_char_boundary(mark) {
            mark -= 1;
        }
        let before = runner_reports(&log[..mark]).last().copied();
        let during = runner_reports(&log[mark..]);
        let no_new_slip = match (before, during.last()) {
            (Some(b), Some(d)) => d.slips == b.slips,
            (None, Some(d)) => d.slips == 0,
            _ => false,
        };
        if !during.is_empty() && no_new_slip && during.iter().all(RunnerReport::kept_pace) {
            judged = Some((during, std::mem::take(&mut seen.out_of_band)));
            break;
        }
        println!(
            "hold not judged: the board's world did not keep pace ({during:?}; judged at ≥ {MIN_REALTIME_RATIO}× real time, no slip, coupling gaps ≤ {MAX_COUPLING_GAP_MS} ms); {} samples out of the bands",
            seen.out_of_band.len()
        );
        not_judged.push(during);
    }
    match judged {
        Some((reports, out_of_band)) => {
            println!("hold judged: {reports:?}");
            assert!(
                out_of_band.is_empty(),
                "left 2 ± {DEPTH_BAND_M} m / 90 ± {HEADING_BAND_DEG}° during the hold ({reports:?}): {:?}",
                &out_of_band[..out_of_band.len().min(10)]
            );
        }
        None => println!(
            "THE HOLD WAS NOT JUDGED: in {HOLD_TRIES} holds the machine never let the board's world keep pace ({not_judged:?})"
        ),
    }

    // Telemetry against truth, nearly at rest.
    let figures = [
        ("depth (m)", median(seen.depth.clone()), DEPTH_AGREE_M),
        ("yaw (°)", median(seen.yaw.clone()), ANGLE_AGREE_DEG),
        ("roll (°)", median(seen.roll.clone()), ANGLE_AGREE_DEG),
        ("pitch (°)", median(seen.pitch.clone()), ANGLE_AGREE_DEG),
    ];
    for (what, diff, tol) in figures {
        println!("telemetry − truth at 2 m, 90°: {what} median {diff:+.3} (tolerance {tol})");
        assert!(
            diff.abs() <= tol,
            "{what}: telemetry − truth median {diff:+.3}, more than {tol}"
        );
    }

    // SURFACE brings it up.
    set_mode(&mut gcs, &mut vehicle, 9);
    let surfaced = gcs
        .run_until(&mut vehicle, NEUTRAL_STICKS, REACH, |msgs| {
            seen.take(msgs, false);
            seen.truth.as_ref().is_some_and(|t| t.z < 0.3)
        })
        .unwrap();
    assert!(
        surfaced,
        "SURFACE did not bring it up within {REACH:?}: truth {:?}\n{}",
        seen.truth,
        vehicle.stderr_tail()
    );
}
