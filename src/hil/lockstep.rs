//! The genuine firmware beside a scenario, on simulated time: `neptunus
//! sim-report --hil` runs the closed-loop scenarios ([`crate::scenario`])
//! with the real firmware in the loop instead of the board emulator.
//!
//! Owns [`HilRig`], a [`Rig`] that steps the firmware in simavr by
//! simulated cycles in lock-step with the scenario's 10-ms step (in 1-ms
//! slices, as the real-time runner does) rather than pacing it to the wall
//! clock: it runs as fast as simavr can, and the same inputs give the same
//! run. Between the vehicle core and the firmware is the serial link's own
//! sans-IO session (`firmware::link::session`: handshake, the dead-man
//! ping, coalescing, pacing by the board's echoes), the frames encoded with
//! the firmware's framing and put on its UART line at the baud rate; what
//! the firmware prints is decoded by the same session into the link's
//! events. The measured ESC pulses drive the simulated vehicle and its
//! readings go back to the sensors through [`super::surroundings`], the
//! coupling `neptunus --hil` uses. [`GenuineRigs`] makes one rig per
//! scenario (the firmware booted afresh) and says what each did.
//!
//! The session keeps its time as `Instant`s: simulated time is laid onto
//! them from one origin taken when a rig is made. Nothing waits on that
//! clock or reads it again; it is only where the board's time zero sits.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use super::avr::{AvrError, F_CPU_HZ};
use super::bench::{Bench, Wiring};
use super::compile::Firmware;
use super::ms5803::Water;
use super::pins::PulseChange;
use super::surroundings::Surroundings;
use crate::firmware::codec::{Command, Event};
use crate::firmware::emulator::{EmulatorOptions, SimSnapshot};
use crate::firmware::link::session::{Output, Session};
use crate::firmware::link::{LinkConfig, LinkEvent, LinkState};
use crate::scenario::Rig;
use crate::scenario::report::{Metric, Rigs};
use crate::sim::plant::SimError;

/// Simulated time between looks at the link and the sensors.
const SLICE_CYCLES: u64 = F_CPU_HZ / 1000;
/// Board time the firmware may take from power-up to its first navigation
/// line on a link that is up (30.0.2 sets up its IMU for about 2.2 s).
const BOOT_LIMIT: Duration = Duration::from_secs(20);

/// Why a run with the genuine firmware could not be made or finished.
#[derive(Debug, thiserror::Error)]
pub enum LockstepError {
    #[error("the simulator's options: {0}")]
    Sim(#[from] SimError),
    #[error(transparent)]
    Avr(#[from] AvrError),
    #[error(
        "the genuine firmware {elf} printed no navigation line on a link that is up within {limit_s} s of board time (handshakes: {handshakes}, lines decoded: {lines}) — pass the controller board's firmware (an openrov-software-arduino checkout, its OpenROV folder or its .elf)"
    )]
    NoLink {
        elf: PathBuf,
        limit_s: u64,
        handshakes: u64,
        lines: u64,
    },
    #[error(
        "scenario {scenario}: the genuine board stopped after {board_time_s:.1} s of board time: {source}"
    )]
    Stopped {
        scenario: usize,
        board_time_s: f64,
        source: AvrError,
    },
}

/// What the firmware's side of one run amounted to, from power-up on.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Figures {
    /// Lines of the firmware's the link decoded and accepted.
    pub lines: u64,
    /// Navigation lines that carried a depth (`deap`), decoded.
    pub depth_lines: u64,
    /// Lines the decoder rejected.
    pub rejected_lines: u64,
    /// Frames the firmware said failed its CRC check.
    pub crc_failures: u64,
    /// Thruster commands the firmware echoed (it took them).
    pub thrust_echoed: u64,
    /// Board time from power-up to the link up (before the scenario's time zero).
    pub boot_s: f64,
}

/// The genuine firmware and the simulated vehicle it drives, stepped on a
/// scenario's time (see the module docs). Lives on the thread that made it.
pub struct HilRig {
    bench: Bench,
    vehicle: Surroundings,
    session: Session,
    /// Where the board's cycle 0 sits on the session's clock.
    origin: Instant,
    /// The board's cycle at the scenario's time zero (after boot).
    cycle_at_zero: u64,
    out: Vec<u8>,
    changes: Vec<PulseChange>,
    frame: Vec<u8>,
    figures: Figures,
    failure: Option<AvrError>,
}

