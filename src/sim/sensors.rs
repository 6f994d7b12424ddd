//! What the OpenROV board would report for a simulated vehicle: navigation
//! (heading, depth, attitude, forward thrust) and status (pressure,
//! temperature, supply voltage and currents).
//!
//! This module owns the mapping from the simulated vehicle to board
//! readings in the board's own units, and the sensors' imperfections
//! ([`SensorImperfections`]): Gaussian noise and constant bias, the
//! pressure sensor's 1 Hz update, and wild points. It must never do I/O or
//! read a clock (time is passed in), and its only randomness is a generator
//! seeded from the options, so a seed gives the same readings every run.
//!
//! # Imperfections and their defaults ([`NoiseOptions`])
//! The OpenROV 2.x IMU/depth module carries an MPU-9150 (accelerometer,
//! gyro, magnetometer) and an MS5803-14BA pressure sensor.
//! - Heading: 1° noise (a magnetometer heading next to thruster motors and
//!   their currents wanders by about that), 2° bias (an uncalibrated hard-
//!   iron offset; also where declination would show if not corrected).
//! - Pitch and roll: 0.3° noise, +0.5° / −0.5° bias (the module is never
//!   mounted perfectly level).
//! - Depth: 1 cm noise and 2 cm bias. The MS5803-14BA resolves 0.2 mbar
//!   (2 mm of water) at its finest oversampling, and its absolute accuracy
//!   is about ±2 mbar (2 cm), which zeroing at the surface only partly
//!   cancels as the temperature changes; 1 cm of noise covers coarser
//!   oversampling and the ripple of a moving vehicle.
//! - The pressure sensor is read once a second by the board (`depth_update_hz`
//!   1.0): the navigation line still comes every 100 ms, with the last depth
//!   held (sample and hold).
//! - Wild points (off by default): at `wild_rate` per reading, independently
//!   for depth and heading, the value reported is the measured one × 0.1,
//!   × 10 or × 100 — the factors the thesis saw in its telemetry (§8.3).
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

use std::time::Duration;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use super::thesis::{Demand, SimState, thruster_outputs, wrap_deg_180, wrap_deg_360};

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
        self.battery_current_for_efforts_a(&thruster_outputs(d))
    }

    /// Battery current (A) with each thruster at an effort in `[-1, 1]`
    /// (its ESC command as a fraction of the range, which sets motor speed
    /// and so current whichever way the propeller turns).
    pub fn battery_current_for_efforts_a(&self, efforts: &[f64; 3]) -> f64 {
        let p = &self.params;
        let thrusters_a: f64 = efforts
            .iter()
            .map(|u| p.thruster_full_current_a * u.abs().powf(p.thruster_current_exponent))
            .sum();
        p.idle_current_a + thrusters_a
    }

    /// What a perfect board would report for a pose (6-DOF: attitude
    /// included), the forward thrust setting and the thrusters' efforts.
    pub fn read_pose(&self, pose: &Pose, fthr_pct: f64, efforts: &[f64; 3]) -> Readings {
        let p = &self.params;
        let heading_deg = wrap_deg_360(pose.heading_rad.to_degrees());
        let pressure_mbar =
            p.surface_pressure_mbar + pose.depth_m.max(0.0) / p.water.depth_m_per_mbar();
        let btti_a = self.battery_current_for_efforts_a(efforts);
        Readings {
            heading_deg,
            depth_m: self.board_depth_m(pressure_mbar),
            pitch_deg: pose.pitch_rad.to_degrees(),
            roll_deg: pose.roll_rad.to_degrees(),
            yaw_deg: wrap_deg_180(heading_deg),
            fthr_pct,
            pressure_mbar,
            temp_c: p.water_temp_c,
            vout_v: p.battery_open_circuit_v - p.internal_resistance_ohm * btti_a,
            iout_a: p.idle_current_a,
            btti_a,
        }
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

/// The part of the vehicle's state the board's sensors see.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    pub depth_m: f64,
    /// Continuous or wrapped; the reading is wrapped into `[0, 360)`.
    pub heading_rad: f64,
    pub pitch_rad: f64,
    pub roll_rad: f64,
}

/// Noise and bias of the board's sensors (`[emulator.sim.noise]`).
/// `Default` is the OpenROV 2.x IMU/depth module as documented in the
/// module doc; [`NoiseOptions::none`] is a perfect sensor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseOptions {
    /// Standard deviation of the heading noise (deg).
    pub heading_std_deg: f64,
    /// Constant heading error (deg).
    pub heading_bias_deg: f64,
    /// Standard deviation of the depth noise (m), per pressure sample.
    pub depth_std_m: f64,
    /// Constant depth error (m).
    pub depth_bias_m: f64,
    pub pitch_std_deg: f64,
    pub pitch_bias_deg: f64,
    pub roll_std_deg: f64,
    pub roll_bias_deg: f64,
}

impl Default for NoiseOptions {
    fn default() -> Self {
        Self {
            heading_std_deg: 1.0,
            heading_bias_deg: 2.0,
            depth_std_m: 0.01,
            depth_bias_m: 0.02,
            pitch_std_deg: 0.3,
            pitch_bias_deg: 0.5,
            roll_std_deg: 0.3,
            roll_bias_deg: -0.5,
        }
    }
}

