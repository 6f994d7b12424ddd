//! The board emulator in the same process, without a pseudo-terminal: the
//! built-in simulator of run mode SIMULATOR and the closed-loop scenarios
//! that run on simulated time.
//!
//! [`LoopbackBoard`] owns one sans-IO [`Board`] and a telemetry decoder, and
//! moves bytes between them and typed commands/events. [`BuiltinSim`] is the
//! one type the app (run mode SIMULATOR) and `scenario/` step: commands,
//! dead-man pings and ground truth. Neither must ever read a clock: the
//! caller passes the time, so a scenario runs as fast as the CPU allows and
//! gives the same result every time.

use std::time::Duration;

use super::codec::{self, Command, Event, Framing, LineDecoder};
use super::emulator::{Board, BoardSnapshot, EmulatorOptions, SimSnapshot};

/// A board emulator driven by calls instead of a serial line.
#[derive(Debug)]
pub struct LoopbackBoard {
    board: Board,
    decoder: LineDecoder,
    framing: Framing,
    bytes: Vec<u8>,
}

impl LoopbackBoard {
    /// A board powered up at `now` (its boot line is decoded with the first
    /// [`LoopbackBoard::advance`]).
    pub fn new(opts: EmulatorOptions, now: Duration) -> Self {
        let framing = opts.framing;
        let mut board = Board::new(opts);
        let mut bytes = Vec::with_capacity(256);
        board.start(now, &mut bytes);
        Self {
            board,
            decoder: LineDecoder::new(),
            framing,
            bytes,
        }
    }

    /// A command, as the link would put it on the wire at `now`.
    pub fn send(&mut self, cmd: &Command, now: Duration) {
        let mut frame = Vec::with_capacity(32);
        codec::encode(cmd, self.framing, &mut frame);
        self.board.receive(&frame, now, &mut self.bytes);
    }

    /// Runs the board and its simulator to `now`; the telemetry it printed
    /// since the last call, decoded, is appended to `events`.
    pub fn advance(&mut self, now: Duration, events: &mut Vec<Event>) {
        self.board.tick(now, &mut self.bytes);
        self.decoder.push(&self.bytes, events);
        self.bytes.clear();
    }

    pub fn snapshot(&self) -> BoardSnapshot {
        self.board.snapshot()
    }

    /// The emulated board (to place the simulated vehicle, stall it …).
    pub fn board_mut(&mut self) -> &mut Board {
        &mut self.board
    }
}

/// Dead-man pings to the built-in simulator's board, at most this often (its
/// dead man stops the motors after 2 s without one).
pub const PING_PERIOD: Duration = Duration::from_millis(500);

/// The built-in simulator: a board emulator and its physics in this
/// process, stepped on the caller's tick. The app's run mode SIMULATOR and
/// the closed-loop scenarios both drive it through this type: stepping,
/// commands, the dead-man ping and the ground truth.
#[derive(Debug)]
pub struct BuiltinSim {
    board: LoopbackBoard,
    last_ping: Option<Duration>,
}

impl BuiltinSim {
    /// A board powered up at `now`, the simulated vehicle at rest at the surface.
    pub fn new(opts: EmulatorOptions, now: Duration) -> Self {
        Self {
            board: LoopbackBoard::new(opts, now),
            last_ping: None,
        }
    }

    /// Places the simulated vehicle, at rest, at this depth and heading.
    pub fn place(&mut self, depth_m: f64, heading_deg: f64) {
        let mut s = crate::sim::SimState::default();
        s.eta[2] = depth_m;
        s.eta[3] = heading_deg.to_radians();
        self.board.board_mut().set_sim_state(s);
    }

    /// Runs the board and its simulator to `now`; the telemetry it printed
    /// since the last step is appended to `events`.
    pub fn step(&mut self, now: Duration, events: &mut Vec<Event>) {
        self.board.advance(now, events);
    }

    /// A command for the board, at `now`.
    pub fn command(&mut self, cmd: &Command, now: Duration) {
        self.board.send(cmd, now);
    }

    /// The vehicle is healthy: the board's dead man hears a ping (at most
    /// every [`PING_PERIOD`]).
    pub fn healthy(&mut self, now: Duration) {
        if self
            .last_ping
            .is_none_or(|t| now.saturating_sub(t) >= PING_PERIOD)
        {
            self.last_ping = Some(now);
            self.board.send(&Command::Ping(0), now);
        }
    }

    /// Where the simulated vehicle really is.
    pub fn truth(&self) -> SimSnapshot {
        self.board.snapshot().sim
    }

    pub fn snapshot(&self) -> BoardSnapshot {
        self.board.snapshot()
    }

    pub fn loopback(&self) -> &LoopbackBoard {
        &self.board
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dead_man_hears_one_ping_per_period_however_often_the_vehicle_is_healthy() {
        let mut sim = BuiltinSim::new(EmulatorOptions::default(), Duration::ZERO);
        let mut events = Vec::new();
        for ms in (10..=1000).step_by(10) {
            let now = Duration::from_millis(ms);
            sim.healthy(now);
            sim.step(now, &mut events);
        }
        // The board answers once its set-up (about a second) is done.
        sim.step(Duration::from_secs(3), &mut events);
        let pongs = events
            .iter()
            .filter(|e| matches!(e, Event::Pong(_)))
            .count();
        assert_eq!(pongs, 2, "pings at 10 ms and 510 ms: {events:?}");
    }

    #[test]
    fn a_placed_vehicle_is_where_it_was_put() {
        let mut sim = BuiltinSim::new(EmulatorOptions::default(), Duration::ZERO);
        sim.place(12.0, 90.0);
        let t = sim.truth();
        assert!((t.depth_m - 12.0).abs() < 1e-9);
        assert!((t.heading_deg - 90.0).abs() < 1e-9);
    }
}
