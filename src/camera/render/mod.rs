//! The synthetic camera picture: drawn from a [`Scene`] and encoded as JPEG.
//!
//! Pure and deterministic (same scene, same bytes), so tests compare pixels
//! and the bench times it. What a camera on the vehicle would see, for an
//! operator to tell that the simulated vehicle moves:
//! - water that darkens with depth, lighter towards the surface, the edge
//!   between the two (the horizon) tilted by roll and moved by pitch plus
//!   camera tilt (nose or camera up moves it down);
//! - shafts of light from the surface at fixed bearings, which sweep across
//!   the picture as the vehicle turns.
//!
//! The instruments are not part of the scene: the browser's HUD draws them
//! over any camera. With `[camera] synthetic_overlay = true` the picture
//! carries its own ([`overlay`]): a horizon line and pitch ladder, a heading
//! tape, depth, tilt, pitch and roll readouts, the armed state and a `SIM`
//! marker, for viewers without the page (`/video.mjpg` in VLC).

mod overlay;

use bytes::Bytes;
use jpeg_encoder::{ColorType, Encoder};

use super::frame::Scene;

/// Vertical field of view (a 4:3 webcam like the OpenROV's).
const VFOV_DEG: f64 = 45.0;
/// Degrees of heading across the whole tape.
const TAPE_SPAN_DEG: f64 = 90.0;
/// Sub-pixel resolution of the background table.
const LUT_STEPS_PER_PX: f64 = 2.0;
/// Light shafts around the compass, each at its own bearing and width.
const SHAFTS: usize = 16;
/// Brightness steps of a shaft (0: none), for the table of colours.
const SHAFT_LEVELS: usize = 8;

type Rgb = [u8; 3];

const WHITE: Rgb = [235, 240, 240];
const YELLOW: Rgb = [255, 215, 40];
const RED: Rgb = [220, 40, 30];
const GREEN: Rgb = [70, 210, 90];
const BLACK: Rgb = [0, 0, 0];

/// The JPEG encoder could not encode the picture.
#[derive(Debug, thiserror::Error)]
#[error(
    "camera source synthetic: cannot encode a {width}×{height} JPEG at quality {quality}: {source} — use a smaller camera.width/camera.height"
)]
pub struct RenderError {
    width: u32,
    height: u32,
    quality: u8,
    source: jpeg_encoder::EncodingError,
}

/// Draws and encodes synthetic frames, reusing its buffers.
#[derive(Debug)]
pub struct SyntheticRenderer {
    width: usize,
    height: usize,
    quality: u8,
    /// Draw the instruments into the picture.
    overlay: bool,
    rgb: Vec<u8>,
    lut: Vec<Cell>,
    /// Light-shaft level by position along the horizon (same steps as `lut`).
    shafts: Vec<u8>,
    last_jpeg_len: usize,
}

/// One entry of the background table, by signed distance to the horizon.
#[derive(Debug, Clone, Copy, Default)]
struct Cell {
    /// The water at each light-shaft level (`[0]`: no shaft).
    water: [Rgb; SHAFT_LEVELS],
    line: Rgb,
    kind: Line,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
enum Line {
    #[default]
    None,
    Horizon,
    /// A pitch-ladder rung at 20°, 40°…: drawn longer.
    LongRung,
    ShortRung,
}

impl SyntheticRenderer {
    /// Sizes outside 1..=65535 are clamped (the config allows 16..=4096).
    /// Without the instruments: see [`with_overlay`](Self::with_overlay).
    pub fn new(width: u32, height: u32, quality: u8) -> Self {
        let width = width.clamp(1, u32::from(u16::MAX)) as usize;
        let height = height.clamp(1, u32::from(u16::MAX)) as usize;
        SyntheticRenderer {
            width,
            height,
            quality: quality.clamp(1, 100),
            overlay: false,
            rgb: vec![0; width * height * 3],
            lut: Vec::new(),
            shafts: Vec::new(),
            last_jpeg_len: 0,
        }
    }

    /// Draws the instruments (heading tape, readouts, pitch ladder …) into
    /// the picture too, or not.
    pub fn with_overlay(mut self, on: bool) -> Self {
        self.overlay = on;
        self
    }

    pub fn width(&self) -> u32 {
        self.width as u32
    }

    pub fn height(&self) -> u32 {
        self.height as u32
    }

    /// Draws `scene`; returns the RGB pixels, row by row.
    pub fn render(&mut self, scene: &Scene) -> &[u8] {
        let s = Sanitized::from(scene);
        self.background(&s);
        if self.overlay {
            let mut canvas = overlay::Canvas::new(&mut self.rgb, self.width, self.height);
            canvas.instruments(&s);
        }
        &self.rgb
    }

