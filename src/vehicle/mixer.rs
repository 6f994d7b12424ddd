//! Thrust allocation: a normalised demand `[X, Z, M]` to the three pulse
//! widths of the board's `go(port, vertical, starboard)` command.
//!
//! This module owns the thesis allocation (section 9.3) with the pilot gain,
//! the per-motor directions and the MOT_PWM_MIN/MAX range. It must never do
//! I/O or keep state, and no input — NaN, infinity, a misconfigured range —
//! may produce a pulse width outside `pwm_min_us..=pwm_max_us`.
//!
//! # Signs
//! - surge X > 0: forward; heave Z > 0: **down** (body z axis, deeper);
//!   yaw M > 0: turn to starboard (heading increases).
//! - `u_port = sat(k(X+M))`, `u_vertical = sat(kZ)`, `u_starboard = sat(k(X−M))`:
//!   positive yaw drives the port thruster harder, which turns the bow to
//!   starboard. ArduSub's SIMPLEROV_3 factors say the same with its own sign
//!   convention (its throttle is "up", hence its −1 on the vertical motor).
//! - Each thruster's output is multiplied by its direction (MOT_n_DIRECTION:
//!   motor 1 starboard, 2 port, 3 vertical); on Neptunus the port thruster is
//!   wired reversed, so MOT_2_DIRECTION defaults to −1.
//!
//! # Pulse widths
//! `u = −1 → pwm_min_us`, `0 → 1500`, `+1 → pwm_max_us`, linear on each side,
//! so an asymmetric range (1100..1500..1950) still stops the thruster at 1500.

use serde::Serialize;

/// Pulse width that stops a thruster (µs).
pub const NEUTRAL_US: u16 = 1500;

/// Normalised demand τ in `[-1, 1]³`, before the pilot gain.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Demand {
    /// X: positive = forward.
    pub surge: f64,
    /// Z: positive = down (body z axis), i.e. deeper.
    pub heave: f64,
    /// M: positive = turn to starboard (heading increases).
    pub yaw: f64,
}

/// Everything the allocation needs besides the demand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MixerConfig {
    /// Pilot gain k in `[0, 1]` (values outside are clamped, NaN counts as 0).
    pub gain: f64,
    /// `[port, vertical, starboard]` = `[MOT_2, MOT_3, MOT_1]_DIRECTION`;
    /// only the sign counts (0 disables that thruster).
    pub directions: [i8; 3],
    /// Pulse width for full reverse thrust.
    pub pwm_min_us: u16,
    /// Pulse width for full forward thrust.
    pub pwm_max_us: u16,
}

impl MixerConfig {
    /// The gain actually applied: clamped to `[0, 1]`, NaN → 0.
    fn gain(&self) -> f64 {
        clean(self.gain).max(0.0)
    }

    /// The PWM range ordered, and the neutral inside it. Parameter
    /// validation keeps min < 1500 < max; this keeps a hand-built config
    /// that breaks the rule from producing a pulse outside its own range.
    fn range(&self) -> (f64, f64, f64) {
        let lo = self.pwm_min_us.min(self.pwm_max_us);
        let hi = self.pwm_min_us.max(self.pwm_max_us);
        (
            f64::from(lo),
            f64::from(NEUTRAL_US.clamp(lo, hi)),
            f64::from(hi),
        )
    }
}

/// A finite number clamped to `[-1, 1]`; NaN and ±∞ count as 0 so a bad
/// number never commands thrust.
fn clean(x: f64) -> f64 {
    if x.is_finite() {
        x.clamp(-1.0, 1.0)
    } else {
        0.0
    }
}

/// The thesis allocation: `[port, vertical, starboard]` pulse widths for `go()`.
pub fn mix(d: &Demand, cfg: &MixerConfig) -> [u16; 3] {
    let k = cfg.gain();
    let (x, z, m) = (clean(d.surge), clean(d.heave), clean(d.yaw));
    let u = [clean(k * (x + m)), clean(k * z), clean(k * (x - m))];
    let mut out = [NEUTRAL_US; 3];
    for ((o, u), dir) in out.iter_mut().zip(u).zip(cfg.directions) {
        *o = to_us(u, dir, cfg);
    }
    out
}

/// The mixer inverted: the demand three pulse widths really produce (after
/// direction, before the gain), with a thruster within `deadzone_us` of
/// neutral (the board's ESC deadzone) giving nothing. The estimator's
/// model input.
pub fn unmix(us: [u16; 3], cfg: &MixerConfig, deadzone_us: f64) -> Demand {
    let (lo, neutral, hi) = cfg.range();
    let u = |i: usize| {
        let d = f64::from(us[i]) - neutral;
        if d.abs() <= deadzone_us {
            return 0.0;
        }
        let span = if d > 0.0 { hi - neutral } else { neutral - lo };
        let v = if span > 0.0 { d / span } else { 0.0 };
        v.clamp(-1.0, 1.0) * f64::from(cfg.directions[i].signum())
    };
    let (port, vertical, starboard) = (u(0), u(1), u(2));
    Demand {
        surge: (port + starboard) / 2.0,
        heave: vertical,
        yaw: (port - starboard) / 2.0,
    }
}

/// One thruster driven directly: `u ∈ [-1, 1]` times the gain, then the
/// same direction and range rules as [`mix`].
pub fn thruster_us(u: f64, direction: i8, cfg: &MixerConfig) -> u16 {
    to_us(clean(cfg.gain() * clean(u)), direction, cfg)
}

/// `u` (already in `[-1, 1]`) with its direction to a pulse width.
fn to_us(u: f64, direction: i8, cfg: &MixerConfig) -> u16 {
    let (lo, neutral, hi) = cfg.range();
    let v = u * f64::from(direction.signum());
    let us = if v >= 0.0 {
        neutral + v * (hi - neutral)
    } else {
        neutral + v * (neutral - lo)
    };
    // Clamped to a u16 range before the cast, so the cast cannot wrap.
    us.round().clamp(lo, hi) as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> MixerConfig {
        MixerConfig {
            gain: 1.0,
            directions: [1, 1, 1],
            pwm_min_us: 1100,
            pwm_max_us: 1900,
        }
    }

    #[test]
    fn inverted_range_stays_inside_itself() {
        let c = MixerConfig {
            pwm_min_us: 1900,
            pwm_max_us: 1100,
            ..cfg()
        };
        for u in [-1.0, 0.0, 1.0] {
            let us = thruster_us(u, 1, &c);
            assert!((1100..=1900).contains(&us));
        }
    }

    #[test]
    fn range_not_containing_neutral_is_respected() {
        let c = MixerConfig {
            pwm_min_us: 1600,
            pwm_max_us: 1800,
            ..cfg()
        };
        assert_eq!(thruster_us(0.0, 1, &c), 1600);
        assert_eq!(thruster_us(1.0, 1, &c), 1800);
        assert_eq!(thruster_us(-1.0, 1, &c), 1600);
    }
}
