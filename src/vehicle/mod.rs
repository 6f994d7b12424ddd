//! The vehicle core: pure code that owns the vehicle's state and decisions.
//!
//! - [`params`]: the MAVLink parameter set (ArduSub names and types where
//!   the meaning is the same), its validation and its file storage.
//!
//! Nothing here opens a socket, reads a clock or sleeps; time comes in as an
//! argument and effects go out as values.

pub mod params;
