//! The meanings of two parameter families, by name: what a joystick button
//! does (BTNn_FUNCTION, BTNn_SFUNCTION, ArduSub's codes) and what a virtual
//! output drives (SERVOn_FUNCTION, ArduPilot's codes). The codes travel as
//! parameter values; code that acts on them uses these enums.

use crate::vehicle::mode::Mode;

/// Button function code of Neptunus' own "toggle the laser" (not in ArduSub).
pub const BTN_FUNCTION_LASER_TOGGLE: u8 = 101;
/// ArduSub's button function "disarm".
pub const BTN_FUNCTION_DISARM: u8 = 4;
/// ArduSub's button function "arm_toggle".
pub const BTN_FUNCTION_ARM_TOGGLE: u8 = 2;

/// What a joystick button does, for the codes Neptunus acts on; every
/// other code ArduSub knows is [`ButtonFunction::Unsupported`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ButtonFunction {
    /// 0: nothing.
    None,
    /// 1: while held, buttons use their SFUNCTION.
    Shift,
    /// 2: arm when disarmed, disarm when armed.
    ArmToggle,
    /// 3
    Arm,
    /// 4
    Disarm,
    /// 5..13: mode_manual, mode_stabilize, mode_depth_hold, mode_poshold,
    /// mode_auto, mode_circle, mode_guided, mode_acro, mode_surftrak.
    Mode(Mode),
    /// 21: camera tilt to the middle.
    MountCenter,
    /// 22
    MountTiltUp,
    /// 23
    MountTiltDown,
    /// 31: lights one step brighter, and off after the brightest.
    LightsCycle,
    /// 32
    LightsBrighter,
    /// 33
    LightsDimmer,
    /// 41: pilot gain between its minimum and maximum.
    GainToggle,
    /// 42
    GainInc,
    /// 43
    GainDec,
    /// 48: hold the sticks' current input (again: release).
    InputHoldSet,
    /// 101: Neptunus' laser toggle.
    LaserToggle,
    /// An ArduSub code this vehicle has nothing for (relays, trims, pan …).
    Unsupported(u8),
}

/// The mode buttons 5..=13 in code order.
const MODE_BUTTONS: [Mode; 9] = [
    Mode::Manual,
    Mode::Stabilize,
    Mode::AltHold,
    Mode::PosHold,
    Mode::Auto,
    Mode::Circle,
    Mode::Guided,
    Mode::Acro,
    Mode::SurfTrak,
];

impl ButtonFunction {
    /// The function of a code; `None` for a code ArduSub does not know.
    pub fn from_code(code: u8) -> Option<Self> {
        use ButtonFunction as B;
        if !is_button_function(code) {
            return None;
        }
        Some(match code {
            0 => B::None,
            1 => B::Shift,
            BTN_FUNCTION_ARM_TOGGLE => B::ArmToggle,
            3 => B::Arm,
            BTN_FUNCTION_DISARM => B::Disarm,
            5..=13 => B::Mode(MODE_BUTTONS[usize::from(code - 5)]),
            21 => B::MountCenter,
            22 => B::MountTiltUp,
            23 => B::MountTiltDown,
            31 => B::LightsCycle,
            32 => B::LightsBrighter,
            33 => B::LightsDimmer,
            41 => B::GainToggle,
            42 => B::GainInc,
            43 => B::GainDec,
            48 => B::InputHoldSet,
            BTN_FUNCTION_LASER_TOGGLE => B::LaserToggle,
            other => B::Unsupported(other),
        })
    }
}

/// Whether `code` is a button function ArduSub knows (or our laser toggle).
pub fn is_button_function(code: u8) -> bool {
    matches!(code, 0..=13 | 21..=27 | 31..=36 | 41..=49 | 51..=59 | 61..=87 | 91..=96)
        || code == BTN_FUNCTION_LASER_TOGGLE
}

/// What a virtual output drives (SERVOn_FUNCTION), for the codes Neptunus
/// reports; the values are ArduPilot's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServoFunction {
    /// 0: nothing.
    Disabled,
    /// 7: the camera tilt servo.
    MountTilt,
    /// 33..=35: motor 1..3 (starboard, port, vertical).
    Motor(u8),
    /// 59: lights 1, the lamp.
    Lights1,
    /// 60: lights 2, which is the laser on Neptunus.
    Lights2,
    /// Any other code.
    Other(u16),
}

impl ServoFunction {
    pub fn from_code(code: u16) -> Self {
        match code {
            0 => Self::Disabled,
            7 => Self::MountTilt,
            33..=35 => Self::Motor((code - 32) as u8),
            59 => Self::Lights1,
            60 => Self::Lights2,
            other => Self::Other(other),
        }
    }

    pub fn code(self) -> u16 {
        match self {
            Self::Disabled => 0,
            Self::MountTilt => 7,
            Self::Motor(n) => 32 + u16::from(n),
            Self::Lights1 => 59,
            Self::Lights2 => 60,
            Self::Other(c) => c,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_mode_button_names_a_mode_and_codes_round_trip() {
        for code in 5..=13 {
            assert!(matches!(
                ButtonFunction::from_code(code),
                Some(ButtonFunction::Mode(_))
            ));
        }
        assert_eq!(
            ButtonFunction::from_code(7),
            Some(ButtonFunction::Mode(Mode::AltHold))
        );
        assert_eq!(ButtonFunction::from_code(14), None);
        assert_eq!(
            ButtonFunction::from_code(51),
            Some(ButtonFunction::Unsupported(51))
        );
        for code in 0..=100 {
            assert_eq!(ServoFunction::from_code(code).code(), code);
        }
    }
}
