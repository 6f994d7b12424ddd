//! The parameter set: what QGroundControl needs, validation, TOML storage and
//! the user guide's table.

use std::collections::HashSet;
use std::fs;

use neptunus::dialect::neptunus::MavParamType;
use neptunus::vehicle::params::{
    BTN_DEFAULTS, ControlClaim, FailsafeAction, ParamError, ParamFile, ParamStore, ParamType, Use,
    definitions, index_of, is_button_function, markdown_table,
};

/// Every parameter QGroundControl reads from an ArduSub vehicle
/// (shared/reference/qgc-ardusub-params.md), plus what ArduSub users expect.
const QGC_READS: &[&str] = &[
    // At connect.
    "COMPASS_DEV_ID",
    "COMPASS_DEV_ID2",
    "COMPASS_DEV_ID3",
    "INS_ACCOFFS_X",
    "INS_ACCOFFS_Y",
    "INS_ACCOFFS_Z",
    // Setup summary.
    "COMPASS_OFS_X",
    "COMPASS_OFS_Y",
    "COMPASS_OFS_Z",
    "COMPASS_OFS2_X",
    "COMPASS_OFS2_Y",
    "COMPASS_OFS2_Z",
    "COMPASS_OFS3_X",
    "COMPASS_OFS3_Y",
    "COMPASS_OFS3_Z",
    "COMPASS_DEC",
    "BATT_MONITOR",
    "FS_GCS_ENABLE",
    "FS_LEAK_ENABLE",
    "LEAK1_PIN",
    "LEAK1_LOGIC",
    "FS_PILOT_INPUT",
    "FS_PILOT_TIMEOUT",
    "FS_EKF_ACTION",
    "FS_EKF_THRESH",
    "FS_PRESS_ENABLE",
    "FS_PRESS_MAX",
    "FS_TEMP_ENABLE",
    "FS_TEMP_MAX",
    "SERVO5_FUNCTION",
    "SERVO6_FUNCTION",
    "SERVO7_FUNCTION",
    "SERVO8_FUNCTION",
    "SERVO9_FUNCTION",
    "SERVO10_FUNCTION",
    "SERVO11_FUNCTION",
    "SERVO12_FUNCTION",
    "SERVO13_FUNCTION",
    "SERVO14_FUNCTION",
    "FRAME_CONFIG",
    // Sensors page.
    "AHRS_ORIENTATION",
    "COMPASS_AUTODEC",
    // Battery drawer.
    "BATT_FS_LOW_ACT",
    "BATT_LOW_VOLT",
    "BATT_LOW_MAH",
    "BATT_FS_CRT_ACT",
    "BATT_CRT_VOLT",
    "BATT_CRT_MAH",
    // Status drawer.
    "FS_GCS_TIMEOUT",
    "FS_OPTIONS",
    // Motors page.
    "MOT_1_DIRECTION",
    "MOT_2_DIRECTION",
    "MOT_3_DIRECTION",
    // Lights page.
    "SERVO15_FUNCTION",
    "SERVO16_FUNCTION",
    "JS_LIGHTS_STEPS",
    "BRD_PWM_COUNT",
    // Tuning page.
    "ATC_ANG_PIT_P",
    "ATC_ANG_RLL_P",
    "ATC_ANG_YAW_P",
    "ATC_RAT_PIT_P",
    "ATC_RAT_PIT_I",
    "ATC_RAT_PIT_IMAX",
    "ATC_RAT_PIT_D",
    "ATC_RAT_RLL_P",
    "ATC_RAT_RLL_I",
    "ATC_RAT_RLL_IMAX",
    "ATC_RAT_RLL_D",
    "ATC_RAT_YAW_P",
    "ATC_RAT_YAW_I",
    "ATC_RAT_YAW_IMAX",
    "ATC_RAT_YAW_D",
    "PSC_POSXY_P",
    "PSC_POSZ_P",
    "PSC_VELXY_P",
    "PSC_VELXY_I",
    "PSC_VELXY_IMAX",
    "PSC_VELZ_P",
    "PSC_ACCZ_D",
    "PSC_ACCZ_FLTD",
    "PSC_ACCZ_FLTE",
    "PSC_ACCZ_FLTT",
    "PSC_ACCZ_I",
    "PSC_ACCZ_IMAX",
    "PSC_ACCZ_P",
    "WPNAV_ACCEL",
    "WPNAV_ACCEL_Z",
    "WPNAV_RADIUS",
    "WPNAV_SPEED",
    "WPNAV_SPEED_DN",
    "WPNAV_SPEED_UP",
    "LOIT_SPEED",
    "LOIT_ACC_MAX",
    "LOIT_ANG_MAX",
    "LOIT_BRK_ACCEL",
    "LOIT_BRK_DELAY",
    "LOIT_BRK_JERK",
    // Not read by QGC, expected by ArduSub users and scripts.
    "SYSID_MYGCS",
    "SYSID_THISMAV",
    "SURFACE_DEPTH",
    "JS_GAIN_DEFAULT",
    "JS_GAIN_MIN",
    "JS_GAIN_MAX",
    "JS_GAIN_STEPS",
    "JS_THR_GAIN",
    "ARMING_CHECK",
    "BATT_CAPACITY",
];

