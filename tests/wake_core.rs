//! When the core needs to wake, and that a navigation line reaches the
//! ground stations at once: on the core with synthetic time.
//!
//! - a disarmed vehicle with nothing moving asks for a tick only when a
//!   telemetry message (or the camera's heartbeat) is due, and at least
//!   every `IDLE_TICK` (with a navigation line when one comes first);
//!   armed, every `BUSY_TICK`, as before;
//! - ATTITUDE and the other line-made messages go out in the very outputs
//!   of the line that made them, at their rate, and are repeated between
//!   lines only when asked for faster than the lines come.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, count_sent};
use mavlink_core::MessageData;
use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::Event;
use neptunus::vehicle::machine::{
    BUSY_TICK, IDLE_TICK, Identity, Input, Output, Sender, To, Vehicle,
};
use neptunus::vehicle::params::ParamStore;
use neptunus::vehicle::telemetry::LINE_SLACK;

const GCS: Sender = Sender::new(0, 1, 255, 190);

fn rig() -> CoreRig {
    CoreRig::new(Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 1)).started()
}

/// Ticks only when the core asks for one, with the board's 10-Hz lines and
/// 1-Hz status in between, for `d`; every output, and the number of ticks.
fn run_on_demand(r: &mut CoreRig, d: Duration) -> (Vec<Output>, usize) {
    run_with_lines_late(r, d, |_| Duration::ZERO)
}

/// As [`run_on_demand`], the `k`-th line `late(k)` after its beat.
fn run_with_lines_late(
    r: &mut CoreRig,
    d: Duration,
    late: impl Fn(u64) -> Duration,
) -> (Vec<Output>, usize) {
    let end = r.t + d;
    // The next line on the board's 100-ms beat, as `CoreRig::run` gives them.
    let mut next_line = Duration::from_millis((r.t.as_millis() as u64 / 100 + 1) * 100);
    let mut out = Vec::new();
    let mut ticks = 0;
    while r.t < end {
        let tick_at = r.v.next_tick().max(r.t);
        let line_at = next_line + late(next_line.as_millis() as u64 / 100);
        if line_at <= tick_at {
            r.t = line_at;
            let nav = r.feed.nav;
            out.extend(r.input(Input::Board(Event::Nav(nav))));
            if next_line.as_millis().is_multiple_of(1000) {
                let status = r.feed.status.clone();
                out.extend(r.input(Input::Board(Event::Status(status))));
            }
            next_line += Duration::from_millis(100);
        } else {
            r.t = tick_at;
            out.extend(r.input(Input::Tick));
            ticks += 1;
        }
    }
    (out, ticks)
}

#[test]
fn an_idle_vehicle_wakes_only_for_what_is_due() {
    let mut r = rig();
    let (out, ticks) = run_on_demand(&mut r, Duration::from_secs(10));
    eprintln!("{ticks} ticks in 10 s for an idle vehicle");
    // ArduSub's default streams on one endpoint: the line-made ones at the
    // lines' rate need no tick at all; the clocked ones (1–5 Hz, the 3-Hz
    // line-made ones among them) and the idle tick's timers go with a line
    // when one comes before they are due, so while the board's lines come
    // on their beat they are all that wakes the vehicle.
    assert_eq!(
        ticks, 0,
        "{ticks} ticks in 10 s for an idle vehicle besides its 100 lines (was 1000 at 100 Hz)"
    );
    // The timers still run at least every IDLE_TICK: the board's dead-man
    // is fed as often.
    let fed = out.iter().filter(|o| matches!(o, Output::Healthy)).count();
    assert!(fed >= 10 * 10 - 2, "the dead-man fed {fed} times in 10 s");
    // Nothing lost: the default rates still hold.
    let n = |id| count_sent(&out, id, To::Endpoint(0));
    assert!(
        (98..=101).contains(&n(ATTITUDE_DATA::ID)),
        "ATTITUDE {}",
        n(ATTITUDE_DATA::ID)
    );
    assert!(
        (19..=21).contains(&n(SYS_STATUS_DATA::ID)),
        "SYS_STATUS {}",
        n(SYS_STATUS_DATA::ID)
    );
    assert!(
        (9..=11).contains(&n(HEARTBEAT_DATA::ID)),
        "HEARTBEAT {}",
        n(HEARTBEAT_DATA::ID)
    );
    // The 3-Hz line-made ones keep their rate, not the lines' whole periods.
    for id in [GLOBAL_POSITION_INT_DATA::ID, AHRS2_DATA::ID] {
        assert!(
            (29..=31).contains(&n(id)),
            "message {id}: {} in 10 s",
            n(id)
        );
    }
    // Never more than IDLE_TICK (and a line's slack) without a tick.
    assert!(r.v.next_tick() <= r.t + IDLE_TICK + LINE_SLACK);
}

