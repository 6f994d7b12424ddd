//! The 4-DOF ROV model of the Neptunus thesis (chapter 12) and its thrust
//! allocation (section 9.3), forward and inverse.
//!
//! This module owns the equations of motion, their RK4 integration and the
//! mapping between `go()` pulse widths and the normalised demand `[X, Z, M]`.
//! It must never do I/O, read a clock or draw random numbers: every function
//! is a plain function of its arguments, so the board emulator, the tests and
//! the benches all get the same numbers.
//!
//! # Frames, units and signs
//! - `η = [x, y, z, ψ]`: NED position in metres (x north, y east, **z down**,
//!   so `z` is depth) and heading ψ in radians, positive clockwise seen from
//!   above (north → east).
//! - `ν = [u, v, w, r]`: body-frame surge, sway, heave (m/s, heave positive
//!   down) and yaw rate r (rad/s, positive = turning to starboard).
//! - Kinematics `η̇ = J(ψ)ν`, `J = diag(R(ψ), 1)`, R the rotation about the
//!   down axis: `ẋ = u cosψ − v sinψ`, `ẏ = u sinψ + v cosψ`, `ż = w`, `ψ̇ = r`.
//! - Kinetics `M ν̇ + D(ν)ν + g = τ` with `M = M_A + M_RB`,
//!   `D(ν) = D_l + D_q|ν|`; Coriolis and centripetal terms are neglected
//!   (the thesis argues the speeds are low). Pitch and roll are fixed at 0.
//! - `τ = [f·X, 0, f·Z, 2·f·l·M]` (N, N, N, N·m). A positive heave demand Z
//!   pushes the vehicle **down**. A positive yaw demand M drives the port
//!   thruster harder than the starboard one, which turns the bow to
//!   starboard: τ_N > 0 gives r > 0 and ψ increases.
//! - `g = [0, 0, 0.0234, 0]`: with z down, a positive heave restoring term
//!   means the vehicle is very slightly buoyant and drifts up (w < 0) when
//!   the thrusters are off.
//!
//! ψ is kept continuous (never wrapped) in [`SimState`] so the integrator
//! never sees a jump; use [`SimState::heading_deg`] for a 0..360° heading.
//!
//! The model has no free surface: with no thrust the vehicle keeps rising
//! past z = 0. The sensor model reads surface pressure above the surface.

use nalgebra::{Cholesky, Matrix4, Vector3, Vector4};

use super::environment::Environment;

/// Pulse width that stops a thruster (µs). The simulator keeps its own
/// constant on purpose, apart from the vehicle's `mixer::NEUTRAL_US`: it
/// models the ESC as the thesis measured it, an independent check of what
/// the vehicle commands.
pub const PWM_NEUTRAL_US: u16 = 1500;
/// Pulse width swing from neutral to full thrust either way (µs).
pub const PWM_HALF_RANGE_US: u16 = 500;

/// Coefficients of the thesis model. `Default` gives the thesis values.
#[derive(Debug, Clone, PartialEq)]
pub struct ThesisParams {
    /// Added mass `M_A` (kg, kg·m, kg·m²), symmetric.
    pub m_a: Matrix4<f64>,
    /// Rigid-body mass and inertia `M_RB`.
    pub m_rb: Matrix4<f64>,
    /// Linear damping, the diagonal of `D_l` (N·s/m, N·m·s/rad).
    pub d_l: Vector4<f64>,
    /// Quadratic damping coefficients: `D_q = diag(d_q ∘ |ν|)`.
    pub d_q: Vector4<f64>,
    /// Restoring forces `g` (N, N·m); heave positive down.
    pub g: Vector4<f64>,
    /// Force `f` of a thruster at full demand (N).
    pub thrust_n: f64,
    /// Yaw moment arm `l` of the horizontal thrusters (m).
    pub arm_m: f64,
}

