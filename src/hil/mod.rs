//! The genuine OpenROV firmware in the loop (feature `hil`): the controller
//! board's own firmware, built from source and run in the simavr AVR
//! simulator — at real time behind a pseudo-terminal, or in lock-step with
//! a scenario's simulated time — so that Neptunus talks to what runs on the
//! ROV rather than to our reading of it.
//!
//! - [`compile`]: finds the sketch and builds it with avr-gcc and Debian's
//!   Arduino AVR core, caching the ELF.
//! - `avr`: simavr behind a safe face (the crate's one FFI boundary).
//! - [`bno055`]: the BNO055 IMU on the board's I2C bus, its fused Euler
//!   registers worked out from the vehicle's attitude so that the firmware
//!   prints it back in its own convention (documented there).
//! - [`ms5803`]: the MS5803-14BA depth sensor on the board's I2C bus, its
//!   raw readings worked back from a depth and water temperature through
//!   the firmware's own arithmetic.
//! - [`pins`]: the board's outputs as an instrument reads them: ESC and
//!   servo pulse widths from pin edges, lights and lasers from their timer.
//! - `bench`: the board without a clock — the firmware in simavr with what
//!   is wired to it ([`Wiring`], [`Analog`]), run to a given cycle.
//! - [`runner`]: [`GenuineBoard`], the bench paced to the wall clock on
//!   its own thread, its UART0 on a pty, its analog inputs set in volts and
//!   amperes, its depth sensor's water, its IMU's attitude, a reset line,
//!   and the records tests and benches read.
//! - [`surroundings`]: the simulated vehicle around the board (ESC pulses
//!   in, sensor inputs out, on the board's time), sans-IO.
//! - [`relay`]: [`NoisyRelay`], a damaging serial line (a pty relay that
//!   flips bits and drops bytes, seeded) between the vehicle and a board.
//! - [`rov`]: [`HilRov`], the loop closed at real time for `neptunus --hil`.
//! - [`lockstep`]: the loop closed on a scenario's simulated time for
//!   `neptunus sim-report --hil`.
//!
//! The firmware is test data, not part of Neptunus: this module builds and
//! runs it, it never changes it. Nothing here decides what the vehicle
//! does; the firmware decides what the board does.

mod avr;
mod bench;
pub mod bno055;
pub mod compile;
pub mod lockstep;
pub mod ms5803;
pub mod pins;
pub mod relay;
pub mod rov;
pub mod runner;
pub mod surroundings;

pub use avr::{AvrError, F_CPU_HZ};
pub use bench::{Analog, Wiring};
pub use bno055::Attitude;
pub use compile::{BUILD_PACKAGES, BuildError, Firmware, SIMAVR_PACKAGES, prepare};
pub use ms5803::Water;
pub use pins::{Output, PinsReport, PulseChange};
pub use relay::{Damage, DamageCount, NoisyRelay, RelayError};
pub use rov::{HilError, HilRov};
pub use runner::{
    GenuineBoard, GenuineControl, GenuineError, GenuineSnapshot, SerialChunk, TimedChange,
};
