//! Sans-IO codec for the OpenROV board's serial protocol.
//!
//! Host → board: `name(arg,...);` ASCII commands, optionally preceded by a
//! Dallas/Maxim CRC-8 byte (`crc8` framing, 2015 firmware) or plain (`plain`
//! framing, December 2014 firmware).
//! Board → host: `\r\n`-terminated lines of `key:value;` pairs, decoded into
//! typed [`Event`]s by [`LineDecoder`].
//!
//! This module owns the byte-exact format and the first line of defence
//! against garbage: a value that is not a number or lies outside the
//! physical range of its sensor is counted and dropped here, never passed on.
//! It never does I/O, never reads a clock, never panics on any input and never
//! decides whether a command is safe to send (that is the vehicle core's job:
//! [`encode`] writes whatever it is given).
//!
//! # Decoding rules
//! - A line ends at `\n`; one `\r` right before it is stripped. Empty lines
//!   are ignored and not counted.
//! - Any byte that is neither printable ASCII (0x20..=0x7E) nor `\r`/`\n` is
//!   garbage: it is counted in [`DecodeStats::garbage_bytes`] and the partial
//!   line collected so far is discarded, because a line with noise inside
//!   cannot be trusted. The bytes after the noise start a fresh line; this is
//!   how the decoder resyncs after line noise. A `\r` anywhere but at the end
//!   makes the line [`RejectReason::Torn`].
//! - A line longer than [`MAX_LINE_BYTES`] (not counting `\r\n`) is counted
//!   once as [`RejectReason::Overlong`] and its bytes are dropped up to the
//!   next `\n`, garbage included. The decoder never buffers more than
//!   `MAX_LINE_BYTES + 1` bytes.
//! - A line is a sequence of `key:value;` pairs. Each pair splits at its first
//!   `:` (values such as `cmd:go(1,2,3)` or `crc:fail,12/34` hold commas and
//!   parentheses). Empty segments (from `;;`) are ignored.
//! - The whole line is rejected as [`RejectReason::Torn`] if it does not end
//!   with `;`, if a non-empty segment has no `:`, or if a key is empty.
//! - Numeric keys must hold a number inside the key's physical range
//!   ([`physical_range`]), else the whole line is rejected as
//!   [`RejectReason::NonNumeric`] or [`RejectReason::OutOfRange`]. Real-valued
//!   keys accept an optional sign, digits and at most one `.` (what the
//!   Arduino prints), so `1e5`, `inf`, `nan`, ` 1` and `pitc` are non-numeric.
//!   Integer keys (`time`, `fmem`, `motorAttached`, `servo`, `starg`,
//!   `mtarg`, `motors`, `CAPA`, `LIGT`, `claser`) accept an optional `-` and
//!   digits only. `mtarg`/`motors` hold exactly three comma-separated
//!   integers. A number too large to represent is out of range.
//! - A rejected line emits nothing at all and is counted once, with the first
//!   reason found reading left to right (a missing final `;` is found first).
//! - `ver` goes into [`StatusSample::version`]; `cmpd`, `BRDT`, `BRDI`,
//!   `BRDV`, `SC1I`, `SC2I`, `SC3I`, `BT1I`, `BT2I` and `AVCC` are known and
//!   ignored without being parsed. Any other key is counted in
//!   [`DecodeStats::unknown_keys`] (only for accepted lines) and ignored; the
//!   line is still accepted.
//! - Event keys: `boot` → [`Event::Boot`] (any value), `CAPA` →
//!   [`Event::Capabilities`], `crc` → `pass` / `fail,<calc>/<got>` (decimal,
//!   each 0..=255), `cmd` → [`Event::CmdEcho`], `rawcmd` → [`Event::RawCmd`],
//!   `pong` → [`Event::Pong`], `log` → [`Event::Log`] (text values verbatim),
//!   `LIGT` → [`Event::Lights`] with the fraction from a `LIGP` anywhere on
//!   the same line (a `LIGP` without `LIGT` is range-checked and otherwise
//!   ignored),
//!   `claser` → [`Event::Laser`].
//! - An accepted line emits, in order: [`Event::Nav`] if any nav key is
//!   present, [`Event::Status`] if any status key is present, then the event
//!   keys in line order. When a key repeats on a line, the last value wins.

use std::fmt;
use std::str::FromStr;

