//! A 6-DOF model of Neptunus: the thesis' coefficients for the four degrees
//! of freedom it modelled, plus roll and pitch with the restoring moments of
//! the centres of gravity and buoyancy, and the thrusters where they sit.
//!
//! This module owns the equations of motion and their RK4 integration. It
//! must never do I/O, read a clock or draw random numbers: [`SixDofModel::step`]
//! is a plain function of its arguments, like [`super::thesis`].
//!
//! # Frames, units and signs
//! - `η = [x, y, z, φ, θ, ψ]`: NED position (m, z **down**, so z is depth)
//!   and the zyx Euler angles roll φ, pitch θ (positive = nose up) and
//!   heading ψ (positive clockwise seen from above). ψ is continuous, never
//!   wrapped, so the integrator never sees a jump. θ = ±90° is the Euler
//!   singularity; the restoring moment keeps the vehicle far from it.
//! - `ν = [u, v, w, p, q, r]`: body-frame surge, sway, heave (m/s, heave
//!   positive down) and roll, pitch, yaw rates (rad/s), over ground.
//! - Kinematics `η̇ = J(η)ν`, `J = diag(R(φ,θ,ψ), T(φ,θ))`, with `R = R_z(ψ)
//!   R_y(θ) R_x(φ)`.
//! - Kinetics, with `ν_r = ν − ν_c` the velocity relative to the water and
//!   `ν_c` the current in the body frame:
//!   `M ν̇_r + C_RB(ν_r) ν_r + D(ν_r) ν_r + g(η) = τ + τ_tether`,
//!   `ν̇ = ν̇_r − [ω × v_c; 0]` (a constant NED current seen from a rotating
//!   body). This is Fossen's formulation for an irrotational constant
//!   current, which holds because the body origin is the centre of gravity
//!   and `C_RB` is written independently of the linear velocity.
//!
//! # Terms and where the numbers come from
//! - **Mass** 3.46 kg and **yaw inertia** 0.399 kg·m² (thesis M_RB, eq. 12.9).
//! - **Roll and pitch inertia** 0.018 and 0.032 kg·m²: a uniform box of
//!   the vehicle's mass and OpenROV 2.x's outer size, about 30 × 20 × 15 cm
//!   (`m(b² + c²)/12`). No measurement exists. (The thesis' yaw inertia is
//!   ten times the same box's 0.038 kg·m², so its source may have included
//!   added inertia; we keep it for yaw so the shared DOF match the thesis.)
//! - **Added mass** for surge, sway, heave, yaw and the sway–yaw coupling:
//!   the thesis' M_A (eq. 12.8). Roll and pitch: 0.375 × the rigid-body
//!   inertia, the thesis' own ratio of added to rigid-body yaw inertia
//!   (0.1498 / 0.399).
//! - **Damping** for surge, sway, heave, yaw: the thesis' D_l and D_q (eqs.
//!   12.11–12.12). Pitch takes the thesis' yaw damping (the vehicle presents
//!   a similar length and area to rotation about both axes); roll half of it
//!   (about its long axis the vehicle sweeps much less water). With the
//!   restoring stiffness below this makes pitch well damped (linear damping
//!   ratio ≈ 0.66) and roll livelier (≈ 0.45).
//! - **Restoring**: weight W = m·g, buoyancy B = W + 0.0234 N (the thesis'
//!   slightly positive buoyancy, eq. 12.13), the centre of buoyancy
//!   `BG` = 2.5 cm above the centre of gravity. OpenROV 2.x carries its
//!   batteries in the two lower tubes and its buoyancy foam on top, which is
//!   what makes it self-righting; 2.5 cm is a guess at that separation
//!   giving roll and pitch periods of about 1.1 s and 1.5 s. Fossen's
//!   `g(η)` with `r_g = 0`, `r_b = [0, 0, −BG]`.
//! - **Thrusters**: the thesis writes `τ = [fX, 0, fZ, 2flM]` with f = 12 N,
//!   l = 0.045 m and `X = (u_p + u_s)/2`, `M = (u_p − u_s)/2`. Per thruster
//!   that is `τ_X = 6·(u_p + u_s)`, `τ_N = 6·0.09·(u_p − u_s)`, `τ_Z = 12·u_v`:
//!   exactly two 6 N horizontal thrusters at ±0.09 m and one 12 N vertical
//!   thruster. We mount them so: the horizontal pair 5 mm above the centre of
//!   gravity (full forward pitches the nose down by about 4°), the vertical
//!   thruster 5 mm aft of it (full down thrust pitches the nose up by about
//!   4°). Both offsets are small guesses standing for "not quite on the
//!   centre line"; the couplings they give are what a pilot sees.
//! - **Coriolis**: the rigid-body `C_RB` is kept (it is exact kinematics
//!   and couples the now-free roll and pitch). The added-mass `C_A` is left
//!   out, as the thesis did: with the thesis' coefficients its Munk moment
//!   `(Y_v̇ − X_u̇)·u·v` makes straight running at full speed unstable in yaw
//!   (the linearised sway–yaw system at 1.4 m/s has a negative determinant,
//!   about −140), which the thesis' test runs did not show; the coefficients
//!   were identified for a model without it.
//!
//! Like the thesis model there is no free surface: with no thrust the
//! vehicle rises slowly past z = 0.

