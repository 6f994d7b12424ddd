//! Neptunus: onboard software for an OpenROV 2.x based ROV.
//!
//! The crate is organised by concern; `docs/ARCHITECTURE.md` is the map
//! (the one picture, the data paths, who owns what, where to add things):
//! - [`firmware`]: the OpenROV board's serial protocol (sans-IO codec), the
//!   serial link task and the board emulator.
//! - [`sim`]: the vehicle simulator (pure physics and sensor model).
//! - [`mavlink`]: MAVLink framing, endpoints (UDP, TCP, serial), routing
//!   and the telemetry log.
//! - [`dialect`]: the generated `neptunus` MAVLink dialect.
//! - [`config`]: command line and configuration file.
//! - [`doctor`]: `neptunus doctor`, the pool-side checks of the machine.
//! - [`durable`]: the one atomic, synced write of the files that must survive a power cut.
//! - [`wallclock`]: the logs' clock (set by the station in control when the ROV's is wrong).
//! - [`eventlog`]: the operator's event log (JSON lines in the data directory).
//! - [`logfile`]: `neptunus.log`, rotated by size.
//! - [`files`]: the files served over MAVLink (log download, FTP): the
//!   virtual tree, the component metadata, the disk worker thread.
//! - [`app`]: wiring of tasks and shutdown.
//! - [`hmi`]: the browser HMI (HTTP, WebSocket sessions as in-process ground stations).
//! - [`vehicle`]: the vehicle core (state machine, modes, driving, authority,
//!   failsafes, estimator, autopilots, parameters, telemetry) — sans-IO.
//! - [`scenario`]: closed-loop scenarios on simulated time (`sim-report`).
//! - `hil` (feature `hil`): the genuine OpenROV firmware built from source
//!   and run in the simavr AVR simulator — behind a pty at real time, or in
//!   lock-step with a scenario — for tests against the real board's
//!   behaviour, `--hil` and `sim-report --hil`.
//! - [`camera`]: video sources (synthetic, ffmpeg, mjpg-streamer, url) and
//!   the MJPEG, snapshot and status routes.

// The generated dialect's serde defaults name `crate::utils`.
#[cfg(feature = "serde")]
use mavlink_core::utils;

pub mod app;
pub mod camera;
pub mod config;
pub mod dialect;
pub mod doctor;
pub mod durable;
pub mod eventlog;
pub mod files;
pub mod firmware;
#[doc(hidden)]
pub mod fuzzing;
#[cfg(feature = "hil")]
pub mod hil;
pub mod hmi;
pub mod logfile;
pub mod mavlink;
pub mod scenario;
pub mod sim;
pub mod vehicle;
pub mod wallclock;