/// Longest board line accepted, not counting `\r\n`. The board's longest
/// real lines (status with all sensors) are well under 200 bytes; anything
/// far longer is two lines whose terminator was lost.
pub const MAX_LINE_BYTES: usize = 512;

/// The board ends a frame at the first `;`, so a CRC byte with this value
/// would end the frame before its text.
const FRAME_END: u8 = b';';

// ---------------------------------------------------------------------------
// Framing
// ---------------------------------------------------------------------------

/// How commands are framed on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Framing {
    /// One raw CRC-8 byte before each command (firmware from March 2015 on).
    #[default]
    Crc8,
    /// The text alone (December 2014 firmware v2.5.1).
    Plain,
}

/// A framing name that is neither `crc8` nor `plain`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown serial framing {0:?} — use \"crc8\" (OpenROV firmware from March 2015 on) \
     or \"plain\" (December 2014 firmware v2.5.1)"
)]
pub struct ParseFramingError(pub String);

impl FromStr for Framing {
    type Err = ParseFramingError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "crc8" => Ok(Self::Crc8),
            "plain" => Ok(Self::Plain),
            other => Err(ParseFramingError(other.to_owned())),
        }
    }
}

impl fmt::Display for Framing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Crc8 => "crc8",
            Self::Plain => "plain",
        })
    }
}

// ---------------------------------------------------------------------------
// Commands (host → board)
// ---------------------------------------------------------------------------

/// One command to the board. Arguments are written as given: checking that
/// they are safe belongs to the vehicle core, not to the wire format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// `go(p,v,s);` thruster pulse widths: port, vertical, starboard.
    Go {
        port_us: u16,
        vertical_us: u16,
        starboard_us: u16,
    },
    /// `stop();` all thrusters to neutral.
    Stop,
    /// `start();` re-attaches the motor outputs.
    Start,
    /// `ligt(n);` lights PWM 0..255.
    Lights(u8),
    /// `claser(n);` calibration lasers.
    Laser(u8),
    /// `tilt(us);` camera tilt servo.
    Tilt(u16),
    /// `escp(0|1);` ESC power.
    EscPower(bool),
    /// `ping(n);` resets the board's dead-man timer.
    Ping(u32),
    /// `dms(0|1);` disarms/arms the board's dead-man switch.
    DeadMan(bool),
    /// `dzer();` zero the depth (2015 firmware).
    DepthZero,
    /// `depth_zero();` zero the depth (2016+ firmware).
    DepthZero2016,
    /// `rcap();` ask for the capability bitmask (blocks the board ~5 s).
    Capabilities,
    /// `thro(n);` -100..100, mixed by the board.
    Throttle(i8),
    /// `yaw(n);` -100..100, mixed by the board.
    Yaw(i8),
    /// `lift(n);` -100..100, mixed by the board.
    Lift(i8),
}

impl Command {
    /// The command's name as the board knows it.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Go { .. } => "go",
            Self::Stop => "stop",
            Self::Start => "start",
            Self::Lights(_) => "ligt",
            Self::Laser(_) => "claser",
            Self::Tilt(_) => "tilt",
            Self::EscPower(_) => "escp",
            Self::Ping(_) => "ping",
            Self::DeadMan(_) => "dms",
            Self::DepthZero => "dzer",
            Self::DepthZero2016 => "depth_zero",
            Self::Capabilities => "rcap",
            Self::Throttle(_) => "thro",
            Self::Yaw(_) => "yaw",
            Self::Lift(_) => "lift",
        }
    }

    /// Whether the command moves (or stops) thrusters; the link coalesces
    /// these so that only the newest is ever sent.
    pub fn is_thrust(&self) -> bool {
        matches!(
            self,
            Self::Go { .. } | Self::Stop | Self::Throttle(_) | Self::Yaw(_) | Self::Lift(_)
        )
    }

    /// Appends the command's text, e.g. `go(1500,1500,1500);` or `stop();`.
    pub fn write_text(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(self.name().as_bytes());
        out.push(b'(');
        match *self {
            Self::Go {
                port_us,
                vertical_us,
                starboard_us,
            } => {
                write_int(out, port_us.into());
                out.push(b',');
                write_int(out, vertical_us.into());
                out.push(b',');
                write_int(out, starboard_us.into());
            }
            Self::Stop
            | Self::Start
            | Self::DepthZero
            | Self::DepthZero2016
            | Self::Capabilities => {}
            Self::Lights(n) | Self::Laser(n) => write_int(out, n.into()),
            Self::Tilt(us) => write_int(out, us.into()),
            Self::EscPower(on) | Self::DeadMan(on) => write_int(out, i64::from(on)),
            Self::Ping(n) => write_int(out, n.into()),
            Self::Throttle(n) | Self::Yaw(n) | Self::Lift(n) => write_int(out, n.into()),
        }
        out.extend_from_slice(b");");
    }
}

