//! The values of board keys: physical ranges and the strict number
//! parsers the decoder uses.
//!
//! Owns [`physical_range`], the one source of truth for what a sensor may
//! report, and the value parsers (`real`, `int`, pulses, CRC reports). A
//! value outside its range or not written the way the Arduino prints it is
//! a [`RejectReason`], never a panic.

use super::types::{Event, RejectReason};

// Physical ranges, inclusive. One source of truth for the decoder and for
// `physical_range`, which tests and the emulator use.
pub(super) const HEADING_DEG: (f64, f64) = (0.0, 360.0);
pub(super) const DEPTH_M: (f64, f64) = (-10.0, 200.0);
pub(super) const ANGLE_DEG: (f64, f64) = (-180.0, 180.0);
/// `yaw` is whatever the IMU driver calls yaw: the MPU9150's fused angle
/// about z (−180..180), or the BNO055's heading register (0..360).
pub(super) const YAW_DEG: (f64, f64) = (-180.0, 360.0);
pub(super) const FTHR_PCT: (f64, f64) = (-100.0, 100.0);
pub(super) const VOUT_V: (f64, f64) = (0.0, 30.0);
pub(super) const CURRENT_A: (f64, f64) = (0.0, 20.0);
pub(super) const PRES_MBAR: (f64, f64) = (0.0, 30_000.0);
pub(super) const TEMP_C: (f64, f64) = (-10.0, 60.0);
pub(super) const BOARD_TEMP_C: (f64, f64) = (-40.0, 125.0);
pub(super) const TIME_MS: (f64, f64) = (0.0, 4_294_967_296.0);
pub(super) const FMEM_BYTES: (f64, f64) = (0.0, 65_535.0);
pub(super) const FLAG: (f64, f64) = (0.0, 1.0);
const PULSE_US: (f64, f64) = (500.0, 2500.0);
pub(super) const BYTE: (f64, f64) = (0.0, 255.0);
pub(super) const FRACTION: (f64, f64) = (0.0, 1.0);

/// Physical range of a numeric key, inclusive, or `None` for non-range keys.
/// For `mtarg`/`motors` it is the range of each of the three values.
pub fn physical_range(key: &str) -> Option<(f64, f64)> {
    Some(match key {
        "hdgd" => HEADING_DEG,
        "deep" | "deap" => DEPTH_M,
        "pitc" | "roll" => ANGLE_DEG,
        "yaw" => YAW_DEG,
        "fthr" => FTHR_PCT,
        "vout" => VOUT_V,
        "iout" | "BT1I" | "BT2I" => CURRENT_A,
        "pres" => PRES_MBAR,
        "temp" => TEMP_C,
        "BRDT" => BOARD_TEMP_C,
        "time" => TIME_MS,
        "fmem" => FMEM_BYTES,
        "motorAttached" => FLAG,
        "servo" | "starg" | "mtarg" | "motors" => PULSE_US,
        "CAPA" | "LIGT" | "claser" => BYTE,
        "LIGP" => FRACTION,
        _ => return None,
    })
}

/// A real number as the Arduino prints it (`-2.10`, `0`, `1500`), in range.
pub(super) fn real(value: &[u8], (lo, hi): (f64, f64)) -> Result<f64, RejectReason> {
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
pub(super) fn int(value: &[u8], (lo, hi): (f64, f64)) -> Result<i64, RejectReason> {
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

pub(super) fn byte(value: &[u8]) -> Result<u8, RejectReason> {
    int(value, BYTE)?
        .try_into()
        .map_err(|_| RejectReason::OutOfRange)
}

pub(super) fn pulse(value: &[u8]) -> Result<u16, RejectReason> {
    int(value, PULSE_US)?
        .try_into()
        .map_err(|_| RejectReason::OutOfRange)
}

/// `mtarg`/`motors`: exactly three comma-separated pulse widths.
pub(super) fn pulses(value: &[u8]) -> Result<[u16; 3], RejectReason> {
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

/// `pass` or `fail,<calc>/<got>`, the two CRCs in hexadecimal as the
/// board's `Serial.print(crc, HEX)` writes them (`9E`, `7`).
pub(super) fn crc_report(value: &[u8]) -> Result<Event, RejectReason> {
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

/// A CRC byte in hexadecimal: one or two hex digits, nothing else.
fn crc_value(value: &[u8]) -> Result<u8, RejectReason> {
    if value.is_empty() || value.len() > 2 || !value.iter().all(u8::is_ascii_hexdigit) {
        return Err(RejectReason::NonNumeric);
    }
    std::str::from_utf8(value)
        .ok()
        .and_then(|s| u8::from_str_radix(s, 16).ok())
        .ok_or(RejectReason::NonNumeric)
}

/// A whole number printed as a float (`912.00`): real-valued, in range,
/// rounded to the nearest integer.
pub(super) fn whole(value: &[u8], range: (f64, f64)) -> Result<u64, RejectReason> {
    // `real` has checked the range, which starts at 0 for every caller.
    Ok(real(value, range)?.round() as u64)
}
