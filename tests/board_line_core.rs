//! The core on a noisy board line: a damaged reading is not taken for an
//! event (a `time` with a flipped digit is no reboot), and the line's
//! quality the link reports reaches the ground stations in SYS_STATUS.

mod common;

use std::time::Duration;

use common::core_rig::{BoardFeed, CoreRig, has_text, sent};
use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::{Event, StatusSample};
use neptunus::firmware::link::LinkQuality;
use neptunus::vehicle::machine::{Identity, Input, Sender, Vehicle};
use neptunus::vehicle::params::ParamStore;

const OWNER: Sender = Sender::new(0, 1, 255, 190);

fn armed_rig() -> CoreRig {
    let mut rig = CoreRig::new(Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 1))
        .feed(BoardFeed {
            uptime: true,
            ..BoardFeed::level_at_1_m()
        })
        .alive(OWNER)
        .started();
    rig.run(Duration::from_secs(20));
    rig.arm(OWNER);
    drive(&mut rig, Duration::from_millis(500));
    assert!(rig.v.armed());
    rig
}

/// `d` of the rig's beats with the owner's sticks centred at 10 Hz (the
/// pilot-input failsafe would disarm a vehicle without them).
fn drive(rig: &mut CoreRig, d: Duration) -> Vec<neptunus::vehicle::machine::Output> {
    let mut out = Vec::new();
    let end = rig.t + d;
    while rig.t < end {
        out.extend(rig.stick(OWNER, 0));
        out.extend(rig.run(Duration::from_millis(100)));
    }
    out
}

fn uptime(rig: &mut CoreRig, ms: u64) -> Vec<neptunus::vehicle::machine::Output> {
    rig.input(Input::Board(Event::Status(StatusSample {
        time_ms: Some(ms),
        ..StatusSample::default()
    })))
}

#[test]
fn a_damaged_uptime_is_no_reboot_and_a_clock_that_stays_back_is() {
    let mut rig = armed_rig();
    let now_ms = rig.t.as_millis() as u64;
    // A digit flipped down (21xxx -> 01xxx), then one flipped up: each
    // followed by the board's true clock.
    for damaged in [now_ms - 20_000, now_ms + 900_000] {
        rig.t += Duration::from_millis(300);
        let out = uptime(&mut rig, damaged);
        let out2 = drive(&mut rig, Duration::from_secs(2));
        assert!(
            rig.v.armed() && !has_text(&out, "rebooted") && !has_text(&out2, "rebooted"),
            "a damaged uptime {damaged} ms disarmed the vehicle"
        );
    }
    // The board really restarted (its `boot` line lost): its clock starts
    // again and stays there.
    rig.feed.uptime = false;
    rig.t += Duration::from_millis(300);
    let first = uptime(&mut rig, 400);
    assert!(rig.v.armed() && !has_text(&first, "rebooted"));
    drive(&mut rig, Duration::from_secs(1));
    let second = uptime(&mut rig, 1_400);
    assert!(!rig.v.armed(), "a board whose clock went back stayed armed");
    assert!(has_text(&second, "Board rebooted"));
}

#[test]
fn the_links_quality_is_in_sys_status() {
    let mut rig = armed_rig();
    rig.input(Input::LinkQuality(LinkQuality {
        drop_rate_cpct: 327,
        errors: 87,
    }));
    let out = drive(&mut rig, Duration::from_secs(1));
    let status = sent(&out)
        .into_iter()
        .find_map(|(_, m)| match m {
            MavMessage::SYS_STATUS(s) => Some(s),
            _ => None,
        })
        .expect("a SYS_STATUS within a second");
    assert_eq!((status.drop_rate_comm, status.errors_comm), (327, 87));
}
