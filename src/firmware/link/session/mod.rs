//! The link's decisions, sans-IO: what to write to the board, when, and what
//! to report, as a plain state machine over (state, event, now).
//!
//! Owns the start-up handshake (wait for `boot`, or `boot_wait` for a board
//! that was already running, longer for one heard in its set-up; then
//! `dms(1)`, `start()`), the keep-alive
//! `ping(0)` gated on the vehicle task's health (queued ahead of pending
//! levels), the outbox that coalesces thruster commands and lights, laser
//! and tilt levels (the newest wins), the pacing that keeps the board's
//! receive buffer from overflowing, the telemetry watchdog, the link state
//! and its figures, and the reopen backoff.
//!
//! What the genuine firmware taught: `rcap()` blocks the board for five
//! seconds (an I2C scan and a `delay(5000)`), so it is never sent; the
//! board reads the serial line only between its loop's other work into a
//! 64-byte buffer, so frames are written only while the ones not yet
//! echoed (`rawcmd:` with CRC-8 framing, `cmd:` with plain) fit in it — a
//! board that stops echoing (busy, resetting) gets nothing more; a board
//! that prints `boot` again has restarted, and the link handshakes again
//! before it reports itself up; a board whose sensors' set-up takes longer
//! than the boot wait (30.0.2 with an IMU: 2.5 s) prints its chatter first,
//! and a handshake written then would sit unread in its buffer, its echoes
//! time out and more frames follow into the full buffer; and after a gap
//! in the pings as long as the board's dead-man timeout, or nearly (its
//! clock is not ours), a thrust command decided before the gap is replaced
//! by neutral: the board has just stopped, and the ping that follows
//! restarts it on its last target.
//!
//! It must never read a clock, sleep, or touch the serial device or a
//! channel: the I/O loop (`io.rs`) passes the time in with every call, writes
//! the frames it is handed and delivers the [`Output`]s in order. Nor does it
//! decide what the vehicle does: commands come from the vehicle task.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use super::{LinkConfig, LinkEvent, LinkQuality, LinkState, LinkStats};
use crate::firmware::codec::{Command, Event, Framing, LineDecoder, encode};

mod confirm;
mod outbox;
pub(crate) mod quality;
mod timing;

use confirm::Confirm;
use outbox::{Budget, ECHO_OVERDUE, InFlight, Outbox, acknowledge, echo_matches, raw_frame};
use quality::Quality;

/// How often the figures are published while the device is open (at most;
/// when the session runs anyway), and while it is closed.
const STATS_PERIOD: Duration = Duration::from_millis(100);

/// The longest the session sleeps while the device is open and nothing is
/// due (a link that is down, a silent board): its figures stay fresh to a
/// second.
const WATCHDOG_IDLE: Duration = Duration::from_secs(1);

/// What the session asks the I/O loop to deliver, in the order it decided.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Output {
    /// Publish these figures (a copy taken when they were decided).
    Stats(LinkStats),
    /// Hand this to the vehicle task; if it has no room, tell
    /// [`Session::event_dropped`].
    Event(LinkEvent),
}

/// The neutral pulse width.
const NEUTRAL_US: u16 = crate::vehicle::mixer::NEUTRAL_US;

/// `go()` with every thruster stopped.
const NEUTRAL_GO: Command = Command::Go {
    port_us: NEUTRAL_US,
    vertical_us: NEUTRAL_US,
    starboard_us: NEUTRAL_US,
};

/// The board's motor mapping, as the firmware ships it (`Motor.cpp`): what
/// its `motors:` reports are compared with.
fn cfg_motors() -> crate::vehicle::mixer::BoardMotors {
    crate::vehicle::mixer::BoardMotors::default()
}