/// Present, these turn on QGC pages or checks that do not fit Neptunus.
const MUST_BE_ABSENT: &[&str] = &[
    "FRAME_CLASS",
    "ARMING_REQUIRE",
    "MNT1_TYPE",
    "BARO1_DEVID",
    "COMPASS_PRIO1_ID",
];

fn def(name: &str) -> &'static neptunus::vehicle::params::ParamDef {
    &definitions()[index_of(name).unwrap_or_else(|| panic!("{name} missing"))]
}

#[test]
fn every_parameter_qgc_reads_exists() {
    let missing: Vec<_> = QGC_READS.iter().filter(|n| index_of(n).is_none()).collect();
    assert!(missing.is_empty(), "missing: {missing:?}");
    for i in 0..32 {
        assert!(index_of(&format!("BTN{i}_FUNCTION")).is_some());
        assert!(index_of(&format!("BTN{i}_SFUNCTION")).is_some());
    }
}

#[test]
fn qgc_types_match_ardusub() {
    let expect = [
        ("COMPASS_DEV_ID", ParamType::Int32),
        ("INS_ACCOFFS_X", ParamType::Real32),
        ("BATT_MONITOR", ParamType::Int8),
        ("FS_PRESS_MAX", ParamType::Int32),
        ("FRAME_CONFIG", ParamType::Int8),
        ("FS_GCS_TIMEOUT", ParamType::Real32),
        ("FS_OPTIONS", ParamType::Int32),
        ("MOT_1_DIRECTION", ParamType::Int8),
        ("JS_LIGHTS_STEPS", ParamType::Int16),
        ("BRD_PWM_COUNT", ParamType::Int8),
        ("SERVO7_FUNCTION", ParamType::Int16),
        ("BTN4_FUNCTION", ParamType::Int16),
        ("SYSID_THISMAV", ParamType::Int16),
        ("SYSID_MYGCS", ParamType::Int16),
    ];
    for (name, ty) in expect {
        assert_eq!(def(name).ty, ty, "{name}");
    }
    for name in QGC_READS.iter().filter(|n| {
        ["ATC_", "PSC_", "WPNAV_", "LOIT_"]
            .iter()
            .any(|p| n.starts_with(p))
    }) {
        assert_eq!(def(name).ty, ParamType::Real32, "{name}");
    }
}

#[test]
fn forbidden_parameters_are_absent() {
    for name in MUST_BE_ABSENT {
        assert!(index_of(name).is_none(), "{name} must not exist");
    }
}

#[test]
fn no_unsigned_types_on_the_wire() {
    for d in definitions() {
        let t = d.ty.mav_type();
        assert!(
            !matches!(
                t,
                MavParamType::MAV_PARAM_TYPE_UINT8
                    | MavParamType::MAV_PARAM_TYPE_UINT16
                    | MavParamType::MAV_PARAM_TYPE_UINT32
            ),
            "{} is {t:?}",
            d.name
        );
    }
    assert_eq!(
        ParamType::Int8.mav_type(),
        MavParamType::MAV_PARAM_TYPE_INT8
    );
    assert_eq!(
        ParamType::Int16.mav_type(),
        MavParamType::MAV_PARAM_TYPE_INT16
    );
    assert_eq!(
        ParamType::Int32.mav_type(),
        MavParamType::MAV_PARAM_TYPE_INT32
    );
    assert_eq!(
        ParamType::Real32.mav_type(),
        MavParamType::MAV_PARAM_TYPE_REAL32
    );
}

#[test]
fn names_fit_mavlink_and_are_unique() {
    let mut seen = HashSet::new();
    for (i, d) in definitions().iter().enumerate() {
        assert!(
            !d.name.is_empty() && d.name.len() <= 16,
            "{} is {} bytes",
            d.name,
            d.name.len()
        );
        assert!(
            d.name
                .bytes()
                .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b'_'),
            "{}",
            d.name
        );
        assert!(seen.insert(d.name), "{} twice", d.name);
        assert_eq!(index_of(d.name), Some(i));
    }
}

