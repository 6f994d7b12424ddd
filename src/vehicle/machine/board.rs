//! The board as the core knows it: the link state and the latest
//! navigation, power and environment readings, each stamped with when it
//! arrived. Readings older than [`FRESH`] or from a link that is down are
//! not reported as if they were current.
//!
//! The genuine board prints its status as about ten separate lines a
//! second (`motorAttached`, `servo`/`starg`, `fmem`/`vout`/`iout`, `time`,
//! `pres`/`temp`, `BRDT`/`BT1I`/`BT2I`, `mtarg`, `motors` …): each reading
//! is kept and stamped on its own, so a line that stops coming goes stale by
//! itself while the others stay current.

use std::time::Duration;

use super::texts::Topic;
use super::{FRESH, Now, Output, SimTruth, Vehicle, holds};
use crate::dialect::neptunus::*;
use crate::firmware::codec::{Event, NavSample, StatusSample};
use crate::firmware::link::LinkState;

/// The genuine firmware's dead-man timeout (`DeadManSwitch.cpp`: no ping
/// for 2 s).
const BOARD_DEAD_MAN: Duration = Duration::from_secs(2);

/// A reading and when it arrived.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Stamped<T> {
    pub value: T,
    pub at: Option<Duration>,
}

impl<T> Stamped<T> {
    fn new(value: T, at: Duration) -> Self {
        Self {
            value,
            at: Some(at),
        }
    }

    /// Younger than [`FRESH`] at `now`.
    pub fn recent(&self, now: Now) -> bool {
        self.at.is_some_and(|t| now.mono.saturating_sub(t) <= FRESH)
    }
}

/// What the board (or, in SIMULATOR run mode, the simulator) last said.
#[derive(Debug, Default)]
pub(super) struct BoardState {
    pub link: LinkState,
    pub link_reason: Option<String>,
    /// The serial line's quality as the link last reported it.
    pub link_quality: crate::firmware::link::LinkQuality,
    /// The link has been up at least once since start.
    pub link_seen_up: bool,
    pub heading_deg: Stamped<f64>,
    pub depth_m: Stamped<f64>,
    pub pitch_deg: Stamped<f64>,
    pub roll_deg: Stamped<f64>,
    prev_heading: Option<(Duration, f64)>,
    /// Yaw rate from successive headings (before the estimator starts).
    pub yaw_rate_rps: f64,
    /// Supply (battery) voltage, `vout`.
    pub vout_v: Stamped<f64>,
    /// Battery current: the battery tubes' `BT1I` + `BT2I`, else the
    /// board's own `iout`.
    pub current_a: Stamped<f64>,
    /// Water pressure (mbar) and temperature (°C) from the depth sensor.
    pub water: Stamped<(f64, Option<f64>)>,
    /// Whether the depth sensor has been read since the board started:
    /// `Some(false)` while the board prints `pres:0` (the firmware's value
    /// before its first conversion, and for ever without a sensor), `None`
    /// before any `pres` since start or reboot.
    pressure_read: Option<bool>,
    /// Camera tilt servo position the board reports (`servo`, µs).
    pub servo_us: Stamped<u16>,
    /// Controller-board temperature (`BRDT`).
    pub board_temp_c: Stamped<f64>,
    /// The board's free RAM (`fmem`) and uptime (`time`).
    pub fmem_bytes: Stamped<u32>,
    pub uptime_ms: Stamped<u64>,
    /// A `time` reading that did not follow the uptime (and when it came),
    /// held until the next one says whether the clock really moved.
    uptime_doubt: Option<(u64, Duration)>,
    /// The firmware's `ver` and `cmpd`, once the board said them.
    pub firmware: Option<(String, Option<String>)>,
    /// The board's dead-man switch stopped the thrusters (`icmd:stop`) and
    /// no ping has restarted them yet (`icmd:start`).
    pub dead_man_tripped: bool,
    /// Charge used since start, integrated from the current (mAh).
    pub consumed_mah: f64,
    last_current: Option<(Duration, f64)>,
    /// The current reading came from `iout` (no battery tube sensor on the line).
    current_from_iout: bool,
    /// Ground truth of the built-in simulator.
    pub sim_truth: Stamped<SimTruth>,
}