use nalgebra::{Cholesky, Matrix3, Matrix6, Vector3, Vector6};

use super::environment::Environment;
use super::thesis::{ParamsError, ThesisParams};

/// Standard gravity (m/s²).
pub const GRAVITY_MPS2: f64 = 9.80665;

/// Where a thruster sits and which way it pushes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThrusterMount {
    /// Position relative to the centre of gravity, body frame (m).
    pub position_m: Vector3<f64>,
    /// Unit direction of positive thrust, body frame.
    pub axis: Vector3<f64>,
    /// Thrust at full forward effort (N).
    pub max_thrust_n: f64,
}

/// Coefficients of the 6-DOF model. `Default` is Neptunus as documented in
/// the module doc.
#[derive(Debug, Clone, PartialEq)]
pub struct SixDofParams {
    pub mass_kg: f64,
    /// `[I_xx, I_yy, I_zz]` about the centre of gravity (kg·m²).
    pub inertia_kgm2: Vector3<f64>,
    /// Added mass `M_A`, symmetric, `[u, v, w, p, q, r]` order.
    pub m_a: Matrix6<f64>,
    /// Linear damping, the diagonal of `D_l`.
    pub d_l: Vector6<f64>,
    /// Quadratic damping coefficients: `D_q = diag(d_q ∘ |ν_r|)`.
    pub d_q: Vector6<f64>,
    /// Buoyancy minus weight (N); positive = the vehicle floats up.
    pub buoyancy_excess_n: f64,
    /// Height of the centre of buoyancy above the centre of gravity (m).
    pub bg_m: f64,
    pub gravity_mps2: f64,
    /// `[port, vertical, starboard]`.
    pub thrusters: [ThrusterMount; 3],
}

impl Default for SixDofParams {
    fn default() -> Self {
        let thesis = ThesisParams::default();
        let mass_kg = thesis.m_rb[(0, 0)];
        let inertia_kgm2 = Vector3::new(0.018, 0.032, thesis.m_rb[(3, 3)]);
        let added_ratio = thesis.m_a[(3, 3)] / thesis.m_rb[(3, 3)];
        // The thesis' 4-DOF order is [u, v, w, r]; ours is [u, v, w, p, q, r].
        let map = [0, 1, 2, 5];
        let mut m_a = Matrix6::zeros();
        let mut d_l = Vector6::zeros();
        let mut d_q = Vector6::zeros();
        for (i, &a) in map.iter().enumerate() {
            for (j, &b) in map.iter().enumerate() {
                m_a[(a, b)] = thesis.m_a[(i, j)];
            }
            d_l[a] = thesis.d_l[i];
            d_q[a] = thesis.d_q[i];
        }
        m_a[(3, 3)] = added_ratio * inertia_kgm2[0];
        m_a[(4, 4)] = added_ratio * inertia_kgm2[1];
        d_l[4] = thesis.d_l[3];
        d_q[4] = thesis.d_q[3];
        d_l[3] = 0.5 * thesis.d_l[3];
        d_q[3] = 0.5 * thesis.d_q[3];
        let horizontal_n = 0.5 * thesis.thrust_n;
        let arm_m = 2.0 * thesis.arm_m;
        let horizontal_z_m = -0.005;
        let forward = Vector3::new(1.0, 0.0, 0.0);
        Self {
            mass_kg,
            inertia_kgm2,
            m_a,
            d_l,
            d_q,
            buoyancy_excess_n: thesis.g[2],
            bg_m: 0.025,
            gravity_mps2: GRAVITY_MPS2,
            thrusters: [
                ThrusterMount {
                    position_m: Vector3::new(-0.10, -arm_m, horizontal_z_m),
                    axis: forward,
                    max_thrust_n: horizontal_n,
                },
                ThrusterMount {
                    position_m: Vector3::new(-0.005, 0.0, -0.05),
                    axis: Vector3::new(0.0, 0.0, 1.0),
                    max_thrust_n: thesis.thrust_n,
                },
                ThrusterMount {
                    position_m: Vector3::new(-0.10, arm_m, horizontal_z_m),
                    axis: forward,
                    max_thrust_n: horizontal_n,
                },
            ],
        }
    }
}

