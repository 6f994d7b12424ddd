//! Neptunus: onboard software for an OpenROV 2.x based ROV.
//!
//! The crate is organised by concern (the whole picture, the data paths and
//! where to add things are in `docs/ARCHITECTURE.md`):
//! - [`firmware`]: the OpenROV board's serial protocol (sans-IO codec), the
//!   serial link task and the board emulator.
//! - [`sim`]: the vehicle simulator (pure physics and sensor model).
//! - [`mavlink`]: MAVLink framing, endpoints (UDP, TCP, serial), routing
//!   and the telemetry log.
//! - [`dialect`]: the generated `neptunus` MAVLink dialect.
//! - [`config`]: command line and configuration file.
//! - [`eventlog`]: the operator's event log (JSON lines in the data directory).
//! - [`logfile`]: `neptunus.log`, rotated by size.
//! - [`app`]: wiring of tasks and shutdown.
//! - [`hmi`]: the browser HMI (HTTP, WebSocket sessions as in-process ground stations).
//! - [`vehicle`]: the vehicle core, sans-IO: the state machine (authority,
//!   failsafes, arming, modes, driving), mixer, ground-station input,
//!   parameters, telemetry schedule, estimator and autopilots.
//! - [`scenario`]: closed-loop runs of the core, the emulator and the
//!   simulator on simulated time (tests and `neptunus sim-report`).
//! - [`camera`]: video sources (synthetic, ffmpeg, mjpg-streamer, url) and
//!   the MJPEG, snapshot and status routes.

pub mod app;
pub mod camera;
pub mod config;
pub mod dialect;
pub mod eventlog;
pub mod firmware;
pub mod hmi;
pub mod logfile;
pub mod mavlink;
pub mod scenario;
pub mod sim;
pub mod vehicle;