impl BoardState {
    /// A `deap` reading is a measurement unless it is the firmware's unset
    /// zero: the genuine board prints `deap:0.00` from boot until its depth
    /// sensor's first conversion (about a second later), and always when no
    /// sensor is fitted — with `pres:0` beside it. A zero depth before any
    /// pressure reading is not trusted either; any other depth from a board
    /// that never prints `pres` is.
    fn depth_is_measured(&self, depth_m: f64) -> bool {
        self.pressure_read.unwrap_or(depth_m != 0.0)
    }

    pub fn on_sim_truth(&mut self, t: SimTruth, now: Now) {
        self.sim_truth = Stamped::new(t, now.mono);
    }
}

impl Vehicle {
    pub(super) fn on_link(
        &mut self,
        state: LinkState,
        reason: Option<String>,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let was = self.board.link;
        self.board.link = state;
        self.board.link_reason = reason.clone();
        if state == LinkState::Up && was != LinkState::Up {
            self.board.link_seen_up = true;
            self.log("link_up", None, "board link up".into(), out);
            // Whatever the board had, it gets what we decide now.
            self.send_neutral(out);
            self.payload_to_board(out);
            self.statustext(
                Topic::BoardLink,
                MavSeverity::MAV_SEVERITY_INFO,
                "Board link up",
                out,
            );
        } else if state == LinkState::Down && was != LinkState::Down {
            let why = reason.unwrap_or_else(|| "unknown".into());
            self.statustext(
                Topic::BoardLink,
                MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("Board link down: {why}"),
                out,
            );
            self.log("link_down", None, why, out);
        }
        // The board-link failsafe disarms at once, not at the next tick.
        self.failsafe_tick(now, out);
    }

    /// The built-in simulator's board, in run mode SIMULATOR. It powers up
    /// when the run mode switches to it and counts time on the vehicle's
    /// clock, not the board's: its `boot` line and its uptime say nothing
    /// of the vehicle's board, and taken as the board's they read as a
    /// restart that disarms the vehicle a second into the simulator. The
    /// board's own `boot` line still counts in SIMULATOR run mode.
    pub(super) fn on_sim_board(&mut self, ev: Event, now: Now, out: &mut Vec<Output>) {
        match ev {
            Event::Boot => {}
            Event::Status(mut s) => {
                s.time_ms = None;
                self.on_board(Event::Status(s), now, out);
            }
            ev => self.on_board(ev, now, out),
        }
    }

    pub(super) fn on_board(&mut self, ev: Event, now: Now, out: &mut Vec<Output>) {
        match ev {
            Event::Nav(NavSample {
                heading_deg,
                depth_m,
                pitch_deg,
                roll_deg,
                ..
            }) => {
                if let Some(h) = heading_deg {
                    if let Some((pt, ph)) = self.board.prev_heading {
                        let dt = now.mono.saturating_sub(pt).as_secs_f64();
                        if dt > 0.0 {
                            let d = (h - ph + 540.0).rem_euclid(360.0) - 180.0;
                            self.board.yaw_rate_rps = d.to_radians() / dt;
                        }
                    }
                    self.board.prev_heading = Some((now.mono, h));
                    self.board.heading_deg = Stamped::new(h, now.mono);
                    self.estimator_reading(holds::Reading::Heading(h), now, out);
                }
                if let Some(d) = depth_m.filter(|&d| self.board.depth_is_measured(d)) {
                    self.board.depth_m = Stamped::new(d, now.mono);
                    self.estimator_reading(holds::Reading::Depth(d), now, out);
                }
                if let Some(p) = pitch_deg {
                    self.board.pitch_deg = Stamped::new(p, now.mono);
                }
                if let Some(r) = roll_deg {
                    self.board.roll_deg = Stamped::new(r, now.mono);
                }
                self.stream_nav_line(now, out);
            }
            Event::Status(s) => self.on_status(s, now, out),
            // While the board's dead-man has the lights blinking, its echoes
            // are not the pilot's level: that is restored once it is over.
            Event::Lights { level, .. } if !self.board.dead_man_tripped => {
                self.payload.lights = level
            }
            Event::Laser(l) => self.payload.laser = l,
            Event::Boot => self.on_board_boot(out),
            Event::InternalCommand(cmd) => self.on_internal_command(&cmd, now, out),
            _ => {}
        }
    }

