//! The synthetic camera picture: drawn from a [`Scene`] and encoded as JPEG.
//!
//! Pure and deterministic (same scene, same bytes), so tests compare pixels
//! and the bench times it. What it shows, for an operator to tell that the
//! simulated vehicle moves:
//! - the horizon, tilted by roll and moved by pitch plus camera tilt
//!   (nose or camera up moves it down), with a pitch ladder every 10°;
//! - water that darkens with depth, lighter towards the surface;
//! - a heading tape with the heading readout, depth, tilt, pitch and roll
//!   readouts, the armed state and a `SIM` marker when simulated.

use bytes::Bytes;
use jpeg_encoder::{ColorType, Encoder};

use super::font::{self, ADVANCE, GLYPH_H, GLYPH_W};
use super::frame::Scene;

/// Vertical field of view (a 4:3 webcam like the OpenROV's).
const VFOV_DEG: f64 = 45.0;
/// Degrees of heading across the whole tape.
const TAPE_SPAN_DEG: f64 = 90.0;
/// Sub-pixel resolution of the background table.
const LUT_STEPS_PER_PX: f64 = 2.0;

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
    rgb: Vec<u8>,
    lut: Vec<Cell>,
    last_jpeg_len: usize,
}

/// One entry of the background table, by signed distance to the horizon.
#[derive(Debug, Clone, Copy, Default)]
struct Cell {
    water: Rgb,
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
    pub fn new(width: u32, height: u32, quality: u8) -> Self {
        let width = width.clamp(1, u32::from(u16::MAX)) as usize;
        let height = height.clamp(1, u32::from(u16::MAX)) as usize;
        SyntheticRenderer {
            width,
            height,
            quality: quality.clamp(1, 100),
            rgb: vec![0; width * height * 3],
            lut: Vec::new(),
            last_jpeg_len: 0,
        }
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
        self.overlays(&s);
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

    /// Water, horizon and pitch ladder. Every pixel's colour depends only on
    /// its signed distance to the horizon (and, for ladder rungs, on how far
    /// along the horizon it is), so the colours come from a table indexed by
    /// that distance, which changes by a constant step along a row.
    fn background(&mut self, s: &Sanitized) {
        let (w, h) = (self.width, self.height);
        let ppd = self.px_per_deg();
        let scale = self.scale() as f64;
        let reach = (w + h) as f64;
        self.fill_lut(s, reach, ppd, scale);
        let lut_last = self.lut.len() - 1;

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
                let cell = &self.lut[i];
                let colour = match cell.kind {
                    Line::None => &cell.water,
                    Line::Horizon => &cell.line,
                    Line::LongRung if a.abs() <= long_rung => &cell.line,
                    Line::ShortRung if a.abs() <= short_rung => &cell.line,
                    Line::LongRung | Line::ShortRung => &cell.water,
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
        for (i, cell) in self.lut.iter_mut().enumerate() {
            let d = i as f64 / LUT_STEPS_PER_PX - reach;
            let water = if d < 0.0 {
                mix([40, 125, 165], [125, 210, 235], -d / fade)
            } else {
                mix([25, 85, 105], [6, 28, 38], d / fade)
            };
            let k = (d / rung).round();
            let off = (d - k * rung).abs();
            let (kind, line) = if d.abs() < scale {
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
                water: dim(water, light),
                line,
                kind,
            };
        }
    }

    fn overlays(&mut self, s: &Sanitized) {
        let (w, h) = (self.width as i64, self.height as i64);
        let sc = self.scale();
        let sci = sc as i64;
        let mut c = Canvas {
            px: &mut self.rgb,
            w: self.width,
            h: self.height,
        };
        let cx = w / 2;
        let cy = h / 2;

        // Fixed reticle: where the camera points.
        for x in [cx - 30 * sci, cx + 10 * sci] {
            c.fill(x, cy - sci / 2, 20 * sci, sci, YELLOW);
        }
        c.fill(cx - sci, cy - sci, 2 * sci, 2 * sci, YELLOW);

        // Heading tape along the top.
        let tape_h = 22 * sci;
        c.shade(0, 0, w, tape_h, 0.4);
        let ppd = w as f64 / TAPE_SPAN_DEG;
        let first = ((s.heading_deg - TAPE_SPAN_DEG / 2.0) / 5.0).ceil() as i64 * 5;
        let last = ((s.heading_deg + TAPE_SPAN_DEG / 2.0) / 5.0).floor() as i64 * 5;
        for deg in (first..=last).step_by(5) {
            let x = cx + ((deg as f64 - s.heading_deg) * ppd).round() as i64;
            let len = if deg % 10 == 0 { 6 * sci } else { 3 * sci };
            c.fill(x - sci / 2, tape_h - len, sci, len, WHITE);
            if deg.rem_euclid(30) == 0 {
                let label = match deg.rem_euclid(360) {
                    0 => "N".to_owned(),
                    90 => "E".to_owned(),
                    180 => "S".to_owned(),
                    270 => "W".to_owned(),
                    other => format!("{other:03}"),
                };
                let tw = font::text_width(&label, sc) as i64;
                c.text(x - tw / 2, 3 * sci, sc, &label, WHITE);
            }
        }
        c.fill(cx - sci / 2, 0, sci.max(2), tape_h + 3 * sci, YELLOW);
        let hdg = format!("{:03}°", (s.heading_deg.round() as i64).rem_euclid(360));
        let tw = font::text_width(&hdg, sc) as i64;
        c.shade(
            cx - tw / 2 - 3 * sci,
            tape_h + 3 * sci,
            tw + 6 * sci,
            11 * sci,
            0.4,
        );
        c.text(cx - tw / 2, tape_h + 5 * sci, sc, &hdg, YELLOW);

        // Markers under the tape.
        if s.simulated {
            let tw = font::text_width("SIM", sc) as i64;
            c.fill(4 * sci, tape_h + 4 * sci, tw + 6 * sci, 11 * sci, RED);
            c.text(7 * sci, tape_h + 6 * sci, sc, "SIM", WHITE);
        }
        let (armed, colour) = if s.armed {
            ("ARMED", RED)
        } else {
            ("DISARMED", GREEN)
        };
        let tw = font::text_width(armed, sc) as i64;
        c.shade(
            w - tw - 10 * sci,
            tape_h + 4 * sci,
            tw + 6 * sci,
            11 * sci,
            0.4,
        );
        c.text(w - tw - 7 * sci, tape_h + 6 * sci, sc, armed, colour);

        // Readouts along the bottom.
        let line = (GLYPH_H as i64 + 4) * sci;
        let depth = format!("DEPTH {:.1} M", s.depth_m);
        let attitude = format!("PITCH {:+.0}° ROLL {:+.0}°", s.pitch_deg, s.roll_deg);
        let tilt = format!("TILT {:+.0}°", s.tilt_deg);
        let tw = font::text_width(&depth, sc) as i64;
        c.shade(
            0,
            h - 2 * line - 2 * sci,
            tw + 8 * sci,
            2 * line + 2 * sci,
            0.4,
        );
        c.text(4 * sci, h - 2 * line, sc, &depth, WHITE);
        c.text(4 * sci, h - line, sc, &tilt, WHITE);
        let tw = font::text_width(&attitude, sc) as i64;
        c.shade(
            w - tw - 8 * sci,
            h - line - 2 * sci,
            tw + 8 * sci,
            line + 2 * sci,
            0.4,
        );
        c.text(w - tw - 4 * sci, h - line, sc, &attitude, WHITE);
    }
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

/// Pixel drawing with clipping: shapes partly or wholly off the picture
/// draw what is on it.
struct Canvas<'a> {
    px: &'a mut [u8],
    w: usize,
    h: usize,
}

impl Canvas<'_> {
    /// Clipped pixel rows and columns of a rectangle.
    fn clip(&self, x: i64, y: i64, w: i64, h: i64) -> Option<(usize, usize, usize, usize)> {
        let x0 = x.clamp(0, self.w as i64) as usize;
        let y0 = y.clamp(0, self.h as i64) as usize;
        let x1 = x.saturating_add(w).clamp(0, self.w as i64) as usize;
        let y1 = y.saturating_add(h).clamp(0, self.h as i64) as usize;
        (x0 < x1 && y0 < y1).then_some((x0, y0, x1, y1))
    }

    fn fill(&mut self, x: i64, y: i64, w: i64, h: i64, c: Rgb) {
        let Some((x0, y0, x1, y1)) = self.clip(x, y, w, h) else {
            return;
        };
        for yy in y0..y1 {
            let row = &mut self.px[(yy * self.w + x0) * 3..(yy * self.w + x1) * 3];
            for px in row.chunks_exact_mut(3) {
                px.copy_from_slice(&c);
            }
        }
    }

    /// Darkens a rectangle so text on it reads over any background.
    fn shade(&mut self, x: i64, y: i64, w: i64, h: i64, keep: f64) {
        let Some((x0, y0, x1, y1)) = self.clip(x, y, w, h) else {
            return;
        };
        let keep = (keep.clamp(0.0, 1.0) * 256.0) as u16;
        for yy in y0..y1 {
            let row = &mut self.px[(yy * self.w + x0) * 3..(yy * self.w + x1) * 3];
            for v in row {
                *v = ((u16::from(*v) * keep) >> 8) as u8;
            }
        }
    }

    /// Text with a one-pixel dark shadow.
    fn text(&mut self, x: i64, y: i64, scale: usize, text: &str, c: Rgb) {
        let s = scale as i64;
        for (colour, off) in [(BLACK, s), (c, 0)] {
            let mut gx = x + off;
            for ch in text.chars() {
                let rows = font::glyph(ch);
                for (ry, bits) in rows.iter().enumerate() {
                    for rx in 0..GLYPH_W {
                        if bits & (1 << (GLYPH_W - 1 - rx)) != 0 {
                            self.fill(gx + rx as i64 * s, y + off + ry as i64 * s, s, s, colour);
                        }
                    }
                }
                gx += (ADVANCE * scale) as i64;
            }
        }
    }
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

    #[test]
    fn heading_moves_the_tape_and_markers_show() {
        let mut r = SyntheticRenderer::new(320, 240, 80);
        let a = r.render(&Scene::default()).to_vec();
        let b = r
            .render(&Scene {
                heading_deg: 37.0,
                ..Scene::default()
            })
            .to_vec();
        let tape = 320 * 22 * 3;
        assert_ne!(a[..tape], b[..tape]);
        let c = r
            .render(&Scene {
                simulated: true,
                armed: true,
                ..Scene::default()
            })
            .to_vec();
        assert_ne!(a, c);
    }

    #[test]
    fn wild_values_do_not_panic_and_encode() {
        let mut r = SyntheticRenderer::new(16, 16, 1);
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
