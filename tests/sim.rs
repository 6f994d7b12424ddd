//! Acceptance tests of the simulator: the thesis model's steady states and
//! signs, RK4 accuracy and order, the thrust allocation round trip, and the
//! board sensor model.

#![allow(clippy::unwrap_used)]

use nalgebra::Vector4;
use neptunus::sim::sensors::Water;
use neptunus::sim::thesis::ParamsError;
use neptunus::sim::{
    Demand, SensorModel, SensorParams, SimState, ThesisModel, ThesisParams, demand_from_thrusters,
    thrusters_from_demand,
};

const NEPTUNUS_DIRS: [i8; 3] = [-1, 1, 1];

fn model() -> ThesisModel {
    ThesisModel::new(ThesisParams::default())
}

fn run(m: &ThesisModel, s0: SimState, d: &Demand, dt_s: f64, steps: usize) -> SimState {
    (0..steps).fold(s0, |s, _| m.step(&s, d, dt_s))
}

/// Positive root of `a x² + b x = c`.
fn root(a: f64, b: f64, c: f64) -> f64 {
    (-b + (b * b + 4.0 * a * c).sqrt()) / (2.0 * a)
}

// 1 ------------------------------------------------------------------------

#[test]
fn full_forward_reaches_thesis_terminal_surge_speed() {
    let m = model();
    let terminal = m.terminal_surge_speed(1.0);
    assert_eq!((terminal * 1000.0).round() / 1000.0, 1.468);
    assert!((terminal - root(4.008, 2.2907, 12.0)).abs() < 1e-12);

    let d = Demand {
        surge: 1.0,
        ..Demand::default()
    };
    let s = run(&m, SimState::default(), &d, 0.01, 6000);
    let u = s.nu[0];
    assert!((u - 1.468).abs() / 1.468 < 0.01, "u = {u}");
    assert!((u - terminal).abs() / terminal < 0.001, "u = {u}");
    // Pure surge: nothing else moves but the slow buoyant rise.
    assert_eq!(s.nu[1], 0.0);
    assert_eq!(s.nu[3], 0.0);
    assert_eq!(s.eta[1], 0.0);
    assert_eq!(s.eta[3], 0.0);
    assert!(s.eta[0] > 80.0, "x = {}", s.eta[0]);
}

#[test]
fn terminal_surge_speed_is_odd_and_saturates() {
    let m = model();
    assert_eq!(m.terminal_surge_speed(0.0), 0.0);
    assert_eq!(m.terminal_surge_speed(-0.5), -m.terminal_surge_speed(0.5));
    assert_eq!(m.terminal_surge_speed(3.0), m.terminal_surge_speed(1.0));
    assert_eq!(m.terminal_surge_speed(f64::NAN), 0.0);
}

// 2 ------------------------------------------------------------------------

#[test]
fn zero_thrust_only_drifts_up_slowly() {
    let m = model();
    let s = run(&m, SimState::default(), &Demand::default(), 0.01, 6000);
    for (name, value) in [
        ("u", s.nu[0]),
        ("v", s.nu[1]),
        ("r", s.nu[3]),
        ("x", s.eta[0]),
        ("y", s.eta[1]),
        ("psi", s.eta[3]),
    ] {
        assert!(value.abs() < 1e-12, "{name} = {value}");
    }
    // Terminal heave speed: 10.304 w|w| + 15.1897 w = −0.0234 (rising).
    let expected_w = -root(10.304, 15.1897, 0.0234);
    assert!((expected_w / (-0.0234 / 15.1897) - 1.0).abs() < 0.01);
    assert!((s.nu[2] - expected_w).abs() < 1e-9, "w = {}", s.nu[2]);
    assert!((m.terminal_heave_speed(0.0) - expected_w).abs() < 1e-12);
    assert!(s.eta[2] < 0.0 && s.eta[2].abs() < 0.1, "z = {}", s.eta[2]);
}

// 3 ------------------------------------------------------------------------