impl Default for ThesisParams {
    fn default() -> Self {
        #[rustfmt::skip]
        let m_a = Matrix4::new(
            2.055, 0.0,     0.0,    0.0,
            0.0,   14.6033, 0.0,    -0.8926,
            0.0,   0.0,     2.3295, 0.0,
            0.0,   -0.8926, 0.0,    0.1498,
        );
        Self {
            m_a,
            m_rb: Matrix4::from_diagonal(&Vector4::new(3.46, 3.46, 3.46, 0.399)),
            d_l: Vector4::new(2.2907, 4.9804, 15.1897, 0.2605),
            d_q: Vector4::new(4.008, 35.216, 10.304, 0.320),
            g: Vector4::new(0.0, 0.0, 0.0234, 0.0),
            thrust_n: 12.0,
            arm_m: 0.045,
        }
    }
}

/// Why a parameter set cannot be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamsError {
    #[error("simulator parameter {name} is not finite — give every coefficient a finite number")]
    NotFinite { name: &'static str },
    #[error(
        "simulator mass matrix M_A + M_RB is not symmetric positive definite — \
         check the added-mass and rigid-body coefficients (a mass matrix must be)"
    )]
    MassNotPositiveDefinite,
    #[error(
        "simulator damping {name}[{index}] = {value} is negative — damping must be ≥ 0 \
         or the model gains energy"
    )]
    NegativeDamping {
        name: &'static str,
        index: usize,
        value: f64,
    },
    #[error("simulator parameter {name} = {value} is not positive — {fix}")]
    NotPositive {
        name: &'static str,
        value: f64,
        fix: &'static str,
    },
}

/// Position/heading and body velocities of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimState {
    /// `[x_m, y_m, z_m, psi_rad]`, NED, z down, ψ continuous (not wrapped).
    pub eta: Vector4<f64>,
    /// `[u_mps, v_mps, w_mps, r_radps]`, body frame, w positive down.
    pub nu: Vector4<f64>,
}

impl SimState {
    /// Depth below the surface (m); negative above it (the model has no surface).
    pub fn depth_m(&self) -> f64 {
        self.eta[2]
    }

    /// Heading in degrees, wrapped into `[0, 360)`.
    pub fn heading_deg(&self) -> f64 {
        wrap_deg_360(self.eta[3].to_degrees())
    }
}

/// Wraps an angle in degrees into `[0, 360)`.
pub fn wrap_deg_360(deg: f64) -> f64 {
    let w = deg.rem_euclid(360.0);
    // rem_euclid of a tiny negative number rounds to exactly 360.0.
    if w >= 360.0 { 0.0 } else { w }
}

/// Wraps an angle in degrees into `(-180, 180]`.
pub fn wrap_deg_180(deg: f64) -> f64 {
    let w = wrap_deg_360(deg);
    if w > 180.0 { w - 360.0 } else { w }
}

/// Normalised motion demand (gain already applied), each in `[-1, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Demand {
    /// X: positive = forward.
    pub surge: f64,
    /// Z: positive = down (z is down).
    pub heave: f64,
    /// M: positive = turn to starboard (heading increases).
    pub yaw: f64,
}

impl Demand {
    /// The demand with every component forced into `[-1, 1]`; NaN becomes 0
    /// so a bad number can never command thrust.
    pub fn saturated(&self) -> Self {
        Self {
            surge: sat(self.surge),
            heave: sat(self.heave),
            yaw: sat(self.yaw),
        }
    }
}

/// `sat()` of the thesis, plus NaN → 0 (a bad number must not move a thruster).
fn sat(x: f64) -> f64 {
    if x.is_nan() { 0.0 } else { x.clamp(-1.0, 1.0) }
}

/// The thesis model with `M⁻¹` precomputed.
#[derive(Debug, Clone)]
pub struct ThesisModel {
    params: ThesisParams,
    m_inv: Matrix4<f64>,
}

