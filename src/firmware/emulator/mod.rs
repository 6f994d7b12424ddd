//! The OpenROV 2.x controller board, emulated: the twin of the genuine
//! board firmware (`openrov-software-arduino`, release 30.0.2 or the
//! December 2014 sketch), driving the simulator.
//!
//! - `sketch/`: the firmware's `setup()` and `loop()` re-told in Rust —
//!   the frame buffer and its echo, the internal command queue, every
//!   device in registration order with its `Timer`s, the status cycle and
//!   the navigation line — on a modelled clock (the cost of a pass, the
//!   `delay()`s, prints waiting for the transmit buffer). `arduino.rs`:
//!   the Arduino core's number printing and arithmetic. `uart.rs`: the
//!   serial port at 115200 baud, its 64-byte receive ring and transmit
//!   buffer.
//! - [`Board`] (`board.rs`) is sans-IO: the bytes the host wrote and the
//!   time in, the bytes the board prints out; it wires the sketch to the
//!   simulator and to the fault injector (`faults.rs`).
//! - [`PtyBoard`] (`pty_board.rs`) puts it behind a real pseudo-terminal,
//!   which is what `neptunus --sim`, `neptunus emulate-board` and the tests
//!   use, so the serial link runs the same code as on the ROV.
//!
//! This file holds the options and the figures they share.
//!
//! # What it imitates
//! For the same bytes in, it prints what the genuine firmware prints,
//! modulo sensor values and timing:
//! - the set-up chatter of a board whose MPU-9150 and MS5803-14BA answer
//!   (the default, [`FittedSensors`]; "Loading firmware", `log:init on
//!   primary addresses;`, the depth sensor's PROM words) or do not (the
//!   firmware's "not found" chatter, zeros for their readings), the BNO055
//!   never found (as on a 2.5–2.7 board; 30.0.2 probes it again every
//!   30 s), then `boot:1;`;
//! - the echo of every frame: in 30.0.2 `rawcmd:` with each byte in upper-
//!   case hex, then `crc:pass;` or `crc:fail,<calc>/<got>;` in hex with no
//!   line end (a failed frame stops there), then `cmd:name(args);` with
//!   each argument as it was typed; in 2014-12 the `cmd:` line alone. An
//!   unknown command is echoed and does nothing. A command is matched by
//!   prefix (`gox(…)` is a `go`), arguments are `atoi`'d;
//! - the 80-byte frame buffer (a longer frame loses the byte that found it
//!   full and goes on from the buffer's start) and the 63 bytes the
//!   receive ring holds while the sketch is busy;
//! - the internal command queue (four waiting at most; the oldest is lost
//!   with `log: CommandBufferOverrun;`), its `icmd:` echo, one command a
//!   pass, a serial frame first;
//! - each device's replies: `LIGT`/`LIGP`, `claser:n;` (no line end),
//!   `CAPA:` then the I2C scan's logs and a 5 s `delay` in which the board
//!   reads nothing, `pong:<argument count>,<millis>;` (no line end),
//!   `log:escpower=`, `*settings:`, `mtrmod:`, `dtwa:`, the pilot's hold
//!   lines, `asr.t`/`asr.v`, `LIGTE`/`LIGPE`;
//! - the thrusters as `Thrusters2X1.cpp` and `Motor.cpp` do them: `go()`
//!   taken when all three lie in 1000..2000, `thro`/`yaw`/`lift` mixed on
//!   the board in single precision, and each ESC pulse from `goms()`:
//!   the modifier truncated to an `int`, constrained, then mapped around
//!   the deadzone (`go(1600)` → 1640, `go(1400)` → 1270). The pulses are
//!   written, and `motors:` printed, at most every 50 ms when they change;
//! - the dead-man switch: armed by `dms(…)` with any argument, disarmed by
//!   `dms()`, armed anyway after 180 s; 2 s without `ping` pushes
//!   `deptloff`, `headloff` and `stop`, the lights blink through pushed
//!   `ligt` every 500 ms, `go()` is still obeyed, and the next `ping`
//!   pushes `start`;
//! - the status cycle as the firmware's separate lines — `motorAttached`,
//!   `servo`/`starg`, the `fmem`…`cmpd` line broken before its `;`, which
//!   opens the `;time:` line, `pres`/`temp`, `dlms`, `alps` — the
//!   `BRDT`…`AVCC` line, `mtarg` and (30.0.2) `mtrmod` each second, and
//!   the navigation line (`hdgd`, `deap`, …) every 100 ms; numbers as the
//!   Arduino prints floats; `ver:CUSTOM_BUILD`.
//!
//! The simulator ([`crate::sim::Plant`]) is driven with the ESC pulses the
//! sketch writes (nothing while `escp(0)` has the ESCs unpowered), and the
//! sketch reads it as the board's sensors and ADC: heading, pitch and roll
//! from the IMU every 50 ms, depth, pressure and temperature once a second,
//! battery voltage and currents (split between the two battery tubes,
//! `BT1I`/`BT2I`) through the ADC's 10 bits.
//!
//! Not imitated: a BNO055 that answers, `ccal()`'s `dia:` lines (they come
//! from raw magnetometer data the simulator does not have), arguments
//! after the ninth (the firmware writes them past its array), the
//! watchdog and the EEPROM. `cmpd:` is a plausible stamp of the release's
//! build, `fmem:` the genuine build's figure; the times a pass, the MPU's
//! set-up and the I2C traffic take are estimates.
//!
//! # How it was verified
//! `tests/genuine_twin.rs` sends one scripted session to the genuine
//! firmware running in simavr (feature `hil`) and to this emulator, for
//! both releases, and compares the outputs item by item: set-up chatter
//! and replies exactly, line breaks included; `motors:` values; the
//! blinking; and the shape and rate of every periodic line. simavr has no
//! I2C devices, so that test runs the sensor-less board; the sensor chatter
//! is read from the firmware's source.
//!
//! Fault injection (all off by default) reproduces what the thesis saw on
//! the real link: garbage bytes, torn lines, wild points, dropped lines and
//! a stalled board. It touches the periodic lines that end in `;` (not the
//! broken `cmpd` line and its `;time:` continuation, nor replies). The
//! emulator counts what it injected so tests can check the decoder's
//! rejection counters against it.
//!
//! The emulator never decides anything on the host's behalf; it only
//! behaves like the hardware.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::firmware::codec::Framing;
use crate::sim::{SimOptions, SimState, Truth, thesis::wrap_deg_360};

