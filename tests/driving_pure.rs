//! Driving, pure parts: the mixer, ground-station conventions, profiles and
//! the `profiles check` command.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;

use neptunus::sim::{self, SimState, ThesisModel, ThesisParams};
use neptunus::vehicle::input::{
    self, Profile, ProfileError, Profiles, RcAxis, RcValue, ZConvention, edges, rc_override,
    sticks_from_manual_control,
};
use neptunus::vehicle::mixer::{Demand, MixerConfig, mix, thruster_us};
use neptunus::vehicle::params::ParamStore;
use proptest::prelude::*;

const BIN: &str = env!("CARGO_BIN_EXE_neptunus");
/// The emulator's wiring: the port thruster is wired reversed.
const WIRING: [i8; 3] = [-1, 1, 1];

fn cfg(gain: f64) -> MixerConfig {
    MixerConfig {
        gain,
        directions: [1, 1, 1],
        pwm_min_us: 1100,
        pwm_max_us: 1900,
    }
}

fn d(surge: f64, heave: f64, yaw: f64) -> Demand {
    Demand { surge, heave, yaw }
}

// ---------------------------------------------------------------- mixer

#[test]
fn mixer_table() {
    // (demand, gain, [port, vertical, starboard]) with directions all +1.
    let cases: &[(Demand, f64, [u16; 3])] = &[
        (d(0.0, 0.0, 0.0), 1.0, [1500, 1500, 1500]),
        (d(1.0, 0.0, 0.0), 1.0, [1900, 1500, 1900]),
        (d(-1.0, 0.0, 0.0), 1.0, [1100, 1500, 1100]),
        (d(0.0, 1.0, 0.0), 1.0, [1500, 1900, 1500]),
        (d(0.0, -1.0, 0.0), 1.0, [1500, 1100, 1500]),
        // Full yaw: port and starboard opposite, port harder for + yaw.
        (d(0.0, 0.0, 1.0), 1.0, [1900, 1500, 1100]),
        (d(0.0, 0.0, -1.0), 1.0, [1100, 1500, 1900]),
        // Saturation: sat(k(X+M)) = sat(1.5) = 1, sat(k(X−M)) = 0.5.
        (d(1.0, 0.0, 0.5), 1.0, [1900, 1500, 1700]),
        (d(1.0, 0.0, 1.0), 1.0, [1900, 1500, 1500]),
        // Gain scales before saturation: 0.5·(1+1) = 1.
        (d(1.0, 0.0, 1.0), 0.5, [1900, 1500, 1500]),
        (d(1.0, 1.0, 0.0), 0.5, [1700, 1700, 1700]),
        (d(0.5, -0.5, 0.25), 0.5, [1650, 1400, 1550]),
        // Gain 0: nothing moves.
        (d(1.0, 1.0, 1.0), 0.0, [1500, 1500, 1500]),
        // Inputs past ±1 are clamped first.
        (d(7.0, -3.0, 0.0), 1.0, [1900, 1100, 1900]),
    ];
    for (i, (dem, gain, want)) in cases.iter().enumerate() {
        assert_eq!(
            mix(dem, &cfg(*gain)),
            *want,
            "case {i}: {dem:?} at gain {gain}"
        );
    }
}

#[test]
fn mixer_directions_flip_each_thruster() {
    let c = MixerConfig {
        directions: [-1, -1, 1],
        ..cfg(1.0)
    };
    assert_eq!(mix(&d(0.5, 0.5, 0.0), &c), [1300, 1300, 1700]);
    // Direction 0 disables a thruster; only the sign of other values counts.
    let c = MixerConfig {
        directions: [0, 5, -7],
        ..cfg(1.0)
    };
    assert_eq!(mix(&d(1.0, 1.0, 0.0), &c), [1500, 1900, 1100]);
}

