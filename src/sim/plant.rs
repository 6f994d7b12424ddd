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

use std::time::Duration;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::environment::{CurrentOptions, Environment, TetherOptions};
use super::sensors::{
    NoiseOptions, Pose, Readings, SensorImperfections, SensorModel, SensorParams, SensorStats,
};
use super::six_dof::{SixDofModel, SixDofParams, SixDofState};
use super::thesis::{Demand, ParamsError, SimState, ThesisModel, ThesisParams};
use super::thruster::Thruster;

/// Which equations of motion run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// [`super::six_dof`]: roll and pitch free, restoring moments, thruster
    /// couplings.
    #[default]
    SixDof,
    /// [`super::thesis`]: the thesis' 4-DOF model, roll and pitch 0.
    #[serde(rename = "thesis-4dof")]
    Thesis4Dof,
}

/// Simulator options (`[emulator.sim]`). `Default` is the most realistic
/// simulation: 6-DOF, thrusters with a 0.2 s rise time and weaker reverse,
/// the tether's drag, sensor noise and bias, depth at 1 Hz; no wild points
/// and still water. [`SimOptions::ideal_thesis`] is the thesis' model with
/// perfect thrusters and sensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimOptions {
    pub model: ModelKind,
    /// 10–90 % rise time of a thruster's thrust after a step command (s);
    /// 0 = thrust follows the command at once.
    pub thruster_rise_time_s: f64,
    /// Reverse thrust per unit ESC effort relative to forward, in (0, 1].
    pub reverse_thrust_ratio: f64,
    pub tether: TetherOptions,
    pub current: CurrentOptions,
    pub noise: NoiseOptions,
    /// How often the pressure sensor gives a new depth (Hz); 0 = at every
    /// reading.
    pub depth_update_hz: f64,
    /// Probability per reading of a wild point, for depth and heading each.
    pub wild_rate: f64,
    /// Seed of the sensor noise.
    pub seed: u64,
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            model: ModelKind::SixDof,
            thruster_rise_time_s: 0.2,
            reverse_thrust_ratio: 0.5,
            tether: TetherOptions::default(),
            current: CurrentOptions::default(),
            noise: NoiseOptions::default(),
            depth_update_hz: 1.0,
            wild_rate: 0.0,
            seed: 0,
        }
    }
}

/// Why simulator options cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// `key` is relative to `[emulator.sim]`, e.g. `tether.diameter_m`.
    #[error("simulator option {key} = {value} is out of range — {fix}")]
    Invalid {
        key: &'static str,
        value: f64,
        fix: &'static str,
    },
    #[error(transparent)]
    Params(#[from] ParamsError),
}

impl SimOptions {
    /// The thesis' 4-DOF model with ideal parts: thrust follows the command
    /// at once and reverse is as strong as forward, no tether, still water,
    /// perfect sensors reporting depth at every reading, no wild points.
    ///
    /// This is the simulator as it was before the plant existed, with one
    /// difference: the plant feels the ESC outputs, after the board's
    /// reverse multiplier. For the old trajectories exactly, also set the
    /// board's `reverse_multiplier` to 1 (`EmulatorOptions::ideal_thesis`).
    pub fn ideal_thesis() -> Self {
        Self {
            model: ModelKind::Thesis4Dof,
            thruster_rise_time_s: 0.0,
            reverse_thrust_ratio: 1.0,
            tether: TetherOptions::off(),
            current: CurrentOptions::default(),
            noise: NoiseOptions::none(),
            depth_update_hz: 0.0,
            wild_rate: 0.0,
            seed: 0,
        }
    }