impl NoiseOptions {
    /// Perfect sensors: no noise, no bias.
    pub fn none() -> Self {
        Self {
            heading_std_deg: 0.0,
            heading_bias_deg: 0.0,
            depth_std_m: 0.0,
            depth_bias_m: 0.0,
            pitch_std_deg: 0.0,
            pitch_bias_deg: 0.0,
            roll_std_deg: 0.0,
            roll_bias_deg: 0.0,
        }
    }

    /// Every field by its key, for validation messages.
    pub fn fields(&self) -> [(&'static str, f64); 8] {
        [
            ("heading_std_deg", self.heading_std_deg),
            ("heading_bias_deg", self.heading_bias_deg),
            ("depth_std_m", self.depth_std_m),
            ("depth_bias_m", self.depth_bias_m),
            ("pitch_std_deg", self.pitch_std_deg),
            ("pitch_bias_deg", self.pitch_bias_deg),
            ("roll_std_deg", self.roll_std_deg),
            ("roll_bias_deg", self.roll_bias_deg),
        ]
    }
}

/// The factors of the thesis' wild points.
pub const WILD_FACTORS: [f64; 3] = [0.1, 10.0, 100.0];

/// What the imperfections did, for tests and tools.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SensorStats {
    pub readings: u64,
    pub depth_samples: u64,
    pub depth_wild: u64,
    pub heading_wild: u64,
}

/// Noise, bias, the pressure sensor's sample-and-hold and wild points,
/// applied to perfect [`Readings`]. Deterministic for a seed.
#[derive(Debug, Clone)]
pub struct SensorImperfections {
    noise: NoiseOptions,
    depth_update_hz: f64,
    wild_rate: f64,
    rng: SmallRng,
    /// The pressure sample being held: its slot number and the depth measured.
    held_depth: Option<(u64, f64)>,
    stats: SensorStats,
}

impl SensorImperfections {
    /// `depth_update_hz` 0 samples the pressure at every reading; the
    /// caller validates the options (`SimOptions::validate`), and a
    /// `wild_rate` outside `[0, 1]` is clamped.
    pub fn new(noise: NoiseOptions, depth_update_hz: f64, wild_rate: f64, seed: u64) -> Self {
        Self {
            noise,
            depth_update_hz,
            wild_rate: if wild_rate.is_nan() {
                0.0
            } else {
                wild_rate.clamp(0.0, 1.0)
            },
            rng: SmallRng::seed_from_u64(seed),
            held_depth: None,
            stats: SensorStats::default(),
        }
    }

    pub fn stats(&self) -> SensorStats {
        self.stats
    }

    /// The depth the pressure sensor last measured (noise and bias, no wild
    /// point): what the board zeroes on `dzer()`.
    pub fn held_depth_m(&self) -> Option<f64> {
        self.held_depth.map(|(_, d)| d)
    }

    /// Starts the sample-and-hold afresh (a scenario start).
    pub fn reset_hold(&mut self) {
        self.held_depth = None;
    }

    /// A standard normal variate (Box–Muller on the seeded generator).
    fn gaussian(&mut self) -> f64 {
        // 1 − U is in (0, 1], so the logarithm is finite.
        let u1: f64 = 1.0 - self.rng.random::<f64>();
        let u2: f64 = self.rng.random();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    fn noisy(&mut self, std: f64, bias: f64) -> f64 {
        if std > 0.0 {
            bias + std * self.gaussian()
        } else {
            bias
        }
    }

    fn wild(&mut self) -> Option<f64> {
        if self.wild_rate > 0.0 && self.rng.random_bool(self.wild_rate) {
            Some(WILD_FACTORS[self.rng.random_range(0..WILD_FACTORS.len())])
        } else {
            None
        }
    }

    /// What the board reports at board time `t` for perfect readings `clean`.
    pub fn apply(&mut self, t: Duration, clean: &Readings, depth_m_per_mbar: f64) -> Readings {
        self.stats.readings += 1;
        let mut r = *clean;
        let n = self.noise.clone();
        let heading =
            wrap_deg_360(clean.heading_deg + self.noisy(n.heading_std_deg, n.heading_bias_deg));
        r.heading_deg = heading;
        r.yaw_deg = wrap_deg_180(heading);
        r.pitch_deg = clean.pitch_deg + self.noisy(n.pitch_std_deg, n.pitch_bias_deg);
        r.roll_deg = clean.roll_deg + self.noisy(n.roll_std_deg, n.roll_bias_deg);
        // Slots of 1/rate seconds; a new slot takes a new sample. Time that
        // goes backwards (a status line due before the last nav line) keeps
        // the sample: the sensor cannot un-measure.
        let slot = if self.depth_update_hz > 0.0 {
            (t.as_secs_f64() * self.depth_update_hz).floor() as u64
        } else {
            self.stats.readings
        };
        let depth = match self.held_depth {
            Some((held_slot, depth)) if slot <= held_slot => depth,
            _ => {
                let depth = clean.depth_m + self.noisy(n.depth_std_m, n.depth_bias_m);
                self.held_depth = Some((slot, depth));
                self.stats.depth_samples += 1;
                depth
            }
        };
        r.depth_m = depth;
        // The board derives depth from pressure: report the pressure that
        // gives the held depth, so `pres` and `deep` agree.
        r.pressure_mbar = clean.pressure_mbar + (depth - clean.depth_m) / depth_m_per_mbar;
        if let Some(f) = self.wild() {
            r.depth_m *= f;
            self.stats.depth_wild += 1;
        }
        if let Some(f) = self.wild() {
            r.heading_deg *= f;
            self.stats.heading_wild += 1;
        }
        r
    }
}
