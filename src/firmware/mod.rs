//! The OpenROV 2.x controller board: its serial protocol and everything that
//! talks it.
//!
//! - [`codec`]: sans-IO encoding of commands and decoding of telemetry lines.
//! - [`link`]: the task that owns the serial device (handshake, keep-alive,
//!   coalescing and pacing of commands, reconnection): the decisions in a
//!   sans-IO session, the device and channels in an I/O loop around it.
//! - [`emulator`]: a byte-exact emulator of the 2015 board driving the
//!   simulator, used by `--sim`, `emulate-board` and the tests: a sans-IO
//!   board, and the pty task that runs it.
//! - [`pty`]: pseudo-terminal helpers so the emulator sits behind a real tty.
//!
//! Nothing here decides whether a thruster may move: that is the vehicle
//! core's job. This module only moves bytes faithfully.

pub mod codec;
pub mod emulator;
pub mod link;
pub mod loopback;
pub mod pty;
