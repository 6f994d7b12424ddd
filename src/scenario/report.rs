//! `neptunus sim-report DIR`: the step responses of the depth and heading
//! autopilots, redone for our controllers the way the thesis' figures
//! 12.2–12.5 show the simulator (state, rate and command over time).
//!
//! Owns the scenario definitions (fixed seeds, so every run gives the same
//! numbers), their figures of merit, and the CSV and PNG files. Plots are
//! drawn with `plotters` as SVG and rasterised with `resvg`; text needs a
//! system font (Debian: fonts-dejavu-core), and its absence is a clear error.

use std::path::{Path, PathBuf};
use std::time::Duration;

use plotters::prelude::*;

use super::{Sample, Scenario, Sticks};
use crate::firmware::emulator::EmulatorOptions;
use crate::vehicle::mode::Mode;

/// Errors writing the report.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("plot {name}: {message}")]
    Plot { name: String, message: String },
    #[error(
        "no system font found to label the plots — install one (Debian: apt install fonts-dejavu-core)"
    )]
    NoFont,
}

/// A scenario's result: its samples and figures of merit.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub name: &'static str,
    pub title: &'static str,
    pub samples: Vec<Sample>,
    /// (name, value, unit), in the order they are reported.
    pub metrics: Vec<(&'static str, f64, &'static str)>,
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

fn armed_in(mode: Mode, opts: EmulatorOptions, depth_m: f64, heading_deg: f64) -> Scenario {
    let mut s = Scenario::new(opts);
    s.place(depth_m, heading_deg);
    // Telemetry first: the pre-arm checks want a fresh heading, and the
    // hold modes a depth estimate.
    s.run(Duration::from_secs(3));
    s.arm();
    s.set_mode(mode.number());
    s
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
    let mut s = armed_in(Mode::AltHold, options(1), 0.0, 45.0);
    s.run(Duration::from_secs(2));
    let start = s.now().as_secs_f64();
    s.set_depth_target(2.0);
    s.run(Duration::from_secs(40));
    let samples = s.samples().to_vec();
    let after: Vec<&Sample> = samples.iter().filter(|x| x.t_s >= start).collect();
    let peak = after
        .iter()
        .map(|x| x.depth_true_m)
        .fold(f64::MIN, f64::max);
    Outcome {
        name: "depth_step",
        title: "Depth step 0 → 2 m (ALT_HOLD)",
        metrics: vec![
            (
                "settling_time_0.1m",
                settling_time_s(&samples, start, 2.0, 0.1, |x| x.depth_true_m),
                "s",
            ),
            ("overshoot", ((peak - 2.0) / 2.0 * 100.0).max(0.0), "%"),
        ],
        samples,
    }
}

/// Heading step 30° → 120° in STABILIZE. Judged on the compass reading
/// without noise (true heading plus the compass' configured bias): a
/// heading hold can only hold the heading its compass reports.
pub fn heading_step() -> Outcome {
    let opts = options(2);
    let bias = opts.sim.noise.heading_bias_deg;
    let mut s = armed_in(Mode::Stabilize, opts, 1.0, 30.0);
    s.run(Duration::from_secs(2));
    let start = s.now().as_secs_f64();
    s.set_heading_target(120.0);
    s.run(Duration::from_secs(20));
    let samples = s.samples().to_vec();
    let compass = |x: &Sample| x.heading_true_deg + bias;
    let peak = samples
        .iter()
        .filter(|x| x.t_s >= start)
        .map(|x| angle_diff(compass(x), 120.0))
        .fold(f64::MIN, f64::max);
    Outcome {
        name: "heading_step",
        title: "Heading step 30° → 120° (STABILIZE)",
        metrics: vec![
            (
                "settling_time_3deg",
                settling_time_s(&samples, start, 0.0, 3.0, |x| angle_diff(compass(x), 120.0)),
                "s",
            ),
            ("overshoot", peak.max(0.0), "deg"),
            ("compass_bias", bias, "deg"),
        ],
        samples,
    }
}

/// Depth hold at 2 m for 60 s in a 0.2 m/s current with tether drag.
pub fn depth_hold_in_current() -> Outcome {
    let mut opts = options(3);
    set_current(&mut opts, 0.2);
    let mut s = armed_in(Mode::AltHold, opts, 2.0, 45.0);
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
    let samples = s.samples().to_vec();
    let max_err = samples
        .iter()
        .filter(|x| x.t_s >= start)
        .map(|x| (x.depth_true_m - 2.0).abs())
        .fold(0.0, f64::max);
    Outcome {
        name: "depth_hold_current",
        title: "Depth hold 2 m, 60 s, 0.2 m/s current, tether",
        metrics: vec![("max_depth_error", max_err, "m")],
        samples,
    }
}