/// The board's timing jitters: lines up to 20 ms late (as the genuine
/// firmware's loop gives them) still carry everything that is due, with
/// the rates kept; silent, the board leaves the idle tick to its clock.
#[test]
fn lines_a_little_late_still_wake_the_vehicle_alone() {
    let mut r = rig();
    // A fixed pseudo-random pattern of 0–20 ms.
    let late = |k: u64| Duration::from_millis(k.wrapping_mul(2_654_435_761) % 21);
    // (The first second settles the phases.)
    run_with_lines_late(&mut r, Duration::from_secs(1), late);
    let (out, ticks) = run_with_lines_late(&mut r, Duration::from_secs(10), late);
    assert_eq!(ticks, 0, "{ticks} ticks in 10 s besides the lines");
    let n = |id| count_sent(&out, id, To::Endpoint(0));
    assert!(
        (97..=101).contains(&n(ATTITUDE_DATA::ID)),
        "ATTITUDE {}",
        n(ATTITUDE_DATA::ID)
    );
    for (id, hz) in [
        (SYS_STATUS_DATA::ID, 2),
        (GLOBAL_POSITION_INT_DATA::ID, 3),
        (HEARTBEAT_DATA::ID, 1),
    ] {
        let want = 10 * hz;
        assert!(
            (want - 1..=want + 1).contains(&n(id)),
            "message {id}: {} in 10 s",
            n(id)
        );
    }
    // The board falls silent: the idle tick runs on its own clock.
    let mut ticks = 0;
    let end = r.t + Duration::from_secs(1);
    while r.t < end {
        r.t = r.v.next_tick().max(r.t);
        let out = r.input(Input::Tick);
        ticks += 1;
        assert!(
            out.iter().any(|o| matches!(o, Output::Healthy)),
            "a tick without the dead-man feed"
        );
    }
    assert!(
        (8..=40).contains(&ticks),
        "{ticks} idle ticks in a silent second"
    );
}

#[test]
fn armed_the_core_ticks_every_busy_tick() {
    let mut r = rig().alive(GCS);
    r.run(Duration::from_secs(1));
    let out = r.arm(GCS);
    assert!(
        common::core_rig::acks(&out)
            .iter()
            .any(|a| a.result == MavResult::MAV_RESULT_ACCEPTED),
        "not armed"
    );
    r.input(Input::Tick);
    assert_eq!(r.v.next_tick(), r.t + BUSY_TICK);
}

