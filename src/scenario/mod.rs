//! Closed-loop scenarios on simulated time: the real vehicle core (estimator,
//! autopilots, mixer, failsafes) driving the real board emulator and its
//! simulator through the real codec, with a scripted ground station — no
//! sockets, no pty, no clock. A 60-second dive runs in a fraction of a second
//! and gives the same numbers every time (the simulator is seeded).
//!
//! Owns the loop that moves commands and telemetry between
//! [`Vehicle::handle`] and a [`Rig`] — the board and the water around it:
//! a [`BuiltinSim`], or with the feature `hil` the genuine firmware in
//! simavr stepped in lock-step (`hil::lockstep`) — and the recorded
//! samples. Used by the acceptance tests and by `neptunus sim-report`
//! ([`report`]). It must never read a clock or sleep.

#[cfg(feature = "report")]
mod plot;
#[cfg(feature = "report")]
pub use plot::PlotError;
pub mod report;

use std::time::Duration;

use crate::dialect::neptunus::*;
use crate::firmware::codec::{Command, Event};
use crate::firmware::emulator::{EmulatorOptions, SimSnapshot};
use crate::firmware::link::{LinkEvent, LinkState};
use crate::firmware::loopback::{BuiltinSim, LoopbackBoard};
use crate::vehicle::machine::{Identity, Input, Now, Output, Sender, Vehicle};
use crate::vehicle::params::ParamStore;

/// The loop period, as the app's tick.
pub const STEP: Duration = Duration::from_millis(10);
/// The scripted ground station: QGC's system id, on endpoint 0.
pub const GCS: Sender = Sender::new(0, 1, 255, 190);
/// MANUAL_CONTROL and heartbeat periods of the scripted ground station.
const STICK_PERIOD: Duration = Duration::from_millis(100);
const HEARTBEAT_PERIOD: Duration = Duration::from_secs(1);

/// Stick positions in MANUAL_CONTROL units (x, y, r in −1000..1000; z 0..1000, 500 centred).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sticks {
    pub x: i16,
    pub z: i16,
    pub r: i16,
}

impl Sticks {
    pub const CENTRED: Sticks = Sticks { x: 0, z: 500, r: 0 };
}

/// One recorded step.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Sample {
    pub t_s: f64,
    pub depth_true_m: f64,
    pub depth_measured_m: f64,
    pub depth_estimate_m: f64,
    /// NaN when depth is not held.
    pub depth_target_m: f64,
    pub heave_true_mps: f64,
    pub heave_estimate_mps: f64,
    pub heading_true_deg: f64,
    pub heading_measured_deg: f64,
    pub heading_estimate_deg: f64,
    /// NaN when heading is not held.
    pub heading_target_deg: f64,
    pub yaw_rate_true_dps: f64,
    pub yaw_rate_estimate_dps: f64,
    pub north_m: f64,
    pub east_m: f64,
    pub surge_mps: f64,
    /// Normalised demands the thrusters were given.
    pub surge_demand: f64,
    pub heave_demand: f64,
    pub yaw_demand: f64,
    pub port_us: u16,
    pub vertical_us: u16,
    pub starboard_us: u16,
    pub depth_rejected: u64,
    pub heading_rejected: u64,
}

/// What a scenario's vehicle is connected to: a board on its serial link
/// and the simulated vehicle it drives, run on the scenario's time. A rig
/// is handed to a scenario with its link up.
pub trait Rig {
    /// Places the simulated vehicle, at rest, at this depth and heading.
    fn place(&mut self, depth_m: f64, heading_deg: f64);
    /// A command from the vehicle for the board, at `now`.
    fn command(&mut self, cmd: &Command, now: Duration);
    /// The vehicle is healthy at `now` (the board's dead man is fed).
    fn healthy(&mut self, now: Duration);
    /// Runs the board and the water to `now`; what the link reports since
    /// the last step (telemetry, and changes of its state) is appended.
    fn step(&mut self, now: Duration, events: &mut Vec<LinkEvent>);
    /// Where the simulated vehicle really is.
    fn truth(&self) -> SimSnapshot;
}

impl Rig for BuiltinSim {
    fn place(&mut self, depth_m: f64, heading_deg: f64) {
        BuiltinSim::place(self, depth_m, heading_deg);
    }
    fn command(&mut self, cmd: &Command, now: Duration) {
        BuiltinSim::command(self, cmd, now);
    }
    fn healthy(&mut self, now: Duration) {
        BuiltinSim::healthy(self, now);
    }
    fn step(&mut self, now: Duration, events: &mut Vec<LinkEvent>) {
        let mut decoded: Vec<Event> = Vec::new();
        BuiltinSim::step(self, now, &mut decoded);
        events.extend(decoded.into_iter().map(LinkEvent::Telemetry));
    }
    fn truth(&self) -> SimSnapshot {
        BuiltinSim::truth(self)
    }
}

