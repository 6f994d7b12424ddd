//! The vehicle simulator: pure physics and a board sensor model.
//!
//! - [`plant`]: the simulated vehicle as the board emulator drives it — ESC
//!   pulses in, true state and board readings out — whichever model runs.
//!   [`SimOptions`] chooses the model and the imperfections.
//! - [`thesis`]: the 4-DOF model of the Neptunus thesis (chapter 12),
//!   integrated with RK4, and the thrust allocation of section 9.3 in both
//!   directions (`go()` pulse widths ↔ normalised demand).
//! - [`six_dof`]: a 6-DOF model with the thesis' coefficients, restoring
//!   moments from the centres of gravity and buoyancy, and the thrusters'
//!   geometry.
//! - [`thruster`]: thrust following the ESC command with a first-order lag,
//!   weaker in reverse.
//! - [`environment`]: water current and the tether's drag.
//! - [`sensors`]: what the OpenROV board would report for a simulated
//!   state, with noise, bias, the 1 Hz depth and wild points.
//!
//! This module owns the numbers only. It must never do I/O, read a clock,
//! sleep, or draw random numbers without a seed passed in: the board
//! emulator (`firmware::emulator`) owns time and drives [`Plant::step`]
//! with its own `dt`, so simulation runs are reproducible to the bit.
//!
//! Conventions (detailed in [`thesis`] and [`six_dof`]): NED with z
//! **down** (z is depth), heading ψ positive clockwise from north, body
//! velocities with heave w positive down. Demand `[X, Z, M]` in `[-1, 1]`:
//! X > 0 forward, Z > 0 down, M > 0 turns to starboard (heading increases).

pub mod environment;
pub mod plant;
pub mod sensors;
pub mod six_dof;
pub mod thesis;
pub mod thruster;

pub use environment::{CurrentOptions, Environment, TetherOptions};
pub use plant::{ModelKind, Plant, SimError, SimOptions, Truth};
pub use sensors::{NoiseOptions, Readings, SensorModel, SensorParams};
pub use six_dof::{SixDofModel, SixDofParams, SixDofState};
pub use thesis::{
    Demand, SimState, ThesisModel, ThesisParams, demand_from_thrusters, thrusters_from_demand,
};
