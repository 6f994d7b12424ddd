//! The vehicle core: one state machine that owns everything the vehicle
//! knows and decides, driven by [`Vehicle::handle`].
//!
//! Sans-IO: inputs are decoded MAVLink messages, board events and ticks,
//! each with the time as an argument; outputs are messages to send, board
//! commands and requests to persist parameters. Nothing here reads a clock,
//! sleeps or touches a socket — so every rule is testable with synthetic time.
//!
//! It must never let a thruster move while disarmed: every `go()` it emits
//! while disarmed is neutral.

// Ground stations still send the legacy messages and commands MAVLink has
// deprecated (SET_MODE, REQUEST_DATA_STREAM, PING, GET_MESSAGE_INTERVAL …);
// an ArduSub-compatible vehicle must answer them.
#![allow(deprecated)]

use std::time::Duration;

use mavlink_core::MessageData;
use mavlink_core::types::CharArray;

mod authority;
mod driving;
mod failsafe;
mod holds;
mod param_set;
mod persist;
mod texts;

pub use holds::RunMode;
pub use persist::{SAVE_DEBOUNCE, SAVE_MAX_DELAY};
use texts::ReplyKind;
pub use texts::ascii_text;

use super::input::Profiles;
pub use super::mode::Mode;
use super::params::ParamStore;
use super::telemetry::{self, Schedule};
use crate::dialect::neptunus::*;
pub use crate::eventlog::LogEvent;
use crate::firmware::codec::{Command, Event, NavSample, StatusSample};
use crate::firmware::link::LinkState;

/// Our MAVLink component id (the autopilot).
pub const COMPONENT_ID: u8 = 1;
/// Telemetry older than this is not re-sent as if fresh.
pub const FRESH: Duration = Duration::from_millis(1500);
/// Parameters sent per tick while a list is being streamed (a burst of
/// hundreds of datagrams can overflow a ground station's socket buffer).
const PARAMS_PER_TICK: usize = 20;

/// Where an output message goes (the app maps this onto its endpoints).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum To {
    /// Every peer on every endpoint.
    All,
    /// Every peer on one endpoint.
    Endpoint(usize),
    /// One peer.
    Peer(usize, u64),
}

/// Who sent a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sender {
    pub endpoint: usize,
    pub peer: u64,
    pub sysid: u8,
    pub compid: u8,
    /// The frame carried a valid MAVLink 2 signature with our key.
    pub signed: bool,
    /// It came over an endpoint marked trusted (SETUP_SIGNING is accepted there).
    pub trusted: bool,
    /// A browser HMI session whose operator is a pilot (gave the pilot
    /// password, or none is configured): allowed to request and take control
    /// whatever its system id, like a station in the NEPT_GCS_ALLOWn list.
    pub pilot: bool,
}

impl Sender {
    /// An unsigned sender on an untrusted endpoint.
    pub const fn new(endpoint: usize, peer: u64, sysid: u8, compid: u8) -> Self {
        Self {
            endpoint,
            peer,
            sysid,
            compid,
            signed: false,
            trusted: false,
            pilot: false,
        }
    }

    fn reply(&self) -> To {
        To::Peer(self.endpoint, self.peer)
    }
}

/// Time as the core sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Now {
    /// Monotonic time since the vehicle started.
    pub mono: Duration,
    /// Wall clock, µs since the Unix epoch.
    pub unix_us: u64,
}

/// What the core reacts to.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    Mavlink {
        from: Sender,
        msg: MavMessage,
    },
    Board(Event),
    /// Telemetry of the built-in simulator (run mode SIMULATOR).
    SimBoard(Event),
    Link {
        state: LinkState,
        reason: Option<String>,
    },
    /// Periodic (the app ticks at 100 Hz): telemetry, timeouts.
    Tick,
    /// Ground truth from the simulator (only when running on it).
    SimTruth(SimTruth),
    /// Something happened to a browser HMI session (the HMI sends these; the
    /// core acts on them like on any ground station's).
    Hmi {
        sysid: u8,
        event: HmiEvent,
    },
    /// The answer to [`Output::SaveParams`]: the parameters reached the disk,
    /// or why not.
    ParamsSaved(Result<(), String>),
    /// A PARAM_SET whose `param_type` is not a MAV_PARAM_TYPE value (the
    /// frame decoder cannot represent it as a message): answered with the
    /// parameter's current value.
    BadParamSet {
        from: Sender,
        target_system: u8,
        target_component: u8,
        param_id: [u8; 16],
        param_type: u8,
    },
    /// A COMMAND_LONG/COMMAND_INT whose number our dialect does not define.
    UnknownCommand {
        from: Sender,
        command: u16,
        target_system: u8,
        target_component: u8,
    },
}

/// Events of a browser HMI session that matter for safety.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HmiEvent {
    /// The window lost focus (the operator is looking elsewhere).
    FocusLost,
    /// The operator switched input device (keyboard, touch, gamepad).
    InputModeChanged,
    /// The session's WebSocket closed.
    Disconnected,
}

/// The simulated vehicle's true state, in plain units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimTruth {
    pub north_m: f64,
    pub east_m: f64,
    pub depth_m: f64,
    pub heading_rad: f64,
    pub surge_mps: f64,
    pub sway_mps: f64,
    pub heave_mps: f64,
    pub yaw_rate_rps: f64,
    /// Roll and pitch (0 in the 4-DOF model).
    pub roll_rad: f64,
    pub pitch_rad: f64,
}

/// What the core asks the I/O around it to do.
// Outputs live briefly in a reused Vec; boxing every message would cost an
// allocation per send for no gain.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    Send {
        to: To,
        msg: MavMessage,
    },
    Board(Command),
    /// A command for the built-in simulator's board (run mode SIMULATOR).
    SimBoard(Command),
    /// The run mode changed: route thruster commands and telemetry
    /// accordingly; a new simulator starts at the given depth and heading.
    RunMode {
        mode: RunMode,
        start_depth_m: f64,
        start_heading_deg: f64,
    },
    /// Parameters changed: write `Vehicle::params()` to disk off the
    /// vehicle task, and answer with [`Input::ParamsSaved`]. Never asked
    /// again before that answer.
    SaveParams,
    /// The board's dead-man switch may be fed now: the core is alive and
    /// the owner showed life recently (or the vehicle is disarmed, or a
    /// failsafe action needs thrust).
    Healthy,
    /// A line for the event log.
    Log(LogEvent),
    /// A trusted SETUP_SIGNING: persist this key (all zero = signing off)
    /// and never let our signing timestamp fall below `initial_timestamp`.
    SetSigningKey {
        key: [u8; 32],
        initial_timestamp: u64,
    },
    /// COMMAND_ACK for a command number the dialect cannot represent.
    AckUnknown {
        to: To,
        command: u16,
        result: MavResult,
        target_system: u8,
        target_component: u8,
    },
}

/// How the vehicle presents itself.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Identity {
    /// ArduSub-compatible (autopilot ARDUPILOTMEGA): QGC's Sub plugin, pymavlink's mode map.
    #[default]
    Ardupilot,
    /// MAV_AUTOPILOT_GENERIC: generic ground-station plugins, REAL32 parameters.
    Generic,
}

/// All thrusters neutral.
pub const NEUTRAL_GO: Command = Command::Go {
    port_us: 1500,
    vertical_us: 1500,
    starboard_us: 1500,
};

// The mode numbers by name, for code and tests that speak `custom_mode`.
pub const MODE_MANUAL: u32 = Mode::Manual.number();
pub const MODE_MANUAL_THRUSTERS: u32 = Mode::ManualThrusters.number();
pub const MODE_STABILIZE: u32 = Mode::Stabilize.number();
pub const MODE_ALT_HOLD: u32 = Mode::AltHold.number();
pub const MODE_SURFACE: u32 = Mode::Surface.number();

