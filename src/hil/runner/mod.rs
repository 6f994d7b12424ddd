//! The genuine board on a pseudo-terminal: the firmware in simavr, paced to
//! the wall clock on its own thread, its UART0 bridged to a pty that the
//! serial link opens like `/dev/ttyO1`.
//!
//! Owns the pacing (simulated cycles against the wall clock, in 1 ms
//! slices; the simulator's speed against real time is measured, not
//! assumed), the bridge (bytes from the host go onto the UART line at its
//! baud rate, bytes the firmware prints go to the pty), and the controls
//! and figures a test or a bench reads ([`GenuineControl`]). The board
//! itself — what is wired to it (analog inputs, the sensors on its I2C
//! bus) and its outputs measured — is `super::bench`'s. It never decides
//! anything the board does: that is the firmware's.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::Serialize;

use super::avr::{AvrError, F_CPU_HZ};
use super::bench::{Analog, Bench, Wiring};
use super::bno055::Attitude;
use super::compile::Firmware;
use super::ms5803::Water;
use super::pins::{PinsReport, PulseChange};
use crate::firmware::pty::{PtyError, open_raw, remove_link_to, symlink_to};

mod pacing;
use pacing::Runner;

/// Simulated time run between looks at the wall clock, the pty and the controls.
const SLICE_CYCLES: u64 = F_CPU_HZ / 1000;
/// Behind the wall clock by more than this, the runner stops trying to catch
/// up (and counts a slip): a board that cannot keep real time runs slow
/// rather than in bursts.
const MAX_DEBT_CYCLES: u64 = F_CPU_HZ / 4;
/// How often the speed figures are renewed.
const SPEED_WINDOW: Duration = Duration::from_secs(1);

/// Errors starting the genuine board.
#[derive(Debug, thiserror::Error)]
pub enum GenuineError {
    #[error(transparent)]
    Avr(#[from] AvrError),
    #[error(transparent)]
    Pty(#[from] PtyError),
    #[error("cannot start the simulator thread: {0}")]
    Thread(io::Error),
}

/// Bytes on the serial line, stamped with the wall time the runner moved them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SerialChunk {
    pub at: Instant,
    /// `true`: host → board; `false`: board → host.
    pub to_board: bool,
    pub bytes: Vec<u8>,
}

/// A pulse change, stamped with the wall time its simulated cycle maps to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedChange {
    pub at: Instant,
    pub change: PulseChange,
}

/// The genuine board right now.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GenuineSnapshot {
    /// Simulated time since power-up (s).
    pub sim_time_s: f64,
    pub pins: PinsReport,
    pub analog: Analog,
    /// What the depth sensor is in.
    pub water: Water,
    /// The vehicle's attitude the IMU senses.
    pub attitude: Attitude,
    /// Simulated seconds per wall second over the last second: 1.0 when the
    /// board keeps real time, below when it cannot.
    pub realtime_ratio: f64,
    /// Simulated seconds per wall second spent simulating: how much faster
    /// than real time simavr could run this firmware on this machine.
    pub speed_ratio: f64,
    /// Times the runner fell more than 250 ms behind and let the debt go.
    pub slips: u64,
    pub resets: u64,
    pub bytes_to_board: u64,
    pub bytes_from_board: u64,
    /// Board output the pty had no room for (nobody reading).
    pub bytes_lost: u64,
    /// Why the simulation stopped, if it did.
    pub error: Option<String>,
}

enum Ctl {
    Analog(Analog),
    Water(Water),
    Attitude(Attitude),
    Reset,
    Inject(Vec<u8>),
    Serial(Sender<SerialChunk>),
    Changes(Sender<TimedChange>),
    Stop,
}

/// Controls for a running [`GenuineBoard`]; cheap to clone, usable from any thread.
#[derive(Debug, Clone)]
pub struct GenuineControl {
    tx: Sender<Ctl>,
    snapshot: Arc<Mutex<GenuineSnapshot>>,
}

impl std::fmt::Debug for Ctl {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Ctl::Analog(_) => "Analog",
            Ctl::Water(_) => "Water",
            Ctl::Attitude(_) => "Attitude",
            Ctl::Reset => "Reset",
            Ctl::Inject(_) => "Inject",
            Ctl::Serial(_) => "Serial",
            Ctl::Changes(_) => "Changes",
            Ctl::Stop => "Stop",
        })
    }
}

