//! Thruster dynamics: how one thruster's force follows the pulse width its
//! ESC is driven with.
//!
//! This module owns the map from an ESC pulse (µs) to a normalised thrust
//! level and the first-order lag between them. It must never do I/O, read a
//! clock or draw random numbers; it never applies the board's deadzone or
//! reverse multiplier either — those are firmware (`firmware::emulator`),
//! and the plant is driven with what the firmware already wrote to the ESCs.
//!
//! # Model
//! - **Effort** `e ∈ [-1, 1]` is the ESC's command as a fraction of its
//!   range, `(pwm − 1500) / 500`, positive = the ESC's forward. It stands
//!   for motor speed, which is what lags: the propeller and motor have to
//!   spin up. `ė = (e_cmd − e) / T`, integrated exactly over a step, so the
//!   response is on the continuous curve whatever the step length.
//! - A first-order lag reaches 10 % at `T·ln(10/9)` and 90 % at `T·ln 10`,
//!   so its 10–90 % rise time is `T·ln 9 ≈ 2.197·T`; the configured rise
//!   time sets `T = rise / ln 9`.
//! - **Level** (thrust as a fraction of full forward thrust) is linear in
//!   effort, as in the thesis' allocation (`τ = f·u`), but **weaker in
//!   reverse**: `level = e` for `e ≥ 0`, `level = r·e` for `e < 0`, with
//!   `r` the reverse-thrust ratio. OpenROV 2.x propellers are pitched for
//!   forward thrust; turned backwards the same motor speed gives markedly
//!   less thrust. The OpenROV firmware's ×2 reverse multiplier exists to
//!   compensate for exactly this, so our default `r = 0.5` is the ratio the
//!   firmware authors assumed: a small reverse command, doubled by the
//!   board, gives about the thrust of the same forward command, and a
//!   reverse command past half range saturates the ESC at half thrust.
//!
//! Which way is "reverse" is the ESC's: the wiring direction (Neptunus'
//! port motor is wired reversed) is applied afterwards by the plant when it
//! turns levels into body forces. That is the firmware's assumption too (its
//! multiplier acts on the ESC value); a miswired motor whose propeller was
//! also turned round would be the other way, and no record says which
//! Neptunus has.

/// Pulse width that stops a thruster (µs): the ESC's own, kept apart from
/// the vehicle's `mixer::NEUTRAL_US` on purpose (an independent check).
const NEUTRAL_US: f64 = 1500.0;
/// Pulse width swing from neutral to full either way (µs).
const HALF_RANGE_US: f64 = 500.0;

/// ESC command as a fraction of its range: `(pwm − 1500) / 500` clamped to
/// `[-1, 1]`. The ESC cannot be driven past its end points.
pub fn esc_effort(esc_us: u16) -> f64 {
    ((f64::from(esc_us) - NEUTRAL_US) / HALF_RANGE_US).clamp(-1.0, 1.0)
}

/// `ln 9`: a first-order lag's 10–90 % rise time in time constants.
pub fn rise_time_per_time_constant() -> f64 {
    9.0_f64.ln()
}

/// One thruster: the lagged effort and the current command.
#[derive(Debug, Clone, PartialEq)]
pub struct Thruster {
    /// First-order time constant (s); 0 = no lag.
    time_constant_s: f64,
    reverse_thrust_ratio: f64,
    command: f64,
    effort: f64,
}

impl Thruster {
    /// A thruster at rest. `rise_time_s` is the 10–90 % rise time of its
    /// thrust after a step command (0 = thrust follows the command at once);
    /// `reverse_thrust_ratio` the reverse thrust per unit effort relative to
    /// forward. The caller validates both (`SimOptions::validate`); a
    /// negative or NaN rise time counts as no lag.
    pub fn new(rise_time_s: f64, reverse_thrust_ratio: f64) -> Self {
        let time_constant_s = if rise_time_s > 0.0 {
            rise_time_s / rise_time_per_time_constant()
        } else {
            0.0
        };
        Self {
            time_constant_s,
            reverse_thrust_ratio,
            command: 0.0,
            effort: 0.0,
        }
    }