/// The name of a `custom_mode` number ("UNKNOWN" for none of ours).
pub fn mode_name(mode: u32) -> &'static str {
    Mode::name_of(mode)
}

#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Stamped<T> {
    value: T,
    at: Option<Duration>,
}

/// Everything the vehicle knows and decides.
#[derive(Debug)]
pub struct Vehicle {
    identity: Identity,
    params: ParamStore,
    mode: Mode,
    armed: bool,
    link: LinkState,
    link_reason: Option<String>,
    heading_deg: Stamped<f64>,
    depth_m: Stamped<f64>,
    pitch_deg: Stamped<f64>,
    roll_deg: Stamped<f64>,
    prev_heading: Option<(Duration, f64)>,
    yaw_rate_rps: f64,
    status: Stamped<StatusSample>,
    consumed_mah: f64,
    last_current: Option<(Duration, f64)>,
    lights: u8,
    last_lights_on: u8,
    laser: u8,
    tilt_us: u16,
    gain: f64,
    motors_us: [u16; 3],
    schedules: Vec<Schedule>,
    param_queue: Vec<(To, usize)>,
    statustext_id: u16,
    /// The system id in use; SYSID_THISMAV changes apply at the next start.
    sysid: u8,
    /// System ids the browser HMI lends to its sessions (ground stations).
    hmi_sysids: (u8, u8),
    replies: texts::Replies,
    persist: persist::Persist,
    storage_problem: Option<String>,
    /// Telemetry-rate requests refused (stations that may not control).
    refused_rate_requests: u64,
    /// PARAM_SETs whose param_type was not acceptable.
    bad_param_types: u64,
    booted: Duration,
    started: bool,
    pilot: driving::Pilot,
    profiles: std::sync::Arc<Profiles>,
    sim_truth: Stamped<SimTruth>,
    tilt_accum: f64,
    last_tick: Option<Duration>,
    auth: authority::Authority,
    /// The last station that owned the vehicle (for failsafe texts).
    last_owner: Option<u8>,
    failsafes: failsafe::Failsafes,
    /// Low and critical battery thresholds.
    battery: [failsafe::BatteryWatch; 2],
    signing_active: bool,
    armed_at: Option<Duration>,
    link_seen_up: bool,
    holds: holds::Holds,
}

fn chars<const N: usize>(s: &str) -> CharArray<N> {
    CharArray::from(s)
}

