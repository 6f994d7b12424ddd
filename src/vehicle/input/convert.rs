//! The pure conversions: MANUAL_CONTROL axes to [`Sticks`], and
//! RC_CHANNELS_OVERRIDE channels to an [`RcUpdate`], under a profile's
//! conventions (see the [module docs](super) for the rules).
//!
//! Functions of their inputs only; they never decide who is in control and
//! never apply the pilot gain.

use super::profile::{Profile, ZConvention};
use super::{INVALID_AXIS, MAX_DEADBAND, RC_CHANNELS};

const RC_NEUTRAL_US: f64 = 1500.0;
const RC_HALF_RANGE_US: f64 = 400.0;
const RC_MIN_US: f64 = 1100.0;
const RC_FULL_RANGE_US: f64 = 800.0;

/// Normalised sticks from one MANUAL_CONTROL; `None` = axis not given.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sticks {
    /// −1..1, + = forward.
    pub forward: Option<f64>,
    /// −1..1, + = right.
    pub lateral: Option<f64>,
    /// −1..1, + = down (descend).
    pub heave_down: Option<f64>,
    /// −1..1, + = turn to starboard.
    pub yaw: Option<f64>,
}

/// Clamp to ±1 (NaN → 0), deadband, expo. Profile values out of range are
/// clamped here too, since a `Profile` can be built without the loader.
fn shape(v: f64, p: &Profile) -> f64 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(-1.0, 1.0) };
    let db = if p.deadband.is_finite() {
        p.deadband.clamp(0.0, MAX_DEADBAND)
    } else {
        0.0
    };
    let e = if p.expo.is_finite() {
        p.expo.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let a = v.abs();
    let v = if a <= db {
        0.0
    } else {
        ((a - db) / (1.0 - db)).copysign(v)
    };
    (1.0 - e) * v + e * v * v * v
}

/// MANUAL_CONTROL axes to normalised sticks under a profile's conventions.
pub fn sticks_from_manual_control(x: i16, y: i16, z: i16, r: i16, p: &Profile) -> Sticks {
    let axis = |v: i16| (v != INVALID_AXIS).then(|| shape(f64::from(v) / 1000.0, p));
    let heave_down = (z != INVALID_AXIS).then(|| {
        let z = f64::from(z);
        let down = match p.z_convention {
            ZConvention::ZeroToThousand => (500.0 - z) / 500.0,
            ZConvention::Centered => -z / 1000.0,
        };
        shape(down, p)
    });
    Sticks {
        forward: axis(x),
        lateral: axis(y),
        heave_down,
        yaw: axis(r),
    }
}

/// What one RC_CHANNELS_OVERRIDE field asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RcValue {
    /// Keep whatever the channel had.
    Ignore,
    /// Stop overriding: back to neutral.
    Release,
    /// A pulse width.
    Us(u16),
}

impl RcValue {
    /// The meaning of `raw` on channel `index` (0-based): channels 1–8 use
    /// 65535 = ignore, 0 = release; the MAVLink 2 extension channels 9–18
    /// use 0 or 65535 = ignore, 65534 = release.
    pub fn from_raw(index: usize, raw: u16) -> Self {
        match (index < 8, raw) {
            (_, u16::MAX) => Self::Ignore,
            (true, 0) => Self::Release,
            (false, 0) => Self::Ignore,
            (false, 65534) => Self::Release,
            (_, us) => Self::Us(us),
        }
    }
}

/// A new value for one input axis from an RC override.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RcAxis {
    /// The override stops: sticks and tilt rate go to 0; for lights the
    /// override stops holding the level (the caller keeps the last one).
    Release,
    /// A normalised value: −1..1 for motion and tilt rate, 0..1 for lights.
    Set(f64),
}

/// Per-axis updates from one RC_CHANNELS_OVERRIDE; `None` = leave as is.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RcUpdate {
    /// + = forward.
    pub forward: Option<RcAxis>,
    /// + = right.
    pub lateral: Option<RcAxis>,
    /// + = down (channel 3 above 1500 is up, so it is negated here).
    pub heave_down: Option<RcAxis>,
    /// + = turn to starboard.
    pub yaw: Option<RcAxis>,
    /// Camera tilt rate, + = up.
    pub tilt_rate: Option<RcAxis>,
    /// Lights level 0..1 (1100 µs off, 1900 µs full).
    pub lights: Option<RcAxis>,
}

/// RC_CHANNELS_OVERRIDE to per-axis updates under a profile's channel map.
/// Motion axes get the profile's deadband and expo like MANUAL_CONTROL.
pub fn rc_override(channels: &[u16; RC_CHANNELS], p: &Profile) -> RcUpdate {
    let value = |ch: u8| {
        let i = usize::from(ch).checked_sub(1)?;
        match RcValue::from_raw(i, *channels.get(i)?) {
            RcValue::Ignore => None,
            RcValue::Release => Some(RcAxis::Release),
            RcValue::Us(us) => Some(RcAxis::Set(f64::from(us))),
        }
    };
    let map = |ch: u8, f: &dyn Fn(f64) -> f64| {
        value(ch).map(|a| match a {
            RcAxis::Set(us) => RcAxis::Set(f(us)),
            RcAxis::Release => RcAxis::Release,
        })
    };
    let centred = |us: f64| ((us - RC_NEUTRAL_US) / RC_HALF_RANGE_US).clamp(-1.0, 1.0);
    let stick = |us: f64| shape(centred(us), p);
    RcUpdate {
        forward: map(p.rc.forward, &stick),
        lateral: map(p.rc.lateral, &stick),
        heave_down: map(p.rc.heave, &|us| -stick(us)),
        yaw: map(p.rc.yaw, &stick),
        tilt_rate: map(p.rc.tilt, &centred),
        lights: map(p.rc.lights, &|us| {
            ((us - RC_MIN_US) / RC_FULL_RANGE_US).clamp(0.0, 1.0)
        }),
    }
}