    /// Sets the ESC pulse width the thruster is driven with from now on.
    pub fn command_us(&mut self, esc_us: u16) {
        self.command = esc_effort(esc_us);
    }

    /// Advances the lag by `dt_s` and returns the **mean** effort over the
    /// step. The equations of motion hold thrust constant over one step;
    /// the mean (rather than the value at either end) keeps the impulse
    /// right even when the time constant is only a few steps long.
    pub fn advance(&mut self, dt_s: f64) -> f64 {
        if self.time_constant_s <= 0.0 || dt_s <= 0.0 {
            if dt_s > 0.0 {
                self.effort = self.command;
            }
            return self.effort;
        }
        let ratio = dt_s / self.time_constant_s;
        // 1 − e^(−x) without cancellation for small x.
        let decay = -(-ratio).exp_m1();
        let gap = self.effort - self.command;
        self.effort = self.command + gap * (1.0 - decay);
        self.command + gap * decay / ratio
    }

    /// Zeroes command and effort (a scenario start).
    pub fn reset(&mut self) {
        self.command = 0.0;
        self.effort = 0.0;
    }

    /// The lagged effort, `[-1, 1]` (stands for motor speed; drives the
    /// power model).
    pub fn effort(&self) -> f64 {
        self.effort
    }

    /// The commanded effort, before the lag.
    pub fn command(&self) -> f64 {
        self.command
    }

    /// Thrust as a fraction of full forward thrust for an effort, in the
    /// ESC's direction: reverse is `reverse_thrust_ratio` times weaker.
    pub fn level(&self, effort: f64) -> f64 {
        if effort < 0.0 {
            effort * self.reverse_thrust_ratio
        } else {
            effort
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effort_is_the_esc_fraction_clamped() {
        assert_eq!(esc_effort(1500), 0.0);
        assert_eq!(esc_effort(2000), 1.0);
        assert_eq!(esc_effort(1000), -1.0);
        assert_eq!(esc_effort(1250), -0.5);
        assert_eq!(esc_effort(0), -1.0);
        assert_eq!(esc_effort(u16::MAX), 1.0);
    }

    #[test]
    fn rise_is_ln9_time_constants() {
        // 10 % at T·ln(10/9), 90 % at T·ln 10.
        let (t10, t90) = ((10.0_f64 / 9.0).ln(), 10.0_f64.ln());
        assert!((t90 - t10 - rise_time_per_time_constant()).abs() < 1e-12);
    }

    #[test]
    fn no_lag_follows_at_once() {
        let mut t = Thruster::new(0.0, 0.5);
        t.command_us(1750);
        assert_eq!(t.advance(0.01), 0.5);
        assert_eq!(t.effort(), 0.5);
        assert_eq!(t.level(-0.5), -0.25);
        assert_eq!(t.level(0.5), 0.5);
    }

    #[test]
    fn lag_is_exact_first_order_and_the_mean_is_between_the_ends() {
        let rise = 0.2;
        let mut t = Thruster::new(rise, 0.5);
        t.command_us(2000);
        let tau = rise / 9.0_f64.ln();
        let mut now = 0.0;
        for _ in 0..50 {
            let before = t.effort();
            let mean = t.advance(0.01);
            now += 0.01;
            let exact = 1.0 - (-now / tau).exp();
            assert!((t.effort() - exact).abs() < 1e-12);
            assert!(mean > before && mean < t.effort());
        }
    }

    #[test]
    fn zero_or_negative_step_changes_nothing() {
        let mut t = Thruster::new(0.2, 0.5);
        t.command_us(2000);
        assert_eq!(t.advance(0.0), 0.0);
        assert_eq!(t.advance(-1.0), 0.0);
        let mut t = Thruster::new(0.0, 0.5);
        t.command_us(2000);
        assert_eq!(t.advance(0.0), 0.0);
    }
}