/// What lives only as long as one opening of the device.
#[derive(Debug)]
struct Connection {
    opened_at: Instant,
    decoder: LineDecoder,
    /// Scratch for one read's events, kept to spare an allocation per read.
    decoded: Vec<Event>,
    handshake_due: Option<Instant>,
    handshaken: bool,
    /// Frames written and not yet echoed by the board, oldest first: their
    /// bytes (to recognise the echo) and when they were written.
    in_flight: VecDeque<InFlight>,
    /// The board's last `rawcmd:` echo took a frame out of `in_flight`:
    /// the `cmd:` echo that follows it is of that same frame, not of the
    /// next (an identical frame behind it, a re-send, is still on its way).
    raw_echoed: bool,
    /// When the last `ping` was written.
    last_ping: Option<Instant>,
    /// When the board will have taken everything written so far (a virtual
    /// finish time: each frame costs its wire time plus `frame_gap`). A
    /// frame may go out while that is at most `max_ahead` away, so a
    /// command after a ping is written at once, while a burst is held back
    /// before it can fill the board's 80-byte buffer or 5-slot queue.
    line_free_at: Instant,
    next_ping: Instant,
    next_stats: Instant,
    /// Lines accepted before the last handshake: only a newer one proves
    /// the handshaken board is talking.
    lines_at_open: u64,
    /// The board printed telemetry since the device was opened: a `boot`
    /// before that is its first start (still setting up when the boot wait
    /// ran out), not a reboot.
    board_talked: bool,
    /// The board printed something (set-up chatter, a torn line, anything)
    /// since the device was opened.
    heard: bool,
    /// The board printed `boot` since the device was opened.
    booted: bool,
    /// When the board last printed anything at all.
    last_heard: Option<Instant>,
}

impl Connection {
    /// The board is still in its set-up: heard, but neither `boot` nor
    /// telemetry yet. A command written now would wait in its receive
    /// buffer through the set-up and its echo time out, and more would
    /// follow into a buffer nobody empties.
    fn setting_up(&self, now: Instant, allowance: Duration) -> bool {
        self.heard && !self.booted && !self.board_talked && now < self.opened_at + allowance
    }
}

/// How close to the board's dead-man timeout a gap in the pings counts as
/// one that may have tripped it. Pings go every 400 ms while the vehicle
/// is healthy, so only a vehicle that stood still comes this near.
const DEAD_MAN_DOUBT: Duration = Duration::from_millis(500);

/// The link's state machine (see the module docs).
#[derive(Debug)]
pub(crate) struct Session {
    cfg: LinkConfig,
    stats: LinkStats,
    outbox: Outbox,
    last_healthy: Option<Instant>,
    backoff: Duration,
    /// The state last reported to the vehicle task.
    reported: Option<LinkState>,
    /// When the newest navigation or status line arrived (kept across
    /// openings; only one newer than the opening counts).
    last_line: Option<Instant>,
    conn: Option<Connection>,
    outputs: VecDeque<Output>,
    /// Whether the board holds the thrust the vehicle wants.
    confirm: Confirm,
    quality: Quality,
    /// The line quality last reported to the vehicle task.
    quality_reported: Option<LinkQuality>,
    /// The next frame's number.
    next_serial: u64,
}

impl Session {
    /// A session for a device not opened yet (reported down at once).
    pub(crate) fn new(cfg: LinkConfig) -> Self {
        let mut session = Self {
            backoff: cfg.backoff_min,
            cfg,
            stats: LinkStats::default(),
            outbox: Outbox::default(),
            last_healthy: None,
            reported: None,
            last_line: None,
            conn: None,
            outputs: VecDeque::new(),
            confirm: Confirm::new(cfg_motors()),
            quality: Quality::default(),
            quality_reported: None,
            next_serial: 0,
        };
        session.report(LinkState::Down, Some("not opened yet".into()));
        session
    }

    /// The figures as they are now.
    pub(crate) fn stats(&self) -> &LinkStats {
        &self.stats
    }

    /// The next thing to deliver, oldest first.
    pub(crate) fn poll_output(&mut self) -> Option<Output> {
        self.outputs.pop_front()
    }

    /// The vehicle task had no room for `event`.
    pub(crate) fn event_dropped(&mut self, event: &LinkEvent) {
        self.stats.events_dropped += 1;
        if matches!(event, LinkEvent::State { .. }) {
            self.publish();
        }
    }

