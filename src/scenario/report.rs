//! `neptunus sim-report DIR`: the step responses of the depth and heading
//! autopilots, redone for our controllers the way the thesis' figures
//! 12.2–12.5 show the simulator (state, rate and command over time).
//!
//! Owns the scenario definitions (fixed seeds, so every run gives the same
//! numbers), their figures of merit, the CSV files and the summary; the
//! plots are `super::plot`'s. Each scenario runs on the [`Rigs`] it is
//! given: the built-in simulator ([`Simulator`]), or with the feature `hil`
//! the genuine firmware in simavr (`neptunus sim-report --hil`), whose
//! figures [`comparison`] sets beside the simulator's.

use std::convert::Infallible;
#[cfg(feature = "report")]
use std::path::{Path, PathBuf};
use std::time::Duration;

#[cfg(feature = "report")]
use super::plot::{PlotError, fonts, plot};
use super::{Rig, Sample, Scenario, Sticks};
use crate::firmware::emulator::EmulatorOptions;
use crate::firmware::loopback::BuiltinSim;
use crate::vehicle::mode::Mode;
use crate::vehicle::params::ParamStore;

/// Errors writing the report.
#[cfg(feature = "report")]
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// A figure of merit: (name, value, unit).
pub type Metric = (&'static str, f64, &'static str);

/// A scenario's result: its samples and figures of merit.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub name: &'static str,
    pub title: &'static str,
    /// What it ran on, when not the built-in simulator ([`Rigs::label`]).
    pub rig: Option<&'static str>,
    pub samples: Vec<Sample>,
    /// In the order they are reported.
    pub metrics: Vec<Metric>,
}

impl Outcome {
    pub fn metric(&self, name: &str) -> f64 {
        self.metrics
            .iter()
            .find(|m| m.0 == name)
            .map_or(f64::NAN, |m| m.1)
    }
}

/// The simulator set-up of the scenarios: the default (most realistic)
/// model with a fixed seed.
pub fn options(seed: u64) -> EmulatorOptions {
    let mut o = EmulatorOptions::default();
    o.faults.seed = seed;
    o.sim.seed = seed;
    o
}

/// Where the scenarios run: a fresh [`Rig`] for each scenario's options.
pub trait Rigs {
    type Rig: Rig;
    type Error;
    /// A rig with the simulated vehicle of `opts` at rest at this depth
    /// and heading, its link up. (Placed before its board starts, so that
    /// no reading from before the scenario is still on its way.)
    fn rig(
        &mut self,
        opts: &EmulatorOptions,
        depth_m: f64,
        heading_deg: f64,
    ) -> Result<Self::Rig, Self::Error>;
    /// What the plots and tables call these runs (`None`: the built-in
    /// simulator, as `neptunus sim-report` always ran).
    fn label(&self) -> Option<&'static str> {
        None
    }
    /// The bias of the heading the rig's compass reports for `opts`: the
    /// heading step is judged in that frame.
    fn compass_bias_deg(&self, opts: &EmulatorOptions) -> f64 {
        opts.sim.noise.heading_bias_deg
    }
    /// After a scenario: an error if the rig did not run it to its end, else
    /// figures of its own for the report.
    fn finish(&mut self, _rig: &Self::Rig) -> Result<Vec<Metric>, Self::Error> {
        Ok(Vec::new())
    }
}

/// The built-in simulator: the board emulator and its simulator in the
/// process (`firmware::loopback`).
#[derive(Debug, Clone, Copy, Default)]
pub struct Simulator;

impl Rigs for Simulator {
    type Rig = BuiltinSim;
    type Error = Infallible;
    fn rig(
        &mut self,
        opts: &EmulatorOptions,
        depth_m: f64,
        heading_deg: f64,
    ) -> Result<BuiltinSim, Infallible> {
        let mut sim = BuiltinSim::new(opts.clone(), Duration::ZERO);
        sim.place(depth_m, heading_deg);
        Ok(sim)
    }
}

