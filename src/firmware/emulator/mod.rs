//! Emulator of the 2015 OpenROV controller board, driving the simulator.
//!
//! [`Board`] (`board.rs`) is sans-IO: it takes the bytes the host wrote and
//! the current time, and produces the bytes the board would print; its
//! telemetry faults come from `faults.rs`. [`PtyBoard`] (`pty_board.rs`)
//! puts it behind a real pseudo-terminal, which is what `neptunus --sim`,
//! `neptunus emulate-board` and the tests use, so the serial link runs the
//! same code as on the ROV. This file holds the options and the figures
//! they share.
//!
//! Behaviour modelled on the board (see `reference/openrov-serial.md`):
//! - frames end at the first `;`; in `crc8` framing the first byte of a
//!   frame is the CRC-8 of the rest. Every frame is echoed as
//!   `rawcmd:<hex>,...,;`, then `crc:pass;` or `crc:fail,<calc>/<got>;`
//!   (failed frames are dropped), then `cmd:<text>;`;
//! - an 80-byte frame buffer (longer frames are dropped), at most 10
//!   integer arguments parsed with `atoi` semantics, a 5-slot command queue
//!   that drops the oldest with `log:CommandBufferOverrun;`;
//! - `go()` applied only when all three values are in 1000..=2000, a 50 µs
//!   deadzone around 1500 and a ×2 reverse multiplier on the ESC outputs;
//! - lights (`LIGT`/`LIGP`), laser (`claser`), camera tilt slewing 1 µs per
//!   millisecond, `boot:1;` at start, `CAPA:` for `rcap()`, `pong:` for
//!   `ping()`, and the dead-man switch: after `dms(1)` (or 180 s of uptime)
//!   two seconds without `ping` stop the motors until the next ping;
//! - navigation lines at 10 Hz and status lines at 1 Hz from the simulator.
//!
//! The simulator ([`crate::sim::Plant`]) is driven with the ESC outputs, as
//! on the vehicle: after the board's deadzone and its reverse multiplier
//! (which compensates for propellers that push less in reverse — the plant
//! models that), and neutral while the motors are detached, the ESCs are
//! powered off or the dead-man switch has tripped. The navigation line
//! reports the plant's readings: heading, 1 Hz depth, pitch and roll, with
//! the noise the options ask for.
//!
//! Fault injection (all off by default) reproduces what the thesis saw on
//! the real link: garbage bytes, torn lines, wild points, dropped lines and
//! a stalled board. The emulator counts what it injected so tests can check
//! the decoder's rejection counters against it.
//!
//! The emulator never decides anything on the host's behalf; it only
//! behaves like the hardware.

use serde::{Deserialize, Serialize};

use crate::firmware::codec::Framing;
use crate::sim::{SimOptions, SimState, Truth, thesis::wrap_deg_360};

mod board;
mod faults;
mod pty_board;

pub use board::{Board, CAPABILITIES, COMMAND_QUEUE_SLOTS, FRAME_BUFFER_BYTES, MAX_ARGS};
pub use pty_board::{BoardControl, PtyBoard};

/// Fault injection rates, each a probability per emitted telemetry line.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaultOptions {
    /// Random non-printable bytes in front of a line (line noise).
    pub garbage: f64,
    /// A line cut inside a value, or a value replaced by the next key's
    /// name (the thesis' heading reading `pitc`).
    pub torn: f64,
    /// One value multiplied by 0.1, 10 or 100.
    pub wild: f64,
    /// A line never sent.
    pub dropped: f64,
    /// Seed of the fault generator (the faults are reproducible).
    pub seed: u64,
}

impl FaultOptions {
    /// Whether any fault is enabled.
    pub fn any(&self) -> bool {
        self.garbage > 0.0 || self.torn > 0.0 || self.wild > 0.0 || self.dropped > 0.0
    }
}

/// How the emulated board is set up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmulatorOptions {
    pub framing: Framing,
    /// Deadzone around 1500 µs in which the ESCs get neutral.
    pub deadzone_us: u16,
    /// Multiplier on reverse thrust applied to the ESC outputs.
    pub reverse_multiplier: f64,
    /// Thruster directions [port, vertical, starboard] as wired on the
    /// vehicle (Neptunus' port thruster is wired reversed).
    pub wiring_directions: [i8; 3],
    pub nav_period_ms: u64,
    pub status_period_ms: u64,
    /// Firmware version printed in status lines.
    pub version: String,
    pub faults: FaultOptions,
    /// The simulated vehicle (`[emulator.sim]`).
    pub sim: SimOptions,
}

impl EmulatorOptions {
    /// The board with the thesis' ideal simulator, reproducing the emulator
    /// from before the plant existed: [`SimOptions::ideal_thesis`], and a
    /// reverse multiplier of 1 so the ESC outputs are the accepted `go()`
    /// values (the old emulator fed those to the physics, never the
    /// multiplied ones). For tests that check exact physics.
    pub fn ideal_thesis() -> Self {
        Self {
            reverse_multiplier: 1.0,
            sim: SimOptions::ideal_thesis(),
            ..Self::default()
        }
    }
}