    /// A command from the vehicle task. Thruster commands are coalesced:
    /// only the newest pending one is written. Taken while the device is
    /// down too, so the newest one is what goes out once the board is back.
    pub(crate) fn command(&mut self, cmd: Command) {
        if cmd.is_thrust() {
            self.confirm.wanted(&cmd);
        }
        self.outbox.push(cmd, &mut self.stats);
    }

    /// The vehicle task said it is alive at `now`.
    pub(crate) fn healthy(&mut self, now: Instant) {
        self.last_healthy = Some(now);
    }

    /// The device could not be opened. Returns when to try again.
    pub(crate) fn open_failed(&mut self, reason: String, now: Instant) -> Instant {
        self.report(LinkState::Down, Some(reason));
        self.publish();
        self.retry_at(now)
    }

    /// The device was opened at `now`: wait for `boot` (or `boot_wait`),
    /// then handshake.
    pub(crate) fn opened(&mut self, now: Instant) {
        self.stats.opens += 1;
        self.conn = Some(Connection {
            opened_at: now,
            decoder: LineDecoder::new(),
            decoded: Vec::with_capacity(16),
            handshake_due: Some(now + self.cfg.boot_wait),
            handshaken: false,
            in_flight: VecDeque::new(),
            raw_echoed: false,
            last_ping: None,
            line_free_at: now,
            next_ping: now,
            next_stats: now,
            lines_at_open: 0,
            board_talked: false,
            heard: false,
            booted: false,
            last_heard: None,
        });
        self.report(LinkState::Handshaking, None);
    }

    /// The device failed or closed for `reason`. Returns when to reopen.
    pub(crate) fn closed(&mut self, reason: String, now: Instant) -> Instant {
        self.conn = None;
        // What was pending was decided for a board that is gone; the vehicle
        // task decides again when the link is back.
        if self.outbox.thrust.take().is_some() {
            self.stats.thrust_coalesced += 1;
        }
        self.confirm.forget();
        self.report(LinkState::Down, Some(reason));
        self.publish();
        self.retry_at(now)
    }