impl ThesisModel {
    /// Builds the model and inverts the mass matrix once.
    ///
    /// # Panics
    /// If the parameters are not simulable (see [`ThesisModel::try_new`]);
    /// the thesis defaults always are. Use `try_new` for parameters that come
    /// from a user.
    pub fn new(params: ThesisParams) -> Self {
        match Self::try_new(params) {
            Ok(model) => model,
            Err(e) => panic!("{e}"),
        }
    }

    /// Builds the model, rejecting non-finite coefficients, negative damping
    /// and a mass matrix that is not symmetric positive definite.
    pub fn try_new(params: ThesisParams) -> Result<Self, ParamsError> {
        let finite = |name, ok: bool| {
            if ok {
                Ok(())
            } else {
                Err(ParamsError::NotFinite { name })
            }
        };
        finite("m_a", params.m_a.iter().all(|x| x.is_finite()))?;
        finite("m_rb", params.m_rb.iter().all(|x| x.is_finite()))?;
        finite("d_l", params.d_l.iter().all(|x| x.is_finite()))?;
        finite("d_q", params.d_q.iter().all(|x| x.is_finite()))?;
        finite("g", params.g.iter().all(|x| x.is_finite()))?;
        finite("thrust_n", params.thrust_n.is_finite())?;
        finite("arm_m", params.arm_m.is_finite())?;
        for (name, d) in [("d_l", &params.d_l), ("d_q", &params.d_q)] {
            if let Some((index, &value)) = d.iter().enumerate().find(|(_, x)| **x < 0.0) {
                return Err(ParamsError::NegativeDamping { name, index, value });
            }
        }
        let m = params.m_a + params.m_rb;
        // Cholesky only reads one triangle, so symmetry is checked separately.
        if (m - m.transpose()).abs().max() > 1e-12 * m.abs().max() {
            return Err(ParamsError::MassNotPositiveDefinite);
        }
        let m_inv = Cholesky::new(m)
            .ok_or(ParamsError::MassNotPositiveDefinite)?
            .inverse();
        Ok(Self { params, m_inv })
    }

    pub fn params(&self) -> &ThesisParams {
        &self.params
    }

    /// Generalised thruster forces `τ = [f·X, 0, f·Z, 2·f·l·M]` for a demand
    /// (saturated to `[-1, 1]` first, NaN → 0).
    pub fn tau(&self, d: &Demand) -> Vector4<f64> {
        let d = d.saturated();
        let f = self.params.thrust_n;
        Vector4::new(
            f * d.surge,
            0.0,
            f * d.heave,
            2.0 * f * self.params.arm_m * d.yaw,
        )
    }

    /// Time derivative `(η̇, ν̇)` packed as a [`SimState`].
    pub fn derivative(&self, s: &SimState, d: &Demand) -> SimState {
        self.derivative_tau(s, &self.tau(d))
    }

    fn derivative_tau(&self, s: &SimState, tau: &Vector4<f64>) -> SimState {
        let p = &self.params;
        let nu = &s.nu;
        let (sin, cos) = s.eta[3].sin_cos();
        let eta_dot = Vector4::new(
            nu[0] * cos - nu[1] * sin,
            nu[0] * sin + nu[1] * cos,
            nu[2],
            nu[3],
        );
        // D(ν)ν with diagonal D_l and D_q: component-wise (d_l + d_q|ν|)ν.
        let damping = (p.d_l + p.d_q.component_mul(&nu.abs())).component_mul(nu);
        let nu_dot = self.m_inv * (tau - damping - p.g);
        SimState {
            eta: eta_dot,
            nu: nu_dot,
        }
    }