#[test]
fn mixer_asymmetric_range() {
    let c = MixerConfig {
        pwm_min_us: 1300,
        pwm_max_us: 2000,
        ..cfg(1.0)
    };
    assert_eq!(mix(&d(1.0, -1.0, 0.0), &c), [2000, 1300, 2000]);
    assert_eq!(mix(&d(0.5, -0.5, 0.0), &c), [1750, 1400, 1750]);
    assert_eq!(mix(&d(0.0, 0.0, 0.0), &c), [1500, 1500, 1500]);
}

#[test]
fn mixer_from_params_uses_mot_directions_and_range() {
    let mut p = ParamStore::defaults();
    let c = p.mixer_config(0.5);
    assert_eq!(
        c.directions,
        [-1, 1, 1],
        "port is MOT_2, reversed by default"
    );
    assert_eq!((c.pwm_min_us, c.pwm_max_us), (1100, 1900));
    assert_eq!(c.gain, 0.5);
    p.set("MOT_1_DIRECTION", -1.0).unwrap();
    p.set("MOT_3_DIRECTION", -1.0).unwrap();
    p.set("MOT_PWM_MAX", 1950.0).unwrap();
    let c = p.mixer_config(1.0);
    assert_eq!(c.directions, [-1, -1, -1]);
    assert_eq!(c.pwm_max_us, 1950);
}

/// ArduSub's worked example: at gain 0.5, x = 500 is +0.25 of full forward
/// thrust (ArduSub's channel value 1600).
#[test]
fn ardusub_worked_example_through_the_mixer() {
    let profile = Profile::ardusub_default();
    let sticks = sticks_from_manual_control(500, 0, 500, 0, &profile);
    assert_eq!(sticks.forward, Some(0.5));
    assert_eq!(sticks.heave_down, Some(0.0));
    let c = ParamStore::defaults().mixer_config(0.5);
    let out = mix(&d(sticks.forward.unwrap(), 0.0, 0.0), &c);
    // 0.25 of the 400 µs half range: starboard +100, port (reversed) −100.
    assert_eq!(out, [1400, 1500, 1600]);
    // z = 250 (ArduSub: throttle 1400, descend at 0.25).
    let sticks = sticks_from_manual_control(0, 0, 250, 0, &profile);
    assert_eq!(sticks.heave_down, Some(0.5));
    assert_eq!(mix(&d(0.0, 0.5, 0.0), &c), [1500, 1600, 1500]);
}

#[test]
fn mixer_nan_and_infinity_count_as_zero() {
    let c = cfg(1.0);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert_eq!(mix(&d(bad, bad, bad), &c), [1500, 1500, 1500]);
        assert_eq!(mix(&d(0.5, bad, 0.0), &c), [1700, 1500, 1700]);
        assert_eq!(thruster_us(bad, 1, &c), 1500);
        assert_eq!(mix(&d(1.0, 1.0, 1.0), &cfg(bad)), [1500, 1500, 1500]);
    }
}

#[test]
fn single_thruster_command() {
    let c = cfg(0.5);
    assert_eq!(thruster_us(1.0, 1, &c), 1700);
    assert_eq!(thruster_us(1.0, -1, &c), 1300);
    assert_eq!(thruster_us(-4.0, 1, &c), 1300);
    assert_eq!(thruster_us(0.0, -1, &c), 1500);
    assert_eq!(thruster_us(1.0, 1, &cfg(1.0)), 1900);
}

fn any_config() -> impl Strategy<Value = MixerConfig> {
    (
        0.0..=1.0f64,
        prop::array::uniform3(prop::sample::select(vec![-1i8, 0, 1])),
        1000u16..=1500,
        1500u16..=2000,
    )
        .prop_map(|(gain, directions, pwm_min_us, pwm_max_us)| MixerConfig {
            gain,
            directions,
            pwm_min_us,
            pwm_max_us,
        })
}

