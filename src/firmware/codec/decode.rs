//! Board → host: turning bytes, in any chunking, into [`Event`]s.
//!
//! Owns [`LineDecoder`] (line assembly, garbage and overlong handling) and
//! the decoding of one line into samples and events. The rules are listed
//! in the [module docs](super).

use super::MAX_LINE_BYTES;
use super::types::{DecodeStats, Event, NavSample, RejectReason, StatusSample};
use super::value::{
    ANGLE_DEG, BOARD_TEMP_C, BYTE, CURRENT_A, DEPTH_M, FLAG, FMEM_BYTES, FRACTION, FTHR_PCT,
    HEADING_DEG, PRES_MBAR, TEMP_C, TIME_MS, VOUT_V, YAW_DEG, byte, crc_report, int, pulse, pulses,
    real, whole,
};

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
    /// A line that ended without its `;`, kept until the next line says
    /// whether the `;` merely came after a line break (the next line starts
    /// with `;`) or was never printed.
    held: Option<Vec<u8>>,
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

    /// Decides a held line now, as if the line after it did not begin with
    /// `;` (the board went quiet, or the device is being closed).
    pub fn flush(&mut self, out: &mut Vec<Event>) {
        if let Some(held) = self.held.take() {
            self.unterminated(&held, out);
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
            reject(&mut self.stats, RejectReason::Overlong, &self.line);
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
        let line = std::mem::take(&mut self.line);
        let text = line.strip_suffix(b"\r").unwrap_or(&line);
        if text.len() > MAX_LINE_BYTES {
            reject(&mut self.stats, RejectReason::Overlong, text);
        } else if !text.is_empty() {
            self.complete(text, out);
        }
        self.line = line;
        self.line.clear();
    }

    /// A whole line (without its terminator): joined to a held one, held
    /// itself, or decoded.
    fn complete(&mut self, text: &[u8], out: &mut Vec<Event>) {
        if let Some(mut held) = self.held.take() {
            if text.first() == Some(&b';') && held.len() + text.len() <= MAX_LINE_BYTES {
                // The board printed a line break before this line's `;`.
                held.extend_from_slice(text);
                self.stats.joined_lines += 1;
                self.decode(&held, out);
                return;
            }
            self.unterminated(&held, out);
        }
        if text.ends_with(b";") {
            self.decode(text, out);
        } else {
            self.held = Some(text.to_vec());
        }
    }

    /// A line that ended without `;` and was not continued by one.
    fn unterminated(&mut self, text: &[u8], out: &mut Vec<Event>) {
        // Pairs, then a message without its `;`: a `pong:…;` is printed
        // without a line end, and the board's next print shares its line —
        // a `log:` message (the depth sensor's failure) or free text (the
        // 2014 firmware's IMU set-up retried every 30 s, "mpu_init failed
        // with code: -1"). The pairs are a line of their own.
        if let Some(last) = text.iter().rposition(|&b| b == b';') {
            let (pairs, rest) = text.split_at(last + 1);
            if rest.starts_with(b"log:") || (!rest.contains(&b';') && rest.contains(&b' ')) {
                self.decode(pairs, out);
                self.unterminated(rest, out);
                return;
            }
        }
        if let Some(message) = text.strip_prefix(b"log:") {
            // The board's log messages are free text; some lack the `;`.
            self.stats.lines_accepted += 1;
            out.push(Event::Log(text_of(message)));
        } else if !text.contains(&b';') && text.contains(&b' ') {
            // Words, not `key:value;` pairs: a sensor's set-up chatter.
            self.stats.text_lines += 1;
        } else {
            reject(&mut self.stats, RejectReason::Torn, text);
        }
    }

    fn decode(&mut self, text: &[u8], out: &mut Vec<Event>) {
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
            Err(reason) => reject(&mut self.stats, reason, text),
        }
    }
}

/// Counts a rejected line and logs it (at debug level: a noisy line would
/// otherwise flood the log; the counters say how many).
fn reject(stats: &mut DecodeStats, reason: RejectReason, text: &[u8]) {
    stats.count_rejected(reason);
    tracing::debug!(?reason, line = %String::from_utf8_lossy(text), "board line rejected");
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
    let mut tubes: [Option<f64>; 2] = [None; 2];

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
            b"yaw" => nav.yaw_deg = Some(real(value, YAW_DEG)?),
            b"fthr" => nav.fthr_pct = Some(real(value, FTHR_PCT)?),
            b"vout" => status.vout_v = Some(real(value, VOUT_V)?),
            b"iout" => status.iout_a = Some(real(value, CURRENT_A)?),
            // Each tube's reading once (a key twice: the last, as for every
            // key), summed after the line.
            b"BT1I" => tubes[0] = Some(real(value, CURRENT_A)?),
            b"BT2I" => tubes[1] = Some(real(value, CURRENT_A)?),
            b"BRDT" => status.board_temp_c = Some(real(value, BOARD_TEMP_C)?),
            b"pres" => status.pres_mbar = Some(real(value, PRES_MBAR)?),
            b"temp" => status.temp_c = Some(real(value, TEMP_C)?),
            b"time" => status.time_ms = Some(whole(value, TIME_MS)?),
            b"fmem" => {
                status.fmem_bytes = Some(
                    whole(value, FMEM_BYTES)?
                        .try_into()
                        .map_err(|_| OutOfRange)?,
                )
            }
            b"motorAttached" => status.motor_attached = Some(int(value, FLAG)? == 1),
            b"servo" => status.servo_us = Some(pulse(value)?),
            b"starg" => status.starg_us = Some(pulse(value)?),
            b"mtarg" => status.mtarg_us = Some(pulses(value)?),
            b"motors" => status.motors_us = Some(pulses(value)?),
            b"ver" => status.version = Some(text_of(value)),
            b"cmpd" => status.compiled = Some(text_of(value)),
            // Known and not needed: the same readings again (`BRDV` = `vout`,
            // `BRDI` = `iout`), the ESC supply currents, AVcc, the unused
            // MCU temperature, loop statistics, motor modifiers, the board's
            // own holds' targets and errors, the external lights.
            b"BRDI" | b"BRDV" | b"SC1I" | b"SC2I" | b"SC3I" | b"AVCC" | b"atmp" | b"alps"
            | b"dlms" | b"mtrmod" | b"targetDepth" | b"targetHeading" | b"dp_er" | b"p_er"
            | b"LIGTE" | b"LIGPE" | b"dtwa" => {}
            // A device's set-up report (`MPU9150.status`, `Depth.C0`, `BNO055.Address`).
            _ if key.contains(&b'.') => {}
            b"boot" => events.push(Event::Boot),
            b"CAPA" => events.push(Event::Capabilities(
                int(value, BYTE)?.try_into().map_err(|_| OutOfRange)?,
            )),
            b"crc" => events.push(crc_report(value)?),
            b"cmd" => events.push(Event::CmdEcho(text_of(value))),
            b"rawcmd" => events.push(Event::RawCmd(text_of(value))),
            b"pong" => events.push(Event::Pong(text_of(value))),
            b"log" => events.push(Event::Log(text_of(value))),
            b"icmd" => events.push(Event::InternalCommand(text_of(value))),
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
    if tubes.iter().any(Option::is_some) {
        status.battery_current_a = Some(tubes.iter().flatten().sum());
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