    /// One RK4 step of length dt_s. Pure.
    ///
    /// The demand is held constant over the step (zero-order hold, as the
    /// board holds a `go()` until the next one).
    pub fn step(&self, s: &SimState, d: &Demand, dt_s: f64) -> SimState {
        let tau = self.tau(d);
        let half = 0.5 * dt_s;
        let k1 = self.derivative_tau(s, &tau);
        let k2 = self.derivative_tau(&axpy(s, half, &k1), &tau);
        let k3 = self.derivative_tau(&axpy(s, half, &k2), &tau);
        let k4 = self.derivative_tau(&axpy(s, dt_s, &k3), &tau);
        let sixth = dt_s / 6.0;
        SimState {
            eta: s.eta + (k1.eta + 2.0 * (k2.eta + k3.eta) + k4.eta) * sixth,
            nu: s.nu + (k1.nu + 2.0 * (k2.nu + k3.nu) + k4.nu) * sixth,
        }
    }

    /// One RK4 step in moving water and on a tether: as [`ThesisModel::step`],
    /// but the damping acts on the velocity relative to the water,
    /// `D(ν_r)ν_r` as the thesis writes it (eq. 12.10), and the tether's drag
    /// is added to τ in surge, sway and heave (the 4-DOF model has no roll or
    /// pitch for it to act on). With [`Environment::is_calm`] this is the
    /// same motion as `step` to rounding.
    pub fn step_in(&self, s: &SimState, d: &Demand, env: &Environment, dt_s: f64) -> SimState {
        let tau = self.tau(d);
        let half = 0.5 * dt_s;
        let k1 = self.derivative_env(s, &tau, env);
        let k2 = self.derivative_env(&axpy(s, half, &k1), &tau, env);
        let k3 = self.derivative_env(&axpy(s, half, &k2), &tau, env);
        let k4 = self.derivative_env(&axpy(s, dt_s, &k3), &tau, env);
        let sixth = dt_s / 6.0;
        SimState {
            eta: s.eta + (k1.eta + 2.0 * (k2.eta + k3.eta) + k4.eta) * sixth,
            nu: s.nu + (k1.nu + 2.0 * (k2.nu + k3.nu) + k4.nu) * sixth,
        }
    }

    fn derivative_env(&self, s: &SimState, tau: &Vector4<f64>, env: &Environment) -> SimState {
        let p = &self.params;
        let nu = &s.nu;
        let (sin, cos) = s.eta[3].sin_cos();
        let eta_dot = Vector4::new(
            nu[0] * cos - nu[1] * sin,
            nu[0] * sin + nu[1] * cos,
            nu[2],
            nu[3],
        );
        let c = &env.current_ned_mps;
        // The current in the body frame: Rᵀ(ψ)·v_c.
        let current_body =
            Vector4::new(c[0] * cos + c[1] * sin, -c[0] * sin + c[1] * cos, c[2], 0.0);
        let nu_r = nu - current_body;
        let damping = (p.d_l + p.d_q.component_mul(&nu_r.abs())).component_mul(&nu_r);
        let position = Vector3::new(s.eta[0], s.eta[1], s.eta[2]);
        let v_rel_ned = Vector3::new(eta_dot[0], eta_dot[1], eta_dot[2]) - c;
        let f = env.tether_force_ned_n(&position, &v_rel_ned);
        let tether_body =
            Vector4::new(f[0] * cos + f[1] * sin, -f[0] * sin + f[1] * cos, f[2], 0.0);
        let nu_dot = self.m_inv * (tau + tether_body - damping - p.g);
        SimState {
            eta: eta_dot,
            nu: nu_dot,
        }
    }

    /// Analytic terminal surge speed (m/s) for a constant surge demand:
    /// the root of `d_q·u|u| + d_l·u = f·X`. Surge is decoupled from the
    /// other axes in this model, so this is exactly where `step` settles.
    pub fn terminal_surge_speed(&self, surge: f64) -> f64 {
        let p = &self.params;
        terminal_speed(p.thrust_n * sat(surge) - p.g[0], p.d_l[0], p.d_q[0])
    }

    /// Analytic terminal heave speed (m/s, positive down) for a constant
    /// heave demand, including the buoyancy term: `d_q·w|w| + d_l·w = f·Z − g_z`.
    pub fn terminal_heave_speed(&self, heave: f64) -> f64 {
        let p = &self.params;
        terminal_speed(p.thrust_n * sat(heave) - p.g[2], p.d_l[2], p.d_q[2])
    }
}

