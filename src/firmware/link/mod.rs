//! The serial link to the board: its public face (configuration, handle,
//! events, figures, errors) and the task that owns the serial device.
//!
//! It opens the device, performs the start-up handshake (wait for `boot`,
//! `dms(1)`, `start()`), keeps the board's dead-man switch fed with
//! `ping(0)` about once a second *only while the vehicle task says it is
//! healthy*, coalesces thruster commands (the newest wins; a stale one is
//! never written), and paces writes so that what the board has not echoed
//! yet always fits its 64-byte receive buffer. When the device vanishes or
//! goes silent it reports the link down, reopens with backoff and redoes
//! the handshake; when the board reboots it handshakes again.
//!
//! It never decides what to send: commands come from the vehicle task, which
//! owns arming and authority. The link only delivers them faithfully, and
//! turns the board's bytes into decoded events.
//!
//! Every decision above lives in `session/`, a sans-IO state machine that
//! takes the time as an argument; `io.rs` is the tokio loop that owns the
//! device and the channels and only moves bytes, requests and timers
//! between them and the session (the genuine firmware's scenarios,
//! `hil::lockstep`, drive the same session on simulated time). This file
//! holds the types both share.

use std::path::PathBuf;
use std::time::Duration;

use serde::Serialize;
use tokio::sync::{mpsc, watch};

use super::codec::{Command, DecodeStats, Event, Framing};

mod io;
pub(crate) mod session;

/// How the link talks to the board.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    pub device: PathBuf,
    pub baud: u32,
    pub framing: Framing,
    /// Period of `ping(0)` while the vehicle task is healthy.
    pub ping_period: Duration,
    /// The vehicle task counts as healthy this long after its last keep-alive.
    pub healthy_window: Duration,
    /// No telemetry for this long: the link is reported down.
    pub stale_after: Duration,
    /// How long to wait for `boot` after opening before handshaking anyway
    /// (a board that was already running prints no `boot`).
    pub boot_wait: Duration,
    /// A board heard printing since the opening, but neither its `boot` nor
    /// telemetry yet, is running its set-up (its sensors' chatter): the
    /// handshake waits for `boot` past `boot_wait`, at most this long after
    /// the opening (the firmware's own watchdog resets a set-up that hangs
    /// after 8 s).
    pub setup_allowance: Duration,
    pub backoff_min: Duration,
    pub backoff_max: Duration,
    /// Extra time after each frame's wire time before the next is written,
    /// so the board's loop takes each command before the next arrives.
    pub frame_gap: Duration,
    /// How far ahead of the board (in wire time plus gaps) writes may run:
    /// about two `go()` frames, well inside the board's buffer and queue.
    pub max_ahead: Duration,
    /// Bytes written and not yet echoed by the board, at most: its Arduino
    /// serial receive buffer (64 bytes), where frames wait while its loop
    /// is busy.
    pub max_in_flight_bytes: usize,
    /// A frame not echoed within this was lost by the board.
    pub echo_timeout: Duration,
    /// The board's dead-man timeout: after a gap in the pings this long,
    /// its motors have been stopped.
    pub dead_man_timeout: Duration,
}

impl LinkConfig {
    /// Defaults for the OpenROV board on `device`.
    pub fn new(device: impl Into<PathBuf>) -> Self {
        Self {
            device: device.into(),
            baud: 115_200,
            framing: Framing::Crc8,
            // Five pings in the board's 2-s dead-man window: three lost
            // in a row on a noisy line still leave it fed.
            ping_period: Duration::from_millis(400),
            healthy_window: Duration::from_millis(500),
            stale_after: Duration::from_millis(1500),
            boot_wait: Duration::from_millis(1500),
            setup_allowance: Duration::from_secs(8),
            backoff_min: Duration::from_millis(200),
            backoff_max: Duration::from_secs(5),
            frame_gap: Duration::from_millis(2),
            max_ahead: Duration::from_millis(8),
            max_in_flight_bytes: 64,
            echo_timeout: Duration::from_millis(500),
            dead_man_timeout: Duration::from_secs(2),
        }
    }

    /// Time one frame of `len` bytes occupies the wire (8N1: 10 bits a byte).
    pub fn wire_time(&self, len: usize) -> Duration {
        Duration::from_micros((len as u64 * 10 * 1_000_000).div_ceil(u64::from(self.baud.max(1))))
    }
}

/// Whether the board can be commanded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LinkState {
    /// No device, or no telemetry.
    #[default]
    Down,
    /// Device open, handshake under way.
    Handshaking,
    /// Handshake done and telemetry flowing.
    Up,
}