proptest! {
    /// `f64::ANY` includes NaN, ±∞ and subnormals (`any::<f64>()` does not).
    #[test]
    fn mixer_output_always_in_range(
        surge in prop::num::f64::ANY, heave in prop::num::f64::ANY, yaw in prop::num::f64::ANY,
        u in prop::num::f64::ANY, dir in any::<i8>(), c in any_config(),
    ) {
        for us in mix(&d(surge, heave, yaw), &c) {
            prop_assert!((c.pwm_min_us..=c.pwm_max_us).contains(&us), "{us} outside {c:?}");
        }
        let us = thruster_us(u, dir, &c);
        prop_assert!((c.pwm_min_us..=c.pwm_max_us).contains(&us));
    }

    #[test]
    fn zero_demand_is_exactly_neutral(c in any_config()) {
        prop_assert_eq!(mix(&Demand::default(), &c), [1500, 1500, 1500]);
        prop_assert_eq!(thruster_us(0.0, 1, &c), 1500);
    }
}

// ----------------------------------------------- signs through the simulator

/// mix() with default parameters, through the emulator's wiring and the
/// simulator's inverse allocation: + heave goes deeper, + yaw turns to
/// starboard (heading increases), + surge goes forward.
#[test]
fn mixer_signs_match_the_simulator() {
    let c = ParamStore::defaults().mixer_config(1.0);
    let model = ThesisModel::new(ThesisParams::default());
    let run = |dem: Demand| {
        let seen = sim::demand_from_thrusters(mix(&dem, &c), WIRING);
        let mut s = SimState::default();
        for _ in 0..200 {
            s = model.step(&s, &seen, 0.01);
        }
        (seen, s)
    };

    let (seen, s) = run(d(0.5, 0.0, 0.0));
    assert!(
        seen.surge > 0.0 && seen.heave == 0.0 && seen.yaw == 0.0,
        "{seen:?}"
    );
    assert!(s.eta[0] > 0.1, "forward demand moved x by {}", s.eta[0]);

    let (seen, s) = run(d(0.0, 0.5, 0.0));
    assert!(
        seen.heave > 0.0 && seen.surge == 0.0 && seen.yaw == 0.0,
        "{seen:?}"
    );
    assert!(
        s.depth_m() > 0.1,
        "heave + should go deeper, depth {}",
        s.depth_m()
    );

    let (seen, s) = run(d(0.0, 0.0, 0.5));
    assert!(seen.yaw > 0.0 && seen.surge == 0.0, "{seen:?}");
    let heading = s.eta[3].to_degrees();
    assert!(
        heading > 1.0,
        "yaw + should increase heading, got {heading}°"
    );

    // And the other way round.
    let (seen, _) = run(d(-0.5, -0.5, -0.5));
    assert!(
        seen.surge < 0.0 && seen.heave < 0.0 && seen.yaw < 0.0,
        "{seen:?}"
    );
}

// ---------------------------------------------------------- conventions

fn profile(z: ZConvention) -> Profile {
    Profile {
        z_convention: z,
        ..Profile::ardusub_default()
    }
}

#[test]
fn z_conventions() {
    let zt = profile(ZConvention::ZeroToThousand);
    let c = profile(ZConvention::Centered);
    let hd = |z: i16, p: &Profile| sticks_from_manual_control(0, 0, z, 0, p).heave_down;
    assert_eq!(hd(500, &zt), Some(0.0));
    assert_eq!(hd(0, &zt), Some(1.0), "z 0 = full descend");
    assert_eq!(hd(1000, &zt), Some(-1.0), "z 1000 = full rise");
    assert_eq!(hd(250, &zt), Some(0.5));
    assert_eq!(hd(0, &c), Some(0.0));
    assert_eq!(hd(-1000, &c), Some(1.0));
    assert_eq!(hd(1000, &c), Some(-1.0));
    assert_eq!(hd(500, &c), Some(-0.5));
}

