//! The board emulator behind a pseudo-terminal, on the tokio runtime.
//!
//! Owns the task that moves bytes between the pty and the sans-IO
//! [`Board`], wakes it when [`Board::next_deadline`] says, and publishes
//! its snapshots and records to tests and tools ([`BoardControl`]). It must
//! never decide anything the board does: every behaviour lives in
//! [`Board`], so `--sim`, the loopback and the tests see the same board.

use std::path::PathBuf;
use std::time::Duration;

use tokio::sync::{broadcast, oneshot, watch};

use super::{Board, BoardRecord, BoardSnapshot, EmulatorOptions, TimedRecord};
use crate::firmware::pty::{PtyError, PtyPair};

/// Controls for a running [`PtyBoard`].
#[derive(Debug, Clone)]
pub struct BoardControl {
    stall: watch::Sender<bool>,
    snapshot: watch::Receiver<BoardSnapshot>,
    records: broadcast::Sender<BoardRecord>,
    timed: broadcast::Sender<TimedRecord>,
}

impl BoardControl {
    /// Stalls (or resumes) the board.
    pub fn set_stalled(&self, stalled: bool) {
        let _ = self.stall.send(stalled);
    }
    /// The latest snapshot (updated at 10 Hz and on every executed command).
    pub fn snapshot(&self) -> BoardSnapshot {
        self.snapshot.borrow().clone()
    }
    /// Frames received and commands executed from now on.
    pub fn records(&self) -> broadcast::Receiver<BoardRecord> {
        self.records.subscribe()
    }
    /// As [`BoardControl::records`], each with the time the emulator woke to
    /// handle it (benchmarks).
    pub fn timed_records(&self) -> broadcast::Receiver<TimedRecord> {
        self.timed.subscribe()
    }
    /// A receiver that changes with every snapshot.
    pub fn subscribe(&self) -> watch::Receiver<BoardSnapshot> {
        self.snapshot.clone()
    }
}

/// The board emulator behind a pseudo-terminal, running on the tokio runtime.
#[derive(Debug)]
pub struct PtyBoard {
    path: PathBuf,
    control: BoardControl,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<()>,
}

impl PtyBoard {
    /// Creates the pty, optionally a stable symlink to it, boots the board
    /// and runs it until [`PtyBoard::shutdown`] or drop.
    pub fn spawn(opts: EmulatorOptions, symlink: Option<PathBuf>) -> Result<Self, PtyError> {
        // Bad simulator options fail before a pty or a symlink exists.
        let mut board = Board::try_new(opts)?;
        board.record(true);
        let mut pty = PtyPair::open()?;
        if let Some(link) = &symlink {
            pty.make_symlink(link)?;
        }
        let path = symlink.unwrap_or_else(|| pty.slave_path().to_path_buf());
        let (stall_tx, stall_rx) = watch::channel(false);
        let (snap_tx, snap_rx) = watch::channel(board.snapshot());
        let (records_tx, _) = broadcast::channel(4096);
        let (timed_tx, _) = broadcast::channel(4096);
        let (stop_tx, stop_rx) = oneshot::channel();
        let task = tokio::spawn(run_board(
            pty,
            board,
            stall_rx,
            snap_tx,
            records_tx.clone(),
            timed_tx.clone(),
            stop_rx,
        ));
        Ok(Self {
            path,
            control: BoardControl {
                stall: stall_tx,
                snapshot: snap_rx,
                records: records_tx,
                timed: timed_tx,
            },
            stop: Some(stop_tx),
            task,
        })
    }

    /// The path a serial program opens (the symlink if one was asked for).
    pub fn path(&self) -> &std::path::Path {
        &self.path
    }

    pub fn control(&self) -> BoardControl {
        self.control.clone()
    }

    /// Stops the board and closes the pty (the host sees the device vanish).
    pub async fn shutdown(mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        let _ = (&mut self.task).await;
    }
}

impl Drop for PtyBoard {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn run_board(
    pty: PtyPair,
    mut board: Board,
    mut stall: watch::Receiver<bool>,
    snapshots: watch::Sender<BoardSnapshot>,
    records: broadcast::Sender<BoardRecord>,
    timed: broadcast::Sender<TimedRecord>,
    mut stop: oneshot::Receiver<()>,
) {
    let origin = tokio::time::Instant::now();
    let now = || tokio::time::Instant::now() - origin;
    let mut out = Vec::with_capacity(4096);
    board.start(now(), &mut out);
    let mut buf = [0u8; 512];
    let mut last_snapshot = Duration::ZERO;
    let mut last_executed = 0;
    loop {
        if !out.is_empty() {
            // Bytes the tty cannot take are lost, as on a UART nobody reads.
            if let Err(e) = pty.try_write(&out) {
                tracing::debug!("emulator pty write failed: {e}");
            }
            out.clear();
        }
        let deadline = origin + board.next_deadline();
        tokio::select! {
            _ = &mut stop => break,
            changed = stall.changed() => {
                if changed.is_err() { break; }
                let stalled = *stall.borrow();
                board.set_stalled(stalled);
            }
            read = pty.read(&mut buf) => match read {
                Ok(0) => {}
                Ok(n) => board.receive(&buf[..n], now(), &mut out),
                Err(e) => {
                    tracing::warn!("emulator pty read failed: {e}");
                    break;
                }
            },
            _ = tokio::time::sleep_until(deadline) => {}
        }
        let woke_at = std::time::Instant::now();
        let t = now();
        board.tick(t, &mut out);
        // The snapshot first: whoever sees a record must find the state it led to.
        if t.saturating_sub(last_snapshot) >= Duration::from_millis(100)
            || board.executed_total() != last_executed
        {
            last_snapshot = t;
            last_executed = board.executed_total();
            let _ = snapshots.send(board.snapshot());
        }
        let timed_wanted = timed.receiver_count() > 0;
        for r in board.take_records() {
            if timed_wanted {
                let _ = timed.send(TimedRecord {
                    at: woke_at,
                    record: r.clone(),
                });
            }
            // Nobody listening is fine: records are for tests and tools.
            let _ = records.send(r);
        }
    }
}
