//! The serial link task: owns the board's serial device.
//!
//! It opens the device, performs the start-up handshake (wait for `boot`,
//! `rcap()` once, `dms(1)`, `start()`), keeps the board's dead-man switch
//! fed with `ping(0)` about once a second *only while the vehicle task says
//! it is healthy*, coalesces thruster commands (the newest wins; a stale one
//! is never written), and paces writes so the board's 80-byte buffer and
//! 5-slot queue cannot overflow. When the device vanishes or goes silent it
//! reports the link down, reopens with backoff and redoes the handshake.
//!
//! It never decides what to send: commands come from the vehicle task, which
//! owns arming and authority. The link only delivers them faithfully, and
//! turns the board's bytes into decoded events.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::Duration;

use serde::Serialize;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tokio_serial::SerialPortBuilderExt;

use super::codec::{Command, DecodeStats, Event, Framing, LineDecoder, encode};

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
    pub backoff_min: Duration,
    pub backoff_max: Duration,
    /// Extra time after each frame's wire time before the next is written,
    /// so the board's loop takes each command before the next arrives.
    pub frame_gap: Duration,
    /// How far ahead of the board (in wire time plus gaps) writes may run:
    /// about two `go()` frames, well inside the board's buffer and queue.
    pub max_ahead: Duration,
}

impl LinkConfig {
    /// Defaults for the OpenROV board on `device`.
    pub fn new(device: impl Into<PathBuf>) -> Self {
        Self {
            device: device.into(),
            baud: 115_200,
            framing: Framing::Crc8,
            ping_period: Duration::from_secs(1),
            healthy_window: Duration::from_millis(500),
            stale_after: Duration::from_millis(1500),
            boot_wait: Duration::from_millis(1500),
            backoff_min: Duration::from_millis(200),
            backoff_max: Duration::from_secs(5),
            frame_gap: Duration::from_millis(2),
            max_ahead: Duration::from_millis(8),
        }
    }

    /// Time one frame of `len` bytes occupies the wire (8N1: 10 bits a byte).
    pub fn wire_time(&self, len: usize) -> Duration {
        Duration::from_micros((len as u64 * 10 * 1_000_000).div_ceil(u64::from(self.baud.max(1))))
    }
}

/// Whether the board can be commanded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LinkState {
    /// No device, or no telemetry.
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
    /// Thruster commands superseded by a newer one before being written.
    pub thrust_coalesced: u64,
    pub pings_written: u64,
    pub bytes_in: u64,
    pub bytes_out: u64,
    pub opens: u64,
    pub handshakes: u64,
    /// Telemetry events dropped because the vehicle task lagged.
    pub events_dropped: u64,
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
            thrust_coalesced: 0,
            pings_written: 0,
            bytes_in: 0,
            bytes_out: 0,
            opens: 0,
            handshakes: 0,
            events_dropped: 0,
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
    open(cfg).map(drop)
}

fn open(cfg: &LinkConfig) -> Result<tokio_serial::SerialStream, LinkError> {
    if !cfg.device.exists() {
        return Err(LinkError::NotFound {
            path: cfg.device.clone(),
        });
    }
    tokio_serial::new(cfg.device.to_string_lossy(), cfg.baud)
        .data_bits(tokio_serial::DataBits::Eight)
        .parity(tokio_serial::Parity::None)
        .stop_bits(tokio_serial::StopBits::One)
        .flow_control(tokio_serial::FlowControl::None)
        .open_native_async()
        .map_err(|e| LinkError::Open {
            path: cfg.device.clone(),
            reason: e.to_string(),
        })
}

/// Starts the link task. Events arrive on the returned receiver; the task
/// ends when every [`LinkHandle`] is dropped.
pub fn spawn(cfg: LinkConfig) -> (LinkHandle, mpsc::Receiver<LinkEvent>) {
    let (tx, rx) = mpsc::unbounded_channel();
    let (events_tx, events_rx) = mpsc::channel(4096);
    let (stats_tx, stats_rx) = watch::channel(LinkStats::default());
    tokio::spawn(run(cfg, rx, events_tx, stats_tx));
    (
        LinkHandle {
            tx,
            stats: stats_rx,
        },
        events_rx,
    )
}

/// Pending writes: control commands in order, plus the newest thrust command.
#[derive(Debug, Default)]
struct Outbox {
    control: VecDeque<Command>,
    thrust: Option<Command>,
}

impl Outbox {
    fn push(&mut self, cmd: Command, stats: &mut LinkStats) {
        if cmd.is_thrust() {
            if self.thrust.replace(cmd).is_some() {
                stats.thrust_coalesced += 1;
            }
        } else {
            self.control.push_back(cmd);
        }
    }
    fn pop(&mut self) -> Option<Command> {
        self.control.pop_front().or_else(|| self.thrust.take())
    }
    fn is_empty(&self) -> bool {
        self.control.is_empty() && self.thrust.is_none()
    }
}

