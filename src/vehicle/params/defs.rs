//! The parameter definitions: every parameter's name, wire type, default,
//! range, units, whether Neptunus acts on it, and its documentation, in the
//! index order PARAM_REQUEST_READ uses.
//!
//! This is a data table and long on purpose: one row per parameter, grouped
//! as ground stations page through them, so a reader sees the whole set and
//! its order in one place. It holds no values (that is [`ParamStore`]) and
//! never changes at run time; it never does I/O.
//!
//! [`ParamStore`]: super::ParamStore

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::LazyLock;

use crate::dialect::neptunus::MavParamType;

/// Wire type of a parameter (only the types ArduSub uses).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum ParamType {
    Int8,
    Int16,
    Int32,
    Real32,
}

impl ParamType {
    /// The MAVLink `MAV_PARAM_TYPE` sent in PARAM_VALUE.
    pub fn mav_type(self) -> MavParamType {
        match self {
            Self::Int8 => MavParamType::MAV_PARAM_TYPE_INT8,
            Self::Int16 => MavParamType::MAV_PARAM_TYPE_INT16,
            Self::Int32 => MavParamType::MAV_PARAM_TYPE_INT32,
            Self::Real32 => MavParamType::MAV_PARAM_TYPE_REAL32,
        }
    }

    /// The name used in documentation (`INT8`, …).
    pub fn name(self) -> &'static str {
        match self {
            Self::Int8 => "INT8",
            Self::Int16 => "INT16",
            Self::Int32 => "INT32",
            Self::Real32 => "REAL32",
        }
    }

    /// Smallest and largest value the wire type can carry.
    pub fn limits(self) -> (f64, f64) {
        match self {
            Self::Int8 => (i8::MIN.into(), i8::MAX.into()),
            Self::Int16 => (i16::MIN.into(), i16::MAX.into()),
            Self::Int32 => (i32::MIN.into(), i32::MAX.into()),
            Self::Real32 => (f32::MIN.into(), f32::MAX.into()),
        }
    }

    pub fn is_integer(self) -> bool {
        self != Self::Real32
    }
}

/// The value as it travels: REAL32 rounded to `f32`, integers cast toward zero.
pub(super) fn wire_value(ty: ParamType, value: f64) -> f64 {
    match ty {
        ParamType::Real32 => f64::from(value as f32),
        _ => value.trunc(),
    }
}

/// A value as TOML and documentation show it: integers without a decimal
/// point, REAL32 as the shortest decimal that reads back to the same `f32`.
pub(super) fn format_value(ty: ParamType, value: f64) -> String {
    if ty.is_integer() {
        format!("{}", value as i64)
    } else {
        let s = format!("{}", value as f32);
        if s.contains(['.', 'e', 'i', 'N']) {
            s
        } else {
            s + ".0"
        }
    }
}

/// Whether Neptunus acts on a parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Use {
    /// Neptunus acts on it.
    Neptunus,
    /// Exists so that ground stations work; setting it has no effect.
    Compat,
}

/// One parameter: name, wire type, default, inclusive range and
/// documentation, and what a ground station needs to offer it (its named
/// values or bits, whether it needs a restart). The parameter metadata the
/// vehicle serves over MAVLink FTP (`params::metadata`) is made from these
/// rows alone.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ParamDef {
    pub name: &'static str,
    pub ty: ParamType,
    pub default: f64,
    pub min: f64,
    pub max: f64,
    pub units: &'static str,
    pub doc: &'static str,
    pub used: Use,
    /// A short name for lists; empty: the doc's first words (up to its
    /// first full stop, parenthesis or colon).
    pub short: &'static str,
    /// The values it takes, each with its meaning (empty: any in range).
    pub values: &'static [(i32, &'static str)],
    /// The meaning of its bits (empty: not a bitmask).
    pub bitmask: &'static [(u8, &'static str)],
    /// A change takes effect only at the next start.
    pub reboot: bool,
}

impl ParamDef {
    const fn values(mut self, values: &'static [(i32, &'static str)]) -> Self {
        self.values = values;
        self
    }
    const fn bitmask(mut self, bits: &'static [(u8, &'static str)]) -> Self {
        self.bitmask = bits;
        self
    }
    const fn reboot(mut self) -> Self {
        self.reboot = true;
        self
    }
    const fn short(mut self, short: &'static str) -> Self {
        self.short = short;
        self
    }
}

#[allow(clippy::too_many_arguments)]
const fn def(
    name: &'static str,
    ty: ParamType,
    default: f64,
    min: f64,
    max: f64,
    units: &'static str,
    used: Use,
    doc: &'static str,
) -> ParamDef {
    ParamDef {
        name,
        ty,
        default,
        min,
        max,
        units,
        doc,
        used,
        short: "",
        values: &[],
        bitmask: &[],
        reboot: false,
    }
}

