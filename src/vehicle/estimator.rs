//! State estimation: depth with vertical speed, heading with yaw rate.
//!
//! Two small Kalman filters, each with a position-like state and its rate,
//! driven by the commanded thrust as the known input (the thesis' chapter 11
//! left this as a placeholder). Before a measurement reaches a filter it
//! passes an **innovation gate**: a value too far from the filter's
//! prediction — the thesis' wild points (a reading ×0.1, ×10 or ×100) or a
//! torn value that still passed the decoder's range checks — is rejected and
//! counted. If the measurements keep disagreeing with the prediction *and
//! agree with each other*, the vehicle really is elsewhere (a re-zeroed depth
//! sensor, a model far off): the filter then widens its uncertainty so the
//! next measurements pull it over, instead of trusting one value blindly.
//!
//! The board's pressure sensor updates once a second while the nav line comes
//! every 100 ms: a depth value identical to the previous one is the same
//! sample repeated, not a new measurement, and is fused again only after
//! [`DEPTH_REPEAT_AS_NEW`] (a vehicle that really sits still).
//!
//! Pure: time is an argument, no I/O, no clock.
//!
//! # Model (per axis)
//! `ẋ = v`, `v̇ = −(a_lin + a_quad·|v|)·v + b·u`, with `u` the normalised
//! thrust demand along the axis. The coefficients come from the thesis'
//! 4-DOF identification (heave: mass + added mass 5.79 kg, damping 15.19 N·s/m
//! and 10.30 N·s²/m², 12 N per thruster; yaw: 0.549 kg·m², 0.2605 and 0.320,
//! two thrusters at 0.045 m). Whatever the model misses (tether, current,
//! weaker reverse thrust, buoyancy) is process noise.

use std::time::Duration;

use nalgebra::{Matrix2, Vector2};

/// A depth sample unchanged for this long is fused again (the vehicle sits still).
pub const DEPTH_REPEAT_AS_NEW: Duration = Duration::from_millis(1500);
/// Consecutive rejected measurements that agree with each other before the
/// filter accepts that the vehicle is really elsewhere.
const DEPTH_REJECTS_TO_RELEARN: usize = 3;
const HEADING_REJECTS_TO_RELEARN: usize = 5;
/// A measurement older than this (no update) makes the estimate invalid.
const STALE: Duration = Duration::from_millis(2500);

/// Coefficients of one axis' filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisModel {
    /// Linear damping over mass (1/s).
    pub a_lin: f64,
    /// Quadratic damping over mass (1/unit).
    pub a_quad: f64,
    /// Acceleration per unit of demand.
    pub b: f64,
    /// White acceleration noise spectral density (unit²/s³).
    pub accel_noise: f64,
    /// Measurement noise standard deviation.
    pub meas_std: f64,
    /// Innovation gate in standard deviations of the innovation.
    pub gate_sigma: f64,
    /// The gate is never narrower than this (so a good sensor's noise and
    /// rounding never look wild).
    pub gate_min: f64,
    /// Rejected values agree with each other when their spread is within this.
    pub relearn_spread: f64,
}

impl AxisModel {
    /// Heave, in metres (down positive) and m/s.
    pub fn depth() -> Self {
        let mass = 3.46 + 2.3295;
        Self {
            a_lin: 15.1897 / mass,
            a_quad: 10.304 / mass,
            b: 12.0 / mass,
            accel_noise: 0.02,
            meas_std: 0.02,
            gate_sigma: 4.0,
            gate_min: 0.12,
            relearn_spread: 0.15,
        }
    }

    /// Yaw, in radians and rad/s.
    pub fn heading() -> Self {
        let inertia = 0.399 + 0.1498;
        Self {
            a_lin: 0.2605 / inertia,
            a_quad: 0.320 / inertia,
            b: 2.0 * 12.0 * 0.045 / inertia,
            accel_noise: 0.05,
            meas_std: 1.0_f64.to_radians(),
            gate_sigma: 4.0,
            gate_min: 4.0_f64.to_radians(),
            relearn_spread: 6.0_f64.to_radians(),
        }
    }
}

