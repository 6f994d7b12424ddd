//! The fixed tables of the parameters that come in rows of many: the
//! joystick buttons' BTNn_FUNCTION/SFUNCTION pairs with ArduSub's default
//! map, and the virtual outputs' SERVOn_FUNCTION values ground stations read
//! to learn the vehicle's hardware. Data only; `defs.rs` makes their rows.

/// Number of joystick buttons with a BTNn_FUNCTION/SFUNCTION pair.
pub const BUTTONS: usize = 32;

macro_rules! button_names {
    ($($n:literal)*) => {
        [$((concat!("BTN", $n, "_FUNCTION"), concat!("BTN", $n, "_SFUNCTION"))),*]
    };
}

pub(super) const BTN_NAMES: [(&str, &str); BUTTONS] = button_names!(
    0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29 30 31
);

/// ArduSub's default button map (regular, shifted) for buttons 0..15;
/// buttons 16..31 default to 0 (none).
pub const BTN_DEFAULTS: [(u8, u8); 16] = [
    (0, 0),   // 0: none
    (5, 0),   // 1: mode_manual
    (7, 0),   // 2: mode_depth_hold
    (6, 0),   // 3: mode_stabilize
    (4, 0),   // 4: disarm
    (1, 0),   // 5: shift
    (3, 0),   // 6: arm
    (21, 0),  // 7: mount_center
    (48, 0),  // 8: input_hold_set
    (23, 27), // 9: mount_tilt_down / mount_pan_left
    (22, 26), // 10: mount_tilt_up / mount_pan_right
    (42, 47), // 11: gain_inc / trim_pitch_dec
    (43, 46), // 12: gain_dec / trim_pitch_inc
    (33, 45), // 13: lights1_dimmer / trim_roll_dec
    (32, 44), // 14: lights1_brighter / trim_roll_inc
    (0, 0),   // 15: none
];

pub(super) const BTN_DOC: &str = "Function of joystick button n (SFUNCTION: while shift is held): an \
     ArduSub code (0 none, 1 shift, 2 arm_toggle, 3 arm, 4 disarm, 5-13 modes, 21-27 mount and \
     camera, 31-36 lights, 41-49 gain, trim and input hold, 51-59 relays, 61-87 actuators, \
     91-96 custom) or 101 = Neptunus' laser toggle. Arming needs some button on 4 or 2.";

/// Virtual output map (SERVOn_FUNCTION): what QGC's Lights and Motors pages
/// need to see for Neptunus' hardware.
pub(super) const SERVOS: [(&str, f64, &str); 16] = [
    (
        "SERVO1_FUNCTION",
        33.0,
        "Output 1 = motor 1 (starboard thruster). Fixed: describes Neptunus' hardware for ground stations; no effect.",
    ),
    (
        "SERVO2_FUNCTION",
        34.0,
        "Output 2 = motor 2 (port thruster). Fixed: describes Neptunus' hardware for ground stations; no effect.",
    ),
    (
        "SERVO3_FUNCTION",
        35.0,
        "Output 3 = motor 3 (vertical thruster). Fixed: describes Neptunus' hardware for ground stations; no effect.",
    ),
    (
        "SERVO4_FUNCTION",
        0.0,
        "Output 4: unused. Fixed; no effect.",
    ),
    (
        "SERVO5_FUNCTION",
        0.0,
        "Output 5: unused. Fixed; no effect.",
    ),
    (
        "SERVO6_FUNCTION",
        60.0,
        "Output 6 = lights 2 (60), which is the laser on Neptunus, so QGC's Lights page finds it. Fixed; no effect.",
    ),
    (
        "SERVO7_FUNCTION",
        59.0,
        "Output 7 = lights 1 (59), the lamp, so QGC's Lights page finds it. Fixed; no effect.",
    ),
    (
        "SERVO8_FUNCTION",
        7.0,
        "Output 8 = camera tilt (7). Fixed: describes Neptunus' hardware for ground stations; no effect.",
    ),
    (
        "SERVO9_FUNCTION",
        0.0,
        "Output 9: unused. Fixed; no effect.",
    ),
    (
        "SERVO10_FUNCTION",
        0.0,
        "Output 10: unused. Fixed; no effect.",
    ),
    (
        "SERVO11_FUNCTION",
        0.0,
        "Output 11: unused. Fixed; no effect.",
    ),
    (
        "SERVO12_FUNCTION",
        0.0,
        "Output 12: unused. Fixed; no effect.",
    ),
    (
        "SERVO13_FUNCTION",
        0.0,
        "Output 13: unused. Fixed; no effect.",
    ),
    (
        "SERVO14_FUNCTION",
        0.0,
        "Output 14: unused. Fixed; no effect.",
    ),
    (
        "SERVO15_FUNCTION",
        0.0,
        "Output 15: unused. Fixed; no effect.",
    ),
    (
        "SERVO16_FUNCTION",
        0.0,
        "Output 16: unused. Fixed; no effect.",
    ),
];
