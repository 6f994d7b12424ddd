//! The MAVLink parameter set, its validation and its file storage.
//!
//! Neptunus presents itself as ArduSub, so ground stations (QGroundControl
//! above all) expect ArduSub's parameter names and types: a missing one makes
//! QGC pop up an error, a wrong type breaks its write echo. Every parameter is
//! therefore either one Neptunus acts on ([`Use::Neptunus`]) or one that
//! exists only so ground stations work ([`Use::Compat`], no effect). Our own
//! parameters are prefixed `NEPT_`.
//!
//! This module owns the list ([`definitions`], in the index order of
//! PARAM_REQUEST_READ), the values ([`ParamStore`]), the typed accessors the
//! vehicle uses, and `params.toml` in the data directory ([`ParamFile`]).
//! It never touches a socket or a clock; the only I/O is [`ParamFile`].
//!
//! Values are `f64` holding the numeric value, as MAVLink's C-cast encoding
//! carries it: integer parameters hold integral values, REAL32 parameters
//! hold values exactly representable as `f32`. No parameter is UINT8/UINT16
//! (QGC fails to match its own write echo for those).
//!
//! The pieces: `defs` is the table of definitions (and the wire types),
//! `store` the values with their validation and typed accessors, `file`
//! `params.toml` and its TOML text, `doc` the table the user guide embeds, `metadata` the parameter
//! metadata file ground stations fetch over MAVLink FTP, `functions` what the
//! button and servo-output function codes mean.
//! Everything is re-exported here, so users name `vehicle::params::X`.

mod defs;
mod doc;
mod file;
mod functions;
pub mod metadata;
mod outputs;
mod store;

pub use defs::{ParamDef, ParamType, Use, definitions, index_of};
pub use doc::markdown_table;
pub use file::{ParamFile, StoreError};
pub use functions::{
    BTN_FUNCTION_ARM_TOGGLE, BTN_FUNCTION_DISARM, BTN_FUNCTION_LASER_TOGGLE, ButtonFunction,
    ServoFunction, is_button_function,
};
pub use outputs::{BTN_DEFAULTS, BUTTONS};
pub use store::{ControlClaim, FailsafeAction, ParamError, ParamStore, PidGains};