#[test]
fn positive_heave_goes_deeper_at_the_analytic_terminal_speed() {
    let m = model();
    let d = Demand {
        heave: 1.0,
        ..Demand::default()
    };
    let s = run(&m, SimState::default(), &d, 0.01, 3000);
    let expected_w = root(10.304, 15.1897, 12.0 - 0.0234);
    assert!(s.eta[2] > 10.0, "z = {}", s.eta[2]);
    assert!(
        (s.nu[2] - expected_w).abs() / expected_w < 0.01,
        "w = {}",
        s.nu[2]
    );
    assert!((m.terminal_heave_speed(1.0) - expected_w).abs() < 1e-12);

    let up = Demand {
        heave: -1.0,
        ..Demand::default()
    };
    let s = run(&m, SimState::default(), &up, 0.01, 100);
    assert!(s.eta[2] < -0.1 && s.nu[2] < 0.0);
}

#[test]
fn positive_yaw_turns_to_starboard() {
    let m = model();
    let d = Demand {
        yaw: 0.5,
        ..Demand::default()
    };
    assert!(m.tau(&d)[3] > 0.0);
    let s = run(&m, SimState::default(), &d, 0.01, 200);
    assert!(s.nu[3] > 0.0 && s.eta[3] > 0.0);
    let h = s.heading_deg();
    assert!(h > 0.0 && h < 180.0, "heading {h}");

    let port = Demand {
        yaw: -0.5,
        ..Demand::default()
    };
    let s = run(&m, SimState::default(), &port, 0.01, 200);
    assert!(s.nu[3] < 0.0 && s.heading_deg() > 180.0);
}

#[test]
fn surge_at_heading_east_moves_east() {
    let m = model();
    let s0 = SimState {
        eta: Vector4::new(0.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2),
        nu: Vector4::zeros(),
    };
    let d = Demand {
        surge: 1.0,
        ..Demand::default()
    };
    let s = run(&m, s0, &d, 0.01, 500);
    assert!(s.eta[1] > 1.0 && s.eta[0].abs() < 1e-9, "{:?}", s.eta);
}

#[test]
fn yaw_torque_couples_into_sway_through_added_mass() {
    // M_A has −0.8926 between sway and yaw: a pure yaw torque must also
    // accelerate the vehicle sideways, or M is not being used whole.
    let m = model();
    let d = Demand {
        yaw: 1.0,
        ..Demand::default()
    };
    let ds = m.derivative(&SimState::default(), &d);
    assert!(ds.nu[1] != 0.0 && ds.nu[3] > 0.0);
}

// 4 ------------------------------------------------------------------------

/// A piecewise-constant demand that changes on whole seconds, so every
/// integrator step size used here sees the same input.
fn varying_demand(t_s: f64) -> Demand {
    match t_s as u32 {
        0..=4 => Demand {
            surge: 0.8,
            heave: 0.6,
            yaw: 0.3,
        },
        5..=9 => Demand {
            surge: 0.4,
            heave: 0.9,
            yaw: 0.6,
        },
        10..=14 => Demand {
            surge: 1.0,
            heave: 0.3,
            yaw: 0.1,
        },
        _ => Demand {
            surge: 0.6,
            heave: 0.7,
            yaw: 0.4,
        },
    }
}

/// Integrates `varying_demand` for `seconds` with `steps_per_s` RK4 steps per
/// second, sampling the state once per second.
fn trajectory(m: &ThesisModel, steps_per_s: u32, seconds: u32) -> Vec<SimState> {
    let dt_s = 1.0 / f64::from(steps_per_s);
    let mut s = SimState {
        // Start moving so no velocity passes through zero, where |ν|ν is
        // only C¹ and RK4 would lose an order.
        eta: Vector4::zeros(),
        nu: Vector4::new(0.5, 0.0, 0.3, 0.0),
    };
    let mut out = vec![s];
    for sec in 0..seconds {
        let d = varying_demand(f64::from(sec));
        for _ in 0..steps_per_s {
            s = m.step(&s, &d, dt_s);
        }
        out.push(s);
    }
    out
}