/// Decimal without going through `fmt`, which would need an `io::Write`
/// result to be handled for a write into a `Vec` that cannot fail.
fn write_int(out: &mut Vec<u8>, n: i64) {
    if n < 0 {
        out.push(b'-');
    }
    let mut magnitude = n.unsigned_abs();
    let mut digits = [0u8; 20];
    let mut start = digits.len();
    loop {
        start -= 1;
        // `% 10` is below 10, so the cast cannot truncate.
        digits[start] = b'0' + (magnitude % 10) as u8;
        magnitude /= 10;
        if magnitude == 0 {
            break;
        }
    }
    out.extend_from_slice(&digits[start..]);
}

const CRC8_TABLE: [u8; 256] = crc8_table();

const fn crc8_table() -> [u8; 256] {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = i as u8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0x8C
            } else {
                crc >> 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

/// Dallas/Maxim 1-Wire CRC-8: reflected polynomial 0x8C, init 0.
pub fn crc8(data: &[u8]) -> u8 {
    data.iter()
        .fold(0u8, |crc, &b| CRC8_TABLE[usize::from(crc ^ b)])
}

/// Appends one frame. `Crc8`: `[crc byte][text]`; if the CRC would be 0x3B
/// (`;`, which the board takes as end of frame) a space is inserted before
/// the closing `)` and the CRC recomputed, repeating until it is not 0x3B
/// (the board tokenises on spaces, so the meaning is unchanged). `Plain`:
/// just the text.
pub fn encode(cmd: &Command, framing: Framing, out: &mut Vec<u8>) {
    match framing {
        Framing::Plain => cmd.write_text(out),
        Framing::Crc8 => {
            let crc_at = out.len();
            out.push(0);
            cmd.write_text(out);
            let mut crc = crc8(&out[crc_at + 1..]);
            // Terminates after at most one extra space: the CRC update with a
            // space byte has no fixed point (checked exhaustively in
            // tests/firmware_codec.rs), so the state after one more space
            // differs, and so does the CRC over the unchanged `);` tail.
            while crc == FRAME_END {
                // The text always ends in `);`.
                let close_paren = out.len() - 2;
                out.insert(close_paren, b' ');
                crc = crc8(&out[crc_at + 1..]);
            }
            out[crc_at] = crc;
        }
    }
}

/// [`encode`] into a fresh buffer.
pub fn encoded(cmd: &Command, framing: Framing) -> Vec<u8> {
    let mut out = Vec::with_capacity(24);
    encode(cmd, framing, &mut out);
    out
}

// ---------------------------------------------------------------------------
// Telemetry (board → host)
// ---------------------------------------------------------------------------

/// The navigation line (10 Hz). Fields absent from the line are `None`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NavSample {
    /// `hdgd`, 0..360.
    pub heading_deg: Option<f64>,
    /// `deep` (or `deap` before March 2015), -10..200.
    pub depth_m: Option<f64>,
    /// `pitc`, -180..180.
    pub pitch_deg: Option<f64>,
    /// `roll`, -180..180.
    pub roll_deg: Option<f64>,
    /// `yaw` (raw), -180..180.
    pub yaw_deg: Option<f64>,
    /// `fthr` forward thrust, -100..100 %.
    pub fthr_pct: Option<f64>,
}