/// What happened to a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fused {
    /// Fused into the estimate.
    Accepted,
    /// The same depth sample repeated: not a new measurement.
    Repeated,
    /// Outside the innovation gate: a wild point, dropped.
    Rejected { innovation: f64, gate: f64 },
    /// Rejected values agreed with each other: the filter starts over from them.
    Relearned,
    /// Not a finite number.
    Invalid,
}

/// A two-state Kalman filter with an innovation gate.
#[derive(Debug, Clone)]
pub struct AxisFilter {
    model: AxisModel,
    /// `[position, rate]`.
    x: Vector2<f64>,
    p: Matrix2<f64>,
    initialised: bool,
    /// Time the state refers to.
    at: Duration,
    /// Last fused measurement time.
    fused_at: Option<Duration>,
    /// The position is an angle: innovations wrap to ±π.
    angular: bool,
    rejected_total: u64,
    rejected_run: Vec<f64>,
    /// The demand applied since the last prediction (carried to a measurement's time).
    u: f64,
}

/// An angle wrapped into `[−π, π)`; a non-finite angle counts as 0.
pub(crate) fn wrap_pi(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w.is_finite() { w } else { 0.0 }
}

impl AxisFilter {
    pub fn new(model: AxisModel, angular: bool) -> Self {
        Self {
            model,
            x: Vector2::zeros(),
            p: Matrix2::identity(),
            initialised: false,
            at: Duration::ZERO,
            fused_at: None,
            angular,
            rejected_total: 0,
            rejected_run: Vec::new(),
            u: 0.0,
        }
    }

    /// Advances the estimate to `t` with demand `u` applied since the last call.
    pub fn predict(&mut self, t: Duration, u: f64) {
        let u = if u.is_finite() {
            u.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        if !self.initialised || t <= self.at {
            self.u = u;
            return;
        }
        let mut left = (t - self.at).as_secs_f64();
        self.at = t;
        let m = self.model;
        // Sub-steps keep the quadratic damping stable over a long gap.
        while left > 1e-9 {
            let dt = left.min(0.02);
            left -= dt;
            let v = self.x[1];
            let damping = m.a_lin + m.a_quad * v.abs();
            let f = Matrix2::new(
                1.0,
                dt,
                0.0,
                1.0 - (m.a_lin + 2.0 * m.a_quad * v.abs()) * dt,
            );
            self.x[0] += v * dt;
            self.x[1] += (-damping * v + m.b * u) * dt;
            let q = m.accel_noise;
            let qm = Matrix2::new(
                q * dt.powi(3) / 3.0,
                q * dt.powi(2) / 2.0,
                q * dt.powi(2) / 2.0,
                q * dt,
            );
            self.p = f * self.p * f.transpose() + qm;
        }
        if self.angular {
            // Keep the angle bounded without a jump in what it means.
            self.x[0] = self.x[0].rem_euclid(std::f64::consts::TAU);
        }
        self.u = u;
    }

    fn innovation(&self, z: f64) -> f64 {
        if self.angular {
            wrap_pi(z - self.x[0])
        } else {
            z - self.x[0]
        }
    }

    /// Fuses a measurement taken at `t` (after [`AxisFilter::predict`] to `t`).
    pub fn measure(&mut self, t: Duration, z: f64) -> Fused {
        if !z.is_finite() {
            return Fused::Invalid;
        }
        let r = self.model.meas_std.powi(2);
        if !self.initialised {
            self.x = Vector2::new(z, 0.0);
            self.p = Matrix2::new(r, 0.0, 0.0, 0.25);
            self.initialised = true;
            self.at = t;
            self.fused_at = Some(t);
            return Fused::Accepted;
        }
        self.predict(t, self.u);
        let y = self.innovation(z);
        let s = self.p[(0, 0)] + r;
        let gate = (self.model.gate_sigma * s.sqrt()).max(self.model.gate_min);
        if y.abs() > gate {
            self.rejected_total += 1;
            self.rejected_run.push(z);
            let needed = if self.angular {
                HEADING_REJECTS_TO_RELEARN
            } else {
                DEPTH_REJECTS_TO_RELEARN
            };
            if self.rejected_run.len() >= needed {
                let tail = &self.rejected_run[self.rejected_run.len() - needed..];
                if self.agree(tail) {
                    // Start over from the measurements, with their rate unknown.
                    self.x = Vector2::new(z, 0.0);
                    self.p = Matrix2::new(r, 0.0, 0.0, 0.25);
                    self.rejected_run.clear();
                    self.fused_at = Some(t);
                    return Fused::Relearned;
                }
                self.rejected_run.remove(0);
            }
            return Fused::Rejected {
                innovation: y,
                gate,
            };
        }
        self.rejected_run.clear();
        let k = Vector2::new(self.p[(0, 0)] / s, self.p[(1, 0)] / s);
        self.x += k * y;
        let h = nalgebra::RowVector2::new(1.0, 0.0);
        self.p = (Matrix2::identity() - k * h) * self.p;
        // Symmetric, for numerical hygiene.
        self.p = (self.p + self.p.transpose()) * 0.5;
        if self.angular {
            self.x[0] = self.x[0].rem_euclid(std::f64::consts::TAU);
        }
        self.fused_at = Some(t);
        Fused::Accepted
    }

    fn agree(&self, values: &[f64]) -> bool {
        let first = values[0];
        values.iter().all(|v| {
            let d = if self.angular {
                wrap_pi(v - first)
            } else {
                v - first
            };
            d.abs() <= self.model.relearn_spread
        })
    }

    pub fn position(&self) -> f64 {
        self.x[0]
    }
    pub fn rate(&self) -> f64 {
        self.x[1]
    }
    pub fn std(&self) -> f64 {
        self.p[(0, 0)].max(0.0).sqrt()
    }
    /// Variance of the rate (units²/s²).
    pub fn rate_variance(&self) -> f64 {
        self.p[(1, 1)].max(0.0)
    }
    pub fn rejected(&self) -> u64 {
        self.rejected_total
    }
    /// Has fused a measurement within the last `STALE`.
    pub fn valid(&self, now: Duration) -> bool {
        self.initialised
            && self
                .fused_at
                .is_some_and(|t| now.saturating_sub(t) <= STALE)
    }
    pub fn initialised(&self) -> bool {
        self.initialised
    }
}

/// Depth and heading estimates.
#[derive(Debug, Clone)]
pub struct Estimator {
    depth: AxisFilter,
    heading: AxisFilter,
    /// Last raw measurements (for telemetry beside the estimates).
    pub depth_measured_m: Option<f64>,
    pub heading_measured_deg: Option<f64>,
    depth_raw_at: Option<Duration>,
}

impl Default for Estimator {
    fn default() -> Self {
        Self::new(AxisModel::depth(), AxisModel::heading())
    }
}

/// A snapshot of the estimates in the units telemetry uses.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Estimate {
    pub depth_m: f64,
    /// Down positive.
    pub heave_mps: f64,
    pub depth_std_m: f64,
    pub heading_deg: f64,
    pub yaw_rate_dps: f64,
    pub heading_std_deg: f64,
    pub depth_valid: bool,
    pub heading_valid: bool,
    pub depth_rejected: u64,
    pub heading_rejected: u64,
}