    /// Bytes read from the device at `now`: decoded and passed on.
    pub(crate) fn received(&mut self, bytes: &[u8], now: Instant) {
        let Some(conn) = self.conn.as_mut() else {
            return;
        };
        self.stats.bytes_in += bytes.len() as u64;
        let mut reboot = false;
        conn.decoded.clear();
        conn.decoder.push(bytes, &mut conn.decoded);
        self.stats.decode = conn.decoder.stats().clone();
        for ev in conn.decoded.drain(..) {
            match &ev {
                Event::Boot => {
                    tracing::info!("board booted; handshaking");
                    conn.handshake_due = Some(now);
                    conn.booted = true;
                    // Whatever it had not taken is gone with its old state;
                    // it holds neutral, and the vehicle decides again: a
                    // thrust still pending was decided for the board
                    // before, and is not written to the new one.
                    conn.in_flight.clear();
                    if self.outbox.thrust.take().is_some() {
                        self.stats.thrust_coalesced += 1;
                    }
                    self.confirm.forget();
                    reboot = conn.handshaken && conn.board_talked;
                }
                Event::RawCmd(hex) if self.cfg.framing == Framing::Crc8 => {
                    conn.raw_echoed = raw_frame(hex).is_some_and(|frame| {
                        acknowledge(
                            &mut conn.in_flight,
                            &mut self.stats,
                            &mut self.confirm,
                            |f| *f == frame,
                        )
                    });
                }
                // After `crc:pass`: the text of the frame whose `rawcmd:`
                // came just before. Already taken out when that echo was
                // recognised; else the oldest frame's, its `rawcmd:` echo
                // damaged on the way back (an identical frame behind it
                // taken for it holds the same command).
                Event::CmdEcho(_) if std::mem::take(&mut conn.raw_echoed) => {}
                Event::CmdEcho(text) if self.cfg.framing == Framing::Crc8 => {
                    let front = conn.in_flight.front().map(|f| f.frame.clone());
                    if let Some(front) = front {
                        acknowledge(
                            &mut conn.in_flight,
                            &mut self.stats,
                            &mut self.confirm,
                            |f| f == front.as_slice() && echo_matches(&f[1..], text),
                        );
                    }
                }
                Event::CmdEcho(text) if self.cfg.framing == Framing::Plain => {
                    let ours = conn.in_flight.iter().any(|f| echo_matches(&f.frame, text));
                    if ours {
                        acknowledge(
                            &mut conn.in_flight,
                            &mut self.stats,
                            &mut self.confirm,
                            |f| echo_matches(f, text),
                        );
                    } else if let Some(f) = conn.in_flight.pop_front() {
                        // No CRC in this framing: the board read the oldest
                        // frame damaged (and may have taken what it read),
                        // or the echo was damaged on its way back. Either
                        // way that frame is not known taken.
                        self.stats.echoes_missed += 1;
                        if f.thrust {
                            self.confirm.lost(f.serial);
                        }
                    }
                }
                Event::CrcFail { calc, got } => {
                    conn.raw_echoed = false;
                    self.stats.crc_failures_echoed += 1;
                    tracing::debug!(calc, got, "board dropped a frame: CRC mismatch");
                    // It reads frames in order: the one it rejected is the
                    // oldest not echoed yet.
                    if let Some(f) = conn.in_flight.pop_front()
                        && f.thrust
                    {
                        self.confirm.lost(f.serial);
                    }
                }
                Event::Nav(_) => {
                    self.last_line = Some(now);
                    conn.board_talked = true;
                }
                Event::Status(status) => {
                    self.last_line = Some(now);
                    conn.board_talked = true;
                    if let Some(target) = status.mtarg_us {
                        self.confirm.target_reported(target);
                    }
                    if let Some(esc) = status.motors_us {
                        self.confirm.outputs_reported(esc);
                    }
                }
                // The dead-man's stop: the board holds neutral now.
                Event::InternalCommand(cmd) if cmd.starts_with("stop") => {
                    self.confirm.target_reported([NEUTRAL_US; 3]);
                }
                _ => {}
            }
            self.outputs
                .push_back(Output::Event(LinkEvent::Telemetry(ev)));
        }
        if !bytes.is_empty() {
            conn.heard = true;
            conn.last_heard = Some(now);
        }
        if reboot {
            self.stats.board_reboots += 1;
            self.report(LinkState::Handshaking, Some("the board rebooted".into()));
        }
    }

