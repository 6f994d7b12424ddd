//! The simulated vehicle as the board sees it: ESC pulses in, sensor
//! readings out, whichever model runs underneath.
//!
//! This module owns the wiring of the simulator's parts — thruster
//! dynamics ([`super::thruster`]), one of the two vehicle models
//! ([`super::thesis`] or [`super::six_dof`]), the water and tether
//! ([`super::environment`]) and the sensors with their imperfections
//! ([`super::sensors`]) — and the options that choose them. It must never
//! do I/O or read a clock: the board emulator passes the ESC outputs and the
//! board time in. Its only randomness is the sensor noise, seeded from
//! [`SimOptions::seed`].
//!
//! The plant is driven by what the firmware wrote to the ESCs, after the
//! board's deadzone and reverse multiplier: those belong to the firmware
//! (`firmware::emulator`), the plant only knows motors and water.
//!
//! The options that choose the parts are in `options` (re-exported here).

mod options;

use std::time::Duration;

use nalgebra::Vector3;

pub use options::{ModelKind, SimError, SimOptions};

use super::environment::Environment;
use super::sensors::{Pose, Readings, SensorImperfections, SensorModel, SensorParams, SensorStats};
use super::six_dof::{SixDofModel, SixDofParams, SixDofState};
use super::thesis::{Demand, SimState, ThesisModel, ThesisParams};
use super::thruster::Thruster;

/// The simulated vehicle's true state, in plain units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Truth {
    pub north_m: f64,
    pub east_m: f64,
    pub depth_m: f64,
    pub roll_rad: f64,
    pub pitch_rad: f64,
    /// Continuous (not wrapped).
    pub heading_rad: f64,
    pub surge_mps: f64,
    pub sway_mps: f64,
    /// Positive down.
    pub heave_mps: f64,
    pub roll_rate_rps: f64,
    pub pitch_rate_rps: f64,
    pub yaw_rate_rps: f64,
    /// `[port, vertical, starboard]` (N) along the vehicle's axes: positive
    /// pushes forward (horizontal thrusters) or down (vertical).
    pub thrust_n: [f64; 3],
    pub tether_length_m: f64,
}

#[derive(Debug, Clone)]
enum Model {
    Thesis {
        model: Box<ThesisModel>,
        state: SimState,
    },
    SixDof {
        model: Box<SixDofModel>,
        state: SixDofState,
    },
}

/// Thrusters, vehicle, water and sensors (sans-IO). See the module doc.
#[derive(Debug, Clone)]
pub struct Plant {
    model: Model,
    /// Wiring direction of each thruster as a multiplier (its sign).
    directions: [f64; 3],
    /// Thrust at full forward effort per thruster (N).
    max_thrust_n: [f64; 3],
    thrusters: [Thruster; 3],
    env: Environment,
    sensors: SensorModel,
    imperfections: SensorImperfections,
}

impl Plant {
    /// A plant at rest at the origin, heading north. `wiring_directions`
    /// are the thrusters' directions as wired (`[port, vertical, starboard]`,
    /// Neptunus `[-1, 1, 1]`); only the sign counts and 0 disables a thruster.
    pub fn new(opts: &SimOptions, wiring_directions: [i8; 3]) -> Result<Self, SimError> {
        opts.validate()?;
        let (model, max_thrust_n) = match opts.model {
            ModelKind::Thesis4Dof => {
                let model = ThesisModel::try_new(ThesisParams::default())?;
                let f = model.params().thrust_n;
                (
                    Model::Thesis {
                        model: Box::new(model),
                        state: SimState::default(),
                    },
                    // The per-thruster reading of τ = [fX, 0, fZ, 2flM]
                    // (see `six_dof`): 6 N, 12 N, 6 N at full demand.
                    [0.5 * f, f, 0.5 * f],
                )
            }
            ModelKind::SixDof => {
                let model = SixDofModel::try_new(SixDofParams::default())?;
                let max = model.params().thrusters.map(|t| t.max_thrust_n);
                (
                    Model::SixDof {
                        model: Box::new(model),
                        state: SixDofState::default(),
                    },
                    max,
                )
            }
        };
        let thruster = Thruster::new(opts.thruster_rise_time_s, opts.reverse_thrust_ratio);
        let sensors = SensorModel::new(SensorParams::default());
        Ok(Self {
            model,
            directions: wiring_directions.map(|d| f64::from(d.signum())),
            max_thrust_n,
            thrusters: [thruster.clone(), thruster.clone(), thruster],
            env: Environment::new(&opts.current, &opts.tether),
            sensors,
            imperfections: SensorImperfections::new(
                opts.noise.clone(),
                opts.depth_update_hz,
                opts.wild_rate,
                opts.seed,
            ),
        })
    }