mod arduino;
mod board;
mod faults;
mod pty_board;
mod sketch;
mod uart;

pub use board::{Board, COMMAND_QUEUE_SLOTS, FRAME_BUFFER_BYTES, MAX_ARGS};
pub use pty_board::{BoardControl, PtyBoard};

/// Which release of the genuine firmware the emulator imitates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum FirmwareVersion {
    /// Tag 30.0.2 (31 Aug 2015): CRC-8 framing with the `rawcmd:`/`crc:`
    /// echo, the alternative servo, the BNO055 probe, `mtrmod:` each second.
    #[default]
    #[serde(rename = "30.0.2")]
    V30_0_2,
    /// The December 2014 sketch (v2.5.1): plain framing, `cmd:` echo only.
    #[serde(rename = "2014-12")]
    V2014_12,
}

impl FirmwareVersion {
    /// The framing this release speaks.
    pub fn framing(self) -> Framing {
        match self {
            Self::V30_0_2 => Framing::Crc8,
            Self::V2014_12 => Framing::Plain,
        }
    }
}

impl fmt::Display for FirmwareVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::V30_0_2 => "30.0.2",
            Self::V2014_12 => "2014-12",
        })
    }
}

/// A firmware name that is neither `30.0.2` nor `2014-12`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown board firmware {0:?} — use \"30.0.2\" (2015, crc8 framing) or \"2014-12\" \
     (December 2014, plain framing)"
)]
pub struct ParseFirmwareError(pub String);

impl FromStr for FirmwareVersion {
    type Err = ParseFirmwareError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "30.0.2" => Ok(Self::V30_0_2),
            "2014-12" => Ok(Self::V2014_12),
            other => Err(ParseFirmwareError(other.to_owned())),
        }
    }
}

/// The I2C sensors on the emulated board (the OpenROV 2.x IMU/depth
/// module). Absent, the firmware prints what it prints when a probe finds
/// nothing, and reports zeros.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FittedSensors {
    /// The MPU-9150 IMU (heading, pitch, roll).
    pub mpu9150: bool,
    /// The MS5803-14BA pressure sensor (depth, pressure, water temperature).
    pub ms5803: bool,
}

impl FittedSensors {
    /// Neither sensor: the genuine firmware in simavr, which has no I2C
    /// devices, prints this board's chatter.
    pub fn none() -> Self {
        Self {
            mpu9150: false,
            ms5803: false,
        }
    }
}

