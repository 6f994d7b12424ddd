//! Time from the ground station in control: SYSTEM_TIME (QGroundControl
//! sends it twice after connecting, Cockpit every 10 s) sets the vehicle's
//! wall clock when its own is implausible (before this build) or known
//! unsynchronised — a BeagleBone at the pool has no RTC and no network.
//!
//! The decision only: [`Output::SetWallClock`] asks the app to carry it out
//! (`wallclock::WallClock`, which the telemetry and event logs use). Once per
//! run, and only ever from the station in control: a SYSTEM_TIME from a
//! station that may control but does not (yet) is held, and applied —
//! carried forward by the time since — if that station takes control; it is
//! never applied while another station, or none, is in control.

use std::time::Duration;

use super::texts::Topic;
use super::{Now, Output, Sender, Vehicle};
use crate::dialect::neptunus::{MavSeverity, SYSTEM_TIME_DATA};
use crate::eventlog::rfc3339_utc;
pub use crate::wallclock::ClockSync;

/// A held SYSTEM_TIME older than this is dropped (the station sends again).
const HELD_FOR: Duration = Duration::from_secs(600);

#[derive(Debug)]
pub(super) struct WallTime {
    sync: ClockSync,
    /// Before this, the vehicle's clock is certainly wrong.
    build_unix_us: u64,
    /// Who set the clock (once per run).
    set_by: Option<u8>,
    /// A station's time received before it was in control:
    /// (sysid, its time, when it came).
    held: Option<(u8, u64, Duration)>,
}

impl Default for WallTime {
    fn default() -> Self {
        Self {
            sync: ClockSync::Unknown,
            build_unix_us: crate::wallclock::BUILD_UNIX_S * 1_000_000,
            set_by: None,
            held: None,
        }
    }
}

impl Vehicle {
    /// Whether the system clock follows a time source, and this build's
    /// date (µs since the epoch): a clock before it is wrong.
    pub fn with_wall_clock(mut self, sync: ClockSync, build_unix_us: u64) -> Self {
        self.wall_time.sync = sync;
        self.wall_time.build_unix_us = build_unix_us;
        self
    }

    /// The station whose SYSTEM_TIME set the clock, if one did.
    pub fn clock_set_by(&self) -> Option<u8> {
        self.wall_time.set_by
    }

    fn clock_needs_setting(&self, now: Now) -> bool {
        self.wall_time.set_by.is_none()
            && (now.unix_us < self.wall_time.build_unix_us
                || self.wall_time.sync == ClockSync::Unsynced)
    }

    pub(super) fn on_system_time(
        &mut self,
        from: Sender,
        t: &SYSTEM_TIME_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        // Its own clock no better than ours: nothing to learn (QGC sends 0
        // when it has no time itself).
        if !self.clock_needs_setting(now)
            || t.time_unix_usec < self.wall_time.build_unix_us
            || !self.may_control(from)
        {
            return;
        }
        if self.owner() == Some(from.sysid) {
            self.set_wall_clock(from.sysid, t.time_unix_usec, now, out);
        } else {
            self.wall_time.held = Some((from.sysid, t.time_unix_usec, now.mono));
        }
    }

    /// On the tick: a held time whose station is now in control is applied.
    pub(super) fn wall_time_tick(&mut self, now: Now, out: &mut Vec<Output>) {
        let Some((sysid, unix_us, at)) = self.wall_time.held else {
            return;
        };
        let age = now.mono.saturating_sub(at);
        if age > HELD_FOR || !self.clock_needs_setting(now) {
            self.wall_time.held = None;
        } else if self.owner() == Some(sysid) {
            self.wall_time.held = None;
            let carried = unix_us.saturating_add(u64::try_from(age.as_micros()).unwrap_or(0));
            self.set_wall_clock(sysid, carried, now, out);
        }
    }

    fn set_wall_clock(&mut self, sysid: u8, unix_us: u64, now: Now, out: &mut Vec<Output>) {
        self.wall_time.set_by = Some(sysid);
        self.wall_time.held = None;
        // First, so what follows (this text's event line) has the new time.
        out.push(Output::SetWallClock { unix_us });
        let at = rfc3339_utc(unix_us);
        let at = at.get(..19).unwrap_or(&at);
        let text = format!("Clock set from GCS {sysid}: {at}Z");
        self.statustext(Topic::General, MavSeverity::MAV_SEVERITY_NOTICE, &text, out);
        let why = match self.wall_time.sync {
            ClockSync::Unsynced if now.unix_us >= self.wall_time.build_unix_us => "unsynchronised",
            _ => "before this build",
        };
        self.log(
            "clock_set",
            Some(sysid),
            format!(
                "{text} (the vehicle's clock said {}, {why})",
                rfc3339_utc(now.unix_us)
            ),
            out,
        );
    }
}