/// The status line (1 Hz). Fields absent from the line are `None`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StatusSample {
    /// `vout` supply voltage, 0..30.
    pub vout_v: Option<f64>,
    /// `iout` board current, 0..20.
    pub iout_a: Option<f64>,
    /// `btti` battery current, 0..20.
    pub btti_a: Option<f64>,
    /// `pres` pressure, 0..30000.
    pub pres_mbar: Option<f64>,
    /// `temp` water temperature, -10..60.
    pub temp_c: Option<f64>,
    /// `time` board uptime, 0..=2^32.
    pub time_ms: Option<u64>,
    /// `fmem` free RAM, 0..65535.
    pub fmem_bytes: Option<u32>,
    /// `motorAttached` 0/1.
    pub motor_attached: Option<bool>,
    /// `servo` tilt servo current pulse width, 500..2500.
    pub servo_us: Option<u16>,
    /// `starg` tilt servo target pulse width, 500..2500.
    pub starg_us: Option<u16>,
    /// `mtarg` motor targets (port, vertical, starboard), each 500..2500.
    pub mtarg_us: Option<[u16; 3]>,
    /// `motors` actual motor outputs, each 500..2500.
    pub motors_us: Option<[u16; 3]>,
    /// `ver` firmware version text.
    pub version: Option<String>,
}

/// One thing the board said.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// Navigation keys of one line.
    Nav(NavSample),
    /// Status keys of one line.
    Status(StatusSample),
    /// `boot:1;`
    Boot,
    /// `CAPA:<bitmask>;`
    Capabilities(u32),
    /// `crc:pass;`
    CrcPass,
    /// `crc:fail,<calc>/<got>;`
    CrcFail { calc: u8, got: u8 },
    /// `cmd:<text>;` the board's echo of a command it accepted.
    CmdEcho(String),
    /// `rawcmd:<hex>,;` the bytes the board received, verbatim.
    RawCmd(String),
    /// `pong:<anything>;`
    Pong(String),
    /// `LIGT:n;` with `LIGP:fraction;` from the same line.
    Lights { level: u8, fraction: Option<f64> },
    /// `claser:n;`
    Laser(u8),
    /// `log:<text>;`
    Log(String),
}

/// Why a whole line was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RejectReason {
    /// Not a clean sequence of `key:value;` pairs (lost bytes, merged lines).
    Torn,
    /// Longer than [`MAX_LINE_BYTES`].
    Overlong,
    /// A numeric key whose value is not a plain decimal number.
    NonNumeric,
    /// A numeric key whose value lies outside its physical range.
    OutOfRange,
}

/// Counters kept by a [`LineDecoder`].
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct DecodeStats {
    pub lines_accepted: u64,
    pub rejected_torn: u64,
    pub rejected_overlong: u64,
    pub rejected_non_numeric: u64,
    pub rejected_out_of_range: u64,
    /// Keys this decoder does not know, in accepted lines.
    pub unknown_keys: u64,
    /// Bytes that are neither printable ASCII nor a line terminator.
    pub garbage_bytes: u64,
}

impl DecodeStats {
    /// Lines rejected for any reason.
    pub fn rejected_total(&self) -> u64 {
        self.rejected_torn
            + self.rejected_overlong
            + self.rejected_non_numeric
            + self.rejected_out_of_range
    }

    /// Lines rejected for `reason`.
    pub fn rejected(&self, reason: RejectReason) -> u64 {
        match reason {
            RejectReason::Torn => self.rejected_torn,
            RejectReason::Overlong => self.rejected_overlong,
            RejectReason::NonNumeric => self.rejected_non_numeric,
            RejectReason::OutOfRange => self.rejected_out_of_range,
        }
    }

    fn count_rejected(&mut self, reason: RejectReason) {
        let counter = match reason {
            RejectReason::Torn => &mut self.rejected_torn,
            RejectReason::Overlong => &mut self.rejected_overlong,
            RejectReason::NonNumeric => &mut self.rejected_non_numeric,
            RejectReason::OutOfRange => &mut self.rejected_out_of_range,
        };
        *counter += 1;
    }
}

// Physical ranges, inclusive. One source of truth for the decoder and for
// `physical_range`, which tests and the emulator use.
const HEADING_DEG: (f64, f64) = (0.0, 360.0);
const DEPTH_M: (f64, f64) = (-10.0, 200.0);
const ANGLE_DEG: (f64, f64) = (-180.0, 180.0);
const FTHR_PCT: (f64, f64) = (-100.0, 100.0);
const VOUT_V: (f64, f64) = (0.0, 30.0);
const CURRENT_A: (f64, f64) = (0.0, 20.0);
const PRES_MBAR: (f64, f64) = (0.0, 30_000.0);
const TEMP_C: (f64, f64) = (-10.0, 60.0);
const TIME_MS: (f64, f64) = (0.0, 4_294_967_296.0);
const FMEM_BYTES: (f64, f64) = (0.0, 65_535.0);
const FLAG: (f64, f64) = (0.0, 1.0);
const PULSE_US: (f64, f64) = (500.0, 2500.0);
const BYTE: (f64, f64) = (0.0, 255.0);
const FRACTION: (f64, f64) = (0.0, 1.0);

