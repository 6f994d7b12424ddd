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

/// Every button function code with ArduSub's name for it (and ours, 101),
/// in code order: the values BTNn_FUNCTION and BTNn_SFUNCTION offer in the
/// parameter metadata. Codes Neptunus has nothing for say "(no effect)".
pub const BUTTON_FUNCTION_NAMES: &[(i32, &str)] = &[
    (0, "disabled"),
    (1, "shift"),
    (2, "arm_toggle"),
    (3, "arm"),
    (4, "disarm"),
    (5, "mode_manual"),
    (6, "mode_stabilize"),
    (7, "mode_depth_hold"),
    (8, "mode_poshold"),
    (9, "mode_auto"),
    (10, "mode_circle"),
    (11, "mode_guided"),
    (12, "mode_acro"),
    (13, "mode_surftrak"),
    (21, "mount_center"),
    (22, "mount_tilt_up"),
    (23, "mount_tilt_down"),
    (24, "camera_trigger (no effect)"),
    (25, "camera_source_toggle (no effect)"),
    (26, "mount_pan_right (no effect)"),
    (27, "mount_pan_left (no effect)"),
    (31, "lights1_cycle"),
    (32, "lights1_brighter"),
    (33, "lights1_dimmer"),
    (34, "lights2_cycle (no effect)"),
    (35, "lights2_brighter (no effect)"),
    (36, "lights2_dimmer (no effect)"),
    (41, "gain_toggle"),
    (42, "gain_inc"),
    (43, "gain_dec"),
    (44, "trim_roll_inc (no effect)"),
    (45, "trim_roll_dec (no effect)"),
    (46, "trim_pitch_inc (no effect)"),
    (47, "trim_pitch_dec (no effect)"),
    (48, "input_hold_set"),
    (49, "roll_pitch_toggle (no effect)"),
    (51, "relay_1_on (no effect)"),
    (52, "relay_1_off (no effect)"),
    (53, "relay_1_toggle (no effect)"),
    (54, "relay_2_on (no effect)"),
    (55, "relay_2_off (no effect)"),
    (56, "relay_2_toggle (no effect)"),
    (57, "relay_3_on (no effect)"),
    (58, "relay_3_off (no effect)"),
    (59, "relay_3_toggle (no effect)"),
    (61, "servo_1_inc (no effect)"),
    (62, "servo_1_dec (no effect)"),
    (63, "servo_1_min (no effect)"),
    (64, "servo_1_max (no effect)"),
    (65, "servo_1_center (no effect)"),
    (66, "servo_2_inc (no effect)"),
    (67, "servo_2_dec (no effect)"),
    (68, "servo_2_min (no effect)"),
    (69, "servo_2_max (no effect)"),
    (70, "servo_2_center (no effect)"),
    (71, "servo_3_inc (no effect)"),
    (72, "servo_3_dec (no effect)"),
    (73, "servo_3_min (no effect)"),
    (74, "servo_3_max (no effect)"),
    (75, "servo_3_center (no effect)"),
    (76, "servo_1_min_momentary (no effect)"),
    (77, "servo_1_max_momentary (no effect)"),
    (78, "servo_1_min_toggle (no effect)"),
    (79, "servo_1_max_toggle (no effect)"),
    (80, "servo_2_min_momentary (no effect)"),
    (81, "servo_2_max_momentary (no effect)"),
    (82, "servo_2_min_toggle (no effect)"),
    (83, "servo_2_max_toggle (no effect)"),
    (84, "servo_3_min_momentary (no effect)"),
    (85, "servo_3_max_momentary (no effect)"),
    (86, "servo_3_min_toggle (no effect)"),
    (87, "servo_3_max_toggle (no effect)"),
    (91, "custom_1 (no effect)"),
    (92, "custom_2 (no effect)"),
    (93, "custom_3 (no effect)"),
    (94, "custom_4 (no effect)"),
    (95, "custom_5 (no effect)"),
    (96, "custom_6 (no effect)"),
    (BTN_FUNCTION_LASER_TOGGLE as i32, "laser_toggle (Neptunus)"),
];

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

    #[test]
    fn every_button_code_is_named_and_the_unused_say_so() {
        let named: Vec<u8> = BUTTON_FUNCTION_NAMES
            .iter()
            .map(|(c, _)| *c as u8)
            .collect();
        let known: Vec<u8> = (0..=255).filter(|&c| is_button_function(c)).collect();
        assert_eq!(named, known);
        for (code, name) in BUTTON_FUNCTION_NAMES {
            let unused = matches!(
                ButtonFunction::from_code(*code as u8),
                Some(ButtonFunction::Unsupported(_))
            );
            assert_eq!(unused, name.ends_with("(no effect)"), "{code} {name}");
        }
    }
}
