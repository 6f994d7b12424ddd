//! The parameter values ([`ParamStore`]): validating every write against
//! its definition, and the typed accessors through which the vehicle reads
//! parameters (with their units, clamps and decoded enums).
//!
//! Pure: it never touches a file, a socket or a clock (`params.toml` is
//! [`super::file`]'s).

use super::defs::{ParamDef, ParamType, definitions, index_of, wire_value};
use super::functions::{
    BTN_FUNCTION_ARM_TOGGLE, BTN_FUNCTION_DISARM, ServoFunction, is_button_function,
};
use super::outputs::{BTN_NAMES, BUTTONS};
use crate::vehicle::mixer::{BoardMotors, MixerConfig, NEUTRAL_US};

/// Rejected parameter writes.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    #[error("no parameter named {0}")]
    Unknown(String),
    #[error("{name} = {value} is outside {min}..{max}")]
    OutOfRange {
        name: String,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error("{name} = {value} is not a valid value: {why}")]
    Invalid {
        name: String,
        value: f64,
        why: String,
    },
}

/// What a failsafe does when it triggers, decoded from its ArduSub parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailsafeAction {
    Off,
    Warn,
    Disarm,
    DepthHold,
    Surface,
}

/// How an allowed ground station gets control of an unowned vehicle
/// (`NEPT_CTRL_CLAIM`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControlClaim {
    /// The first allowed GCS that drives or arms takes control (ArduSub-like).
    FirstToDrive,
    /// Only an explicit MAV_CMD_REQUEST_OPERATOR_CONTROL takes control.
    ExplicitOnly,
}

/// PID gains as ArduPilot names them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidGains {
    pub p: f32,
    pub i: f32,
    pub imax: f32,
    pub d: f32,
}

/// Neutral thruster pulse width; MOT_PWM_MIN/MAX must bracket it.
const PWM_NEUTRAL_US: f64 = NEUTRAL_US as f64;

/// The values of every parameter, aligned with [`definitions`].
#[derive(Debug, Clone, PartialEq)]
pub struct ParamStore {
    pub(super) values: Vec<f64>,
}

impl Default for ParamStore {
    fn default() -> Self {
        Self::defaults()
    }
}

impl ParamStore {
    /// Every parameter at its default.
    pub fn defaults() -> Self {
        Self {
            values: definitions()
                .iter()
                .map(|d| wire_value(d.ty, d.default))
                .collect(),
        }
    }

    pub fn len(&self) -> usize {
        self.values.len()
    }

    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    pub fn get(&self, name: &str) -> Option<f64> {
        index_of(name).map(|i| self.values[i])
    }

    pub fn get_index(&self, index: usize) -> Option<(&'static ParamDef, f64)> {
        Some((definitions().get(index)?, *self.values.get(index)?))
    }

