//! The whole ROV with the genuine firmware in the loop: the firmware in
//! simavr ([`super::runner`]) reads the simulator's sensors and drives the
//! simulator's thrusters with its own ESC pulses.
//!
//! Owns the loop between the two, on its own thread: every few
//! milliseconds it hands the board's time and measured ESC pulses to the
//! simulated vehicle ([`super::surroundings`], the same coupling the
//! scenarios use on simulated time) and the vehicle's readings back to the
//! board's sensors and ADC pins. So every number Neptunus reads has been
//! through the firmware's own conversions, and every thrust through its own
//! motor code. It decides nothing: the firmware decides what the board
//! does, the plant what the water does.
//!
//! The truth it publishes ([`SimSnapshot`]) is what `--sim` publishes, so
//! NEPTUNUS_SIM_STATE and the synthetic camera work unchanged.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use tokio::sync::watch;

use super::Firmware;
use super::bench::Wiring;
use super::ms5803::Water;
use super::runner::{GenuineBoard, GenuineControl, GenuineError};
use super::surroundings::Surroundings;
use crate::firmware::emulator::{EmulatorOptions, SimSnapshot};
use crate::sim::plant::SimError;

/// How often the loop looks at the pins and feeds the sensors (wall time).
const LOOP_PERIOD: Duration = Duration::from_millis(5);
/// How often the simulator's speed figures go to the log.
const REPORT_PERIOD: Duration = Duration::from_secs(10);

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
        let mut vehicle = Surroundings::new(opts)?;
        let wiring = Wiring {
            analog: vehicle.sensed(Water::default()).analog,
            ..Wiring::default()
        };
        let board = GenuineBoard::spawn(firmware, wiring, None)?;
        let control = board.control();
        let (truth_tx, truth) = watch::channel(vehicle.truth());
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("hil-vehicle".into())
            .spawn(move || run(&mut vehicle, &control, &truth_tx, &stopping))
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

fn run(
    vehicle: &mut Surroundings,
    control: &GenuineControl,
    truth_tx: &watch::Sender<SimSnapshot>,
    stop: &AtomicBool,
) {
    let mut next_report = std::time::Instant::now() + REPORT_PERIOD;
    // The longest wait between two of this loop's passes since the last
    // report: while it waits (a machine too busy to run this thread), the
    // board's sensors read a frozen world and the plant then catches up
    // in one leap on the pulses of the moment.
    let mut last_pass = std::time::Instant::now();
    let mut widest_gap = Duration::ZERO;
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(LOOP_PERIOD);
        let now = std::time::Instant::now();
        widest_gap = widest_gap.max(now.duration_since(last_pass));
        last_pass = now;
        let snap = control.snapshot();
        if now >= next_report {
            next_report += REPORT_PERIOD;
            tracing::info!(
                board_time_s = format_args!("{:.1}", snap.sim_time_s),
                realtime_ratio = format_args!("{:.2}", snap.realtime_ratio),
                speed_ratio = format_args!("{:.1}", snap.speed_ratio),
                slips = snap.slips,
                widest_gap_ms = widest_gap.as_millis(),
                "genuine board in simavr"
            );
            widest_gap = Duration::ZERO;
        }
        if snap.error.is_some() {
            // The board stopped; the vehicle stays where it is.
            continue;
        }
        vehicle.advance(snap.sim_time_s, snap.pins.esc_us);
        let sensed = vehicle.sensed(snap.water);
        control.set_water(sensed.water);
        control.set_attitude(sensed.attitude);
        if snap.analog != sensed.analog {
            control.set_analog(sensed.analog);
        }
        truth_tx.send_replace(vehicle.truth());
    }
}