fn on_simulator<T>(run: impl FnOnce(&mut Simulator) -> Result<T, Infallible>) -> T {
    match run(&mut Simulator) {
        Ok(o) => o,
        Err(never) => match never {},
    }
}

fn armed_in<F: Rigs>(
    rigs: &mut F,
    mode: Mode,
    opts: &EmulatorOptions,
    depth_m: f64,
    heading_deg: f64,
) -> Result<Scenario<F::Rig>, F::Error> {
    let s = rigs.rig(opts, depth_m, heading_deg)?;
    let mut s = Scenario::on(s, ParamStore::default());
    // Telemetry first: the pre-arm checks want a fresh heading, and the
    // hold modes a depth estimate.
    s.run(Duration::from_secs(3));
    s.arm();
    s.set_mode(mode.number());
    Ok(s)
}

/// The outcome of a scenario run on `rigs`, with the rig's own figures
/// after the scenario's.
fn outcome<F: Rigs>(
    rigs: &mut F,
    s: Scenario<F::Rig>,
    name: &'static str,
    title: &'static str,
    mut metrics: Vec<Metric>,
) -> Result<Outcome, F::Error> {
    metrics.extend(rigs.finish(s.rig())?);
    Ok(Outcome {
        name,
        title,
        rig: rigs.label(),
        samples: s.samples().to_vec(),
        metrics,
    })
}

/// First time after which the signal stays within ±`band` of `target`.
pub fn settling_time_s(
    samples: &[Sample],
    start_s: f64,
    target: f64,
    band: f64,
    f: impl Fn(&Sample) -> f64,
) -> f64 {
    let mut settled_at = None;
    for s in samples.iter().filter(|s| s.t_s >= start_s) {
        let inside = (f(s) - target).abs() <= band;
        match (inside, settled_at) {
            (true, None) => settled_at = Some(s.t_s),
            (false, Some(_)) => settled_at = None,
            _ => {}
        }
    }
    settled_at.map_or(f64::INFINITY, |t| t - start_s)
}

fn angle_diff(a: f64, b: f64) -> f64 {
    crate::sim::thesis::wrap_deg_180(a - b)
}

/// Depth step 0 → 2 m in ALT_HOLD.
pub fn depth_step() -> Outcome {
    on_simulator(depth_step_on)
}

/// [`depth_step`] on `rigs`.
pub fn depth_step_on<F: Rigs>(rigs: &mut F) -> Result<Outcome, F::Error> {
    let mut s = armed_in(rigs, Mode::AltHold, &options(1), 0.0, 45.0)?;
    s.run(Duration::from_secs(2));
    let start = s.now().as_secs_f64();
    s.set_depth_target(2.0);
    s.run(Duration::from_secs(40));
    let samples = s.samples();
    let peak = samples
        .iter()
        .filter(|x| x.t_s >= start)
        .map(|x| x.depth_true_m)
        .fold(f64::MIN, f64::max);
    let metrics = vec![
        (
            "settling_time_0.1m",
            settling_time_s(samples, start, 2.0, 0.1, |x| x.depth_true_m),
            "s",
        ),
        ("overshoot", ((peak - 2.0) / 2.0 * 100.0).max(0.0), "%"),
    ];
    outcome(
        rigs,
        s,
        "depth_step",
        "Depth step 0 → 2 m (ALT_HOLD)",
        metrics,
    )
}

/// Heading step 30° → 120° in STABILIZE. Judged on the compass reading
/// without noise (true heading plus the compass' configured bias): a
/// heading hold can only hold the heading its compass reports.
pub fn heading_step() -> Outcome {
    on_simulator(heading_step_on)
}

