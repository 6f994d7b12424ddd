//! The event log as an operator and a log reader see it: the JSON lines on
//! disk, their time stamps, rotation, restarts, a folder that cannot be
//! used, and a writer that cannot keep up or has stopped. Every test ends
//! with `shutdown()` (which joins the writer) before reading files, so none
//! waits on a clock.

#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use neptunus::eventlog::{
    EventLog, EventLogConfig, EventLogError, EventLogStats, FILE_NAME, LogEvent, format_line,
    rfc3339_utc, rotated_file_name,
};
use serde_json::Value;

fn cfg(dir: &Path, max_bytes: u64, keep: usize) -> EventLogConfig {
    EventLogConfig {
        dir: dir.to_path_buf(),
        max_bytes,
        keep,
    }
}

fn read_lines(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "{} does not end with a newline: {text:?}",
        path.display()
    );
    text.lines().map(str::to_owned).collect()
}

fn parse(line: &str) -> serde_json::Map<String, Value> {
    match serde_json::from_str(line) {
        Ok(Value::Object(map)) => map,
        other => panic!("not a JSON object: {line:?} ({other:?})"),
    }
}

/// Unix time of `2026-11-21T10:00:00Z` in µs (checked with `date -u -d @1795255200`).
const NOV_2026_US: u64 = 1_795_255_200_000_000;

// 1 — the line format ---------------------------------------------------------

#[test]
fn lines_are_json_objects_with_exactly_the_documented_fields() {
    let tmp = tempfile::tempdir().unwrap();
    let log = EventLog::start(cfg(tmp.path(), 1 << 20, 5)).unwrap();
    log.record(
        NOV_2026_US + 123_456,
        Duration::from_micros(12_345_678),
        &LogEvent::new("armed", Some(255), "..."),
    );
    log.record(
        NOV_2026_US + 2_000_000,
        Duration::from_secs(14),
        &LogEvent::new("link_down", None, "board link lost"),
    );
    let stats = log.shutdown();
    assert_eq!(
        stats,
        EventLogStats {
            written: 2,
            ..EventLogStats::default()
        }
    );

    let lines = read_lines(&tmp.path().join(FILE_NAME));
    // Byte for byte the example of the spec: field order, number formats, no spaces.
    assert_eq!(
        lines,
        [
            r#"{"time":"2026-11-21T10:00:00.123456Z","unix_us":1795255200123456,"mono_s":12.345,"event":"armed","sysid":255,"detail":"..."}"#,
            r#"{"time":"2026-11-21T10:00:02.000000Z","unix_us":1795255202000000,"mono_s":14.0,"event":"link_down","sysid":null,"detail":"board link lost"}"#,
        ]
    );
    for line in &lines {
        let obj = parse(line);
        let keys: Vec<&str> = obj.keys().map(String::as_str).collect();
        let mut expected = ["time", "unix_us", "mono_s", "event", "sysid", "detail"];
        expected.sort_unstable(); // serde_json's map is sorted
        assert_eq!(keys, expected);
        assert!(obj["time"].is_string());
        assert!(obj["unix_us"].is_u64());
        assert!(obj["mono_s"].is_f64());
        assert!(obj["event"].is_string());
        assert!(obj["detail"].is_string());
    }
    assert_eq!(parse(&lines[0])["sysid"], Value::from(255));
    assert_eq!(parse(&lines[1])["sysid"], Value::Null);
}

#[test]
fn detail_is_escaped_and_round_trips() {
    let details = [
        r#"she said "stop" \ now"#.to_owned(),
        "two\nlines\r\nand a\ttab".to_owned(),
        "nul \u{0} bell \u{7} del \u{7f}".to_owned(),
        "Tiefe 3,5 m — Überdruck 🐟 深さ".to_owned(),
        "line\u{2028}separator\u{2029}paragraph".to_owned(),
        "{\"event\":\"forged\",\"sysid\":1}\n{\"x\":".to_owned(),
        String::new(),
    ];
    let tmp = tempfile::tempdir().unwrap();
    let log = EventLog::start(cfg(tmp.path(), 1 << 20, 5)).unwrap();
    for (i, detail) in details.iter().enumerate() {
        let sysid = u8::try_from(i).unwrap();
        log.record(
            i as u64,
            Duration::ZERO,
            &LogEvent::new("mode", Some(sysid), detail.clone()),
        );
    }
    assert_eq!(log.shutdown().written, details.len() as u64);

    let lines = read_lines(&tmp.path().join(FILE_NAME));
    assert_eq!(
        lines.len(),
        details.len(),
        "a detail broke a line: {lines:#?}"
    );
    for (i, (line, detail)) in lines.iter().zip(&details).enumerate() {
        let obj = parse(line);
        assert_eq!(
            obj["detail"],
            Value::from(detail.as_str()),
            "line {i}: {line}"
        );
        assert_eq!(obj["event"], Value::from("mode"));
        assert_eq!(obj["sysid"], Value::from(i));
        assert!(!line.contains('\n') && !line.contains('\r') && !line.contains('\0'));
    }
}

