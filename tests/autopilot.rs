//! The autopilots and the estimator in closed loop with
//! the board emulator and simulator, on simulated time (no waiting), with
//! the simulator's fixed seeds; and the modes, setpoints and run mode seen
//! from a ground station.

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, acks};
use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::{Command, Event, StatusSample};
use neptunus::scenario::report;
use neptunus::scenario::{Scenario, Sticks};
use neptunus::vehicle::machine::{Input, Mode, Now, Output, RunMode, Sender, Vehicle};

fn secs(s: u64) -> Duration {
    Duration::from_secs(s)
}

#[test]
fn depth_step_settles_fast_without_overshoot() {
    let o = report::depth_step();
    let settle = o.metric("settling_time_0.1m");
    let overshoot = o.metric("overshoot");
    assert!(settle < 20.0, "settling {settle} s");
    assert!(overshoot < 10.0, "overshoot {overshoot} %");
}

#[test]
fn heading_step_settles_within_3_degrees_in_10_s() {
    let o = report::heading_step();
    let settle = o.metric("settling_time_3deg");
    assert!(settle < 10.0, "settling {settle} s");
}

#[test]
fn depth_hold_in_current_with_tether_and_lag_stays_within_15_cm() {
    let o = report::depth_hold_in_current();
    let err = o.metric("max_depth_error");
    assert!(err <= 0.15, "max error {err} m");
    // The current really pushed the vehicle: it moved.
    let last = o.samples.last().expect("recorded samples");
    let moved = last.north_m.hypot(last.east_m);
    assert!(moved > 1.0, "moved only {moved} m in 65 s");
}

#[test]
fn wild_points_never_jump_the_estimates() {
    let o = report::wild_points();
    let dj = o.metric("max_depth_estimate_jump");
    let hj = o.metric("max_heading_estimate_jump");
    assert!(dj <= 0.2, "depth estimate jumped {dj} m");
    assert!(hj <= 5.0, "heading estimate jumped {hj} deg");
    // The gate really had wild points to reject (the board's nav line has
    // six values: about one wild point in six lands on the heading, and a
    // depth repeated between the sensor's 1 Hz reads is not a measurement).
    assert!(o.metric("depth_rejected") >= 1.0, "{:?}", o.metrics);
    assert!(o.metric("heading_rejected") >= 5.0, "{:?}", o.metrics);
}

#[test]
fn surface_rises_then_goes_neutral() {
    let o = report::surface();
    let t = o.metric("time_to_surface");
    assert!(t < 20.0, "surfaced after {t} s");
    let last = o.samples.last().expect("recorded samples");
    assert_eq!(last.vertical_us, 1500, "neutral once surfaced");
}

