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
//!
//! One file per concern, as ArduSub keeps them; `docs/ARCHITECTURE.md` is
//! the map (data paths, rules, where to add a message, a mode or a
//! parameter):
//!
//! | file | concern |
//! |---|---|
//! | `mod.rs` | [`Vehicle`] and its grouped state, [`Input`]/[`Output`], [`Vehicle::handle`], the tick |
//! | `inbound.rs` | MAVLink dispatch, the one addressing check, the one control-input check, HMI events |
//! | `command.rs` | COMMAND_LONG/INT → handler, COMMAND_ACK |
//! | `param_proto.rs` | PARAM_REQUEST_LIST/READ, PARAM_SET |
//! | `telemetry.rs` | what each outgoing message says, the streams |
//! | `arming.rs` | arm, disarm, pre-arm checks |
//! | `board.rs` | board link and readings |
//! | `payload.rs` | lights, laser, camera tilt, servo outputs |
//! | `gimbal.rs` | the camera tilt as a MAVLink gimbal (protocol v2, manager on component 1) |
//! | `camera.rs` | the MAVLink camera component (id 100): heartbeat, camera and video-stream information |
//! | `recording.rs` | recording on the vehicle: the capture commands (after the authority check), capture status, storage information, the telemetry beside the video |
//! | `modes.rs` | flight mode changes, AVAILABLE_MODES |
//! | `run_mode.rs` | real board or built-in simulator |
//! | `driving.rs` | sticks, buttons, motor test → one `go()` |
//! | `holds.rs` | estimator and autopilot modes, setpoints |
//! | `authority.rs` | who controls: the authority check, owner changes, pick-up, CONTROL_STATUS |
//! | `handover.rs` | REQUEST_OPERATOR_CONTROL and the owner's answer |
//! | `failsafe.rs` | GCS, pilot-input, board-link and battery failsafes |
//! | `persist.rs` | parameter saving (asked of the app) |
//! | `signing.rs` | SETUP_SIGNING |
//! | `stubs.rs` | missions, TIMESYNC, PING answered without implementing them |
//! | `transfer/` | onboard log download (LOG_*) and MAVLink FTP's read side: sessions, paced streams, who may read what |
//! | `texts.rs` | STATUSTEXT to all or to one asker, with a topic |
//! | `wall_time.rs` | SYSTEM_TIME from the station in control sets a wrong clock |

// Ground stations still send the legacy messages and commands MAVLink has
// deprecated (SET_MODE, REQUEST_DATA_STREAM, PING, GET_MESSAGE_INTERVAL …);
// an ArduSub-compatible vehicle must answer them.
#![allow(deprecated)]

use std::time::Duration;

use mavlink_core::types::CharArray;

mod arming;
mod authority;
mod board;
mod camera;
mod command;
mod driving;
mod failsafe;
mod gimbal;
mod handover;
mod holds;
mod inbound;
mod inout;
mod instruments;
mod modes;
mod param_proto;
mod payload;
mod persist;
mod recording;
mod run_mode;
mod signing;
mod stubs;
mod telemetry;
mod texts;
mod transfer;
mod wake;
mod wall_time;

pub use camera::{CAMERA_COMPONENT_ID, CameraSpec, VIDEO_STREAM_ID, VideoStreamInfo};
pub use gimbal::GIMBAL_DEVICE_ID;
pub use inout::{HmiEvent, Input, Output, SimTruth};
pub use persist::{SAVE_DEBOUNCE, SAVE_MAX_DELAY};
pub use recording::{RecordControl, RecordSample, RecorderEvent, StorageReport};
pub use run_mode::RunMode;
pub use texts::{FailsafeKind, Topic, ascii_text};
pub use transfer::{NETWORK_RATE, START_RATE};
pub use wake::{BUSY_TICK, IDLE_TICK};
pub use wall_time::ClockSync;

use super::input::Profiles;
pub use super::mode::Mode;
use super::params::ParamStore;
use crate::dialect::neptunus::*;
pub use crate::eventlog::LogEvent;
use crate::firmware::codec::{Command, Event};
use crate::firmware::link::{LinkQuality, LinkState};
pub use crate::vehicle::mixer::NEUTRAL_US;

/// Our MAVLink component id (the autopilot).
pub const COMPONENT_ID: u8 = 1;
/// Telemetry older than this is not re-sent as if fresh.
pub const FRESH: Duration = Duration::from_millis(1500);

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
    port_us: NEUTRAL_US,
    vertical_us: NEUTRAL_US,
    starboard_us: NEUTRAL_US,
};

