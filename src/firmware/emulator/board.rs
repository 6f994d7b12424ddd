//! The emulated controller board, sans-IO: bytes in from the host and the
//! current time, bytes out that the board would print, and the simulated
//! vehicle its ESCs drive.
//!
//! Owns the wiring around the sketch ([`super::sketch`]): the serial port
//! ([`super::uart`]), the simulator ([`Plant`]) stepped with the ESC pulses
//! the sketch writes, the analog inputs and sensors read from it, the fault
//! injector on the periodic lines, the records for tests, and the
//! snapshot. A stalled board runs no sketch but its physics goes on.
//!
//! It must never read a clock, sleep or touch a file descriptor: time comes
//! in as an argument (a `Duration` since an arbitrary origin), so the pty
//! wrapper, the in-process loopback and the tests drive the same board.

use std::collections::VecDeque;
use std::time::Duration;

use super::faults::FaultInjector;
use super::sketch::{Hardware, Sketch, SketchConfig};
use super::uart::Uart;
use super::{BoardRecord, BoardSnapshot, EmulatorOptions, SimSnapshot};
use crate::sim::{Plant, Readings, SimError, SimState};

pub use super::sketch::{COMMAND_QUEUE_SLOTS, FRAME_BUFFER_BYTES, MAX_ARGS};

const SIM_STEP: Duration = Duration::from_millis(10);
/// The ESCs' neutral pulse: the board's own constant, apart from the
/// vehicle's `mixer::NEUTRAL_US` on purpose (an independent check).
const NEUTRAL_US: u16 = 1500;
/// How long a hung board lets its physics run between wake-ups (a running
/// one prints a navigation line every 101 ms).
const IDLE_WAKE: Duration = Duration::from_millis(200);

/// A change on the ESC pins, from its time on.
#[derive(Debug, Clone, Copy)]
enum EscChange {
    Pulses([u16; 3]),
    Power(bool),
}

/// What the sketch's pins and buses reach: the simulated vehicle, the
/// fault injector and the records.
#[derive(Debug)]
struct Wiring {
    plant: Plant,
    sim_time: Duration,
    /// The physics never runs past the caller's `now`, even while a pass
    /// of the sketch does: what it writes later waits here.
    horizon: Duration,
    pending: VecDeque<(Duration, EscChange)>,
    esc_us: [u16; 3],
    esc_power: bool,
    faults: FaultInjector,
    records: Vec<BoardRecord>,
    recording: bool,
}

impl Wiring {
    /// Steps the physics towards `t` (not past the horizon) in 10 ms
    /// steps, each with the ESC pulses written before its end.
    fn step_to(&mut self, t: Duration) {
        let t = t.min(self.horizon);
        while self.sim_time + SIM_STEP <= t {
            let end = self.sim_time + SIM_STEP;
            while let Some(&(at, change)) = self.pending.front() {
                if at >= end {
                    break;
                }
                self.pending.pop_front();
                match change {
                    EscChange::Pulses(us) => self.esc_us = us,
                    EscChange::Power(on) => self.esc_power = on,
                }
            }
            let drive = if self.esc_power {
                self.esc_us
            } else {
                // Unpowered ESCs push nothing, whatever their pulse.
                [NEUTRAL_US; 3]
            };
            self.plant.step(drive, SIM_STEP.as_secs_f64());
            self.sim_time = end;
        }
        // Written by `t`: on the pins now, and driving the step under way.
        while let Some(&(at, change)) = self.pending.front() {
            if at > t {
                break;
            }
            self.pending.pop_front();
            match change {
                EscChange::Pulses(us) => self.esc_us = us,
                EscChange::Power(on) => self.esc_power = on,
            }
        }
    }

    fn change(&mut self, at: Duration, change: EscChange) {
        self.step_to(at);
        self.pending.push_back((at, change));
    }
}

