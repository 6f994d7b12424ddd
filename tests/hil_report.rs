//! `neptunus sim-report --hil`: the closed-loop scenarios of `sim-report`
//! with the genuine 30.0.2 firmware in simavr instead of the board
//! emulator, stepped in lock-step with the scenarios' simulated time.
//!
//! Judged from what the command writes: with the firmware in the loop the
//! depth hold reaches 2 m and holds it within ±0.15 m, the heading hold
//! reaches and holds within ±5°, both hold for a minute in a current, and
//! SURFACE brings the vehicle up — and the figures are the firmware's: its
//! `deap` lines were decoded (none rejected), it echoed the thruster
//! commands, and its runs differ from the simulator's. Nothing here
//! measures how fast it runs.
#![cfg(feature = "hil")]
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stdout)]

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::sync::OnceLock;

use neptunus::hil::lockstep::GenuineRigs;
use neptunus::hil::{Firmware, prepare};
use neptunus::scenario::report;

const DEPTH_BAND_M: f64 = 0.15;
const HEADING_BAND_DEG: f64 = 5.0;

/// Where the firmware is built and cached: the binary's `--data-dir` puts
/// its cache in `<data dir>/openrov-firmware`, as the other tests' is.
fn data_dir() -> &'static Path {
    Path::new(env!("CARGO_TARGET_TMPDIR"))
}

/// The firmware built once for this process (one build at a time per
/// process: the cache's work folder is named by the process).
fn firmware() -> &'static Firmware {
    static BUILT: OnceLock<Firmware> = OnceLock::new();
    BUILT.get_or_init(|| {
        prepare(
            &common::firmware_dir("30.0.2"),
            &data_dir().join("openrov-firmware"),
        )
        .unwrap_or_else(|e| panic!("building the 30.0.2 firmware: {e}"))
    })
}

/// One run's samples, by column.
struct Csv {
    columns: BTreeMap<String, Vec<f64>>,
}

impl Csv {
    fn read(path: &Path) -> Self {
        let text =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut lines = text.lines();
        let names: Vec<String> = lines
            .next()
            .expect("header")
            .split(',')
            .map(str::to_owned)
            .collect();
        let mut columns: BTreeMap<String, Vec<f64>> =
            names.iter().map(|n| (n.clone(), Vec::new())).collect();
        for line in lines {
            for (name, v) in names.iter().zip(line.split(',')) {
                columns
                    .get_mut(name)
                    .unwrap()
                    .push(v.parse().unwrap_or(f64::NAN));
            }
        }
        Self { columns }
    }

    fn col(&self, name: &str) -> &[f64] {
        &self.columns[name]
    }

    /// (t, value − target) where a target is set.
    fn errors(&self, value: &str, target: &str, wrap: bool) -> Vec<(f64, f64)> {
        let t = self.col("t_s");
        let v = self.col(value);
        let g = self.col(target);
        (0..t.len())
            .filter(|&i| g[i].is_finite())
            .map(|i| {
                let e = v[i] - g[i];
                (t[i], if wrap { wrap_deg(e) } else { e })
            })
            .collect()
    }
}

fn wrap_deg(d: f64) -> f64 {
    let d = d.rem_euclid(360.0);
    if d > 180.0 { d - 360.0 } else { d }
}

/// From when on the error stays within ±`band` to the last sample, and how
/// long that is (s); `None` if it is outside at the end.
fn held(errors: &[(f64, f64)], band: f64) -> Option<(f64, f64)> {
    let end = errors.last()?.0;
    let from = errors
        .iter()
        .rev()
        .take_while(|(_, e)| e.abs() <= band)
        .last()?
        .0;
    Some((from, end - from))
}

/// The `sim` and `hil` columns of the printed table, by (scenario, figure).
fn table(stdout: &str) -> BTreeMap<(String, String), (Option<f64>, Option<f64>)> {
    stdout
        .lines()
        .filter_map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            let num = |s: &str| s.parse::<f64>().ok();
            (w.len() >= 4 && (num(w[2]).is_some() || num(w[3]).is_some()))
                .then(|| ((w[0].to_owned(), w[1].to_owned()), (num(w[2]), num(w[3]))))
        })
        .collect()
}