impl GenuineControl {
    /// The board and its outputs as last measured (renewed every millisecond
    /// of simulated time).
    pub fn snapshot(&self) -> GenuineSnapshot {
        match self.snapshot.lock() {
            Ok(s) => s.clone(),
            Err(poisoned) => poisoned.into_inner().clone(),
        }
    }
    /// New analog inputs from the next slice on.
    pub fn set_analog(&self, analog: Analog) {
        let _ = self.tx.send(Ctl::Analog(analog));
    }
    /// New depth and water temperature for the depth sensor's next
    /// conversion (the firmware reads it once a second); nothing changes on
    /// a board wired without one.
    pub fn set_water(&self, water: Water) {
        let _ = self.tx.send(Ctl::Water(water));
    }
    /// The vehicle's new attitude, in the IMU's fusion output from its next
    /// read (the firmware reads it about 21 times a second); nothing changes
    /// on a board wired without one.
    pub fn set_attitude(&self, attitude: Attitude) {
        let _ = self.tx.send(Ctl::Attitude(attitude));
    }
    /// Pulls the reset line: the firmware starts again from power-up.
    pub fn reset(&self) {
        let _ = self.tx.send(Ctl::Reset);
    }
    /// Bytes onto the board's receive line as if the host wrote them,
    /// between two of the host's frames (after its next `;`).
    pub fn inject(&self, bytes: Vec<u8>) {
        let _ = self.tx.send(Ctl::Inject(bytes));
    }
    /// Every byte on the serial line from now on, both ways.
    pub fn serial(&self) -> Receiver<SerialChunk> {
        let (tx, rx) = mpsc::channel();
        let _ = self.tx.send(Ctl::Serial(tx));
        rx
    }
    /// Every pulse change from now on.
    pub fn changes(&self) -> Receiver<TimedChange> {
        let (tx, rx) = mpsc::channel();
        let _ = self.tx.send(Ctl::Changes(tx));
        rx
    }
}

/// The genuine firmware in simavr behind a pty, running until dropped.
#[derive(Debug)]
pub struct GenuineBoard {
    path: PathBuf,
    firmware: Firmware,
    control: GenuineControl,
    thread: Option<JoinHandle<()>>,
}

impl GenuineBoard {
    /// Loads `firmware`, powers the board up wired as `rig` says and runs it
    /// in real time behind a fresh pty (reachable at `symlink` if given).
    pub fn spawn(
        firmware: Firmware,
        rig: Wiring,
        symlink: Option<PathBuf>,
    ) -> Result<Self, GenuineError> {
        let analog = rig.analog;
        let elf = firmware.elf.clone();
        let pty = open_raw()?;
        let path = match &symlink {
            Some(link) => {
                symlink_to(&pty.slave_path, link)?;
                link.clone()
            }
            None => pty.slave_path.clone(),
        };
        let snapshot = Arc::new(Mutex::new(GenuineSnapshot {
            sim_time_s: 0.0,
            pins: PinsReport::default(),
            analog,
            water: Water::default(),
            attitude: Attitude::default(),
            realtime_ratio: 0.0,
            speed_ratio: 0.0,
            slips: 0,
            resets: 0,
            bytes_to_board: 0,
            bytes_from_board: 0,
            bytes_lost: 0,
            error: None,
        }));
        let (tx, rx) = mpsc::channel();
        let (ready_tx, ready_rx) = mpsc::channel();
        let shared = Arc::clone(&snapshot);
        let link = symlink.map(|l| (l, pty.slave_path.clone()));
        let thread = std::thread::Builder::new()
            .name("genuine-board".into())
            .spawn(move || {
                // simavr's objects never leave this thread.
                let bench = match Bench::load(&elf, &rig) {
                    Ok(bench) => {
                        let _ = ready_tx.send(Ok(()));
                        bench
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                let mut runner = Runner::new(bench, pty.master, shared);
                runner.run(&rx);
                drop(pty.slave);
                if let Some((link, target)) = link {
                    remove_link_to(&link, &target);
                }
            })
            .map_err(GenuineError::Thread)?;
        match ready_rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => {
                let _ = thread.join();
                return Err(e.into());
            }
            Err(_) => {
                let _ = thread.join();
                return Err(GenuineError::Thread(io::Error::other(
                    "the simulator thread ended before loading the firmware",
                )));
            }
        }
        Ok(Self {
            path,
            firmware,
            control: GenuineControl { tx, snapshot },
            thread: Some(thread),
        })
    }

    /// The serial device to give the link (`--serial`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The firmware running.
    pub fn firmware(&self) -> &Firmware {
        &self.firmware
    }

    pub fn control(&self) -> GenuineControl {
        self.control.clone()
    }
}

impl Drop for GenuineBoard {
    fn drop(&mut self) {
        let _ = self.control.tx.send(Ctl::Stop);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