#[test]
fn defaults_are_in_range_and_fit_their_type() {
    let store = ParamStore::defaults();
    assert_eq!(store.len(), definitions().len());
    assert!(!store.is_empty());
    for (i, d) in definitions().iter().enumerate() {
        assert!(d.min <= d.default && d.default <= d.max, "{}", d.name);
        let (lo, hi) = d.ty.limits();
        assert!(
            lo <= d.min && d.max <= hi,
            "{} range exceeds its type",
            d.name
        );
        if d.ty != ParamType::Real32 {
            assert_eq!(d.default.fract(), 0.0, "{} default not integral", d.name);
            assert_eq!(d.min.fract(), 0.0, "{}", d.name);
            assert_eq!(d.max.fract(), 0.0, "{}", d.name);
        }
        assert!(!d.doc.is_empty(), "{} undocumented", d.name);
        if d.used == Use::Compat {
            assert!(
                d.doc.to_lowercase().contains("no effect"),
                "{} is compat-only, its doc must say it has no effect",
                d.name
            );
        }
        // Every default is accepted by set() unchanged.
        let (got, value) = store.get_index(i).expect("index");
        assert_eq!(got.name, d.name);
        let mut copy = store.clone();
        assert_eq!(copy.set(d.name, value), Ok(value), "{}", d.name);
        assert_eq!(copy, store);
    }
    assert!(store.get_index(definitions().len()).is_none());
}

#[test]
fn specified_defaults() {
    let s = ParamStore::defaults();
    let cases: &[(&str, f64)] = &[
        ("SYSID_THISMAV", 1.0),
        ("SYSID_MYGCS", 255.0),
        ("COMPASS_DEV_ID", 0.0),
        ("COMPASS_DEV_ID2", 0.0),
        ("COMPASS_DEV_ID3", 0.0),
        ("BATT_MONITOR", 4.0),
        ("BATT_LOW_VOLT", 10.5),
        ("FS_GCS_ENABLE", 2.0),
        ("FS_GCS_TIMEOUT", 5.0),
        ("FS_PILOT_INPUT", 2.0),
        ("FS_PILOT_TIMEOUT", 3.0),
        ("LEAK1_PIN", -1.0),
        ("FRAME_CONFIG", 4.0),
        ("MOT_1_DIRECTION", 1.0),
        ("MOT_2_DIRECTION", -1.0),
        ("MOT_3_DIRECTION", 1.0),
        ("MOT_PWM_MIN", 1100.0),
        ("MOT_PWM_MAX", 1900.0),
        ("JS_GAIN_DEFAULT", 0.5),
        ("JS_GAIN_MIN", 0.25),
        ("JS_GAIN_MAX", 1.0),
        ("JS_GAIN_STEPS", 4.0),
        ("JS_THR_GAIN", 1.0),
        ("JS_LIGHTS_STEPS", 8.0),
        ("SURFACE_DEPTH", -10.0),
        ("ARMING_CHECK", 1.0),
        ("SERVO1_FUNCTION", 33.0),
        ("SERVO2_FUNCTION", 34.0),
        ("SERVO3_FUNCTION", 35.0),
        ("SERVO4_FUNCTION", 0.0),
        ("SERVO5_FUNCTION", 0.0),
        ("SERVO6_FUNCTION", 60.0),
        ("SERVO7_FUNCTION", 59.0),
        ("SERVO8_FUNCTION", 7.0),
        ("SERVO14_FUNCTION", 0.0),
        ("SR0_RAW_SENS", 2.0),
        ("SR0_EXT_STAT", 2.0),
        ("SR0_RC_CHAN", 2.0),
        ("SR0_POSITION", 3.0),
        ("SR0_EXTRA1", 10.0),
        ("SR0_EXTRA2", 10.0),
        ("SR0_EXTRA3", 3.0),
        ("NEPT_CTRL_CLAIM", 0.0),
        ("NEPT_GCS_ALLOW1", 245.0),
        ("NEPT_GCS_ALLOW2", 0.0),
        ("NEPT_TILT_MIN_US", 1000.0),
        ("NEPT_TILT_MAX_US", 2000.0),
        ("NEPT_LIGHTS_MAX", 255.0),
    ];
    for (name, value) in cases {
        assert_eq!(s.get(name), Some(*value), "{name}");
    }
    // Accelerometer offsets all 0 would turn QGC's setup red.
    let offs: Vec<f64> = ["INS_ACCOFFS_X", "INS_ACCOFFS_Y", "INS_ACCOFFS_Z"]
        .iter()
        .map(|n| s.get(n).expect("exists"))
        .collect();
    assert!(offs.iter().any(|v| *v != 0.0), "{offs:?}");
    assert!(offs.iter().all(|v| v.abs() < 0.01), "{offs:?}");
    // Heading and depth controller gains are real; roll/pitch/position are not.
    for name in [
        "ATC_ANG_YAW_P",
        "ATC_RAT_YAW_P",
        "PSC_POSZ_P",
        "PSC_VELZ_P",
        "PSC_VELZ_I",
        "PILOT_SPEED_UP",
        "ACRO_YAW_P",
    ] {
        assert_eq!(def(name).used, Use::Neptunus, "{name}");
    }
    for name in [
        "ATC_ANG_PIT_P",
        "ATC_RAT_RLL_P",
        "PSC_POSXY_P",
        // No vertical accelerometer reading from the board: no acceleration loop.
        "PSC_ACCZ_I",
        "WPNAV_SPEED",
        "LOIT_SPEED",
    ] {
        assert_eq!(def(name).used, Use::Compat, "{name}");
    }
}