#[test]
fn int16_max_means_axis_not_given() {
    let p = Profile::ardusub_default();
    let s = sticks_from_manual_control(i16::MAX, 300, i16::MAX, i16::MAX, &p);
    assert_eq!(s.forward, None);
    assert_eq!(s.lateral, Some(0.3));
    assert_eq!(s.heave_down, None);
    assert_eq!(s.yaw, None);
    // 32766 is a (wild) value, clamped.
    assert_eq!(
        sticks_from_manual_control(32766, 0, 500, 0, &p).forward,
        Some(1.0)
    );
}

#[test]
fn out_of_range_values_are_clamped() {
    let p = Profile::ardusub_default();
    let s = sticks_from_manual_control(-32768, 2000, -5000, 1001, &p);
    assert_eq!(s.forward, Some(-1.0));
    assert_eq!(s.lateral, Some(1.0));
    assert_eq!(s.heave_down, Some(1.0));
    assert_eq!(s.yaw, Some(1.0));
    let s = sticks_from_manual_control(0, 0, 30000, 0, &p);
    assert_eq!(s.heave_down, Some(-1.0));
}

#[test]
fn deadband_is_rescaled() {
    let p = Profile {
        deadband: 0.1,
        ..profile(ZConvention::Centered)
    };
    let fwd = |x: i16| sticks_from_manual_control(x, 0, 0, 0, &p).forward.unwrap();
    assert_eq!(fwd(0), 0.0);
    assert_eq!(fwd(100), 0.0);
    assert_eq!(fwd(-100), 0.0);
    assert!((fwd(550) - 0.5).abs() < 1e-12, "{}", fwd(550));
    assert!((fwd(-550) + 0.5).abs() < 1e-12);
    assert_eq!(fwd(1000), 1.0);
    // Applies to z as well (centred: z = −100 is inside the band).
    assert_eq!(
        sticks_from_manual_control(0, 0, -100, 0, &p).heave_down,
        Some(0.0)
    );
}

#[test]
fn expo_curve() {
    let p = Profile {
        expo: 0.5,
        ..Profile::ardusub_default()
    };
    let yaw = |r: i16| sticks_from_manual_control(0, 0, 500, r, &p).yaw.unwrap();
    // 0.5·0.5 + 0.5·0.125 = 0.3125
    assert!((yaw(500) - 0.3125).abs() < 1e-12);
    assert!((yaw(-500) + 0.3125).abs() < 1e-12);
    assert_eq!(yaw(1000), 1.0);
    assert_eq!(yaw(0), 0.0);
    // Deadband first, then expo.
    let p = Profile {
        deadband: 0.2,
        expo: 1.0,
        ..Profile::ardusub_default()
    };
    let y = sticks_from_manual_control(0, 600, 500, 0, &p)
        .lateral
        .unwrap();
    assert!((y - 0.125).abs() < 1e-12, "{y}");
}

#[test]
fn bad_profile_values_built_by_hand_cannot_break_shaping() {
    let p = Profile {
        deadband: f64::NAN,
        expo: 40.0,
        ..Profile::ardusub_default()
    };
    let s = sticks_from_manual_control(1000, -1000, 0, 0, &p);
    assert_eq!((s.forward, s.lateral), (Some(1.0), Some(-1.0)));
}

fn channels(set: &[(usize, u16)]) -> [u16; 18] {
    let mut c = [u16::MAX; 18];
    for &(ch, v) in set {
        c[ch - 1] = v;
    }
    c
}

