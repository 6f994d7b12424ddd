//! Depth and heading autopilots (the thesis' "DP" sub-functions of depth
//! and heading hold), as ArduSub's STABILIZE, ALT_HOLD and SURFACE use them.
//!
//! Owns the controllers and their setpoints; reads the estimator's output
//! and the pilot's sticks and returns thrust demands. Pure: `dt` and the
//! measurements are arguments; no I/O, no clock. The vehicle core decides
//! which controller runs in which mode and what reaches the thrusters.
//!
//! # Structure (ArduPilot's, where the names match)
//! - Heading: heading error → yaw-rate target (`ATC_ANG_YAW_P`, limited to
//!   `NEPT_YAW_RATE_MAX`) → yaw-rate PID + feed-forward (`ATC_RAT_YAW_P/I/D/
//!   IMAX/FF`) → yaw demand. The yaw stick commands the rate directly; when
//!   it is released and the turn has stopped, the heading is captured and held.
//! - Depth: the held depth is approached along a reference that moves no
//!   faster than `PILOT_SPEED_DN`/`PILOT_SPEED_UP`; reference error → climb
//!   target (`PSC_POSZ_P`, plus the reference's own rate as feed-forward) →
//!   climb-rate PID + feed-forward (`PSC_VELZ_P/I/D/IMAX/FF`) → vertical
//!   demand. ArduPilot closes a third, acceleration loop (`PSC_ACCZ_*`) on the
//!   IMU's vertical accelerometer; the OpenROV board reports none, so the
//!   velocity loop drives the thruster directly and its gains are in
//!   demand per m/s. The heave stick commands a climb rate; on release the
//!   depth is captured and held.
//!
//! Every PID uses derivative on measurement (a setpoint step never kicks the
//! thruster) and conditional integration (the integrator stops growing while
//! the output is saturated in the same direction, and is clamped to IMAX).

use super::estimator::wrap_pi;

/// Gains of one PID stage.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PidGains {
    pub p: f64,
    pub i: f64,
    pub d: f64,
    /// Integrator limit, in output units.
    pub imax: f64,
    /// Feed-forward on the target.
    pub ff: f64,
}

/// A PID with derivative on measurement and anti-windup.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Pid {
    integrator: f64,
    last_measurement: Option<f64>,
    /// Last output parts, for telemetry and tests.
    pub last_p: f64,
    pub last_i: f64,
    pub last_d: f64,
}

/// Finite or zero: a NaN gain or input must never become thrust.
fn finite(x: f64) -> f64 {
    if x.is_finite() { x } else { 0.0 }
}

impl Pid {
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// A step with no output: the integrator keeps its value and the
    /// derivative its reference.
    pub fn hold(&mut self, measurement: f64) {
        self.last_measurement = Some(finite(measurement));
    }

    /// One step: `target` and `measurement` in the loop's units; output clamped to ±`limit`.
    pub fn step(&mut self, g: PidGains, target: f64, measurement: f64, dt: f64, limit: f64) -> f64 {
        let (target, measurement, dt) = (finite(target), finite(measurement), finite(dt));
        let error = target - measurement;
        let d_meas = match self.last_measurement {
            Some(prev) if dt > 0.0 => (measurement - prev) / dt,
            _ => 0.0,
        };
        self.last_measurement = Some(measurement);
        let p = finite(g.p) * error;
        let d = -finite(g.d) * d_meas;
        let ff = finite(g.ff) * target;
        let unsat = p + self.integrator + d + ff;
        // Integrate unless that would push a saturated output further out.
        let saturated_same_way =
            (unsat >= limit && error > 0.0) || (unsat <= -limit && error < 0.0);
        if !saturated_same_way && dt > 0.0 {
            let imax = finite(g.imax).abs();
            self.integrator = (self.integrator + finite(g.i) * error * dt).clamp(-imax, imax);
        }
        self.last_p = p;
        self.last_i = self.integrator;
        self.last_d = d;
        (p + self.integrator + d + ff).clamp(-limit, limit)
    }
}

/// What the controllers read from the estimator.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measured {
    /// Down positive (m).
    pub depth_m: f64,
    /// Down positive (m/s).
    pub heave_mps: f64,
    pub heading_rad: f64,
    pub yaw_rate_rps: f64,
}