    /// Validates and stores a value; returns the value stored.
    ///
    /// The value must be finite and inside the parameter's range. Integer
    /// parameters take it rounded toward zero, as a C cast would (1.9 → 1,
    /// -1.5 → -1); REAL32 parameters take it rounded to `f32`. Button
    /// functions must be a known code, motor directions ±1, and pairs that
    /// bracket something (MOT_PWM_MIN/MAX around neutral, the tilt range)
    /// must keep doing so. On error nothing changes.
    pub fn set(&mut self, name: &str, value: f64) -> Result<f64, ParamError> {
        let index = index_of(name).ok_or_else(|| ParamError::Unknown(name.to_owned()))?;
        let d = &definitions()[index];
        let invalid = |why: &str| ParamError::Invalid {
            name: d.name.to_owned(),
            value,
            why: why.to_owned(),
        };
        if !value.is_finite() {
            return Err(invalid("not a finite number"));
        }
        let mut v = wire_value(d.ty, value);
        if d.ty.is_integer() {
            // A float cannot tell 2147483647 from 2147483648: a station that
            // sends INT32's maximum (or any bound past 2^24) as a float
            // means the bound, so it is taken exactly.
            if v > d.max && (v as f32) == (d.max as f32) {
                v = d.max;
            } else if v < d.min && (v as f32) == (d.min as f32) {
                v = d.min;
            }
        }
        let outside = match d.ty {
            // Compare in f32 so a bound such as 0.7 accepts 0.7 sent as REAL32.
            ParamType::Real32 => {
                !v.is_finite() || (v as f32) < (d.min as f32) || (v as f32) > (d.max as f32)
            }
            _ => v < d.min || v > d.max,
        };
        if outside {
            return Err(ParamError::OutOfRange {
                name: d.name.to_owned(),
                value,
                min: d.min,
                max: d.max,
            });
        }
        if d.name.starts_with("BTN") {
            // In range 0..=101, so the cast is exact.
            if !is_button_function(v as u8) {
                return Err(invalid(
                    "not an ArduSub button function (0..13, 21..27, 31..36, 41..49, 51..59, 61..87, 91..96) nor 101 (Neptunus laser toggle)",
                ));
            }
        } else if d.name.starts_with("MOT_") && d.name.ends_with("_DIRECTION") {
            if v == 0.0 {
                return Err(invalid("a motor direction is 1 (normal) or -1 (reversed)"));
            }
        } else if d.name == "MOT_PWM_MIN" && v >= PWM_NEUTRAL_US {
            return Err(invalid(
                "must be below the 1500 µs neutral, or reverse demand would drive forward",
            ));
        } else if d.name == "MOT_PWM_MAX" && v <= PWM_NEUTRAL_US {
            return Err(invalid(
                "must be above the 1500 µs neutral, or forward demand would drive reverse",
            ));
        } else if d.name == "SYSID_THISMAV" && v == 255.0 {
            return Err(invalid(
                "255 is the ground stations' id (QGroundControl, MAVProxy, pymavlink)",
            ));
        } else if d.name == "SYSID_THISMAV"
            && (v == self.num("SYSID_MYGCS") || self.gcs_allowed_extra().contains(&(v as u8)))
        {
            return Err(invalid(
                "that is a ground station's id (SYSID_MYGCS or NEPT_GCS_ALLOWn)",
            ));
        } else if (d.name == "SYSID_MYGCS" || d.name.starts_with("NEPT_GCS_ALLOW"))
            && v != 0.0
            && v == self.num("SYSID_THISMAV")
        {
            return Err(invalid("that is the vehicle's own id (SYSID_THISMAV)"));
        } else if d.name == "NEPT_TILT_MIN_US" && v >= self.num("NEPT_TILT_MAX_US") {
            return Err(invalid("must be below NEPT_TILT_MAX_US"));
        } else if d.name == "NEPT_TILT_MAX_US" && v <= self.num("NEPT_TILT_MIN_US") {
            return Err(invalid("must be above NEPT_TILT_MIN_US"));
        }
        self.values[index] = v;
        Ok(v)
    }

    /// Value of a parameter the accessors know exists (tests check every one).
    fn num(&self, name: &'static str) -> f64 {
        match index_of(name) {
            Some(i) => self.values[i],
            None => {
                debug_assert!(
                    false,
                    "accessor for a parameter that does not exist: {name}"
                );
                0.0
            }
        }
    }

    fn f32_of(&self, name: &'static str) -> f32 {
        self.num(name) as f32
    }

    /// An integer parameter as `u8`, saturating (ranges keep it inside anyway).
    fn u8_of(&self, name: &'static str) -> u8 {
        self.num(name).clamp(0.0, 255.0) as u8
    }

    fn u16_of(&self, name: &'static str) -> u16 {
        self.num(name).clamp(0.0, f64::from(u16::MAX)) as u16
    }

    pub fn sysid_thismav(&self) -> u8 {
        self.u8_of("SYSID_THISMAV")
    }

    pub fn sysid_mygcs(&self) -> u8 {
        self.u8_of("SYSID_MYGCS")
    }

    /// The NEPT_GCS_ALLOWn system ids that are set (non-zero).
    pub fn gcs_allowed_extra(&self) -> Vec<u8> {
        [
            "NEPT_GCS_ALLOW1",
            "NEPT_GCS_ALLOW2",
            "NEPT_GCS_ALLOW3",
            "NEPT_GCS_ALLOW4",
        ]
        .into_iter()
        .map(|n| self.u8_of(n))
        .filter(|&id| id != 0)
        .collect()
    }

    /// Whether `sysid` may control the vehicle (SYSID_MYGCS or NEPT_GCS_ALLOWn).
    pub fn gcs_allowed(&self, sysid: u8) -> bool {
        sysid != 0 && (sysid == self.sysid_mygcs() || self.gcs_allowed_extra().contains(&sysid))
    }

    pub fn ctrl_claim(&self) -> ControlClaim {
        if self.num("NEPT_CTRL_CLAIM") == 1.0 {
            ControlClaim::ExplicitOnly
        } else {
            ControlClaim::FirstToDrive
        }
    }

    pub fn js_gain_min(&self) -> f32 {
        self.f32_of("JS_GAIN_MIN")
    }