/// A vehicle, its board (the built-in simulator unless told otherwise) and
/// a scripted pilot.
pub struct Scenario<R: Rig = BuiltinSim> {
    vehicle: Vehicle,
    rig: R,
    now: Duration,
    outputs: Vec<Output>,
    events: Vec<LinkEvent>,
    sticks: Sticks,
    next_stick: Duration,
    next_heartbeat: Duration,
    samples: Vec<Sample>,
    /// Messages the vehicle sent (for assertions on texts and acks).
    pub sent: Vec<MavMessage>,
    record_every: usize,
    steps: usize,
}

impl Scenario {
    /// A vehicle with default parameters on a board with these options.
    pub fn new(opts: EmulatorOptions) -> Self {
        Self::with_params(opts, ParamStore::default())
    }

    pub fn with_params(opts: EmulatorOptions, params: ParamStore) -> Self {
        Self::on(BuiltinSim::new(opts, Duration::ZERO), params)
    }

    pub fn board(&self) -> &LoopbackBoard {
        self.rig.loopback()
    }
}

impl<R: Rig> Scenario<R> {
    /// A vehicle with these parameters connected to `rig`, at time zero.
    pub fn on(rig: R, params: ParamStore) -> Self {
        let mut s = Self {
            vehicle: Vehicle::new(Identity::Ardupilot, params, 1),
            rig,
            now: Duration::ZERO,
            outputs: Vec::with_capacity(64),
            events: Vec::with_capacity(16),
            sticks: Sticks::CENTRED,
            next_stick: Duration::ZERO,
            next_heartbeat: Duration::ZERO,
            samples: Vec::new(),
            sent: Vec::new(),
            record_every: 1,
            steps: 0,
        };
        s.input(Input::Link {
            state: LinkState::Up,
            reason: None,
        });
        s
    }

    /// Records one sample every `n` steps (1 = every 10 ms).
    pub fn record_every(&mut self, n: usize) {
        self.record_every = n.max(1);
    }

    fn clock(&self) -> Now {
        Now {
            mono: self.now,
            unix_us: 1_800_000_000_000_000 + self.now.as_micros() as u64,
        }
    }

    fn input(&mut self, input: Input) {
        let now = self.clock();
        self.vehicle.handle(input, now, &mut self.outputs);
        self.apply();
    }

    fn apply(&mut self) {
        for out in std::mem::take(&mut self.outputs) {
            match out {
                Output::Board(cmd) => self.rig.command(&cmd, self.now),
                Output::Healthy => self.rig.healthy(self.now),
                Output::Send { msg, .. } | Output::Text { msg, .. } => self.sent.push(msg),
                _ => {}
            }
        }
    }

    /// A message from the scripted ground station.
    pub fn gcs(&mut self, msg: MavMessage) {
        self.input(Input::Mavlink { from: GCS, msg });
    }