#[test]
fn format_line_is_what_the_file_gets() {
    let ev = LogEvent::new("control_granted", Some(254), "255 -> 254");
    let line = format_line(NOV_2026_US, Duration::from_millis(1500), &ev);
    assert_eq!(
        line,
        "{\"time\":\"2026-11-21T10:00:00.000000Z\",\"unix_us\":1795255200000000,\"mono_s\":1.5,\
         \"event\":\"control_granted\",\"sysid\":254,\"detail\":\"255 -> 254\"}\n"
    );
    // Sub-millisecond monotonic time is cut, never printed as float noise.
    for ms in [0u64, 1, 7, 100, 999, 12_345, 86_399_999, 3_600_000_001] {
        let line = format_line(0, Duration::from_micros(ms * 1000 + 999), &ev);
        let mono = parse(line.trim_end())["mono_s"].to_string();
        let want = format!("{}.{:03}", ms / 1000, ms % 1000);
        let want = want.trim_end_matches('0');
        let want = if want.ends_with('.') {
            format!("{want}0")
        } else {
            want.to_owned()
        };
        assert_eq!(mono, want, "{ms} ms");
    }
}

// 2 — time stamps -------------------------------------------------------------

#[test]
fn time_is_rfc3339_utc_with_microseconds() {
    let cases = [
        (0, "1970-01-01T00:00:00.000000Z"),
        (1, "1970-01-01T00:00:00.000001Z"),
        (86_399_999_999, "1970-01-01T23:59:59.999999Z"),
        (68_255_999_999_999, "1972-02-29T23:59:59.999999Z"),
        (951_827_696_000_001, "2000-02-29T12:34:56.000001Z"),
        (951_868_800_000_000, "2000-03-01T00:00:00.000000Z"),
        (978_307_199_999_999, "2000-12-31T23:59:59.999999Z"),
        (1_700_000_000_000_000, "2023-11-14T22:13:20.000000Z"),
        (1_709_164_800_000_000, "2024-02-29T00:00:00.000000Z"),
        (2_147_483_648_000_000, "2038-01-19T03:14:08.000000Z"),
        (NOV_2026_US + 123_456, "2026-11-21T10:00:00.123456Z"),
        (4_107_542_400_000_000, "2100-03-01T00:00:00.000000Z"), // 2100 is no leap year
        (253_402_300_799_999_999, "9999-12-31T23:59:59.999999Z"),
    ];
    for (unix_us, want) in cases {
        assert_eq!(rfc3339_utc(unix_us), want, "unix_us {unix_us}");
    }
    // Garbage in (a clock gone mad) is still a time stamp, not a panic.
    assert_eq!(rfc3339_utc(u64::MAX), "586524-01-19T08:01:49.551615Z");
}

/// Every day from 1970 to 2400 against a calendar counted the slow way.
#[test]
fn every_date_from_1970_to_2400_matches_a_counted_calendar() {
    let is_leap = |y: u64| (y.is_multiple_of(4) && !y.is_multiple_of(100)) || y.is_multiple_of(400);
    let (mut y, mut m, mut d) = (1970u64, 1u64, 1u64);
    let mut day = 0u64;
    while y <= 2400 {
        let at_noon = (day * 86_400 + 43_200) * 1_000_000;
        assert_eq!(
            rfc3339_utc(at_noon),
            format!("{y:04}-{m:02}-{d:02}T12:00:00.000000Z"),
            "day {day}"
        );
        let month_len = match m {
            2 if is_leap(y) => 29,
            2 => 28,
            4 | 6 | 9 | 11 => 30,
            _ => 31,
        };
        d += 1;
        if d > month_len {
            d = 1;
            m += 1;
            if m > 12 {
                m = 1;
                y += 1;
            }
        }
        day += 1;
    }
}

