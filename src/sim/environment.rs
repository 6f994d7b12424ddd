//! The water around the vehicle: a constant current and the umbilical's
//! drag.
//!
//! This module owns the external forces that are not the vehicle's own
//! hydrodynamics: what the current does to the velocity the damping sees,
//! and the tether's drag. It must never do I/O, read a clock or draw random
//! numbers; both vehicle models ([`super::thesis`] and [`super::six_dof`])
//! take an [`Environment`] and stay pure.
//!
//! # Current
//! A constant, uniform, irrotational current in NED (horizontal only): speed
//! and the compass direction it flows **towards**. Hydrodynamic damping and
//! tether drag act on the velocity relative to the water, so a vehicle with
//! no thrust ends up drifting with the current.
//!
//! # Tether
//! A lumped drag on the vehicle, opposing its velocity relative to the water:
//! `F = −½·ρ·C_d·d·L·|v_r|·v_r`, the drag of a cylinder of diameter `d` and
//! length `L` moving broadside at the vehicle's relative velocity `v_r`.
//! Deployed length `L = max(L_min, |p − p_launch|)`: the tether runs in a
//! straight line from the launch point at the surface (the NED origin; a
//! scenario start with [`super::Plant::set_pose`] does not move it) to the
//! vehicle, and never shorter than the slack the pilot pays out before
//! diving. This is an upper bound — the real tether hangs in a curve and
//! its far end moves slower than the vehicle — which is the conservative
//! side for a pilot or an autopilot. The force acts at the centre of
//! gravity: the moment of an off-centre attachment is left out, as no
//! measurement of it exists for Neptunus.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Current options (`[emulator.sim.current]`). Default: still water (a pool).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CurrentOptions {
    /// Speed of the water over ground (m/s).
    pub speed_mps: f64,
    /// Direction the water flows **towards**, degrees clockwise from north.
    pub direction_deg: f64,
}

impl CurrentOptions {
    /// The current as a NED velocity (m/s), vertical component 0.
    pub fn velocity_ned_mps(&self) -> Vector3<f64> {
        let (sin, cos) = self.direction_deg.to_radians().sin_cos();
        Vector3::new(self.speed_mps * cos, self.speed_mps * sin, 0.0)
    }
}

/// Tether options (`[emulator.sim.tether]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TetherOptions {
    /// Whether the tether's drag is simulated.
    pub enabled: bool,
    /// Outer diameter (m). Default 3 mm, a thin twisted-pair tether of the
    /// kind OpenROV 2.x used (an assumption, not a measurement: measure yours).
    pub diameter_m: f64,
    /// Drag coefficient of a cylinder in cross-flow. Default 1.2, the
    /// textbook value for a smooth cylinder at the Reynolds numbers of a
    /// few-mm cable at walking pace (10³–10⁴).
    pub drag_coefficient: f64,
    /// Tether deployed however close the vehicle is to the launch point (m).
    /// Default 2 m: the slack paid out to leave the pool edge.
    pub min_length_m: f64,
    /// Water density (kg/m³): 1000 fresh, about 1025 salt.
    pub water_density_kg_m3: f64,
}

impl Default for TetherOptions {
    fn default() -> Self {
        Self {
            enabled: true,
            diameter_m: 0.003,
            drag_coefficient: 1.2,
            min_length_m: 2.0,
            water_density_kg_m3: 1000.0,
        }
    }
}

impl TetherOptions {
    /// No tether drag.
    pub fn off() -> Self {
        Self {
            enabled: false,
            ..Self::default()
        }
    }

    /// `½·ρ·C_d·d` (N·s²/m³): drag per metre of tether per (m/s)².
    pub fn drag_per_length(&self) -> f64 {
        if self.enabled {
            0.5 * self.water_density_kg_m3 * self.drag_coefficient * self.diameter_m
        } else {
            0.0
        }
    }
}

