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

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

/// One thing worth an operator's later attention. Pure data: the vehicle core creates these.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LogEvent {
    /// snake_case event name, e.g. "armed", "control_granted",
    /// "failsafe_raised" (the list is in the issue 5 spec, "Event log").
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

/// `events.{n}.jsonl`: `n` = 1 is the newest rotated file.
pub fn rotated_file_name(n: usize) -> String {
    format!("events.{n}.jsonl")
}

/// Events queued for the writer before [`EventLog::record`] starts dropping.
pub const DEFAULT_QUEUE_LEN: usize = 1024;

/// Handle to the writer thread. Clones are cheap and share the queue, the
/// thread and the counters. Dropping every handle without
/// [`shutdown`](Self::shutdown) lets the thread write what is queued and end
/// on its own, but nothing waits for it.
#[derive(Debug, Clone)]
pub struct EventLog {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    tx: SyncSender<Msg>,
    counters: Arc<Counters>,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
}

#[derive(Debug, Default)]
struct Counters {
    written: AtomicU64,
    dropped: AtomicU64,
    write_errors: AtomicU64,
    rotations: AtomicU64,
    warned_full: AtomicBool,
    warned_stopped: AtomicBool,
}

#[derive(Debug)]
enum Msg {
    Event {
        unix_us: u64,
        mono: Duration,
        event: LogEvent,
    },
    Stop,
}

impl EventLog {
    /// Creates `cfg.dir` and `events.jsonl` in it (appending if it exists)
    /// and starts the writer thread.
    pub fn start(cfg: EventLogConfig) -> Result<Self, EventLogError> {
        Self::with_capacity(cfg, DEFAULT_QUEUE_LEN)
    }

    /// [`start`](Self::start) with a queue of `queue_len` events. 0 makes a
    /// rendezvous queue: an event is taken only if the writer is idle.
    pub fn with_capacity(cfg: EventLogConfig, queue_len: usize) -> Result<Self, EventLogError> {
        let file = EventFile::open(&cfg)?;
        tracing::info!(path = %file.path().display(), "event log started");
        Self::spawn(file, queue_len)
    }

    /// Like [`start`](Self::start), but a folder or file that cannot be
    /// opened (read-only or full data directory, a file in the way) does not
    /// stop the vehicle: the log starts closed, returns why, and the writer
    /// tries again at every event, so it recovers when the disk does. Events
    /// until then are lost and counted (`write_errors`).
    pub fn start_or_degraded(cfg: EventLogConfig) -> (Self, Option<EventLogError>) {
        let (file, problem) = match EventFile::open(&cfg) {
            Ok(file) => (file, None),
            Err(e) => (EventFile::closed(&cfg), Some(e)),
        };
        match Self::spawn(file, DEFAULT_QUEUE_LEN) {
            Ok(log) => {
                if problem.is_none() {
                    tracing::info!(dir = %cfg.dir.display(), "event log started");
                }
                (log, problem)
            }
            // No thread: a log whose writer is gone drops and counts every event.
            Err(e) => {
                let (tx, _) = std::sync::mpsc::sync_channel(0);
                let log = Self {
                    inner: Arc::new(Inner {
                        tx,
                        counters: Arc::new(Counters::default()),
                        thread: Mutex::new(None),
                    }),
                };
                (log, Some(problem.unwrap_or(e)))
            }
        }
    }

    fn spawn(file: EventFile, queue_len: usize) -> Result<Self, EventLogError> {
        let counters = Arc::new(Counters::default());
        let (tx, rx) = std::sync::mpsc::sync_channel(queue_len);
        let thread_counters = Arc::clone(&counters);
        // A thread, not a task: file writes may block, and must not hold up
        // a runtime worker (or the vehicle task sharing it).
        let thread = std::thread::Builder::new()
            .name("neptunus-events".into())
            .spawn(move || run_writer(file, &rx, &thread_counters))
            .map_err(|source| EventLogError::Thread { source })?;
        Ok(Self {
            inner: Arc::new(Inner {
                tx,
                counters,
                thread: Mutex::new(Some(thread)),
            }),
        })
    }