// 3 — rotation ----------------------------------------------------------------

/// Files oldest first: `events.{keep}.jsonl` … `events.1.jsonl`, `events.jsonl`.
fn files_oldest_first(dir: &Path, keep: usize) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = (1..=keep)
        .rev()
        .map(|n| dir.join(rotated_file_name(n)))
        .filter(|p| p.exists())
        .collect();
    files.push(dir.join(FILE_NAME));
    files
}

fn names_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    names
}

fn seq_event(i: usize) -> LogEvent {
    LogEvent::new("input_rejected", Some(254), format!("#{i:04}"))
}

fn seq_of(line: &str) -> usize {
    let obj = parse(line);
    obj["detail"].as_str().unwrap()[1..].parse().unwrap()
}

#[test]
fn rotation_keeps_whole_lines_in_order_and_at_most_keep_files() {
    let one_line = format_line(0, Duration::ZERO, &seq_event(0)).len() as u64;
    // Room for three lines and a bit, never four.
    let max_bytes = 3 * one_line + one_line / 2;
    let keep = 3;
    let tmp = tempfile::tempdir().unwrap();
    // Left over from a run with a bigger `keep`: goes at the first rotation.
    std::fs::write(tmp.path().join(rotated_file_name(7)), "old\n").unwrap();
    std::fs::write(tmp.path().join("notes.txt"), "not ours\n").unwrap();

    let log = EventLog::start(cfg(tmp.path(), max_bytes, keep)).unwrap();
    let total = 40;
    for i in 0..total {
        log.record(i as u64, Duration::from_millis(i as u64), &seq_event(i));
    }
    let stats = log.shutdown();
    // 40 lines, 3 a file: 13 full files and one with a line in it.
    assert_eq!(stats.written, total as u64);
    assert_eq!(stats.rotations, 13);
    assert_eq!((stats.dropped, stats.write_errors), (0, 0));

    assert_eq!(
        names_in(tmp.path()),
        [
            "events.1.jsonl",
            "events.2.jsonl",
            "events.3.jsonl",
            "events.jsonl",
            "notes.txt"
        ]
    );
    let mut seqs = Vec::new();
    for path in files_oldest_first(tmp.path(), keep) {
        let len = std::fs::metadata(&path).unwrap().len();
        assert!(len <= max_bytes, "{} has {len} bytes", path.display());
        let lines = read_lines(&path); // whole lines: each ends with \n …
        for line in &lines {
            seqs.push(seq_of(line)); // … and parses
        }
    }
    // The newest 3 × 3 + 1 lines survive, in order, none twice, none missing.
    let want: Vec<usize> = (total - 10..total).collect();
    assert_eq!(seqs, want);
}

#[test]
fn a_line_longer_than_the_limit_gets_a_file_of_its_own() {
    let tmp = tempfile::tempdir().unwrap();
    let log = EventLog::start(cfg(tmp.path(), 10, 2)).unwrap();
    for i in 0..4 {
        log.record(0, Duration::ZERO, &seq_event(i));
    }
    let stats = log.shutdown();
    assert_eq!((stats.written, stats.rotations), (4, 3));
    let files = files_oldest_first(tmp.path(), 2);
    let per_file: Vec<Vec<usize>> = files
        .iter()
        .map(|p| read_lines(p).iter().map(|l| seq_of(l)).collect())
        .collect();
    assert_eq!(per_file, [vec![1], vec![2], vec![3]]);
}

#[test]
fn keep_zero_keeps_only_the_current_file() {
    let tmp = tempfile::tempdir().unwrap();
    let one_line = format_line(0, Duration::ZERO, &seq_event(0)).len() as u64;
    let log = EventLog::start(cfg(tmp.path(), 2 * one_line, 0)).unwrap();
    for i in 0..5 {
        log.record(0, Duration::ZERO, &seq_event(i));
    }
    assert_eq!(log.shutdown().rotations, 2);
    assert_eq!(names_in(tmp.path()), [FILE_NAME]);
    let seqs: Vec<usize> = read_lines(&tmp.path().join(FILE_NAME))
        .iter()
        .map(|l| seq_of(l))
        .collect();
    assert_eq!(seqs, [4]);
}