/// Physical range of a numeric key, inclusive, or `None` for non-range keys.
/// For `mtarg`/`motors` it is the range of each of the three values.
pub fn physical_range(key: &str) -> Option<(f64, f64)> {
    Some(match key {
        "hdgd" => HEADING_DEG,
        "deep" | "deap" => DEPTH_M,
        "pitc" | "roll" | "yaw" => ANGLE_DEG,
        "fthr" => FTHR_PCT,
        "vout" => VOUT_V,
        "iout" | "btti" => CURRENT_A,
        "pres" => PRES_MBAR,
        "temp" => TEMP_C,
        "time" => TIME_MS,
        "fmem" => FMEM_BYTES,
        "motorAttached" => FLAG,
        "servo" | "starg" | "mtarg" | "motors" => PULSE_US,
        "CAPA" | "LIGT" | "claser" => BYTE,
        "LIGP" => FRACTION,
        _ => return None,
    })
}

/// Turns board bytes, in any chunking, into [`Event`]s.
#[derive(Debug, Default)]
pub struct LineDecoder {
    /// The line being collected; never longer than `MAX_LINE_BYTES + 1`
    /// (the `+ 1` leaves room for the `\r` of a maximal line).
    line: Vec<u8>,
    /// Dropping the rest of an overlong line up to its `\n`.
    skipping_overlong: bool,
    /// Events of the line being decoded, held back until the whole line is
    /// known to be good; kept to reuse its allocation.
    pending: Vec<Event>,
    stats: DecodeStats,
}

impl LineDecoder {
    pub fn new() -> Self {
        Self {
            line: Vec::with_capacity(MAX_LINE_BYTES + 1),
            ..Self::default()
        }
    }

    /// Feeds raw bytes (any chunking); appends decoded events to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Event>) {
        let mut rest = bytes;
        while !rest.is_empty() {
            // Take the run of line bytes in one go: the common case is a
            // whole clean line per scan.
            let run = rest
                .iter()
                .position(|&b| !is_line_byte(b))
                .unwrap_or(rest.len());
            if run > 0 {
                self.take_line_bytes(&rest[..run]);
                rest = &rest[run..];
                continue;
            }
            let b = rest[0];
            rest = &rest[1..];
            if b == b'\n' {
                self.end_line(out);
            } else {
                self.stats.garbage_bytes += 1;
                // The rest of an overlong line is dropped up to its `\n`
                // whatever it holds, so noise does not end the skipping.
                self.line.clear();
            }
        }
    }

    /// Counters since this decoder was made.
    pub fn stats(&self) -> &DecodeStats {
        &self.stats
    }

    fn take_line_bytes(&mut self, run: &[u8]) {
        if self.skipping_overlong {
            return;
        }
        if self.line.len() + run.len() > MAX_LINE_BYTES + 1 {
            self.stats.count_rejected(RejectReason::Overlong);
            self.skipping_overlong = true;
            self.line.clear();
        } else {
            self.line.extend_from_slice(run);
        }
    }

    fn end_line(&mut self, out: &mut Vec<Event>) {
        if self.skipping_overlong {
            self.skipping_overlong = false;
            self.line.clear();
            return;
        }
        let text = self.line.strip_suffix(b"\r").unwrap_or(&self.line);
        if text.len() > MAX_LINE_BYTES {
            self.stats.count_rejected(RejectReason::Overlong);
        } else if !text.is_empty() {
            self.pending.clear();
            match decode_line(text, &mut self.pending) {
                Ok(line) => {
                    self.stats.lines_accepted += 1;
                    self.stats.unknown_keys += line.unknown_keys;
                    if let Some(nav) = line.nav {
                        out.push(Event::Nav(nav));
                    }
                    if let Some(status) = line.status {
                        out.push(Event::Status(status));
                    }
                    out.append(&mut self.pending);
                }
                Err(reason) => self.stats.count_rejected(reason),
            }
        }
        self.line.clear();
    }
}

/// Printable ASCII or `\r`: bytes that may belong to a line.
fn is_line_byte(b: u8) -> bool {
    matches!(b, 0x20..=0x7E | b'\r')
}