use super::functions::{BTN_FUNCTION_LASER_TOGGLE, BUTTON_FUNCTION_NAMES};
use super::outputs::{BTN_DEFAULTS, BTN_DOC, BTN_NAMES, BUTTONS, SERVOS};
use ParamType::{Int8, Int16, Int32, Real32};
use Use::{Compat, Neptunus};

const I32_MAX: f64 = i32::MAX as f64;

/// Named values shared by several rows.
const OFF_WARN: &[(i32, &str)] = &[(0, "Disabled"), (1, "Warn only")];
const OFF_WARN_DISARM: &[(i32, &str)] = &[(0, "Disabled"), (1, "Warn only"), (2, "Disarm")];
const GCS_FAILSAFE: &[(i32, &str)] = &[
    (0, "Disabled"),
    (1, "Warn only"),
    (2, "Disarm"),
    (3, "Enter depth hold mode"),
    (4, "Enter surface mode"),
];
const LEAK_FAILSAFE: &[(i32, &str)] =
    &[(0, "Disabled"), (1, "Warn only"), (2, "Enter surface mode")];
const BATTERY_FAILSAFE: &[(i32, &str)] = &[
    (0, "None"),
    (1, "Warn only"),
    (2, "Disarm"),
    (3, "Enter surface mode"),
];
const DIRECTION: &[(i32, &str)] = &[(-1, "Reversed"), (1, "Normal")];
const ENABLED: &[(i32, &str)] = &[(0, "Disabled"), (1, "Enabled")];
const CLAIM: &[(i32, &str)] = &[
    (0, "First station to drive or arm"),
    (1, "Explicit control request only"),
];
/// What the virtual outputs drive (each row's value is fixed, and named).
const SERVO_VALUES: &[(i32, &str)] = &[
    (0, "Disabled"),
    (7, "Mount tilt"),
    (33, "Motor 1"),
    (34, "Motor 2"),
    (35, "Motor 3"),
    (59, "Lights 1 (RCIN9)"),
    (60, "Lights 2 (RCIN10)"),
];