    /// What to write at `now`, if anything: handshakes that are due, the
    /// keep-alive, then one pending command if pacing allows. The frame is
    /// encoded into `frame`; call [`Session::transmitted`] once it is
    /// written (a frame that fails to write is lost with the device).
    pub(crate) fn poll_transmit(&mut self, now: Instant, frame: &mut Vec<u8>) -> Option<Command> {
        let healthy = self.vehicle_healthy(now);
        let conn = self.conn.as_mut()?;
        // Handshake: after `boot`, or after boot_wait for a board that was
        // already up (or is silent) — but not while it is still setting up.
        if conn.handshake_due.is_some_and(|t| now >= t)
            && !conn.setting_up(now, self.cfg.setup_allowance)
        {
            conn.handshake_due = None;
            conn.handshaken = true;
            self.stats.handshakes += 1;
            self.outputs.push_back(Output::Stats(self.stats.clone()));
            self.outbox.control.push_back(Command::DeadMan(true));
            self.outbox.control.push_back(Command::Start);
            conn.lines_at_open = self.stats.decode.lines_accepted;
            // A ping now, so the freshly armed dead-man has a full period.
            conn.next_ping = now;
        }
        // A gap in the pings that may have tripped the board's dead-man:
        // within DEAD_MAN_DOUBT of its timeout counts, for the board's clock
        // is not ours (a crystal's error, a simulator catching up) and a
        // thrust written to a board that did trip is resumed by the ping
        // that follows.
        let gap = Self::gap_since(conn.last_ping, now, self.cfg.dead_man_timeout);
        if conn.handshaken && now >= conn.next_ping && healthy {
            conn.next_ping = now + self.cfg.ping_period;
            if !self.outbox.control.contains(&Command::Ping(0)) {
                // Ahead of levels waiting their turn (the dead-man must not
                // starve behind the lights), behind the handshake.
                let at = self
                    .outbox
                    .control
                    .iter()
                    .position(Command::is_level)
                    .unwrap_or(self.outbox.control.len());
                self.outbox.control.insert(at, Command::Ping(0));
                self.stats.pings_written += 1;
                if gap {
                    // The board stopped, and this ping restarts it on its
                    // last target (the firmware's `start`): neutral first,
                    // so it restarts stopped and only the vehicle's next
                    // decision drives it; a thrust decided before the gap
                    // is not written.
                    self.outbox.control.insert(at, NEUTRAL_GO);
                    if self.outbox.thrust.take().is_some() {
                        self.stats.thrust_coalesced += 1;
                    }
                    // And neutral is what the link confirms (and writes
                    // again) until the vehicle's next decision: the push
                    // it wanted before the gap is not renewed.
                    self.confirm.wanted(&NEUTRAL_GO);
                }
            }
        }
        // A thrust the board did not take (or says it does not hold) goes
        // again, unless a newer one waits already; a push only while the
        // keep-alive would go (the vehicle healthy, no gap).
        if conn.handshaken
            && let Some(again) = self.confirm.due(now, healthy && !gap)
            && self.outbox.thrust.is_none()
        {
            self.outbox.thrust = Some(again);
            self.stats.thrust_resent += 1;
        }
        // The board's dead-man has (or may have) stopped it since the last
        // ping; it still obeys `go()`, so no thrust but neutral is written
        // until a ping is (the ping then goes behind a neutral, above).
        if gap && self.outbox.thrust.is_some_and(|t| t != NEUTRAL_GO) {
            self.outbox.thrust = None;
            self.stats.thrust_coalesced += 1;
        }
        // Echoes that never came: the board lost those frames (or is busy
        // and will not take them soon); they no longer hold the budget.
        while let Some(f) = conn
            .in_flight
            .front()
            .is_some_and(|f| now.duration_since(f.at) > self.cfg.echo_timeout)
            .then(|| conn.in_flight.pop_front())
            .flatten()
        {
            self.stats.echoes_missed += 1;
            tracing::debug!(
                frame = %String::from_utf8_lossy(&f.frame).trim_start_matches(|c: char| !c.is_ascii_graphic()),
                age_ms = now.duration_since(f.at).as_millis() as u64,
                "the board never echoed a frame"
            );
            if f.thrust {
                self.confirm.lost(f.serial);
            }
        }
        let budget = Budget::at(&conn.in_flight, self.cfg.max_in_flight_bytes, now);
        if conn.line_free_at.saturating_duration_since(now) <= self.cfg.max_ahead
            && conn.handshaken
            && let Some(mut cmd) = self.outbox.peek()
        {
            frame.clear();
            encode(&cmd, self.cfg.framing, frame);
            if budget.fits(&cmd, frame.len()) {
                self.outbox.pop();
            } else {
                // Waits for the board's echo (or its timeout) — but a
                // keep-alive behind it goes past (a stop written again
                // into a budget lost echoes hold must not starve the
                // board's dead-man).
                if cmd == Command::Ping(0) || !self.outbox.take_ping() {
                    return None;
                }
                cmd = Command::Ping(0);
                frame.clear();
                encode(&cmd, self.cfg.framing, frame);
                if !budget.fits(&cmd, frame.len()) {
                    self.outbox.control.push_front(cmd);
                    return None;
                }
            }
            let serial = self.next_serial;
            self.next_serial += 1;
            if cmd.is_thrust() {
                self.confirm.written(&cmd, serial, now);
            }
            conn.in_flight.push_back(InFlight {
                frame: frame.clone(),
                at: now,
                thrust: cmd.is_thrust(),
                serial,
            });
            if cmd == Command::Ping(0) {
                conn.last_ping = Some(now);
            }
            return Some(cmd);
        }
        None
    }

