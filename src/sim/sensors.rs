//! What the OpenROV board would report for a simulated vehicle: navigation
//! (heading, depth, attitude, forward thrust) and status (pressure,
//! temperature, supply voltage and currents).
//!
//! This module owns the mapping from [`SimState`] and [`Demand`] to board
//! readings in the board's own units. It must never do I/O, read a clock or
//! add noise on its own: noise and wild points, if wanted, are the caller's
//! job with an explicit seed.
//!
//! Depth is produced the way the board produces it: from a pressure, with
//! the board's conversion `depth_m = (p_mbar − p_surface) · 1.019716 / 100`
//! (fresh water; salt water × 0.9945). Above the surface (z < 0, which the
//! thesis model allows) the gauge reads surface pressure, so depth reads 0.
//!
//! The power model is a Thevenin battery `V = V_oc − R·I` with
//! `I = I_idle + Σ I_full·|u_i|^1.5` over the three thrusters. Its defaults
//! are calibrated to the one in-water measurement of the thesis (full
//! forward and up: 3.13 A, 10.9 V from 12 V idle). That test ran on a bench
//! supply limited to 3.13 A, so the true draw may have been higher; the
//! model reproduces what the board reported, not what the motors wanted.

use super::thesis::{Demand, SimState, thruster_outputs, wrap_deg_180};

/// Board depth per mbar above surface pressure in fresh water, ×100 (m).
/// `100 mbar = 10⁴ Pa = ρgh` with ρ = 1000 kg/m³, g = 9.80665 m/s².
pub const FRESH_WATER_M_PER_100_MBAR: f64 = 1.019716;
/// The board's salt-water correction factor on fresh-water depth.
pub const SALT_WATER_FACTOR: f64 = 0.9945;

/// Which water the vehicle is in (and the board is set for).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Water {
    #[default]
    Fresh,
    Salt,
}

impl Water {
    /// Metres of depth per mbar of gauge pressure.
    pub fn depth_m_per_mbar(self) -> f64 {
        let factor = match self {
            Water::Fresh => 1.0,
            Water::Salt => SALT_WATER_FACTOR,
        };
        FRESH_WATER_M_PER_100_MBAR * factor / 100.0
    }
}

/// Parameters of the sensor and power model. `Default` is the Neptunus
/// vehicle in the thesis's fresh-water test tank.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorParams {
    /// Absolute pressure at the surface (mbar); the board's depth zero.
    pub surface_pressure_mbar: f64,
    /// Water type, for both the physical pressure and the board's conversion.
    pub water: Water,
    /// Water temperature (°C), uniform with depth.
    pub water_temp_c: f64,
    /// Battery open-circuit voltage (V). Thesis: 12 V idle.
    pub battery_open_circuit_v: f64,
    /// Battery plus tether internal resistance (Ω). Thesis: 1.1 V drop at 3.13 A.
    pub internal_resistance_ohm: f64,
    /// Board electronics current, thrusters off (A).
    pub idle_current_a: f64,
    /// Current of one thruster at full thrust in water (A).
    pub thruster_full_current_a: f64,
    /// Exponent of thruster current against |u| (propeller power ~ speed³,
    /// thrust ~ speed², so current ~ thrust^1.5).
    pub thruster_current_exponent: f64,
}

impl Default for SensorParams {
    fn default() -> Self {
        let idle_current_a = 0.3;
        Self {
            surface_pressure_mbar: 1015.0,
            water: Water::Fresh,
            water_temp_c: 18.0,
            battery_open_circuit_v: 12.0,
            internal_resistance_ohm: 0.35,
            idle_current_a,
            // Three thrusters at full plus idle = the thesis's 3.13 A.
            thruster_full_current_a: (3.13 - idle_current_a) / 3.0,
            thruster_current_exponent: 1.5,
        }
    }
}

/// One set of board readings, in the board's units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Readings {
    /// `hdgd`, 0..360.
    pub heading_deg: f64,
    /// `deep`, from pressure as the board computes it.
    pub depth_m: f64,
    /// `pitc`, always 0 in the 4-DOF model.
    pub pitch_deg: f64,
    /// `roll`, always 0 in the 4-DOF model.
    pub roll_deg: f64,
    /// `yaw`, (-180, 180].
    pub yaw_deg: f64,
    /// `fthr`, surge demand × 100.
    pub fthr_pct: f64,
    /// `pres`.
    pub pressure_mbar: f64,
    /// `temp`.
    pub temp_c: f64,
    /// `vout`, supply voltage under load.
    pub vout_v: f64,
    /// `iout`, board electronics current.
    pub iout_a: f64,
    /// `btti`, battery current including thrusters.
    pub btti_a: f64,
}

/// Deterministic board sensor model.
#[derive(Debug, Clone)]
pub struct SensorModel {
    params: SensorParams,
}

impl SensorModel {
    pub fn new(p: SensorParams) -> Self {
        Self { params: p }
    }

    pub fn params(&self) -> &SensorParams {
        &self.params
    }

    /// Absolute pressure at the vehicle (mbar); surface pressure above water.
    pub fn pressure_mbar(&self, s: &SimState) -> f64 {
        let p = &self.params;
        p.surface_pressure_mbar + s.depth_m().max(0.0) / p.water.depth_m_per_mbar()
    }

    /// Depth as the board derives it from a pressure reading (m).
    pub fn board_depth_m(&self, pressure_mbar: f64) -> f64 {
        let p = &self.params;
        (pressure_mbar - p.surface_pressure_mbar) * p.water.depth_m_per_mbar()
    }

    /// Battery current (A) for a demand: idle plus each thruster's share.
    pub fn battery_current_a(&self, d: &Demand) -> f64 {
        let p = &self.params;
        let thrusters_a: f64 = thruster_outputs(d)
            .iter()
            .map(|u| p.thruster_full_current_a * u.abs().powf(p.thruster_current_exponent))
            .sum();
        p.idle_current_a + thrusters_a
    }

    /// What the board would report for this state and thruster demand (no noise in this model; pitch/roll 0 in 4-DOF).
    /// depth_m comes from pressure exactly as the board computes it: pressure_mbar = 1015 + depth·100/1.019716 (fresh water).
    pub fn read(&self, s: &SimState, d: &Demand) -> Readings {
        let p = &self.params;
        let heading_deg = s.heading_deg();
        let pressure_mbar = self.pressure_mbar(s);
        let btti_a = self.battery_current_a(d);
        Readings {
            heading_deg,
            depth_m: self.board_depth_m(pressure_mbar),
            pitch_deg: 0.0,
            roll_deg: 0.0,
            yaw_deg: wrap_deg_180(heading_deg),
            fthr_pct: d.saturated().surge * 100.0,
            pressure_mbar,
            temp_c: p.water_temp_c,
            vout_v: p.battery_open_circuit_v - p.internal_resistance_ohm * btti_a,
            iout_a: p.idle_current_a,
            btti_a,
        }
    }
}