/// Identity, control authority, motors, joystick and lights (before the buttons).
#[rustfmt::skip]
const HEAD: &[ParamDef] = &[
    def("SYSID_THISMAV", Int16, 1.0, 1.0, 255.0, "", Neptunus,
        "MAVLink system id of the vehicle. Takes effect at the next start (the running vehicle keeps its id). Never a ground station's id: not 255, SYSID_MYGCS, a NEPT_GCS_ALLOWn id or one lent to browser HMI sessions (200..209 by default).").reboot(),
    def("SYSID_MYGCS", Int16, 255.0, 1.0, 255.0, "", Neptunus,
        "System id of the primary ground station (QGroundControl and MAVProxy use 255). It may control the vehicle like the NEPT_GCS_ALLOWn ids, and may take control from another station without asking (the owner gets a warning first)."),
    def("NEPT_CTRL_CLAIM", Int8, 0.0, 0.0, 1.0, "", Neptunus,
        "How an allowed ground station gets control of a vehicle nobody controls: 0 = the first one that drives (MANUAL_CONTROL) or arms (ArduSub-like), 1 = only by an explicit MAV_CMD_REQUEST_OPERATOR_CONTROL.").values(CLAIM),
    def("NEPT_GCS_ALLOW1", Int16, 245.0, 0.0, 255.0, "", Neptunus,
        "Another ground-station system id allowed to control the vehicle besides SYSID_MYGCS (245 = MAVSDK's default); 0 = unused slot.").short("Another allowed ground-station system id"),
    def("NEPT_GCS_ALLOW2", Int16, 0.0, 0.0, 255.0, "", Neptunus,
        "Another ground-station system id allowed to control the vehicle; 0 = unused slot.").short("Another allowed ground-station system id"),
    def("NEPT_GCS_ALLOW3", Int16, 0.0, 0.0, 255.0, "", Neptunus,
        "Another ground-station system id allowed to control the vehicle; 0 = unused slot.").short("Another allowed ground-station system id"),
    def("NEPT_GCS_ALLOW4", Int16, 0.0, 0.0, 255.0, "", Neptunus,
        "Another ground-station system id allowed to control the vehicle; 0 = unused slot.").short("Another allowed ground-station system id"),
    def("FRAME_CONFIG", Int8, 4.0, 4.0, 4.0, "", Compat,
        "Frame: 4 = SimpleROV-3, from which QGC derives three thrusters. Fixed: Neptunus' mixer is always the three-thruster one; no effect.").values(&[(4, "SimpleROV-3")]).short("Frame configuration"),
    def("MOT_1_DIRECTION", Int8, 1.0, -1.0, 1.0, "", Neptunus,
        "Direction of motor 1, the starboard thruster (SimpleROV-3 factors: yaw -1, forward +1): 1 normal, -1 reversed.").values(DIRECTION),
    def("MOT_2_DIRECTION", Int8, -1.0, -1.0, 1.0, "", Neptunus,
        "Direction of motor 2, the port thruster (SimpleROV-3 factors: yaw +1, forward +1): 1 normal, -1 reversed. Default -1 because Neptunus' port thruster is wired reversed.").values(DIRECTION),
    def("MOT_3_DIRECTION", Int8, 1.0, -1.0, 1.0, "", Neptunus,
        "Direction of motor 3, the vertical thruster (SimpleROV-3 factor: throttle -1): 1 normal, -1 reversed.").values(DIRECTION),
    def("MOT_PWM_MIN", Int16, 1100.0, 1000.0, 2000.0, "µs", Neptunus,
        "Pulse width for full reverse thrust. Must stay below the 1500 µs neutral (and so below MOT_PWM_MAX)."),
    def("MOT_PWM_MAX", Int16, 1900.0, 1000.0, 2000.0, "µs", Neptunus,
        "Pulse width for full forward thrust. Must stay above the 1500 µs neutral (and so above MOT_PWM_MIN)."),
    def("JS_GAIN_DEFAULT", Real32, 0.5, 0.1, 1.0, "", Neptunus,
        "Pilot gain at start: stick deflection is scaled by it (clamped to JS_GAIN_MIN..JS_GAIN_MAX)."),
    def("JS_GAIN_MIN", Real32, 0.25, 0.1, 0.8, "", Neptunus,
        "Lowest pilot gain the gain buttons reach."),
    def("JS_GAIN_MAX", Real32, 1.0, 0.2, 1.0, "", Neptunus,
        "Highest pilot gain the gain buttons reach."),
    def("JS_GAIN_STEPS", Int8, 4.0, 1.0, 10.0, "", Neptunus,
        "Number of steps between JS_GAIN_MIN and JS_GAIN_MAX for the gain buttons."),
    def("JS_THR_GAIN", Real32, 1.0, 0.5, 4.0, "", Neptunus,
        "Extra gain on the throttle (vertical) axis, on top of the pilot gain."),
    def("JS_LIGHTS_STEPS", Int16, 8.0, 1.0, 10.0, "", Neptunus,
        "Number of brightness steps of the lights buttons from off to full."),
    def("NEPT_ESC_REVMUL", Int8, 2.0, 1.0, 4.0, "", Neptunus,
        "The board firmware's reverse multiplier (OpenROV Motor.cpp: 2): it doubles how far below 1500 µs a go() value lies, making up for the propellers' weak reverse, so reverse thrust ends at 1500 − 500/multiplier µs (1250). The estimator counts no more thrust past it. Match the board's setting (1 for a board that passes go() through)."),
    def("NEPT_LIGHTS_MAX", Int16, 255.0, 0.0, 255.0, "", Neptunus,
        "Lamp level sent to the OpenROV board (ligt) at full brightness; lower it to cap the lamp's power.").short("Lamp level at full brightness"),
    def("NEPT_TILT_MIN_US", Int16, 1000.0, 500.0, 2500.0, "µs", Neptunus,
        "Camera tilt servo pulse width at the lowest tilt. Must be below NEPT_TILT_MAX_US."),
    def("NEPT_TILT_MAX_US", Int16, 2000.0, 500.0, 2500.0, "µs", Neptunus,
        "Camera tilt servo pulse width at the highest tilt. Must be above NEPT_TILT_MIN_US."),
];