/// Pose and velocities of the 6-DOF vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SixDofState {
    /// `[x_m, y_m, z_m, roll_rad, pitch_rad, psi_rad]`, NED, ψ continuous.
    pub eta: Vector6<f64>,
    /// `[u, v, w, p, q, r]` (m/s, rad/s), body frame, over ground.
    pub nu: Vector6<f64>,
}

impl SixDofState {
    fn axpy(&self, h: f64, k: &SixDofState) -> SixDofState {
        SixDofState {
            eta: self.eta + k.eta * h,
            nu: self.nu + k.nu * h,
        }
    }
}

/// Body-to-NED rotation `R_z(ψ) R_y(θ) R_x(φ)`.
pub fn rotation(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sf, cf) = roll.sin_cos();
    let (st, ct) = pitch.sin_cos();
    let (sp, cp) = yaw.sin_cos();
    #[rustfmt::skip]
    let r = Matrix3::new(
        cp * ct, -sp * cf + cp * st * sf, sp * sf + cp * cf * st,
        sp * ct, cp * cf + sf * st * sp,  -cp * sf + st * sp * cf,
        -st,     ct * sf,                 ct * cf,
    );
    r
}

/// The 6-DOF model with `M⁻¹` and the thruster map precomputed.
#[derive(Debug, Clone)]
pub struct SixDofModel {
    params: SixDofParams,
    m_inv: Matrix6<f64>,
    /// Generalised force of 1 N from each thruster.
    tau_per_n: [Vector6<f64>; 3],
    weight_n: f64,
    buoyancy_n: f64,
}

impl SixDofModel {
    /// Builds the model, rejecting non-finite coefficients, negative damping,
    /// a non-positive mass, inertia or metacentric height, and a mass matrix
    /// that is not symmetric positive definite.
    pub fn try_new(params: SixDofParams) -> Result<Self, ParamsError> {
        let finite = |name, ok: bool| {
            if ok {
                Ok(())
            } else {
                Err(ParamsError::NotFinite { name })
            }
        };
        finite("mass_kg", params.mass_kg.is_finite())?;
        finite(
            "inertia_kgm2",
            params.inertia_kgm2.iter().all(|x| x.is_finite()),
        )?;
        finite("m_a", params.m_a.iter().all(|x| x.is_finite()))?;
        finite("d_l", params.d_l.iter().all(|x| x.is_finite()))?;
        finite("d_q", params.d_q.iter().all(|x| x.is_finite()))?;
        finite("buoyancy_excess_n", params.buoyancy_excess_n.is_finite())?;
        finite("bg_m", params.bg_m.is_finite())?;
        finite("gravity_mps2", params.gravity_mps2.is_finite())?;
        finite(
            "thrusters",
            params.thrusters.iter().all(|t| {
                t.position_m.iter().all(|x| x.is_finite())
                    && t.axis.iter().all(|x| x.is_finite())
                    && t.max_thrust_n.is_finite()
            }),
        )?;
        for (name, d) in [("d_l", &params.d_l), ("d_q", &params.d_q)] {
            if let Some((index, &value)) = d.iter().enumerate().find(|(_, x)| **x < 0.0) {
                return Err(ParamsError::NegativeDamping { name, index, value });
            }
        }
        let positive = |name, value: f64, fix| {
            if value > 0.0 {
                Ok(())
            } else {
                Err(ParamsError::NotPositive { name, value, fix })
            }
        };
        positive("mass_kg", params.mass_kg, "give the vehicle's mass in kg")?;
        for i in 0..3 {
            positive(
                "inertia_kgm2",
                params.inertia_kgm2[i],
                "every principal moment of inertia is > 0",
            )?;
        }
        positive(
            "bg_m",
            params.bg_m,
            "the centre of buoyancy must sit above the centre of gravity or the vehicle capsizes",
        )?;
        positive("gravity_mps2", params.gravity_mps2, "use 9.80665")?;
        let mut m_rb = Matrix6::zeros();
        for i in 0..3 {
            m_rb[(i, i)] = params.mass_kg;
            m_rb[(i + 3, i + 3)] = params.inertia_kgm2[i];
        }
        let m = params.m_a + m_rb;
        // Cholesky only reads one triangle, so symmetry is checked separately.
        if (m - m.transpose()).abs().max() > 1e-12 * m.abs().max() {
            return Err(ParamsError::MassNotPositiveDefinite);
        }
        let m_inv = Cholesky::new(m)
            .ok_or(ParamsError::MassNotPositiveDefinite)?
            .inverse();
        let tau_per_n = params.thrusters.map(|t| {
            let moment = t.position_m.cross(&t.axis);
            Vector6::new(
                t.axis[0], t.axis[1], t.axis[2], moment[0], moment[1], moment[2],
            )
        });
        let weight_n = params.mass_kg * params.gravity_mps2;
        Ok(Self {
            buoyancy_n: weight_n + params.buoyancy_excess_n,
            weight_n,
            params,
            m_inv,
            tau_per_n,
        })
    }