struct Session {
    handshake_due: Option<Instant>,
    handshaken: bool,
    rcap_sent: bool,
}

async fn run(
    cfg: LinkConfig,
    mut rx: mpsc::UnboundedReceiver<Request>,
    events: mpsc::Sender<LinkEvent>,
    stats_tx: watch::Sender<LinkStats>,
) {
    let mut stats = LinkStats::default();
    let mut outbox = Outbox::default();
    let mut last_healthy: Option<Instant> = None;
    let mut backoff = cfg.backoff_min;
    let mut reported: Option<LinkState> = None;
    let mut last_line: Option<Instant> = None;
    let report = |stats: &mut LinkStats,
                  reported: &mut Option<LinkState>,
                  state: LinkState,
                  reason: Option<String>,
                  events: &mpsc::Sender<LinkEvent>| {
        stats.state = state;
        stats.down_reason = reason.clone();
        if *reported != Some(state) {
            *reported = Some(state);
            match state {
                LinkState::Down => {
                    tracing::warn!(device = %cfg.device.display(), reason = reason.as_deref().unwrap_or(""), "board link down")
                }
                LinkState::Handshaking => {
                    tracing::info!(device = %cfg.device.display(), "board link: handshaking")
                }
                LinkState::Up => tracing::info!(device = %cfg.device.display(), "board link up"),
            }
            // Figures first: anyone looking at them after the event sees the
            // new state (the other order let a test read the old reason).
            let _ = stats_tx.send(stats.clone());
            if events.try_send(LinkEvent::State { state, reason }).is_err() {
                stats.events_dropped += 1;
                let _ = stats_tx.send(stats.clone());
            }
        }
    };
    report(
        &mut stats,
        &mut reported,
        LinkState::Down,
        Some("not opened yet".into()),
        &events,
    );

    'outer: loop {
        // Open, or wait and retry; requests keep being taken meanwhile so the
        // newest thrust command is what gets written once the board is back.
        let mut port = match open(&cfg) {
            Ok(p) => p,
            Err(e) => {
                report(
                    &mut stats,
                    &mut reported,
                    LinkState::Down,
                    Some(e.to_string()),
                    &events,
                );
                let _ = stats_tx.send(stats.clone());
                let retry_at = Instant::now() + backoff;
                backoff = (backoff * 2).min(cfg.backoff_max);
                if !wait_retry(
                    &mut rx,
                    &mut outbox,
                    &mut stats,
                    &mut last_healthy,
                    retry_at,
                )
                .await
                {
                    break 'outer;
                }
                continue 'outer;
            }
        };
        stats.opens += 1;
        let opened_at = Instant::now();
        let mut decoder = LineDecoder::new();
        let mut decoded = Vec::with_capacity(16);
        let mut session = Session {
            handshake_due: Some(opened_at + cfg.boot_wait),
            handshaken: false,
            rcap_sent: false,
        };
        report(
            &mut stats,
            &mut reported,
            LinkState::Handshaking,
            None,
            &events,
        );
        // When the board will have taken everything written so far (a virtual
        // finish time: each frame costs its wire time plus `frame_gap`). A
        // frame may go out while that is at most `max_ahead` away, so a
        // command after a ping is written at once, while a burst is held back
        // before it can fill the board's 80-byte buffer or 5-slot queue.
        let mut line_free_at = Instant::now();
        let mut next_ping = Instant::now();
        let mut next_stats = Instant::now();
        let mut buf = [0u8; 1024];
        let mut frame = Vec::with_capacity(64);
        let mut lines_at_open = 0;
        let down_reason: String = loop {
            let now = Instant::now();
            // Handshake: after `boot`, or after boot_wait for a board that was already up.
            if session.handshake_due.is_some_and(|t| now >= t) {
                session.handshake_due = None;
                session.handshaken = true;
                stats.handshakes += 1;
                let _ = stats_tx.send(stats.clone());
                if !session.rcap_sent {
                    session.rcap_sent = true;
                    outbox.control.push_front(Command::Capabilities);
                }
                outbox.control.push_back(Command::DeadMan(true));
                outbox.control.push_back(Command::Start);
                lines_at_open = stats.decode.lines_accepted;
                // A ping now, so the freshly armed dead-man has a full period.
                next_ping = now;
            }
            if session.handshaken
                && now >= next_ping
                && last_healthy.is_some_and(|t| now.duration_since(t) <= cfg.healthy_window)
            {
                next_ping = now + cfg.ping_period;
                if !outbox.control.contains(&Command::Ping(0)) {
                    outbox.control.push_back(Command::Ping(0));
                    stats.pings_written += 1;
                }
            }
            if line_free_at.saturating_duration_since(now) <= cfg.max_ahead
                && session.handshaken
                && let Some(cmd) = outbox.pop()
            {
                frame.clear();
                encode(&cmd, cfg.framing, &mut frame);
                if let Err(e) = port.write_all(&frame).await {
                    break format!("write failed: {e}");
                }
                stats.bytes_out += frame.len() as u64;
                stats.commands_written += 1;
                if cmd.is_thrust() {
                    stats.thrust_written += 1;
                }
                line_free_at = line_free_at.max(now) + cfg.wire_time(frame.len()) + cfg.frame_gap;
            }

            // Telemetry watchdog.
            let silent_since = last_line.filter(|t| *t >= opened_at).unwrap_or(opened_at);
            if now.duration_since(silent_since)
                > cfg.stale_after
                    + if session.handshaken {
                        Duration::ZERO
                    } else {
                        cfg.boot_wait
                    }
            {
                if stats.state != LinkState::Down {
                    report(
                        &mut stats,
                        &mut reported,
                        LinkState::Down,
                        Some(format!(
                            "no telemetry from the board for {:.1} s",
                            now.duration_since(silent_since).as_secs_f64()
                        )),
                        &events,
                    );
                }
            } else if session.handshaken
                && stats.decode.lines_accepted > lines_at_open
                && stats.state != LinkState::Up
            {
                report(&mut stats, &mut reported, LinkState::Up, None, &events);
                backoff = cfg.backoff_min;
            }
            if now >= next_stats {
                next_stats = now + Duration::from_millis(100);
                stats.telemetry_age_ms =
                    last_line.map(|t| now.duration_since(t).as_millis() as u64);
                let _ = stats_tx.send(stats.clone());
            }

            let mut wake = next_stats.min(now + Duration::from_millis(100));
            if let Some(t) = session.handshake_due {
                wake = wake.min(t);
            }
            if session.handshaken && !outbox.is_empty() {
                wake = wake.min(line_free_at.checked_sub(cfg.max_ahead).unwrap_or(now));
            }
            if session.handshaken {
                wake = wake.min(next_ping);
            }
            tokio::select! {
                read = port.read(&mut buf) => match read {
                    Ok(0) => break "device closed".to_owned(),
                    Ok(n) => {
                        stats.bytes_in += n as u64;
                        decoded.clear();
                        decoder.push(&buf[..n], &mut decoded);
                        stats.decode = decoder.stats().clone();
                        let t = Instant::now();
                        for ev in decoded.drain(..) {
                            match &ev {
                                Event::Boot => {
                                    tracing::info!("board booted; handshaking");
                                    session.handshake_due = Some(t);
                                    session.rcap_sent = false;
                                }
                                Event::CrcFail { calc, got } => {
                                    stats.crc_failures_echoed += 1;
                                    tracing::debug!(calc, got, "board dropped a frame: CRC mismatch");
                                }
                                Event::Nav(_) | Event::Status(_) => last_line = Some(t),
                                _ => {}
                            }
                            if events.try_send(LinkEvent::Telemetry(ev)).is_err() {
                                stats.events_dropped += 1;
                            }
                        }
                    }
                    Err(e) => break format!("read failed: {e}"),
                },
                req = rx.recv() => match req {
                    None => break 'outer,
                    Some(Request::Command(c)) => {
                        outbox.push(c, &mut stats);
                        // Drain what else is waiting so that only the newest thrust survives.
                        while let Ok(r) = rx.try_recv() {
                            match r {
                                Request::Command(c) => outbox.push(c, &mut stats),
                                Request::Healthy => last_healthy = Some(Instant::now()),
                            }
                        }
                    }
                    Some(Request::Healthy) => last_healthy = Some(Instant::now()),
                },
                _ = tokio::time::sleep_until(wake) => {}
            }
        };
        drop(port);
        // What was pending was decided for a board that is gone; the vehicle
        // task decides again when the link is back.
        if outbox.thrust.take().is_some() {
            stats.thrust_coalesced += 1;
        }
        report(
            &mut stats,
            &mut reported,
            LinkState::Down,
            Some(down_reason),
            &events,
        );
        let _ = stats_tx.send(stats.clone());
        // Wait before reopening: a vanished USB device takes a moment to return.
        let retry_at = Instant::now() + backoff;
        backoff = (backoff * 2).min(cfg.backoff_max);
        if !wait_retry(
            &mut rx,
            &mut outbox,
            &mut stats,
            &mut last_healthy,
            retry_at,
        )
        .await
        {
            break 'outer;
        }
    }
    let _ = stats_tx.send(stats);
}

/// Waits until `retry_at` while still taking requests, so that the newest
/// thrust command is what goes out once the board is back. `false` when every
/// [`LinkHandle`] is gone.
async fn wait_retry(
    rx: &mut mpsc::UnboundedReceiver<Request>,
    outbox: &mut Outbox,
    stats: &mut LinkStats,
    last_healthy: &mut Option<Instant>,
    retry_at: Instant,
) -> bool {
    loop {
        tokio::select! {
            req = rx.recv() => match req {
                None => return false,
                Some(Request::Command(c)) => outbox.push(c, stats),
                Some(Request::Healthy) => *last_healthy = Some(Instant::now()),
            },
            _ = tokio::time::sleep_until(retry_at) => return true,
        }
    }
}
