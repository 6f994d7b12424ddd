//! The simulated vehicle around the genuine board, sans-IO: the ESC pulse
//! widths measured on the firmware's pins step the simulator's plant
//! ([`crate::sim::plant`], the one the board emulator drives) by the
//! board's own time, and the plant's depth, water temperature, attitude,
//! supply voltage and currents are what the board's sensors and analog
//! inputs are given.
//!
//! Owns that coupling and nothing else: whoever runs the board —
//! [`super::rov`] on a thread at real time, [`super::lockstep`] beside a
//! scenario on simulated time — passes the board's time and pulses in and
//! hands the readings to the board. It never reads a clock. The sensors
//! get the plant's clean readings: the imperfections the board emulator
//! adds (noise, bias, wild points) are the simulated chips' to add, and
//! these add none; what the firmware does to them (rates, resolution,
//! conversions) is its own.

use super::bench::Analog;
use super::bno055::Attitude;
use super::ms5803::Water;
use crate::firmware::emulator::{EmulatorOptions, SimSnapshot};
use crate::sim::plant::{Plant, SimError};
use crate::sim::sensors::Readings;

/// Longest plant step: a board that ran ahead is caught up in steps no
/// longer than this.
const MAX_STEP_S: f64 = 0.01;
/// The ESCs' neutral: what a thruster sees while its pin does not pulse.
const NEUTRAL_US: u16 = 1500;

/// What the board's sensors and analog inputs are given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensed {
    pub water: Water,
    pub attitude: Attitude,
    pub analog: Analog,
}

/// The simulated vehicle the genuine board sits in.
#[derive(Debug)]
pub struct Surroundings {
    plant: Plant,
    /// The board time the plant was last stepped to.
    board_time_s: Option<f64>,
}

impl Surroundings {
    /// The vehicle of `opts.sim` at rest at the surface, its thrusters wired
    /// as `opts.wiring_directions` says (the board's own options — deadzone,
    /// reverse multiplier, framing — are the firmware's, not `opts`').
    pub fn new(opts: &EmulatorOptions) -> Result<Self, SimError> {
        Ok(Self {
            plant: Plant::new(&opts.sim, opts.wiring_directions)?,
            board_time_s: None,
        })
    }

    /// Steps the plant to board time `now_s`, the ESCs held at `esc_us` as
    /// measured since the last call (`None`: the pin does not pulse, a
    /// stopped thruster). The first call only starts the clock; a clock
    /// that went back (a reset starts the board's again) steps nothing —
    /// the water does not start again.
    pub fn advance(&mut self, now_s: f64, esc_us: [Option<f64>; 3]) {
        let Some(last) = self.board_time_s.replace(now_s) else {
            return;
        };
        let mut dt = now_s - last;
        let esc = esc_of(esc_us);
        while dt > 1e-9 {
            let step = dt.min(MAX_STEP_S);
            self.plant.step(esc, step);
            dt -= step;
        }
    }

    /// What the sensors sense now; `water` keeps what the firmware chose
    /// (fresh or salt water).
    pub fn sensed(&self, water: Water) -> Sensed {
        let clean = self.plant.read_clean();
        let t = self.plant.truth();
        Sensed {
            water: Water {
                depth_m: t.depth_m.max(0.0),
                temp_c: clean.temp_c,
                ..water
            },
            attitude: Attitude {
                heading_deg: clean.heading_deg,
                pitch_deg: t.pitch_rad.to_degrees(),
                roll_deg: t.roll_rad.to_degrees(),
            },
            analog: analog_of(&clean),
        }
    }

    /// Where the simulated vehicle really is.
    pub fn truth(&self) -> SimSnapshot {
        SimSnapshot::from(&self.plant.truth())
    }

    /// Puts the vehicle at rest at this depth and heading, level, its
    /// thrusters stopped (a scenario's start).
    pub fn place(&mut self, depth_m: f64, heading_deg: f64) {
        self.plant
            .set_pose(0.0, 0.0, depth_m, heading_deg.to_radians());
    }
}

/// What the board's dividers see for the plant's supply voltage and
/// currents (two battery tubes share the vehicle's current).
fn analog_of(r: &Readings) -> Analog {
    Analog {
        battery_v: r.vout_v,
        board_current_a: r.iout_a,
        battery_current_a: [r.btti_a / 2.0; 2],
        ..Analog::default()
    }
}

/// The ESC pulses as the thrusters see them: the last measured width, or
/// neutral while a pin does not pulse.
fn esc_of(widths: [Option<f64>; 3]) -> [u16; 3] {
    widths.map(|w| w.map_or(NEUTRAL_US, |us| us.round().clamp(0.0, 3000.0) as u16))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pin_that_does_not_pulse_is_a_stopped_thruster() {
        assert_eq!(
            esc_of([None, Some(1640.4), Some(1270.6)]),
            [1500, 1640, 1271]
        );
    }

    #[test]
    fn the_plant_runs_on_the_boards_time_and_a_reset_does_not_rewind_it() {
        let mut s = Surroundings::new(&EmulatorOptions::default()).expect("plant");
        s.place(1.0, 90.0);
        let dive = [None, Some(1800.0), None];
        s.advance(5.0, dive);
        assert_eq!(
            s.truth().depth_m,
            1.0,
            "the first call only starts the clock"
        );
        s.advance(7.0, dive);
        let after = s.truth().depth_m;
        assert!(after > 1.05, "two seconds of dive thrust: {after}");
        // The board reset: its clock starts at 0 again.
        s.advance(0.001, dive);
        assert_eq!(s.truth().depth_m, after);
        s.advance(0.5, dive);
        assert!(s.truth().depth_m > after);
        let sensed = s.sensed(Water {
            salt_water: true,
            ..Water::default()
        });
        assert!((sensed.water.depth_m - s.truth().depth_m).abs() < 1e-9);
        assert!(sensed.water.salt_water);
        assert!((sensed.attitude.heading_deg - 90.0).abs() < 1e-6);
    }
}