fn char_str<const N: usize>(c: &CharArray<N>) -> String {
    let bytes: &[u8] = c.as_ref();
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// NaN means "not given" (MAVSDK sends unused params as NaN).
fn given(v: f32) -> Option<f32> {
    (!v.is_nan()).then_some(v)
}

impl Vehicle {
    pub fn new(identity: Identity, params: ParamStore, endpoints: usize) -> Self {
        let gain = params.get("JS_GAIN_DEFAULT").unwrap_or(0.5);
        let sysid = params.sysid_thismav();
        Self {
            identity,
            params,
            mode: Mode::BOOT,
            armed: false,
            link: LinkState::Down,
            link_reason: None,
            heading_deg: Stamped::default(),
            depth_m: Stamped::default(),
            pitch_deg: Stamped::default(),
            roll_deg: Stamped::default(),
            prev_heading: None,
            yaw_rate_rps: 0.0,
            status: Stamped::default(),
            consumed_mah: 0.0,
            last_current: None,
            lights: 0,
            last_lights_on: 255,
            laser: 0,
            tilt_us: 1500,
            gain,
            motors_us: [1500; 3],
            schedules: vec![Schedule::default(); endpoints.max(1)],
            param_queue: Vec::new(),
            statustext_id: 0,
            sysid,
            hmi_sysids: (200, 209),
            replies: texts::Replies::default(),
            persist: persist::Persist::default(),
            storage_problem: None,
            refused_rate_requests: 0,
            bad_param_types: 0,
            booted: Duration::ZERO,
            started: false,
            pilot: driving::Pilot::default(),
            sim_truth: Stamped::default(),
            profiles: std::sync::Arc::new(Profiles::builtin()),
            tilt_accum: 0.0,
            last_tick: None,
            auth: authority::Authority::default(),
            last_owner: None,
            failsafes: failsafe::Failsafes::default(),
            battery: Default::default(),
            signing_active: false,
            armed_at: None,
            link_seen_up: false,
            holds: holds::Holds::default(),
        }
    }

    /// Ground-station conventions (default: the profiles built into the binary).
    pub fn with_profiles(mut self, profiles: Profiles) -> Self {
        self.profiles = std::sync::Arc::new(profiles);
        self
    }

    /// The system ids the browser HMI lends its sessions (default 200..=209):
    /// SYSID_THISMAV may not take one of them.
    pub fn with_hmi_sysids(mut self, lo: u8, hi: u8) -> Self {
        self.hmi_sysids = (lo.min(hi), hi.max(lo));
        self
    }

    /// Telemetry-rate requests refused because the sender may not control.
    pub fn refused_rate_requests(&self) -> u64 {
        self.refused_rate_requests
    }

    /// PARAM_SETs answered with the current value because of their param_type.
    pub fn bad_param_types(&self) -> u64 {
        self.bad_param_types
    }

    /// Pilot input refused because it came from a station not in control.
    pub fn refused_inputs(&self) -> u64 {
        self.auth.input_refusals.count
    }

    /// Signing is on (a key is set): control traffic must be signed.
    pub fn set_signing_active(&mut self, active: bool) {
        self.signing_active = active;
    }
    pub fn signing_active(&self) -> bool {
        self.signing_active
    }

    pub fn params(&self) -> &ParamStore {
        &self.params
    }
    pub fn armed(&self) -> bool {
        self.armed
    }
    /// The mode's number (HEARTBEAT.custom_mode).
    pub fn mode(&self) -> u32 {
        self.mode.number()
    }
    /// The system id in use (SYSID_THISMAV as it was at start).
    pub fn sysid(&self) -> u8 {
        self.sysid
    }
    pub fn motors_us(&self) -> [u16; 3] {
        self.motors_us
    }

    /// The schedule of an endpoint (endpoint ids beyond the table share the last one).
    fn schedule_mut(&mut self, endpoint: usize) -> &mut Schedule {
        let last = self.schedules.len() - 1;
        &mut self.schedules[endpoint.min(last)]
    }

    fn param(&self, name: &str, default: f64) -> f64 {
        self.params.get(name).unwrap_or(default)
    }

    /// Reacts to one input at `now`, appending what must happen to `out`.
    pub fn handle(&mut self, input: Input, now: Now, out: &mut Vec<Output>) {
        if !self.started {
            self.started = true;
            self.booted = now.mono;
            for s in &mut self.schedules {
                *s = Schedule::with_defaults(now.mono);
            }
        }
        match input {
            Input::Tick => self.tick(now, out),
            Input::Link { state, reason } => self.on_link(state, reason, now, out),
            Input::Hmi { sysid, event } => self.on_hmi(sysid, event, now, out),
            Input::Board(ev) => {
                // In SIMULATOR run mode the board's navigation and power
                // telemetry is not the vehicle's (the simulator's is).
                let simulated = self.holds.run_mode == RunMode::Simulator;
                if !(simulated && matches!(ev, Event::Nav(_) | Event::Status(_))) {
                    self.on_board(ev, now, out);
                }
            }
            Input::SimBoard(ev) => {
                if self.holds.run_mode == RunMode::Simulator {
                    self.on_board(ev, now, out);
                }
            }
            Input::ParamsSaved(result) => self.on_params_saved(result, now, out),
            Input::BadParamSet {
                from,
                target_system,
                target_component,
                param_id,
                param_type,
            } => {
                if self.for_us(target_system, target_component) {
                    let name = char_str(&CharArray::<16>::from(param_id));
                    self.bad_param_type(from, &name, param_type, now, out);
                }
            }
            Input::UnknownCommand {
                from,
                command,
                target_system,
                target_component,
            } => {
                if self.for_us(target_system, target_component) {
                    out.push(Output::AckUnknown {
                        to: from.reply(),
                        command,
                        result: MavResult::MAV_RESULT_UNSUPPORTED,
                        target_system: from.sysid,
                        target_component: from.compid,
                    });
                }
            }
            Input::SimTruth(t) => {
                self.sim_truth = Stamped {
                    value: t,
                    at: Some(now.mono),
                }
            }
            Input::Mavlink { from, msg } => self.on_mavlink(from, msg, now, out),
        }
    }

    fn boot_ms(&self, now: Now) -> u32 {
        (now.mono.saturating_sub(self.booted)).as_millis() as u32
    }

    fn send_neutral(&mut self, out: &mut Vec<Output>) {
        self.motors_us = [1500; 3];
        self.holds.applied = driving::NO_DEMAND;
        self.send_go(NEUTRAL_GO, out);
    }

    /// A thruster command, to the board or, in SIMULATOR run mode, to the
    /// simulator (the board then stays stopped).
    fn send_go(&mut self, go: Command, out: &mut Vec<Output>) {
        match self.holds.run_mode {
            RunMode::Normal => out.push(Output::Board(go)),
            RunMode::Simulator => out.push(Output::SimBoard(go)),
        }
    }

    // ---- board ----

    fn on_link(
        &mut self,
        state: LinkState,
        reason: Option<String>,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let was = self.link;
        self.link = state;
        self.link_reason = reason.clone();
        if state == LinkState::Up && was != LinkState::Up {
            self.link_seen_up = true;
            self.log("link_up", None, "board link up".into(), out);
            // Whatever the board had, it gets what we decide now.
            self.send_neutral(out);
            let (l, t) = (self.lights, self.tilt_us);
            out.push(Output::Board(Command::Lights(l)));
            out.push(Output::Board(Command::Tilt(t)));
            if self.laser > 0 {
                out.push(Output::Board(Command::Laser(self.laser)));
            }
            self.statustext(MavSeverity::MAV_SEVERITY_INFO, "Board link up", out);
        } else if state == LinkState::Down && was != LinkState::Down {
            let why = reason.unwrap_or_else(|| "unknown".into());
            self.statustext(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("Board link down: {why}"),
                out,
            );
            self.log("link_down", None, why, out);
        }
        // The board-link failsafe disarms at once, not at the next tick.
        self.failsafe_tick(now, out);
    }

    /// Thrusters to neutral and pilot state cleared (the thesis' safety-mode
    /// stop). With `pickup`, the owner's sticks are ignored until centred.
    fn safety_stop(&mut self, pickup: bool, out: &mut Vec<Output>) {
        self.stop_pilot();
        self.pilot.hold = None;
        // An autopilot mode stops where it is: the held depth and heading are
        // taken again from the vehicle's state.
        self.holds_reset();
        // After a transfer the next button mask is a baseline: buttons the new
        // owner holds were not pressed now. Otherwise buttons start released.
        self.pilot.buttons_stale = pickup;
        if pickup {
            self.auth.pickup = true;
        } else {
            self.pilot.buttons = 0;
        }
        self.send_neutral(out);
    }

    fn on_hmi(&mut self, sysid: u8, event: HmiEvent, now: Now, out: &mut Vec<Output>) {
        let owner = self.owner() == Some(sysid);
        match event {
            HmiEvent::FocusLost | HmiEvent::InputModeChanged => {
                if owner {
                    self.safety_stop(true, out);
                }
                let kind = if event == HmiEvent::FocusLost {
                    "hmi_focus_lost"
                } else {
                    "hmi_input_mode"
                };
                self.log(kind, Some(sysid), format!("owner: {owner}"), out);
            }
            HmiEvent::Disconnected => {
                self.log(
                    "hmi_disconnected",
                    Some(sysid),
                    format!("owner: {owner}"),
                    out,
                );
                if owner {
                    self.drop_owner("control_released", "HMI session closed", now, out);
                }
            }
        }
    }

    fn on_board(&mut self, ev: Event, now: Now, out: &mut Vec<Output>) {
        let t = Some(now.mono);
        match ev {
            Event::Nav(NavSample {
                heading_deg,
                depth_m,
                pitch_deg,
                roll_deg,
                ..
            }) => {
                if let Some(h) = heading_deg {
                    if let Some((pt, ph)) = self.prev_heading {
                        let dt = now.mono.saturating_sub(pt).as_secs_f64();
                        if dt > 0.0 {
                            let d = (h - ph + 540.0).rem_euclid(360.0) - 180.0;
                            self.yaw_rate_rps = d.to_radians() / dt;
                        }
                    }
                    self.prev_heading = Some((now.mono, h));
                    self.heading_deg = Stamped { value: h, at: t };
                    self.estimator_reading(holds::Reading::Heading(h), now, out);
                }
                if let Some(d) = depth_m {
                    self.depth_m = Stamped { value: d, at: t };
                    self.estimator_reading(holds::Reading::Depth(d), now, out);
                }
                if let Some(p) = pitch_deg {
                    self.pitch_deg = Stamped { value: p, at: t };
                }
                if let Some(r) = roll_deg {
                    self.roll_deg = Stamped { value: r, at: t };
                }
            }
            Event::Status(s) => {
                if s.vout_v.is_none() {
                    // A `motors:` line on its own: keep the last full status.
                    return;
                }
                if let Some(v) = s.vout_v {
                    let low = f64::from(self.params.batt_low_volt());
                    let crt = f64::from(self.params.batt_crt_volt());
                    self.battery[0].sample(v, low, now.mono);
                    self.battery[1].sample(v, crt, now.mono);
                }
                if let Some(i) = s.btti_a.or(s.iout_a) {
                    if let Some((pt, pi)) = self.last_current {
                        let h = now.mono.saturating_sub(pt).as_secs_f64() / 3600.0;
                        self.consumed_mah += (pi + i) / 2.0 * h * 1000.0;
                    }
                    self.last_current = Some((now.mono, i));
                }
                self.status = Stamped { value: s, at: t };
            }
            Event::Lights { level, .. } => self.lights = level,
            Event::Laser(l) => self.laser = l,
            _ => {}
        }
    }

    fn fresh<T>(&self, s: &Stamped<T>, now: Now) -> bool {
        self.link == LinkState::Up && s.at.is_some_and(|t| now.mono.saturating_sub(t) <= FRESH)
    }

    // ---- time ----

    fn tick(&mut self, now: Now, out: &mut Vec<Output>) {
        let dt = self
            .last_tick
            .map_or(Duration::ZERO, |t| now.mono.saturating_sub(t));
        self.last_tick = Some(now.mono);
        self.drive_tick(now, dt, out);
        // Failsafes act before the owner is dropped for silence, so a pending
        // request is granted only after the GCS failsafe has acted.
        self.failsafe_tick(now, out);
        self.authority_tick(now, out);
        self.persist_tick(now, out);
        // The board's dead-man is fed by the owner's life, not by ours alone:
        // a dead owner link reaches the board even if this loop runs on.
        if !self.armed
            || self.owner_alive(now, authority::LIFE_FEEDS_DEADMAN)
            || self.failsafe_needs_thrust()
        {
            out.push(Output::Healthy);
        }
        let mut due = Vec::new();
        for ep in 0..self.schedules.len() {
            due.clear();
            self.schedules[ep].due(now.mono, &mut due);
            for id in &due {
                for msg in self.build(*id, now) {
                    out.push(Output::Send {
                        to: To::Endpoint(ep),
                        msg,
                    });
                }
            }
        }
        // Stream pending parameter lists.
        let n = self.param_queue.len().min(PARAMS_PER_TICK);
        let batch: Vec<(To, usize)> = self.param_queue.drain(..n).collect();
        for (to, idx) in batch {
            if let Some(msg) = self.param_value(idx) {
                out.push(Output::Send { to, msg });
            }
        }
    }

    // ---- telemetry ----

    fn sensors(&self, now: Now) -> (MavSysStatusSensor, MavSysStatusSensor, MavSysStatusSensor) {
        use MavSysStatusSensor as S;
        let imu = S::MAV_SYS_STATUS_SENSOR_3D_GYRO
            | S::MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | S::MAV_SYS_STATUS_SENSOR_3D_MAG;
        let depth = S::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE;
        let motors = S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS;
        let battery = S::MAV_SYS_STATUS_SENSOR_BATTERY;
        let rc = S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER;
        let prearm = S::MAV_SYS_STATUS_PREARM_CHECK;
        // Storage (parameters, logs): unhealthy while the data directory is
        // unusable or parameters fail to save.
        let logging = S::MAV_SYS_STATUS_LOGGING;
        let present = imu | depth | motors | battery | rc | prearm | logging;
        let enabled = present;
        // GEOFENCE is healthy though absent, as ArduPilot reports it: MAVProxy's
        // fence module announces "fence breach" when this bit is clear.
        let mut health = S::MAV_SYS_STATUS_GEOFENCE;
        if self.fresh(&self.heading_deg, now) {
            health |= imu;
        }
        if self.fresh(&self.depth_m, now) {
            health |= depth;
        }
        if self.link == LinkState::Up {
            health |= motors;
        }
        if self.link == LinkState::Up
            && !self.failsafes.active[failsafe::GCS]
            && !self.failsafes.active[failsafe::PILOT]
        {
            health |= rc;
        }
        if self.battery_ok(now) {
            health |= battery;
        }
        if self.prearm_failure(now).is_none() {
            health |= prearm;
        }
        if self.storage_healthy() {
            health |= logging;
        }
        (present, enabled, health)
    }

    fn battery_ok(&self, now: Now) -> bool {
        let low = self.param("BATT_LOW_VOLT", 10.5);
        self.fresh(&self.status, now)
            && self
                .status
                .value
                .vout_v
                .is_some_and(|v| low <= 0.0 || v > low)
    }

    /// Why the vehicle cannot arm, if it cannot.
    pub fn prearm_failure(&self, now: Now) -> Option<String> {
        if self.link != LinkState::Up {
            return Some(format!(
                "board link down ({})",
                self.link_reason
                    .clone()
                    .unwrap_or_else(|| "no telemetry".into())
            ));
        }
        if !self.fresh(&self.depth_m, now) || !self.fresh(&self.heading_deg, now) {
            return Some("no fresh depth and attitude from the board".into());
        }
        if !self.fresh(&self.status, now) || self.status.value.vout_v.is_none() {
            return Some("no fresh battery voltage from the board".into());
        }
        if !self.battery_ok(now) {
            return Some(format!(
                "battery below BATT_LOW_VOLT {:.1} V",
                self.param("BATT_LOW_VOLT", 10.5)
            ));
        }
        if !self.params.some_button_disarms() {
            return Some("no joystick button is mapped to disarm (BTNn_FUNCTION 2 or 4)".into());
        }
        None
    }

    fn battery_remaining(&self) -> i8 {
        let Some(v) = self.status.value.vout_v else {
            return -1;
        };
        let empty = self.param("BATT_LOW_VOLT", 10.5);
        let full = 12.6_f64.max(empty + 0.1);
        // A voltage-based estimate: the board has no coulomb counter.
        (((v - empty) / (full - empty)) * 100.0).clamp(0.0, 100.0) as i8
    }

    fn heartbeat(&self) -> MavMessage {
        use MavModeFlag as F;
        let mut base = F::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | F::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
            | F::MAV_MODE_FLAG_STABILIZE_ENABLED;
        if self.armed {
            base |= F::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        if self.holds.run_mode == RunMode::Simulator {
            // Telemetry is simulated: MAVLink's flag for hardware in the loop.
            base |= F::MAV_MODE_FLAG_HIL_ENABLED;
        }
        let system_status = if self.link != LinkState::Up || self.failsafe_active() {
            MavState::MAV_STATE_CRITICAL
        } else if self.armed {
            MavState::MAV_STATE_ACTIVE
        } else {
            MavState::MAV_STATE_STANDBY
        };
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: self.mode.number(),
            mavtype: MavType::MAV_TYPE_SUBMARINE,
            autopilot: match self.identity {
                Identity::Ardupilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                Identity::Generic => MavAutopilot::MAV_AUTOPILOT_GENERIC,
            },
            base_mode: base,
            system_status,
            mavlink_version: 3,
        })
    }

    /// The message(s) for `id` now; empty when there is nothing honest to send.
    pub fn build(&self, id: u32, now: Now) -> Vec<MavMessage> {
        let boot_ms = self.boot_ms(now);
        // Estimates where the filters have started, raw readings before.
        let e = self.holds.est.estimate(now.mono);
        let (heading, yaw_rate_rps) = if self.holds.est.heading_filter().initialised() {
            (e.heading_deg, e.yaw_rate_dps.to_radians())
        } else {
            (self.heading_deg.value, self.yaw_rate_rps)
        };
        let (depth, heave_mps) = if self.holds.est.depth_filter().initialised() {
            (e.depth_m, e.heave_mps)
        } else {
            (self.depth_m.value, 0.0)
        };
        match id {
            HEARTBEAT_DATA::ID => vec![self.heartbeat()],
            SYS_STATUS_DATA::ID => {
                let (present, enabled, health) = self.sensors(now);
                let s = &self.status.value;
                vec![MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                    onboard_control_sensors_present: present,
                    onboard_control_sensors_enabled: enabled,
                    onboard_control_sensors_health: health,
                    load: 0,
                    voltage_battery: s.vout_v.map_or(u16::MAX, |v| {
                        (v * 1000.0).round().clamp(0.0, 65534.0) as u16
                    }),
                    current_battery: s
                        .btti_a
                        .map_or(-1, |a| (a * 100.0).round().clamp(0.0, 32767.0) as i16),
                    battery_remaining: self.battery_remaining(),
                    ..Default::default()
                })]
            }
            SYSTEM_TIME_DATA::ID => vec![MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
                time_unix_usec: now.unix_us,
                time_boot_ms: boot_ms,
            })],
            ATTITUDE_DATA::ID if self.fresh(&self.heading_deg, now) => {
                let yaw = (heading + 180.0).rem_euclid(360.0) - 180.0;
                vec![MavMessage::ATTITUDE(ATTITUDE_DATA {
                    time_boot_ms: boot_ms,
                    roll: self.roll_deg.value.to_radians() as f32,
                    pitch: self.pitch_deg.value.to_radians() as f32,
                    yaw: yaw.to_radians() as f32,
                    rollspeed: 0.0,
                    pitchspeed: 0.0,
                    yawspeed: yaw_rate_rps as f32,
                })]
            }
            GLOBAL_POSITION_INT_DATA::ID if self.fresh(&self.depth_m, now) => {
                vec![MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                    time_boot_ms: boot_ms,
                    lat: 0,
                    lon: 0,
                    alt: (-depth * 1000.0).round() as i32,
                    relative_alt: (-depth * 1000.0).round() as i32,
                    vx: 0,
                    vy: 0,
                    vz: (heave_mps * 100.0).round().clamp(-32767.0, 32767.0) as i16,
                    hdg: if self.fresh(&self.heading_deg, now) {
                        (heading * 100.0).round().rem_euclid(36000.0) as u16
                    } else {
                        u16::MAX
                    },
                })]
            }
            SERVO_OUTPUT_RAW_DATA::ID => {
                let [port, vert, star] = self.motors_us;
                let laser_pwm = if self.laser > 0 { 1900 } else { 1100 };
                let lights_pwm = (1100 + (u32::from(self.lights) * 800) / 255) as u16;
                vec![MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
                    time_usec: (now.mono.saturating_sub(self.booted).as_micros() & 0xffff_ffff)
                        as u32,
                    // MOT_1 starboard, MOT_2 port, MOT_3 vertical (ArduSub SimpleROV-3 numbering).
                    servo1_raw: star,
                    servo2_raw: port,
                    servo3_raw: vert,
                    servo6_raw: laser_pwm,
                    servo7_raw: lights_pwm,
                    servo8_raw: self.tilt_us,
                    ..Default::default()
                })]
            }
            VFR_HUD_DATA::ID
                if self.fresh(&self.heading_deg, now) || self.fresh(&self.depth_m, now) =>
            {
                let throttle =
                    ((i32::from(self.motors_us[1]) - 1500).unsigned_abs() / 5).min(100) as u16;
                vec![MavMessage::VFR_HUD(VFR_HUD_DATA {
                    airspeed: 0.0,
                    groundspeed: 0.0,
                    alt: -depth as f32,
                    climb: -heave_mps as f32,
                    heading: heading.round().rem_euclid(360.0) as i16,
                    throttle,
                })]
            }
            SCALED_PRESSURE2_DATA::ID
                if self.fresh(&self.status, now) && self.status.value.pres_mbar.is_some() =>
            {
                let s = &self.status.value;
                vec![MavMessage::SCALED_PRESSURE2(SCALED_PRESSURE2_DATA {
                    time_boot_ms: boot_ms,
                    press_abs: s.pres_mbar.unwrap_or(0.0) as f32,
                    press_diff: 0.0,
                    temperature: s.temp_c.map_or(0, |t| (t * 100.0).round() as i16),
                    temperature_press_diff: 0,
                })]
            }
            BATTERY_STATUS_DATA::ID => {
                let s = &self.status.value;
                let mut voltages = [u16::MAX; 10];
                voltages[0] = s.vout_v.map_or(u16::MAX, |v| {
                    (v * 1000.0).round().clamp(0.0, 65534.0) as u16
                });
                vec![MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
                    current_consumed: self.consumed_mah.round() as i32,
                    energy_consumed: -1,
                    temperature: i16::MAX,
                    voltages,
                    current_battery: s
                        .btti_a
                        .map_or(-1, |a| (a * 100.0).round().clamp(0.0, 32767.0) as i16),
                    id: 0,
                    battery_function: MavBatteryFunction::MAV_BATTERY_FUNCTION_ALL,
                    mavtype: MavBatteryType::MAV_BATTERY_TYPE_UNKNOWN,
                    battery_remaining: self.battery_remaining(),
                    ..Default::default()
                })]
            }
            NAMED_VALUE_FLOAT_DATA::ID => {
                let tilt_min = self.param("NEPT_TILT_MIN_US", 1000.0);
                let tilt_max = self.param("NEPT_TILT_MAX_US", 2000.0);
                let tilt = if tilt_max > tilt_min {
                    (f64::from(self.tilt_us) - tilt_min) / (tilt_max - tilt_min)
                } else {
                    0.5
                };
                [
                    ("Lights1", f64::from(self.lights) / 255.0),
                    ("PilotGain", self.gain),
                    ("CamTilt", tilt),
                    ("Laser", f64::from(self.laser) / 255.0),
                    (
                        "InputHold",
                        if self.pilot.hold.is_some() { 1.0 } else { 0.0 },
                    ),
                ]
                .iter()
                .map(|(name, v)| {
                    MavMessage::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
                        time_boot_ms: boot_ms,
                        value: *v as f32,
                        name: chars(name),
                    })
                })
                .collect()
            }
            AUTOPILOT_VERSION_DATA::ID => vec![self.autopilot_version()],
            CONTROL_STATUS_DATA::ID => vec![self.control_status()],
            NEPTUNUS_SIM_STATE_DATA::ID
                if self
                    .sim_truth
                    .at
                    .is_some_and(|t| now.mono.saturating_sub(t) <= FRESH) =>
            {
                let t = self.sim_truth.value;
                vec![MavMessage::NEPTUNUS_SIM_STATE(NEPTUNUS_SIM_STATE_DATA {
                    time_boot_ms: boot_ms,
                    x: t.north_m as f32,
                    y: t.east_m as f32,
                    z: t.depth_m as f32,
                    psi: t.heading_rad as f32,
                    u: t.surge_mps as f32,
                    v: t.sway_mps as f32,
                    w: t.heave_mps as f32,
                    r: t.yaw_rate_rps as f32,
                    phi: t.roll_rad as f32,
                    theta: t.pitch_rad as f32,
                })]
            }
            _ => self.build_holds(id, now).into_iter().collect(),
        }
    }

    fn autopilot_version(&self) -> MavMessage {
        use MavProtocolCapability as C;
        let mut caps = C::MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | C::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | C::MAV_PROTOCOL_CAPABILITY_MISSION_INT;
        // Values travel as their numeric value (C cast) under both
        // identities; the generic one also sends every type as REAL32.
        #[allow(deprecated)]
        let param_float = C::MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT;
        caps |= param_float
            | C::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
            | C::MAV_PROTOCOL_CAPABILITY_COMPONENT_ACCEPTS_GCS_CONTROL;
        let mut custom = [0u8; 8];
        let v = env!("CARGO_PKG_VERSION").as_bytes();
        let tag = b"nept";
        custom[..4].copy_from_slice(tag);
        for (i, b) in v.iter().filter(|b| b.is_ascii_digit()).take(4).enumerate() {
            custom[4 + i] = *b;
        }
        MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
            capabilities: caps,
            uid: 0x4e45_5054_0000_0000 | u64::from(self.sysid()),
            // Claim ArduSub 4.5.0, BETA type: QGC then uses its Sub 4.5 metadata and does not nag.
            flight_sw_version: (4 << 24) | (5 << 16) | 128,
            middleware_sw_version: 0,
            os_sw_version: 0,
            board_version: 0,
            vendor_id: 0,
            product_id: 0,
            flight_custom_version: custom,
            ..Default::default()
        })
    }

    fn param_value(&self, index: usize) -> Option<MavMessage> {
        let (def, value) = self.params.get_index(index)?;
        let param_type = match self.identity {
            Identity::Ardupilot => def.ty.mav_type(),
            Identity::Generic => MavParamType::MAV_PARAM_TYPE_REAL32,
        };
        Some(MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: value as f32,
            param_count: self.params.len() as u16,
            param_index: index as u16,
            param_id: chars(def.name),
            param_type,
        }))
    }

    // ---- MAVLink in ----

    fn for_us(&self, target_system: u8, target_component: u8) -> bool {
        (target_system == 0 || target_system == self.sysid())
            && (target_component == 0 || target_component == COMPONENT_ID)
    }

    fn on_mavlink(&mut self, from: Sender, msg: MavMessage, now: Now, out: &mut Vec<Output>) {
        match msg {
            MavMessage::COMMAND_LONG(c) => {
                if !self.for_us(c.target_system, c.target_component) {
                    return;
                }
                let params = [
                    c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7,
                ];
                self.command(from, c.command, params, now, out);
            }
            MavMessage::COMMAND_INT(c) => {
                if !self.for_us(c.target_system, c.target_component) {
                    return;
                }
                let params = [
                    c.param1, c.param2, c.param3, c.param4, c.x as f32, c.y as f32, c.z,
                ];
                self.command(from, c.command, params, now, out);
            }
            MavMessage::MANUAL_CONTROL(m) => self.on_manual_control(from, &m, now, out),
            MavMessage::RC_CHANNELS_OVERRIDE(r) => self.on_rc_override(from, &r, now, out),
            MavMessage::NEPTUNUS_THRUSTERS(t) => self.on_thrusters_message(from, &t, now, out),
            MavMessage::SET_POSITION_TARGET_GLOBAL_INT(t) => {
                self.on_position_target(from, &t, now, out)
            }
            MavMessage::SET_ATTITUDE_TARGET(t) => self.on_attitude_target(from, &t, now, out),
            MavMessage::HEARTBEAT(h) if h.mavtype == MavType::MAV_TYPE_GCS => {
                // Only a ground station's own heartbeats keep it in control.
                self.note_life(from, now);
            }
            MavMessage::COMMAND_ACK(a)
                if a.target_system == self.sysid()
                    && (a.target_component == 0 || a.target_component == COMPONENT_ID) =>
            {
                self.on_gcs_ack(from, &a, out);
            }
            MavMessage::SETUP_SIGNING(k) if self.for_us(k.target_system, k.target_component) => {
                self.setup_signing(from, &k, now, out);
            }
            MavMessage::SET_MODE(m) => {
                if m.target_system != self.sysid() && m.target_system != 0 {
                    return;
                }
                let result = match self.check_control(from, authority::Control::Command, now, out) {
                    Ok(()) => self.set_mode(m.custom_mode, Some(from.sysid), now, out),
                    Err(why) => self.refuse_command(from, "mode change", why, now, out),
                };
                out.push(Output::Send {
                    to: from.reply(),
                    msg: ack_set_mode(result, from),
                });
            }
            MavMessage::PARAM_REQUEST_LIST(p) => {
                if !self.for_us(p.target_system, p.target_component) {
                    return;
                }
                // A repeated request restarts the list for that peer.
                let to = from.reply();
                self.param_queue.retain(|(t, _)| *t != to);
                self.param_queue
                    .extend((0..self.params.len()).map(|i| (to, i)));
            }
            MavMessage::PARAM_REQUEST_READ(p) => {
                if !self.for_us(p.target_system, p.target_component) {
                    return;
                }
                let index = if p.param_index >= 0 {
                    Some(p.param_index as usize)
                } else {
                    super::params::index_of(&char_str(&p.param_id))
                };
                if let Some(msg) = index.and_then(|i| self.param_value(i)) {
                    out.push(Output::Send {
                        to: from.reply(),
                        msg,
                    });
                }
            }
            MavMessage::PARAM_SET(p) => {
                if !self.for_us(p.target_system, p.target_component) {
                    return;
                }
                self.param_set(from, &p, now, out);
            }
            MavMessage::REQUEST_DATA_STREAM(r) => {
                if !self.for_us(r.target_system, r.target_component) {
                    return;
                }
                if !self.may_control(from) {
                    // No ack exists for this message: ignored, counted, and
                    // the asker told (rate-limited) why its rates stay.
                    self.refuse_rates(from, now, out);
                    return;
                }
                let id = r.req_stream_id as u8;
                let groups: Vec<u8> = if id == 0 {
                    telemetry::ALL_GROUPS.to_vec()
                } else {
                    vec![id]
                };
                let interval = (r.start_stop != 0 && r.req_message_rate > 0)
                    .then(|| Duration::from_secs_f64(1.0 / f64::from(r.req_message_rate)));
                for g in groups {
                    for msg_id in telemetry::stream_group(g) {
                        self.schedule_mut(from.endpoint)
                            .set(*msg_id, interval, now.mono);
                    }
                }
            }
            MavMessage::MISSION_REQUEST_LIST(m) => {
                if !self.for_us(m.target_system, m.target_component) {
                    return;
                }
                out.push(Output::Send {
                    to: from.reply(),
                    msg: MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
                        count: 0,
                        target_system: from.sysid,
                        target_component: from.compid,
                        mission_type: m.mission_type,
                        opaque_id: 0,
                    }),
                });
            }
            MavMessage::MISSION_COUNT(m) => {
                if !self.for_us(m.target_system, m.target_component) {
                    return;
                }
                out.push(self.mission_ack(
                    from,
                    m.mission_type,
                    MavMissionResult::MAV_MISSION_UNSUPPORTED,
                ));
            }
            MavMessage::MISSION_CLEAR_ALL(m) => {
                if !self.for_us(m.target_system, m.target_component) {
                    return;
                }
                out.push(self.mission_ack(
                    from,
                    m.mission_type,
                    MavMissionResult::MAV_MISSION_ACCEPTED,
                ));
            }
            MavMessage::FILE_TRANSFER_PROTOCOL(f) => {
                if !self.for_us(f.target_system, f.target_component) {
                    return;
                }
                out.push(Output::Send {
                    to: from.reply(),
                    msg: ftp_reply(&f.payload, from),
                });
            }
            MavMessage::TIMESYNC(t) if t.tc1 == 0 => {
                out.push(Output::Send {
                    to: from.reply(),
                    msg: MavMessage::TIMESYNC(TIMESYNC_DATA {
                        tc1: now.mono.as_nanos().min(i64::MAX as u128) as i64,
                        ts1: t.ts1,
                        target_system: from.sysid,
                        target_component: from.compid,
                    }),
                });
            }
            MavMessage::PING(p) if p.target_system == 0 && p.target_component == 0 => {
                out.push(Output::Send {
                    to: from.reply(),
                    msg: MavMessage::PING(PING_DATA {
                        time_usec: p.time_usec,
                        seq: p.seq,
                        target_system: from.sysid,
                        target_component: from.compid,
                    }),
                });
            }
            _ => {}
        }
    }

    fn mission_ack(
        &self,
        from: Sender,
        mission_type: MavMissionType,
        result: MavMissionResult,
    ) -> Output {
        Output::Send {
            to: from.reply(),
            msg: MavMessage::MISSION_ACK(MISSION_ACK_DATA {
                target_system: from.sysid,
                target_component: from.compid,
                mavtype: result,
                mission_type,
                opaque_id: 0,
            }),
        }
    }

    fn on_param_changed(&mut self, name: &str) {
        if name == "JS_GAIN_DEFAULT" {
            self.gain = self.param("JS_GAIN_DEFAULT", 0.5);
        }
    }

    fn set_mode(
        &mut self,
        mode: u32,
        by: Option<u8>,
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        let Some(m) = Mode::from_number(mode) else {
            self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Mode {mode} does not exist"),
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        };
        if let Some(why) = m.refused() {
            self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Mode {m} refused: {why}"),
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        if self.mode != m {
            if let Some(why) = self.hold_unavailable(m, now) {
                self.statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("Mode {m} refused: {why}"),
                    out,
                );
                return MavResult::MAV_RESULT_FAILED;
            }
            let old = self.mode;
            self.mode = m;
            // A mode change is a safety-mode stop.
            self.stop_pilot();
            self.holds_reset();
            self.send_neutral(out);
            self.statustext(MavSeverity::MAV_SEVERITY_INFO, &format!("Mode {m}"), out);
            self.log("mode", by, format!("{old} -> {m}"), out);
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    fn command(&mut self, from: Sender, cmd: MavCmd, p: [f32; 7], now: Now, out: &mut Vec<Output>) {
        use MavCmd as C;
        use MavResult as R;
        use authority::Control;
        let reply = from.reply();
        let ack = |result: MavResult| Output::Send {
            to: reply,
            msg: ack(cmd, result, from),
        };
        match cmd {
            C::MAV_CMD_COMPONENT_ARM_DISARM => {
                let arm = given(p[0]).unwrap_or(0.0) >= 0.5;
                let force = given(p[1])
                    .is_some_and(|v| (v - 2989.0).abs() < 0.5 || (v - 21196.0).abs() < 0.5);
                // Disarming is open to every station (stopping is never the
                // wrong answer), but with signing on only to signed ones.
                let result = if arm {
                    match self.check_control(from, Control::Arm, now, out) {
                        Ok(()) => self.arm(force, Some(from.sysid), now, out),
                        Err(why) => self.refuse_command(from, "arm", why, now, out),
                    }
                } else if self.signing_active && !from.signed {
                    self.refuse_command(from, "disarm", authority::Refusal::Unsigned, now, out)
                } else {
                    self.disarm("commanded", Some(from.sysid), out)
                };
                out.push(ack(result));
            }
            C::MAV_CMD_REQUEST_OPERATOR_CONTROL => {
                let result = self.operator_control(from, p, now, out);
                out.push(ack(result));
            }
            C::MAV_CMD_NEPTUNUS_SET_RUN_MODE => {
                let result = self.run_mode_command(from, p, now, out);
                out.push(ack(result));
            }
            C::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET => {
                let result = self.autopilot_target_command(from, p, now, out);
                out.push(ack(result));
            }
            C::MAV_CMD_DO_SET_MODE => {
                let mode = given(p[1]).map_or(u32::MAX, |m| m.max(0.0) as u32);
                let result = match self.check_control(from, Control::Command, now, out) {
                    Ok(()) => self.set_mode(mode, Some(from.sysid), now, out),
                    Err(why) => self.refuse_command(from, "mode change", why, now, out),
                };
                out.push(ack(result));
            }
            C::MAV_CMD_SET_MESSAGE_INTERVAL => {
                let id = given(p[0]).map_or(u32::MAX, |v| v as u32);
                let interval_us = given(p[1]).unwrap_or(0.0);
                let result = if !telemetry::is_streamable(id) {
                    R::MAV_RESULT_UNSUPPORTED
                } else if !self.may_control(from) {
                    // The schedule is shared by every station on the endpoint.
                    self.refuse_rates(from, now, out);
                    R::MAV_RESULT_DENIED
                } else if interval_us < 0.0 && !telemetry::may_disable(id) {
                    self.reply_text(
                        from,
                        ReplyKind::Rates,
                        MavSeverity::MAV_SEVERITY_WARNING,
                        &format!("Message {id} cannot be turned off: ground stations detect link loss by it"),
                        now,
                        out,
                    );
                    R::MAV_RESULT_DENIED
                } else {
                    let iv = if interval_us < 0.0 {
                        None
                    } else if interval_us == 0.0 {
                        telemetry::default_interval(id)
                    } else {
                        Some(Duration::from_micros(interval_us as u64))
                    };
                    self.schedule_mut(from.endpoint).set(id, iv, now.mono);
                    R::MAV_RESULT_ACCEPTED
                };
                out.push(ack(result));
            }
            C::MAV_CMD_GET_MESSAGE_INTERVAL => {
                let id = given(p[0]).map_or(u32::MAX, |v| v as u32);
                if telemetry::is_streamable(id) {
                    let iv = self.schedule_mut(from.endpoint).interval(id);
                    out.push(ack(R::MAV_RESULT_ACCEPTED));
                    out.push(Output::Send {
                        to: reply,
                        msg: MavMessage::MESSAGE_INTERVAL(MESSAGE_INTERVAL_DATA {
                            interval_us: iv
                                .map_or(-1, |d| d.as_micros().min(i32::MAX as u128) as i32),
                            message_id: id as u16,
                        }),
                    });
                } else {
                    out.push(ack(R::MAV_RESULT_UNSUPPORTED));
                }
            }
            C::MAV_CMD_REQUEST_MESSAGE => {
                let id = given(p[0]).map_or(u32::MAX, |v| v as u32);
                let msgs = match id {
                    AVAILABLE_MODES_DATA::ID => {
                        self.available_modes(given(p[1]).unwrap_or(0.0) as u32)
                    }
                    PARAM_VALUE_DATA::ID => {
                        // PARAM_VALUE by index (param2).
                        self.param_value(given(p[1]).unwrap_or(-1.0).max(0.0) as usize)
                            .into_iter()
                            .collect()
                    }
                    PROTOCOL_VERSION_DATA::ID => vec![protocol_version()],
                    _ => self.build(id, now),
                };
                if msgs.is_empty() {
                    out.push(ack(R::MAV_RESULT_UNSUPPORTED));
                } else {
                    out.push(ack(R::MAV_RESULT_ACCEPTED));
                    out.extend(msgs.into_iter().map(|msg| Output::Send { to: reply, msg }));
                }
            }
            C::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
                out.push(ack(R::MAV_RESULT_ACCEPTED));
                out.push(Output::Send {
                    to: reply,
                    msg: self.autopilot_version(),
                });
            }
            C::MAV_CMD_REQUEST_PROTOCOL_VERSION => {
                out.push(ack(R::MAV_RESULT_ACCEPTED));
                out.push(Output::Send {
                    to: reply,
                    msg: protocol_version(),
                });
            }
            C::MAV_CMD_DO_MOTOR_TEST => {
                let result = match self.check_control(from, Control::Drive, now, out) {
                    Ok(()) => self.motor_test(p, now, out),
                    Err(why) => self.refuse_command(from, "motor test", why, now, out),
                };
                out.push(ack(result));
            }
            C::MAV_CMD_DO_SET_SERVO
            | C::MAV_CMD_DO_MOUNT_CONTROL
            | C::MAV_CMD_ILLUMINATOR_ON_OFF
            | C::MAV_CMD_DO_ILLUMINATOR_CONFIGURE
                if let Err(why) = self.check_control(from, Control::Command, now, out) =>
            {
                let result = self.refuse_command(from, "command", why, now, out);
                out.push(ack(result));
            }
            C::MAV_CMD_DO_SET_SERVO => {
                let result = self.set_servo(
                    given(p[0]).unwrap_or(0.0) as u32,
                    given(p[1]).unwrap_or(0.0),
                    out,
                );
                out.push(ack(result));
            }
            C::MAV_CMD_DO_MOUNT_CONTROL => {
                let result = match given(p[0]) {
                    Some(tilt_cdeg) => {
                        let deg = f64::from(tilt_cdeg) / 100.0;
                        self.set_tilt_us((1500.0 + deg / 90.0 * 500.0).round(), out);
                        R::MAV_RESULT_ACCEPTED
                    }
                    None => R::MAV_RESULT_DENIED,
                };
                out.push(ack(result));
            }
            C::MAV_CMD_ILLUMINATOR_ON_OFF => {
                let on = given(p[0]).unwrap_or(0.0) >= 0.5;
                let level = if on { self.last_lights_on.max(1) } else { 0 };
                self.set_lights(level, out);
                out.push(ack(R::MAV_RESULT_ACCEPTED));
            }
            C::MAV_CMD_DO_ILLUMINATOR_CONFIGURE => {
                let result = match given(p[1]) {
                    Some(pct) if (0.0..=100.0).contains(&pct) => {
                        let level = (f64::from(pct) / 100.0 * self.param("NEPT_LIGHTS_MAX", 255.0))
                            .round()
                            .clamp(0.0, 255.0) as u8;
                        self.set_lights(level, out);
                        R::MAV_RESULT_ACCEPTED
                    }
                    _ => R::MAV_RESULT_DENIED,
                };
                out.push(ack(result));
            }
            _ => out.push(ack(R::MAV_RESULT_UNSUPPORTED)),
        }
    }

    fn arm(&mut self, force: bool, by: Option<u8>, now: Now, out: &mut Vec<Output>) -> MavResult {
        if self.armed {
            return MavResult::MAV_RESULT_ACCEPTED;
        }
        if self.link != LinkState::Up {
            let why = self
                .prearm_failure(now)
                .unwrap_or_else(|| "board link down".into());
            self.statustext(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("Arm: {why}"),
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        if !force && let Some(why) = self.prearm_failure(now) {
            self.statustext(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("PreArm: {why}"),
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        self.armed = true;
        self.armed_at = Some(now.mono);
        // Arming starts from neutral: sticks sent while disarmed do not move
        // the vehicle the instant it arms.
        self.stop_pilot();
        self.holds_reset();
        self.send_neutral(out);
        self.statustext(MavSeverity::MAV_SEVERITY_INFO, "Armed", out);
        self.log(
            "armed",
            by,
            if force {
                "forced"
            } else {
                "pre-arm checks passed"
            }
            .into(),
            out,
        );
        MavResult::MAV_RESULT_ACCEPTED
    }

    fn disarm(&mut self, why: &str, by: Option<u8>, out: &mut Vec<Output>) -> MavResult {
        self.pilot.hold = None;
        self.stop_pilot();
        if self.armed {
            self.armed = false;
            self.statustext(
                MavSeverity::MAV_SEVERITY_INFO,
                &format!("Disarmed ({why})"),
                out,
            );
            self.log("disarmed", by, why.to_owned(), out);
        }
        self.send_neutral(out);
        MavResult::MAV_RESULT_ACCEPTED
    }

    fn set_lights(&mut self, level: u8, out: &mut Vec<Output>) {
        self.lights = level;
        if level > 0 {
            self.last_lights_on = level;
        }
        out.push(Output::Board(Command::Lights(level)));
    }

    fn set_tilt_us(&mut self, us: f64, out: &mut Vec<Output>) {
        let lo = self.param("NEPT_TILT_MIN_US", 1000.0);
        let hi = self.param("NEPT_TILT_MAX_US", 2000.0);
        let us = us.clamp(lo.min(hi), hi.max(lo)).round() as u16;
        self.tilt_us = us;
        out.push(Output::Board(Command::Tilt(us)));
    }

    /// DO_SET_SERVO: the output's SERVOn_FUNCTION says what it drives.
    fn set_servo(&mut self, servo: u32, pwm: f32, out: &mut Vec<Output>) -> MavResult {
        let function = self
            .params
            .get(&format!("SERVO{servo}_FUNCTION"))
            .map(|f| f as i64);
        let pwm = f64::from(pwm);
        if !(800.0..=2200.0).contains(&pwm) {
            self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Servo {servo}: {pwm} µs out of range"),
                out,
            );
            return MavResult::MAV_RESULT_DENIED;
        }
        let frac = ((pwm - 1100.0) / 800.0).clamp(0.0, 1.0);
        match function {
            Some(59) => {
                let level = (frac * self.param("NEPT_LIGHTS_MAX", 255.0))
                    .round()
                    .clamp(0.0, 255.0) as u8;
                self.set_lights(level, out);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(60) => {
                self.laser = if pwm > 1500.0 { 255 } else { 0 };
                out.push(Output::Board(Command::Laser(self.laser)));
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(7) => {
                self.set_tilt_us(pwm, out);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(33..=35) => {
                self.statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("Servo {servo} is a thruster: use MAV_CMD_DO_MOTOR_TEST"),
                    out,
                );
                MavResult::MAV_RESULT_DENIED
            }
            _ => MavResult::MAV_RESULT_UNSUPPORTED,
        }
    }

    fn available_modes(&self, index: u32) -> Vec<MavMessage> {
        let n = Mode::ALL.len() as u8;
        Mode::ALL
            .iter()
            .enumerate()
            .filter(|(i, _)| index == 0 || *i as u32 + 1 == index)
            .map(|(i, m)| {
                MavMessage::AVAILABLE_MODES(AVAILABLE_MODES_DATA {
                    custom_mode: m.number(),
                    properties: if m.refused().is_some() {
                        MavModeProperty::MAV_MODE_PROPERTY_NOT_USER_SELECTABLE
                    } else {
                        MavModeProperty::empty()
                    },
                    number_modes: n,
                    mode_index: i as u8 + 1,
                    standard_mode: MavStandardMode::MAV_STANDARD_MODE_NON_STANDARD,
                    mode_name: chars(m.name()),
                })
            })
            .collect()
    }
}

fn protocol_version() -> MavMessage {
    MavMessage::PROTOCOL_VERSION(PROTOCOL_VERSION_DATA {
        version: 200,
        min_version: 100,
        max_version: 200,
        spec_version_hash: [0; 8],
        library_version_hash: [0; 8],
    })
}

fn ack(command: MavCmd, result: MavResult, from: Sender) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        progress: 0,
        result_param2: 0,
        target_system: from.sysid,
        target_component: from.compid,
    })
}

/// COMMAND_ACK for the SET_MODE message: ArduPilot puts the message id (11)
/// in `command`, and clients wait for exactly that.
fn ack_set_mode(result: MavResult, from: Sender) -> MavMessage {
    ack(MavCmd::MAV_CMD_NEPTUNUS_SET_MODE_MESSAGE, result, from)
}

/// MAVLink FTP: we hold no files. Opening anything answers NAK FileNotFound,
/// so QGroundControl and MAVProxy fall back to the parameter protocol at once.
fn ftp_reply(req: &[u8; 251], from: Sender) -> MavMessage {
    const ACK: u8 = 128;
    const NAK: u8 = 129;
    const FILE_NOT_FOUND: u8 = 10;
    let seq = u16::from_le_bytes([req[0], req[1]]).wrapping_add(1);
    let session = req[2];
    let opcode = req[3];
    let mut payload = [0u8; 251];
    payload[0..2].copy_from_slice(&seq.to_le_bytes());
    payload[2] = session;
    payload[5] = opcode;
    match opcode {
        // TerminateSession, ResetSessions: nothing to do, fine.
        1 | 2 => {
            payload[3] = ACK;
            payload[4] = 0;
        }
        _ => {
            payload[3] = NAK;
            payload[4] = 1;
            payload[12] = FILE_NOT_FOUND;
        }
    }
    MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
        target_network: 0,
        target_system: from.sysid,
        target_component: from.compid,
        payload,
    })
}