/// Depth and heading hold with 5 % wild points on both readings.
pub fn wild_points() -> Outcome {
    let mut opts = options(4);
    set_wild_rate(&mut opts, 0.05);
    let mut s = armed_in(Mode::AltHold, opts, 2.0, 30.0);
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
    let samples = s.samples().to_vec();
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
    Outcome {
        name: "wild_points",
        title: "5 % wild points on depth and heading",
        metrics: vec![
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
        ],
        samples,
    }
}

/// SURFACE from 3 m.
pub fn surface() -> Outcome {
    let mut s = armed_in(Mode::Surface, options(5), 3.0, 45.0);
    let start = s.now().as_secs_f64();
    s.run(Duration::from_secs(25));
    let samples = s.samples().to_vec();
    let surfaced = samples
        .iter()
        .find(|x| x.t_s >= start && x.depth_true_m <= 0.1)
        .map_or(f64::INFINITY, |x| x.t_s - start);
    Outcome {
        name: "surface",
        title: "SURFACE from 3 m",
        metrics: vec![("time_to_surface", surfaced, "s")],
        samples,
    }
}

/// Every scenario of the report.
pub fn all() -> Vec<Outcome> {
    vec![
        depth_step(),
        heading_step(),
        depth_hold_in_current(),
        wild_points(),
        surface(),
    ]
}

/// A current across the vehicle's heading (it flows towards the east).
fn set_current(opts: &mut EmulatorOptions, speed_mps: f64) {
    opts.sim.current.speed_mps = speed_mps;
    opts.sim.current.direction_deg = 90.0;
}

fn set_wild_rate(opts: &mut EmulatorOptions, rate: f64) {
    opts.sim.wild_rate = rate;
}

/// Writes `DIR/<scenario>.csv`, `DIR/<scenario>.png` and `DIR/summary.md`.
pub fn write(dir: &Path, outcomes: &[Outcome]) -> Result<Vec<PathBuf>, ReportError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ReportError::Write { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let fonts = fonts()?;
    let mut written = Vec::new();
    let mut summary = String::from("| scenario | figure | value |\n|---|---|---|\n");
    for o in outcomes {
        let csv_path = dir.join(format!("{}.csv", o.name));
        std::fs::write(&csv_path, csv(&o.samples)).map_err(io(&csv_path))?;
        written.push(csv_path);
        let png_path = dir.join(format!("{}.png", o.name));
        let png = plot(o, &fonts)?;
        std::fs::write(&png_path, png).map_err(io(&png_path))?;
        written.push(png_path);
        for (name, value, unit) in &o.metrics {
            summary.push_str(&format!("| {} | {name} | {value:.3} {unit} |\n", o.title));
        }
    }
    let summary_path = dir.join("summary.md");
    std::fs::write(&summary_path, summary).map_err(io(&summary_path))?;
    written.push(summary_path);
    Ok(written)
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

fn fonts() -> Result<resvg::usvg::Options<'static>, ReportError> {
    let mut opt = resvg::usvg::Options::default();
    opt.fontdb_mut().load_system_fonts();
    if opt.fontdb.is_empty() {
        return Err(ReportError::NoFont);
    }
    let family = ["DejaVu Sans", "Liberation Sans", "Noto Sans"]
        .into_iter()
        .find(|f| {
            opt.fontdb
                .faces()
                .any(|face| face.families.iter().any(|(n, _)| n == f))
        })
        .map(str::to_owned)
        .or_else(|| {
            opt.fontdb
                .faces()
                .next()
                .and_then(|f| f.families.first().map(|(n, _)| n.clone()))
        })
        .ok_or(ReportError::NoFont)?;
    opt.font_family = family.clone();
    opt.fontdb_mut().set_sans_serif_family(family);
    Ok(opt)
}