impl Default for FittedSensors {
    fn default() -> Self {
        Self {
            mpu9150: true,
            ms5803: true,
        }
    }
}

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
    /// The framing the board speaks. `plain` means the 2014-12 firmware
    /// (no 30.0.2 build speaks it); see [`EmulatorOptions::imitated`].
    pub framing: Framing,
    /// Which firmware release the board runs (`"30.0.2"` or `"2014-12"`).
    pub firmware: FirmwareVersion,
    /// Which I2C sensors the board has.
    pub sensors: FittedSensors,
    /// The firmware's `deadZone_min`/`deadZone_max` (µs): the ESC pulses
    /// skip this far from 1500 µs (`Motor::goms` maps around it).
    pub deadzone_us: u16,
    /// The motors' `motor_negative_modifer`: reverse targets are pushed
    /// this many times further from 1500 µs. The firmware truncates it to
    /// an `int` (2.5 acts as 2).
    pub reverse_multiplier: f64,
    /// Thruster directions [port, vertical, starboard] as wired on the
    /// vehicle (Neptunus' port thruster is wired reversed).
    pub wiring_directions: [i8; 3],
    /// The navigation line's `Timer` period (it fires after more than this).
    pub nav_period_ms: u64,
    /// The status cycle's `Timer` period.
    pub status_period_ms: u64,
    /// What the status cycle prints after `ver:`.
    pub version: String,
    pub faults: FaultOptions,
    /// The simulated vehicle (`[emulator.sim]`).
    pub sim: SimOptions,
}

impl EmulatorOptions {
    /// The board with the thesis' ideal simulator, reproducing the emulator
    /// from before the plant existed: [`SimOptions::ideal_thesis`], no
    /// deadzone and a reverse multiplier of 1, so the ESC outputs are the
    /// accepted `go()` values (the old emulator fed those to the physics).
    /// For tests that check exact physics.
    pub fn ideal_thesis() -> Self {
        Self {
            deadzone_us: 0,
            reverse_multiplier: 1.0,
            sim: SimOptions::ideal_thesis(),
            ..Self::default()
        }
    }

    /// The firmware the board runs: [`EmulatorOptions::firmware`], except
    /// that `plain` framing can only be the 2014-12 release.
    pub fn imitated(&self) -> FirmwareVersion {
        if self.framing == Framing::Plain {
            FirmwareVersion::V2014_12
        } else {
            self.firmware
        }
    }

    /// The framing the board speaks (its firmware's).
    pub fn effective_framing(&self) -> Framing {
        self.imitated().framing()
    }
}

impl Default for EmulatorOptions {
    fn default() -> Self {
        Self {
            framing: Framing::Crc8,
            firmware: FirmwareVersion::default(),
            sensors: FittedSensors::default(),
            deadzone_us: 50,
            reverse_multiplier: 2.0,
            wiring_directions: [-1, 1, 1],
            nav_period_ms: 100,
            status_period_ms: 1000,
            version: "CUSTOM_BUILD".into(),
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
    /// A complete frame as the board parsed it, CRC byte included, up to
    /// its `;` (the tail of one that outgrew the frame buffer).
    Frame(Vec<u8>),
    /// A host command the board parsed (its CRC passed), as it tokenised
    /// it: `go(1500,1500,1500)` (the arguments `atoi`'d). Commands from the
    /// board's own queue (`icmd:`) are not recorded.
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
    /// The thrusters' targets [port, vertical, starboard]: the last valid
    /// `go()`, or what `thro`/`yaw`/`lift`/`stop` made of them.
    pub target_us: [u16; 3],
    /// The ESC pulses (`Motor::goms` of the targets, written at most every
    /// 50 ms when they change).
    pub motors_us: [u16; 3],
    pub motors_attached: bool,
    /// The ESCs' power switch (`escp`).
    pub escs_powered: bool,
    pub dead_man_armed: bool,
    pub dead_man_tripped: bool,
    pub lights: u8,
    pub laser: u8,
    pub tilt_us: u16,
    pub tilt_target_us: u16,
    pub frames_ok: u64,
    pub crc_failures: u64,
    /// `log: CommandBufferOverrun;`: internal commands lost.
    pub overruns: u64,
    /// Host bytes lost to a full receive ring.
    pub rx_lost: u64,
    pub stalled: bool,
    /// Host commands parsed (after a CRC pass), as counted by
    /// [`BoardRecord::Executed`].
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