    /// Queues one event for the file. Never blocks and never fails: when the
    /// queue is full or the writer has stopped, the event is dropped and
    /// counted (and that is logged once per cause).
    pub fn record(&self, unix_us: u64, mono: Duration, ev: &LogEvent) {
        let msg = Msg::Event {
            unix_us,
            mono,
            event: ev.clone(),
        };
        let (warned, why) = match self.inner.tx.try_send(msg) {
            Ok(()) => return,
            Err(TrySendError::Full(_)) => (
                &self.inner.counters.warned_full,
                "event log cannot keep up: dropping events (logged once)",
            ),
            Err(TrySendError::Disconnected(_)) => (
                &self.inner.counters.warned_stopped,
                "event log writer has stopped: dropping events (logged once)",
            ),
        };
        self.inner.counters.dropped.fetch_add(1, Ordering::Relaxed);
        if !warned.swap(true, Ordering::Relaxed) {
            tracing::warn!(event = ev.kind, "{why}");
        }
    }

    pub fn stats(&self) -> EventLogStats {
        let c = &self.inner.counters;
        EventLogStats {
            written: c.written.load(Ordering::Relaxed),
            dropped: c.dropped.load(Ordering::Relaxed),
            write_errors: c.write_errors.load(Ordering::Relaxed),
            rotations: c.rotations.load(Ordering::Relaxed),
        }
    }

    /// Writes what is queued, stops the writer thread, waits for it and
    /// returns the final counters. Blocking (it waits for the disk): call it
    /// from shutdown code, via `spawn_blocking` in async code. It stops the
    /// writer for every clone; their later events are counted as dropped. An
    /// event another clone queues while this runs may be lost uncounted.
    pub fn shutdown(self) -> EventLogStats {
        let thread = self
            .inner
            .thread
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        if let Some(thread) = thread {
            // Blocks only while the writer drains a full queue; fails only
            // if the writer is already gone.
            let _ = self.inner.tx.send(Msg::Stop);
            if thread.join().is_err() {
                tracing::warn!("event log writer thread panicked");
            }
        }
        self.stats()
    }
}

fn run_writer(mut file: EventFile, rx: &Receiver<Msg>, counters: &Counters) {
    let mut health = Health::default();
    let mut line = Vec::with_capacity(256);
    // Ends on Stop, or when every handle is gone (Disconnected comes only
    // after the queue is empty).
    while let Ok(Msg::Event {
        unix_us,
        mono,
        event,
    }) = rx.recv()
    {
        write_event(
            &mut file,
            &mut line,
            unix_us,
            mono,
            &event,
            counters,
            &mut health,
        );
    }
    // Events another clone queued behind Stop are written rather than
    // dropped with the queue.
    while let Ok(Msg::Event {
        unix_us,
        mono,
        event,
    }) = rx.try_recv()
    {
        write_event(
            &mut file,
            &mut line,
            unix_us,
            mono,
            &event,
            counters,
            &mut health,
        );
    }
}

/// Which kinds of disk trouble are ongoing: each is logged once when it
/// starts and once when it ends, never per line.
#[derive(Debug, Default)]
struct Health {
    write_failing: bool,
    lost_lines: u64,
    rotate_failing: bool,
}

