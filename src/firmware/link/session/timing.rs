//! The session's clocks: when the board counts as silent, when the
//! keep-alive is due, whether the next frame fits the board's budget, and
//! when to try a lost device again.

use std::time::{Duration, Instant};

use super::*;

impl Session {
    /// Since when the board counts as silent at `now`, and how long it may
    /// be.
    pub(super) fn silence(&self, conn: &Connection, now: Instant) -> (Instant, Duration) {
        let opened_at = conn.opened_at;
        // Until the board's first telemetry line it may still be setting up
        // (an IMU's self-test holds the 30.0.2 firmware ~2.5 s): the boot
        // wait's allowance stays.
        let settled = conn.handshaken && conn.board_talked;
        let mut silent_since = self
            .last_line
            .filter(|t| *t >= opened_at)
            .unwrap_or(opened_at);
        // A board printing its set-up chatter or its `boot` is alive though
        // it prints no telemetry yet (a slow sensor, or a loaded simulator,
        // stretches a set-up past the boot wait's allowance) — for as long as a
        // set-up may last; a device that only ever prints what is not
        // telemetry (a wrong baud rate) is down after that.
        if !settled
            && now < opened_at + self.cfg.setup_allowance
            && let Some(heard) = conn.last_heard
        {
            silent_since = silent_since.max(heard);
        }
        let allowed = self.cfg.stale_after
            + if settled {
                Duration::ZERO
            } else {
                self.cfg.boot_wait
            };
        (silent_since, allowed)
    }

    /// When the telemetry watchdog next has something to decide: just past
    /// the board's allowed silence, and the end of a set-up's allowance
    /// (where chatter stops counting as life). None once the link is down:
    /// the board's next line is what changes that.
    pub(super) fn watchdog_due(&self, conn: &Connection, now: Instant) -> Option<Instant> {
        if self.stats.state == LinkState::Down {
            return None;
        }
        let (silent_since, allowed) = self.silence(conn, now);
        // Just past it: the check is "longer than allowed".
        let mut due = silent_since + allowed + Duration::from_millis(1);
        let setup_ends = conn.opened_at + self.cfg.setup_allowance;
        if now < setup_ends {
            due = due.min(setup_ends);
        }
        Some(due)
    }

    /// When the session next has something to do without new input: the
    /// telemetry watchdog's deadline, the handshake, a frame the line has
    /// room for, an echo's timeout, the next ping. The figures do not wake
    /// it: they are published when it runs anyway, at most every 100 ms (a
    /// talking board's lines wake it ten times a second; a silent one, the
    /// watchdog, or at least every second).
    pub(crate) fn next_wake(&self, now: Instant) -> Instant {
        let Some(conn) = self.conn.as_ref() else {
            return now + STATS_PERIOD;
        };
        let mut wake = self
            .watchdog_due(conn, now)
            .unwrap_or(now + WATCHDOG_IDLE)
            .min(now + WATCHDOG_IDLE);
        if let Some(t) = conn.handshake_due {
            let t = if conn.setting_up(now, self.cfg.setup_allowance) {
                t.max(conn.opened_at + self.cfg.setup_allowance)
            } else {
                t
            };
            wake = wake.min(t);
        }
        if conn.handshaken && !self.outbox.is_empty() {
            // The line's room, when the board's has room for the next frame
            // too (else only an echo, or its timeout, frees it: waking for
            // the line would spin).
            if self.next_fits(conn, now) {
                wake = wake.min(
                    conn.line_free_at
                        .checked_sub(self.cfg.max_ahead)
                        .unwrap_or(now),
                );
            }
            // Waiting for an echo: the oldest frame's overdue time (when a
            // keep-alive or a stop may go) and its timeout are the latest
            // the budget frees (just past each: the checks are "later
            // than").
            if let Some(f) = conn.in_flight.front() {
                let overdue = f.at + ECHO_OVERDUE + Duration::from_millis(1);
                let timeout = f.at + self.cfg.echo_timeout + Duration::from_millis(1);
                wake = wake.min(if overdue > now { overdue } else { timeout });
            }
        }
        let alive = self.vehicle_healthy(now) && !self.ping_gap(conn, now);
        if conn.handshaken
            && let Some(t) = self.confirm.next_due(now, alive)
        {
            wake = wake.min(t);
        }
        // While the vehicle is not healthy no ping is due (a due-but-withheld
        // ping must not make the loop spin); its next `healthy` wakes the loop.
        if conn.handshaken && self.vehicle_healthy(now) {
            wake = wake.min(conn.next_ping);
        }
        wake
    }

    /// Whether the board has room for the next frame [`Session::poll_transmit`]
    /// would write (the pending keep-alive, if the head must wait).
    pub(super) fn next_fits(&self, conn: &Connection, now: Instant) -> bool {
        let budget = Budget::at(&conn.in_flight, self.cfg.max_in_flight_bytes, now);
        let fits = |cmd: &Command| {
            let mut frame = Vec::new();
            encode(cmd, self.cfg.framing, &mut frame);
            budget.fits(cmd, frame.len())
        };
        self.outbox.peek().is_some_and(|c| fits(&c))
            || (self.outbox.control.contains(&Command::Ping(0)) && fits(&Command::Ping(0)))
    }

    /// Whether the pings have had a gap at `now` that may have tripped the
    /// board's dead-man (within [`DEAD_MAN_DOUBT`] of its timeout).
    pub(super) fn gap_since(last_ping: Option<Instant>, now: Instant, dead_man: Duration) -> bool {
        last_ping.is_some_and(|t| now.duration_since(t) + DEAD_MAN_DOUBT > dead_man)
    }

    pub(super) fn ping_gap(&self, conn: &Connection, now: Instant) -> bool {
        Self::gap_since(conn.last_ping, now, self.cfg.dead_man_timeout)
    }

    /// The vehicle task said it is alive within the healthy window.
    pub(super) fn vehicle_healthy(&self, now: Instant) -> bool {
        self.last_healthy
            .is_some_and(|t| now.duration_since(t) <= self.cfg.healthy_window)
    }

    /// When to try the device again after a failure at `now`; the wait
    /// doubles each time up to `backoff_max`, and is reset once the link is up.
    pub(super) fn retry_at(&mut self, now: Instant) -> Instant {
        // A vanished USB device takes a moment to return.
        let at = now + self.backoff;
        self.backoff = (self.backoff * 2).min(self.cfg.backoff_max);
        at
    }
}
