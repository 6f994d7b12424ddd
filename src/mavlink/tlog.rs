//! Telemetry log (`.tlog`) files in the format pymavlink's `mavlogdump.py`
//! and QGroundControl replay read: each record is an 8-byte big-endian Unix
//! time in microseconds followed by one raw MAVLink frame.
//!
//! Owns: naming, writing, flushing and size-based rotation of the files, the
//! total size cap of the folder (oldest of *our* files deleted first, at
//! start and at each rotation; nothing else in the folder is touched), and
//! scrubbing secrets out of frames before they are written. It must never
//! write a signing key: SETUP_SIGNING (id 256) is logged with its key zeroed.
//! The writer is synchronous on purpose; the router runs it on a dedicated
//! thread (`TlogHandle`) so disk stalls never reach a socket or the
//! vehicle. Recording never waits: when the thread cannot keep up, records
//! are dropped (logged once) rather than queued without bound.

use std::borrow::Cow;
use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use crate::wallclock::WallClock;

/// Where and how big, and by which clock.
#[derive(Debug, Clone)]
pub struct TlogConfig {
    pub dir: PathBuf,
    /// A new file is started before a record would take the current one past
    /// this (at most half of `total_bytes`, so the cap always leaves room
    /// for the file being written).
    pub max_bytes: u64,
    /// The tlog files in `dir` (ours, by name) add up to at most this: the
    /// oldest are deleted at start and at each rotation.
    pub total_bytes: u64,
    /// Names and time stamps come from it; once the ground station in
    /// control sets it, the log goes on in a file named with the new time.
    pub clock: Arc<WallClock>,
}

impl TlogConfig {
    pub const DEFAULT_MAX_BYTES: u64 = 64 * 1024 * 1024;
    pub const DEFAULT_TOTAL_BYTES: u64 = 256 * 1024 * 1024;

    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            max_bytes: Self::DEFAULT_MAX_BYTES,
            total_bytes: Self::DEFAULT_TOTAL_BYTES,
            clock: WallClock::system(),
        }
    }

    /// The size at which files rotate: `max_bytes`, at most half the total.
    pub fn file_bytes(&self) -> u64 {
        self.max_bytes.min(self.total_bytes / 2).max(1)
    }
}

/// The files this run of the vehicle has written its telemetry log to
/// (every piece after rotations and a corrected clock): what LOG_ERASE
/// must never delete. Shared between the log's thread and whoever asks.
#[derive(Debug, Clone, Default)]
pub struct TlogRun(Arc<Mutex<Vec<PathBuf>>>);

impl TlogRun {
    pub fn add(&self, path: PathBuf) {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(path);
    }

    pub fn contains(&self, path: &Path) -> bool {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .any(|p| p == path)
    }
}

const SETUP_SIGNING_ID: u32 =
    <crate::dialect::neptunus::SETUP_SIGNING_DATA as mavlink_core::MessageData>::ID;
/// `secret_key[32]` sits after `initial_timestamp` (u64), `target_system`
/// and `target_component` (u8 each) in SETUP_SIGNING's wire order.
const SETUP_SIGNING_KEY: std::ops::Range<usize> = 10..42;
const V2_HEADER_LEN: usize = 10;

/// A buffered writer of one session's `.tlog` files.
#[derive(Debug)]
pub struct TlogWriter {
    dir: PathBuf,
    session: String,
    max_bytes: u64,
    total_bytes: u64,
    /// 1 for `{session}.tlog`, n for `{session}-n.tlog`.
    index: u32,
    path: PathBuf,
    file: BufWriter<File>,
    written: u64,
    /// Where the files it opens are noted, if anywhere.
    run: Option<TlogRun>,
}

impl TlogWriter {
    /// Creates `{dir}/{session}.tlog` (and `dir` if needed). An existing file
    /// is never overwritten: the next free `{session}-n.tlog` is used instead.
    /// Old tlogs are deleted first, oldest first, until they and the new
    /// file's room fit in `total_bytes`.
    pub fn create(cfg: &TlogConfig, session: &str) -> io::Result<Self> {
        std::fs::create_dir_all(&cfg.dir)?;
        let max_bytes = cfg.file_bytes();
        prune(&cfg.dir, None, cfg.total_bytes.saturating_sub(max_bytes));
        let (index, path, file) = open_next(&cfg.dir, session, 1)?;
        Ok(Self {
            dir: cfg.dir.clone(),
            session: session.to_owned(),
            max_bytes,
            total_bytes: cfg.total_bytes,
            index,
            path,
            file: BufWriter::new(file),
            written: 0,
            run: None,
        })
    }

