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
//!   `:` (values such as `cmd:go(1,2,3)` or `crc:fail,9E/CB` hold commas and
//!   parentheses). Empty segments (from `;;`) are ignored.
//! - A line that does not end with `;` is held until the next line: if that
//!   one begins with `;`, the board printed a line break before the `;`
//!   (its status line's `cmpd` is `println`ed, then `;` follows) and the two
//!   are decoded as one ([`DecodeStats::joined_lines`]). Otherwise the held
//!   line is a `log:` message printed without its `;` ([`Event::Log`]), the
//!   board's free text if it holds no `;` and has words with spaces (a
//!   sensor's set-up chatter, counted in [`DecodeStats::text_lines`] and
//!   ignored), or else [`RejectReason::Torn`]. Pairs with such a message
//!   after their last `;` (a `pong:…;` printed without a line end, then the
//!   board's next print) are decoded as a line, then the message as above.
//!   [`LineDecoder::flush`] decides a held line without waiting.
//! - The whole line is rejected as [`RejectReason::Torn`] if a non-empty
//!   segment has no `:`, or if a key is empty.
//! - Numeric keys must hold a number inside the key's physical range
//!   ([`physical_range`]), else the whole line is rejected as
//!   [`RejectReason::NonNumeric`] or [`RejectReason::OutOfRange`]. Real-valued
//!   keys accept an optional sign, digits and at most one `.` (what the
//!   Arduino prints), so `1e5`, `inf`, `nan`, ` 1` and `pitc` are non-numeric.
//!   `time` and `fmem` are whole numbers the board prints as floats
//!   (`time:912.00`), rounded. Integer keys (`motorAttached`, `servo`,
//!   `starg`, `mtarg`, `motors`, `CAPA`, `LIGT`, `claser`) accept an
//!   optional `-` and digits only. `mtarg`/`motors` hold exactly three
//!   comma-separated integers. A number too large to represent is out of range.
//! - A rejected line emits nothing at all and is counted once, with the first
//!   reason found reading left to right (a missing final `;` is found first).
//! - `ver` goes into [`StatusSample::version`], `cmpd` into
//!   [`StatusSample::compiled`], `BRDT` into [`StatusSample::board_temp_c`],
//!   `BT1I` + `BT2I` into [`StatusSample::battery_current_a`]. Known and
//!   ignored without being parsed: `BRDI`, `BRDV`, `SC1I`..`SC3I`, `AVCC`,
//!   `atmp`, `alps`, `dlms`, `mtrmod`, `targetDepth`, `targetHeading`,
//!   `dp_er`, `p_er`, `LIGTE`, `LIGPE`, `dtwa`, and any key with a `.` (a
//!   device's set-up report such as `MPU9150.status` or `Depth.C0`). Any
//!   other key is counted in [`DecodeStats::unknown_keys`] (only for
//!   accepted lines) and ignored; the line is still accepted.
//! - Event keys: `boot` → [`Event::Boot`] (any value), `CAPA` →
//!   [`Event::Capabilities`], `crc` → `pass` / `fail,<calc>/<got>` (each one
//!   or two hex digits), `cmd` → [`Event::CmdEcho`], `icmd` →
//!   [`Event::InternalCommand`], `rawcmd` → [`Event::RawCmd`],
//!   `pong` → [`Event::Pong`], `log` → [`Event::Log`] (text values verbatim),
//!   `LIGT` → [`Event::Lights`] with the fraction from a `LIGP` anywhere on
//!   the same line (a `LIGP` without `LIGT` is range-checked and otherwise
//!   ignored),
//!   `claser` → [`Event::Laser`].
//! - An accepted line emits, in order: [`Event::Nav`] if any nav key is
//!   present, [`Event::Status`] if any status key is present, then the event
//!   keys in line order. When a key repeats on a line, the last value wins.
//!
//! One file per concern: `command` (host → board), `types` (what a line
//! yields), `value` (key ranges and number parsing) and `decode`
//! ([`LineDecoder`]); everything public is re-exported here.

mod command;
mod decode;
mod types;
mod value;

pub use command::{Command, Framing, ParseFramingError, crc8, encode, encoded};
pub use decode::LineDecoder;
pub use types::{DecodeStats, Event, NavSample, RejectReason, StatusSample};
pub use value::physical_range;

/// Longest board line accepted, not counting `\r\n`. The board's longest
/// real lines (status with all sensors) are well under 200 bytes; anything
/// far longer is two lines whose terminator was lost.
pub const MAX_LINE_BYTES: usize = 512;