/// Heading-hold settings from the parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingGains {
    /// Heading error (rad) to rate target (rad/s).
    pub angle_p: f64,
    pub rate: PidGains,
    /// Full yaw stick and the largest rate the hold commands (rad/s).
    pub max_rate_rps: f64,
    /// Held heading error below which the thrusters rest (rad): the ESCs'
    /// deadzone makes the smallest yaw moment a sizeable one, so correcting
    /// every tenth of a degree would only make the vehicle hunt.
    pub band_rad: f64,
}

/// Depth-hold settings from the parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthGains {
    /// Reference error (m) to climb-rate target (m/s).
    pub pos_p: f64,
    pub vel: PidGains,
    /// Largest ascent and descent speeds (m/s, both positive).
    pub speed_up_mps: f64,
    pub speed_down_mps: f64,
}

/// Below this stick deflection an axis counts as released.
pub const STICK_DEADBAND: f64 = 0.05;
/// The heading is captured once the turn has slowed below this after release.
const CAPTURE_RATE_RPS: f64 = 0.087; // 5 °/s

/// The heading controller.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HeadingHold {
    /// Held heading (rad, 0..2π); None while the pilot turns or before capture.
    pub target_rad: Option<f64>,
    pub rate_target_rps: f64,
    pub output: f64,
    pid: Pid,
}

impl HeadingHold {
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Sets the held heading (from a command or the HMI).
    pub fn set_target(&mut self, heading_rad: f64) {
        if heading_rad.is_finite() {
            self.target_rad = Some(heading_rad.rem_euclid(std::f64::consts::TAU));
        }
    }

    /// One step: yaw demand in −1..1 for a yaw stick in −1..1.
    pub fn step(&mut self, g: &HeadingGains, m: &Measured, stick: f64, dt: f64) -> f64 {
        let max_rate = finite(g.max_rate_rps).abs();
        let stick = finite(stick).clamp(-1.0, 1.0);
        self.rate_target_rps = if stick.abs() > STICK_DEADBAND {
            self.target_rad = None;
            stick * max_rate
        } else {
            if self.target_rad.is_none() && m.yaw_rate_rps.abs() < CAPTURE_RATE_RPS {
                self.target_rad = Some(m.heading_rad.rem_euclid(std::f64::consts::TAU));
            }
            match self.target_rad {
                Some(t) => {
                    (finite(g.angle_p) * wrap_pi(t - m.heading_rad)).clamp(-max_rate, max_rate)
                }
                // Still turning after release: brake first, then capture.
                None => 0.0,
            }
        };
        self.output = self
            .pid
            .step(g.rate, self.rate_target_rps, m.yaw_rate_rps, dt, 1.0);
        self.output
    }
}

/// The depth controller.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DepthHold {
    /// Held depth (m, down positive); None while the pilot climbs or dives.
    pub target_m: Option<f64>,
    /// The reference that approaches the target at the allowed speeds.
    pub reference_m: Option<f64>,
    /// Climb-rate target, down positive (m/s).
    pub heave_target_mps: f64,
    pub output: f64,
    pid: Pid,
}

impl DepthHold {
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Sets the held depth; the vehicle goes there at the allowed speeds.
    pub fn set_target(&mut self, depth_m: f64) {
        if depth_m.is_finite() {
            self.target_m = Some(depth_m.max(0.0));
        }
    }

    /// One step: vertical demand in −1..1 (down positive) for a heave stick
    /// in −1..1 (down positive).
    pub fn step(&mut self, g: &DepthGains, m: &Measured, stick: f64, dt: f64) -> f64 {
        let up = finite(g.speed_up_mps).abs();
        let down = finite(g.speed_down_mps).abs();
        let stick = finite(stick).clamp(-1.0, 1.0);
        self.heave_target_mps = if stick.abs() > STICK_DEADBAND {
            self.target_m = None;
            self.reference_m = None;
            stick * if stick > 0.0 { down } else { up }
        } else {
            let target = *self.target_m.get_or_insert(m.depth_m.max(0.0));
            let reference = self.reference_m.get_or_insert(m.depth_m);
            let before = *reference;
            *reference += (target - *reference).clamp(-up * dt, down * dt);
            let reference_rate = if dt > 0.0 {
                (*reference - before) / dt
            } else {
                0.0
            };
            (finite(g.pos_p) * (*reference - m.depth_m) + reference_rate).clamp(-up, down)
        };
        self.output = self
            .pid
            .step(g.vel, self.heave_target_mps, m.heave_mps, dt, 1.0);
        self.output
    }

