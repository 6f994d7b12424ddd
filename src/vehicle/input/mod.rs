//! Pilot input from ground stations: MANUAL_CONTROL and RC_CHANNELS_OVERRIDE
//! turned into normalised sticks, per ground-station convention ("profile").
//!
//! This module owns the conventions of each ground station (which way z
//! runs, deadband and expo, default buttons, RC channel map), the loader of
//! `gcs_profiles/*.toml` and the pure conversions. It must never decide who
//! is in control, apply the pilot gain or talk to the board: the vehicle
//! core does that with the [`Sticks`] and [`RcUpdate`] returned here, and
//! [`super::mixer`] applies the gain.
//!
//! # Conventions
//! - x forward, y lateral (right +), r yaw (turn right +): −1000..1000 → −1..1.
//! - z, the heave stick, comes in two conventions ([`ZConvention`]):
//!   ArduSub's 0..1000 with 500 neutral (QGroundControl, Cockpit, MAVSDK,
//!   pymavlink scripts), and the MAVLink spec's ±1000 (the Neptunus web
//!   HMI). In both, stick up means rise; [`Sticks::heave_down`] is positive
//!   **down** so it feeds the mixer's heave directly (z = 250 → +0.5, descend).
//! - `INT16_MAX` (32767) on an axis means "not given": that axis is `None`.
//! - Shaping, in this order: clamp to ±1, deadband (rescaled so full
//!   deflection still gives ±1), expo `out = (1−e)·in + e·in³`.
//!
//! # The pilot gain, a worked example (ArduSub's)
//! At gain 0.5, ArduSub turns x = 500 into channel value
//! `1500 + 500 · 0.4 · 0.5 = 1600`, i.e. +0.25 of full forward thrust.
//! Here x = 500 gives `forward = 0.5`; the mixer multiplies by the gain:
//! `mix(Demand { surge: 0.5, .. })` at gain 0.5 gives each horizontal
//! thruster 0.25 of its half range — 1600 µs starboard and, with the port
//! thruster wired reversed, 1400 µs port (MOT_PWM 1100..1900).
//! Likewise z = 250 (ArduSub: 1400, descend at 0.25) gives
//! `heave_down = 0.5`, and 0.25 after the gain. ArduSub's JS_THR_GAIN
//! multiplies heave on top of that; the caller applies it.
//!
//! # RC_CHANNELS_OVERRIDE
//! ArduSub's map (1-based): 3 heave (1500 neutral, > 1500 = up), 4 yaw,
//! 5 forward, 6 lateral, 8 camera tilt rate, 9 lights. 1100..1900 µs ↔ −1..1
//! (lights: 1100..1900 ↔ off..full). Channels 1–8: 65535 = ignore (keep the
//! last value), 0 = release (back to neutral). Channels 9–18 are MAVLink 2
//! extensions, zero-filled when a MAVLink 1 sender leaves them out, so there
//! 0 and 65535 both mean ignore and 65534 means release (the MAVLink spec
//! and ArduPilot agree).
//!
//! One file per concern: `profile` (one ground station's conventions),
//! `profiles` (loading and picking them), `locate` (where in a file an error
//! is) and `convert` (the pure conversions); everything public is
//! re-exported here.

mod convert;
mod locate;
mod profile;
mod profiles;

pub use convert::{RcAxis, RcUpdate, RcValue, Sticks, rc_override, sticks_from_manual_control};
pub use profile::{Profile, RcMap, ZConvention};
pub use profiles::{ProfileError, Profiles};

/// MANUAL_CONTROL's "this axis is not given".
pub const INVALID_AXIS: i16 = i16::MAX;
/// Name of the built-in fallback profile.
pub const DEFAULT_PROFILE_NAME: &str = "ardusub-default";
/// Largest deadband a profile may ask for (fraction of full scale).
pub const MAX_DEADBAND: f64 = 0.5;
/// RC_CHANNELS_OVERRIDE carries 18 channels.
pub const RC_CHANNELS: usize = 18;

/// Button edges between two 32-bit states (`buttons | buttons2 << 16`):
/// `(pressed, released)`.
pub fn edges(prev: u32, now: u32) -> (u32, u32) {
    (now & !prev, prev & !now)
}
