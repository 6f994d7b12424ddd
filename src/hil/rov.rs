//! The whole ROV with the genuine firmware in the loop: the firmware in
//! simavr ([`super::runner`]) reads the simulator's sensors and drives the
//! simulator's thrusters with its own ESC pulses.
//!
//! Owns the loop between the two, on its own thread: the ESC pulse widths
//! measured on the firmware's pins ([`super::pins`]) step the simulated
//! vehicle ([`crate::sim::plant`], the same plant the board emulator
//! drives) by the board's own simulated time, and the vehicle's true depth,
//! water temperature and attitude go to the simulated MS5803 and BNO055,
//! its supply voltage and currents to the ADC pins. So every number
//! Neptunus reads has been through the firmware's own conversions, and
//! every thrust through its own motor code. It decides nothing: the
//! firmware decides what the board does, the plant what the water does.
//!
//! The truth it publishes ([`SimSnapshot`]) is what `--sim` publishes, so
//! NEPTUNUS_SIM_STATE and the synthetic camera work unchanged.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use tokio::sync::watch;

use super::Firmware;
use super::bno055::Attitude;
use super::ms5803::Water;
use super::runner::{Analog, GenuineBoard, GenuineControl, GenuineError, Wiring};
use crate::firmware::emulator::{EmulatorOptions, SimSnapshot};
use crate::sim::plant::Plant;
use crate::sim::plant::SimError;

/// How often the loop looks at the pins and feeds the sensors (wall time).
const LOOP_PERIOD: Duration = Duration::from_millis(5);
/// Longest plant step: a board that ran ahead (a late loop) is caught up
/// in steps no longer than this.
const MAX_STEP_S: f64 = 0.01;
/// How often the simulator's speed figures go to the log.
const REPORT_PERIOD: Duration = Duration::from_secs(10);
/// The ESCs' neutral: what a thruster sees while its pin does not pulse.
const NEUTRAL_US: u16 = 1500;

/// Why the ROV could not start.
#[derive(Debug, thiserror::Error)]
pub enum HilError {
    #[error("the simulator's options: {0}")]
    Sim(#[from] SimError),
    #[error(transparent)]
    Board(#[from] GenuineError),
    #[error("cannot start the simulator's thread: {0}")]
    Thread(std::io::Error),
}

/// The genuine board behind a pty and the simulated vehicle it drives,
/// running until dropped.
#[derive(Debug)]
pub struct HilRov {
    board: GenuineBoard,
    truth: watch::Receiver<SimSnapshot>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl HilRov {
    /// Powers the board running `firmware` with the depth sensor and the
    /// IMU on its bus, and starts the simulated vehicle of `opts.sim`
    /// (thruster wiring from `opts.wiring_directions`; the board's own
    /// options — deadzone, reverse multiplier, framing — are the
    /// firmware's, not `opts`').
    pub fn spawn(firmware: Firmware, opts: &EmulatorOptions) -> Result<Self, HilError> {
        let mut plant = Plant::new(&opts.sim, opts.wiring_directions)?;
        let power = plant.read_clean();
        let wiring = Wiring {
            analog: analog_of(&power),
            ..Wiring::default()
        };
        let board = GenuineBoard::spawn(firmware, wiring, None)?;
        let control = board.control();
        let (truth_tx, truth) = watch::channel(SimSnapshot::from(&plant.truth()));
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("hil-vehicle".into())
            .spawn(move || run(&mut plant, &control, &truth_tx, &stopping))
            .map_err(HilError::Thread)?;
        Ok(Self {
            board,
            truth,
            stop,
            thread: Some(thread),
        })
    }

    /// The genuine board (its pty, its controls and figures).
    pub fn board(&self) -> &GenuineBoard {
        &self.board
    }

    /// The simulated vehicle's truth, renewed as the board's time runs.
    pub fn truth(&self) -> watch::Receiver<SimSnapshot> {
        self.truth.clone()
    }
}

impl Drop for HilRov {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// What the board's dividers see for the plant's supply voltage and
/// currents (two battery tubes share the vehicle's current).
fn analog_of(r: &crate::sim::sensors::Readings) -> Analog {
    Analog {
        battery_v: r.vout_v,
        board_current_a: r.iout_a,
        battery_current_a: [r.btti_a / 2.0; 2],
        ..Analog::default()
    }
}

/// The ESC pulses as the thrusters see them: the last measured width, or
/// neutral while a pin does not pulse.
fn esc_us(widths: [Option<f64>; 3]) -> [u16; 3] {
    widths.map(|w| w.map_or(NEUTRAL_US, |us| us.round().clamp(0.0, 3000.0) as u16))
}

fn run(
    plant: &mut Plant,
    control: &GenuineControl,
    truth_tx: &watch::Sender<SimSnapshot>,
    stop: &AtomicBool,
) {
    let mut board_time_s: Option<f64> = None;
    let mut next_report = std::time::Instant::now() + REPORT_PERIOD;
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(LOOP_PERIOD);
        let snap = control.snapshot();
        if std::time::Instant::now() >= next_report {
            next_report += REPORT_PERIOD;
            tracing::info!(
                board_time_s = format_args!("{:.1}", snap.sim_time_s),
                realtime_ratio = format_args!("{:.2}", snap.realtime_ratio),
                speed_ratio = format_args!("{:.1}", snap.speed_ratio),
                slips = snap.slips,
                "genuine board in simavr"
            );
        }
        if snap.error.is_some() {
            // The board stopped; the vehicle stays where it is.
            continue;
        }
        let now_s = snap.sim_time_s;
        let last = board_time_s.replace(now_s);
        let Some(last) = last else { continue };
        let mut dt = now_s - last;
        if dt < 0.0 {
            // A reset starts the board's clock again; the water does not.
            continue;
        }
        let esc = esc_us(snap.pins.esc_us);
        while dt > 1e-9 {
            let step = dt.min(MAX_STEP_S);
            plant.step(esc, step);
            dt -= step;
        }
        let clean = plant.read_clean();
        let t = plant.truth();
        control.set_water(Water {
            depth_m: t.depth_m.max(0.0),
            temp_c: clean.temp_c,
            ..snap.water
        });
        control.set_attitude(Attitude {
            heading_deg: clean.heading_deg,
            pitch_deg: t.pitch_rad.to_degrees(),
            roll_deg: t.roll_rad.to_degrees(),
        });
        if snap.analog != analog_of(&clean) {
            control.set_analog(analog_of(&clean));
        }
        truth_tx.send_replace(SimSnapshot::from(&t));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pin_that_does_not_pulse_is_a_stopped_thruster() {
        assert_eq!(
            esc_us([None, Some(1640.4), Some(1270.6)]),
            [1500, 1640, 1271]
        );
    }
}
