//! The event log: `DATA_DIR/events/events.jsonl`, one JSON object per line,
//! for the things an operator wants to look back at (arming, who had control,
//! failsafes, link drops, refused commands):
//!
//! ```text
//! {"time":"2026-11-21T10:00:00.123456Z","unix_us":1795255200123456,"mono_s":12.345,"event":"armed","sysid":255,"detail":"..."}
//! ```
//!
//! Owns: the line format, the file, size-based rotation
//! (`events.jsonl` → `events.1.jsonl` → … `events.{keep}.jsonl`) and the
//! writer thread. The vehicle core only creates [`LogEvent`]s; it reads no
//! clock for them, the caller passes the time in.
//!
//! It must never block the vehicle task and never panic: [`EventLog::record`]
//! only tries to queue the event (a full queue or a stopped writer drops and
//! counts it), and a disk error is counted, logged once, and the writer keeps
//! trying with the next line. Each line goes to the file with one `write`
//! call as soon as it arrives, so `tail -f` sees it at once. A line torn by
//! a power cut or a full disk is ended before the next one is written, so a
//! reader loses that line only: readers should skip lines that do not parse.
//!
//! One file per concern: this file holds the public types; `writer` the
//! handle and the writer thread, `line` the JSON line and its time stamp,
//! `file` the file and its rotation.

mod file;
mod line;
mod writer;

use std::io;
use std::path::PathBuf;

pub(crate) use line::civil_from_days;
pub use line::{format_line, rfc3339_utc};
pub use writer::EventLog;

/// One thing worth an operator's later attention. Pure data: the vehicle core creates these.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LogEvent {
    /// snake_case event name, e.g. "armed", "control_granted",
    /// "failsafe_raised" (the list is in the user guide,
    /// docs/guide/src/safety.md, "Event log").
    pub kind: &'static str,
    /// The ground station involved, if any.
    pub sysid: Option<u8>,
    /// Human-readable detail ("gcs: GCS 255 heartbeat lost", "255 -> 254").
    pub detail: String,
}

impl LogEvent {
    pub fn new(kind: &'static str, sysid: Option<u8>, detail: impl Into<String>) -> Self {
        Self {
            kind,
            sysid,
            detail: detail.into(),
        }
    }
}

/// Where, how big, how many old files.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EventLogConfig {
    /// The folder of `events.jsonl`, normally `DATA_DIR/events`.
    pub dir: PathBuf,
    /// `events.jsonl` is rotated before a line would take it past this. A
    /// single line longer than this still gets a file of its own.
    pub max_bytes: u64,
    /// How many rotated files (`events.1.jsonl` …) are kept; 0 keeps none.
    pub keep: usize,
}

impl EventLogConfig {
    pub const DEFAULT_MAX_BYTES: u64 = 10 * 1024 * 1024;
    pub const DEFAULT_KEEP: usize = 5;

    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            max_bytes: Self::DEFAULT_MAX_BYTES,
            keep: Self::DEFAULT_KEEP,
        }
    }
}

/// Counters since [`EventLog::start`], shared by all clones of the handle.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EventLogStats {
    /// Lines written to the file.
    pub written: u64,
    /// Events not queued: the queue was full, or the writer had stopped.
    pub dropped: u64,
    /// Lines lost to a disk error (open or write).
    pub write_errors: u64,
    /// Completed rotations.
    pub rotations: u64,
}

/// Why the event log could not start.
#[derive(Debug, thiserror::Error)]
pub enum EventLogError {
    #[error(
        "cannot create the event log folder {}: {} is a file, not a folder — move that file \
         away, or pass --data-dir DIR to use another data directory",
        dir.display(),
        blocker.display()
    )]
    NotAFolder { dir: PathBuf, blocker: PathBuf },
    #[error(
        "cannot create the event log folder {}: {source} — make it writable, or pass \
         --data-dir DIR to use another data directory",
        dir.display()
    )]
    Folder { dir: PathBuf, source: io::Error },
    #[error(
        "cannot open the event log {}: {source} — make the folder writable, or pass \
         --data-dir DIR to use another data directory",
        path.display()
    )]
    Open { path: PathBuf, source: io::Error },
    #[error(
        "cannot start the event log writer thread: {source} — the system is out of threads \
         or memory"
    )]
    Thread { source: io::Error },
}

/// The file being written; the rotated ones are `events.{n}.jsonl`.
pub const FILE_NAME: &str = "events.jsonl";

/// Whether `name` is the event log's file or one of its rotations (what
/// the events folder holds of ours).
pub fn is_event_log_name(name: &str) -> bool {
    name == FILE_NAME || file::rotated_index(name).is_some()
}

/// `events.{n}.jsonl`: `n` = 1 is the newest rotated file.
pub fn rotated_file_name(n: usize) -> String {
    format!("events.{n}.jsonl")
}

/// Events queued for the writer before [`EventLog::record`] starts dropping.
pub const DEFAULT_QUEUE_LEN: usize = 1024;
