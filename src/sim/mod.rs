//! The vehicle simulator: pure physics and a board sensor model.
//!
//! - [`thesis`]: the 4-DOF model of the Neptunus thesis (chapter 12),
//!   integrated with RK4, and the thrust allocation of section 9.3 in both
//!   directions (`go()` pulse widths ↔ normalised demand).
//! - [`sensors`]: what the OpenROV board would report for a simulated state.
//!
//! This module owns the numbers only. It must never do I/O, read a clock,
//! sleep, or draw random numbers without a seed passed in: the board
//! emulator (`firmware::emulator`) owns time and drives [`ThesisModel::step`]
//! with its own `dt`, so simulation runs are reproducible to the bit.
//!
//! Conventions (detailed in [`thesis`]): NED with z **down** (z is depth),
//! heading ψ positive clockwise from north, body velocities `[u, v, w, r]`
//! with heave w positive down. Demand `[X, Z, M]` in `[-1, 1]`: X > 0
//! forward, Z > 0 down, M > 0 turns to starboard (heading increases).

pub mod sensors;
pub mod thesis;

pub use sensors::{Readings, SensorModel, SensorParams};
pub use thesis::{
    Demand, SimState, ThesisModel, ThesisParams, demand_from_thrusters, thrusters_from_demand,
};