    /// Encodes what [`render`](Self::render) drew last.
    pub fn encode(&mut self) -> Result<Bytes, RenderError> {
        let mut out = Vec::with_capacity(self.last_jpeg_len + self.last_jpeg_len / 4 + 1024);
        let enc = Encoder::new(&mut out, self.quality);
        enc.encode(
            &self.rgb,
            self.width as u16,
            self.height as u16,
            ColorType::Rgb,
        )
        .map_err(|source| RenderError {
            width: self.width as u32,
            height: self.height as u32,
            quality: self.quality,
            source,
        })?;
        self.last_jpeg_len = out.len();
        Ok(Bytes::from(out))
    }

    /// Paints the capture time `unix_ms` ([`timecode`](super::timecode))
    /// over what [`render`](Self::render) drew last.
    pub fn stamp(&mut self, unix_ms: u64) {
        super::timecode::paint(&mut self.rgb, self.width, self.height, unix_ms);
    }

    pub fn render_jpeg(&mut self, scene: &Scene) -> Result<Bytes, RenderError> {
        self.render(scene);
        self.encode()
    }

    fn px_per_deg(&self) -> f64 {
        self.height as f64 / VFOV_DEG
    }

    fn scale(&self) -> usize {
        (self.height / 240).max(1)
    }

    /// Water and light shafts (with the overlay: the horizon line and pitch
    /// ladder). Every pixel's colour depends only on its signed distance to
    /// the horizon and on how far along the horizon it is, so the colours
    /// come from two tables indexed by those, which change by constant
    /// steps along a row.
    fn background(&mut self, s: &Sanitized) {
        let (w, h) = (self.width, self.height);
        let ppd = self.px_per_deg();
        let scale = self.scale() as f64;
        let reach = (w + h) as f64;
        self.fill_lut(s, reach, ppd, scale);
        self.fill_shafts(s, reach, ppd);
        let lut_last = self.lut.len() - 1;
        let shafts_last = self.shafts.len() - 1;

        let (sin, cos) = s.roll_deg.to_radians().sin_cos();
        let cx = w as f64 / 2.0;
        // Nose or camera up: the horizon goes down the picture.
        let y0 = h as f64 / 2.0 + (s.pitch_deg + s.tilt_deg) * ppd;
        let long_rung = w as f64 * 0.09;
        let short_rung = w as f64 * 0.045;
        for y in 0..h {
            let dy = y as f64 + 0.5 - y0;
            // d: distance below the horizon; a: position along it.
            let mut d = (0.5 - cx) * sin + dy * cos;
            let mut a = (0.5 - cx) * cos - dy * sin;
            let row = &mut self.rgb[y * w * 3..(y + 1) * w * 3];
            for px in row.chunks_exact_mut(3) {
                let i = ((d + reach) * LUT_STEPS_PER_PX).clamp(0.0, lut_last as f64) as usize;
                let j = ((a + reach) * LUT_STEPS_PER_PX).clamp(0.0, shafts_last as f64) as usize;
                let cell = &self.lut[i];
                let water = &cell.water[usize::from(self.shafts[j])];
                let colour = match cell.kind {
                    Line::None => water,
                    Line::Horizon => &cell.line,
                    Line::LongRung if a.abs() <= long_rung => &cell.line,
                    Line::ShortRung if a.abs() <= short_rung => &cell.line,
                    Line::LongRung | Line::ShortRung => water,
                };
                px.copy_from_slice(colour);
                d += sin;
                a += cos;
            }
        }
    }

    fn fill_lut(&mut self, s: &Sanitized, reach: f64, ppd: f64, scale: f64) {
        let n = (2.0 * reach * LUT_STEPS_PER_PX) as usize + 2;
        self.lut.resize(n, Cell::default());
        // Light falls off with depth; never fully black so overlays stay legible.
        let light = 0.18 + 0.82 * (-s.depth_m.max(0.0) / 20.0).exp();
        let fade = self.height as f64 * 0.6;
        let rung = 10.0 * ppd;
        let lines = self.overlay;
        for (i, cell) in self.lut.iter_mut().enumerate() {
            let d = i as f64 / LUT_STEPS_PER_PX - reach;
            let water = if d < 0.0 {
                mix([40, 125, 165], [125, 210, 235], -d / fade)
            } else {
                mix([25, 85, 105], [6, 28, 38], d / fade)
            };
            // Shafts come down from the surface: strongest looking up, lost
            // in the haze towards the horizon, none below it.
            let t = ((-d / fade - 0.2) / 0.8).clamp(0.0, 1.0);
            let strength = 0.65 * t * t * (3.0 - 2.0 * t);
            let levels = std::array::from_fn(|l| {
                let t = strength * l as f64 / (SHAFT_LEVELS - 1) as f64;
                dim(
                    [0, 1, 2].map(|c| water[c] + (f64::from(SHAFT_LIGHT[c]) - water[c]) * t),
                    light,
                )
            });
            let k = (d / rung).round();
            let off = (d - k * rung).abs();
            let (kind, line) = if !lines {
                (Line::None, BLACK)
            } else if d.abs() < scale {
                (Line::Horizon, dim(rgbf(WHITE), light.max(0.55)))
            } else if k != 0.0 && k.abs() <= 9.0 && off < 0.6 * scale {
                let kind = if (k as i64) % 2 == 0 {
                    Line::LongRung
                } else {
                    Line::ShortRung
                };
                (kind, dim([200.0, 225.0, 235.0], light.max(0.45)))
            } else {
                (Line::None, BLACK)
            };
            *cell = Cell {
                water: levels,
                line,
                kind,
            };
        }
    }