/// A vehicle at 1.5 m in ALT_HOLD, armed, for the stick tests.
fn alt_hold_at(depth_m: f64) -> Scenario {
    let mut s = Scenario::new(report::options(11));
    s.place(depth_m, 45.0);
    s.run(secs(3));
    assert_eq!(s.arm(), Some(MavResult::MAV_RESULT_ACCEPTED));
    assert_eq!(
        s.set_mode(Mode::AltHold.number()),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    s
}

#[test]
fn heave_stick_commands_a_climb_rate_and_release_holds_the_depth() {
    let mut s = alt_hold_at(1.5);
    s.run(secs(3));
    // Full down stick (z = 0 in ArduSub's 0..1000 convention) for 3 s.
    s.set_sticks(Sticks { x: 0, z: 0, r: 0 });
    s.run(secs(3));
    let deeper = s.samples().last().expect("recorded samples").depth_true_m;
    assert!(deeper > 2.3, "dove only to {deeper} m");
    s.set_sticks(Sticks::CENTRED);
    s.run(secs(5));
    let held = s.vehicle().targets().0.expect("depth captured on release");
    s.run(secs(20));
    let end = s.samples().last().expect("recorded samples").depth_true_m;
    assert!((end - held).abs() < 0.1, "held {held} m, at {end} m");
}

#[test]
fn yaw_stick_turns_and_release_holds_the_heading() {
    let mut s = Scenario::new(report::options(12));
    s.place(1.0, 10.0);
    s.run(secs(3));
    s.arm();
    assert_eq!(
        s.set_mode(Mode::Stabilize.number()),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    s.set_sticks(Sticks {
        x: 0,
        z: 500,
        r: 600,
    });
    s.run(secs(2));
    let rate = s
        .samples()
        .last()
        .expect("recorded samples")
        .yaw_rate_true_dps;
    assert!(rate > 10.0, "turning at {rate} deg/s");
    s.set_sticks(Sticks::CENTRED);
    s.run(secs(3));
    let held = s.vehicle().targets().1.expect("heading captured");
    s.run(secs(15));
    let end = s
        .samples()
        .last()
        .expect("recorded samples")
        .heading_true_deg;
    let err = (end - held + 540.0).rem_euclid(360.0) - 180.0;
    assert!(err.abs() < 3.0, "held {held}, at {end}");
}

#[test]
fn position_target_moves_the_held_depth_only_in_alt_hold() {
    let mut s = Scenario::new(report::options(13));
    s.place(1.0, 0.0);
    s.run(secs(3));
    s.arm();
    // MANUAL: ignored, with a warning.
    s.sent.clear();
    s.set_depth_target(2.0);
    assert!(s.sent.iter().any(|m| matches!(m, MavMessage::STATUSTEXT(t)
        if String::from_utf8_lossy(t.text.as_ref()).contains("ignored in MANUAL"))));
    assert_eq!(s.vehicle().targets().0, None);
    s.set_mode(Mode::AltHold.number());
    s.set_depth_target(2.0);
    s.run(secs(15));
    assert_eq!(s.vehicle().targets().0, Some(2.0));
    let end = s.samples().last().expect("recorded samples").depth_true_m;
    assert!((end - 2.0).abs() < 0.1, "at {end} m");
}

#[test]
fn position_modes_are_refused_with_the_reason() {
    let mut s = Scenario::new(report::options(14));
    s.run(secs(3));
    for mode in [3u32, 4, 7, 16] {
        s.sent.clear();
        assert_eq!(s.set_mode(mode), Some(MavResult::MAV_RESULT_FAILED));
        assert!(
            s.sent.iter().any(|m| matches!(m, MavMessage::STATUSTEXT(t)
            if String::from_utf8_lossy(t.text.as_ref()).contains("position estimate"))),
            "mode {mode}"
        );
    }
}

// ---- the core alone, for run mode and refusals ----

const GCS: Sender = Sender::new(0, 1, 255, 190);
const STRANGER: Sender = Sender::new(0, 2, 77, 190);

/// COMMAND_LONG with param1 and param2 from `from` at `ms` on the rig's
/// clock: the result of its ACK, and everything the core emitted.
fn command(
    r: &mut CoreRig,
    from: Sender,
    cmd: MavCmd,
    p1: f32,
    p2: f32,
    ms: u64,
) -> (Option<MavResult>, Vec<Output>) {
    r.t = Duration::from_millis(ms);
    let out = r.cmd(from, cmd, &[p1, p2]);
    let result = acks(&out)
        .into_iter()
        .find(|a| a.command == cmd)
        .map(|a| a.result);
    (result, out)
}

/// A vehicle fed with board telemetry, armed by the GCS, in `mode`, on a
/// core rig from here on (the tests place each input in time).
fn armed_vehicle(mode: u32) -> CoreRig {
    let mut s = Scenario::new(report::options(21));
    s.place(1.0, 0.0);
    s.run(secs(3));
    s.arm();
    s.set_mode(mode);
    s.set_sticks(Sticks {
        x: 800,
        z: 500,
        r: 0,
    });
    s.run(Duration::from_millis(500));
    assert!(s.vehicle().armed());
    assert_ne!(
        s.vehicle().motors_us(),
        [1500; 3],
        "driving before the switch"
    );
    // The scenario's vehicle, moved out for the core-level assertions.
    CoreRig::new(s.into_vehicle())
}

#[test]
fn switching_run_mode_stops_the_thrusters_and_flags_telemetry_simulated() {
    let mut r = armed_vehicle(Mode::Manual.number());
    let (result, out) = command(
        &mut r,
        GCS,
        MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE,
        1.0,
        f32::NAN,
        3600,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_ACCEPTED));
    let neutral = Command::Go {
        port_us: 1500,
        vertical_us: 1500,
        starboard_us: 1500,
    };
    // The real board gets stop() and neutral; the simulator starts from neutral.
    assert!(out.contains(&Output::Board(Command::Stop)), "{out:?}");
    assert!(out.contains(&Output::Board(neutral)), "{out:?}");
    assert!(out.contains(&Output::SimBoard(neutral)), "{out:?}");
    assert!(out.iter().any(|o| matches!(
        o,
        Output::RunMode {
            mode: RunMode::Simulator,
            ..
        }
    )));
    assert!(out.iter().any(
        |o| matches!(o, Output::Text { msg: MavMessage::STATUSTEXT(t), .. }
        if String::from_utf8_lossy(t.text.as_ref()).contains("simulated"))
    ));
    assert_eq!(r.v.motors_us(), [1500; 3]);
    assert_eq!(r.v.run_mode(), RunMode::Simulator);
    // HEARTBEAT says HIL (simulated) from now on.
    r.t = Duration::from_millis(3700);
    let hb = r.v.build(0, r.now());
    let MavMessage::HEARTBEAT(h) = &hb[0] else {
        panic!()
    };
    assert!(h.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_HIL_ENABLED));
    // Thruster commands now go to the simulator, never to the real board.
    let mut out = Vec::new();
    for ms in (3700..4500).step_by(10) {
        r.t = Duration::from_millis(ms);
        out.extend(r.input(Input::Tick));
    }
    assert!(
        !out.iter().any(|o| matches!(o, Output::Board(Command::Go { .. }) if *o != Output::Board(Command::Go { port_us: 1500, vertical_us: 1500, starboard_us: 1500 }))),
        "the real board got thrust in simulator run mode: {out:?}"
    );
    // And back: another stop, flag cleared.
    let (result, out) = command(
        &mut r,
        GCS,
        MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE,
        0.0,
        f32::NAN,
        4600,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_ACCEPTED));
    assert!(out.iter().any(|o| matches!(
        o,
        Output::RunMode {
            mode: RunMode::Normal,
            ..
        }
    )));
    r.t = Duration::from_millis(4700);
    let hb = r.v.build(0, r.now());
    let MavMessage::HEARTBEAT(h) = &hb[0] else {
        panic!()
    };
    assert!(!h.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_HIL_ENABLED));
}

