//! The step-response plots of `neptunus sim-report`: five panels over time
//! (depth, heave speed, heading, yaw rate, thrust demand) with the true,
//! measured and estimated values and the targets, drawn with `plotters` as
//! SVG and rasterised with `resvg`. Text needs a system font (Debian:
//! fonts-dejavu-core); its absence is a clear error.

use plotters::prelude::*;

use super::Sample;

/// Why a plot could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("plot {name}: {message}")]
    Draw { name: String, message: String },
    #[error(
        "no system font found to label the plots — install one (Debian: apt install fonts-dejavu-core)"
    )]
    NoFont,
}

/// The system font the plots are labelled with.
pub(super) fn fonts() -> Result<resvg::usvg::Options<'static>, PlotError> {
    let mut opt = resvg::usvg::Options::default();
    opt.fontdb_mut().load_system_fonts();
    if opt.fontdb.is_empty() {
        return Err(PlotError::NoFont);
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
        .ok_or(PlotError::NoFont)?;
    opt.font_family = family.clone();
    opt.fontdb_mut().set_sans_serif_family(family);
    Ok(opt)
}

/// One panel: a title, a y label and its series (label, colour, value).
type Series = (&'static str, RGBColor, fn(&Sample) -> f64);

/// The plot of one run's `samples` as PNG, titled `title`.
pub(super) fn plot(
    name: &str,
    title: &str,
    samples: &[Sample],
    opt: &resvg::usvg::Options<'static>,
) -> Result<Vec<u8>, PlotError> {
    let err = |e: String| PlotError::Draw {
        name: name.into(),
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
            .titled(title, ("sans-serif", 24))
            .map_err(|e| err(e.to_string()))?;
        let areas = root.split_evenly((panels.len(), 1));
        let t_end = samples.last().map_or(1.0, |s| s.t_s);
        for (area, (label, series)) in areas.iter().zip(panels) {
            let finite = |f: fn(&Sample) -> f64| {
                samples
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
                 -> Result<(), PlotError> {
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
                for s in samples {
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