    pub fn params(&self) -> &SixDofParams {
        &self.params
    }

    /// Generalised force of the three thrusters pushing `thrust_n`
    /// (`[port, vertical, starboard]`, N along each one's axis).
    pub fn tau(&self, thrust_n: &[f64; 3]) -> Vector6<f64> {
        self.tau_per_n[0] * thrust_n[0]
            + self.tau_per_n[1] * thrust_n[1]
            + self.tau_per_n[2] * thrust_n[2]
    }

    /// Fossen's restoring forces `g(η)` for `r_g = 0`, `r_b = [0, 0, −BG]`.
    pub fn restoring(&self, roll: f64, pitch: f64) -> Vector6<f64> {
        let (sf, cf) = roll.sin_cos();
        let (st, ct) = pitch.sin_cos();
        let w_minus_b = self.weight_n - self.buoyancy_n;
        let bg_b = self.params.bg_m * self.buoyancy_n;
        Vector6::new(
            w_minus_b * st,
            -w_minus_b * ct * sf,
            -w_minus_b * ct * cf,
            bg_b * ct * sf,
            bg_b * st,
            0.0,
        )
    }

    /// Time derivative `(η̇, ν̇)` for a generalised thruster force `tau`.
    pub fn derivative(
        &self,
        s: &SixDofState,
        tau: &Vector6<f64>,
        env: &Environment,
    ) -> SixDofState {
        let p = &self.params;
        let (roll, pitch, yaw) = (s.eta[3], s.eta[4], s.eta[5]);
        let r = rotation(roll, pitch, yaw);
        let v = Vector3::new(s.nu[0], s.nu[1], s.nu[2]);
        let w = Vector3::new(s.nu[3], s.nu[4], s.nu[5]);
        let (sf, cf) = roll.sin_cos();
        let (st, ct) = pitch.sin_cos();
        let tt = st / ct;
        #[rustfmt::skip]
        let t = Matrix3::new(
            1.0, sf * tt,  cf * tt,
            0.0, cf,       -sf,
            0.0, sf / ct,  cf / ct,
        );
        let velocity_ned = r * v;
        let angle_rates = t * w;

        let current_body = r.transpose() * env.current_ned_mps;
        let v_r = v - current_body;
        let nu_r = Vector6::new(v_r[0], v_r[1], v_r[2], w[0], w[1], w[2]);
        // C_RB(ν_r)ν_r = [m ω × v_r; ω × (I ω)] with the origin at the CG.
        let inertia_w = p.inertia_kgm2.component_mul(&w);
        let lin = w.cross(&v_r) * p.mass_kg;
        let ang = w.cross(&inertia_w);
        let coriolis = Vector6::new(lin[0], lin[1], lin[2], ang[0], ang[1], ang[2]);
        let damping = (p.d_l + p.d_q.component_mul(&nu_r.abs())).component_mul(&nu_r);
        let position = Vector3::new(s.eta[0], s.eta[1], s.eta[2]);
        let tether_ned = env.tether_force_ned_n(&position, &(velocity_ned - env.current_ned_mps));
        let tb = r.transpose() * tether_ned;
        let tether = Vector6::new(tb[0], tb[1], tb[2], 0.0, 0.0, 0.0);
        let nu_r_dot =
            self.m_inv * (tau + tether - coriolis - damping - self.restoring(roll, pitch));
        // A constant NED current turns in the body frame as the body turns.
        let current_dot = -w.cross(&current_body);
        SixDofState {
            eta: Vector6::new(
                velocity_ned[0],
                velocity_ned[1],
                velocity_ned[2],
                angle_rates[0],
                angle_rates[1],
                angle_rates[2],
            ),
            nu: nu_r_dot
                + Vector6::new(
                    current_dot[0],
                    current_dot[1],
                    current_dot[2],
                    0.0,
                    0.0,
                    0.0,
                ),
        }
    }