/// [`heading_step`] on `rigs`.
pub fn heading_step_on<F: Rigs>(rigs: &mut F) -> Result<Outcome, F::Error> {
    let opts = options(2);
    let bias = rigs.compass_bias_deg(&opts);
    let mut s = armed_in(rigs, Mode::Stabilize, &opts, 1.0, 30.0)?;
    s.run(Duration::from_secs(2));
    let start = s.now().as_secs_f64();
    s.set_heading_target(120.0);
    s.run(Duration::from_secs(20));
    let samples = s.samples();
    let compass = |x: &Sample| x.heading_true_deg + bias;
    let peak = samples
        .iter()
        .filter(|x| x.t_s >= start)
        .map(|x| angle_diff(compass(x), 120.0))
        .fold(f64::MIN, f64::max);
    let metrics = vec![
        (
            "settling_time_3deg",
            settling_time_s(samples, start, 0.0, 3.0, |x| angle_diff(compass(x), 120.0)),
            "s",
        ),
        ("overshoot", peak.max(0.0), "deg"),
        ("compass_bias", bias, "deg"),
    ];
    let title = "Heading step 30° → 120° (STABILIZE)";
    outcome(rigs, s, "heading_step", title, metrics)
}

/// Depth hold at 2 m for 60 s in a 0.2 m/s current with tether drag.
pub fn depth_hold_in_current() -> Outcome {
    on_simulator(depth_hold_in_current_on)
}

/// [`depth_hold_in_current`] on `rigs`.
pub fn depth_hold_in_current_on<F: Rigs>(rigs: &mut F) -> Result<Outcome, F::Error> {
    let mut opts = options(3);
    set_current(&mut opts, 0.2);
    let mut s = armed_in(rigs, Mode::AltHold, &opts, 2.0, 45.0)?;
    s.set_depth_target(2.0);
    // The vehicle drifts with the current while the pilot drives forward a little.
    s.set_sticks(Sticks {
        x: 300,
        z: 500,
        r: 0,
    });
    s.run(Duration::from_secs(5));
    let start = s.now().as_secs_f64();
    s.run(Duration::from_secs(60));
    let max_err = s
        .samples()
        .iter()
        .filter(|x| x.t_s >= start)
        .map(|x| (x.depth_true_m - 2.0).abs())
        .fold(0.0, f64::max);
    let title = "Depth hold 2 m, 60 s, 0.2 m/s current, tether";
    let metrics = vec![("max_depth_error", max_err, "m")];
    outcome(rigs, s, "depth_hold_current", title, metrics)
}

/// Depth and heading hold with 5 % wild points on both readings.
pub fn wild_points() -> Outcome {
    on_simulator(wild_points_on)
}

/// [`wild_points`] on `rigs`.
pub fn wild_points_on<F: Rigs>(rigs: &mut F) -> Result<Outcome, F::Error> {
    let mut opts = options(4);
    set_wild_rate(&mut opts, 0.05);
    let mut s = armed_in(rigs, Mode::AltHold, &opts, 2.0, 30.0)?;
    s.set_depth_target(2.0);
    s.run(Duration::from_secs(5));
    // A turn, then a climb, so the estimates move while wild points arrive.
    s.set_sticks(Sticks {
        x: 0,
        z: 500,
        r: 500,
    });
    s.run(Duration::from_secs(6));
    s.set_sticks(Sticks { x: 0, z: 750, r: 0 });
    s.run(Duration::from_secs(3));
    s.set_sticks(Sticks::CENTRED);
    s.run(Duration::from_secs(46));
    let samples = s.samples();
    let max_jump = |f: &dyn Fn(&Sample) -> f64, wrap: bool| {
        samples
            .windows(2)
            .filter(|w| w[0].t_s >= 3.0)
            .map(|w| {
                let d = f(&w[1]) - f(&w[0]);
                if wrap {
                    angle_diff(f(&w[1]), f(&w[0])).abs()
                } else {
                    d.abs()
                }
            })
            .fold(0.0, f64::max)
    };
    let last = samples.last().copied().unwrap_or_default();
    let metrics = vec![
        (
            "max_depth_estimate_jump",
            max_jump(&|x| x.depth_estimate_m, false),
            "m",
        ),
        (
            "max_heading_estimate_jump",
            max_jump(&|x| x.heading_estimate_deg, true),
            "deg",
        ),
        ("depth_rejected", last.depth_rejected as f64, ""),
        ("heading_rejected", last.heading_rejected as f64, ""),
    ];
    let title = "5 % wild points on depth and heading";
    outcome(rigs, s, "wild_points", title, metrics)
}

