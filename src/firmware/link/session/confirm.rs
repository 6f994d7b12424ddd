//! Whether the board holds the thrust the vehicle wants, by the board's own
//! words, and when to send it again (sans-IO, time as an argument).
//!
//! The vehicle hands the link a thrust command only when its decision
//! changes (and a non-neutral one again once a second), so a `go()` the
//! board never took — a damaged frame its CRC rejected, a frame whose `;`
//! was lost and that ran into the next — would otherwise stay untaken: a
//! lost stop leaves the last thrust on. The board says what it does:
//!
//! - its echo of each frame it read (`rawcmd:` with the bytes in CRC-8
//!   framing, `cmd:` with the text in either framing; in CRC-8 framing
//!   `cmd:` comes only after `crc:pass`), or `crc:fail` for a frame it
//!   rejected — frames are read in order, so a rejection is the oldest
//!   frame not yet echoed;
//! - `motors:P,V,S` when it applies new outputs (checked every 50 ms):
//!   ESC pulses, the `go()` values through its motor mapping (deadzone
//!   skipped, reverse multiplied: [`BoardMotors`]), compared as such;
//! - `mtarg:P,V,S` once a second: the `go()` values it holds;
//! - `icmd:stop()` when its dead-man stops the thrusters (it holds neutral).
//!
//! The newest thrust written is *held* once the board echoed that frame,
//! or a report says it has it; it is *doubted* when that frame was
//! rejected or lost (a later frame echoed first, no echo within
//! [`CONFIRM_TIMEOUT`]), or when a report heard after it was settled says
//! otherwise. A doubted thrust is written again, at most every
//! [`RESEND_INTERVAL`]; a doubted neutral goes ahead of the keep-alive and
//! the lights (see the outbox). Reports heard while a frame is still on
//! its way say nothing about it and are not judged. A damaged report can
//! only cost a write of what the vehicle wants anyway — or, one that
//! agrees by accident, delay a re-send until the frame's rejection, its
//! missing echo or the board's next report: a thrust held by a report
//! is doubted again when its frame turns out lost.
//!
//! What is written again is only ever the vehicle's newest thrust
//! decision: a newer one replaces it ([`Confirm::wanted`]), a device that
//! closed or a board that rebooted forgets it ([`Confirm::forget`]), and
//! after a gap in the keep-alive the link wants neutral until the vehicle
//! decides again. A thrust that is not neutral is written again only
//! while the vehicle is alive (the keep-alive's own condition): a stalled
//! vehicle's last push is never renewed — the board's dead-man stops it.

use std::time::{Duration, Instant};

use crate::firmware::codec::Command;
use crate::vehicle::mixer::{BoardMotors, NEUTRAL_US};

/// A thrust frame not heard of this long after it was written is taken as
/// lost and written again. The genuine board's echo is ~100 bytes at
/// 115,200 baud (9 ms) once its loop read the frame (~2 ms on the line),
/// behind at most the line it was printing; now and then its loop reads
/// nothing for longer. It is what a stop whose frame was lost, or whose
/// rejection was itself lost, costs on top of the board's 50-ms motor
/// check: a release must reach neutral within 150 ms. Taken as lost too
/// early costs only a frame written twice — when the board's buffer has
/// room for it (the outbox's budget, whose overdue time is longer).
pub(super) const CONFIRM_TIMEOUT: Duration = Duration::from_millis(60);

/// The fewest milliseconds between two writes of a doubted thrust: a board
/// that keeps saying otherwise (a mapping not ours, a line that damages
/// everything) gets at most ten a second.
pub(super) const RESEND_INTERVAL: Duration = Duration::from_millis(100);

/// An ESC pulse in `motors:` within this of what the mapping gives is the
/// same (the servo library's tick rounding).
const ESC_TOLERANCE_US: u16 = 2;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Standing {
    /// Waiting in the outbox.
    Queued,
    /// Its newest frame was written at this time and not heard of since.
    Written(Instant),
    /// The board said it has it.
    Held,
    /// The board did not take it, or said otherwise: to be written again.
    Doubted,
}

/// The thrust the vehicle wants and what the board said about it.
#[derive(Debug)]
pub(super) struct Confirm {
    wanted: Option<[u16; 3]>,
    standing: Standing,
    /// The serial number of the newest thrust frame written.
    newest_frame: Option<u64>,
    last_resend: Option<Instant>,
    motors: BoardMotors,
}

fn values(cmd: &Command) -> Option<[u16; 3]> {
    match *cmd {
        Command::Go {
            port_us,
            vertical_us,
            starboard_us,
        } => Some([port_us, vertical_us, starboard_us]),
        _ => None,
    }
}

impl Confirm {
    pub(super) fn new(motors: BoardMotors) -> Self {
        Self {
            wanted: None,
            standing: Standing::Held,
            newest_frame: None,
            last_resend: None,
            motors,
        }
    }