impl std::fmt::Debug for HilRig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HilRig")
            .field("bench", &self.bench)
            .field("figures", &self.figures)
            .finish_non_exhaustive()
    }
}

impl HilRig {
    /// Powers up the board running `firmware` in the simulated vehicle of
    /// `opts`, at rest at this depth and heading, and runs it until the
    /// link is up and the firmware prints navigation lines: a ROV on deck,
    /// its board in its loop, before the scenario's time zero. (The link
    /// may report itself up earlier, on the firmware's set-up prints;
    /// commands then would meet a board still setting up.)
    pub fn boot(
        firmware: &Firmware,
        opts: &EmulatorOptions,
        depth_m: f64,
        heading_deg: f64,
    ) -> Result<Self, LockstepError> {
        let mut vehicle = Surroundings::new(opts)?;
        vehicle.place(depth_m, heading_deg);
        let sensed = vehicle.sensed(Water::default());
        let wiring = Wiring {
            analog: sensed.analog,
            ..Wiring::default()
        };
        let mut bench = Bench::load(&firmware.elf, &wiring)?;
        bench.set_water(sensed.water);
        bench.set_attitude(sensed.attitude);
        let mut cfg = LinkConfig::new(&firmware.elf);
        cfg.framing = firmware.framing;
        let origin = Instant::now();
        let mut session = Session::new(cfg);
        session.opened(origin);
        let mut rig = Self {
            bench,
            vehicle,
            session,
            origin,
            cycle_at_zero: 0,
            out: Vec::with_capacity(1024),
            changes: Vec::with_capacity(16),
            frame: Vec::with_capacity(64),
            figures: Figures::default(),
            failure: None,
        };
        let mut events = Vec::new();
        let limit = cycles(BOOT_LIMIT);
        let (mut up, mut navigating) = (false, false);
        while !(up && navigating) && rig.bench.cycle() < limit {
            let next = rig.bench.cycle() + cycles(Duration::from_millis(10));
            rig.run_to(next, &mut events);
            if let Some(e) = rig.failure.take() {
                return Err(e.into());
            }
            for e in events.drain(..) {
                match e {
                    LinkEvent::State { state, .. } => up = state == LinkState::Up,
                    LinkEvent::Telemetry(Event::Nav(_)) => navigating = up,
                    LinkEvent::Telemetry(_) | LinkEvent::Quality(_) => {}
                }
            }
        }
        if !(up && navigating) {
            return Err(LockstepError::NoLink {
                elf: firmware.elf.clone(),
                limit_s: BOOT_LIMIT.as_secs(),
                handshakes: rig.session.stats().handshakes,
                lines: rig.session.stats().decode.lines_accepted,
            });
        }
        rig.cycle_at_zero = rig.bench.cycle();
        // The vehicle drifted while the board set up: the scenario starts
        // where it said.
        rig.place(depth_m, heading_deg);
        rig.figures.boot_s = seconds(rig.cycle_at_zero);
        Ok(rig)
    }

    /// What the firmware's side of the run amounted to so far.
    pub fn figures(&self) -> Figures {
        let stats = self.session.stats();
        Figures {
            lines: stats.decode.lines_accepted,
            rejected_lines: stats.decode.rejected_total(),
            crc_failures: stats.crc_failures_echoed,
            thrust_echoed: stats.thrust_echoed,
            ..self.figures
        }
    }

    /// Why the board stopped, if it did (it then stays stopped).
    pub fn failure(&self) -> Option<&AvrError> {
        self.failure.as_ref()
    }

    /// Board time since power-up (s).
    pub fn board_time_s(&self) -> f64 {
        seconds(self.bench.cycle())
    }

    fn instant(&self, cycle: u64) -> Instant {
        let ns = u128::from(cycle) * 1_000_000_000 / u128::from(F_CPU_HZ);
        self.origin + Duration::from_nanos(ns.min(u128::from(u64::MAX)) as u64)
    }