#[test]
fn button_defaults_match_ardusub() {
    // (button, regular, shifted) from ArduSub's default map.
    let expected: [(usize, u8, u8); 16] = [
        (0, 0, 0),
        (1, 5, 0),
        (2, 7, 0),
        (3, 6, 0),
        (4, 4, 0),
        (5, 1, 0),
        (6, 3, 0),
        (7, 21, 0),
        (8, 48, 0),
        (9, 23, 27),
        (10, 22, 26),
        (11, 42, 47),
        (12, 43, 46),
        (13, 33, 45),
        (14, 32, 44),
        (15, 0, 0),
    ];
    let s = ParamStore::defaults();
    for (i, f, sf) in expected {
        assert_eq!(s.btn_function(i, false), f, "BTN{i}_FUNCTION");
        assert_eq!(s.btn_function(i, true), sf, "BTN{i}_SFUNCTION");
        assert_eq!(BTN_DEFAULTS[i], (f, sf));
    }
    for i in 16..32 {
        assert_eq!(s.btn_function(i, false), 0);
        assert_eq!(s.btn_function(i, true), 0);
    }
    assert_eq!(s.btn_function(32, false), 0);
    // ArduSub refuses to arm unless some button disarms.
    assert!(s.some_button_disarms());
    assert_eq!(s.get("BTN4_FUNCTION"), Some(4.0));
    let mut s = s;
    s.set("BTN4_FUNCTION", 0.0).expect("valid");
    assert!(!s.some_button_disarms());
    s.set("BTN20_SFUNCTION", 2.0).expect("arm_toggle is valid");
    assert!(s.some_button_disarms());
}

#[test]
fn out_of_range_is_refused_and_old_value_kept() {
    let mut s = ParamStore::defaults();
    let before = s.clone();
    let err = s.set("FS_GCS_TIMEOUT", 1.0).expect_err("below 2 s");
    assert_eq!(
        err,
        ParamError::OutOfRange {
            name: "FS_GCS_TIMEOUT".into(),
            value: 1.0,
            min: 2.0,
            max: 120.0
        }
    );
    assert!(
        err.to_string()
            .contains("FS_GCS_TIMEOUT = 1 is outside 2..120")
    );
    assert!(s.set("SYSID_THISMAV", 256.0).is_err());
    assert!(s.set("SYSID_THISMAV", 0.0).is_err());
    assert!(s.set("FRAME_CONFIG", 5.0).is_err());
    assert!(s.set("COMPASS_DEV_ID", 1.0).is_err());
    assert!(s.set("FS_PILOT_TIMEOUT", 3.5).is_err());
    assert!(s.set("BATT_LOW_VOLT", 1e300).is_err());
    assert_eq!(s, before);
    assert_eq!(s.set("FS_GCS_TIMEOUT", 120.0), Ok(120.0));
    assert_eq!(s.fs_gcs_timeout_s(), 120.0);
}

#[test]
fn integers_round_toward_zero_like_a_c_cast() {
    let mut s = ParamStore::defaults();
    assert_eq!(s.set("SYSID_THISMAV", 7.9), Ok(7.0));
    assert_eq!(s.get("SYSID_THISMAV"), Some(7.0));
    assert_eq!(s.sysid_thismav(), 7);
    assert_eq!(s.set("MOT_1_DIRECTION", -1.7), Ok(-1.0));
    assert_eq!(s.mot_direction(1), -1);
    assert_eq!(s.set("LEAK1_PIN", -0.5), Ok(0.0));
    // 255.99 casts to 255, inside the range.
    assert_eq!(s.set("SYSID_MYGCS", 255.99), Ok(255.0));
    // 0.9 casts to 0, outside 1..255.
    assert!(matches!(
        s.set("SYSID_MYGCS", 0.9),
        Err(ParamError::OutOfRange { .. })
    ));
    assert_eq!(s.get("SYSID_MYGCS"), Some(255.0));
    // REAL32 values are stored as the f32 that travels.
    assert_eq!(s.set("JS_THR_GAIN", 1.1), Ok(f64::from(1.1f32)));
    // A bound such as 0.1 accepts 0.1 sent as REAL32 (slightly above or below).
    assert!(s.set("FS_PILOT_TIMEOUT", f64::from(0.1f32)).is_ok());
    assert!(s.set("FS_EKF_THRESH", f64::from(0.6f32)).is_ok());
}

#[test]
fn non_finite_and_unknown_are_refused() {
    let mut s = ParamStore::defaults();
    let before = s.clone();
    for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert!(
            matches!(s.set("JS_GAIN_DEFAULT", v), Err(ParamError::Invalid { .. })),
            "{v}"
        );
        assert!(s.set("SYSID_MYGCS", v).is_err());
    }
    assert_eq!(
        s.set("FRAME_CLASS", 1.0),
        Err(ParamError::Unknown("FRAME_CLASS".into()))
    );
    assert!(
        s.set("sysid_thismav", 2.0).is_err(),
        "names are case-sensitive"
    );
    assert_eq!(s.get("NOPE"), None);
    assert_eq!(s, before);
}