    /// At least [`js_gain_min`](Self::js_gain_min), even if set lower.
    pub fn js_gain_max(&self) -> f32 {
        self.f32_of("JS_GAIN_MAX").max(self.js_gain_min())
    }

    /// Clamped to JS_GAIN_MIN..JS_GAIN_MAX.
    pub fn js_gain_default(&self) -> f32 {
        self.f32_of("JS_GAIN_DEFAULT")
            .max(self.js_gain_min())
            .min(self.js_gain_max())
    }

    pub fn js_gain_steps(&self) -> u8 {
        self.u8_of("JS_GAIN_STEPS").max(1)
    }

    pub fn js_thr_gain(&self) -> f32 {
        self.f32_of("JS_THR_GAIN")
    }

    pub fn js_lights_steps(&self) -> u16 {
        self.u16_of("JS_LIGHTS_STEPS").max(1)
    }

    /// Function code of button `i` (0..32), regular or shifted; 0 for any
    /// other button.
    pub fn btn_function(&self, i: usize, shifted: bool) -> u8 {
        BTN_NAMES.get(i).map_or(0, |(name, sname)| {
            self.u8_of(if shifted { sname } else { name })
        })
    }

    /// Whether some button (regular or shifted) disarms (disarm or
    /// arm_toggle); ArduSub refuses to arm otherwise.
    pub fn some_button_disarms(&self) -> bool {
        (0..BUTTONS).any(|i| {
            [false, true].into_iter().any(|s| {
                matches!(
                    self.btn_function(i, s),
                    BTN_FUNCTION_DISARM | BTN_FUNCTION_ARM_TOGGLE
                )
            })
        })
    }

    /// Direction of motor 1..=3 (1 starboard, 2 port, 3 vertical): 1 or -1.
    /// Motors without a parameter get 1.
    pub fn mot_direction(&self, motor: usize) -> i8 {
        let name = match motor {
            1 => "MOT_1_DIRECTION",
            2 => "MOT_2_DIRECTION",
            3 => "MOT_3_DIRECTION",
            _ => return 1,
        };
        if self.num(name) < 0.0 { -1 } else { 1 }
    }

    /// The board's motor mapping (its reverse multiplier as set here).
    pub fn board_motors(&self) -> BoardMotors {
        BoardMotors {
            reverse_multiplier: self.num("NEPT_ESC_REVMUL").clamp(1.0, 4.0) as u8,
            ..BoardMotors::default()
        }
    }

    pub fn mot_pwm_min(&self) -> u16 {
        self.u16_of("MOT_PWM_MIN")
    }

    pub fn mot_pwm_max(&self) -> u16 {
        self.u16_of("MOT_PWM_MAX")
    }

    /// FS_GCS_ENABLE: off, warn, disarm, depth hold or surface.
    pub fn fs_gcs_enable(&self) -> FailsafeAction {
        match self.num("FS_GCS_ENABLE") as i64 {
            0 => FailsafeAction::Off,
            1 => FailsafeAction::Warn,
            3 => FailsafeAction::DepthHold,
            4 => FailsafeAction::Surface,
            _ => FailsafeAction::Disarm,
        }
    }

    pub fn fs_gcs_timeout_s(&self) -> f32 {
        self.f32_of("FS_GCS_TIMEOUT")
    }

    /// FS_PILOT_INPUT: off, warn or disarm.
    pub fn fs_pilot_input(&self) -> FailsafeAction {
        match self.num("FS_PILOT_INPUT") as i64 {
            0 => FailsafeAction::Off,
            1 => FailsafeAction::Warn,
            _ => FailsafeAction::Disarm,
        }
    }

    /// Heading-hold gains (ATC_*), in SI units.
    pub fn heading_gains(&self) -> crate::vehicle::autopilot::HeadingGains {
        use crate::vehicle::autopilot::{HeadingGains, PidGains};
        HeadingGains {
            angle_p: self.num("ATC_ANG_YAW_P"),
            rate: PidGains {
                p: self.num("ATC_RAT_YAW_P"),
                i: self.num("ATC_RAT_YAW_I"),
                d: self.num("ATC_RAT_YAW_D"),
                imax: self.num("ATC_RAT_YAW_IMAX"),
                ff: self.num("ATC_RAT_YAW_FF"),
            },
            max_rate_rps: (self.num("ACRO_YAW_P") * 45.0).to_radians(),
            band_rad: self.num("NEPT_HDG_BAND").to_radians(),
        }
    }