    /// SURFACE: rise at the full ascent speed (no held depth).
    pub fn step_surface(&mut self, g: &DepthGains, m: &Measured, dt: f64) -> f64 {
        self.target_m = None;
        self.reference_m = None;
        self.heave_target_mps = -finite(g.speed_up_mps).abs();
        self.output = self
            .pid
            .step(g.vel, self.heave_target_mps, m.heave_mps, dt, 1.0);
        self.output
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivative_on_measurement_does_not_kick_on_a_setpoint_step() {
        let mut pid = Pid::default();
        let g = PidGains {
            p: 1.0,
            d: 10.0,
            ..PidGains::default()
        };
        pid.step(g, 0.0, 0.0, 0.01, 1.0);
        let out = pid.step(g, 0.5, 0.0, 0.01, 1.0);
        assert!((out - 0.5).abs() < 1e-12, "{out}");
    }

    #[test]
    fn integrator_does_not_wind_up_while_saturated() {
        let mut pid = Pid::default();
        let g = PidGains {
            p: 10.0,
            i: 5.0,
            imax: 0.5,
            ..PidGains::default()
        };
        for _ in 0..1000 {
            pid.step(g, 1.0, 0.0, 0.01, 1.0);
        }
        assert_eq!(pid.last_i, 0.0, "saturated by P alone: no integration");
        // Unsaturated: integrates, clamped to IMAX.
        let g = PidGains { p: 0.1, ..g };
        for _ in 0..1000 {
            pid.step(g, 1.0, 0.0, 0.01, 1.0);
        }
        assert!((pid.last_i - 0.5).abs() < 1e-9, "{}", pid.last_i);
    }

    #[test]
    fn nan_never_becomes_thrust() {
        let mut pid = Pid::default();
        let g = PidGains {
            p: f64::NAN,
            i: 1.0,
            imax: 1.0,
            ..PidGains::default()
        };
        let out = pid.step(g, f64::NAN, 1.0, f64::INFINITY, 1.0);
        assert!(out.is_finite());
        let mut h = HeadingHold::default();
        let hg = HeadingGains {
            angle_p: 1.0,
            rate: PidGains::default(),
            max_rate_rps: f64::NAN,
            band_rad: f64::NAN,
        };
        assert!(
            h.step(&hg, &Measured::default(), f64::NAN, 0.01)
                .is_finite()
        );
    }

    #[test]
    fn heading_is_captured_after_the_turn_stops() {
        let g = HeadingGains {
            angle_p: 4.5,
            rate: PidGains {
                p: 0.5,
                ..PidGains::default()
            },
            max_rate_rps: 0.8,
            band_rad: 0.02,
        };
        let mut h = HeadingHold::default();
        let turning = Measured {
            heading_rad: 1.0,
            yaw_rate_rps: 0.5,
            ..Measured::default()
        };
        h.step(&g, &turning, 0.6, 0.01);
        assert_eq!(h.target_rad, None);
        h.step(&g, &turning, 0.0, 0.01);
        assert_eq!(h.target_rad, None, "still turning: brake first");
        assert_eq!(h.rate_target_rps, 0.0);
        let stopped = Measured {
            yaw_rate_rps: 0.01,
            ..turning
        };
        h.step(&g, &stopped, 0.0, 0.01);
        assert_eq!(h.target_rad, Some(1.0));
    }

    #[test]
    fn depth_reference_moves_at_the_allowed_speed() {
        let g = DepthGains {
            pos_p: 1.0,
            vel: PidGains::default(),
            speed_up_mps: 0.5,
            speed_down_mps: 0.25,
        };
        let mut d = DepthHold::default();
        d.set_target(2.0);
        let m = Measured::default();
        for _ in 0..100 {
            d.step(&g, &m, 0.0, 0.01);
        }
        let r = d.reference_m.expect("a reference once a target is held");
        assert!((r - 0.25).abs() < 1e-9, "{r}");
    }
}
