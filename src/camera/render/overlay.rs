//! The synthetic camera's own instruments, drawn into the picture only
//! with `[camera] synthetic_overlay = true` (the browser's HUD draws them
//! over any camera): a fixed reticle, a heading tape with the heading
//! readout, depth, tilt, pitch and roll readouts, the armed state and a
//! `SIM` marker. The horizon line and pitch ladder come with the
//! background's table (`mod.rs`).

use super::{BLACK, GREEN, RED, Rgb, Sanitized, TAPE_SPAN_DEG, WHITE, YELLOW};
use crate::camera::font::{self, ADVANCE, GLYPH_H, GLYPH_W};

/// Pixel drawing with clipping: shapes partly or wholly off the picture
/// draw what is on it.
pub(super) struct Canvas<'a> {
    px: &'a mut [u8],
    w: usize,
    h: usize,
}

impl<'a> Canvas<'a> {
    /// `px`: `w`×`h` RGB pixels, row by row.
    pub fn new(px: &'a mut [u8], w: usize, h: usize) -> Self {
        Self { px, w, h }
    }

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

    /// The heading tape, the reticle, the markers and the readouts.
    pub fn instruments(&mut self, s: &Sanitized) {
        let (w, h) = (self.w as i64, self.h as i64);
        let sc = (self.h / 240).max(1);
        let sci = sc as i64;
        let c = self;
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