/// What one accepted line held besides its event keys.
struct DecodedLine {
    nav: Option<NavSample>,
    status: Option<StatusSample>,
    unknown_keys: u64,
}

/// Decodes one line without its terminator; event keys go to `events`,
/// which the caller discards if this fails.
fn decode_line(text: &[u8], events: &mut Vec<Event>) -> Result<DecodedLine, RejectReason> {
    use RejectReason::{OutOfRange, Torn};

    let body = text.strip_suffix(b";").ok_or(Torn)?;
    // Only a `\r` right before the `\n` is a terminator; one inside means
    // two lines ran into each other.
    if body.contains(&b'\r') {
        return Err(Torn);
    }
    let mut nav = NavSample::default();
    let mut status = StatusSample::default();
    let mut unknown_keys = 0;
    let mut lights_at: Option<usize> = None;
    let mut lone_fraction: Option<f64> = None;

    for segment in body.split(|&b| b == b';') {
        if segment.is_empty() {
            continue;
        }
        let colon = segment.iter().position(|&b| b == b':').ok_or(Torn)?;
        let (key, value) = (&segment[..colon], &segment[colon + 1..]);
        if key.is_empty() {
            return Err(Torn);
        }
        match key {
            b"hdgd" => nav.heading_deg = Some(real(value, HEADING_DEG)?),
            b"deep" | b"deap" => nav.depth_m = Some(real(value, DEPTH_M)?),
            b"pitc" => nav.pitch_deg = Some(real(value, ANGLE_DEG)?),
            b"roll" => nav.roll_deg = Some(real(value, ANGLE_DEG)?),
            b"yaw" => nav.yaw_deg = Some(real(value, ANGLE_DEG)?),
            b"fthr" => nav.fthr_pct = Some(real(value, FTHR_PCT)?),
            b"vout" => status.vout_v = Some(real(value, VOUT_V)?),
            b"iout" => status.iout_a = Some(real(value, CURRENT_A)?),
            b"btti" => status.btti_a = Some(real(value, CURRENT_A)?),
            b"pres" => status.pres_mbar = Some(real(value, PRES_MBAR)?),
            b"temp" => status.temp_c = Some(real(value, TEMP_C)?),
            b"time" => {
                status.time_ms = Some(int(value, TIME_MS)?.try_into().map_err(|_| OutOfRange)?)
            }
            b"fmem" => {
                status.fmem_bytes =
                    Some(int(value, FMEM_BYTES)?.try_into().map_err(|_| OutOfRange)?)
            }
            b"motorAttached" => status.motor_attached = Some(int(value, FLAG)? == 1),
            b"servo" => status.servo_us = Some(pulse(value)?),
            b"starg" => status.starg_us = Some(pulse(value)?),
            b"mtarg" => status.mtarg_us = Some(pulses(value)?),
            b"motors" => status.motors_us = Some(pulses(value)?),
            b"ver" => status.version = Some(text_of(value)),
            b"cmpd" | b"BRDT" | b"BRDI" | b"BRDV" | b"SC1I" | b"SC2I" | b"SC3I" | b"BT1I"
            | b"BT2I" | b"AVCC" => {}
            b"boot" => events.push(Event::Boot),
            b"CAPA" => events.push(Event::Capabilities(
                int(value, BYTE)?.try_into().map_err(|_| OutOfRange)?,
            )),
            b"crc" => events.push(crc_report(value)?),
            b"cmd" => events.push(Event::CmdEcho(text_of(value))),
            b"rawcmd" => events.push(Event::RawCmd(text_of(value))),
            b"pong" => events.push(Event::Pong(text_of(value))),
            b"log" => events.push(Event::Log(text_of(value))),
            b"LIGT" => {
                lights_at = Some(events.len());
                events.push(Event::Lights {
                    level: byte(value)?,
                    fraction: lone_fraction,
                });
            }
            b"LIGP" => {
                let fraction = real(value, FRACTION)?;
                match lights_at.and_then(|at| events.get_mut(at)) {
                    Some(Event::Lights { fraction: f, .. }) => *f = Some(fraction),
                    _ => lone_fraction = Some(fraction),
                }
            }
            b"claser" => events.push(Event::Laser(byte(value)?)),
            _ => unknown_keys += 1,
        }
    }
    // Every nav/status key that parsed set its field to `Some`, so "any key
    // present" is "not all `None`"; no per-key bookkeeping in the hot loop.
    let has_nav = nav != NavSample::default();
    let has_status = status != StatusSample::default();
    Ok(DecodedLine {
        nav: has_nav.then_some(nav),
        status: has_status.then_some(status),
        unknown_keys,
    })
}