impl Estimator {
    pub fn new(depth: AxisModel, heading: AxisModel) -> Self {
        Self {
            depth: AxisFilter::new(depth, false),
            heading: AxisFilter::new(heading, true),
            depth_measured_m: None,
            heading_measured_deg: None,
            depth_raw_at: None,
        }
    }

    /// Advances both filters to `t`; `heave` and `yaw` are the normalised
    /// thrust demands applied since the last call.
    pub fn predict(&mut self, t: Duration, heave: f64, yaw: f64) {
        self.depth.predict(t, heave);
        self.heading.predict(t, yaw);
    }

    /// A depth reading from the board (m, down positive).
    pub fn depth_reading(&mut self, t: Duration, depth_m: f64) -> Fused {
        let repeated = self.depth_measured_m == Some(depth_m)
            && self
                .depth_raw_at
                .is_some_and(|at| t.saturating_sub(at) < DEPTH_REPEAT_AS_NEW);
        self.depth_measured_m = Some(depth_m);
        if repeated {
            return Fused::Repeated;
        }
        self.depth_raw_at = Some(t);
        self.depth.measure(t, depth_m)
    }

    /// A heading reading from the board (degrees, 0..360).
    pub fn heading_reading(&mut self, t: Duration, heading_deg: f64) -> Fused {
        self.heading_measured_deg = Some(heading_deg);
        self.heading.measure(t, heading_deg.to_radians())
    }