// 4 — restarts ----------------------------------------------------------------

#[test]
fn a_restart_appends_to_the_existing_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("data").join("events"); // created on the way
    for run in 0..3 {
        let log = EventLog::start(cfg(&dir, 1 << 20, 5)).unwrap();
        log.record(0, Duration::ZERO, &seq_event(2 * run));
        log.record(0, Duration::ZERO, &seq_event(2 * run + 1));
        assert_eq!(log.shutdown().written, 2);
    }
    let seqs: Vec<usize> = read_lines(&dir.join(FILE_NAME))
        .iter()
        .map(|l| seq_of(l))
        .collect();
    assert_eq!(seqs, [0, 1, 2, 3, 4, 5]);
    assert_eq!(names_in(&dir), [FILE_NAME]);
}

#[test]
fn a_restart_counts_the_existing_size_towards_rotation() {
    let tmp = tempfile::tempdir().unwrap();
    let one_line = format_line(0, Duration::ZERO, &seq_event(0)).len() as u64;
    let config = cfg(tmp.path(), 2 * one_line, 5);
    let log = EventLog::start(config.clone()).unwrap();
    log.record(0, Duration::ZERO, &seq_event(0));
    log.record(0, Duration::ZERO, &seq_event(1));
    assert_eq!(log.shutdown().rotations, 0);
    // The file is full: the first line after the restart starts a new one.
    let log = EventLog::start(config).unwrap();
    log.record(0, Duration::ZERO, &seq_event(2));
    assert_eq!(log.shutdown().rotations, 1);
    let first: Vec<usize> = read_lines(&tmp.path().join(rotated_file_name(1)))
        .iter()
        .map(|l| seq_of(l))
        .collect();
    assert_eq!(first, [0, 1]);
    assert_eq!(seq_of(&read_lines(&tmp.path().join(FILE_NAME))[0]), 2);
}

/// Power cut mid-line: the torn line stays a line of its own (which readers
/// skip), and the next event is a clean line after it.
#[test]
fn a_torn_last_line_is_ended_before_new_lines() {
    let tmp = tempfile::tempdir().unwrap();
    let good = format_line(0, Duration::ZERO, &seq_event(0));
    std::fs::write(
        tmp.path().join(FILE_NAME),
        format!("{good}{{\"time\":\"2026-11-"),
    )
    .unwrap();
    let log = EventLog::start(cfg(tmp.path(), 1 << 20, 5)).unwrap();
    log.record(0, Duration::ZERO, &seq_event(1));
    log.shutdown();
    let lines = read_lines(&tmp.path().join(FILE_NAME));
    assert_eq!(lines.len(), 3);
    assert_eq!(seq_of(&lines[0]), 0);
    assert!(serde_json::from_str::<Value>(&lines[1]).is_err());
    assert_eq!(seq_of(&lines[2]), 1);
}

// 5 — a folder that cannot be used ----------------------------------------------

#[test]
fn a_file_in_place_of_the_folder_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    // Root ignores permissions, so a regular file is what is in the way.
    let data_dir = tmp.path().join("data");
    std::fs::write(&data_dir, "i am a file").unwrap();
    for dir in [data_dir.clone(), data_dir.join("events")] {
        let err = EventLog::start(cfg(&dir, 1 << 20, 5)).unwrap_err();
        assert!(
            matches!(&err, EventLogError::NotAFolder { blocker, .. } if *blocker == data_dir),
            "{err:?}"
        );
        let msg = err.to_string();
        assert!(msg.contains(&dir.display().to_string()), "{msg}");
        assert!(
            msg.contains(&format!("{} is a file, not a folder", data_dir.display())),
            "{msg}"
        );
        assert!(msg.contains("--data-dir"), "{msg}");
    }
}