/// SURFACE from 3 m.
pub fn surface() -> Outcome {
    on_simulator(surface_on)
}

/// [`surface`] on `rigs`.
pub fn surface_on<F: Rigs>(rigs: &mut F) -> Result<Outcome, F::Error> {
    let mut s = armed_in(rigs, Mode::Surface, &options(5), 3.0, 45.0)?;
    let start = s.now().as_secs_f64();
    s.run(Duration::from_secs(25));
    let surfaced = s
        .samples()
        .iter()
        .find(|x| x.t_s >= start && x.depth_true_m <= 0.1)
        .map_or(f64::INFINITY, |x| x.t_s - start);
    let metrics = vec![("time_to_surface", surfaced, "s")];
    outcome(rigs, s, "surface", "SURFACE from 3 m", metrics)
}

/// Every scenario of the report.
pub fn all() -> Vec<Outcome> {
    on_simulator(all_on)
}

/// Every scenario of the report, on `rigs`, in the order [`all`] runs them.
pub fn all_on<F: Rigs>(rigs: &mut F) -> Result<Vec<Outcome>, F::Error> {
    Ok(vec![
        depth_step_on(rigs)?,
        heading_step_on(rigs)?,
        depth_hold_in_current_on(rigs)?,
        wild_points_on(rigs)?,
        surface_on(rigs)?,
    ])
}

/// A current across the vehicle's heading (it flows towards the east).
fn set_current(opts: &mut EmulatorOptions, speed_mps: f64) {
    opts.sim.current.speed_mps = speed_mps;
    opts.sim.current.direction_deg = 90.0;
}

fn set_wild_rate(opts: &mut EmulatorOptions, rate: f64) {
    opts.sim.wild_rate = rate;
}

/// What the files of a run on the genuine firmware end in, before the
/// extension (`depth_step-hil.csv`).
pub const HIL_SUFFIX: &str = "-hil";

/// Writes `DIR/<scenario>.csv`, `DIR/<scenario>.png` and `DIR/summary.md`.
#[cfg(feature = "report")]
pub fn write(dir: &Path, outcomes: &[Outcome]) -> Result<Vec<PathBuf>, ReportError> {
    let mut summary = String::from("| scenario | figure | value |\n|---|---|---|\n");
    for o in outcomes {
        for (name, value, unit) in &o.metrics {
            summary.push_str(&format!("| {} | {name} | {value:.3} {unit} |\n", o.title));
        }
    }
    write_files(dir, &[(outcomes, "")], &summary)
}

/// Writes the simulator's files as [`write()`] does, the other run's beside
/// them with [`HIL_SUFFIX`] (`DIR/<scenario>-hil.csv`, `.png`), and
/// `DIR/summary.md` with the two side by side ([`comparison`]).
#[cfg(feature = "report")]
pub fn write_beside(
    dir: &Path,
    sim: &[Outcome],
    hil: &[Outcome],
) -> Result<Vec<PathBuf>, ReportError> {
    let mut summary =
        String::from("| scenario | figure | sim | hil | unit |\n|---|---|---|---|---|\n");
    for row in comparison(sim, hil) {
        summary.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            row.title,
            row.figure,
            cell(row.sim),
            cell(row.hil),
            row.unit
        ));
    }
    write_files(dir, &[(sim, ""), (hil, HIL_SUFFIX)], &summary)
}

#[cfg(feature = "report")]
fn write_files(
    dir: &Path,
    runs: &[(&[Outcome], &str)],
    summary: &str,
) -> Result<Vec<PathBuf>, ReportError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ReportError::Write { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let fonts = fonts()?;
    let mut written = Vec::new();
    for (outcomes, suffix) in runs {
        for o in *outcomes {
            let csv_path = dir.join(format!("{}{suffix}.csv", o.name));
            std::fs::write(&csv_path, csv(&o.samples)).map_err(io(&csv_path))?;
            written.push(csv_path);
            let png_path = dir.join(format!("{}{suffix}.png", o.name));
            let title = match o.rig {
                Some(rig) => format!("{} — {rig}", o.title),
                None => o.title.to_owned(),
            };
            let png = plot(o.name, &title, &o.samples, &fonts)?;
            std::fs::write(&png_path, png).map_err(io(&png_path))?;
            written.push(png_path);
        }
    }
    let summary_path = dir.join("summary.md");
    std::fs::write(&summary_path, summary).map_err(io(&summary_path))?;
    written.push(summary_path);
    Ok(written)
}

