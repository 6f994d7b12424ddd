//! The board emulator in the same process, without a pseudo-terminal: the
//! built-in simulator of run mode SIMULATOR and the closed-loop scenarios
//! that run on simulated time.
//!
//! Owns one sans-IO [`Board`] and a telemetry decoder, and moves bytes
//! between them and typed commands/events. It must never read a clock:
//! the caller passes the time, so a scenario runs as fast as the CPU allows
//! and gives the same result every time.

use std::time::Duration;

use super::codec::{self, Command, Event, Framing, LineDecoder};
use super::emulator::{Board, BoardSnapshot, EmulatorOptions};

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