/// Everything the vehicle knows and decides, grouped by the file that
/// owns each part.
#[derive(Debug)]
pub struct Vehicle {
    identity: Identity,
    params: ParamStore,
    /// Ground-station conventions (sticks, buttons) per system id.
    profiles: std::sync::Arc<Profiles>,
    /// The system id in use; SYSID_THISMAV changes apply at the next start.
    sysid: u8,
    /// System ids the browser HMI lends to its sessions (ground stations).
    hmi_sysids: (u8, u8),
    clock: Clock,
    mode: Mode,
    run_mode: RunMode,
    armed: bool,
    armed_at: Option<Duration>,
    /// The thruster pulse widths last commanded [port, vertical, starboard].
    motors_us: [u16; 3],
    board: board::BoardState,
    payload: payload::Payload,
    camera: camera::Camera,
    recording: recording::Recording,
    gimbal: gimbal::Gimbal,
    pilot: driving::Pilot,
    auth: authority::Authority,
    failsafes: failsafe::Failsafes,
    holds: holds::Holds,
    streams: telemetry::Streams,
    texts: texts::Texts,
    persist: persist::Persist,
    transfers: transfer::Transfers,
    signing_active: bool,
    wall_time: wall_time::WallTime,
    counters: Counters,
}

/// When the core started and last ticked.
#[derive(Debug, Default)]
struct Clock {
    started: bool,
    booted: Duration,
    last_tick: Option<Duration>,
    /// When the core last handled anything: a gap longer than [`STALL`]
    /// means the process stood still.
    last_input: Option<Duration>,
}

/// An armed vehicle handles something at least every tick (10 ms); a gap
/// this long means the program itself stood still (stopped, swapped out, a
/// hung disk) while the board held its last command. Until the gap nears the
/// board's dead-man (2 s) that is what a late tether does too: the pilot's
/// input waits in the socket and the next decision is the newest. From here
/// on the dead-man may have stopped the thrusters by itself (the board's
/// clock is not ours: the link's own rule for a gap in its pings, 0.5 s of
/// doubt), so the board's state is unknown and control is in doubt: the
/// vehicle disarms. ArduSub's main-loop lockup limit is 2 s.
pub const STALL: Duration = Duration::from_millis(1500);

/// A gap this long while armed is told to the pilot as a warning: the
/// thrusters held the last command for that long.
pub const STALL_WARN: Duration = Duration::from_millis(500);

/// Requests refused and only counted (the app reports them).
#[derive(Debug, Default)]
struct Counters {
    /// Telemetry-rate requests refused (stations that may not control).
    refused_rate_requests: u64,
    /// PARAM_SETs whose param_type was not acceptable.
    bad_param_types: u64,
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
        let pilot = driving::Pilot {
            gain: f64::from(params.js_gain_default()),
            ..Default::default()
        };
        let sysid = params.sysid_thismav();
        Self {
            identity,
            params,
            profiles: std::sync::Arc::new(Profiles::builtin()),
            sysid,
            hmi_sysids: (200, 209),
            clock: Clock::default(),
            mode: Mode::BOOT,
            run_mode: RunMode::Normal,
            armed: false,
            armed_at: None,
            motors_us: [NEUTRAL_US; 3],
            board: board::BoardState::default(),
            payload: payload::Payload::default(),
            camera: camera::Camera::default(),
            recording: recording::Recording::default(),
            gimbal: gimbal::Gimbal::default(),
            pilot,
            auth: authority::Authority::default(),
            failsafes: failsafe::Failsafes::default(),
            holds: holds::Holds::default(),
            streams: telemetry::Streams::new(endpoints),
            texts: texts::Texts::default(),
            persist: persist::Persist::default(),
            transfers: transfer::Transfers::default(),
            signing_active: false,
            wall_time: wall_time::WallTime::default(),
            counters: Counters::default(),
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
        self.counters.refused_rate_requests
    }