    /// The light-shaft level along the horizon: each shaft sits at a fixed
    /// bearing, so turning the vehicle sweeps them across the picture.
    fn fill_shafts(&mut self, s: &Sanitized, reach: f64, ppd: f64) {
        let n = (2.0 * reach * LUT_STEPS_PER_PX) as usize + 2;
        self.shafts.resize(n, 0);
        for (j, level) in self.shafts.iter_mut().enumerate() {
            let a = j as f64 / LUT_STEPS_PER_PX - reach;
            let bearing = s.heading_deg + a / ppd;
            let mut v: f64 = 0.0;
            for k in 0..SHAFTS {
                let (centre, half_width, peak) = shaft(k);
                let off = (bearing - centre + 180.0).rem_euclid(360.0) - 180.0;
                // A soft edge: full in the middle, none beyond the half width.
                let x = (off.abs() / half_width).min(1.0);
                v = v.max(peak * (1.0 - x * x));
            }
            *level = (v * (SHAFT_LEVELS - 1) as f64).round() as u8;
        }
    }
}

/// The colour a light shaft tends to.
const SHAFT_LIGHT: Rgb = [225, 245, 250];

/// Shaft `k`'s bearing (deg), half width (deg) and peak brightness (0..1):
/// spread around the compass with a fixed irregularity, the same every run.
fn shaft(k: usize) -> (f64, f64, f64) {
    // A small integer hash: deterministic, looks irregular.
    let h = (k as u32).wrapping_mul(0x9E37_79B9).rotate_left(13) ^ 0x5bd1_e995;
    let u = |shift: u32| f64::from((h >> shift) & 0xff) / 255.0;
    let spacing = 360.0 / SHAFTS as f64;
    (
        k as f64 * spacing + (u(0) - 0.5) * spacing * 0.6,
        1.5 + 3.0 * u(8),
        0.55 + 0.45 * u(16),
    )
}

/// Scene values safe to draw: non-finite become 0, angles are wrapped.
struct Sanitized {
    depth_m: f64,
    heading_deg: f64,
    roll_deg: f64,
    pitch_deg: f64,
    tilt_deg: f64,
    simulated: bool,
    armed: bool,
}

impl From<&Scene> for Sanitized {
    fn from(s: &Scene) -> Self {
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        let angle = |v: f64| {
            let v = finite(v).rem_euclid(360.0);
            if v > 180.0 { v - 360.0 } else { v }
        };
        Sanitized {
            depth_m: finite(s.depth_m).clamp(-1e4, 1e4),
            heading_deg: finite(s.heading_deg).rem_euclid(360.0),
            roll_deg: angle(s.roll_deg),
            pitch_deg: angle(s.pitch_deg).clamp(-90.0, 90.0),
            tilt_deg: angle(s.tilt_deg).clamp(-90.0, 90.0),
            simulated: s.simulated,
            armed: s.armed,
        }
    }
}

fn mix(a: Rgb, b: Rgb, t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    [0, 1, 2].map(|i| f64::from(a[i]) * (1.0 - t) + f64::from(b[i]) * t)
}

fn rgbf(c: Rgb) -> [f64; 3] {
    c.map(f64::from)
}

fn dim(c: [f64; 3], light: f64) -> Rgb {
    c.map(|v| (v * light).round().clamp(0.0, 255.0) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn luma(r: &SyntheticRenderer, x: usize, y: usize) -> f64 {
        let i = (y * r.width + x) * 3;
        let p = &r.rgb[i..i + 3];
        0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2])
    }

    #[test]
    fn same_scene_same_pixels() {
        let mut r = SyntheticRenderer::new(160, 120, 80);
        let scene = Scene {
            heading_deg: 42.0,
            roll_deg: 5.0,
            ..Scene::default()
        };
        let a = r.render(&scene).to_vec();
        let b = r.render(&scene).to_vec();
        assert_eq!(a, b);
        assert_eq!(a.len(), 160 * 120 * 3);
    }