fn write_event(
    file: &mut EventFile,
    line: &mut Vec<u8>,
    unix_us: u64,
    mono: Duration,
    event: &LogEvent,
    counters: &Counters,
    health: &mut Health,
) {
    line.clear();
    if let Err(e) = write_line(line, unix_us, mono, event) {
        // Unreachable with these field types; counted rather than trusted.
        counters.write_errors.fetch_add(1, Ordering::Relaxed);
        tracing::warn!(error = %e, event = event.kind, "cannot format an event log line");
        return;
    }
    if file.wants_rotation(line.len()) {
        match file.rotate() {
            Ok(()) => {
                counters.rotations.fetch_add(1, Ordering::Relaxed);
                if std::mem::take(&mut health.rotate_failing) {
                    tracing::info!(dir = %file.dir.display(), "event log rotates again");
                }
            }
            Err(e) => {
                if !std::mem::replace(&mut health.rotate_failing, true) {
                    tracing::warn!(
                        dir = %file.dir.display(), error = %e,
                        "cannot rotate the event log; appending past its size limit (logged once)"
                    );
                }
            }
        }
    }
    match file.append(line) {
        Ok(()) => {
            counters.written.fetch_add(1, Ordering::Relaxed);
            if std::mem::take(&mut health.write_failing) {
                tracing::info!(
                    path = %file.path().display(),
                    lost = std::mem::take(&mut health.lost_lines),
                    "event log writable again"
                );
            }
        }
        Err(e) => {
            counters.write_errors.fetch_add(1, Ordering::Relaxed);
            health.lost_lines += 1;
            if !std::mem::replace(&mut health.write_failing, true) {
                tracing::warn!(
                    path = %file.path().display(), error = %e,
                    "cannot write the event log; losing events until it works again (logged once)"
                );
            }
        }
    }
}

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
fn write_line(
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

/// The JSON line [`EventLog`] writes for this event (newline included).
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

/// `events.jsonl` and its rotation; synchronous, run by the writer thread.
#[derive(Debug)]
struct EventFile {
    dir: PathBuf,
    path: PathBuf,
    max_bytes: u64,
    keep: usize,
    /// `None` after an error: reopened (and the folder recreated) at the
    /// next line, so the log recovers when the disk does.
    file: Option<File>,
    /// Bytes in the current file, including a torn line found on open.
    size: u64,
    /// The file does not end with a newline (a torn line): end it first.
    torn: bool,
}

impl EventFile {
    fn open(cfg: &EventLogConfig) -> Result<Self, EventLogError> {
        if let Err(source) = std::fs::create_dir_all(&cfg.dir) {
            return Err(match file_in_the_way(&cfg.dir) {
                Some(blocker) => EventLogError::NotAFolder {
                    dir: cfg.dir.clone(),
                    blocker,
                },
                None => EventLogError::Folder {
                    dir: cfg.dir.clone(),
                    source,
                },
            });
        }
        let mut file = Self {
            dir: cfg.dir.clone(),
            path: cfg.dir.join(FILE_NAME),
            max_bytes: cfg.max_bytes,
            keep: cfg.keep,
            file: None,
            size: 0,
            torn: false,
        };
        file.reopen().map_err(|source| EventLogError::Open {
            path: file.path.clone(),
            source,
        })?;
        Ok(file)
    }

    /// Not open yet: the first event opens it (creating the folder).
    fn closed(cfg: &EventLogConfig) -> Self {
        Self {
            dir: cfg.dir.clone(),
            path: cfg.dir.join(FILE_NAME),
            max_bytes: cfg.max_bytes,
            keep: cfg.keep,
            file: None,
            size: 0,
            torn: false,
        }
    }

    fn path(&self) -> &Path {
        &self.path
    }

    fn reopen(&mut self) -> io::Result<()> {
        std::fs::create_dir_all(&self.dir)?;
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(&self.path)?;
        let size = file.metadata()?.len();
        let mut torn = false;
        if size > 0 {
            let mut last = [0u8];
            file.seek(SeekFrom::End(-1))?;
            file.read_exact(&mut last)?;
            torn = last[0] != b'\n';
        }
        self.file = Some(file);
        self.size = size;
        self.torn = torn;
        Ok(())
    }

    /// Rotate before writing `line_len` bytes? Never for an empty file, so
    /// an oversized line gets a file of its own instead of a rotation loop.
    fn wants_rotation(&self, line_len: usize) -> bool {
        let line_len = line_len as u64 + u64::from(self.torn);
        self.size > 0 && self.size.saturating_add(line_len) > self.max_bytes
    }

    /// Writes one whole line with one `write` call (so it appears at once
    /// and is never interleaved), reopening the file first if needed.
    fn append(&mut self, line: &[u8]) -> io::Result<()> {
        if self.file.is_none() {
            self.reopen()?;
        }
        let Some(file) = self.file.as_mut() else {
            return Err(io::Error::other("event log file not open"));
        };
        let result = if self.torn {
            let mut buf = Vec::with_capacity(line.len() + 1);
            buf.push(b'\n');
            buf.extend_from_slice(line);
            file.write_all(&buf).map(|()| buf.len())
        } else {
            file.write_all(line).map(|()| line.len())
        };
        match result {
            Ok(n) => {
                self.size += n as u64;
                self.torn = false;
                Ok(())
            }
            Err(e) => {
                // Part of the line may be on disk: reopen next time, which
                // looks at the last byte and ends a torn line.
                self.file = None;
                Err(e)
            }
        }
    }

    /// `events.jsonl` → `events.1.jsonl`, `.1` → `.2` … and delete what
    /// would go past `keep`; the next [`append`](Self::append) starts a new
    /// `events.jsonl`.
    fn rotate(&mut self) -> io::Result<()> {
        // Closed first: after the rename this handle would write into the
        // rotated file. On failure the next append reopens `events.jsonl`.
        self.file = None;
        self.prune()?;
        for n in (1..self.keep).rev() {
            let from = self.dir.join(rotated_file_name(n));
            match std::fs::rename(&from, self.dir.join(rotated_file_name(n + 1))) {
                Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
        if self.keep == 0 {
            std::fs::remove_file(&self.path)?;
        } else {
            std::fs::rename(&self.path, self.dir.join(rotated_file_name(1)))?;
        }
        tracing::info!(path = %self.path.display(), "event log rotated");
        self.reopen()
    }

    /// Deletes rotated files numbered `keep` or more: after the shift they
    /// would be past `keep`. Scans the folder so leftovers of a larger
    /// `keep` from an earlier run go too.
    fn prune(&self) -> io::Result<()> {
        for entry in std::fs::read_dir(&self.dir)? {
            let entry = entry?;
            let name = entry.file_name();
            let Some(n) = name.to_str().and_then(rotated_index) else {
                continue;
            };
            if n >= self.keep {
                match std::fs::remove_file(entry.path()) {
                    Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
                    _ => {}
                }
            }
        }
        Ok(())
    }
}

/// `n` of a file named exactly `events.{n}.jsonl`, n ≥ 1.
fn rotated_index(name: &str) -> Option<usize> {
    let digits = name.strip_prefix("events.")?.strip_suffix(".jsonl")?;
    let n: usize = digits.parse().ok()?;
    (n >= 1 && rotated_file_name(n) == name).then_some(n)
}

/// The first existing path on the way to `dir` that is not a folder.
fn file_in_the_way(dir: &Path) -> Option<PathBuf> {
    let mut ancestors: Vec<&Path> = dir.ancestors().collect();
    ancestors.reverse();
    ancestors
        .into_iter()
        .filter(|p| !p.as_os_str().is_empty())
        .find(|p| p.exists() && !p.is_dir())
        .map(Path::to_path_buf)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn cfg(dir: &Path, max_bytes: u64, keep: usize) -> EventLogConfig {
        EventLogConfig {
            dir: dir.to_path_buf(),
            max_bytes,
            keep,
        }
    }

    #[test]
    fn rotated_names_are_recognised_exactly() {
        assert_eq!(rotated_index("events.1.jsonl"), Some(1));
        assert_eq!(rotated_index("events.12.jsonl"), Some(12));
        for other in [
            "events.jsonl",
            "events.0.jsonl",
            "events.01.jsonl",
            "events.+1.jsonl",
            "events.1.jsonl.bak",
            "tlog.1.jsonl",
        ] {
            assert_eq!(rotated_index(other), None, "{other}");
        }
    }

    /// A write error loses that line only: the writer reopens the file for
    /// the next line and carries on where the disk works again.
    #[cfg(target_os = "linux")]
    #[test]
    fn recovers_after_a_write_error() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join(FILE_NAME);
        // /dev/full fails every write with ENOSPC, even for root.
        std::os::unix::fs::symlink("/dev/full", &path).unwrap();
        let mut file = EventFile::open(&cfg(tmp.path(), 1 << 20, 2)).unwrap();
        let err = file.append(b"{\"lost\":1}\n").unwrap_err();
        assert_eq!(err.raw_os_error(), Some(28), "{err}"); // ENOSPC
        assert!(file.append(b"{\"lost\":2}\n").is_err());
        std::fs::remove_file(&path).unwrap();
        file.append(b"{\"kept\":3}\n").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "{\"kept\":3}\n");
    }

    /// With nothing to shift into (keep = 0) a rotation starts over.
    #[test]
    fn keep_zero_rotation_keeps_no_old_file() {
        let tmp = tempfile::tempdir().unwrap();
        let mut file = EventFile::open(&cfg(tmp.path(), 8, 0)).unwrap();
        file.append(b"0123456\n").unwrap();
        assert!(file.wants_rotation(2));
        file.rotate().unwrap();
        file.append(b"a\n").unwrap();
        let mut names: Vec<_> = std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, [FILE_NAME]);
        assert_eq!(std::fs::read_to_string(file.path()).unwrap(), "a\n");
    }
}