#[test]
fn a_navigation_line_goes_out_with_the_line_not_on_a_later_tick() {
    let mut r = rig();
    // Past the default interval since the last line.
    r.t += Duration::from_millis(100);
    let mut nav = r.feed.nav;
    nav.heading_deg = Some(123.0);
    let out = r.input(Input::Board(Event::Nav(nav)));
    let ids: Vec<u32> = common::core_rig::sent(&out)
        .iter()
        .map(|(_, m)| mavlink_core::Message::message_id(m))
        .collect();
    for id in [
        ATTITUDE_DATA::ID,
        VFR_HUD_DATA::ID,
        NEPTUNUS_ESTIMATE_DATA::ID,
    ] {
        assert!(
            ids.contains(&id),
            "message {id} not sent with the line: {ids:?}"
        );
    }
    // A line right after it waits for the interval (no doubled rate)…
    r.t += Duration::from_millis(30);
    nav.heading_deg = Some(124.0);
    let out = r.input(Input::Board(Event::Nav(nav)));
    assert_eq!(count_sent(&out, ATTITUDE_DATA::ID, To::Endpoint(0)), 0);
    // …and a newer line arriving when the interval is up goes instead of it.
    r.t += Duration::from_millis(70);
    let out = r.input(Input::Tick);
    assert_eq!(count_sent(&out, ATTITUDE_DATA::ID, To::Endpoint(0)), 0);
    nav.heading_deg = Some(125.0);
    let out = r.input(Input::Board(Event::Nav(nav)));
    // (ATTITUDE carries the filtered heading; the estimate the raw one.)
    let e = common::core_rig::msgs!(&out, NEPTUNUS_ESTIMATE);
    assert_eq!(e.len(), 1);
    assert_eq!(e[0].heading_measured, 125.0, "the newest line's heading");
}

#[test]
fn asked_faster_than_the_lines_the_rate_is_kept_by_repeats() {
    let mut r = rig().alive(GCS);
    r.run(Duration::from_secs(1));
    let out = r.cmd(
        GCS,
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
        &[ATTITUDE_DATA::ID as f32, 50_000.0],
    );
    assert_eq!(
        common::core_rig::ack_of(&out, MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let (out, _) = run_on_demand(&mut r, Duration::from_secs(4));
    let n = count_sent(&out, ATTITUDE_DATA::ID, To::Endpoint(0));
    assert!(
        (78..=81).contains(&n),
        "ATTITUDE at 20 Hz with 10-Hz lines: {n} in 4 s"
    );
}

/// An in-process endpoint (the browser sessions', mavlink2rest's) with
/// nobody listening gets no telemetry streams and costs the vehicle no
/// wake-up; when someone comes, every stream message goes out in the next
/// pass and then at the endpoint's rates. A wire station is not affected.
#[test]
fn an_endpoint_nobody_listens_on_gets_no_streams_until_someone_comes() {
    let mut r =
        CoreRig::new(Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 2)).started();
    let alone = {
        let mut one = rig();
        run_on_demand(&mut one, Duration::from_secs(10)).1
    };
    r.input(Input::Listeners {
        endpoint: 1,
        listened: false,
    });
    let (out, ticks) = run_on_demand(&mut r, Duration::from_secs(10));
    let n = |out: &[Output], id, ep| count_sent(out, id, To::Endpoint(ep));
    for id in [ATTITUDE_DATA::ID, SYS_STATUS_DATA::ID, HEARTBEAT_DATA::ID] {
        assert_eq!(n(&out, id, 1), 0, "message {id} built for nobody");
    }
    assert!(
        (98..=101).contains(&n(&out, ATTITUDE_DATA::ID, 0)),
        "the wire station's ATTITUDE {}",
        n(&out, ATTITUDE_DATA::ID, 0)
    );
    assert!(
        ticks <= alone + 2,
        "{ticks} ticks with a quiet second endpoint, {alone} with one endpoint"
    );

    r.input(Input::Listeners {
        endpoint: 1,
        listened: true,
    });
    assert!(
        r.v.next_tick() <= r.t,
        "someone came: the core must wake at once"
    );
    let first = r.input(Input::Tick);
    for id in [
        ATTITUDE_DATA::ID,
        SYS_STATUS_DATA::ID,
        HEARTBEAT_DATA::ID,
        VFR_HUD_DATA::ID,
    ] {
        assert_eq!(n(&first, id, 1), 1, "message {id} not in the first pass");
    }
    let (out, _) = run_on_demand(&mut r, Duration::from_secs(10));
    assert!(
        (98..=101).contains(&n(&out, ATTITUDE_DATA::ID, 1)),
        "ATTITUDE at its rate again: {}",
        n(&out, ATTITUDE_DATA::ID, 1)
    );
}
