//! The one vocabulary for flight modes: ArduSub's numbers (so QGroundControl's
//! Sub plugin and pymavlink's mode map work unchanged), Neptunus' own modes,
//! each mode's name, and whether Neptunus can honour it — and if not, why.
//!
//! The core, the joystick buttons, AVAILABLE_MODES, the HMI protocol and (via
//! the HMI's welcome message) the browser page all take modes from here; no
//! other code spells a mode number. The number is what goes over MAVLink
//! (HEARTBEAT.custom_mode, SET_MODE, MAV_CMD_DO_SET_MODE) and the HMI.

/// A flight mode, numbered as ArduSub numbers it (`custom_mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum Mode {
    Stabilize = 0,
    Acro = 1,
    AltHold = 2,
    Auto = 3,
    Guided = 4,
    Circle = 7,
    Surface = 9,
    PosHold = 16,
    Manual = 19,
    MotorDetect = 20,
    SurfTrak = 21,
    /// Neptunus' own mode: each thruster driven directly (NEPTUNUS_THRUSTERS).
    ManualThrusters = 100,
}

/// Why the modes that need a position estimate are refused.
const NO_POSITION: &str = "needs a position estimate, which this vehicle does not have";

impl Mode {
    /// Every mode, in the order AVAILABLE_MODES lists them (mode_index 1, 2, …).
    pub const ALL: [Mode; 12] = [
        Mode::Manual,
        Mode::ManualThrusters,
        Mode::Stabilize,
        Mode::Acro,
        Mode::AltHold,
        Mode::Auto,
        Mode::Guided,
        Mode::Circle,
        Mode::Surface,
        Mode::PosHold,
        Mode::MotorDetect,
        Mode::SurfTrak,
    ];

    /// The mode the vehicle starts in.
    pub const BOOT: Mode = Mode::Manual;

    /// The number on the wire (HEARTBEAT.custom_mode, SET_MODE, the HMI).
    pub const fn number(self) -> u32 {
        self as u32
    }

    /// The mode with this number, if there is one.
    pub fn from_number(number: u32) -> Option<Mode> {
        Self::ALL.into_iter().find(|m| m.number() == number)
    }

    /// ArduSub's name for the mode (AVAILABLE_MODES, STATUSTEXT, the HMI).
    pub const fn name(self) -> &'static str {
        match self {
            Mode::Stabilize => "STABILIZE",
            Mode::Acro => "ACRO",
            Mode::AltHold => "ALT_HOLD",
            Mode::Auto => "AUTO",
            Mode::Guided => "GUIDED",
            Mode::Circle => "CIRCLE",
            Mode::Surface => "SURFACE",
            Mode::PosHold => "POSHOLD",
            Mode::Manual => "MANUAL",
            Mode::MotorDetect => "MOTOR_DETECT",
            Mode::SurfTrak => "SURFTRAK",
            Mode::ManualThrusters => "MANUAL_THRUSTERS",
        }
    }

    /// The name of a mode number as received, "UNKNOWN" for none of ours.
    pub fn name_of(number: u32) -> &'static str {
        Self::from_number(number).map_or("UNKNOWN", Mode::name)
    }

    /// Why Neptunus can never honour this mode (None: it can, given the
    /// estimates it needs — see `Vehicle::hold_unavailable`).
    pub const fn refused(self) -> Option<&'static str> {
        match self {
            Mode::Manual
            | Mode::ManualThrusters
            | Mode::Stabilize
            | Mode::AltHold
            | Mode::Surface => None,
            Mode::Acro => Some("rate control is not implemented on this vehicle"),
            Mode::Auto | Mode::Guided | Mode::Circle | Mode::PosHold => Some(NO_POSITION),
            Mode::MotorDetect => Some("not available on this vehicle"),
            Mode::SurfTrak => Some("needs a rangefinder, which this vehicle does not have"),
        }
    }

    /// The heading controller drives yaw.
    pub const fn holds_heading(self) -> bool {
        matches!(self, Mode::Stabilize | Mode::AltHold)
    }

    /// A controller drives the vertical thruster.
    pub const fn holds_depth(self) -> bool {
        matches!(self, Mode::AltHold | Mode::Surface)
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_ardusubs_and_round_trip() {
        // pymavlink's mode_mapping_sub, plus our own 100.
        let ardusub = [
            (0, "STABILIZE"),
            (1, "ACRO"),
            (2, "ALT_HOLD"),
            (3, "AUTO"),
            (4, "GUIDED"),
            (7, "CIRCLE"),
            (9, "SURFACE"),
            (16, "POSHOLD"),
            (19, "MANUAL"),
            (20, "MOTOR_DETECT"),
            (21, "SURFTRAK"),
            (100, "MANUAL_THRUSTERS"),
        ];
        assert_eq!(ardusub.len(), Mode::ALL.len());
        for (number, name) in ardusub {
            let m = Mode::from_number(number).expect(name);
            assert_eq!((m.number(), m.name()), (number, name));
            assert_eq!(Mode::name_of(number), name);
        }
        assert_eq!(Mode::from_number(5), None);
        assert_eq!(Mode::name_of(5), "UNKNOWN");
    }

    #[test]
    fn every_mode_is_listed_once() {
        for m in Mode::ALL {
            assert_eq!(Mode::ALL.iter().filter(|&&n| n == m).count(), 1, "{m}");
        }
        assert_eq!(Mode::BOOT.refused(), None);
    }
}