    /// Which model runs.
    pub fn model_kind(&self) -> ModelKind {
        match self.model {
            Model::Thesis { .. } => ModelKind::Thesis4Dof,
            Model::SixDof { .. } => ModelKind::SixDof,
        }
    }

    /// Advances by `dt_s` with the ESCs driven at `esc_us`
    /// (`[port, vertical, starboard]`, held over the step). A step that is
    /// not a positive finite time does nothing.
    pub fn step(&mut self, esc_us: [u16; 3], dt_s: f64) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        let mut u = [0.0; 3];
        for i in 0..3 {
            let t = &mut self.thrusters[i];
            t.command_us(esc_us[i]);
            let mean_effort = t.advance(dt_s);
            u[i] = self.directions[i] * t.level(mean_effort);
        }
        match &mut self.model {
            Model::Thesis { model, state } => {
                // u is each thruster's output as in the thesis' allocation,
                // so this is the inverse allocation of `demand_from_thrusters`.
                let d = Demand {
                    surge: 0.5 * (u[0] + u[2]),
                    heave: u[1],
                    yaw: 0.5 * (u[0] - u[2]),
                };
                *state = if self.env.is_calm() {
                    // Bit for bit the thesis model's own step.
                    model.step(state, &d, dt_s)
                } else {
                    model.step_in(state, &d, &self.env, dt_s)
                };
            }
            Model::SixDof { model, state } => {
                let thrust = [
                    u[0] * self.max_thrust_n[0],
                    u[1] * self.max_thrust_n[1],
                    u[2] * self.max_thrust_n[2],
                ];
                *state = model.step(state, &thrust, &self.env, dt_s);
            }
        }
    }

    /// The true state.
    pub fn truth(&self) -> Truth {
        let thrust_n = std::array::from_fn(|i| {
            let t = &self.thrusters[i];
            self.directions[i] * t.level(t.effort()) * self.max_thrust_n[i]
        });
        let mut truth = match &self.model {
            Model::Thesis { state: s, .. } => Truth {
                north_m: s.eta[0],
                east_m: s.eta[1],
                depth_m: s.eta[2],
                heading_rad: s.eta[3],
                surge_mps: s.nu[0],
                sway_mps: s.nu[1],
                heave_mps: s.nu[2],
                yaw_rate_rps: s.nu[3],
                ..Truth::default()
            },
            Model::SixDof { state: s, .. } => Truth {
                north_m: s.eta[0],
                east_m: s.eta[1],
                depth_m: s.eta[2],
                roll_rad: s.eta[3],
                pitch_rad: s.eta[4],
                heading_rad: s.eta[5],
                surge_mps: s.nu[0],
                sway_mps: s.nu[1],
                heave_mps: s.nu[2],
                roll_rate_rps: s.nu[3],
                pitch_rate_rps: s.nu[4],
                yaw_rate_rps: s.nu[5],
                ..Truth::default()
            },
        };
        truth.thrust_n = thrust_n;
        truth.tether_length_m = if self.env.tether_drag_per_length > 0.0 {
            self.env
                .tether_length_m(&Vector3::new(truth.north_m, truth.east_m, truth.depth_m))
        } else {
            0.0
        };
        truth
    }

    /// Puts the vehicle at a pose, level and at rest, thrusters stopped (a
    /// scenario start). The tether's launch point stays at the origin.
    pub fn set_pose(&mut self, north_m: f64, east_m: f64, depth_m: f64, heading_rad: f64) {
        match &mut self.model {
            Model::Thesis { state, .. } => {
                *state = SimState::default();
                state.eta = [north_m, east_m, depth_m, heading_rad].into();
            }
            Model::SixDof { state, .. } => {
                *state = SixDofState::default();
                state.eta = [north_m, east_m, depth_m, 0.0, 0.0, heading_rad].into();
            }
        }
        for t in &mut self.thrusters {
            t.reset();
        }
        self.imperfections.reset_hold();
    }

    /// Sets the body velocities the 4-DOF model has (surge, sway, heave in
    /// m/s, yaw rate in rad/s); roll and pitch rates become 0.
    pub fn set_velocities(
        &mut self,
        surge_mps: f64,
        sway_mps: f64,
        heave_mps: f64,
        yaw_rate_rps: f64,
    ) {
        match &mut self.model {
            Model::Thesis { state, .. } => {
                state.nu = [surge_mps, sway_mps, heave_mps, yaw_rate_rps].into();
            }
            Model::SixDof { state, .. } => {
                state.nu = [surge_mps, sway_mps, heave_mps, 0.0, 0.0, yaw_rate_rps].into();
            }
        }
    }

    /// Sets roll and pitch (rad), rates 0 (6-DOF only; the thesis model has
    /// neither, and ignores this).
    pub fn set_attitude(&mut self, roll_rad: f64, pitch_rad: f64) {
        if let Model::SixDof { state, .. } = &mut self.model {
            state.eta[3] = roll_rad;
            state.eta[4] = pitch_rad;
            state.nu[3] = 0.0;
            state.nu[4] = 0.0;
        }
    }

    /// What a perfect board would report now.
    pub fn read_clean(&self) -> Readings {
        let t = self.truth();
        let pose = Pose {
            depth_m: t.depth_m,
            heading_rad: t.heading_rad,
            pitch_rad: t.pitch_rad,
            roll_rad: t.roll_rad,
        };
        // `fthr` is the board's forward thrust setting: the commanded
        // surge, before the thrusters' lag.
        let cmd = |i: usize| {
            let th = &self.thrusters[i];
            self.directions[i] * th.level(th.command())
        };
        let fthr_pct = 0.5 * (cmd(0) + cmd(2)) * 100.0;
        let efforts = self.thrusters.each_ref().map(Thruster::effort);
        self.sensors.read_pose(&pose, fthr_pct, &efforts)
    }

    /// What the board reports at board time `t`: noise and bias, the
    /// pressure sensor's sample-and-hold, wild points. Deterministic for a
    /// seed and a sequence of calls.
    pub fn read(&mut self, t: Duration) -> Readings {
        let clean = self.read_clean();
        let k = self.sensors.params().water.depth_m_per_mbar();
        self.imperfections.apply(t, &clean, k)
    }

    /// The depth the pressure sensor last measured (no wild point), or the
    /// perfect reading if it has not measured yet: what `dzer()` zeroes.
    pub fn depth_sample_m(&self) -> f64 {
        self.imperfections
            .held_depth_m()
            .unwrap_or_else(|| self.read_clean().depth_m)
    }

    /// What the sensor imperfections did so far.
    pub fn sensor_stats(&self) -> SensorStats {
        self.imperfections.stats()
    }

    /// The water and tether.
    pub fn environment(&self) -> &Environment {
        &self.env
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_step_is_ignored_and_a_disabled_thruster_pushes_nothing() {
        let mut p =
            Plant::new(&SimOptions::ideal_thesis(), [0, 1, 1]).unwrap_or_else(|e| panic!("{e}"));
        p.step([2000; 3], f64::NAN);
        p.step([2000; 3], -0.01);
        assert_eq!(p.truth(), Truth::default());
        p.step([2000, 1500, 1500], 0.01);
        assert_eq!(p.truth().thrust_n, [0.0; 3]);
        assert_eq!(p.truth().surge_mps, 0.0);
    }

    #[test]
    fn set_pose_starts_level_at_rest_with_thrusters_stopped() {
        let mut p =
            Plant::new(&SimOptions::default(), [-1, 1, 1]).unwrap_or_else(|e| panic!("{e}"));
        for _ in 0..100 {
            p.step([1200, 1800, 1800], 0.01);
        }
        p.set_attitude(0.1, 0.2);
        p.set_pose(3.0, 4.0, 5.0, 7.0);
        let t = p.truth();
        assert_eq!(
            (t.north_m, t.east_m, t.depth_m, t.heading_rad),
            (3.0, 4.0, 5.0, 7.0)
        );
        assert_eq!(
            (t.roll_rad, t.pitch_rad, t.surge_mps, t.yaw_rate_rps),
            (0.0, 0.0, 0.0, 0.0)
        );
        assert_eq!(t.thrust_n, [0.0; 3]);
        // √(3² + 4² + 5²) beyond the 2 m minimum.
        assert!((t.tether_length_m - 50f64.sqrt()).abs() < 1e-12);
    }
}
