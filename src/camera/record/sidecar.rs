//! The telemetry beside a recording, sans-IO: text out, nothing written.
//!
//! Two files on the video's clock, each line complete when written (a cut
//! power loses at most the line being written):
//! - CSV, one per recording, every sample (five a second) with the time
//!   since the recording started, the UTC time, the segment file and the
//!   time in it — for a spreadsheet;
//! - WebVTT, one per segment, beside its `.ts` with the same name so a
//!   player (VLC, mpv) shows it as subtitles: one cue a second.
//!
//! A reading that was not fresh is an empty CSV field and a dash in the
//! subtitle, never a stale number.

use std::fmt::Write as _;
use std::time::Duration;

use crate::eventlog::rfc3339_utc;
use crate::vehicle::machine::RecordSample;

/// The CSV's first line.
pub const CSV_HEADER: &str = "time_s,utc,segment,segment_time_s,depth_m,heading_deg,roll_deg,pitch_deg,mode,armed,lights_pct,tilt_deg\n";
/// The WebVTT file's first lines.
pub const VTT_HEADER: &str = "WEBVTT\n\n";
/// One subtitle a second.
pub const CUE_PERIOD: Duration = Duration::from_secs(1);

fn opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or_else(String::new, |v| format!("{v:.decimals$}"))
}

/// One CSV row: `t` since the recording started, `seg_t` since the
/// segment `segment` started.
pub fn csv_row(s: &RecordSample, t: Duration, segment: &str, seg_t: Duration) -> String {
    format!(
        "{:.3},{},{segment},{:.3},{},{},{},{},{},{},{:.0},{:.1}\n",
        t.as_secs_f64(),
        rfc3339_utc(s.unix_us),
        seg_t.as_secs_f64(),
        opt(s.depth_m, 3),
        opt(s.heading_deg, 1),
        opt(s.roll_deg, 1),
        opt(s.pitch_deg, 1),
        s.mode,
        u8::from(s.armed),
        s.lights_pct,
        s.tilt_deg,
    )
}

/// `HH:MM:SS.mmm`, WebVTT's time.
pub fn vtt_time(t: Duration) -> String {
    let ms = t.as_millis();
    format!(
        "{:02}:{:02}:{:02}.{:03}",
        ms / 3_600_000,
        (ms / 60_000) % 60,
        (ms / 1000) % 60,
        ms % 1000
    )
}

/// One cue shown from `from` to `to` (times in the segment).
pub fn vtt_cue(s: &RecordSample, from: Duration, to: Duration) -> String {
    let dash = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or_else(|| "-".to_owned(), f);
    let mut text = String::new();
    let _ = write!(
        text,
        "{} --> {}\ndepth {}  heading {}  roll {}  pitch {}\n{} {}  lights {:.0} %  tilt {:.0}°\n\n",
        vtt_time(from),
        vtt_time(to),
        dash(s.depth_m, &|d| format!("{d:.2} m")),
        dash(s.heading_deg, &|h| format!("{h:.0}°")),
        dash(s.roll_deg, &|r| format!("{r:.1}°")),
        dash(s.pitch_deg, &|p| format!("{p:.1}°")),
        s.mode,
        if s.armed { "ARMED" } else { "disarmed" },
        s.lights_pct,
        s.tilt_deg,
    );
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> RecordSample {
        RecordSample {
            mono: Duration::from_secs(5),
            unix_us: 1_780_000_000_250_000,
            depth_m: Some(1.234_56),
            heading_deg: Some(271.04),
            roll_deg: None,
            pitch_deg: Some(-3.45),
            mode: "ALT_HOLD",
            armed: true,
            lights_pct: 40.0,
            tilt_deg: -15.0,
        }
    }

    #[test]
    fn a_csv_row_has_every_column_and_empty_stale_readings() {
        let row = csv_row(
            &sample(),
            Duration::from_millis(6200),
            "rec-x-001.ts",
            Duration::from_millis(1200),
        );
        assert_eq!(
            row,
            "6.200,2026-05-28T20:26:40.250000Z,rec-x-001.ts,1.200,1.235,271.0,,-3.5,ALT_HOLD,1,40,-15.0\n"
        );
        assert_eq!(row.split(',').count(), CSV_HEADER.split(',').count());
    }

    #[test]
    fn a_cue_is_webvtt() {
        let cue = vtt_cue(
            &sample(),
            Duration::from_millis(3_723_004),
            Duration::from_secs(3724),
        );
        assert!(
            cue.starts_with("01:02:03.004 --> 01:02:04.000\ndepth 1.23 m  heading 271°  roll -  pitch -3.5°\nALT_HOLD ARMED"),
            "{cue}"
        );
        assert!(cue.ends_with("\n\n"));
    }
}