/// Figures the link keeps.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LinkStats {
    pub state: LinkState,
    /// Why the link is down, if it is.
    pub down_reason: Option<String>,
    /// Age of the newest accepted telemetry line.
    pub telemetry_age_ms: Option<u64>,
    pub decode: DecodeStats,
    /// `crc:fail` echoes from the board: frames it dropped.
    pub crc_failures_echoed: u64,
    pub commands_written: u64,
    pub thrust_written: u64,
    /// Thruster commands the board echoed (it took them).
    pub thrust_echoed: u64,
    /// Thruster commands written and neither echoed yet nor given up on
    /// (the echo timeout), when these figures were published.
    pub thrust_unechoed: u64,
    /// Thruster commands superseded by a newer one before being written.
    pub thrust_coalesced: u64,
    /// Lights, laser and tilt levels superseded by a newer one of the same
    /// kind before being written.
    pub settings_coalesced: u64,
    pub pings_written: u64,
    pub bytes_in: u64,
    pub bytes_out: u64,
    pub opens: u64,
    pub handshakes: u64,
    /// Telemetry events dropped because the vehicle task lagged.
    pub events_dropped: u64,
    /// Frames the board never echoed (lost, or it was busy or resetting).
    pub echoes_missed: u64,
    /// Times the board printed `boot` again after it had talked on this
    /// opening (a `boot` while it was still setting up is its first).
    pub board_reboots: u64,
    /// Thrust commands written again because the board did not take them
    /// or said it held something else.
    pub thrust_resent: u64,
    /// Frames and lines damaged or lost, both ways, as a share of all over
    /// the last 10 s, in hundredths of a percent (`session/quality.rs`).
    pub drop_rate_cpct: u16,
}

impl LinkStats {
    /// Frames and lines damaged or lost since the link started, both ways
    /// (SYS_STATUS `errors_comm`).
    pub fn errors(&self) -> u16 {
        session::quality::errors(self)
    }
}

/// The line's quality, as the vehicle tells the pilot (SYS_STATUS).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkQuality {
    /// Damaged or lost over the last 10 s, hundredths of a percent.
    pub drop_rate_cpct: u16,
    /// Damaged or lost since the link started (saturating).
    pub errors: u16,
}

impl Default for LinkStats {
    fn default() -> Self {
        Self {
            state: LinkState::Down,
            down_reason: Some("not opened yet".into()),
            telemetry_age_ms: None,
            decode: DecodeStats::default(),
            crc_failures_echoed: 0,
            commands_written: 0,
            thrust_written: 0,
            thrust_echoed: 0,
            thrust_unechoed: 0,
            thrust_coalesced: 0,
            settings_coalesced: 0,
            pings_written: 0,
            bytes_in: 0,
            bytes_out: 0,
            opens: 0,
            handshakes: 0,
            events_dropped: 0,
            echoes_missed: 0,
            board_reboots: 0,
            thrust_resent: 0,
            drop_rate_cpct: 0,
        }
    }
}

/// What the link reports to the vehicle task.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkEvent {
    State {
        state: LinkState,
        reason: Option<String>,
    },
    Telemetry(Event),
    /// The line's quality changed.
    Quality(LinkQuality),
}

#[derive(Debug)]
enum Request {
    Command(Command),
    Healthy,
}

/// The vehicle task's side of the link.
#[derive(Debug, Clone)]
pub struct LinkHandle {
    tx: mpsc::UnboundedSender<Request>,
    stats: watch::Receiver<LinkStats>,
}

impl LinkHandle {
    /// Queues a command. Thruster commands (`go`, `stop`, ...) are coalesced:
    /// only the newest pending one is written.
    pub fn send(&self, cmd: Command) {
        let _ = self.tx.send(Request::Command(cmd));
    }
    /// Tells the link the vehicle task is alive, which keeps `ping` going.
    pub fn healthy(&self) {
        let _ = self.tx.send(Request::Healthy);
    }
    pub fn stats(&self) -> LinkStats {
        self.stats.borrow().clone()
    }
    pub fn subscribe(&self) -> watch::Receiver<LinkStats> {
        self.stats.clone()
    }
}

/// Errors opening the device.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error(
        "serial port {path} does not exist — pass --serial PATH for the board's device, or --sim to run without hardware"
    )]
    NotFound { path: PathBuf },
    #[error(
        "serial port {path} cannot be opened: {reason} — check the device and its permissions, or pass --sim to run without hardware"
    )]
    Open { path: PathBuf, reason: String },
}

/// Opens the device once to check it can be used (for a clear start-up error).
pub fn probe(cfg: &LinkConfig) -> Result<(), LinkError> {
    io::open(cfg).map(drop)
}

/// Starts the link task. Events arrive on the returned receiver; the task
/// ends when every [`LinkHandle`] is dropped.
pub fn spawn(cfg: LinkConfig) -> (LinkHandle, mpsc::Receiver<LinkEvent>) {
    let (tx, rx) = mpsc::unbounded_channel();
    let (events_tx, events_rx) = mpsc::channel(4096);
    let (stats_tx, stats_rx) = watch::channel(LinkStats::default());
    tokio::spawn(io::run(cfg, rx, events_tx, stats_tx));
    (
        LinkHandle {
            tx,
            stats: stats_rx,
        },
        events_rx,
    )
}