    /// PARAM_SETs answered with the current value because of their param_type.
    pub fn bad_param_types(&self) -> u64 {
        self.counters.bad_param_types
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
    /// The flight mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }
    /// The system id in use (SYSID_THISMAV as it was at start).
    pub fn sysid(&self) -> u8 {
        self.sysid
    }
    pub fn motors_us(&self) -> [u16; 3] {
        self.motors_us
    }

    /// Reacts to one input at `now`, appending what must happen to `out`.
    pub fn handle(&mut self, input: Input, now: Now, out: &mut Vec<Output>) {
        if !self.clock.started {
            self.clock.started = true;
            self.clock.booted = now.mono;
            self.streams.start(now.mono);
        }
        let gap = self.clock.last_input.map(|t| now.mono.saturating_sub(t));
        self.clock.last_input = Some(now.mono);
        if let Some(gap) = gap.filter(|g| *g > STALL_WARN)
            && self.armed
        {
            if gap > STALL {
                self.statustext(
                    texts::Topic::Stop,
                    MavSeverity::MAV_SEVERITY_CRITICAL,
                    &format!(
                        "Vehicle stalled {:.1} s: thrusters stopped, arm again",
                        gap.as_secs_f64()
                    ),
                    out,
                );
                self.disarm("the vehicle's program stalled", None, out);
            } else {
                self.statustext(
                    texts::Topic::General,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!(
                        "Vehicle stood still {:.1} s: the thrusters held the last command",
                        gap.as_secs_f64()
                    ),
                    out,
                );
            }
        }
        match input {
            Input::Tick => self.tick(now, out),
            Input::Link { state, reason } => self.on_link(state, reason, now, out),
            Input::LinkQuality(q) => self.board.link_quality = q,
            Input::Board(ev) => {
                // In SIMULATOR run mode the board's navigation and power
                // telemetry is not the vehicle's (the simulator's is).
                let simulated = self.run_mode == RunMode::Simulator;
                let nav = matches!(ev, Event::Nav(_));
                if !(simulated && (nav || matches!(ev, Event::Status(_)))) {
                    self.on_board(ev, now, out);
                }
                if nav {
                    self.tick_with_line(now, out);
                }
            }
            Input::SimBoard(ev) => {
                if self.run_mode == RunMode::Simulator {
                    self.on_sim_board(ev, now, out);
                }
            }
            Input::SimTruth(t) => self.board.on_sim_truth(t, now),
            Input::ParamsSaved(result) => self.on_params_saved(result, now, out),
            Input::Mavlink { from, msg } => self.on_mavlink(from, msg, now, out),
            Input::Hmi { sysid, event } => self.on_hmi(sysid, event, now, out),
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
                    out.push(command::ack_unknown(from, command, COMPONENT_ID));
                } else if self.for_camera(target_system, target_component) {
                    out.push(command::ack_unknown(from, command, CAMERA_COMPONENT_ID));
                }
            }
            Input::VideoStream(stream) => self.set_video_stream(stream),
            Input::Listeners { endpoint, listened } => {
                self.streams.set_listened(endpoint, listened)
            }
            Input::Recorder(ev) => self.on_recorder(ev, now, out),
            Input::Files(reply) => self.on_file_reply(reply, now, out),
            Input::Transfer => self.transfer_pass(now, out),
        }
    }

    fn boot_ms(&self, now: Now) -> u32 {
        (now.mono.saturating_sub(self.clock.booted)).as_millis() as u32
    }

    fn send_neutral(&mut self, out: &mut Vec<Output>) {
        self.motors_us = [NEUTRAL_US; 3];
        self.holds.applied = driving::NO_DEMAND;
        self.send_go(NEUTRAL_GO, out);
    }

    /// A thruster command, to the board or, in SIMULATOR run mode, to the
    /// simulator (the board then stays stopped).
    fn send_go(&mut self, go: Command, out: &mut Vec<Output>) {
        match self.run_mode {
            RunMode::Normal => out.push(Output::Board(go)),
            RunMode::Simulator => out.push(Output::SimBoard(go)),
        }
    }

    /// Periodic work: driving and autopilots, failsafes, authority timeouts,
    /// saving, the dead-man feed, telemetry streams.
    fn tick(&mut self, now: Now, out: &mut Vec<Output>) {
        let dt = self
            .clock
            .last_tick
            .map_or(Duration::ZERO, |t| now.mono.saturating_sub(t));
        self.clock.last_tick = Some(now.mono);
        self.drive_tick(now, dt, out);
        self.gimbal_tick(now, dt, out);
        // Failsafes act before the owner is dropped for silence, so a pending
        // request is granted only after the GCS failsafe has acted.
        self.failsafe_tick(now, out);
        self.authority_tick(now, out);
        self.persist_tick(now, out);
        self.wall_time_tick(now, out);
        self.transfers_tick(now);
        // The board's dead-man is fed by the owner's life, not by ours alone:
        // a dead owner link reaches the board even if this loop runs on.
        if !self.armed
            || self.owner_alive(now, authority::LIFE_FEEDS_DEADMAN)
            || self.failsafe_needs_thrust()
        {
            out.push(Output::Healthy);
        }
        self.stream_tick(now, out);
        self.camera_tick(now, out);
        self.recording_tick(now, out);
        self.param_stream_tick(out);
    }
}