impl Hardware for Wiring {
    fn read_sensors(&mut self, at: Duration) -> Readings {
        self.step_to(at);
        self.plant.read(at)
    }

    fn read_power(&mut self, at: Duration) -> Readings {
        self.step_to(at);
        self.plant.read_clean()
    }

    fn write_escs(&mut self, at: Duration, us: [u16; 3]) {
        self.change(at, EscChange::Pulses(us));
    }

    fn esc_power(&mut self, at: Duration, on: bool) {
        self.change(at, EscChange::Power(on));
    }

    fn record(&mut self, r: BoardRecord) {
        if self.recording {
            self.records.push(r);
        }
    }

    fn telemetry(&mut self, line: String) -> Vec<u8> {
        let mut out = Vec::with_capacity(line.len() + 2);
        self.faults.emit(line, &mut out);
        out
    }
}

/// The emulated board (sans-IO).
#[derive(Debug)]
pub struct Board {
    sketch: Sketch,
    uart: Uart,
    wiring: Wiring,
    stalled: bool,
    now: Duration,
}

impl Board {
    /// A board at power-up; nothing is printed until [`Board::start`].
    ///
    /// # Panics
    /// If `opts.sim` is invalid (see [`SimOptions::validate`](crate::sim::SimOptions::validate)); the defaults
    /// and [`EmulatorOptions::ideal_thesis`] never are. Use
    /// [`Board::try_new`] for options that come from a user.
    pub fn new(opts: EmulatorOptions) -> Self {
        match Self::try_new(opts) {
            Ok(board) => board,
            Err(e) => panic!("{e}"),
        }
    }

    /// A board at power-up, or why its simulator options are unusable.
    pub fn try_new(opts: EmulatorOptions) -> Result<Self, SimError> {
        let plant = Plant::new(&opts.sim, opts.wiring_directions)?;
        let sketch = Sketch::new(SketchConfig {
            firmware: opts.imitated(),
            sensors: opts.sensors.clone(),
            deadzone_us: opts.deadzone_us,
            reverse_multiplier: opts.reverse_multiplier,
            nav_period_ms: opts.nav_period_ms,
            status_period_ms: opts.status_period_ms,
            version: opts.version.clone(),
        });
        Ok(Self {
            sketch,
            uart: Uart::default(),
            wiring: Wiring {
                plant,
                sim_time: Duration::ZERO,
                horizon: Duration::ZERO,
                pending: VecDeque::new(),
                esc_us: [NEUTRAL_US; 3],
                esc_power: false,
                faults: FaultInjector::new(opts.faults.clone()),
                records: Vec::new(),
                recording: false,
            },
            stalled: false,
            now: Duration::ZERO,
        })
    }

    /// Keep every received frame and executed command (read back with
    /// [`Board::take_records`]).
    pub fn record(&mut self, on: bool) {
        self.wiring.recording = on;
    }

    /// Frames received and commands executed since the last call.
    pub fn take_records(&mut self) -> Vec<BoardRecord> {
        std::mem::take(&mut self.wiring.records)
    }

    /// Sets the simulated vehicle's pose and 4-DOF velocities (tests,
    /// scenario start): [`Plant::set_pose`] then [`Plant::set_velocities`].
    /// With the 6-DOF model the vehicle starts level with no roll or pitch
    /// rate, and the thrusters restart from rest.
    pub fn set_sim_state(&mut self, s: SimState) {
        let p = &mut self.wiring.plant;
        p.set_pose(s.eta[0], s.eta[1], s.eta[2], s.eta[3]);
        p.set_velocities(s.nu[0], s.nu[1], s.nu[2], s.nu[3]);
    }

    /// The simulated vehicle.
    pub fn plant(&self) -> &Plant {
        &self.wiring.plant
    }

    /// The simulated vehicle, to set a scenario up.
    pub fn plant_mut(&mut self) -> &mut Plant {
        &mut self.wiring.plant
    }