impl Vehicle {
    /// SETUP_SIGNING: only over a trusted endpoint, and once signing is on
    /// only signed with the current key. The key itself is never logged.
    fn setup_signing(
        &mut self,
        from: Sender,
        k: &SETUP_SIGNING_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let refusal = if !from.trusted {
            Some(format!("endpoint {} is not trusted", from.endpoint))
        } else if self.signing_active && !from.signed {
            Some("unsigned, and a key is already set".to_owned())
        } else {
            None
        };
        if let Some(why) = refusal {
            let text = format!("SETUP_SIGNING from sysid {} ignored: {why}", from.sysid);
            if self.reply_text(
                from,
                ReplyKind::Signing,
                MavSeverity::MAV_SEVERITY_WARNING,
                &text,
                now,
                out,
            ) {
                self.log("signing_refused", Some(from.sysid), text, out);
            }
            return;
        }
        let off = k.secret_key.iter().all(|b| *b == 0);
        self.signing_active = !off;
        out.push(Output::SetSigningKey {
            key: k.secret_key,
            initial_timestamp: k.initial_timestamp,
        });
        let (kind, text) = if off {
            ("signing_key_cleared", "Signing off: key cleared")
        } else {
            ("signing_key_set", "Signing on: key set")
        };
        self.statustext(MavSeverity::MAV_SEVERITY_INFO, text, out);
        self.log(
            kind,
            Some(from.sysid),
            format!("over endpoint {}", from.endpoint),
            out,
        );
    }

    /// The output voltage of the last full power reading (V), for the app's log line.
    pub fn battery_v(&self) -> Option<f64> {
        self.status.value.vout_v
    }
}