/// The built-in simulator powers up at the switch (its `boot` line about a
/// second later) and counts time on the vehicle's clock: neither is the
/// vehicle's board restarting, so the vehicle stays armed in the simulator
/// and back. A `boot` line from the board itself still disarms.
#[test]
fn the_simulators_power_up_is_no_board_restart() {
    let mut r = armed_vehicle(Mode::Manual.number());
    let (result, _) = command(
        &mut r,
        GCS,
        MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE,
        1.0,
        f32::NAN,
        3600,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_ACCEPTED));
    let status = |time_ms| {
        Event::Status(StatusSample {
            vout_v: Some(12.0),
            time_ms: Some(time_ms),
            ..StatusSample::default()
        })
    };
    r.t = Duration::from_millis(4600);
    r.input(Input::SimBoard(Event::Boot));
    // The simulator's clock, behind the board's (about 3.5 s by now).
    r.input(Input::SimBoard(status(100)));
    assert!(r.v.armed(), "disarmed by the simulator's power-up");
    let (result, _) = command(
        &mut r,
        GCS,
        MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE,
        0.0,
        f32::NAN,
        5600,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_ACCEPTED));
    r.t = Duration::from_millis(5700);
    r.input(Input::Board(status(5700)));
    assert!(r.v.armed(), "disarmed back in normal run mode");

    // A board that really restarts while the simulator flies: disarmed.
    let (result, _) = command(
        &mut r,
        GCS,
        MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE,
        1.0,
        f32::NAN,
        6600,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_ACCEPTED));
    r.t = Duration::from_millis(6700);
    r.input(Input::Board(Event::Boot));
    assert!(!r.v.armed(), "still armed after the board restarted");
}