    /// Checks every value; the error names the key, the value and the fix.
    pub fn validate(&self) -> Result<(), SimError> {
        fn check(
            key: &'static str,
            value: f64,
            ok: bool,
            fix: &'static str,
        ) -> Result<(), SimError> {
            // NaN fails every comparison, so `ok` is false for it.
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(SimError::Invalid { key, value, fix })
            }
        }
        let rise = self.thruster_rise_time_s;
        check(
            "thruster_rise_time_s",
            rise,
            (0.0..=1.0).contains(&rise),
            "use a rise time in 0..1 s (0.1–0.3 s is typical of small ROV thrusters; 0 = no lag)",
        )?;
        let ratio = self.reverse_thrust_ratio;
        check(
            "reverse_thrust_ratio",
            ratio,
            ratio > 0.0 && ratio <= 1.0,
            "use a ratio in (0, 1]: reverse thrust per unit effort relative to forward (default 0.5)",
        )?;
        let t = &self.tether;
        check(
            "tether.diameter_m",
            t.diameter_m,
            (0.0..=0.1).contains(&t.diameter_m),
            "use the tether's outer diameter in metres, 0..0.1 (default 0.003)",
        )?;
        check(
            "tether.drag_coefficient",
            t.drag_coefficient,
            (0.0..=10.0).contains(&t.drag_coefficient),
            "use a drag coefficient in 0..10 (a cylinder in cross-flow is about 1.2)",
        )?;
        check(
            "tether.min_length_m",
            t.min_length_m,
            (0.0..=10_000.0).contains(&t.min_length_m),
            "use a length in metres, 0..10000 (default 2)",
        )?;
        check(
            "tether.water_density_kg_m3",
            t.water_density_kg_m3,
            (900.0..=1100.0).contains(&t.water_density_kg_m3),
            "use 1000 for fresh water or about 1025 for salt water",
        )?;
        let c = &self.current;
        check(
            "current.speed_mps",
            c.speed_mps,
            (0.0..=5.0).contains(&c.speed_mps),
            "use a speed in 0..5 m/s; point it with current.direction_deg",
        )?;
        check(
            "current.direction_deg",
            c.direction_deg,
            (-360.0..=360.0).contains(&c.direction_deg),
            "use the direction the water flows towards, degrees from north in -360..360",
        )?;
        for (key, value) in self.noise.fields() {
            let (key, ok, fix) = noise_rule(key, value);
            check(key, value, ok, fix)?;
        }
        check(
            "depth_update_hz",
            self.depth_update_hz,
            (0.0..=1000.0).contains(&self.depth_update_hz),
            "use a rate in 0..1000 Hz (the board's pressure sensor: 1; 0 = every reading)",
        )?;
        check(
            "wild_rate",
            self.wild_rate,
            (0.0..=1.0).contains(&self.wild_rate),
            "use a probability per reading in 0..1",
        )?;
        Ok(())
    }
}

/// The key under `[emulator.sim]`, whether the value is allowed and the fix.
fn noise_rule(field: &'static str, value: f64) -> (&'static str, bool, &'static str) {
    // Keys are listed in full so messages can borrow them statically.
    let key = match field {
        "heading_std_deg" => "noise.heading_std_deg",
        "heading_bias_deg" => "noise.heading_bias_deg",
        "depth_std_m" => "noise.depth_std_m",
        "depth_bias_m" => "noise.depth_bias_m",
        "pitch_std_deg" => "noise.pitch_std_deg",
        "pitch_bias_deg" => "noise.pitch_bias_deg",
        "roll_std_deg" => "noise.roll_std_deg",
        _ => "noise.roll_bias_deg",
    };
    if field.ends_with("_std_deg") {
        (
            key,
            (0.0..=45.0).contains(&value),
            "use a standard deviation in 0..45 degrees (0 = no noise)",
        )
    } else if field.ends_with("_bias_deg") {
        (
            key,
            (-180.0..=180.0).contains(&value),
            "use a bias in -180..180 degrees",
        )
    } else if field.ends_with("_std_m") {
        (
            key,
            (0.0..=10.0).contains(&value),
            "use a standard deviation in 0..10 m (0 = no noise)",
        )
    } else {
        (
            key,
            (-10.0..=10.0).contains(&value),
            "use a bias in -10..10 m",
        )
    }
}

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
    fn defaults_and_ideal_are_valid_and_differ_where_documented() {
        assert_eq!(SimOptions::default().validate(), Ok(()));
        assert_eq!(SimOptions::ideal_thesis().validate(), Ok(()));
        let d = SimOptions::default();
        assert_eq!(d.model, ModelKind::SixDof);
        assert!(d.tether.enabled && d.noise != NoiseOptions::none());
        assert_eq!((d.depth_update_hz, d.wild_rate), (1.0, 0.0));
        let i = SimOptions::ideal_thesis();
        assert_eq!(i.model, ModelKind::Thesis4Dof);
        assert_eq!((i.thruster_rise_time_s, i.reverse_thrust_ratio), (0.0, 1.0));
    }

    #[test]
    fn every_bad_value_is_named() {
        type Spoil = fn(&mut SimOptions);
        let cases: [(&str, Spoil); 6] = [
            ("thruster_rise_time_s", |o| o.thruster_rise_time_s = 2.0),
            ("reverse_thrust_ratio", |o| o.reverse_thrust_ratio = 1.5),
            ("tether.drag_coefficient", |o| {
                o.tether.drag_coefficient = f64::NAN
            }),
            ("current.direction_deg", |o| {
                o.current.direction_deg = f64::INFINITY
            }),
            ("noise.roll_bias_deg", |o| o.noise.roll_bias_deg = 200.0),
            ("noise.depth_bias_m", |o| o.noise.depth_bias_m = -11.0),
        ];
        for (key, spoil) in cases {
            let mut o = SimOptions::default();
            spoil(&mut o);
            match o.validate() {
                Err(SimError::Invalid { key: k, .. }) => assert_eq!(k, key),
                other => panic!("{key}: {other:?}"),
            }
            assert!(Plant::new(&o, [1, 1, 1]).is_err());
        }
    }

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