#[test]
fn motor_direction_zero_is_refused() {
    let mut s = ParamStore::defaults();
    for m in 1..=3 {
        let name = format!("MOT_{m}_DIRECTION");
        let err = s.set(&name, 0.0).expect_err("0 is not a direction");
        assert!(matches!(err, ParamError::Invalid { .. }), "{err}");
        // 0.5 casts to 0: refused too.
        assert!(s.set(&name, 0.5).is_err());
        assert!(s.set(&name, 2.0).is_err());
    }
    assert_eq!(s.mot_direction(1), 1);
    assert_eq!(s.mot_direction(2), -1);
    assert_eq!(s.mot_direction(3), 1);
    assert_eq!(s.mot_direction(4), 1);
}

#[test]
fn unknown_button_function_is_refused() {
    let mut s = ParamStore::defaults();
    for code in [14.0, 20.0, 37.0, 50.0, 60.0, 88.0, 97.0, 100.0, 102.0, -1.0] {
        assert!(s.set("BTN3_FUNCTION", code).is_err(), "{code}");
        assert!(s.set("BTN30_SFUNCTION", code).is_err(), "{code}");
    }
    assert_eq!(s.btn_function(3, false), 6);
    for code in [0u8, 13, 21, 27, 31, 36, 41, 49, 51, 59, 61, 87, 91, 96, 101] {
        assert!(is_button_function(code));
        assert_eq!(s.set("BTN3_FUNCTION", f64::from(code)), Ok(f64::from(code)));
        assert_eq!(s.btn_function(3, false), code);
    }
}

#[test]
fn paired_limits_stay_ordered() {
    let mut s = ParamStore::defaults();
    assert!(s.set("MOT_PWM_MIN", 1500.0).is_err());
    assert!(s.set("MOT_PWM_MIN", 1600.0).is_err());
    assert!(s.set("MOT_PWM_MAX", 1500.0).is_err());
    assert!(s.set("MOT_PWM_MAX", 1400.0).is_err());
    assert_eq!(s.set("MOT_PWM_MIN", 1000.0), Ok(1000.0));
    assert_eq!(s.set("MOT_PWM_MAX", 2000.0), Ok(2000.0));
    assert_eq!((s.mot_pwm_min(), s.mot_pwm_max()), (1000, 2000));
    assert!(s.set("NEPT_TILT_MIN_US", 2000.0).is_err());
    assert!(s.set("NEPT_TILT_MAX_US", 1000.0).is_err());
    assert_eq!(s.set("NEPT_TILT_MIN_US", 1999.0), Ok(1999.0));
}

#[test]
fn typed_accessors() {
    let mut s = ParamStore::defaults();
    assert_eq!(s.sysid_thismav(), 1);
    assert_eq!(s.sysid_mygcs(), 255);
    assert_eq!(s.js_gain_default(), 0.5);
    assert_eq!(s.js_gain_min(), 0.25);
    assert_eq!(s.js_gain_max(), 1.0);
    assert_eq!(s.js_gain_steps(), 4);
    assert_eq!(s.js_thr_gain(), 1.0);
    assert_eq!(s.js_lights_steps(), 8);
    assert_eq!(s.fs_gcs_enable(), FailsafeAction::Disarm);
    assert_eq!(s.fs_gcs_timeout_s(), 5.0);
    assert_eq!(s.fs_pilot_input(), FailsafeAction::Disarm);
    assert_eq!(s.fs_pilot_timeout_s(), 3.0);
    assert_eq!(s.batt_low_volt(), 10.5);
    assert_eq!(s.batt_fs_low_act(), FailsafeAction::Warn);
    assert_eq!(s.batt_crt_volt(), 0.0);
    assert_eq!(s.batt_fs_crt_act(), FailsafeAction::Off);
    assert!((s.surface_depth_m() - -0.1).abs() < 1e-6);
    assert_eq!((s.tilt_min_us(), s.tilt_max_us()), (1000, 2000));
    assert_eq!(s.lights_max(), 255);
    assert_eq!(s.ctrl_claim(), ControlClaim::FirstToDrive);
    assert_eq!(s.gcs_allowed_extra(), vec![245]);
    assert!(s.gcs_allowed(255) && s.gcs_allowed(245) && !s.gcs_allowed(1) && !s.gcs_allowed(0));
    assert!(s.atc_ang_yaw_p() > 0.0 && s.atc_rat_yaw().p > 0.0 && s.psc_accz().p > 0.0);
    assert!(s.psc_posz_p() > 0.0 && s.psc_velz_p() > 0.0);

    s.set("FS_GCS_ENABLE", 3.0).expect("valid");
    assert_eq!(s.fs_gcs_enable(), FailsafeAction::DepthHold);
    s.set("FS_GCS_ENABLE", 4.0).expect("valid");
    assert_eq!(s.fs_gcs_enable(), FailsafeAction::Surface);
    s.set("FS_PILOT_INPUT", 0.0).expect("valid");
    assert_eq!(s.fs_pilot_input(), FailsafeAction::Off);
    s.set("NEPT_CTRL_CLAIM", 1.0).expect("valid");
    assert_eq!(s.ctrl_claim(), ControlClaim::ExplicitOnly);
    // The default gain stays inside a narrowed min..max.
    s.set("JS_GAIN_MIN", 0.6).expect("valid");
    assert_eq!(s.js_gain_default(), 0.6);
    s.set("JS_GAIN_MAX", 0.3).expect("valid");
    assert!(s.js_gain_max() >= s.js_gain_min());
}