    /// Notes in `run` the file being written now and every one after it.
    pub fn note_files_in(&mut self, run: TlogRun) {
        run.add(self.path.clone());
        self.run = Some(run);
    }

    fn opened(&mut self, path: PathBuf) {
        if let Some(run) = &self.run {
            run.add(path.clone());
        }
        self.path = path;
    }

    /// Appends one record, rotating first if it would not fit.
    pub fn write_frame(&mut self, unix_time_us: u64, raw: &[u8]) -> io::Result<()> {
        let record_len = 8 + raw.len() as u64;
        if self.written > 0 && self.written + record_len > self.max_bytes {
            self.rotate()?;
        }
        let raw = redact(raw);
        self.file.write_all(&unix_time_us.to_be_bytes())?;
        self.file.write_all(&raw)?;
        self.written += record_len;
        Ok(())
    }

    pub fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }

    /// The file being written now.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Goes on in `{session}.tlog` (the clock was set: the old name is wrong).
    pub fn new_session(&mut self, session: &str) -> io::Result<()> {
        self.file.flush()?;
        let (index, path, file) = open_next(&self.dir, session, 1)?;
        tracing::info!(path = %path.display(), "telemetry log goes on under the corrected time");
        self.session = session.to_owned();
        self.index = index;
        self.opened(path);
        self.file = BufWriter::new(file);
        self.written = 0;
        prune(
            &self.dir,
            Some(&self.path),
            self.total_bytes.saturating_sub(self.max_bytes),
        );
        Ok(())
    }

    fn rotate(&mut self) -> io::Result<()> {
        self.file.flush()?;
        let (index, path, file) = open_next(&self.dir, &self.session, self.index + 1)?;
        tracing::info!(path = %path.display(), "telemetry log rotated");
        self.index = index;
        self.opened(path);
        self.file = BufWriter::new(file);
        self.written = 0;
        prune(
            &self.dir,
            Some(&self.path),
            self.total_bytes.saturating_sub(self.max_bytes),
        );
        Ok(())
    }
}

/// `(session, index)` of a file name this module gives
/// (`neptunus-YYYYMMDD-HHMMSS.tlog`, `neptunus-YYYYMMDD-HHMMSS-N.tlog`):
/// their order is the order they were written in (UTC names sort by time).
pub fn parse_file_name(name: &str) -> Option<(&str, u32)> {
    let stem = name.strip_suffix(".tlog")?;
    let (session, index) = match stem.get(24..) {
        Some("") => (stem, 1),
        Some(rest) => (&stem[..24], rest.strip_prefix('-')?.parse().ok()?),
        None => return None,
    };
    let digits = session.strip_prefix("neptunus-")?;
    let ok = digits.len() == 15
        && digits.bytes().enumerate().all(|(i, b)| {
            if i == 8 {
                b == b'-'
            } else {
                b.is_ascii_digit()
            }
        });
    ok.then_some((session, index))
}

/// Deletes our tlog files in `dir`, oldest first, until those left (other
/// than `current`) add up to at most `budget` bytes. Never fails: a file
/// that cannot be deleted is logged and skipped.
fn prune(dir: &Path, current: Option<&Path>, budget: u64) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut files: Vec<(String, u32, PathBuf, u64)> = entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let (session, index) = parse_file_name(&name)?;
            let path = e.path();
            if Some(path.as_path()) == current {
                return None;
            }
            // symlink_metadata: a link someone put here is not ours to follow.
            let meta = std::fs::symlink_metadata(&path).ok()?;
            meta.is_file()
                .then(|| (session.to_owned(), index, path, meta.len()))
        })
        .collect();
    files.sort();
    let mut total: u64 = files.iter().map(|f| f.3).sum();
    for (_, _, path, len) in files {
        if total <= budget {
            break;
        }
        match std::fs::remove_file(&path) {
            Ok(()) => {
                total -= len;
                tracing::info!(path = %path.display(), bytes = len, "old telemetry log deleted (tlog_total_mb)");
            }
            Err(e) => {
                tracing::warn!(path = %path.display(), error = %e, "cannot delete an old telemetry log");
            }
        }
    }
}

fn file_name(session: &str, index: u32) -> String {
    if index <= 1 {
        format!("{session}.tlog")
    } else {
        format!("{session}-{index}.tlog")
    }
}