impl Default for EmulatorOptions {
    fn default() -> Self {
        Self {
            framing: Framing::Crc8,
            deadzone_us: 50,
            reverse_multiplier: 2.0,
            wiring_directions: [-1, 1, 1],
            nav_period_ms: 100,
            status_period_ms: 1000,
            version: "30.0.3-neptunus-emu".into(),
            faults: FaultOptions::default(),
            sim: SimOptions::default(),
        }
    }
}

/// What the emulator injected, for checking the decoder's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FaultStats {
    pub lines_emitted: u64,
    pub garbage_bursts: u64,
    pub garbage_bytes: u64,
    pub torn_lines: u64,
    /// Wild points whose value left the physical range: the decoder must reject them.
    pub wild_out_of_range: u64,
    /// Wild points still inside the physical range: only an estimator can catch them.
    pub wild_in_range: u64,
    pub dropped_lines: u64,
}

impl FaultStats {
    /// Lines the host's decoder must reject.
    pub fn expected_rejections(&self) -> u64 {
        self.torn_lines + self.wild_out_of_range
    }
}

/// What the board received and did, for tests.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BoardRecord {
    /// A complete frame as received, CRC byte included, up to its `;`.
    Frame(Vec<u8>),
    /// A command executed, as the board tokenised it: `go(1500,1500,1500)`.
    Executed(String),
}

/// A [`BoardRecord`] with the moment the emulator task woke to handle the
/// bytes (or timer) that produced it. For a `Frame`, that is when the read
/// that completed the frame returned: as close to the pty as the emulator
/// gets, for latency measurements that must not include the delay of a
/// broadcast receiver being scheduled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TimedRecord {
    pub at: std::time::Instant,
    pub record: BoardRecord,
}

/// A snapshot of the board and the simulated vehicle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoardSnapshot {
    pub uptime_ms: u64,
    /// Last accepted `go()` values [port, vertical, starboard].
    pub target_us: [u16; 3],
    /// ESC outputs after deadzone and reverse multiplier.
    pub motors_us: [u16; 3],
    pub motors_attached: bool,
    pub dead_man_armed: bool,
    pub dead_man_tripped: bool,
    pub lights: u8,
    pub laser: u8,
    pub tilt_us: u16,
    pub tilt_target_us: u16,
    pub frames_ok: u64,
    pub crc_failures: u64,
    pub overruns: u64,
    pub stalled: bool,
    /// Every command executed, in order, as text (`go(1500,1500,1500)`).
    pub executed_total: u64,
    pub sim: SimSnapshot,
    pub faults: FaultStats,
}

/// Simulated vehicle state in plain units (the truth, not the readings).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SimSnapshot {
    pub north_m: f64,
    pub east_m: f64,
    pub depth_m: f64,
    /// Wrapped into `[0, 360)`.
    pub heading_deg: f64,
    pub surge_mps: f64,
    pub sway_mps: f64,
    pub heave_mps: f64,
    pub yaw_rate_dps: f64,
    /// 0 in the 4-DOF model.
    pub roll_deg: f64,
    /// Positive nose up; 0 in the 4-DOF model.
    pub pitch_deg: f64,
    /// `[port, vertical, starboard]` (N), positive forward / down.
    pub thrust_n: [f64; 3],
    /// 0 with the tether off.
    pub tether_length_m: f64,
}

impl From<&SimState> for SimSnapshot {
    /// A 4-DOF state: level, thrust and tether unknown (0).
    fn from(s: &SimState) -> Self {
        Self {
            north_m: s.eta[0],
            east_m: s.eta[1],
            depth_m: s.depth_m(),
            heading_deg: s.heading_deg(),
            surge_mps: s.nu[0],
            sway_mps: s.nu[1],
            heave_mps: s.nu[2],
            yaw_rate_dps: s.nu[3].to_degrees(),
            roll_deg: 0.0,
            pitch_deg: 0.0,
            thrust_n: [0.0; 3],
            tether_length_m: 0.0,
        }
    }
}

impl From<&Truth> for SimSnapshot {
    fn from(t: &Truth) -> Self {
        Self {
            north_m: t.north_m,
            east_m: t.east_m,
            depth_m: t.depth_m,
            heading_deg: wrap_deg_360(t.heading_rad.to_degrees()),
            surge_mps: t.surge_mps,
            sway_mps: t.sway_mps,
            heave_mps: t.heave_mps,
            yaw_rate_dps: t.yaw_rate_rps.to_degrees(),
            roll_deg: t.roll_rad.to_degrees(),
            pitch_deg: t.pitch_rad.to_degrees(),
            thrust_n: t.thrust_n,
            tether_length_m: t.tether_length_m,
        }
    }
}

/// Prints one line as the board does, ending in `\r\n` (the board and the
/// fault injector both write lines).
fn print(line: &str, out: &mut Vec<u8>) {
    out.extend_from_slice(line.as_bytes());
    out.extend_from_slice(b"\r\n");
}
