//! Thrust allocation: a normalised demand `[X, Z, M]` to the pulse width
//! each ESC should get, and those to the board's `go(port, vertical,
//! starboard)` values.
//!
//! This module owns the thesis allocation (section 9.3) with the pilot gain,
//! the per-motor directions and the MOT_PWM_MIN/MAX range, and the board
//! firmware's motor mapping ([`BoardMotors`]): the genuine OpenROV firmware
//! does not pass `go()` values to the ESCs unchanged (`Motor.cpp`) — it
//! skips the ESC deadzone and multiplies reverse commands — so the vehicle
//! asks for the `go()` value that gives the ESC pulse it wants. It must
//! never do I/O or keep state, and no input — NaN, infinity, a
//! misconfigured range — may produce a pulse width outside
//! `pwm_min_us..=pwm_max_us`.
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
//! `u = −1 → pwm_min_us`, `0 → 1500`, `+1 → pwm_max_us`, linear on each side
//! beyond the ESC deadzone (`deadzone_us`, where an ESC gives no thrust):
//! the smallest thrust is `1500 ± deadzone_us`, as the board's firmware
//! maps it. An asymmetric range (1100..1500..1950) still stops the thruster
//! at 1500.

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
    /// The ESC deadzone each side of 1500 µs: no thrust inside it.
    pub deadzone_us: u16,
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