    /// Stalls the board: it neither reads nor prints, as a hung firmware.
    pub fn set_stalled(&mut self, stalled: bool) {
        self.stalled = stalled;
    }

    /// Power-up at `now`: the sketch's `setup()` begins; its chatter and
    /// `boot:1;` come out with the following [`Board::tick`]s.
    pub fn start(&mut self, now: Duration, out: &mut Vec<u8>) {
        self.now = now;
        self.wiring.sim_time = now;
        self.wiring.horizon = now;
        self.sketch.power_on(now);
        self.run(now, out);
    }

    /// Bytes from the host at `now`. They cross the wire at 115200 baud
    /// into the board's receive ring; the sketch reads them in the
    /// following [`Board::tick`]s.
    pub fn receive(&mut self, bytes: &[u8], now: Duration, out: &mut Vec<u8>) {
        self.tick(now, out);
        if self.stalled || !self.sketch.powered() {
            return;
        }
        self.uart.host_wrote(bytes, now);
    }

    /// Advances the board to `now`: runs the sketch, steps the simulator
    /// and hands over what the board has printed by then.
    pub fn tick(&mut self, now: Duration, out: &mut Vec<u8>) {
        if !self.sketch.powered() || now < self.now {
            return;
        }
        self.now = now;
        self.run(now, out);
    }

    fn run(&mut self, now: Duration, out: &mut Vec<u8>) {
        self.wiring.horizon = now;
        if self.stalled {
            // A hung board does nothing, but time and physics go on.
            self.uart.drop_input();
            self.sketch.hang_until(now);
        } else {
            self.sketch.run_until(now, &mut self.uart, &mut self.wiring);
        }
        self.wiring.step_to(now);
        // What the passes run for this tick printed goes out with it, even
        // the end of a pass that ran a little past `now`; a pass held up by
        // a long `delay` keeps what it prints after it.
        let printed_by = match self.sketch.between_passes() {
            Some(clock) => clock.max(now),
            None => now,
        };
        self.uart.release(printed_by, out);
    }

    /// When [`Board::tick`] next has something to do: print, move a
    /// thruster, read a frame that has arrived; at least every 200 ms.
    pub fn next_deadline(&self) -> Duration {
        let idle = self.now + IDLE_WAKE;
        let mut next = match self.uart.next_release() {
            Some(at) => idle.min(at),
            None => idle,
        };
        if self.sketch.powered() && !self.stalled {
            next = next.min(self.sketch.next_deadline(&self.uart));
        }
        next
    }

    /// Commands executed since power-up (cheaper than a snapshot, for the
    /// pty wrapper to know when one is due).
    pub(super) fn executed_total(&self) -> u64 {
        self.sketch.counters().3
    }

    /// The board and the simulated vehicle right now.
    pub fn snapshot(&self) -> BoardSnapshot {
        let c = |v: i32| v.clamp(0, i32::from(u16::MAX)) as u16;
        let (frames_ok, crc_failures, overruns, executed_total) = self.sketch.counters();
        let (armed, tripped) = self.sketch.dead_man();
        let (tilt, tilt_target) = self.sketch.tilt();
        BoardSnapshot {
            uptime_ms: self.now.as_millis() as u64,
            target_us: self.sketch.targets().map(c),
            motors_us: self.wiring.esc_us,
            motors_attached: self.sketch.motors_attached(),
            escs_powered: self.wiring.esc_power,
            dead_man_armed: armed,
            dead_man_tripped: tripped,
            lights: self.sketch.lights().clamp(0, 255) as u8,
            laser: self.sketch.laser().clamp(0, 255) as u8,
            tilt_us: c(tilt),
            tilt_target_us: c(tilt_target),
            frames_ok,
            crc_failures,
            overruns,
            rx_lost: self.uart.rx_lost(),
            stalled: self.stalled,
            executed_total,
            sim: SimSnapshot::from(&self.wiring.plant.truth()),
            faults: self.wiring.faults.stats(),
        }
    }
}