fn open_next(dir: &Path, session: &str, mut index: u32) -> io::Result<(u32, PathBuf, File)> {
    loop {
        let path = dir.join(file_name(session, index));
        match OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(file) => return Ok((index, path, file)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists && index < u32::MAX => index += 1,
            Err(e) => return Err(e),
        }
    }
}

/// Returns the frame as it may be logged: a MAVLink 2 SETUP_SIGNING has its
/// secret key zeroed. Its CRC is left as it was, so the logged frame fails
/// its CRC check on replay; that is deliberate, since recomputing it would
/// make a forged all-zero key ("disable signing") look genuine.
pub fn redact(raw: &[u8]) -> Cow<'_, [u8]> {
    let is_setup_signing = raw.len() >= V2_HEADER_LEN
        && raw[0] == mavlink_core::MAV_STX_V2
        && u32::from_le_bytes([raw[7], raw[8], raw[9], 0]) == SETUP_SIGNING_ID;
    if !is_setup_signing {
        return Cow::Borrowed(raw);
    }
    let mut owned = raw.to_vec();
    // MAVLink 2 trims trailing zero bytes from payloads, so only the key
    // bytes actually present are zeroed, never the CRC after them.
    let payload_len = usize::from(raw[1]);
    let start = V2_HEADER_LEN + SETUP_SIGNING_KEY.start;
    let end = V2_HEADER_LEN + SETUP_SIGNING_KEY.end.min(payload_len);
    if let Some(key) = owned.get_mut(start..end) {
        key.fill(0);
    }
    Cow::Owned(owned)
}

// ---------------------------------------------------------------------------
// the writer thread
// ---------------------------------------------------------------------------

/// Records queued for the telemetry log thread.
const TLOG_QUEUE: usize = 8192;
const TLOG_FLUSH_PERIOD: Duration = Duration::from_secs(1);
/// How long the thread gathers records before it writes them. The queue
/// holds far more than this many seconds of the busiest traffic.
const TLOG_BATCH: Duration = Duration::from_millis(250);

enum TlogMsg {
    Frame(u64, Arc<[u8]>),
    Stop,
}

#[derive(Clone)]
pub(super) struct TlogSender {
    tx: std::sync::mpsc::SyncSender<TlogMsg>,
    dropped: Arc<AtomicU64>,
    clock: Arc<WallClock>,
}

impl TlogSender {
    /// Records `raw`, stamped now.
    pub(super) fn record(&self, raw: Arc<[u8]>) {
        let unix_time_us = self.clock.unix_us();
        if let Err(std::sync::mpsc::TrySendError::Full(_)) =
            self.tx.try_send(TlogMsg::Frame(unix_time_us, raw))
            && self.dropped.fetch_add(1, Ordering::Relaxed) == 0
        {
            tracing::warn!("telemetry log cannot keep up: dropping records (logged once)");
        }
    }
}

pub(super) struct TlogHandle {
    pub(super) sender: TlogSender,
    /// The files this run writes.
    pub(super) run: TlogRun,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
}

impl TlogHandle {
    /// Creates the session's first file and starts the thread writing it.
    pub(super) fn spawn(cfg: &TlogConfig) -> io::Result<Self> {
        let clock = Arc::clone(&cfg.clock);
        let generation = clock.generation();
        let mut writer = TlogWriter::create(cfg, &session_name(clock.unix_us()))?;
        let run = TlogRun::default();
        writer.note_files_in(run.clone());
        tracing::info!(path = %writer.path().display(), "telemetry log started");
        let (tx, rx) = std::sync::mpsc::sync_channel(TLOG_QUEUE);
        // A thread, not a task: file writes may block, and must not hold up
        // a runtime worker that is serving sockets.
        let thread = std::thread::Builder::new()
            .name("neptunus-tlog".into())
            .spawn({
                let clock = Arc::clone(&clock);
                move || run_tlog(writer, rx, &clock, generation)
            })?;
        Ok(Self {
            sender: TlogSender {
                tx,
                dropped: Arc::new(AtomicU64::new(0)),
                clock,
            },
            run,
            thread: Mutex::new(Some(thread)),
        })
    }

    pub(super) async fn stop(&self) {
        let thread = self
            .thread
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        let Some(thread) = thread else { return };
        let tx = self.sender.tx.clone();
        let joined = tokio::task::spawn_blocking(move || {
            // Blocks only while the thread drains a full queue.
            let _ = tx.send(TlogMsg::Stop);
            thread.join()
        })
        .await;
        if !matches!(joined, Ok(Ok(()))) {
            tracing::warn!("telemetry log thread did not stop cleanly");
        }
    }
}