/// Failsafes, battery, arming, depth (after the buttons).
#[rustfmt::skip]
const SAFETY: &[ParamDef] = &[
    def("FS_GCS_ENABLE", Int8, 2.0, 0.0, 4.0, "", Neptunus,
        "Action when the station in control shows no life (heartbeat or stick input) for FS_GCS_TIMEOUT while armed, or leaves control (releases it, its HMI page closes) with nobody taking over: 0 off, 1 warn, 2 disarm, 3 depth hold, 4 surface (3 and 4 disarm instead while those modes are not available).").values(GCS_FAILSAFE).short("GCS failsafe action"),
    def("FS_GCS_TIMEOUT", Real32, 5.0, 2.0, 120.0, "s", Neptunus,
        "Time without a heartbeat or stick input from the station in control before it loses control and, if armed, the GCS failsafe acts.").short("GCS failsafe timeout"),
    def("FS_PILOT_INPUT", Int8, 2.0, 0.0, 2.0, "", Neptunus,
        "Action when pilot input (MANUAL_CONTROL or RC override) stops for FS_PILOT_TIMEOUT while armed: 0 off, 1 warn, 2 disarm. The sticks go neutral first in every case.").values(OFF_WARN_DISARM).short("Pilot input failsafe action"),
    def("FS_PILOT_TIMEOUT", Real32, 3.0, 0.1, 3.0, "s", Neptunus,
        "Time without pilot input before the pilot-input failsafe acts."),
    def("FS_LEAK_ENABLE", Int8, 1.0, 0.0, 2.0, "", Compat,
        "Leak failsafe (0 off, 1 warn, 2 surface). The OpenROV 2.x has no leak sensor (LEAK1_PIN -1): no effect.").values(LEAK_FAILSAFE),
    def("LEAK1_PIN", Int8, -1.0, -1.0, 127.0, "", Compat,
        "Leak sensor input; -1 = none, which is the OpenROV 2.x. No effect.").values(&[(-1, "None (no leak sensor)")]),
    def("LEAK1_LOGIC", Int8, 0.0, 0.0, 1.0, "", Compat,
        "Leak sensor polarity (0 low when dry, 1 high when dry). No effect: there is no leak sensor.").values(&[(0, "Low = dry"), (1, "High = dry")]),
    def("FS_EKF_ACTION", Int8, 1.0, 0.0, 2.0, "", Compat,
        "EKF failsafe action (0 off, 1 warn, 2 disarm). Neptunus has no EKF: no effect.").values(OFF_WARN_DISARM),
    def("FS_EKF_THRESH", Real32, 0.8, 0.6, 1.0, "", Compat,
        "EKF variance threshold of the EKF failsafe. No effect."),
    def("FS_PRESS_ENABLE", Int8, 0.0, 0.0, 1.0, "", Compat,
        "Internal pressure failsafe (0 off, 1 warn). The OpenROV 2.x has no internal pressure sensor: no effect.").values(OFF_WARN),
    def("FS_PRESS_MAX", Int32, 105_000.0, 0.0, 1_000_000.0, "Pa", Compat,
        "Internal pressure limit of the pressure failsafe. No effect."),
    def("FS_TEMP_ENABLE", Int8, 0.0, 0.0, 1.0, "", Compat,
        "Internal temperature failsafe (0 off, 1 warn). No effect.").values(OFF_WARN),
    def("FS_TEMP_MAX", Int8, 62.0, 0.0, 100.0, "°C", Compat,
        "Internal temperature limit of the temperature failsafe. No effect."),
    def("FS_OPTIONS", Int32, 0.0, 0.0, 255.0, "", Compat,
        "ArduSub failsafe option bits (QGC's status drawer reads them). No effect."),
    def("BATT_MONITOR", Int8, 4.0, 4.0, 4.0, "", Compat,
        "Battery monitor: 4 = voltage and current, which the OpenROV board always reports. Fixed; no effect.").values(&[(4, "Voltage and current")]),
    def("BATT_CAPACITY", Int32, 3300.0, 0.0, 1_000_000.0, "mAh", Compat,
        "Battery capacity. No effect yet (Neptunus estimates charge from voltage)."),
    def("BATT_LOW_VOLT", Real32, 10.5, 0.0, 30.0, "V", Neptunus,
        "Battery voltage below which the low-battery failsafe acts (BATT_FS_LOW_ACT) and arming is refused; 0 = off."),
    def("BATT_FS_LOW_ACT", Int8, 1.0, 0.0, 3.0, "", Neptunus,
        "Action of the low-battery failsafe: 0 none, 1 warn, 2 disarm, 3 surface.").values(BATTERY_FAILSAFE),
    def("BATT_CRT_VOLT", Real32, 0.0, 0.0, 30.0, "V", Neptunus,
        "Battery voltage below which the critical-battery failsafe acts (BATT_FS_CRT_ACT); 0 = off."),
    def("BATT_FS_CRT_ACT", Int8, 0.0, 0.0, 3.0, "", Neptunus,
        "Action of the critical-battery failsafe: 0 none, 1 warn, 2 disarm, 3 surface.").values(BATTERY_FAILSAFE),
    def("BATT_LOW_MAH", Real32, 0.0, 0.0, 1_000_000.0, "mAh", Compat,
        "Remaining-capacity threshold of the low-battery failsafe. Neptunus counts no mAh: no effect."),
    def("BATT_CRT_MAH", Real32, 0.0, 0.0, 1_000_000.0, "mAh", Compat,
        "Remaining-capacity threshold of the critical-battery failsafe. No effect."),
    def("ARMING_CHECK", Int32, 1.0, 0.0, I32_MAX, "", Compat,
        "ArduPilot pre-arm check bits. Neptunus' own pre-arm checks always run: no effect.").bitmask(&[(0, "All (no effect: Neptunus' own pre-arm checks always run)")]),
    def("SURFACE_DEPTH", Real32, -10.0, -100.0, 0.0, "cm", Neptunus,
        "Depth (negative below the surface) at which the vehicle counts as surfaced: depth hold and surface mode stop climbing there.").short("Depth at which the vehicle counts as surfaced"),
];