#[test]
fn only_the_owner_switches_run_mode_or_sets_targets() {
    let mut r = armed_vehicle(Mode::AltHold.number());
    let (result, _) = command(
        &mut r,
        STRANGER,
        MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE,
        1.0,
        0.0,
        3600,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_NOT_IN_CONTROL));
    assert_eq!(r.v.run_mode(), RunMode::Normal);
    let (result, _) = command(
        &mut r,
        STRANGER,
        MavCmd::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET,
        3.0,
        f32::NAN,
        3610,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_NOT_IN_CONTROL));
    assert_ne!(r.v.targets().0, Some(3.0));
    let (result, _) = command(
        &mut r,
        GCS,
        MavCmd::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET,
        3.0,
        120.0,
        3620,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_ACCEPTED));
    assert_eq!(r.v.targets().0, Some(3.0));
    assert!((r.v.targets().1.expect("heading held") - 120.0).abs() < 1e-6);
    // Out of range: denied, nothing changes.
    let (result, _) = command(
        &mut r,
        GCS,
        MavCmd::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET,
        -5.0,
        f32::NAN,
        3630,
    );
    assert_eq!(result, Some(MavResult::MAV_RESULT_DENIED));
    assert_eq!(r.v.targets().0, Some(3.0));
}

#[test]
fn hold_modes_need_fresh_estimates() {
    let mut r = CoreRig::new(Vehicle::new(
        neptunus::vehicle::machine::Identity::Ardupilot,
        neptunus::vehicle::params::ParamStore::default(),
        1,
    ));
    for mode in [
        Mode::AltHold.number(),
        Mode::Stabilize.number(),
        Mode::Surface.number(),
    ] {
        let (result, out) = command(
            &mut r,
            GCS,
            MavCmd::MAV_CMD_DO_SET_MODE,
            1.0,
            mode as f32,
            100,
        );
        assert_eq!(result, Some(MavResult::MAV_RESULT_FAILED), "mode {mode}");
        assert!(out.iter().any(
            |o| matches!(o, Output::Text { msg: MavMessage::STATUSTEXT(t), .. }
            if String::from_utf8_lossy(t.text.as_ref()).contains("estimate"))
        ));
    }
}

#[test]
fn estimates_and_setpoints_are_published() {
    let mut s = alt_hold_at(1.0);
    s.set_depth_target(1.5);
    s.run(secs(2));
    let v = s.vehicle();
    let t = Now {
        mono: s.now(),
        unix_us: 0,
    };
    let est = v.build(44102, t);
    let Some(MavMessage::NEPTUNUS_ESTIMATE(e)) = est.first() else {
        panic!("no NEPTUNUS_ESTIMATE: {est:?}")
    };
    assert!(
        e.flags
            .contains(NeptunusEstimateFlags::NEPTUNUS_ESTIMATE_FLAGS_DEPTH_VALID)
    );
    assert!((e.depth - 1.0).abs() < 0.5);
    let ap = v.build(44103, t);
    let Some(MavMessage::NEPTUNUS_AUTOPILOT(a)) = ap.first() else {
        panic!("no NEPTUNUS_AUTOPILOT")
    };
    assert_eq!(a.depth_target, 1.5);
    assert!(
        a.flags
            .contains(NeptunusAutopilotFlags::NEPTUNUS_AUTOPILOT_FLAGS_DEPTH_HOLD)
    );
    let nav = v.build(62, t);
    assert!(matches!(
        nav.first(),
        Some(MavMessage::NAV_CONTROLLER_OUTPUT(_))
    ));
}