    fn on_status(&mut self, s: StatusSample, now: Now, out: &mut Vec<Output>) {
        let at = now.mono;
        if let Some(v) = s.vout_v {
            let low = f64::from(self.params.batt_low_volt());
            let crt = f64::from(self.params.batt_crt_volt());
            self.failsafes.battery[0].sample(v, low, at);
            self.failsafes.battery[1].sample(v, crt, at);
            self.board.vout_v = Stamped::new(v, at);
        }
        // The battery tubes' sensors when the board has them on the line,
        // else the board current printed beside the voltage.
        let current = s.battery_current_a.or(s
            .iout_a
            .filter(|_| !self.board.current_a.recent(now) || self.board.current_from_iout));
        if let Some(i) = current {
            self.board.current_from_iout = s.battery_current_a.is_none();
            if let Some((pt, pi)) = self.board.last_current {
                let h = at.saturating_sub(pt).as_secs_f64() / 3600.0;
                self.board.consumed_mah += (pi + i) / 2.0 * h * 1000.0;
            }
            self.board.last_current = Some((at, i));
            self.board.current_a = Stamped::new(i, at);
        }
        if let Some(p) = s.pres_mbar {
            self.board.pressure_read = Some(p != 0.0);
            // `pres:0` is no reading (see `depth_is_measured`).
            if p != 0.0 {
                self.board.water = Stamped::new((p, s.temp_c), at);
            }
        }
        if let Some(us) = s.servo_us {
            self.board.servo_us = Stamped::new(us, at);
        }
        if let Some(t) = s.board_temp_c {
            self.board.board_temp_c = Stamped::new(t, at);
        }
        if let Some(b) = s.fmem_bytes {
            self.board.fmem_bytes = Stamped::new(b, at);
        }
        if let Some(t) = s.time_ms {
            self.on_board_clock(t, at, out);
        }
        if let Some(v) = s.version {
            let first = self.board.firmware.is_none();
            self.board.firmware = Some((v, s.compiled));
            if first {
                self.announce_firmware(out);
            }
        }
    }

    /// The board's uptime `t` (ms), arrived at `at`. A clock that went
    /// back means the board restarted, even if its `boot:1` line was lost.
    /// A noisy line changes digits, though (one byte in 400 with a bit
    /// flipped makes a damaged `time` every few minutes, and a digit flip
    /// stays a number): a reading that does not follow the uptime — back
    /// more than a second, or ahead of it by more than the time since plus
    /// two seconds — moves nothing until the next reading follows *it*;
    /// only then is it the board's clock (and, back, a restart). A damaged
    /// reading is followed by a true one, which follows the old uptime.
    fn on_board_clock(&mut self, t: u64, at: Duration, out: &mut Vec<Output>) {
        let follows = |base: u64, base_at: Duration| {
            let since_ms = at.saturating_sub(base_at).as_millis() as u64;
            t + 1000 >= base && t <= base + since_ms + 2000
        };
        let old = self.board.uptime_ms;
        let Some(old_at) = old.at else {
            self.board.uptime_ms = Stamped::new(t, at);
            return;
        };
        if follows(old.value, old_at) {
            self.board.uptime_doubt = None;
            self.board.uptime_ms = Stamped::new(t, at);
            return;
        }
        match self.board.uptime_doubt {
            Some((doubted, doubted_at)) if follows(doubted, doubted_at) => {
                self.board.uptime_doubt = None;
                if t + 1000 < old.value {
                    self.on_board_boot(out);
                }
                self.board.uptime_ms = Stamped::new(t, at);
            }
            _ => {
                tracing::debug!(
                    uptime_ms = old.value,
                    reading_ms = t,
                    "a board uptime that does not follow; held until the next one"
                );
                self.board.uptime_doubt = Some((t, at));
            }
        }
    }

