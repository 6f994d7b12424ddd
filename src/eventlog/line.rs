//! One line of `events.jsonl`: the JSON object and its RFC 3339 time.
//!
//! Owns the line format (field order as in the module docs) and the
//! calendar arithmetic for the time stamp. Pure functions; no I/O.

use std::time::Duration;

use super::LogEvent;

/// One line of the file, field order as documented.
#[derive(serde::Serialize)]
struct Line<'a> {
    time: &'a str,
    unix_us: u64,
    mono_s: f64,
    event: &'a str,
    sysid: Option<u8>,
    detail: &'a str,
}

/// Appends the JSON line for one event, newline included.
pub(super) fn write_line(
    out: &mut Vec<u8>,
    unix_us: u64,
    mono: Duration,
    event: &LogEvent,
) -> serde_json::Result<()> {
    let time = rfc3339_utc(unix_us);
    // Whole milliseconds divided once, so the float is the one nearest the
    // decimal and prints as "12.345", never "12.345000000000001".
    let mono_ms = u64::try_from(mono.as_millis()).unwrap_or(u64::MAX);
    let line = Line {
        time: &time,
        unix_us,
        mono_s: mono_ms as f64 / 1000.0,
        event: event.kind,
        sysid: event.sysid,
        detail: &event.detail,
    };
    serde_json::to_writer(&mut *out, &line)?;
    out.push(b'\n');
    Ok(())
}

/// The JSON line [`EventLog`](super::EventLog) writes for this event (newline included).
pub fn format_line(unix_us: u64, mono: Duration, event: &LogEvent) -> String {
    let mut out = Vec::with_capacity(128);
    if write_line(&mut out, unix_us, mono, event).is_err() {
        out.clear();
    }
    String::from_utf8(out).unwrap_or_default()
}

/// RFC 3339 UTC time with microseconds, e.g. `2000-02-29T12:34:56.000001Z`.
/// Years past 9999 (from absurd inputs) print with more digits.
pub fn rfc3339_utc(unix_us: u64) -> String {
    let secs = unix_us / 1_000_000;
    let micros = unix_us % 1_000_000;
    let (y, m, d) = civil_from_days(secs / 86_400);
    let rem = secs % 86_400;
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{micros:06}Z",
        rem / 3600,
        (rem / 60) % 60,
        rem % 60
    )
}

/// Proleptic Gregorian (year, month, day) of a day count since 1970-01-01:
/// Howard Hinnant's era-based `civil_from_days`, unsigned since the log
/// never sees times before 1970. The telemetry log's file names use it too;
/// no date crate is in the offline cache.
pub(crate) fn civil_from_days(days: u64) -> (u64, u64, u64) {
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + u64::from(m <= 2);
    (y, m, d)
}