    #[test]
    fn roll_tilts_the_horizon_with_the_right_side_up() {
        let mut r = SyntheticRenderer::new(320, 240, 80);
        let (left, right, mid) = (60, 260, 120);
        r.render(&Scene::default());
        let level = luma(&r, left, mid - 10) - luma(&r, right, mid - 10);
        assert!(level.abs() < 2.0, "{level}");
        // Rolled to starboard: the horizon's right end rises, so just
        // above the middle the right side is already below the horizon (darker).
        r.render(&Scene {
            roll_deg: 20.0,
            ..Scene::default()
        });
        let rolled = luma(&r, left, mid - 10) - luma(&r, right, mid - 10);
        assert!(rolled > 20.0, "{rolled}");
    }

    #[test]
    fn pitch_and_tilt_move_the_horizon_down_and_depth_darkens() {
        let mut r = SyntheticRenderer::new(320, 240, 80);
        let (x, y) = (60, 130);
        let below = {
            r.render(&Scene::default());
            luma(&r, x, y)
        };
        for up in [
            Scene {
                pitch_deg: 10.0,
                ..Scene::default()
            },
            Scene {
                tilt_deg: 10.0,
                ..Scene::default()
            },
        ] {
            r.render(&up);
            assert!(
                luma(&r, x, y) > below + 20.0,
                "{} vs {below}",
                luma(&r, x, y)
            );
        }
        r.render(&Scene {
            depth_m: 40.0,
            ..Scene::default()
        });
        assert!(luma(&r, x, y) < below * 0.5);
    }

    /// Bytes of the top `rows` rows that differ by more than 40.
    fn changed(a: &[u8], b: &[u8], width: usize, rows: usize) -> usize {
        let n = width * rows * 3;
        a[..n]
            .iter()
            .zip(&b[..n])
            .filter(|(x, y)| x.abs_diff(**y) > 40)
            .count()
    }

    #[test]
    fn turning_sweeps_the_light_shafts_across_the_picture() {
        let mut r = SyntheticRenderer::new(320, 240, 80);
        let north = r.render(&Scene::default()).to_vec();
        let east = r
            .render(&Scene {
                heading_deg: 90.0,
                ..Scene::default()
            })
            .to_vec();
        // High above the horizon the shafts moved; below it nothing did.
        assert!(changed(&north, &east, 320, 40) > 300);
        let below = 150 * 320 * 3;
        assert_eq!(north[below..], east[below..]);
        // A full turn comes back to the same picture.
        let round = r
            .render(&Scene {
                heading_deg: 360.0,
                ..Scene::default()
            })
            .to_vec();
        assert_eq!(north, round);
    }

    #[test]
    fn the_instruments_are_drawn_only_with_the_overlay() {
        let mut plain = SyntheticRenderer::new(320, 240, 80);
        let mut hud = SyntheticRenderer::new(320, 240, 80).with_overlay(true);
        let scene = Scene {
            armed: true,
            simulated: true,
            ..Scene::default()
        };
        let without = plain.render(&scene).to_vec();
        let with = hud.render(&scene).to_vec();
        // The heading tape (top 22 rows) is there only with the overlay.
        assert!(changed(&without, &with, 320, 22) > 1000);
        // Without it, the armed and simulated markers change nothing.
        assert_eq!(without, plain.render(&Scene::default()));
        // With it, the tape moves with the heading and the markers show.
        let turned = hud
            .render(&Scene {
                heading_deg: 37.0,
                ..scene.clone()
            })
            .to_vec();
        assert!(changed(&with, &turned, 320, 22) > 300);
        assert_ne!(with, hud.render(&Scene::default()));
        // The horizon line: a bright row across the level horizon.
        let row = 120 * 320 * 3;
        let line = |px: &[u8]| {
            px[row..row + 320 * 3]
                .iter()
                .map(|v| u32::from(*v))
                .sum::<u32>()
        };
        assert!(line(&with) > line(&without) + 320 * 3 * 40);
    }

    #[test]
    fn wild_values_do_not_panic_and_encode() {
        let mut r = SyntheticRenderer::new(16, 16, 1).with_overlay(true);
        for v in [f64::NAN, f64::INFINITY, -1e300, 1e300, -720.0] {
            let scene = Scene {
                depth_m: v,
                heading_deg: v,
                roll_deg: v,
                pitch_deg: v,
                tilt_deg: v,
                simulated: true,
                armed: true,
            };
            let jpeg = r.render_jpeg(&scene).expect("encodes");
            assert_eq!(&jpeg[..2], &[0xFF, 0xD8]);
        }
    }
}