#[test]
fn rc_override_values() {
    let p = Profile::ardusub_default();
    let u = rc_override(
        &channels(&[
            (3, 1900),
            (4, 1300),
            (5, 1700),
            (6, 1500),
            (8, 1100),
            (9, 1500),
        ]),
        &p,
    );
    assert_eq!(u.heave_down, Some(RcAxis::Set(-1.0)), "ch3 > 1500 is up");
    assert_eq!(u.yaw, Some(RcAxis::Set(-0.5)));
    assert_eq!(u.forward, Some(RcAxis::Set(0.5)));
    assert_eq!(u.lateral, Some(RcAxis::Set(0.0)));
    assert_eq!(u.tilt_rate, Some(RcAxis::Set(-1.0)));
    assert_eq!(u.lights, Some(RcAxis::Set(0.5)));
    // Out of range pulse widths are clamped.
    let u = rc_override(&channels(&[(5, 2500), (9, 900)]), &p);
    assert_eq!(u.forward, Some(RcAxis::Set(1.0)));
    assert_eq!(u.lights, Some(RcAxis::Set(0.0)));
}

#[test]
fn rc_override_ignore_and_release() {
    let p = Profile::ardusub_default();
    let all_ignored = rc_override(&[u16::MAX; 18], &p);
    assert_eq!(all_ignored, input::RcUpdate::default());
    // Channels 1–8: 0 releases.
    let u = rc_override(&channels(&[(3, 0), (5, 0)]), &p);
    assert_eq!(u.heave_down, Some(RcAxis::Release));
    assert_eq!(u.forward, Some(RcAxis::Release));
    assert_eq!(u.yaw, None);
    // Channels 9–18: 0 is "not sent" (MAVLink 1 senders zero-fill them),
    // 65534 releases.
    let mut c = [0u16; 18];
    c[..8].fill(u16::MAX);
    assert_eq!(rc_override(&c, &p).lights, None);
    c[8] = 65534;
    assert_eq!(rc_override(&c, &p).lights, Some(RcAxis::Release));
    assert_eq!(RcValue::from_raw(0, 0), RcValue::Release);
    assert_eq!(RcValue::from_raw(8, 0), RcValue::Ignore);
    assert_eq!(RcValue::from_raw(17, u16::MAX), RcValue::Ignore);
    assert_eq!(RcValue::from_raw(2, 1600), RcValue::Us(1600));
}

#[test]
fn rc_override_follows_the_profile_map() {
    let mut p = Profile::ardusub_default();
    p.rc.forward = 2;
    p.rc.heave = 18;
    let u = rc_override(&channels(&[(2, 1900), (5, 1100), (18, 1100)]), &p);
    assert_eq!(u.forward, Some(RcAxis::Set(1.0)));
    assert_eq!(u.heave_down, Some(RcAxis::Set(1.0)));
    // A hand-built map with an impossible channel ignores it.
    p.rc.yaw = 0;
    p.rc.lateral = 40;
    let u = rc_override(&[1500; 18], &p);
    assert_eq!((u.yaw, u.lateral), (None, None));
}

#[test]
fn button_edges() {
    assert_eq!(edges(0, 0), (0, 0));
    assert_eq!(edges(0b0000, 0b0101), (0b0101, 0));
    assert_eq!(edges(0b0101, 0b0110), (0b0010, 0b0001));
    assert_eq!(edges(1 << 31, 0), (0, 1 << 31));
    assert_eq!(edges(u32::MAX, u32::MAX), (0, 0));
}

// ------------------------------------------------------------- profiles

const GOOD: &str = r#"
name = "test"
sysids = [42]
z_convention = "centered"
"#;

fn invalid(e: ProfileError) -> (String, usize, usize, String) {
    match e {
        ProfileError::Invalid {
            file,
            line,
            column,
            message,
        } => (file, line, column, message),
        other => panic!("expected a located error, got {other}"),
    }
}

#[test]
fn all_shipped_profiles_load() {
    let p = Profiles::try_builtin().unwrap();
    let names: Vec<&str> = p.profiles().iter().map(|p| p.name.as_str()).collect();
    for n in [
        "qgroundcontrol",
        "cockpit",
        "mavproxy",
        "mavsdk",
        "pymavlink",
        "neptunus-web",
    ] {
        assert!(names.contains(&n), "{n} missing from {names:?}");
    }
    assert_eq!(p, Profiles::builtin());
    // The directory in the repository is the same set.
    let dir =
        Profiles::load_dir(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("gcs_profiles"))
            .unwrap();
    assert_eq!(dir.profiles().len(), p.profiles().len());
}