#[test]
fn toml_round_trip_writes_only_changes() {
    let defaults = ParamStore::defaults();
    let text = defaults.to_toml();
    assert!(
        text.lines().all(|l| l.starts_with('#')),
        "defaults write nothing: {text}"
    );

    let mut s = ParamStore::defaults();
    s.set("SYSID_THISMAV", 3.0).expect("valid");
    s.set("MOT_2_DIRECTION", 1.0).expect("valid");
    s.set("JS_THR_GAIN", 1.35).expect("valid");
    s.set("BATT_LOW_VOLT", 11.0).expect("valid");
    s.set("BTN15_SFUNCTION", 101.0).expect("valid");
    s.set("NEPT_TILT_MAX_US", 900.0).expect_err("below min");
    s.set("NEPT_TILT_MIN_US", 600.0).expect("valid");
    s.set("NEPT_TILT_MAX_US", 900.0).expect("valid");
    // Set back to its default: not written.
    s.set("FS_GCS_TIMEOUT", 9.0).expect("valid");
    s.set("FS_GCS_TIMEOUT", 5.0).expect("valid");
    let text = s.to_toml();
    let entries: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(
        entries,
        [
            "BATT_LOW_VOLT = 11.0",
            "BTN15_SFUNCTION = 101",
            "JS_THR_GAIN = 1.35",
            "MOT_2_DIRECTION = 1",
            "NEPT_TILT_MAX_US = 900",
            "NEPT_TILT_MIN_US = 600",
            "SYSID_THISMAV = 3",
        ]
    );
    // NEPT_TILT_MAX_US = 900 comes first and only fits once the minimum is applied.
    let (back, warnings) = ParamStore::from_toml(&text).expect("TOML");
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(back, s);
}

#[test]
fn from_toml_skips_bad_entries_with_line_numbers() {
    let text = "# comment\n\
                SYSID_THISMAV = 9\n\
                NO_SUCH_PARAM = 1\n\
                FS_GCS_TIMEOUT = 1000.0\n\
                MOT_1_DIRECTION = 0\n\
                JS_GAIN_STEPS = \"many\"\n\
                BTN1_FUNCTION = 99\n\
                JS_THR_GAIN = 2.5\n";
    let (s, warnings) = ParamStore::from_toml(text).expect("TOML");
    assert_eq!(s.get("SYSID_THISMAV"), Some(9.0));
    assert_eq!(s.get("JS_THR_GAIN"), Some(2.5));
    assert_eq!(s.get("FS_GCS_TIMEOUT"), Some(5.0));
    assert_eq!(s.get("MOT_1_DIRECTION"), Some(1.0));
    assert_eq!(s.get("JS_GAIN_STEPS"), Some(4.0));
    assert_eq!(s.get("BTN1_FUNCTION"), Some(5.0));
    assert_eq!(warnings.len(), 5, "{warnings:#?}");
    let expect = [
        ("line 3:", "NO_SUCH_PARAM"),
        ("line 4:", "FS_GCS_TIMEOUT"),
        ("line 5:", "MOT_1_DIRECTION"),
        ("line 6:", "JS_GAIN_STEPS"),
        ("line 7:", "BTN1_FUNCTION"),
    ];
    for (w, (line, name)) in warnings.iter().zip(expect) {
        assert!(w.starts_with(line) && w.contains(name), "{w}");
    }
    assert!(ParamStore::from_toml("this is = = not toml").is_err());
}

#[test]
fn file_save_load_round_trip() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    let file = ParamFile::new(&data);
    assert_eq!(file.path(), data.join("params.toml"));
    // Missing file (and missing directory): defaults, no warnings.
    let (s, warnings) = file.load();
    assert_eq!(s, ParamStore::defaults());
    assert!(warnings.is_empty());

    let mut s = ParamStore::defaults();
    s.set("SYSID_MYGCS", 200.0).expect("valid");
    s.set("PSC_ACCZ_I", 0.25).expect("valid");
    file.save(&s).expect("save");
    assert!(!data.join("params.toml.tmp").exists());
    let (back, warnings) = file.load();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(back, s);

    // Saving again replaces the file.
    s.set("SYSID_MYGCS", 201.0).expect("valid");
    file.save(&s).expect("save");
    assert_eq!(file.load().0, s);
}

