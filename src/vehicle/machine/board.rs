//! The board as the core knows it: the link state and the latest
//! navigation and power readings, each stamped with when it arrived.
//! Readings older than [`FRESH`] or from a link that is down are not
//! reported as if they were current.

use std::time::Duration;

use super::texts::Topic;
use super::{FRESH, Now, Output, SimTruth, Vehicle, holds};
use crate::dialect::neptunus::*;
use crate::firmware::codec::{Event, NavSample};
use crate::firmware::link::LinkState;

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
    /// The link has been up at least once since start.
    pub link_seen_up: bool,
    pub heading_deg: Stamped<f64>,
    pub depth_m: Stamped<f64>,
    pub pitch_deg: Stamped<f64>,
    pub roll_deg: Stamped<f64>,
    prev_heading: Option<(Duration, f64)>,
    /// Yaw rate from successive headings (before the estimator starts).
    pub yaw_rate_rps: f64,
    /// The last full power reading.
    pub status: Stamped<crate::firmware::codec::StatusSample>,
    /// Charge used since start, integrated from the current (mAh).
    pub consumed_mah: f64,
    last_current: Option<(Duration, f64)>,
    /// Ground truth of the built-in simulator.
    pub sim_truth: Stamped<SimTruth>,
}

impl BoardState {
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
                if let Some(d) = depth_m {
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
            Event::Status(s) => {
                if s.vout_v.is_none() {
                    // A `motors:` line on its own: keep the last full status.
                    return;
                }
                if let Some(v) = s.vout_v {
                    let low = f64::from(self.params.batt_low_volt());
                    let crt = f64::from(self.params.batt_crt_volt());
                    self.failsafes.battery[0].sample(v, low, now.mono);
                    self.failsafes.battery[1].sample(v, crt, now.mono);
                }
                if let Some(i) = s.btti_a.or(s.iout_a) {
                    if let Some((pt, pi)) = self.board.last_current {
                        let h = now.mono.saturating_sub(pt).as_secs_f64() / 3600.0;
                        self.board.consumed_mah += (pi + i) / 2.0 * h * 1000.0;
                    }
                    self.board.last_current = Some((now.mono, i));
                }
                self.board.status = Stamped::new(s, now.mono);
            }
            Event::Lights { level, .. } => self.payload.lights = level,
            Event::Laser(l) => self.payload.laser = l,
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

    /// The output voltage of the last full power reading (V), for the app's log line.
    pub fn battery_v(&self) -> Option<f64> {
        self.board.status.value.vout_v
    }
}