fn run_tlog(
    mut writer: TlogWriter,
    rx: std::sync::mpsc::Receiver<TlogMsg>,
    clock: &WallClock,
    mut generation: u64,
) {
    use std::sync::mpsc::RecvTimeoutError;
    let mut next_flush = std::time::Instant::now() + TLOG_FLUSH_PERIOD;
    let mut dirty = false;
    let mut failed = false;
    let mut report = |result: io::Result<()>, path: &std::path::Path| {
        if let Err(e) = result
            && !std::mem::replace(&mut failed, true)
        {
            tracing::warn!(path = %path.display(), error = %e, "cannot write the telemetry log (logged once)");
        }
    };
    'run: loop {
        let wait = next_flush.saturating_duration_since(std::time::Instant::now());
        let mut next = match rx.recv_timeout(wait) {
            Ok(msg) => Some(msg),
            Err(RecvTimeoutError::Disconnected) => break,
            Err(RecvTimeoutError::Timeout) => None,
        };
        let batch = next.is_some();
        // Everything queued is written in one go, then the thread sleeps a
        // while, so it wakes a few times a second rather than at every
        // message (each frame carries the time it was sent or received).
        while let Some(msg) = next {
            match msg {
                TlogMsg::Frame(time_us, raw) => {
                    let now_generation = clock.generation();
                    if now_generation != generation {
                        generation = now_generation;
                        let result = writer.new_session(&session_name(clock.unix_us()));
                        report(result, writer.path());
                    }
                    let result = writer.write_frame(time_us, &raw);
                    report(result, writer.path());
                    dirty = true;
                }
                TlogMsg::Stop => break 'run,
            }
            next = rx.try_recv().ok();
        }
        if batch {
            std::thread::sleep(TLOG_BATCH);
        }
        let now = std::time::Instant::now();
        if now >= next_flush {
            if dirty {
                let result = writer.flush();
                report(result, writer.path());
                dirty = false;
            }
            next_flush = now + TLOG_FLUSH_PERIOD;
        }
    }
    let result = writer.flush();
    report(result, writer.path());
}

/// `neptunus-YYYYMMDD-HHMMSS` in UTC: sorts by time, and reads the same on
/// the ROV (which may have no time zone set) and on the laptop.
fn session_name(unix_us: u64) -> String {
    let secs = unix_us / 1_000_000;
    let rem = secs % 86_400;
    let (y, m, d) = crate::eventlog::civil_from_days(secs / 86_400);
    format!(
        "neptunus-{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        (rem / 60) % 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dialect::neptunus::{MavMessage, SETUP_SIGNING_DATA};

    #[test]
    fn only_our_names_parse() {
        assert_eq!(
            parse_file_name("neptunus-20261124-223000.tlog"),
            Some(("neptunus-20261124-223000", 1))
        );
        assert_eq!(
            parse_file_name("neptunus-20261124-223000-12.tlog"),
            Some(("neptunus-20261124-223000", 12))
        );
        for other in [
            "neptunus-20261124-223000.tlog.bak",
            "neptunus-2026112-223000.tlog",
            "neptunus-20261124-223000-.tlog",
            "neptunus-20261124-223000-x.tlog",
            "other.tlog",
            "neptunus.log",
            "../neptunus-20261124-223000.tlog",
        ] {
            assert_eq!(parse_file_name(other), None, "{other}");
        }
    }

    #[test]
    fn key_offset_matches_the_dialect() {
        let key = [0xA5; 32];
        let msg = MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
            initial_timestamp: 1,
            target_system: 2,
            target_component: 3,
            secret_key: key,
        });
        let raw = crate::mavlink::frame::encode_v2(1, 1, 0, &msg);
        let at = V2_HEADER_LEN + SETUP_SIGNING_KEY.start;
        assert_eq!(&raw[at..at + 32], &key);
        let redacted = redact(&raw);
        assert!(redacted[at..at + 32].iter().all(|&b| b == 0));
        assert_eq!(redacted.len(), raw.len());
        assert_eq!(redacted[raw.len() - 2..], raw[raw.len() - 2..]);
    }

    #[test]
    fn session_names_are_utc_dates() {
        let t = 1_700_000_000 * 1_000_000;
        assert_eq!(session_name(t), "neptunus-20231114-221320");
        assert_eq!(session_name(0), "neptunus-19700101-000000");
        let leap = 951_782_400 * 1_000_000; // 2000-02-29
        assert_eq!(session_name(leap), "neptunus-20000229-000000");
    }
}