/// Sensors and calibration that QGC checks to call setup complete.
#[rustfmt::skip]
const SENSORS: &[ParamDef] = &[
    def("AHRS_ORIENTATION", Int8, 0.0, 0.0, 101.0, "", Compat,
        "Mounting rotation of the autopilot board. The OpenROV IMU reports attitude in the vehicle frame: no effect.").values(&[(0, "None")]),
    def("COMPASS_DEV_ID", Int32, 0.0, 0.0, 0.0, "", Compat,
        "Compass device id; fixed at 0 (no compass for ground stations to calibrate; the OpenROV IMU calibrates itself). No effect."),
    def("COMPASS_DEV_ID2", Int32, 0.0, 0.0, 0.0, "", Compat,
        "Second compass device id; fixed at 0 (none). No effect."),
    def("COMPASS_DEV_ID3", Int32, 0.0, 0.0, 0.0, "", Compat,
        "Third compass device id; fixed at 0 (none). No effect."),
    def("COMPASS_OFS_X", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Compass offset X. No effect."),
    def("COMPASS_OFS_Y", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Compass offset Y. No effect."),
    def("COMPASS_OFS_Z", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Compass offset Z. No effect."),
    def("COMPASS_OFS2_X", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Second compass offset X. No effect."),
    def("COMPASS_OFS2_Y", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Second compass offset Y. No effect."),
    def("COMPASS_OFS2_Z", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Second compass offset Z. No effect."),
    def("COMPASS_OFS3_X", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Third compass offset X. No effect."),
    def("COMPASS_OFS3_Y", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Third compass offset Y. No effect."),
    def("COMPASS_OFS3_Z", Real32, 0.0, -400.0, 400.0, "mGauss", Compat,
        "Third compass offset Z. No effect."),
    def("COMPASS_DEC", Real32, 0.0, -std::f64::consts::PI, std::f64::consts::PI, "rad", Compat,
        "Magnetic declination. Heading is reported as the IMU gives it: no effect."),
    def("COMPASS_AUTODEC", Int8, 1.0, 0.0, 1.0, "", Compat,
        "Automatic declination (0 off, 1 on). No effect.").values(ENABLED),
    def("INS_ACCOFFS_X", Real32, 0.001, -3.5, 3.5, "m/s²", Compat,
        "Accelerometer offset X: a small non-zero value, because all offsets 0 tells QGC the accelerometer is uncalibrated. The OpenROV IMU calibrates itself: no effect."),
    def("INS_ACCOFFS_Y", Real32, -0.002, -3.5, 3.5, "m/s²", Compat,
        "Accelerometer offset Y (non-zero so QGC shows setup complete). No effect."),
    def("INS_ACCOFFS_Z", Real32, 0.003, -3.5, 3.5, "m/s²", Compat,
        "Accelerometer offset Z (non-zero so QGC shows setup complete). No effect."),
];

/// QGC's Tuning page; the heading (yaw) and depth (Z) gains are used by
/// Neptunus' heading hold and depth hold, the rest exist for QGC only.
#[rustfmt::skip]
const TUNING: &[ParamDef] = &[
    def("ATC_ANG_PIT_P", Real32, 4.5, 3.0, 12.0, "", Compat,
        "Pitch angle P gain. Neptunus has no pitch control: no effect."),
    def("ATC_ANG_RLL_P", Real32, 4.5, 3.0, 12.0, "", Compat,
        "Roll angle P gain. Neptunus has no roll control: no effect."),
    def("ATC_ANG_YAW_P", Real32, 2.0, 1.0, 12.0, "1/s", Neptunus,
        "Heading hold: heading error (rad) to yaw rate target (rad/s).").short("Heading hold: heading error to yaw rate"),
    def("ATC_RAT_PIT_P", Real32, 0.135, 0.0, 0.5, "", Compat,
        "Pitch rate P gain. No effect."),
    def("ATC_RAT_PIT_I", Real32, 0.09, 0.0, 2.0, "", Compat,
        "Pitch rate I gain. No effect."),
    def("ATC_RAT_PIT_IMAX", Real32, 0.444, 0.0, 1.0, "", Compat,
        "Pitch rate I limit. No effect."),
    def("ATC_RAT_PIT_D", Real32, 0.0036, 0.0, 0.05, "", Compat,
        "Pitch rate D gain. No effect."),
    def("ATC_RAT_RLL_P", Real32, 0.135, 0.0, 0.5, "", Compat,
        "Roll rate P gain. No effect."),
    def("ATC_RAT_RLL_I", Real32, 0.09, 0.0, 2.0, "", Compat,
        "Roll rate I gain. No effect."),
    def("ATC_RAT_RLL_IMAX", Real32, 0.444, 0.0, 1.0, "", Compat,
        "Roll rate I limit. No effect."),
    def("ATC_RAT_RLL_D", Real32, 0.0036, 0.0, 0.05, "", Compat,
        "Roll rate D gain. No effect."),
    def("ATC_RAT_YAW_P", Real32, 1.5, 0.0, 2.5, "", Neptunus,
        "Heading hold: yaw rate error (rad/s) to yaw demand (-1..1) P gain.").short("Heading hold: yaw rate P gain"),
    def("ATC_RAT_YAW_I", Real32, 0.2, 0.0, 2.0, "", Neptunus,
        "Heading hold: yaw rate I gain (trims a steady yaw moment, e.g. unequal thrusters).").short("Heading hold: yaw rate I gain"),
    def("ATC_RAT_YAW_IMAX", Real32, 0.3, 0.0, 1.0, "", Neptunus,
        "Heading hold: limit of the yaw rate integrator, as a fraction of full yaw demand.").short("Heading hold: yaw rate I limit"),
    def("ATC_RAT_YAW_D", Real32, 0.0, 0.0, 0.1, "", Neptunus,
        "Heading hold: yaw rate D gain, on the measured rate (no kick on a target step).").short("Heading hold: yaw rate D gain"),
    def("ATC_RAT_YAW_FF", Real32, 0.3, 0.0, 1.0, "", Neptunus,
        "Heading hold: yaw rate target (rad/s) to yaw demand feed-forward.").short("Heading hold: yaw rate feed-forward"),
    def("NEPT_HDG_BAND", Real32, 1.5, 0.0, 10.0, "deg", Neptunus,
        "Heading hold rests the thrusters while the heading is within this of the target and not turning: the ESC deadzone makes the smallest yaw moment a sizeable one.").short("Heading hold: band in which the thrusters rest"),
    def("ACRO_YAW_P", Real32, 1.0, 0.2, 4.0, "", Neptunus,
        "Yaw rate at full yaw stick in STABILIZE and ALT_HOLD, in units of 45 deg/s (1.0 = 45 deg/s). Also the largest rate the heading hold commands.").short("Yaw rate at full yaw stick"),
    def("PSC_POSXY_P", Real32, 1.0, 0.5, 2.0, "", Compat,
        "Horizontal position P gain. Neptunus has no position estimate: no effect."),
    def("PSC_POSZ_P", Real32, 1.0, 0.2, 3.0, "1/s", Neptunus,
        "Depth hold: depth error (m) to climb rate target (m/s).").short("Depth hold: depth error to climb rate"),
    def("PSC_VELXY_P", Real32, 2.0, 0.1, 6.0, "", Compat,
        "Horizontal velocity P gain. No effect."),
    def("PSC_VELXY_I", Real32, 1.0, 0.02, 1.0, "", Compat,
        "Horizontal velocity I gain. No effect."),
    def("PSC_VELXY_IMAX", Real32, 100.0, 0.0, 4500.0, "cm/s²", Compat,
        "Horizontal velocity I limit. No effect."),
    def("PSC_VELZ_P", Real32, 3.0, 0.0, 10.0, "", Neptunus,
        "Depth hold: climb rate error (m/s) to vertical demand (-1..1) P gain. (ArduPilot's velocity loop outputs an acceleration for a third loop; the OpenROV board reports no vertical acceleration, so Neptunus' velocity loop drives the thruster.)").short("Depth hold: climb rate P gain"),
    def("PSC_VELZ_I", Real32, 1.5, 0.0, 10.0, "", Neptunus,
        "Depth hold: climb rate I gain (holds the buoyancy and tether trim).").short("Depth hold: climb rate I gain"),
    def("PSC_VELZ_IMAX", Real32, 0.5, 0.0, 1.0, "", Neptunus,
        "Depth hold: limit of the climb rate integrator, as a fraction of full vertical demand.").short("Depth hold: climb rate I limit"),
    def("PSC_VELZ_D", Real32, 0.0, 0.0, 1.0, "", Neptunus,
        "Depth hold: climb rate D gain, on the measured rate (no kick on a target step).").short("Depth hold: climb rate D gain"),
    def("PSC_VELZ_FF", Real32, 1.3, 0.0, 3.0, "", Neptunus,
        "Depth hold: climb rate target (m/s) to vertical demand feed-forward.").short("Depth hold: climb rate feed-forward"),
    def("PILOT_SPEED_UP", Real32, 40.0, 10.0, 500.0, "cm/s", Neptunus,
        "Ascent speed at full heave stick in ALT_HOLD, the fastest the depth hold climbs to a new target, and SURFACE's ascent speed.").short("Ascent speed at full heave stick"),
    def("PILOT_SPEED_DN", Real32, 40.0, 10.0, 500.0, "cm/s", Neptunus,
        "Descent speed at full heave stick in ALT_HOLD and the fastest the depth hold descends to a new target.").short("Descent speed at full heave stick"),
    def("PSC_ACCZ_P", Real32, 0.5, 0.2, 1.5, "", Compat,
        "Vertical acceleration P gain. The OpenROV board reports no vertical acceleration: no effect (see PSC_VELZ_*)."),
    def("PSC_ACCZ_I", Real32, 0.1, 0.0, 3.0, "", Compat,
        "Vertical acceleration I gain. No effect (see PSC_VELZ_I)."),
    def("PSC_ACCZ_IMAX", Real32, 100.0, 0.0, 1000.0, "d%", Compat,
        "Vertical acceleration I limit. No effect (see PSC_VELZ_IMAX)."),
    def("PSC_ACCZ_D", Real32, 0.0, 0.0, 0.4, "", Compat,
        "Vertical acceleration D gain. No effect."),
    def("PSC_ACCZ_FLTD", Real32, 0.0, 0.0, 100.0, "Hz", Compat,
        "Vertical acceleration D filter. No effect."),
    def("PSC_ACCZ_FLTE", Real32, 20.0, 0.0, 100.0, "Hz", Compat,
        "Vertical acceleration error filter. No effect."),
    def("PSC_ACCZ_FLTT", Real32, 0.0, 0.0, 100.0, "Hz", Compat,
        "Vertical acceleration target filter. No effect."),
    def("WPNAV_ACCEL", Real32, 100.0, 50.0, 500.0, "cm/s²", Compat,
        "Waypoint horizontal acceleration. Neptunus has no waypoint navigation: no effect."),
    def("WPNAV_ACCEL_Z", Real32, 100.0, 50.0, 500.0, "cm/s²", Compat,
        "Waypoint vertical acceleration. No effect."),
    def("WPNAV_RADIUS", Real32, 200.0, 5.0, 1000.0, "cm", Compat,
        "Waypoint radius. No effect."),
    def("WPNAV_SPEED", Real32, 500.0, 20.0, 2000.0, "cm/s", Compat,
        "Waypoint horizontal speed. No effect."),
    def("WPNAV_SPEED_DN", Real32, 150.0, 10.0, 500.0, "cm/s", Compat,
        "Waypoint descent speed. No effect."),
    def("WPNAV_SPEED_UP", Real32, 250.0, 10.0, 1000.0, "cm/s", Compat,
        "Waypoint ascent speed. No effect."),
    def("LOIT_SPEED", Real32, 1250.0, 20.0, 3500.0, "cm/s", Compat,
        "Position-hold speed. Neptunus has no position hold: no effect."),
    def("LOIT_ACC_MAX", Real32, 500.0, 100.0, 981.0, "cm/s²", Compat,
        "Position-hold acceleration. No effect."),
    def("LOIT_ANG_MAX", Real32, 0.0, 0.0, 45.0, "deg", Compat,
        "Position-hold lean angle. No effect."),
    def("LOIT_BRK_ACCEL", Real32, 250.0, 25.0, 250.0, "cm/s²", Compat,
        "Position-hold braking acceleration. No effect."),
    def("LOIT_BRK_DELAY", Real32, 1.0, 0.0, 2.0, "s", Compat,
        "Position-hold braking delay. No effect."),
    def("LOIT_BRK_JERK", Real32, 500.0, 500.0, 5000.0, "cm/s³", Compat,
        "Position-hold braking jerk. No effect."),
];

const SR_DOC: &str = "Legacy stream rate of this telemetry group on link 0. Neptunus schedules \
     telemetry per message (REQUEST_DATA_STREAM, SET_MESSAGE_INTERVAL) instead: no effect.";

/// Legacy stream rates and output hardware description (at the end).
#[rustfmt::skip]
const TAIL: &[ParamDef] = &[
    def("SR0_RAW_SENS", Int16, 2.0, 0.0, 50.0, "Hz", Compat, SR_DOC).short("Legacy stream rate: raw sensors"),
    def("SR0_EXT_STAT", Int16, 2.0, 0.0, 50.0, "Hz", Compat, SR_DOC).short("Legacy stream rate: extended status"),
    def("SR0_RC_CHAN", Int16, 2.0, 0.0, 50.0, "Hz", Compat, SR_DOC).short("Legacy stream rate: RC channels"),
    def("SR0_POSITION", Int16, 3.0, 0.0, 50.0, "Hz", Compat, SR_DOC).short("Legacy stream rate: position"),
    def("SR0_EXTRA1", Int16, 10.0, 0.0, 50.0, "Hz", Compat, SR_DOC).short("Legacy stream rate: extra 1"),
    def("SR0_EXTRA2", Int16, 10.0, 0.0, 50.0, "Hz", Compat, SR_DOC).short("Legacy stream rate: extra 2"),
    def("SR0_EXTRA3", Int16, 3.0, 0.0, 50.0, "Hz", Compat, SR_DOC).short("Legacy stream rate: extra 3"),
    def("BRD_PWM_COUNT", Int8, 8.0, 0.0, 16.0, "", Compat,
        "Number of outputs used as PWM (QGC's Lights page reads it). No effect."),
];

static DEFS: LazyLock<Vec<ParamDef>> = LazyLock::new(|| {
    let mut defs = Vec::with_capacity(
        HEAD.len() + 2 * BUTTONS + SAFETY.len() + SENSORS.len() + TUNING.len() + TAIL.len() + 16,
    );
    defs.extend_from_slice(HEAD);
    // The short names number the buttons; built once, they live as long
    // as the table.
    let leak = |s: String| -> &'static str { Box::leak(s.into_boxed_str()) };
    for (i, (name, sname)) in BTN_NAMES.iter().enumerate() {
        let (function, shifted) = BTN_DEFAULTS.get(i).copied().unwrap_or((0, 0));
        defs.push(
            def(
                name,
                Int16,
                function.into(),
                0.0,
                BTN_FUNCTION_LASER_TOGGLE.into(),
                "",
                Neptunus,
                BTN_DOC,
            )
            .values(BUTTON_FUNCTION_NAMES)
            .short(leak(format!("Function of joystick button {i}"))),
        );
        defs.push(
            def(
                sname,
                Int16,
                shifted.into(),
                0.0,
                BTN_FUNCTION_LASER_TOGGLE.into(),
                "",
                Neptunus,
                BTN_DOC,
            )
            .values(BUTTON_FUNCTION_NAMES)
            .short(leak(format!(
                "Function of joystick button {i} while shift is held"
            ))),
        );
    }
    defs.extend_from_slice(SAFETY);
    defs.extend_from_slice(SENSORS);
    defs.extend_from_slice(TUNING);
    defs.extend_from_slice(TAIL);
    for (name, function, doc) in SERVOS {
        // Its fixed value, named.
        let named = SERVO_VALUES
            .iter()
            .position(|(v, _)| f64::from(*v) == function)
            .map_or(&[][..], |i| &SERVO_VALUES[i..=i]);
        let output = name
            .trim_start_matches("SERVO")
            .trim_end_matches("_FUNCTION");
        defs.push(
            def(name, Int16, function, function, function, "", Compat, doc)
                .values(named)
                .short(leak(format!("Output {output} function"))),
        );
    }
    defs
});

/// The names' index. The core reads parameters by name on every tick, so
/// the key hash is FNV-1a rather than SipHash: the table is fixed (nothing
/// from the network is inserted), so SipHash's defence against chosen
/// colliding keys buys nothing here, and it costs several times more.
static INDEX: LazyLock<HashMap<&'static str, usize, BuildHasherDefault<Fnv1a>>> =
    LazyLock::new(|| DEFS.iter().enumerate().map(|(i, d)| (d.name, i)).collect());

/// FNV-1a, 64 bits.
struct Fnv1a(u64);

impl Default for Fnv1a {
    fn default() -> Fnv1a {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
}

impl Hasher for Fnv1a {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

/// Every parameter, in index order (PARAM_REQUEST_READ by index uses it).
pub fn definitions() -> &'static [ParamDef] {
    &DEFS
}

/// Index of the parameter called `name` (exact, case-sensitive).
pub fn index_of(name: &str) -> Option<usize> {
    INDEX.get(name).copied()
}