/// `s + h·k` for the RK4 stages.
fn axpy(s: &SimState, h: f64, k: &SimState) -> SimState {
    SimState {
        eta: s.eta + k.eta * h,
        nu: s.nu + k.nu * h,
    }
}

/// Root of `dq·x|x| + dl·x = force` (dl, dq ≥ 0).
fn terminal_speed(force: f64, dl: f64, dq: f64) -> f64 {
    let f = force.abs();
    // 2f / (dl + √(dl² + 4·dq·f)) is the usual root without the cancellation
    // of (−dl + √…)/(2dq), and stays valid when dq = 0.
    let denom = dl + (dl * dl + 4.0 * dq * f).sqrt();
    if denom == 0.0 {
        return 0.0;
    }
    (2.0 * f / denom).copysign(force)
}

/// Thesis allocation (section 9.3) without the motor directions:
/// `[sat(X+M), sat(Z), sat(X−M)]` for `[port, vertical, starboard]`.
pub fn thruster_outputs(d: &Demand) -> [f64; 3] {
    let d = d.saturated();
    [sat(d.surge + d.yaw), d.heave, sat(d.surge - d.yaw)]
}

/// Direction as a multiplier: the sign of the configured value, so a
/// mistyped 2 still means forward and 0 disables the thruster.
fn dir_f64(dir: i8) -> f64 {
    f64::from(dir.signum())
}

/// Inverse of the thesis allocation: the demand a `go()` produces.
///
/// `pwm_us` is `[port, vertical, starboard]` as sent in `go()`; `directions`
/// is the ±1 motor direction of each (Neptunus: `[-1, 1, 1]`, the port motor
/// is wired reversed). Each thruster's output is
/// `u_i = directions_i · (pwm_i − 1500) / 500` clamped to `[-1, 1]`, then
/// `X = (u_port + u_starboard) / 2`, `M = (u_port − u_starboard) / 2`,
/// `Z = u_vertical` — the inverse of `u_port = sat(X+M)`, `u_vertical = Z`,
/// `u_starboard = sat(X−M)`. A direction other than ±1 counts by its sign
/// (0 disables the thruster).
///
/// Where the forward allocation saturated (|X| + |M| > 1) the original demand
/// is not recoverable; this returns the demand the thrusters actually
/// produce, which is what the simulator should feel.
pub fn demand_from_thrusters(pwm_us: [u16; 3], directions: [i8; 3]) -> Demand {
    let u = |i: usize| {
        let offset_us = f64::from(pwm_us[i]) - f64::from(PWM_NEUTRAL_US);
        sat(dir_f64(directions[i]) * offset_us / f64::from(PWM_HALF_RANGE_US))
    };
    let (port, vertical, starboard) = (u(0), u(1), u(2));
    Demand {
        surge: 0.5 * (port + starboard),
        heave: vertical,
        yaw: 0.5 * (port - starboard),
    }
}

/// The thesis allocation forward (for tests and the emulator's own checks):
/// pulse widths `[port, vertical, starboard]` in µs, 1000..=2000, rounded to
/// the nearest µs. Demands are saturated to `[-1, 1]` and NaN counts as 0.
pub fn thrusters_from_demand(d: &Demand, directions: [i8; 3]) -> [u16; 3] {
    let u = thruster_outputs(d);
    let mut pwm_us = [PWM_NEUTRAL_US; 3];
    for ((pwm, u), dir) in pwm_us.iter_mut().zip(u).zip(directions) {
        let offset_us = (dir_f64(dir) * u * f64::from(PWM_HALF_RANGE_US)).round();
        // |offset| ≤ 500 by construction, so the cast cannot wrap.
        *pwm = (f64::from(PWM_NEUTRAL_US) + offset_us) as u16;
    }
    pwm_us
}