    /// Runs the board, the link and the water to cycle `end`.
    fn run_to(&mut self, end: u64, events: &mut Vec<LinkEvent>) {
        while self.failure.is_none() && self.bench.cycle() < end {
            let cycle = self.bench.cycle();
            let t = self.instant(cycle);
            while let Some(cmd) = self.session.poll_transmit(t, &mut self.frame) {
                self.bench.host_wrote(&self.frame);
                self.session.transmitted(&cmd, self.frame.len(), t);
            }
            self.session.poll_timers(t);
            let slice_end = (cycle + SLICE_CYCLES).min(end);
            if let Err(e) = self
                .bench
                .run_until(slice_end, &mut self.out, &mut self.changes)
            {
                self.failure = Some(e);
            }
            // The pins are read as a whole (`Bench::pins`), not change by change.
            self.changes.clear();
            let now = self.bench.cycle();
            if !self.out.is_empty() {
                self.session.received(&self.out, self.instant(now));
                self.out.clear();
            }
            self.vehicle.advance(seconds(now), self.bench.pins().esc_us);
            let sensed = self.vehicle.sensed(self.bench.water());
            self.bench.set_water(sensed.water);
            self.bench.set_attitude(sensed.attitude);
            self.bench.set_analog(sensed.analog);
            self.deliver(events);
        }
    }

    /// Hands on what the session decided, in its order.
    fn deliver(&mut self, events: &mut Vec<LinkEvent>) {
        while let Some(out) = self.session.poll_output() {
            // The figures are read from the session when asked for.
            if let Output::Event(ev) = out {
                if let LinkEvent::Telemetry(Event::Nav(nav)) = &ev {
                    self.figures.depth_lines += u64::from(nav.depth_m.is_some());
                }
                events.push(ev);
            }
        }
    }

    fn cycle_of(&self, now: Duration) -> u64 {
        self.cycle_at_zero + cycles(now)
    }
}

impl Rig for HilRig {
    fn place(&mut self, depth_m: f64, heading_deg: f64) {
        self.vehicle.place(depth_m, heading_deg);
        let sensed = self.vehicle.sensed(self.bench.water());
        self.bench.set_water(sensed.water);
        self.bench.set_attitude(sensed.attitude);
    }

    fn command(&mut self, cmd: &Command, _now: Duration) {
        self.session.command(*cmd);
    }

    fn healthy(&mut self, now: Duration) {
        let t = self.instant(self.cycle_of(now));
        self.session.healthy(t);
    }

    fn step(&mut self, now: Duration, events: &mut Vec<LinkEvent>) {
        let end = self.cycle_of(now);
        self.run_to(end, events);
    }

    fn truth(&self) -> SimSnapshot {
        self.vehicle.truth()
    }
}

fn cycles(d: Duration) -> u64 {
    (d.as_nanos() * u128::from(F_CPU_HZ) / 1_000_000_000) as u64
}

fn seconds(cycle: u64) -> f64 {
    cycle as f64 / F_CPU_HZ as f64
}

/// The scenarios' rigs with the genuine firmware: each scenario boots it
/// afresh in its own simulated vehicle.
#[derive(Debug, Clone)]
pub struct GenuineRigs {
    firmware: Firmware,
    /// The firmware's figures of each scenario run so far, in order.
    runs: Vec<Figures>,
}

impl GenuineRigs {
    pub fn new(firmware: Firmware) -> Self {
        Self {
            firmware,
            runs: Vec::new(),
        }
    }

    /// The firmware's figures of each scenario run so far, in order.
    pub fn runs(&self) -> &[Figures] {
        &self.runs
    }
}

impl Rigs for GenuineRigs {
    type Rig = HilRig;
    type Error = LockstepError;

    fn rig(
        &mut self,
        opts: &EmulatorOptions,
        depth_m: f64,
        heading_deg: f64,
    ) -> Result<HilRig, LockstepError> {
        HilRig::boot(&self.firmware, opts, depth_m, heading_deg)
    }

    fn label(&self) -> Option<&'static str> {
        Some("genuine firmware in simavr")
    }

    /// The BNO055 is given the true heading: no bias.
    fn compass_bias_deg(&self, _opts: &EmulatorOptions) -> f64 {
        0.0
    }

    fn finish(&mut self, rig: &HilRig) -> Result<Vec<Metric>, LockstepError> {
        if let Some(e) = rig.failure() {
            return Err(LockstepError::Stopped {
                scenario: self.runs.len() + 1,
                board_time_s: rig.board_time_s(),
                source: e.clone(),
            });
        }
        let f = rig.figures();
        self.runs.push(f);
        Ok(vec![
            ("firmware_lines", f.lines as f64, ""),
            ("firmware_depth_lines", f.depth_lines as f64, ""),
            ("firmware_rejected_lines", f.rejected_lines as f64, ""),
            ("crc_failures", f.crc_failures as f64, ""),
            ("firmware_thrust_echoed", f.thrust_echoed as f64, ""),
        ])
    }
}
