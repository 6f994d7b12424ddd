//! The vehicle core (see DESIGN.md): pure code that owns all vehicle state
//! and decides every byte sent to the board and to ground stations.
//!
//! - [`machine`]: the state machine, `Vehicle::handle(input, now) -> outputs`.
//! - [`params`]: the parameter set (ArduSub names), validation and storage.
//! - [`telemetry`]: the per-endpoint telemetry schedule.

pub mod machine;
pub mod params;
pub mod telemetry;