#[test]
fn with_the_genuine_firmware_in_the_loop_depth_and_heading_hold_and_surface_works() {
    let out = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_neptunus"))
        .arg("sim-report")
        .arg("--hil")
        .arg(common::firmware_dir("30.0.2"))
        .arg(out.path())
        .arg("--data-dir")
        .arg(data_dir())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stdout}\n{stderr}");
    println!("{stdout}");
    let dir = out.path();

    // Depth step 0 → 2 m: reached, then held within the band for at least 30 s.
    let step = Csv::read(&dir.join("depth_step-hil.csv"));
    let (from, hold) = held(
        &step.errors("depth_true_m", "depth_target_m", false),
        DEPTH_BAND_M,
    )
    .expect("the depth hold ends within ±0.15 m of 2 m");
    assert!(hold >= 30.0, "within ±0.15 m of 2 m from {from:.2} s only");
    // The heading is held meanwhile.
    let (_, hold) = held(
        &step.errors("heading_true_deg", "heading_target_deg", true),
        HEADING_BAND_DEG,
    )
    .expect("the heading held during the dive");
    assert!(hold >= 30.0, "heading within ±5° for {hold:.1} s only");

    // Heading step 30° → 120°: reached, then held (the firmware's compass
    // has no bias: the truth is what it reads).
    let turn = Csv::read(&dir.join("heading_step-hil.csv"));
    let errors = turn.errors("heading_true_deg", "heading_target_deg", true);
    assert!(
        errors.iter().any(|(_, e)| e.abs() > 60.0),
        "the target is 90° away at the step"
    );
    let (from, hold) =
        held(&errors, HEADING_BAND_DEG).expect("the heading ends within ±5° of 120°");
    assert!(hold >= 10.0, "within ±5° of 120° from {from:.2} s only");

    // A minute at 2 m in a 0.2 m/s current with the tether: both held throughout.
    let current = Csv::read(&dir.join("depth_hold_current-hil.csv"));
    for (value, target, band, wrap) in [
        ("depth_true_m", "depth_target_m", DEPTH_BAND_M, false),
        (
            "heading_true_deg",
            "heading_target_deg",
            HEADING_BAND_DEG,
            true,
        ),
    ] {
        let (from, hold) = held(&current.errors(value, target, wrap), band)
            .unwrap_or_else(|| panic!("{value} outside its band at the end"));
        assert!(
            hold >= 60.0,
            "{value} within its band from {from:.2} s only"
        );
    }

    // SURFACE from 3 m brings it up.
    let surface = Csv::read(&dir.join("surface-hil.csv"));
    let depth = surface.col("depth_true_m");
    assert!((depth[0] - 3.0).abs() < 0.01, "starts at 3 m: {}", depth[0]);
    let top = depth.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(top <= 0.1, "SURFACE came up to {top:.2} m only");

    // The figures are the firmware's.
    let figures = table(&stdout);
    let hil = |scenario: &str, figure: &str| {
        figures
            .get(&(scenario.to_owned(), figure.to_owned()))
            .and_then(|(_, h)| *h)
            .unwrap_or_else(|| panic!("no hil {scenario} {figure} in\n{stdout}"))
    };
    for scenario in [
        "depth_step",
        "heading_step",
        "depth_hold_current",
        "wild_points",
        "surface",
    ] {
        assert!(hil(scenario, "firmware_depth_lines") > 0.0, "{scenario}");
        assert!(hil(scenario, "firmware_thrust_echoed") > 0.0, "{scenario}");
        assert_eq!(hil(scenario, "firmware_rejected_lines"), 0.0, "{scenario}");
        assert_eq!(hil(scenario, "crc_failures"), 0.0, "{scenario}");
        let sim = std::fs::read(dir.join(format!("{scenario}.csv"))).unwrap();
        let genuine = std::fs::read(dir.join(format!("{scenario}-hil.csv"))).unwrap();
        assert_ne!(sim, genuine, "{scenario}: the same run twice");
        let png = std::fs::read(dir.join(format!("{scenario}-hil.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    }
    let (sim, genuine) = figures[&("surface".to_owned(), "time_to_surface".to_owned())];
    assert!(sim.is_some() && genuine.is_some(), "both columns: {stdout}");
    let summary = std::fs::read_to_string(dir.join("summary.md")).unwrap();
    assert!(summary.contains("| scenario | figure | sim | hil | unit |"));
}

#[test]
fn the_same_scenario_on_the_genuine_firmware_runs_the_same_every_time() {
    let run = || {
        report::surface_on(&mut GenuineRigs::new(firmware().clone()))
            .unwrap_or_else(|e| panic!("{e}"))
    };
    let (a, b) = (run(), run());
    assert!(a.samples.len() > 2000);
    // Debug prints each value exactly (and NaN, the targets not held, as
    // itself, where `==` would call two runs different).
    assert_eq!(format!("{:?}", a.samples), format!("{:?}", b.samples));
    assert_eq!(format!("{:?}", a.metrics), format!("{:?}", b.metrics));
}