#[cfg(feature = "report")]
#[test]
fn sim_report_writes_a_png_and_a_csv_per_scenario() {
    let dir = tempfile::tempdir().expect("temp dir");
    let outcome = report::surface();
    let written = report::write(dir.path(), std::slice::from_ref(&outcome)).expect("report");
    let png = std::fs::read(dir.path().join("surface.png")).expect("png");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    assert!(png.len() > 10_000, "a real plot, {} bytes", png.len());
    let csv = std::fs::read_to_string(dir.path().join("surface.csv")).expect("csv");
    let mut lines = csv.lines();
    assert!(
        lines
            .next()
            .expect("header")
            .starts_with("t_s,depth_true_m,")
    );
    assert_eq!(lines.count(), outcome.samples.len());
    assert_eq!(written.len(), 3, "{written:?}");
}

/// A defect once seen: Normal → Simulator → Normal at 1.5 m / 60° in ALT_HOLD once
/// took the held depth and heading from the reset estimator (0 m, north):
/// the ROV rose to the surface and turned north with no message.
#[test]
fn a_run_mode_round_trip_keeps_the_setpoints_and_the_vehicle_at_depth() {
    let mut s = Scenario::new(report::options(31));
    s.place(1.5, 60.0);
    s.run(secs(3));
    assert_eq!(s.arm(), Some(MavResult::MAV_RESULT_ACCEPTED));
    assert_eq!(
        s.set_mode(Mode::AltHold.number()),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    s.set_depth_target(1.5);
    assert_eq!(
        s.set_heading_target(60.0),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    s.run(secs(10));
    let (depth, heading) = s.vehicle().targets();
    assert!((depth.expect("held depth") - 1.5).abs() < 1e-6);
    assert!((heading.expect("held heading") - 60.0).abs() < 1e-6);

    assert_eq!(
        s.set_run_mode(RunMode::Simulator),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    s.run(secs(2));
    assert_eq!(
        s.set_run_mode(RunMode::Normal),
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    // The pilot is told, not left to guess.
    assert!(
        s.sent.iter().any(|m| matches!(m, MavMessage::STATUSTEXT(t)
            if String::from_utf8_lossy(t.text.as_ref()).contains("Setpoints kept: depth 1.50 m, heading 60"))),
        "{:?}",
        s.sent
    );
    let (depth, heading) = s.vehicle().targets();
    assert!(
        depth.is_some_and(|d| (d - 1.5).abs() < 1e-6),
        "held depth after the round trip: {depth:?}"
    );
    assert!(
        heading.is_some_and(|h| (h - 60.0).abs() < 1e-6),
        "held heading after the round trip: {heading:?}"
    );
    s.run(secs(20));
    let (depth, heading) = s.vehicle().targets();
    assert!(depth.is_some_and(|d| (d - 1.5).abs() < 1e-6), "{depth:?}");
    assert!(
        heading.is_some_and(|h| (h - 60.0).abs() < 1e-6),
        "{heading:?}"
    );
    // The vehicle never left the held depth by more than a hold's error, and
    // ends at the held heading.
    let after: Vec<_> = s.samples().iter().filter(|x| x.t_s > 15.0).collect();
    let worst = after
        .iter()
        .map(|x| (x.depth_true_m - 1.5).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.25, "left the held depth by {worst} m");
    let last = after.last().expect("samples after the round trip");
    let off = (last.heading_true_deg - 60.0 + 540.0).rem_euclid(360.0) - 180.0;
    assert!(off.abs() < 5.0, "heading {} deg", last.heading_true_deg);
}