#[test]
fn a_folder_in_place_of_the_file_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join(FILE_NAME);
    std::fs::create_dir(&path).unwrap();
    let err = EventLog::start(cfg(tmp.path(), 1 << 20, 5)).unwrap_err();
    assert!(matches!(err, EventLogError::Open { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.starts_with(&format!("cannot open the event log {}: ", path.display())),
        "{msg}"
    );
    assert!(msg.contains("--data-dir"), "{msg}");
}

/// A disk that fails every write: each line is counted as lost, nothing
/// panics, and shutdown still returns.
#[cfg(target_os = "linux")]
#[test]
fn write_errors_are_counted_not_fatal() {
    let tmp = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink("/dev/full", tmp.path().join(FILE_NAME)).unwrap();
    let log = EventLog::start(cfg(tmp.path(), 100, 5)).unwrap();
    for i in 0..50 {
        log.record(0, Duration::ZERO, &seq_event(i));
    }
    let stats = log.shutdown();
    assert_eq!(
        stats,
        EventLogStats {
            write_errors: 50,
            ..EventLogStats::default()
        }
    );
}

// 6 — never blocking the caller ------------------------------------------------

#[test]
fn records_after_shutdown_are_dropped_and_counted() {
    let tmp = tempfile::tempdir().unwrap();
    let log = EventLog::start(cfg(tmp.path(), 1 << 20, 5)).unwrap();
    let other = log.clone();
    log.record(0, Duration::ZERO, &seq_event(0));
    assert_eq!(log.shutdown().written, 1);
    for i in 1..=1000 {
        other.record(0, Duration::ZERO, &seq_event(i));
    }
    let stats = other.stats();
    assert_eq!((stats.written, stats.dropped), (1, 1000));
    // A second shutdown through another handle is harmless.
    assert_eq!(other.shutdown(), stats);
    assert_eq!(read_lines(&tmp.path().join(FILE_NAME)).len(), 1);
}

#[test]
fn a_flood_into_a_tiny_queue_drops_and_counts_without_blocking() {
    let total = 100_000u64;
    for queue_len in [0, 1] {
        let tmp = tempfile::tempdir().unwrap();
        let log = EventLog::with_capacity(cfg(tmp.path(), 1 << 16, 2), queue_len).unwrap();
        let ev = LogEvent::new("input_rejected", Some(254), "flood");
        for i in 0..total {
            log.record(i, Duration::from_micros(i), &ev);
        }
        let stats = log.shutdown();
        // Every event is accounted for exactly once.
        assert_eq!(stats.written + stats.dropped, total, "{stats:?}");
        assert_eq!(stats.write_errors, 0);
        // A file write takes far longer than a failed try_send; a queue of
        // at most one cannot keep up with 100 000 back-to-back records.
        assert!(stats.dropped > 0, "{stats:?}");
        let mut lines = 0;
        let mut last_us = None;
        for path in files_oldest_first(tmp.path(), 2) {
            for line in read_lines(&path) {
                let us = parse(&line)["unix_us"].as_u64().unwrap();
                assert!(last_us < Some(us), "out of order: {us} after {last_us:?}");
                last_us = Some(us);
                lines += 1;
            }
        }
        // Rotation dropped whole older files; what is left is the tail.
        assert!(lines <= stats.written);
        assert_eq!(last_us.is_some(), stats.written > 0);
    }
}

/// A data directory that cannot hold the log (here a file in the way; root
/// ignores permission bits) does not stop the vehicle: the log starts
/// closed, says why, loses and counts events, and writes again once the
/// folder can be made.
#[test]
fn a_log_that_cannot_open_degrades_and_recovers_when_the_disk_does() {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    std::fs::write(&data_dir, "i am a file").unwrap();
    let dir = data_dir.join("events");
    let (log, problem) = EventLog::start_or_degraded(cfg(&dir, 1 << 20, 5));
    assert!(
        matches!(&problem, Some(EventLogError::NotAFolder { .. })),
        "{problem:?}"
    );
    log.record(1, Duration::ZERO, &LogEvent::new("lost", None, "no disk"));
    // The writer has tried (a condition, not a sleep).
    let end = std::time::Instant::now() + Duration::from_secs(10);
    while log.stats().write_errors == 0 && std::time::Instant::now() < end {
        std::thread::yield_now();
    }
    // The disk is back.
    std::fs::remove_file(&data_dir).unwrap();
    log.record(2, Duration::ZERO, &LogEvent::new("kept", None, "disk back"));
    let stats = log.shutdown();
    assert_eq!((stats.written, stats.write_errors), (1, 1), "{stats:?}");
    let lines = read_lines(&dir.join(FILE_NAME));
    assert_eq!(lines.len(), 1);
    assert!(lines[0].contains("\"event\":\"kept\""), "{}", lines[0]);
}