    /// Depth-hold gains (PSC_*, PILOT_SPEED_*), in SI units.
    pub fn depth_gains(&self) -> crate::vehicle::autopilot::DepthGains {
        use crate::vehicle::autopilot::{DepthGains, PidGains};
        DepthGains {
            pos_p: self.num("PSC_POSZ_P"),
            vel: PidGains {
                p: self.num("PSC_VELZ_P"),
                i: self.num("PSC_VELZ_I"),
                d: self.num("PSC_VELZ_D"),
                imax: self.num("PSC_VELZ_IMAX"),
                ff: self.num("PSC_VELZ_FF"),
            },
            speed_up_mps: self.num("PILOT_SPEED_UP") / 100.0,
            speed_down_mps: self.num("PILOT_SPEED_DN") / 100.0,
        }
    }

    pub fn fs_pilot_timeout_s(&self) -> f32 {
        self.f32_of("FS_PILOT_TIMEOUT")
    }

    fn battery_action(&self, name: &'static str) -> FailsafeAction {
        match self.num(name) as i64 {
            1 => FailsafeAction::Warn,
            2 => FailsafeAction::Disarm,
            3 => FailsafeAction::Surface,
            _ => FailsafeAction::Off,
        }
    }

    /// Low-battery threshold; 0 = off.
    pub fn batt_low_volt(&self) -> f32 {
        self.f32_of("BATT_LOW_VOLT")
    }

    pub fn batt_fs_low_act(&self) -> FailsafeAction {
        self.battery_action("BATT_FS_LOW_ACT")
    }

    /// Critical-battery threshold; 0 = off.
    pub fn batt_crt_volt(&self) -> f32 {
        self.f32_of("BATT_CRT_VOLT")
    }

    pub fn batt_fs_crt_act(&self) -> FailsafeAction {
        self.battery_action("BATT_FS_CRT_ACT")
    }

    /// SURFACE_DEPTH converted from ArduSub's centimetres to metres
    /// (negative below the surface, -0.1 by default).
    pub fn surface_depth_m(&self) -> f32 {
        self.f32_of("SURFACE_DEPTH") / 100.0
    }

    /// The mixer's directions and PWM range, with the given pilot gain.
    pub fn mixer_config(&self, gain: f64) -> MixerConfig {
        MixerConfig {
            gain,
            directions: [
                self.mot_direction(2),
                self.mot_direction(3),
                self.mot_direction(1),
            ],
            pwm_min_us: self.mot_pwm_min(),
            pwm_max_us: self.mot_pwm_max(),
        }
    }

    /// What virtual output `n` (SERVOn_FUNCTION, 1..=16) drives; `None`
    /// for an output that does not exist.
    pub fn servo_function(&self, n: u32) -> Option<ServoFunction> {
        let i = index_of(&format!("SERVO{n}_FUNCTION"))?;
        Some(ServoFunction::from_code(
            self.values[i].clamp(0.0, 65535.0) as u16
        ))
    }

    pub fn tilt_min_us(&self) -> u16 {
        self.u16_of("NEPT_TILT_MIN_US")
    }

    pub fn tilt_max_us(&self) -> u16 {
        self.u16_of("NEPT_TILT_MAX_US")
    }

    pub fn lights_max(&self) -> u8 {
        self.u8_of("NEPT_LIGHTS_MAX")
    }

    /// Heading hold: heading error → yaw rate gain.
    pub fn atc_ang_yaw_p(&self) -> f32 {
        self.f32_of("ATC_ANG_YAW_P")
    }

    /// Heading hold: yaw rate PID.
    pub fn atc_rat_yaw(&self) -> PidGains {
        PidGains {
            p: self.f32_of("ATC_RAT_YAW_P"),
            i: self.f32_of("ATC_RAT_YAW_I"),
            imax: self.f32_of("ATC_RAT_YAW_IMAX"),
            d: self.f32_of("ATC_RAT_YAW_D"),
        }
    }

    /// Depth hold: depth error → climb rate gain.
    pub fn psc_posz_p(&self) -> f32 {
        self.f32_of("PSC_POSZ_P")
    }

    /// Depth hold: climb rate error → acceleration gain.
    pub fn psc_velz_p(&self) -> f32 {
        self.f32_of("PSC_VELZ_P")
    }

    /// Depth hold: vertical acceleration PID (IMAX in tenths of a percent).
    pub fn psc_accz(&self) -> PidGains {
        PidGains {
            p: self.f32_of("PSC_ACCZ_P"),
            i: self.f32_of("PSC_ACCZ_I"),
            imax: self.f32_of("PSC_ACCZ_IMAX"),
            d: self.f32_of("PSC_ACCZ_D"),
        }
    }
}
