//! The vehicle core (map: `docs/ARCHITECTURE.md`): pure code that owns all vehicle state
//! and decides every byte sent to the board and to ground stations.
//!
//! - [`machine`]: the state machine, `Vehicle::handle(input, now) -> outputs`.
//! - [`mixer`]: the thrust allocation, demand to `go()` pulse widths.
//! - [`input`]: ground-station conventions (profiles), MANUAL_CONTROL and
//!   RC override to normalised sticks, button edges.
//! - [`params`]: the MAVLink parameter set (ArduSub names and types where
//!   the meaning is the same), its validation and its file storage.
//! - [`mode`]: the flight modes (ArduSub's numbers and ours), their names and
//!   whether Neptunus can honour them.
//! - [`telemetry`]: the per-endpoint telemetry schedule.
//! - [`estimator`]: depth and heading Kalman filters with wild-point gating.
//! - [`autopilot`]: depth and heading hold (PID controllers and setpoints).
//!
//! Nothing here opens a socket, reads a clock or sleeps; time comes in as an
//! argument and effects go out as values.

pub mod autopilot;
pub mod estimator;
pub mod input;
pub mod machine;
pub mod mixer;
pub mod mode;
pub mod params;
pub mod telemetry;
