//! Time without internet, through the vehicle core with synthetic time:
//! SYSTEM_TIME from the station in control sets a wrong clock (before the
//! build, or known unsynchronised), once, with a STATUSTEXT and an event;
//! never from a station that is not in control.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, ack_of, events, has_event, has_text};
use neptunus::dialect::neptunus::*;
use neptunus::vehicle::machine::{ClockSync, Identity, Output, Sender, Vehicle};
use neptunus::vehicle::params::ParamStore;

/// Primary station (SYSID_MYGCS 255), in control once it arms.
const OWNER: Sender = Sender::new(0, 1, 255, 190);
/// Allowed (NEPT_GCS_ALLOW2 = 254) but not in control.
const OTHER: Sender = Sender::new(0, 2, 254, 190);
/// Not allowed at all.
const STRANGER: Sender = Sender::new(0, 3, 77, 190);

/// 2026-01-01: the build date of these tests.
const BUILD_US: u64 = 1_767_225_600_000_000;
/// 2000-01-01: a BeagleBone without RTC after boot.
const Y2000_US: u64 = 946_684_800_000_000;
/// The station's (right) time: 2026-11-25T06:00:00Z.
const GCS_US: u64 = 1_795_586_400_000_000;

fn rig(unix_us: u64, sync: ClockSync) -> CoreRig {
    let mut p = ParamStore::defaults();
    p.set("NEPT_GCS_ALLOW2", 254.0).unwrap();
    let v = Vehicle::new(Identity::Ardupilot, p, 1).with_wall_clock(sync, BUILD_US);
    CoreRig::new(v).unix_epoch(unix_us).started()
}

fn system_time(unix_us: u64) -> MavMessage {
    MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
        time_unix_usec: unix_us,
        time_boot_ms: 1234,
    })
}

fn set_to(out: &[Output]) -> Option<u64> {
    out.iter().find_map(|o| match o {
        Output::SetWallClock { unix_us } => Some(*unix_us),
        _ => None,
    })
}

fn take_control(r: &mut CoreRig, who: Sender) {
    r.alive.push(who);
    r.heartbeat(who);
    assert_eq!(
        ack_of(&r.arm(who), MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(r.v.owner(), Some(who.sysid));
}

#[test]
fn the_owner_sets_a_clock_before_the_build_once_with_a_text_and_an_event() {
    let mut r = rig(Y2000_US, ClockSync::Unknown);
    take_control(&mut r, OWNER);
    let out = r.msg(OWNER, system_time(GCS_US));
    assert_eq!(set_to(&out), Some(GCS_US));
    assert!(
        has_text(&out, "Clock set from GCS 255: 2026-11-25T06:00:00Z"),
        "{out:?}"
    );
    assert!(
        has_event(&out, "clock_set", Some(255)),
        "{:?}",
        events(&out)
    );
    // The order matters: the event line after the clock is set carries the new time.
    let set_at = out
        .iter()
        .position(|o| matches!(o, Output::SetWallClock { .. }));
    let log_at = out.iter().position(|o| matches!(o, Output::Log(_)));
    assert!(set_at < log_at, "{out:?}");
    assert_eq!(r.v.clock_set_by(), Some(255));
    // Once per run: the next one (Cockpit sends every 10 s) changes nothing.
    let again = r.msg(OWNER, system_time(GCS_US + 10_000_000));
    assert_eq!(set_to(&again), None);
}

#[test]
fn a_non_owner_never_sets_the_clock() {
    let mut r = rig(Y2000_US, ClockSync::Unsynced);
    take_control(&mut r, OWNER);
    for who in [OTHER, STRANGER] {
        let out = r.msg(who, system_time(GCS_US));
        assert_eq!(set_to(&out), None, "from {who:?}");
        let later = r.run(Duration::from_secs(2));
        assert_eq!(set_to(&later), None, "from {who:?}, later");
    }
    assert_eq!(r.v.clock_set_by(), None);
    // And nobody in control: nobody's time is taken.
    let mut r = rig(Y2000_US, ClockSync::Unsynced);
    let out = r.msg(OWNER, system_time(GCS_US));
    let later = r.run(Duration::from_secs(2));
    assert_eq!((set_to(&out), set_to(&later)), (None, None));
}

#[test]
fn time_sent_before_taking_control_applies_once_in_control() {
    // QGroundControl sends SYSTEM_TIME right after connecting, before it drives.
    let mut r = rig(Y2000_US, ClockSync::Unknown);
    r.msg(OWNER, system_time(GCS_US));
    r.run(Duration::from_secs(3));
    r.alive.push(OWNER);
    r.heartbeat(OWNER);
    let mut out = r.arm(OWNER);
    out.extend(r.run(Duration::from_millis(20)));
    let set = set_to(&out).expect("applied once in control");
    // Carried forward by the time it was held (3 s and a bit).
    assert!(
        (GCS_US + 3_000_000..GCS_US + 3_200_000).contains(&set),
        "{set}"
    );
}

#[test]
fn a_right_clock_is_kept_and_a_wrong_offer_is_refused() {
    // Plausible and not known unsynchronised: the vehicle keeps its own.
    let mut r = rig(GCS_US, ClockSync::Unknown);
    take_control(&mut r, OWNER);
    assert_eq!(set_to(&r.msg(OWNER, system_time(GCS_US + 7_000_000))), None);
    // Synchronised: the same.
    let mut r = rig(GCS_US, ClockSync::Synced);
    take_control(&mut r, OWNER);
    assert_eq!(set_to(&r.msg(OWNER, system_time(GCS_US + 7_000_000))), None);
    // Plausible but unsynchronised (fake-hwclock, no network): taken.
    let mut r = rig(GCS_US - 86_400_000_000, ClockSync::Unsynced);
    take_control(&mut r, OWNER);
    assert_eq!(set_to(&r.msg(OWNER, system_time(GCS_US))), Some(GCS_US));
    // A station whose own clock is before the build (or 0) teaches nothing.
    let mut r = rig(Y2000_US, ClockSync::Unsynced);
    take_control(&mut r, OWNER);
    assert_eq!(set_to(&r.msg(OWNER, system_time(0))), None);
    assert_eq!(set_to(&r.msg(OWNER, system_time(Y2000_US))), None);
    assert_eq!(set_to(&r.msg(OWNER, system_time(GCS_US))), Some(GCS_US));
}