/// One panel: a title, a y label and its series (label, colour, value).
type Series = (&'static str, RGBColor, fn(&Sample) -> f64);

fn plot(o: &Outcome, opt: &resvg::usvg::Options<'static>) -> Result<Vec<u8>, ReportError> {
    let err = |e: String| ReportError::Plot {
        name: o.name.into(),
        message: e,
    };
    let depth: [Series; 4] = [
        ("true", BLUE, |s| s.depth_true_m),
        ("measured", RGBColor(170, 170, 170), |s| s.depth_measured_m),
        ("estimate", RED, |s| s.depth_estimate_m),
        ("target", BLACK, |s| s.depth_target_m),
    ];
    let heave: [Series; 2] = [
        ("true w", BLUE, |s| s.heave_true_mps),
        ("estimate", RED, |s| s.heave_estimate_mps),
    ];
    let heading: [Series; 4] = [
        ("true", BLUE, |s| s.heading_true_deg),
        ("measured", RGBColor(170, 170, 170), |s| {
            s.heading_measured_deg
        }),
        ("estimate", RED, |s| s.heading_estimate_deg),
        ("target", BLACK, |s| s.heading_target_deg),
    ];
    let rate: [Series; 2] = [
        ("true r", BLUE, |s| s.yaw_rate_true_dps),
        ("estimate", RED, |s| s.yaw_rate_estimate_dps),
    ];
    let demand: [Series; 3] = [
        ("heave", BLUE, |s| s.heave_demand),
        ("yaw", RED, |s| s.yaw_demand),
        ("surge", RGBColor(0, 150, 0), |s| s.surge_demand),
    ];
    let panels: [(&str, &[Series]); 5] = [
        ("depth (m, down)", &depth),
        ("heave speed (m/s, down)", &heave),
        ("heading (deg)", &heading),
        ("yaw rate (deg/s)", &rate),
        ("thrust demand (−1..1)", &demand),
    ];
    let (w, h) = (1000u32, 1250u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
        let root = root
            .titled(o.title, ("sans-serif", 24))
            .map_err(|e| err(e.to_string()))?;
        let areas = root.split_evenly((panels.len(), 1));
        let t_end = o.samples.last().map_or(1.0, |s| s.t_s);
        for (area, (label, series)) in areas.iter().zip(panels) {
            let finite = |f: fn(&Sample) -> f64| {
                o.samples
                    .iter()
                    .map(f)
                    .filter(|v| v.is_finite())
                    .collect::<Vec<_>>()
            };
            let mut lo = f64::MAX;
            let mut hi = f64::MIN;
            for (_, _, f) in series {
                for v in finite(*f) {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            if lo > hi {
                (lo, hi) = (0.0, 1.0);
            }
            let pad = ((hi - lo) * 0.08).max(0.05);
            let mut chart = ChartBuilder::on(area)
                .margin(8)
                .x_label_area_size(28)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad))
                .map_err(|e| err(e.to_string()))?;
            chart
                .configure_mesh()
                .x_desc("time (s)")
                .y_desc(label)
                .label_style(("sans-serif", 13))
                .draw()
                .map_err(|e| err(e.to_string()))?;
            for &(name, colour, f) in series {
                // NaN (not held) breaks the line instead of drawing to zero.
                let mut segment: Vec<(f64, f64)> = Vec::new();
                let mut first = true;
                let flush = |seg: &mut Vec<(f64, f64)>,
                             chart: &mut ChartContext<_, _>,
                             first: &mut bool|
                 -> Result<(), ReportError> {
                    if seg.is_empty() {
                        return Ok(());
                    }
                    let series = chart
                        .draw_series(LineSeries::new(seg.drain(..), colour.stroke_width(2)))
                        .map_err(|e| err(e.to_string()))?;
                    if std::mem::take(first) {
                        series.label(name).legend(move |(x, y)| {
                            PathElement::new([(x, y), (x + 16, y)], colour.stroke_width(2))
                        });
                    }
                    Ok(())
                };
                for s in &o.samples {
                    let v = f(s);
                    if v.is_finite() {
                        segment.push((s.t_s, v));
                    } else {
                        flush(&mut segment, &mut chart, &mut first)?;
                    }
                }
                flush(&mut segment, &mut chart, &mut first)?;
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font(("sans-serif", 13))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(|e| err(e.to_string()))?;
        }
        root.present().map_err(|e| err(e.to_string()))?;
    }
    let tree = resvg::usvg::Tree::from_str(&svg, opt).map_err(|e| err(e.to_string()))?;
    let mut pixmap =
        resvg::tiny_skia::Pixmap::new(w, h).ok_or_else(|| err("empty image".into()))?;
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::default(),
        &mut pixmap.as_mut(),
    );
    pixmap.encode_png().map_err(|e| err(e.to_string()))
}