#[test]
fn corrupt_file_is_moved_aside_never_overwriting() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = ParamFile::new(dir.path());
    let garbage1: &[u8] = b"\x00\xff\xfe garbage \x81\n[[[";
    fs::write(file.path(), garbage1).expect("write");
    let (s, warnings) = file.load();
    assert_eq!(s, ParamStore::defaults());
    let aside1 = dir.path().join("params.toml.corrupt-1");
    assert_eq!(warnings.len(), 1);
    assert!(
        warnings[0].contains(&aside1.display().to_string()),
        "{warnings:?}"
    );
    assert_eq!(fs::read(&aside1).expect("aside file"), garbage1);
    assert!(!file.path().exists());

    let garbage2: &[u8] = b"SYSID_THISMAV = = 3\n";
    fs::write(file.path(), garbage2).expect("write");
    let (s, warnings) = file.load();
    assert_eq!(s, ParamStore::defaults());
    let aside2 = dir.path().join("params.toml.corrupt-2");
    assert!(
        warnings[0].contains(&aside2.display().to_string()),
        "{warnings:?}"
    );
    assert_eq!(fs::read(&aside1).expect("first aside kept"), garbage1);
    assert_eq!(fs::read(&aside2).expect("second aside"), garbage2);
}

#[test]
fn partly_bad_file_applies_the_good_values() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = ParamFile::new(dir.path());
    fs::write(
        file.path(),
        "SYSID_THISMAV = 4\nFRAME_CLASS = 2\nMOT_PWM_MAX = 1950\nMOT_PWM_MIN = 1700\n",
    )
    .expect("write");
    let (s, warnings) = file.load();
    assert_eq!(s.sysid_thismav(), 4);
    assert_eq!(s.mot_pwm_max(), 1950);
    assert_eq!(s.mot_pwm_min(), 1100);
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    let shown = file.path().display().to_string();
    assert!(
        warnings[0].starts_with(&format!("{shown}: line 2:")),
        "{warnings:?}"
    );
    assert!(warnings[0].contains("FRAME_CLASS"));
    assert!(
        warnings[1].starts_with(&format!("{shown}: line 4:")),
        "{warnings:?}"
    );
    // Not moved aside: it was TOML.
    assert!(file.path().exists());
    assert!(!dir.path().join("params.toml.corrupt-1").exists());
}

const BEGIN: &str = "<!-- params:begin -->";
const END: &str = "<!-- params:end -->";
/// The guide's parameter page, which embeds the table.
const PAGE: &str = "docs/guide/src/parameters.md";
/// Set to 1 to rewrite the table instead of comparing (named `UPDATE_README`
/// while the table lived in README.md).
const UPDATE: &str = "UPDATE_GUIDE";

/// The guide's parameter page holds exactly `markdown_table()` between its
/// markers. With `UPDATE_GUIDE=1` this rewrites the table instead of
/// comparing.
#[test]
fn guide_parameter_table_is_current() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(PAGE);
    let page = fs::read_to_string(&path).expect(PAGE);
    let table = markdown_table();
    let section = format!("{BEGIN}\n{table}{END}");
    let current = match (page.find(BEGIN), page.find(END)) {
        (Some(b), Some(e)) if b < e => Some((b, e + END.len())),
        _ => None,
    };
    let regenerate = format!("run `{UPDATE}=1 cargo test --test params`");
    if std::env::var(UPDATE).as_deref() == Ok("1") {
        let updated = match current {
            Some((b, e)) => format!("{}{section}{}", &page[..b], &page[e..]),
            None => format!(
                "{}\n\n## Every parameter\n\nGenerated from `src/vehicle/params/defs.rs` \
                 (`{UPDATE}=1 cargo test --test params` rewrites it).\n\n{section}\n",
                page.trim_end()
            ),
        };
        fs::write(&path, updated).expect(PAGE);
        return;
    }
    let (b, e) = current.unwrap_or_else(|| {
        panic!("{PAGE} has no parameter table between its markers: {regenerate}")
    });
    assert!(
        page[b..e] == section,
        "{PAGE}'s parameter table is out of date: {regenerate}"
    );
}

#[test]
fn markdown_table_lists_every_parameter() {
    let table = markdown_table();
    let rows: Vec<&str> = table.lines().skip(2).collect();
    assert_eq!(rows.len(), definitions().len());
    for (row, d) in rows.iter().zip(definitions()) {
        assert!(row.starts_with(&format!("| `{}` |", d.name)), "{row}");
        assert_eq!(row.matches(" | ").count(), 6, "{row}");
    }
    assert!(table.contains("| `FRAME_CONFIG` | INT8 | 4 | fixed 4 |"));
    assert!(table.contains("| `BATT_LOW_VOLT` | REAL32 | 10.5 | 0.0 … 30.0 | V | Neptunus |"));
}

mod arbitrary_writes {
    use super::*;
    use proptest::prelude::*;