    /// The vehicle asked for `cmd` (a thrust command).
    pub(super) fn wanted(&mut self, cmd: &Command) {
        self.wanted = values(cmd);
        self.standing = if self.wanted.is_some() {
            Standing::Queued
        } else {
            // Another thrust command (none the vehicle sends today): not
            // confirmed by these reports, not re-sent.
            Standing::Held
        };
    }

    /// What the vehicle wants is no longer to be written (the device
    /// closed; the vehicle decides again once the link is back).
    pub(super) fn forget(&mut self) {
        self.wanted = None;
        self.standing = Standing::Held;
        self.newest_frame = None;
    }

    /// Thrust frame `serial` carrying `cmd` was written at `now`.
    pub(super) fn written(&mut self, cmd: &Command, serial: u64, now: Instant) {
        self.newest_frame = Some(serial);
        if values(cmd).is_some() && values(cmd) == self.wanted {
            self.standing = Standing::Written(now);
        }
    }

    /// The board echoed thrust frame `serial` (it took it); `newest_alike`:
    /// every thrust frame written after it is the same bytes (an echo of
    /// one of identical frames cannot say which it was, and the board holds
    /// the same either way).
    pub(super) fn echoed(&mut self, serial: u64, newest_alike: bool) {
        if (self.newest_frame == Some(serial) || newest_alike)
            && matches!(self.standing, Standing::Written(_))
        {
            self.standing = Standing::Held;
        }
    }

    /// Thrust frame `serial` never reached the board whole. The newest
    /// one lost is doubted even if a report seemed to agree (a damaged
    /// report, or one the board printed before it read the frame).
    pub(super) fn lost(&mut self, serial: u64) {
        if self.newest_frame == Some(serial)
            && matches!(self.standing, Standing::Written(_) | Standing::Held)
        {
            self.standing = Standing::Doubted;
        }
    }

    /// `mtarg:`: the `go()` values the board holds.
    pub(super) fn target_reported(&mut self, target: [u16; 3]) {
        self.judge(self.wanted.map(|w| w == target));
    }

    /// `motors:`: the ESC pulses the board applies.
    pub(super) fn outputs_reported(&mut self, esc_us: [u16; 3]) {
        let agrees = self.wanted.map(|w| {
            w.iter()
                .zip(esc_us)
                .all(|(&go, esc)| self.motors.esc_us(go).abs_diff(esc) <= ESC_TOLERANCE_US)
        });
        self.judge(agrees);
    }

    /// A report that agrees confirms at any time; one that disagrees
    /// counts only once the newest frame was heard of (before, it may
    /// speak of the board before that frame).
    fn judge(&mut self, agrees: Option<bool>) {
        match (agrees, self.standing) {
            (Some(true), _) => self.standing = Standing::Held,
            (Some(false), Standing::Held) => self.standing = Standing::Doubted,
            _ => {}
        }
    }

    /// Whether what the vehicle wants may be written again now: a stop
    /// always; a push only while `alive` (the vehicle task is healthy and
    /// the keep-alive had no gap).
    fn may_resend(&self, alive: bool) -> bool {
        alive || self.wanted == Some([NEUTRAL_US; 3])
    }

    /// At `now`: the thrust to write again, if it is doubted (or its frame
    /// unheard of too long), the last re-send is old enough and, for a
    /// push, the vehicle is `alive`.
    pub(super) fn due(&mut self, now: Instant, alive: bool) -> Option<Command> {
        if let Standing::Written(at) = self.standing
            && now.duration_since(at) > CONFIRM_TIMEOUT
        {
            self.standing = Standing::Doubted;
        }
        let [port_us, vertical_us, starboard_us] = self.wanted?;
        if self.standing != Standing::Doubted
            || !self.may_resend(alive)
            || self
                .last_resend
                .is_some_and(|t| now.duration_since(t) < RESEND_INTERVAL)
        {
            return None;
        }
        self.last_resend = Some(now);
        self.standing = Standing::Queued;
        Some(Command::Go {
            port_us,
            vertical_us,
            starboard_us,
        })
    }

    /// When [`Confirm::due`] may next have something, looking at `now`
    /// (a push held back while the vehicle is not `alive` is no reason to
    /// wake: its next sign of life is).
    pub(super) fn next_due(&self, now: Instant, alive: bool) -> Option<Instant> {
        let after_last = |t: Instant| {
            self.last_resend
                .map_or(t, |last| t.max(last + RESEND_INTERVAL))
        };
        self.wanted?;
        match self.standing {
            Standing::Written(at) => {
                Some(after_last(at + CONFIRM_TIMEOUT + Duration::from_millis(1)))
            }
            Standing::Doubted if self.may_resend(alive) => Some(after_last(now)),
            Standing::Doubted => None,
            Standing::Queued | Standing::Held => None,
        }
    }
}