/// Everything outside the vehicle that pushes it, precomputed for the
/// integrators.
#[derive(Debug, Clone, PartialEq)]
pub struct Environment {
    /// Water velocity over ground, NED (m/s).
    pub current_ned_mps: Vector3<f64>,
    /// `½·ρ·C_d·d` of the tether; 0 = no tether.
    pub tether_drag_per_length: f64,
    /// Minimum deployed tether length (m).
    pub tether_min_length_m: f64,
    /// Where the tether leaves the surface, NED (m).
    pub launch_ned_m: Vector3<f64>,
}

impl Default for Environment {
    /// Still water, no tether.
    fn default() -> Self {
        Self {
            current_ned_mps: Vector3::zeros(),
            tether_drag_per_length: 0.0,
            tether_min_length_m: 0.0,
            launch_ned_m: Vector3::zeros(),
        }
    }
}

impl Environment {
    pub fn new(current: &CurrentOptions, tether: &TetherOptions) -> Self {
        Self {
            current_ned_mps: current.velocity_ned_mps(),
            tether_drag_per_length: tether.drag_per_length(),
            tether_min_length_m: tether.min_length_m,
            launch_ned_m: Vector3::zeros(),
        }
    }

    /// Still water and no tether: the models can take their plain paths.
    pub fn is_calm(&self) -> bool {
        self.current_ned_mps == Vector3::zeros() && self.tether_drag_per_length == 0.0
    }

    /// Deployed tether length (m) for a vehicle at `position_ned_m`.
    pub fn tether_length_m(&self, position_ned_m: &Vector3<f64>) -> f64 {
        (position_ned_m - self.launch_ned_m)
            .norm()
            .max(self.tether_min_length_m)
    }

    /// Tether drag (N, NED) on a vehicle at `position_ned_m` moving at
    /// `velocity_rel_ned_mps` relative to the water.
    pub fn tether_force_ned_n(
        &self,
        position_ned_m: &Vector3<f64>,
        velocity_rel_ned_mps: &Vector3<f64>,
    ) -> Vector3<f64> {
        if self.tether_drag_per_length == 0.0 {
            return Vector3::zeros();
        }
        let k = self.tether_drag_per_length * self.tether_length_m(position_ned_m);
        velocity_rel_ned_mps * (-k * velocity_rel_ned_mps.norm())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn current_points_where_it_flows() {
        let c = CurrentOptions {
            speed_mps: 0.2,
            direction_deg: 90.0,
        };
        let v = c.velocity_ned_mps();
        assert!(v[0].abs() < 1e-15 && (v[1] - 0.2).abs() < 1e-15 && v[2] == 0.0);
    }

    #[test]
    fn tether_drag_opposes_motion_and_grows_with_speed_and_length() {
        let env = Environment::new(&CurrentOptions::default(), &TetherOptions::default());
        let at = Vector3::new(0.0, 0.0, 1.0);
        let far = Vector3::new(30.0, 0.0, 0.0);
        assert_eq!(env.tether_length_m(&at), 2.0);
        assert_eq!(env.tether_length_m(&far), 30.0);
        let slow = env.tether_force_ned_n(&at, &Vector3::new(0.5, 0.0, 0.0));
        let fast = env.tether_force_ned_n(&at, &Vector3::new(1.0, 0.0, 0.0));
        assert!(slow[0] < 0.0 && fast[0] < slow[0]);
        // Quadratic in speed: twice as fast, four times the drag.
        assert!((fast[0] / slow[0] - 4.0).abs() < 1e-12);
        let long = env.tether_force_ned_n(&far, &Vector3::new(1.0, 0.0, 0.0));
        assert!((long[0] / fast[0] - 15.0).abs() < 1e-12);
        // ½·1000·1.2·0.003·2 m at 1 m/s.
        assert!((fast[0] + 3.6).abs() < 1e-12);
    }

    #[test]
    fn off_and_still_is_calm() {
        let env = Environment::new(&CurrentOptions::default(), &TetherOptions::off());
        assert!(env.is_calm());
        assert_eq!(
            env.tether_force_ned_n(&Vector3::zeros(), &Vector3::new(1.0, 0.0, 0.0)),
            Vector3::zeros()
        );
        assert!(!Environment::new(&CurrentOptions::default(), &TetherOptions::default()).is_calm());
    }
}