    /// `cmd`, `frame_len` bytes long, was written at `now` (the `now` its
    /// [`Session::poll_transmit`] was given).
    pub(crate) fn transmitted(&mut self, cmd: &Command, frame_len: usize, now: Instant) {
        self.stats.bytes_out += frame_len as u64;
        self.stats.commands_written += 1;
        if cmd.is_thrust() {
            self.stats.thrust_written += 1;
        }
        if let Some(conn) = self.conn.as_mut() {
            conn.line_free_at =
                conn.line_free_at.max(now) + self.cfg.wire_time(frame_len) + self.cfg.frame_gap;
        }
    }

    /// The timers at `now`: the telemetry watchdog (down when the board is
    /// silent, up once a handshaken board talks) and the figures.
    pub(crate) fn poll_timers(&mut self, now: Instant) {
        let Some(conn) = self.conn.as_ref() else {
            return;
        };
        let handshaken = conn.handshaken;
        let lines_at_open = conn.lines_at_open;
        let (silent_since, allowed) = self.silence(conn, now);
        if now.duration_since(silent_since) > allowed {
            if self.stats.state != LinkState::Down {
                self.report(
                    LinkState::Down,
                    Some(format!(
                        "no telemetry from the board for {:.1} s",
                        now.duration_since(silent_since).as_secs_f64()
                    )),
                );
            }
        } else if handshaken
            && self.stats.decode.lines_accepted > lines_at_open
            && self.stats.state != LinkState::Up
        {
            self.report(LinkState::Up, None);
            self.backoff = self.cfg.backoff_min;
        }
        if let Some(conn) = self.conn.as_mut()
            && now >= conn.next_stats
        {
            conn.next_stats = now + STATS_PERIOD;
            self.stats.telemetry_age_ms = self
                .last_line
                .map(|t| now.duration_since(t).as_millis() as u64);
            self.stats.drop_rate_cpct = self.quality.drop_rate_cpct(&self.stats, now);
            let q = LinkQuality {
                drop_rate_cpct: self.stats.drop_rate_cpct,
                errors: quality::errors(&self.stats),
            };
            self.publish();
            // The vehicle task hears of a change only (an idle, clean line
            // wakes it for nothing).
            if self.quality_reported != Some(q) {
                self.quality_reported = Some(q);
                self.outputs.push_back(Output::Event(LinkEvent::Quality(q)));
            }
        }
    }

    fn publish(&mut self) {
        self.stats.thrust_unechoed = self.conn.as_ref().map_or(0, |c| {
            c.in_flight.iter().filter(|f| f.thrust).count() as u64
        });
        self.outputs.push_back(Output::Stats(self.stats.clone()));
    }

    /// Records the link state; a change is logged and reported, figures first.
    fn report(&mut self, state: LinkState, reason: Option<String>) {
        self.stats.state = state;
        self.stats.down_reason = reason.clone();
        if self.reported == Some(state) {
            return;
        }
        self.reported = Some(state);
        let device = self.cfg.device.display();
        match state {
            LinkState::Down => {
                tracing::warn!(device = %device, reason = reason.as_deref().unwrap_or(""), "board link down")
            }
            LinkState::Handshaking => {
                tracing::info!(device = %device, "board link: handshaking")
            }
            LinkState::Up => tracing::info!(device = %device, "board link up"),
        }
        // Figures first: anyone looking at them after the event sees the
        // new state (the other order let a test read the old reason).
        self.publish();
        self.outputs
            .push_back(Output::Event(LinkEvent::State { state, reason }));
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_confirm;
#[cfg(test)]
mod tests_hazards;
#[cfg(test)]
mod tests_keepalive;
