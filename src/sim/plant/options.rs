//! The simulator's options (`[emulator.sim]`): which model runs and which
//! imperfections are on, and the check that every value is usable.
//!
//! Owns [`ModelKind`], [`SimOptions`] and [`SimError`]. Every rejected value
//! is named by its key under `[emulator.sim]`, with the fix.

use serde::{Deserialize, Serialize};

use crate::sim::environment::{CurrentOptions, TetherOptions};
use crate::sim::sensors::NoiseOptions;
use crate::sim::thesis::ParamsError;

/// Which equations of motion run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// [`crate::sim::six_dof`]: roll and pitch free, restoring moments, thruster
    /// couplings.
    #[default]
    SixDof,
    /// [`crate::sim::thesis`]: the thesis' 4-DOF model, roll and pitch 0.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Plant;

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
}
