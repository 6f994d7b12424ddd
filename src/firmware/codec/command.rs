//! Host → board: framing and encoding of commands.
//!
//! Owns [`Framing`] (`crc8` or `plain`), [`Command`], the board's CRC-8
//! ([`crc8`]) and [`encode`]. Writes whatever command it is given: whether it
//! is safe to send is the vehicle core's decision.

use std::fmt;
use std::str::FromStr;

/// The board ends a frame at the first `;`, so a CRC byte with this value
/// would end the frame before its text.
const FRAME_END: u8 = b';';

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
    /// `dms(1);` arms the board's dead-man switch, `dms();` disarms it: the
    /// firmware counts the arguments, so `dms(0)` would arm it too.
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

    /// Whether the command sets a level (lights, laser, camera tilt) that a
    /// newer one of the same kind replaces entirely: the link writes only
    /// the newest pending one.
    pub fn is_level(&self) -> bool {
        matches!(self, Self::Lights(_) | Self::Laser(_) | Self::Tilt(_))
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
            Self::EscPower(on) => write_int(out, i64::from(on)),
            Self::DeadMan(true) => write_int(out, 1),
            Self::DeadMan(false) => {}
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
