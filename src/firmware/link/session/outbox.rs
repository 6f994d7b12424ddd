//! What waits to be written to the board and what was written and not yet
//! echoed (sans-IO): the outbox's order (a stop first, the keep-alive
//! ahead of levels, the newest thrust), the board's receive buffer as a
//! budget of unechoed bytes (with room of its own for the keep-alive and a
//! stop once a frame is overdue), and the matching of the board's echoes to the frames in flight.
//! It decides nothing about what the vehicle does.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use super::confirm::Confirm;
use super::{LinkStats, NEUTRAL_GO};
use crate::firmware::codec::Command;

/// The bytes a `rawcmd:` echo lists (`9E,70,69,6E,67,28,30,29,3B,`: each
/// received byte in hex, each followed by a comma).
pub(super) fn raw_frame(hex: &str) -> Option<Vec<u8>> {
    hex.split(',')
        .filter(|h| !h.is_empty())
        .map(|h| u8::from_str_radix(h, 16).ok())
        .collect()
}

/// Whether the board's `cmd:` echo (`go(1500,1500,1500)`, tokens re-joined
/// with commas) is of `frame` (`go(1500,1500,1500);`, plain framing).
pub(super) fn echo_matches(frame: &[u8], echo: &str) -> bool {
    let canon = |t: &[u8]| -> Vec<u8> {
        t.iter()
            .copied()
            .filter(|&b| b != b' ' && b != b';')
            .collect()
    };
    canon(frame) == canon(echo.as_bytes())
}

/// A frame written and not yet echoed.
#[derive(Debug)]
pub(super) struct InFlight {
    pub(super) frame: Vec<u8>,
    pub(super) at: Instant,
    pub(super) thrust: bool,
    /// The frame's number, in the order written.
    pub(super) serial: u64,
}

/// The oldest in-flight frame that `is_it` recognises, and every older one
/// (frames the board lost: it echoes in order), taken out: the echoed one
/// is reported to `confirm`, the older ones as lost and counted. An echo
/// of nothing in flight (another writer's frame, a garbled one) changes
/// nothing. Whether a frame was recognised.
pub(super) fn acknowledge(
    in_flight: &mut VecDeque<InFlight>,
    stats: &mut LinkStats,
    confirm: &mut Confirm,
    is_it: impl Fn(&[u8]) -> bool,
) -> bool {
    let Some(i) = in_flight.iter().position(|f| is_it(&f.frame)) else {
        return false;
    };
    let newest_alike = in_flight
        .iter()
        .skip(i + 1)
        .filter(|g| g.thrust)
        .all(|g| g.frame == in_flight[i].frame);
    for (n, f) in in_flight.drain(..=i).enumerate() {
        if n < i {
            stats.echoes_missed += 1;
            tracing::debug!(
                frame = %String::from_utf8_lossy(&f.frame).trim_start_matches(|c: char| !c.is_ascii_graphic()),
                "the board echoed a later frame first: this one was lost"
            );
            if f.thrust {
                confirm.lost(f.serial);
            }
        } else if f.thrust {
            stats.thrust_echoed += 1;
            confirm.echoed(f.serial, newest_alike);
        }
    }
    true
}

/// Pending writes: control commands in order (a level replacing a pending
/// one of its kind in place, the keep-alive ping ahead of the levels), plus
/// the newest thrust command — which goes first when it is neutral (a stop
/// waits for nothing but the handshake).
#[derive(Debug, Default)]
pub(super) struct Outbox {
    pub(super) control: VecDeque<Command>,
    pub(super) thrust: Option<Command>,
}

impl Outbox {
    pub(super) fn push(&mut self, cmd: Command, stats: &mut LinkStats) {
        if cmd.is_thrust() {
            if self.thrust.replace(cmd).is_some() {
                stats.thrust_coalesced += 1;
            }
        } else if let Some(pending) = cmd
            .is_level()
            .then(|| self.control.iter_mut().find(|c| c.name() == cmd.name()))
            .flatten()
        {
            *pending = cmd;
            stats.settings_coalesced += 1;
        } else {
            self.control.push_back(cmd);
        }
    }
    fn neutral_first(&self) -> bool {
        self.thrust == Some(NEUTRAL_GO)
            && !self
                .control
                .front()
                .is_some_and(|c| matches!(c, Command::DeadMan(_) | Command::Start))
    }
    pub(super) fn pop(&mut self) -> Option<Command> {
        if self.neutral_first() {
            return self.thrust.take();
        }
        self.control.pop_front().or_else(|| self.thrust.take())
    }
    pub(super) fn peek(&self) -> Option<Command> {
        if self.neutral_first() {
            return self.thrust;
        }
        self.control.front().copied().or(self.thrust)
    }
    pub(super) fn is_empty(&self) -> bool {
        self.control.is_empty() && self.thrust.is_none()
    }
    /// Takes the pending keep-alive out of the queue, if there is one.
    pub(super) fn take_ping(&mut self) -> bool {
        let at = self.control.iter().position(|c| *c == Command::Ping(0));
        at.and_then(|i| self.control.remove(i)).is_some()
    }
}

/// Bytes beyond the board's receive buffer that a `ping` and a neutral
/// `go()` may still be written into (the two of them, with CRC-8 framing,
/// and a little over) once the oldest frame in flight is overdue.
const URGENT_ROOM: usize = 32;

/// A frame in flight this long is overdue: on a noisy line it was lost,
/// or its echo was — the budget it holds is most likely free on the board.
/// Longer than the confirm timeout, which only puts a thrust back in the
/// queue: the genuine 30.0.2 board's loop now and then reads nothing for
/// more than 60 ms, and a stop or a ping written into the extra room then
/// overran its 63-byte buffer (CRC rejections in the simulator report's
/// runs, none at 120 ms).
pub(super) const ECHO_OVERDUE: Duration = Duration::from_millis(120);

/// The board's receive buffer as the link sees it at one moment: the bytes
/// written and not yet echoed, and whether the oldest of them is overdue.
#[derive(Debug, Clone, Copy)]
pub(super) struct Budget {
    in_flight: usize,
    max: usize,
    overdue: bool,
}

impl Budget {
    /// With `in_flight` at `now`, the board's buffer `max` bytes.
    pub(super) fn at(in_flight: &VecDeque<InFlight>, max: usize, now: Instant) -> Self {
        Self {
            in_flight: in_flight.iter().map(|f| f.frame.len()).sum(),
            max,
            overdue: in_flight
                .front()
                .is_some_and(|f| now.saturating_duration_since(f.at) > ECHO_OVERDUE),
        }
    }

    /// Whether `cmd`, `len` bytes long, may be written: within the board's
    /// buffer, or — the keep-alive and a stop, once the oldest frame is
    /// overdue — within [`URGENT_ROOM`] more. Frames whose echoes a noisy
    /// line lost hold the budget until their echo timeout (500 ms), and
    /// neither a stop nor the dead-man's feeding may wait that long behind
    /// them; a board merely slow to read a burst echoes within the overdue
    /// time, and its buffer is never overrun. Were it really busy and
    /// full, a keep-alive or a stop it drops costs no more than one not
    /// written.
    pub(super) fn fits(&self, cmd: &Command, len: usize) -> bool {
        let urgent = self.overdue && (*cmd == Command::Ping(0) || *cmd == NEUTRAL_GO);
        self.in_flight + len <= self.max + if urgent { URGENT_ROOM } else { 0 }
    }
}