/// The line holds only printable ASCII, so this never actually replaces.
fn text_of(value: &[u8]) -> String {
    String::from_utf8_lossy(value).into_owned()
}

/// A real number as the Arduino prints it (`-2.10`, `0`, `1500`), in range.
fn real(value: &[u8], (lo, hi): (f64, f64)) -> Result<f64, RejectReason> {
    let unsigned = match value {
        [b'-' | b'+', rest @ ..] => rest,
        _ => value,
    };
    let mut digits = 0usize;
    let mut dots = 0usize;
    for &b in unsigned {
        match b {
            b'0'..=b'9' => digits += 1,
            b'.' => dots += 1,
            _ => return Err(RejectReason::NonNumeric),
        }
    }
    if digits == 0 || dots > 1 {
        return Err(RejectReason::NonNumeric);
    }
    let x: f64 = std::str::from_utf8(value)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or(RejectReason::NonNumeric)?;
    // A digit string too long for f64 parses to infinity: a number, just far
    // out of range, which the comparison below also rejects.
    if (lo..=hi).contains(&x) {
        Ok(x)
    } else {
        Err(RejectReason::OutOfRange)
    }
}

/// An integer (optional `-`, digits), in range.
fn int(value: &[u8], (lo, hi): (f64, f64)) -> Result<i64, RejectReason> {
    let (negative, digits) = match value {
        [b'-', rest @ ..] => (true, rest),
        _ => (false, value),
    };
    if digits.is_empty() {
        return Err(RejectReason::NonNumeric);
    }
    let mut magnitude: i64 = 0;
    let mut overflowed = false;
    for &b in digits {
        if !b.is_ascii_digit() {
            return Err(RejectReason::NonNumeric);
        }
        // Keep scanning after an overflow so that `99999999999999999999x`
        // is still reported as non-numeric.
        match magnitude
            .checked_mul(10)
            .and_then(|m| m.checked_add(i64::from(b - b'0')))
        {
            Some(m) => magnitude = m,
            None => overflowed = true,
        }
    }
    if overflowed {
        return Err(RejectReason::OutOfRange);
    }
    let n = if negative { -magnitude } else { magnitude };
    // Both bounds are small integers, exactly representable as i64.
    if (lo as i64..=hi as i64).contains(&n) {
        Ok(n)
    } else {
        Err(RejectReason::OutOfRange)
    }
}

fn byte(value: &[u8]) -> Result<u8, RejectReason> {
    int(value, BYTE)?
        .try_into()
        .map_err(|_| RejectReason::OutOfRange)
}

fn pulse(value: &[u8]) -> Result<u16, RejectReason> {
    int(value, PULSE_US)?
        .try_into()
        .map_err(|_| RejectReason::OutOfRange)
}

/// `mtarg`/`motors`: exactly three comma-separated pulse widths.
fn pulses(value: &[u8]) -> Result<[u16; 3], RejectReason> {
    let mut parts = value.split(|&b| b == b',');
    let mut out = [0u16; 3];
    for slot in &mut out {
        *slot = pulse(parts.next().ok_or(RejectReason::NonNumeric)?)?;
    }
    if parts.next().is_some() {
        return Err(RejectReason::NonNumeric);
    }
    Ok(out)
}

/// `pass` or `fail,<calc>/<got>`.
fn crc_report(value: &[u8]) -> Result<Event, RejectReason> {
    if value == b"pass" {
        return Ok(Event::CrcPass);
    }
    let numbers = value
        .strip_prefix(b"fail,")
        .ok_or(RejectReason::NonNumeric)?;
    let slash = numbers
        .iter()
        .position(|&b| b == b'/')
        .ok_or(RejectReason::NonNumeric)?;
    Ok(Event::CrcFail {
        calc: crc_value(&numbers[..slash])?,
        got: crc_value(&numbers[slash + 1..])?,
    })
}

/// A CRC byte printed in decimal; a negative sign is not a CRC at all.
fn crc_value(value: &[u8]) -> Result<u8, RejectReason> {
    if value.first() == Some(&b'-') {
        return Err(RejectReason::NonNumeric);
    }
    byte(value)
}