    fn command(&mut self, command: MavCmd, p: [f32; 7]) -> Option<MavResult> {
        self.sent.clear();
        self.gcs(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: 1,
            target_component: 1,
            command,
            confirmation: 0,
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
        }));
        self.sent.iter().find_map(|m| match m {
            MavMessage::COMMAND_ACK(a) if a.command == command => Some(a.result),
            _ => None,
        })
    }

    /// Arms (after the pre-arm checks).
    pub fn arm(&mut self) -> Option<MavResult> {
        self.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    /// MAV_CMD_DO_SET_MODE with an ArduSub custom mode.
    pub fn set_mode(&mut self, mode: u32) -> Option<MavResult> {
        self.command(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, mode as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    /// Held depth (m) as ArduSub's documented pymavlink example sets it.
    pub fn set_depth_target(&mut self, depth_m: f64) {
        let ignore_all_but_z = 0b0000_1101_1111_1011u16; // x, y, vx.., yaw, yaw rate ignored
        self.gcs(MavMessage::SET_POSITION_TARGET_GLOBAL_INT(
            SET_POSITION_TARGET_GLOBAL_INT_DATA {
                time_boot_ms: 0,
                lat_int: 0,
                lon_int: 0,
                alt: -depth_m as f32,
                vx: 0.0,
                vy: 0.0,
                vz: 0.0,
                afx: 0.0,
                afy: 0.0,
                afz: 0.0,
                yaw: 0.0,
                yaw_rate: 0.0,
                type_mask: PositionTargetTypemask::from_bits_truncate(ignore_all_but_z),
                target_system: 1,
                target_component: 1,
                coordinate_frame: MavFrame::MAV_FRAME_GLOBAL,
            },
        ));
    }

    /// Held heading (deg) through our dialect's command.
    pub fn set_heading_target(&mut self, heading_deg: f64) -> Option<MavResult> {
        self.command(
            MavCmd::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET,
            [f32::NAN, heading_deg as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    /// MAV_CMD_NEPTUNUS_SET_RUN_MODE. The scenario's plant is the board, so
    /// in simulator run mode the plant gets no thrust (the board is stopped).
    pub fn set_run_mode(&mut self, mode: crate::vehicle::machine::RunMode) -> Option<MavResult> {
        let p1 = match mode {
            crate::vehicle::machine::RunMode::Normal => 0.0,
            crate::vehicle::machine::RunMode::Simulator => 1.0,
        };
        self.command(
            MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE,
            [p1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    pub fn set_sticks(&mut self, s: Sticks) {
        self.sticks = s;
    }

    /// Places the simulated vehicle (at rest).
    pub fn place(&mut self, depth_m: f64, heading_deg: f64) {
        self.rig.place(depth_m, heading_deg);
    }

    /// Runs for `duration` of simulated time, the ground station sending its
    /// heartbeat and sticks as QGC would.
    pub fn run(&mut self, duration: Duration) {
        let end = self.now + duration;
        while self.now < end {
            self.now += STEP;
            if self.now >= self.next_heartbeat {
                self.next_heartbeat = self.now + HEARTBEAT_PERIOD;
                self.gcs(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 0,
                    mavtype: MavType::MAV_TYPE_GCS,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                    base_mode: MavModeFlag::empty(),
                    system_status: MavState::MAV_STATE_ACTIVE,
                    mavlink_version: 3,
                }));
            }
            if self.now >= self.next_stick {
                self.next_stick = self.now + STICK_PERIOD;
                let s = self.sticks;
                self.gcs(MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
                    target: 1,
                    x: s.x,
                    y: 0,
                    z: s.z,
                    r: s.r,
                    buttons: 0,
                    ..Default::default()
                }));
            }
            self.rig.step(self.now, &mut self.events);
            for ev in std::mem::take(&mut self.events) {
                self.input(match ev {
                    LinkEvent::State { state, reason } => Input::Link { state, reason },
                    LinkEvent::Telemetry(ev) => Input::Board(ev),
                    LinkEvent::Quality(q) => Input::LinkQuality(q),
                });
            }
            self.input(Input::Tick);
            self.steps += 1;
            if self.steps.is_multiple_of(self.record_every) {
                self.record();
            }
        }
    }

    fn record(&mut self) {
        let now = self.clock();
        let truth = self.rig.truth();
        let e = self.vehicle.estimate(now);
        let (depth_target, heading_target) = self.vehicle.targets();
        let demand = self.vehicle.applied_demand();
        let us = self.vehicle.motors_us();
        self.samples.push(Sample {
            t_s: self.now.as_secs_f64(),
            depth_true_m: truth.depth_m,
            depth_measured_m: self.vehicle.raw_depth_m().unwrap_or(f64::NAN),
            depth_estimate_m: if self.vehicle.raw_depth_m().is_some() {
                e.depth_m
            } else {
                f64::NAN
            },
            depth_target_m: depth_target.unwrap_or(f64::NAN),
            heave_true_mps: truth.heave_mps,
            heave_estimate_mps: e.heave_mps,
            heading_true_deg: truth.heading_deg,
            heading_measured_deg: self.vehicle.raw_heading_deg().unwrap_or(f64::NAN),
            heading_estimate_deg: if self.vehicle.raw_heading_deg().is_some() {
                e.heading_deg
            } else {
                f64::NAN
            },
            heading_target_deg: heading_target.unwrap_or(f64::NAN),
            yaw_rate_true_dps: truth.yaw_rate_dps,
            yaw_rate_estimate_dps: e.yaw_rate_dps,
            north_m: truth.north_m,
            east_m: truth.east_m,
            surge_mps: truth.surge_mps,
            surge_demand: demand.surge,
            heave_demand: demand.heave,
            yaw_demand: demand.yaw,
            port_us: us[0],
            vertical_us: us[1],
            starboard_us: us[2],
            depth_rejected: e.depth_rejected,
            heading_rejected: e.heading_rejected,
        });
    }

    pub fn samples(&self) -> &[Sample] {
        &self.samples
    }

    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The board and water the vehicle is connected to.
    pub fn rig(&self) -> &R {
        &self.rig
    }

    pub fn now(&self) -> Duration {
        self.now
    }
}

impl<R: Rig> Scenario<R> {
    /// The vehicle, for assertions on the core after a scenario.
    pub fn into_vehicle(self) -> Vehicle {
        self.vehicle
    }
}
