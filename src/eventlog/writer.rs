//! The event log's handle and its writer thread.
//!
//! Owns [`EventLog`] (queueing never blocks the caller; a full queue or a
//! stopped writer drops and counts), the thread that drains the queue, and
//! the once-per-trouble logging of disk errors.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use super::file::EventFile;
use super::line::write_line;
use super::{DEFAULT_QUEUE_LEN, EventLogConfig, EventLogError, EventLogStats, LogEvent};

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