    pub fn estimate(&self, now: Duration) -> Estimate {
        Estimate {
            depth_m: self.depth.position(),
            heave_mps: self.depth.rate(),
            depth_std_m: self.depth.std(),
            heading_deg: self.heading.position().to_degrees().rem_euclid(360.0),
            yaw_rate_dps: self.heading.rate().to_degrees(),
            heading_std_deg: self.heading.std().to_degrees(),
            depth_valid: self.depth.valid(now),
            heading_valid: self.heading.valid(now),
            depth_rejected: self.depth.rejected(),
            heading_rejected: self.heading.rejected(),
        }
    }

    pub fn depth_filter(&self) -> &AxisFilter {
        &self.depth
    }
    pub fn heading_filter(&self) -> &AxisFilter {
        &self.heading
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn first_measurement_initialises() {
        let mut e = Estimator::default();
        assert_eq!(e.depth_reading(ms(0), 1.5), Fused::Accepted);
        assert!((e.estimate(ms(0)).depth_m - 1.5).abs() < 1e-12);
    }

    #[test]
    fn wild_depth_points_are_rejected() {
        let mut e = Estimator::default();
        for i in 0..20 {
            e.predict(ms(i * 1000), 0.0, 0.0);
            let noisy = 2.0 + 0.01 * (i % 3) as f64;
            assert_eq!(e.depth_reading(ms(i * 1000), noisy), Fused::Accepted);
        }
        for (k, wild) in [0.2, 20.0, 200.0].into_iter().enumerate() {
            let t = ms(20_000 + k as u64 * 1000);
            e.predict(t, 0.0, 0.0);
            assert!(matches!(e.depth_reading(t, wild), Fused::Rejected { .. }));
        }
        assert!((e.estimate(ms(22_000)).depth_m - 2.0).abs() < 0.05);
        assert_eq!(e.estimate(ms(22_000)).depth_rejected, 3);
    }

    #[test]
    fn heading_wraps_through_north() {
        let mut e = Estimator::default();
        for i in 0..50u64 {
            let h = (350.0 + i as f64 * 0.5).rem_euclid(360.0);
            e.predict(ms(i * 100), 0.0, 0.0);
            assert_eq!(e.heading_reading(ms(i * 100), h), Fused::Accepted, "{h}");
        }
        let est = e.estimate(ms(4900));
        assert!(
            (wrap_pi((est.heading_deg - 14.5).to_radians())).abs() < 1.5_f64.to_radians(),
            "{est:?}"
        );
        assert!((est.yaw_rate_dps - 5.0).abs() < 2.0, "{est:?}");
    }

    #[test]
    fn a_real_jump_is_relearned_after_agreeing_rejections() {
        let mut e = Estimator::default();
        for i in 0..10 {
            e.predict(ms(i * 2000), 0.0, 0.0);
            e.depth_reading(ms(i * 2000), 1.0);
        }
        // The depth sensor was re-zeroed: 1 m now reads 0.
        let mut last = Fused::Accepted;
        for i in 10..14 {
            e.predict(ms(i * 2000), 0.0, 0.0);
            last = e.depth_reading(ms(i * 2000), 0.001 * i as f64);
            if last == Fused::Relearned {
                break;
            }
        }
        assert_eq!(last, Fused::Relearned);
        assert!(e.estimate(ms(26_000)).depth_m < 0.1);
    }

    #[test]
    fn repeated_depth_samples_are_not_new_measurements() {
        let mut e = Estimator::default();
        assert_eq!(e.depth_reading(ms(0), 1.0), Fused::Accepted);
        assert_eq!(e.depth_reading(ms(100), 1.0), Fused::Repeated);
        assert_eq!(e.depth_reading(ms(1600), 1.0), Fused::Accepted);
    }

    #[test]
    fn garbage_never_poisons_the_state() {
        let mut e = Estimator::default();
        e.depth_reading(ms(0), 1.0);
        assert_eq!(e.depth_reading(ms(100), f64::NAN), Fused::Invalid);
        e.predict(ms(200), f64::NAN, f64::INFINITY);
        let est = e.estimate(ms(200));
        assert!(est.depth_m.is_finite() && est.heave_mps.is_finite());
        assert!(est.heading_deg.is_finite());
    }
}