/// One figure of one scenario, from two runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub scenario: &'static str,
    pub title: &'static str,
    pub figure: &'static str,
    pub unit: &'static str,
    /// On the built-in simulator; `None` where that run has no such figure.
    pub sim: Option<f64>,
    /// On the other rigs (the genuine firmware).
    pub hil: Option<f64>,
}

/// The figures of two runs of the same scenarios side by side: every
/// figure of either, grouped by scenario in the order they ran.
pub fn comparison(sim: &[Outcome], hil: &[Outcome]) -> Vec<Row> {
    let mut rows: Vec<Row> = Vec::new();
    for (run, is_sim) in [(sim, true), (hil, false)] {
        for o in run {
            for &(figure, value, unit) in &o.metrics {
                let i = match rows
                    .iter()
                    .position(|r| r.scenario == o.name && r.figure == figure)
                {
                    Some(i) => i,
                    None => {
                        rows.push(Row {
                            scenario: o.name,
                            title: o.title,
                            figure,
                            unit,
                            sim: None,
                            hil: None,
                        });
                        rows.len() - 1
                    }
                };
                if is_sim {
                    rows[i].sim = Some(value);
                } else {
                    rows[i].hil = Some(value);
                }
            }
        }
    }
    // A figure only the second run has goes with its scenario's others.
    let mut order: Vec<&'static str> = Vec::new();
    for r in &rows {
        if !order.contains(&r.scenario) {
            order.push(r.scenario);
        }
    }
    rows.sort_by_key(|r| order.iter().position(|&n| n == r.scenario));
    rows
}

/// A figure in a table: three decimals, or a dash where the run has none.
fn cell(value: Option<f64>) -> String {
    value.map_or_else(|| "—".to_owned(), |v| format!("{v:.3}"))
}

/// [`comparison`] as a plain-text table for a terminal.
pub fn comparison_text(sim: &[Outcome], hil: &[Outcome]) -> String {
    let mut out = format!(
        "{:<20} {:<26} {:>10} {:>10}\n",
        "scenario", "figure", "sim", "hil"
    );
    for r in comparison(sim, hil) {
        out.push_str(&format!(
            "{:<20} {:<26} {:>10} {:>10} {}\n",
            r.scenario,
            r.figure,
            cell(r.sim),
            cell(r.hil),
            r.unit
        ));
    }
    out
}

/// The samples as CSV, one column per field.
pub fn csv(samples: &[Sample]) -> String {
    let mut out = String::from(
        "t_s,depth_true_m,depth_measured_m,depth_estimate_m,depth_target_m,heave_true_mps,heave_estimate_mps,\
heading_true_deg,heading_measured_deg,heading_estimate_deg,heading_target_deg,yaw_rate_true_dps,yaw_rate_estimate_dps,\
north_m,east_m,surge_mps,surge_demand,heave_demand,yaw_demand,port_us,vertical_us,starboard_us,depth_rejected,heading_rejected\n",
    );
    for s in samples {
        out.push_str(&format!(
            "{:.2},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{},{}\n",
            s.t_s, s.depth_true_m, s.depth_measured_m, s.depth_estimate_m, s.depth_target_m, s.heave_true_mps,
            s.heave_estimate_mps, s.heading_true_deg, s.heading_measured_deg, s.heading_estimate_deg,
            s.heading_target_deg, s.yaw_rate_true_dps, s.yaw_rate_estimate_dps, s.north_m, s.east_m,
            s.surge_mps, s.surge_demand, s.heave_demand, s.yaw_demand, s.port_us, s.vertical_us,
            s.starboard_us, s.depth_rejected, s.heading_rejected
        ));
    }
    out
}