/// The mixer inverted: the demand three ESC pulse widths really produce
/// (after direction, before the gain), with a thruster within the deadzone
/// of neutral giving nothing. The estimator's model input.
pub fn unmix(us: [u16; 3], cfg: &MixerConfig) -> Demand {
    let (lo, neutral, hi) = cfg.range();
    let dz = f64::from(cfg.deadzone_us);
    let u = |i: usize| {
        let d = f64::from(us[i]) - neutral;
        if d.abs() <= dz {
            return 0.0;
        }
        let span = if d > 0.0 { hi - neutral } else { neutral - lo } - dz;
        let v = if span > 0.0 {
            d.signum() * (d.abs() - dz) / span
        } else {
            d.signum()
        };
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

/// `u` (already in `[-1, 1]`) with its direction to a pulse width: neutral
/// at 0, and beyond the deadzone on each side linearly to the range's end.
fn to_us(u: f64, direction: i8, cfg: &MixerConfig) -> u16 {
    let (lo, neutral, hi) = cfg.range();
    let dz = f64::from(cfg.deadzone_us);
    let v = u * f64::from(direction.signum());
    let us = if v == 0.0 {
        neutral
    } else if v > 0.0 {
        let start = (neutral + dz).min(hi);
        start + v * (hi - start)
    } else {
        let start = (neutral - dz).max(lo);
        start + v * (start - lo)
    };
    // Clamped to a u16 range before the cast, so the cast cannot wrap.
    us.round().clamp(lo, hi) as u16
}

/// The board firmware's motor mapping (OpenROV `Motor.cpp`, 2015): what
/// ESC pulse a `go()` value gives, and the `go()` value for an ESC pulse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardMotors {
    /// The deadzone the firmware skips each side of 1500 µs.
    pub deadzone_us: u16,
    /// The factor on how far below 1500 µs a value lies (a whole number:
    /// the firmware keeps it in an `int`).
    pub reverse_multiplier: u8,
}

impl Default for BoardMotors {
    fn default() -> Self {
        Self {
            deadzone_us: 50,
            reverse_multiplier: 2,
        }
    }
}

/// Arduino's `map()`: integer arithmetic, the division truncating toward zero.
fn arduino_map(x: i32, in_min: i32, in_max: i32, out_min: i32, out_max: i32) -> i32 {
    (x - in_min) * (out_max - out_min) / (in_max - in_min) + out_min
}

impl BoardMotors {
    /// The ESC pulse the firmware writes for `go` (1000..=2000): reverse
    /// values multiplied, then each side mapped past the deadzone.
    pub fn esc_us(&self, go: u16) -> u16 {
        let n = i32::from(NEUTRAL_US);
        let go = i32::from(go.clamp(1000, 2000));
        let dz = i32::from(self.deadzone_us.min(499));
        let factor = if go < n {
            i32::from(self.reverse_multiplier.max(1))
        } else {
            1
        };
        let pre = (n + (go - n) * factor).clamp(1000, 2000);
        let esc = match pre.cmp(&n) {
            std::cmp::Ordering::Less => arduino_map(pre, 1000, n, 1000, n - dz),
            std::cmp::Ordering::Greater => arduino_map(pre, n, 2000, n + dz, 2000),
            std::cmp::Ordering::Equal => n,
        };
        esc.clamp(1000, 2000) as u16
    }

    /// The `go()` value whose ESC pulse is nearest `esc_us`; 1500 for a
    /// pulse inside the deadzone (an ESC gives no thrust there).
    pub fn go_for(&self, esc_us: u16) -> u16 {
        let dz = self.deadzone_us;
        if esc_us.abs_diff(NEUTRAL_US) < dz || esc_us == NEUTRAL_US {
            return NEUTRAL_US;
        }
        // `esc_us` is monotonic in `go`: search the side the pulse is on.
        let (mut lo, mut hi) = if esc_us > NEUTRAL_US {
            (NEUTRAL_US + 1, 2000)
        } else {
            (1000, NEUTRAL_US - 1)
        };
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self.esc_us(mid) < esc_us {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        // `lo` is the first go() reaching the pulse; its neighbour below may be nearer.
        let below = lo.saturating_sub(1).max(1000);
        let side = |g: u16| (g > NEUTRAL_US) == (esc_us > NEUTRAL_US) && g != NEUTRAL_US;
        if side(below) && self.esc_us(below).abs_diff(esc_us) < self.esc_us(lo).abs_diff(esc_us) {
            below
        } else {
            lo
        }
    }

    /// [`BoardMotors::go_for`] of each thruster.
    pub fn go_values(&self, esc_us: [u16; 3]) -> [u16; 3] {
        esc_us.map(|e| self.go_for(e))
    }
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
            deadzone_us: 0,
        }
    }

    #[test]
    fn the_firmwares_mapping_and_its_inverse() {
        let b = BoardMotors::default();
        // Measured on the genuine 30.0.2 in simavr: go(1600) → 1640 µs, go(1400) → 1270 µs.
        assert_eq!(b.esc_us(1600), 1640);
        assert_eq!(b.esc_us(1400), 1270);
        assert_eq!(b.esc_us(1500), 1500);
        assert_eq!(b.esc_us(1501), 1550, "the deadzone is skipped");
        assert_eq!(
            b.esc_us(1250),
            1000,
            "reverse saturates at half the go() range"
        );
        assert_eq!(b.esc_us(1000), 1000);
        assert_eq!(b.esc_us(2000), 2000);
        for esc in (1000..=2000).step_by(7) {
            let go = b.go_for(esc);
            if esc.abs_diff(1500) < 50 {
                assert_eq!(go, 1500, "{esc}");
            } else {
                assert!(
                    b.esc_us(go).abs_diff(esc) <= 2,
                    "{esc} → go {go} → {}",
                    b.esc_us(go)
                );
            }
        }
        assert_eq!(b.go_for(1900), 1889);
        assert_eq!(b.go_for(1100), 1306);
    }

    #[test]
    fn the_deadzone_is_skipped_both_ways() {
        let c = MixerConfig {
            deadzone_us: 50,
            ..cfg()
        };
        assert_eq!(thruster_us(0.0, 1, &c), 1500);
        assert_eq!(thruster_us(0.001, 1, &c), 1550);
        assert_eq!(thruster_us(-0.001, 1, &c), 1450);
        assert_eq!(thruster_us(1.0, 1, &c), 1900);
        assert_eq!(thruster_us(-1.0, 1, &c), 1100);
        assert_eq!(thruster_us(0.5, 1, &c), 1725);
        let d = unmix([1725, 1500, 1275], &c);
        assert!(
            (d.surge - 0.0).abs() < 1e-9 && (d.yaw - 0.5).abs() < 1e-9,
            "{d:?}"
        );
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