    /// One RK4 step of length `dt_s` with the thrusters held at `thrust_n`
    /// (zero-order hold, as the board holds a `go()` until the next one). Pure.
    pub fn step(
        &self,
        s: &SixDofState,
        thrust_n: &[f64; 3],
        env: &Environment,
        dt_s: f64,
    ) -> SixDofState {
        let tau = self.tau(thrust_n);
        let half = 0.5 * dt_s;
        let k1 = self.derivative(s, &tau, env);
        let k2 = self.derivative(&s.axpy(half, &k1), &tau, env);
        let k3 = self.derivative(&s.axpy(half, &k2), &tau, env);
        let k4 = self.derivative(&s.axpy(dt_s, &k3), &tau, env);
        let sixth = dt_s / 6.0;
        SixDofState {
            eta: s.eta + (k1.eta + (k2.eta + k3.eta) * 2.0 + k4.eta) * sixth,
            nu: s.nu + (k1.nu + (k2.nu + k3.nu) * 2.0 + k4.nu) * sixth,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> SixDofModel {
        SixDofModel::try_new(SixDofParams::default()).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn shared_dof_carry_the_thesis_coefficients() {
        let p = SixDofParams::default();
        let t = ThesisParams::default();
        assert_eq!(p.m_a[(1, 5)], t.m_a[(1, 3)]);
        assert_eq!(p.m_a[(5, 1)], t.m_a[(3, 1)]);
        assert_eq!(p.d_q[2], t.d_q[2]);
        assert_eq!(p.d_l[5], t.d_l[3]);
        assert_eq!(p.buoyancy_excess_n, 0.0234);
    }

    #[test]
    fn thrusters_reproduce_the_thesis_tau() {
        // X = 0.3, Z = −0.4, M = 0.2 → u_p = 0.5, u_v = −0.4, u_s = 0.1.
        let m = model();
        let tau = m.tau(&[0.5 * 6.0, -0.4 * 12.0, 0.1 * 6.0]);
        assert!((tau[0] - 12.0 * 0.3).abs() < 1e-12);
        assert!((tau[2] - 12.0 * -0.4).abs() < 1e-12);
        assert!((tau[5] - 2.0 * 12.0 * 0.045 * 0.2).abs() < 1e-12);
        assert_eq!(tau[1], 0.0);
        // Forward thrust above the CG pitches the nose down; down thrust
        // aft of it pitches the nose up.
        assert!(m.tau(&[6.0, 0.0, 6.0])[4] < 0.0);
        assert!(m.tau(&[0.0, 12.0, 0.0])[4] > 0.0);
    }

    #[test]
    fn restoring_rights_the_vehicle() {
        let m = model();
        let g = m.restoring(0.2, -0.1);
        assert!(g[3] > 0.0, "roll to starboard → moment to port on the rhs");
        assert!(g[4] < 0.0);
        // Level: only the heave term, the thesis' 0.0234 N (up).
        let level = m.restoring(0.0, 0.0);
        assert!((level[2] - 0.0234).abs() < 1e-9);
        assert_eq!(level[3], 0.0);
    }

    #[test]
    fn rotation_is_orthonormal_and_yaw_turns_north_to_east() {
        let r = rotation(0.3, -0.2, 1.0);
        assert!((r * r.transpose() - Matrix3::identity()).abs().max() < 1e-12);
        let east = rotation(0.0, 0.0, std::f64::consts::FRAC_PI_2) * Vector3::new(1.0, 0.0, 0.0);
        assert!((east - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12);
        // Nose up: forward motion goes up (z decreases).
        let up = rotation(0.0, 0.2, 0.0) * Vector3::new(1.0, 0.0, 0.0);
        assert!(up[2] < 0.0);
    }

    #[test]
    fn bad_params_are_rejected() {
        let p = SixDofParams {
            bg_m: -0.01,
            ..SixDofParams::default()
        };
        assert!(matches!(
            SixDofModel::try_new(p),
            Err(ParamsError::NotPositive { name: "bg_m", .. })
        ));
        let mut p = SixDofParams::default();
        p.d_q[3] = -1.0;
        assert!(matches!(
            SixDofModel::try_new(p),
            Err(ParamsError::NegativeDamping { index: 3, .. })
        ));
        let mut p = SixDofParams::default();
        p.inertia_kgm2[1] = f64::NAN;
        assert!(matches!(
            SixDofModel::try_new(p),
            Err(ParamsError::NotFinite { .. })
        ));
        let mut p = SixDofParams::default();
        p.m_a[(0, 1)] = 5.0;
        assert_eq!(
            SixDofModel::try_new(p).err(),
            Some(ParamsError::MassNotPositiveDefinite)
        );
    }
}