#[test]
fn sysid_lookup() {
    let p = Profiles::builtin();
    assert_eq!(p.for_sysid(245).name, "mavsdk");
    assert_eq!(p.for_sysid(255).name, "qgroundcontrol");
    assert_eq!(p.for_sysid(200).name, "neptunus-web");
    assert_eq!(p.for_sysid(209).name, "neptunus-web");
    let other = p.for_sysid(17);
    assert_eq!(other.name, "ardusub-default");
    assert_eq!(other, &Profile::ardusub_default());
    assert_eq!(other.z_convention, ZConvention::ZeroToThousand);
    assert_eq!((other.deadband, other.expo), (0.0, 0.0));
    assert_eq!(other.button_function(4, false), 4, "button 4 disarms");
    assert_eq!(other.button_function(9, true), 27);
    assert_eq!(other.button_function(31, false), 0);
    let web = p.get("neptunus-web").unwrap();
    assert_eq!(web.z_convention, ZConvention::Centered);
    assert_eq!(web.deadband, 0.1);
    assert_eq!(web.button_function(15, false), 101);
}

#[test]
fn parse_defaults() {
    let p = Profiles::parse("t.toml", GOOD).unwrap();
    assert_eq!(p.buttons, Profile::ardusub_default().buttons);
    assert_eq!(p.rc, input::RcMap::default());
    assert_eq!(p.description, "");
}

#[test]
fn syntax_error_has_line_and_column() {
    let text = "name = \"x\"\nsysids = [1,\nz_convention = \"centered\"\n";
    let (file, line, column, _) = invalid(Profiles::parse("bad.toml", text).unwrap_err());
    assert_eq!(file, "bad.toml");
    assert_eq!(line, 3, "column {column}");
    let e = Profiles::parse(
        "bad.toml",
        "name = \"x\"\nsysids = [300]\nz_convention = \"centered\"\n",
    )
    .unwrap_err();
    let s = e.to_string();
    assert!(s.starts_with("bad.toml:2:11: "), "{s}");
}

#[test]
fn unknown_key_refused() {
    let text = format!("{GOOD}deadzone = 0.1\n");
    let (_, line, column, message) = invalid(Profiles::parse("t.toml", &text).unwrap_err());
    assert!(message.contains("deadzone"), "{message}");
    assert_eq!((line, column), (5, 1));
    let text = format!("{GOOD}[rc]\nthrottle = 3\n");
    let (_, line, _, message) = invalid(Profiles::parse("t.toml", &text).unwrap_err());
    assert!(message.contains("throttle"), "{message}");
    assert_eq!(line, 6);
}

#[test]
fn bad_values_refused_with_place() {
    let cases: &[(&str, usize, usize, &str)] = &[
        ("buttons = [0, 1, 200]\n", 5, 18, "200"),
        ("buttons = [0, 1, 14]\n", 5, 18, "not a button function"),
        ("shift_buttons = [101, 97]\n", 5, 23, "97"),
        ("deadband = 0.6\n", 5, 12, "deadband"),
        ("expo = -0.1\n", 5, 8, "expo"),
        ("[rc]\nheave = 19\n", 6, 9, "1..=18"),
        ("[rc]\nheave = 4\n", 6, 9, "rc.yaw"),
        ("z_convention2 = 1\n", 5, 1, "z_convention2"),
    ];
    for (extra, line, column, needle) in cases {
        let text = format!("{GOOD}{extra}");
        let (_, l, c, m) = invalid(Profiles::parse("t.toml", &text).unwrap_err());
        assert!(m.contains(needle), "{extra:?}: {m}");
        assert_eq!((l, c), (*line, *column), "{extra:?}: {m}");
    }
    let zero = "name = \"t\"\nsysids = [3, 0]\nz_convention = \"centered\"\n";
    let (_, l, c, m) = invalid(Profiles::parse("t.toml", zero).unwrap_err());
    assert_eq!((l, c), (2, 14), "{m}");
    let reserved = "name = \"ardusub-default\"\nsysids = []\nz_convention = \"centered\"\n";
    let (_, l, _, m) = invalid(Profiles::parse("t.toml", reserved).unwrap_err());
    assert_eq!(l, 1, "{m}");
    let missing = "name = \"t\"\nsysids = []\n";
    let (_, _, _, m) = invalid(Profiles::parse("t.toml", missing).unwrap_err());
    assert!(m.contains("z_convention"), "{m}");
}