fn max_position_error_m(a: &[SimState], b: &[SimState]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(a, b)| (a.eta.xyz() - b.eta.xyz()).norm())
        .fold(0.0, f64::max)
}

#[test]
fn rk4_at_10ms_matches_a_tiny_step_reference() {
    let m = model();
    let reference = trajectory(&m, 2000, 20);
    let coarse = trajectory(&m, 100, 20);
    let err = max_position_error_m(&coarse, &reference);
    assert!(err < 1e-6, "max position error {err} m");
    // The run must actually go somewhere for the comparison to mean anything.
    // It circles (ψ ≈ 13.9 rad) while diving to ≈ 7.6 m.
    assert!(reference[20].eta[2] > 5.0);
    assert!(reference[20].eta[3] > 6.0);
}

#[test]
fn rk4_is_fourth_order() {
    let m = model();
    let reference = trajectory(&m, 2000, 20);
    let e_coarse = max_position_error_m(&trajectory(&m, 25, 20), &reference);
    let e_half = max_position_error_m(&trajectory(&m, 50, 20), &reference);
    let ratio = e_coarse / e_half;
    eprintln!("RK4 error at dt 40 ms {e_coarse:e} m, at 20 ms {e_half:e} m: ratio {ratio:.1}");
    assert!(
        ratio > 8.0,
        "halving dt reduced the error only {ratio}× ({e_coarse} → {e_half})"
    );
    assert!(ratio < 32.0, "suspiciously large ratio {ratio}");
}

#[test]
fn rk4_beats_explicit_euler() {
    let m = model();
    let d = Demand {
        surge: 1.0,
        heave: 0.5,
        yaw: 0.5,
    };
    let dt_s = 0.01;
    let reference = run(&m, SimState::default(), &d, 0.0005, 20_000);
    let rk4 = run(&m, SimState::default(), &d, dt_s, 1000);
    let euler = (0..1000).fold(SimState::default(), |s, _| {
        let k = m.derivative(&s, &d);
        SimState {
            eta: s.eta + k.eta * dt_s,
            nu: s.nu + k.nu * dt_s,
        }
    });
    let e_rk4 = (rk4.eta.xyz() - reference.eta.xyz()).norm();
    let e_euler = (euler.eta.xyz() - reference.eta.xyz()).norm();
    assert!(e_rk4 * 1000.0 < e_euler, "rk4 {e_rk4}, euler {e_euler}");
}

#[test]
fn step_is_pure() {
    let m = model();
    let s = SimState {
        eta: Vector4::new(1.0, 2.0, 3.0, 0.4),
        nu: Vector4::new(0.3, -0.1, 0.2, 0.05),
    };
    let d = Demand {
        surge: 0.3,
        heave: -0.2,
        yaw: 0.7,
    };
    assert_eq!(m.step(&s, &d, 0.01), m.step(&s, &d, 0.01));
    assert_eq!(m.clone().step(&s, &d, 0.01), m.step(&s, &d, 0.01));
}

#[test]
fn out_of_range_and_nan_demands_are_saturated() {
    let m = model();
    let big = Demand {
        surge: 5.0,
        heave: -7.0,
        yaw: 2.0,
    };
    let one = Demand {
        surge: 1.0,
        heave: -1.0,
        yaw: 1.0,
    };
    assert_eq!(m.tau(&big), m.tau(&one));
    let nan = Demand {
        surge: f64::NAN,
        heave: f64::NAN,
        yaw: f64::NAN,
    };
    assert_eq!(m.tau(&nan), Vector4::zeros());
}