    /// A write to parameter `index`: either any f64 (NaN, huge, negative…) or
    /// a value inside the parameter's range, so that most writes land.
    fn write() -> impl Strategy<Value = (usize, f64)> {
        let n = definitions().len();
        (0..n, any::<bool>(), any::<f64>(), 0.0..=1.0f64).prop_map(|(i, inside, raw, frac)| {
            let d = &definitions()[i];
            let v = if inside {
                d.min + frac * (d.max - d.min)
            } else {
                raw
            };
            (i, v)
        })
    }

    proptest! {
        /// Whatever is written, the store only ever holds values a ground
        /// station can receive: in range, integral for integer types, exact
        /// f32 for REAL32; and what is saved reads back identically.
        #[test]
        fn store_invariants_and_round_trip(writes in proptest::collection::vec(write(), 0..40)) {
            let mut s = ParamStore::defaults();
            for (i, v) in writes {
                let name = definitions()[i].name;
                let before = s.clone();
                match s.set(name, v) {
                    Ok(stored) => prop_assert_eq!(s.get(name), Some(stored)),
                    Err(_) => prop_assert_eq!(&s, &before),
                }
            }
            for (i, d) in definitions().iter().enumerate() {
                let (_, v) = s.get_index(i).expect("index");
                prop_assert!(v.is_finite());
                prop_assert!(v as f32 >= d.min as f32 && v as f32 <= d.max as f32, "{} = {}", d.name, v);
                if d.ty == ParamType::Real32 {
                    prop_assert_eq!(f64::from(v as f32), v);
                } else {
                    prop_assert_eq!(v.fract(), 0.0);
                }
            }
            prop_assert!(s.mot_pwm_min() < 1500 && s.mot_pwm_max() > 1500);
            prop_assert!(s.tilt_min_us() < s.tilt_max_us());
            let (back, warnings) = ParamStore::from_toml(&s.to_toml()).expect("TOML");
            prop_assert!(warnings.is_empty(), "{:?}", warnings);
            prop_assert_eq!(back, s);
        }

        /// from_toml never panics, whatever the text: random text, or lines
        /// of real names with number-like values.
        #[test]
        fn from_toml_never_panics(
            text in ".{0,200}",
            lines in proptest::collection::vec(
                (0..definitions().len(), "[-+0-9.eE_a-z\"]{1,12}"), 0..20),
        ) {
            let _ = ParamStore::from_toml(&text);
            let doc: String = lines
                .iter()
                .map(|(i, v)| format!("{} = {v}\n", definitions()[*i].name))
                .collect();
            if let Ok((store, warnings)) = ParamStore::from_toml(&doc) {
                prop_assert!(warnings.len() <= lines.len());
                prop_assert_eq!(store.len(), definitions().len());
            }
        }
    }
}

/// A kill between writing `params.toml.tmp` and renaming it leaves the tmp
/// file; the next start removes it (params.toml, the last complete save,
/// is what counts).
#[test]
fn a_stale_tmp_file_is_removed_and_params_toml_kept() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = ParamFile::new(dir.path());
    assert!(!file.remove_stale_tmp().expect("nothing to remove"));
    let mut s = ParamStore::defaults();
    s.set("JS_GAIN_DEFAULT", 0.6).expect("valid");
    file.save(&s).expect("save");
    fs::write(file.tmp_path(), "JS_GAIN_DEFAULT = 0.9\n").expect("write");
    assert_eq!(file.tmp_path(), dir.path().join("params.toml.tmp"));
    assert!(file.remove_stale_tmp().expect("removed"));
    assert!(!file.tmp_path().exists());
    assert_eq!(file.load().0, s);
}

/// Saving into a directory that cannot exist (a file in the way: fails for
/// root too) is an error naming the path, and leaves nothing behind.
#[test]
fn a_save_that_cannot_write_is_an_error_naming_the_place() {
    let dir = tempfile::tempdir().expect("tempdir");
    let blocker = dir.path().join("data");
    fs::write(&blocker, "a file").expect("write");
    let file = ParamFile::new(&blocker);
    let err = file.save(&ParamStore::defaults()).expect_err("cannot save");
    assert!(
        err.to_string().contains(&blocker.display().to_string()),
        "{err}"
    );
}

#[test]
fn the_vehicle_never_shares_a_ground_stations_system_id() {
    let mut s = ParamStore::defaults();
    for id in [255.0, 245.0] {
        assert!(
            matches!(s.set("SYSID_THISMAV", id), Err(ParamError::Invalid { .. })),
            "{id}"
        );
    }
    assert!(s.set("SYSID_MYGCS", 1.0).is_err(), "the vehicle's own id");
    assert!(s.set("NEPT_GCS_ALLOW2", 1.0).is_err());
    assert_eq!(s.set("SYSID_THISMAV", 2.0), Ok(2.0));
    assert_eq!(s.set("SYSID_MYGCS", 1.0), Ok(1.0), "1 is free now");
    // INT32 extremes: the float nearest i32::MAX means i32::MAX.
    assert_eq!(
        s.set("ARMING_CHECK", f64::from(i32::MAX as f32)),
        Ok(f64::from(i32::MAX))
    );
}