#[test]
fn duplicate_sysid_refused() {
    let a = "name = \"a\"\nsysids = [7, 8]\nz_convention = \"centered\"\n";
    let b = "name = \"b\"\nsysids = [9,\n  8]\nz_convention = \"centered\"\n";
    let e = Profiles::from_sources(&[("a.toml", a), ("b.toml", b)]).unwrap_err();
    let (file, line, column, message) = invalid(e);
    assert_eq!((file.as_str(), line, column), ("b.toml", 3, 3));
    assert!(
        message.contains("sysid 8") && message.contains("a.toml"),
        "{message}"
    );
    // Same name twice.
    let b = "name = \"a\"\nsysids = []\nz_convention = \"centered\"\n";
    let (_, _, _, message) =
        invalid(Profiles::from_sources(&[("a.toml", a), ("b.toml", b)]).unwrap_err());
    assert!(message.contains("already used"), "{message}");
    // Empty sysids never conflict.
    let c = "name = \"c\"\nsysids = []\nz_convention = \"centered\"\n";
    let ok = Profiles::from_sources(&[("a.toml", a), ("c.toml", c)]).unwrap();
    assert_eq!(ok.for_sysid(8).name, "a");
}

#[test]
fn load_dir_reports_the_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("a.toml"), GOOD).unwrap();
    std::fs::write(dir.path().join("notes.txt"), "not a profile").unwrap();
    let p = Profiles::load_dir(dir.path()).unwrap();
    assert_eq!(p.profiles().len(), 1);
    std::fs::write(dir.path().join("b.toml"), format!("{GOOD}sysids = [1]\n")).unwrap();
    let e = Profiles::load_dir(dir.path()).unwrap_err().to_string();
    assert!(e.contains("b.toml:5:1"), "{e}");
    let empty = tempfile::tempdir().unwrap();
    assert!(matches!(
        Profiles::load_dir(empty.path()),
        Err(ProfileError::Empty { .. })
    ));
    assert!(matches!(
        Profiles::load_dir(&empty.path().join("nope")),
        Err(ProfileError::ReadDir { .. })
    ));
}

// ------------------------------------------------------------------ CLI

#[test]
fn cli_profiles_check_shipped_dir() {
    let out = Command::new(BIN)
        .args(["profiles", "check"])
        .arg(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("gcs_profiles"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for n in [
        "qgroundcontrol",
        "cockpit",
        "mavproxy",
        "mavsdk",
        "pymavlink",
        "neptunus-web",
        "ardusub-default",
    ] {
        assert!(stdout.contains(n), "{n} missing:\n{stdout}");
    }
    assert!(stdout.contains("245"), "{stdout}");
    // Without DIR: the built-in set, same names.
    let out = Command::new(BIN)
        .args(["profiles", "check"])
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("mavsdk"));
}

#[test]
fn cli_profiles_check_bad_dir_fails_with_place() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("broken.toml"),
        "name = \"x\"\nsysids = [1]\nz_convention = \"sideways\"\n",
    )
    .unwrap();
    let out = Command::new(BIN)
        .args(["profiles", "check"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("broken.toml:3:"), "{err}");
    assert!(err.contains("sideways"), "{err}");
}