#[test]
fn bad_params_are_rejected_not_simulated() {
    let mut p = ThesisParams::default();
    p.m_rb[(3, 3)] = -5.0;
    assert_eq!(
        ThesisModel::try_new(p).unwrap_err(),
        ParamsError::MassNotPositiveDefinite
    );
    let mut p = ThesisParams::default();
    p.d_l[2] = -1.0;
    assert!(matches!(
        ThesisModel::try_new(p),
        Err(ParamsError::NegativeDamping { index: 2, .. })
    ));
    let p = ThesisParams {
        thrust_n: f64::INFINITY,
        ..ThesisParams::default()
    };
    assert!(matches!(
        ThesisModel::try_new(p),
        Err(ParamsError::NotFinite { name: "thrust_n" })
    ));
    assert!(ThesisModel::try_new(ThesisParams::default()).is_ok());
}

// 5 ------------------------------------------------------------------------

#[test]
fn allocation_round_trips_within_pwm_quantisation() {
    for dirs in [NEPTUNUS_DIRS, [1, 1, 1], [1, -1, -1]] {
        for i in -10..=10 {
            for j in -10..=10 {
                let x = f64::from(i) / 10.0;
                let yaw = f64::from(j) / 10.0;
                if x.abs() + yaw.abs() > 1.0 + 1e-12 {
                    continue;
                }
                for z in [-1.0, -0.37, 0.0, 0.123, 1.0] {
                    let d = Demand {
                        surge: x * 0.987,
                        heave: z,
                        yaw: yaw * 0.987,
                    };
                    let back = demand_from_thrusters(thrusters_from_demand(&d, dirs), dirs);
                    for (a, b) in [
                        (d.surge, back.surge),
                        (d.heave, back.heave),
                        (d.yaw, back.yaw),
                    ] {
                        assert!((a - b).abs() <= 0.002, "{d:?} → {back:?} with {dirs:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn neutral_pulses_are_zero_demand() {
    assert_eq!(
        demand_from_thrusters([1500, 1500, 1500], NEPTUNUS_DIRS),
        Demand::default()
    );
    assert_eq!(
        thrusters_from_demand(&Demand::default(), NEPTUNUS_DIRS),
        [1500, 1500, 1500]
    );
}

#[test]
fn port_direction_is_honoured() {
    let d = demand_from_thrusters([1000, 1500, 2000], NEPTUNUS_DIRS);
    assert_eq!(
        d,
        Demand {
            surge: 1.0,
            heave: 0.0,
            yaw: 0.0
        }
    );
    let forward = Demand {
        surge: 1.0,
        ..Demand::default()
    };
    assert_eq!(
        thrusters_from_demand(&forward, NEPTUNUS_DIRS),
        [1000, 1500, 2000]
    );
    // The same pulses with every motor wired the same way mean "spin in place".
    let spin = demand_from_thrusters([1000, 1500, 2000], [1, 1, 1]);
    assert_eq!(spin.surge, 0.0);
    assert_eq!(spin.yaw, -1.0);
    // Vertical: positive heave (down) with a forward-wired vertical motor.
    assert_eq!(
        demand_from_thrusters([1500, 2000, 1500], NEPTUNUS_DIRS).heave,
        1.0
    );
}

#[test]
fn saturated_allocation_returns_what_the_thrusters_produce() {
    let d = Demand {
        surge: 1.0,
        heave: 0.0,
        yaw: 1.0,
    };
    // u_port = sat(2) = 1, u_star = sat(0) = 0.
    let pwm = thrusters_from_demand(&d, NEPTUNUS_DIRS);
    assert_eq!(pwm, [1000, 1500, 1500]);
    let back = demand_from_thrusters(pwm, NEPTUNUS_DIRS);
    assert_eq!((back.surge, back.yaw), (0.5, 0.5));
}

#[test]
fn out_of_range_pulses_and_directions_never_panic() {
    // Port disabled (direction 0), vertical forward, starboard reversed.
    let d = demand_from_thrusters([0, u16::MAX, 3000], [0, 2, -7]);
    assert_eq!((d.surge, d.heave, d.yaw), (-0.5, 1.0, 0.5));
    let pwm = thrusters_from_demand(
        &Demand {
            surge: f64::NAN,
            heave: 9.0,
            yaw: f64::NEG_INFINITY,
        },
        [0, 1, 1],
    );
    assert_eq!(pwm, [1500, 2000, 2000]);
}

// 6 ------------------------------------------------------------------------

fn at(depth_m: f64, psi_rad: f64) -> SimState {
    SimState {
        eta: Vector4::new(0.0, 0.0, depth_m, psi_rad),
        nu: Vector4::zeros(),
    }
}

#[test]
fn depth_from_pressure_round_trips() {
    let sensors = SensorModel::new(SensorParams::default());
    for depth in [0.0, 0.001, 0.5, 1.234, 10.0, 99.9] {
        let r = sensors.read(&at(depth, 0.0), &Demand::default());
        assert!((r.depth_m - depth).abs() < 0.001, "{depth} → {}", r.depth_m);
        let expected_mbar = 1015.0 + depth * 100.0 / 1.019716;
        assert!((r.pressure_mbar - expected_mbar).abs() < 1e-9);
    }
    // 10 m of fresh water is about 981 mbar.
    let r = sensors.read(&at(10.0, 0.0), &Demand::default());
    assert!(
        (r.pressure_mbar - 1995.66).abs() < 0.01,
        "{}",
        r.pressure_mbar
    );
}

#[test]
fn salt_water_round_trips_too() {
    let sensors = SensorModel::new(SensorParams {
        water: Water::Salt,
        ..SensorParams::default()
    });
    let r = sensors.read(&at(5.0, 0.0), &Demand::default());
    assert!((r.depth_m - 5.0).abs() < 0.001);
    let fresh = SensorModel::new(SensorParams::default()).read(&at(5.0, 0.0), &Demand::default());
    assert!(r.pressure_mbar > fresh.pressure_mbar);
}

#[test]
fn above_the_surface_reads_surface_pressure() {
    let sensors = SensorModel::new(SensorParams::default());
    let r = sensors.read(&at(-0.05, 0.0), &Demand::default());
    assert_eq!(r.pressure_mbar, 1015.0);
    assert_eq!(r.depth_m, 0.0);
}

#[test]
fn heading_and_yaw_wrap() {
    let sensors = SensorModel::new(SensorParams::default());
    for (deg, heading, yaw) in [
        (0.0, 0.0, 0.0),
        (-1e-15, 0.0, 0.0),
        (90.0, 90.0, 90.0),
        (180.0, 180.0, 180.0),
        (181.0, 181.0, -179.0),
        (270.0, 270.0, -90.0),
        (359.5, 359.5, -0.5),
        (360.0, 0.0, 0.0),
        (-90.0, 270.0, -90.0),
        (-180.0, 180.0, 180.0),
        (725.0, 5.0, 5.0),
        (-1085.0, 355.0, -5.0),
    ] {
        let s = at(0.0, f64::to_radians(deg));
        let r = sensors.read(&s, &Demand::default());
        assert!(
            (0.0..360.0).contains(&r.heading_deg),
            "{deg}: {}",
            r.heading_deg
        );
        assert!(
            r.yaw_deg > -180.0 && r.yaw_deg <= 180.0,
            "{deg}: {}",
            r.yaw_deg
        );
        assert!(
            (r.heading_deg - heading).abs() < 1e-9,
            "{deg}: {}",
            r.heading_deg
        );
        assert!((r.yaw_deg - yaw).abs() < 1e-9, "{deg}: {}", r.yaw_deg);
        assert_eq!(r.heading_deg, s.heading_deg());
    }
}

#[test]
fn battery_sags_under_thrust_like_the_thesis_measured() {
    let sensors = SensorModel::new(SensorParams::default());
    let s = at(1.0, 0.0);
    let idle = sensors.read(&s, &Demand::default());
    // Full forward and up: all three thrusters at full.
    let full = sensors.read(
        &s,
        &Demand {
            surge: 1.0,
            heave: -1.0,
            yaw: 0.0,
        },
    );
    assert!(full.vout_v < idle.vout_v);
    assert!((idle.vout_v - 12.0).abs() < 0.2, "idle {} V", idle.vout_v);
    assert!((full.vout_v - 10.9).abs() < 0.3, "full {} V", full.vout_v);
    assert!((full.btti_a - 3.13).abs() < 0.2, "full {} A", full.btti_a);
    assert!(full.btti_a > full.iout_a);
    // Backward and down drew the same in the thesis.
    let back = sensors.read(
        &s,
        &Demand {
            surge: -1.0,
            heave: 1.0,
            yaw: 0.0,
        },
    );
    assert_eq!(back.vout_v, full.vout_v);
    // Current grows faster than linearly with demand.
    let half = sensors.read(
        &s,
        &Demand {
            surge: 0.5,
            ..Demand::default()
        },
    );
    let one = sensors.read(
        &s,
        &Demand {
            surge: 1.0,
            ..Demand::default()
        },
    );
    assert!(half.btti_a - idle.btti_a < 0.5 * (one.btti_a - idle.btti_a));
}

#[test]
fn readings_carry_the_demand_and_fixed_attitude() {
    let sensors = SensorModel::new(SensorParams::default());
    let r = sensors.read(
        &at(2.0, 0.3),
        &Demand {
            surge: -0.25,
            heave: 0.0,
            yaw: 0.0,
        },
    );
    assert_eq!(r.fthr_pct, -25.0);
    assert_eq!((r.pitch_deg, r.roll_deg), (0.0, 0.0));
    assert_eq!(r.temp_c, 18.0);
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    fn direction() -> impl Strategy<Value = i8> {
        prop_oneof![Just(-1i8), Just(1i8)]
    }

    proptest! {
        #[test]
        fn demand_round_trips_through_pulses(
            x in -1.0f64..=1.0,
            share in 0.0f64..=1.0,
            z in -1.0f64..=1.0,
            dirs in [direction(), direction(), direction()],
        ) {
            // |X| + |M| ≤ 1: the allocation does not saturate.
            let yaw = (1.0 - x.abs()) * (2.0 * share - 1.0);
            let d = Demand { surge: x, heave: z, yaw };
            let back = demand_from_thrusters(thrusters_from_demand(&d, dirs), dirs);
            prop_assert!((back.surge - d.surge).abs() <= 0.002);
            prop_assert!((back.heave - d.heave).abs() <= 0.002);
            prop_assert!((back.yaw - d.yaw).abs() <= 0.002);
        }

        #[test]
        fn pulses_round_trip_exactly(
            pwm in [1000u16..=2000, 1000u16..=2000, 1000u16..=2000],
            dirs in [direction(), direction(), direction()],
        ) {
            let d = demand_from_thrusters(pwm, dirs);
            prop_assert_eq!(thrusters_from_demand(&d, dirs), pwm);
        }

        #[test]
        fn any_pulses_give_a_bounded_demand(pwm in any::<[u16; 3]>(), dirs in any::<[i8; 3]>()) {
            let d = demand_from_thrusters(pwm, dirs);
            prop_assert!(d.surge.abs() + d.yaw.abs() <= 1.0);
            prop_assert!(d.heave.abs() <= 1.0);
            let back = thrusters_from_demand(&d, dirs);
            prop_assert!(back.iter().all(|p| (1000..=2000).contains(p)));
        }

        #[test]
        fn step_stays_finite_for_any_demand(
            x in any::<f64>(), z in any::<f64>(), m in any::<f64>(),
        ) {
            let model = model();
            let d = Demand { surge: x, heave: z, yaw: m };
            let s = run(&model, SimState::default(), &d, 0.01, 100);
            prop_assert!(s.eta.iter().chain(s.nu.iter()).all(|v| v.is_finite()));
        }
    }
}
