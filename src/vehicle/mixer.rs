//! Thrust allocation: a normalised demand `[X, Z, M]` to the board's
//! `go(port, vertical, starboard)` values.
//!
//! This module owns the thesis allocation (section 9.3) with the pilot gain,
//! the per-motor directions and the MOT_PWM_MIN/MAX range, and the board
//! firmware's motor mapping ([`BoardMotors`]). The genuine OpenROV firmware
//! does not pass `go()` values to the ESCs unchanged (`Motor.cpp`): it
//! skips the ESC deadzone and doubles reverse commands, because the
//! propellers push about half as hard backwards. That mapping is the
//! thrusters' calibration, so `go()` values are linear in thrust — which is
//! what this module sends, as OpenROV's own cockpit did: the reversed port
//! thruster then pushes as hard as the starboard one at half stick. Reverse
//! saturates at `1500 − 500 / multiplier` (1250 µs with the firmware's 2);
//! [`BoardMotors::effective`] says what a value really gives. It must never
//! do I/O or keep state, and no input — NaN, infinity, a misconfigured
//! range — may produce a value outside `pwm_min_us..=pwm_max_us`.
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
//! `u = −1 → pwm_min_us`, `0 → 1500`, `+1 → pwm_max_us`, linear on each
//! side. An asymmetric range (1100..1500..1950) still stops the thruster at
//! 1500.

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

/// The mixer inverted: the demand three `go()` values produce (after
/// direction, before the gain). With [`BoardMotors::effective`] first, the
/// demand the thrusters really give: the estimator's model input.
pub fn unmix(us: [u16; 3], cfg: &MixerConfig) -> Demand {
    let (lo, neutral, hi) = cfg.range();
    let u = |i: usize| {
        let d = f64::from(us[i]) - neutral;
        let span = if d > 0.0 { hi - neutral } else { neutral - lo };
        let v = if span > 0.0 { d / span } else { d.signum() };
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
/// at 0, linear on each side to the range's end.
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

    /// The lowest `go()` value that still adds reverse thrust: below it
    /// the multiplied value is past the ESC's end (1250 with the
    /// firmware's 2).
    pub fn reverse_limit(&self) -> u16 {
        NEUTRAL_US - 500 / u16::from(self.reverse_multiplier.max(1))
    }

    /// The `go()` values as the thrusters feel them: a reverse value past
    /// [`BoardMotors::reverse_limit`] gives no more than the limit.
    pub fn effective(&self, go: [u16; 3]) -> [u16; 3] {
        let limit = self.reverse_limit();
        go.map(|g| g.max(limit))
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
        }
    }

    #[test]
    fn the_firmwares_mapping_and_where_reverse_ends() {
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
        assert_eq!(b.reverse_limit(), 1250);
        assert_eq!(b.esc_us(b.reverse_limit()), 1000);
        assert_eq!(b.effective([1100, 1300, 1700]), [1250, 1300, 1700]);
        let thesis = BoardMotors {
            deadzone_us: 0,
            reverse_multiplier: 1,
        };
        assert_eq!(thesis.esc_us(1400), 1400);
        assert_eq!(thesis.effective([1000, 1500, 2000]), [1000, 1500, 2000]);
    }

    #[test]
    fn half_stick_either_way_is_the_same_thrust_through_the_firmware() {
        // The propellers push about half as hard backwards; the firmware's
        // doubling makes up for it, so go() values stay linear in thrust.
        let b = BoardMotors::default();
        let fwd = f64::from(b.esc_us(thruster_us(0.5, 1, &cfg())) - 1500);
        let rev = f64::from(1500 - b.esc_us(thruster_us(-0.5, 1, &cfg())));
        assert!(
            (rev * 0.5 - fwd).abs() / fwd < 0.15,
            "forward {fwd} µs, reverse {rev} µs"
        );
        let d = unmix([1300, 1500, 1700], &cfg());
        assert!(
            (d.surge - 0.0).abs() < 1e-9 && (d.yaw + 0.5).abs() < 1e-9,
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