    /// Says once which firmware the board runs (the operator's first
    /// question when something behaves oddly).
    fn announce_firmware(&mut self, out: &mut Vec<Output>) {
        let Some((version, compiled)) = self.board.firmware.clone() else {
            return;
        };
        let text = match compiled {
            Some(c) => format!("Board firmware {version}, built {c}"),
            None => format!("Board firmware {version}"),
        };
        self.statustext(Topic::BoardLink, MavSeverity::MAV_SEVERITY_INFO, &text, out);
        self.log("board_firmware", None, text, out);
    }

    /// The board restarted (power, brown-out, watchdog, a reset by the
    /// BeagleBone): whatever it was doing is gone, so the vehicle stops
    /// and waits for the pilot to arm again.
    fn on_board_boot(&mut self, out: &mut Vec<Output>) {
        self.board.dead_man_tripped = false;
        self.board.pressure_read = None;
        self.board.firmware = None;
        self.board.uptime_ms = Stamped::default();
        self.board.uptime_doubt = None;
        if self.armed {
            self.statustext(
                Topic::Stop,
                MavSeverity::MAV_SEVERITY_CRITICAL,
                "Board rebooted: thrusters stopped, arm again once the link is up",
                out,
            );
            self.disarm("board rebooted", None, out);
        } else {
            self.send_neutral(out);
        }
    }

    /// A command the board queued for itself. Its dead-man switch queues
    /// `stop()` when two seconds pass without a ping, and `start()` at the
    /// next ping: after that it obeys `go()` again, so driving may resume
    /// only through the arming rules. A trip reported less than the
    /// dead-man's timeout after arming began before the arming (the lines
    /// a frozen vehicle finds waiting when it resumes): it disarms nothing,
    /// and the link's neutral ahead of the next ping restarts the board
    /// stopped.
    fn on_internal_command(&mut self, cmd: &str, now: Now, out: &mut Vec<Output>) {
        let name = cmd.split('(').next().unwrap_or_default();
        match name {
            "stop" if !self.board.dead_man_tripped => {
                self.board.dead_man_tripped = true;
                self.log(
                    "board_dead_man",
                    None,
                    "the board's dead-man switch stopped the thrusters (no ping for 2 s)".into(),
                    out,
                );
                let armed_since_before_the_trip = self
                    .armed_at
                    .is_some_and(|t| now.mono.saturating_sub(t) >= BOARD_DEAD_MAN);
                if self.armed && armed_since_before_the_trip {
                    self.statustext(
                        Topic::Stop,
                        MavSeverity::MAV_SEVERITY_CRITICAL,
                        "Board dead-man tripped: no ping for 2 s, thrusters stopped",
                        out,
                    );
                    self.disarm("board dead-man tripped", None, out);
                } else if self.armed {
                    self.statustext(
                        Topic::BoardLink,
                        MavSeverity::MAV_SEVERITY_WARNING,
                        "Board dead-man had tripped before arming: it restarts stopped",
                        out,
                    );
                }
            }
            "start" if self.board.dead_man_tripped => {
                self.board.dead_man_tripped = false;
                // The board blinked the lights meanwhile: give back the pilot's.
                self.send_neutral(out);
                self.payload_to_board(out);
            }
            _ => {}
        }
    }

    /// A reading that is recent, over a link that is up.
    pub(super) fn fresh<T>(&self, s: &Stamped<T>, now: Now) -> bool {
        self.board.link == LinkState::Up && s.recent(now)
    }

    /// Roll and pitch the board reported last (deg).
    pub fn attitude_deg(&self) -> (f64, f64) {
        (self.board.roll_deg.value, self.board.pitch_deg.value)
    }

    /// The last supply voltage the board reported (V), for the app's log line.
    pub fn battery_v(&self) -> Option<f64> {
        self.board.vout_v.at.map(|_| self.board.vout_v.value)
    }
}
