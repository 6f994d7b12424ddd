//! Estimation and the autopilot modes inside the vehicle core: STABILIZE
//! (heading hold), ALT_HOLD (depth and heading hold), SURFACE; setpoints
//! from SET_POSITION_TARGET_GLOBAL_INT, SET_ATTITUDE_TARGET and
//! MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET.
//!
//! The controllers themselves live in [`crate::vehicle::autopilot`], the
//! filters in [`crate::vehicle::estimator`]; this module decides when they
//! run and what they see. Every setpoint has passed the control-input check
//! (`inbound.rs`) before it reaches this file.

use std::time::Duration;

use mavlink_core::MessageData;

use super::authority::Control;
use super::texts::Topic;
use super::{Mode, Now, Output, RunMode, Sender, Vehicle};
use crate::dialect::neptunus::*;
use crate::vehicle::autopilot::{DepthHold, HeadingHold, Measured};
use crate::vehicle::estimator::{Estimate, Estimator, Fused};
use crate::vehicle::mixer::{self, Demand};

/// A depth or heading reading: which filter, and what became of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reading {
    Depth(f64),
    Heading(f64),
}

/// Autopilot state in the core.
#[derive(Debug, Clone, Default)]
pub(super) struct Holds {
    pub est: Estimator,
    pub heading: HeadingHold,
    pub depth: DepthHold,
    /// SURFACE has reached SURFACE_DEPTH.
    pub surfaced: bool,
    /// The demand the thrusters were last given (estimator input), down/starboard positive.
    pub applied: Demand,
    /// Autopilot outputs of the last step (None: that axis is the pilot's).
    pub heave_out: Option<f64>,
    pub yaw_out: Option<f64>,
    /// Setpoint messages in a mode that cannot use them, reported at most every 5 s.
    pub ignored_target_report: Option<Duration>,
}

/// POSITION_TARGET_TYPEMASK bits.
const Z_IGNORE: u16 = 4;
const YAW_IGNORE: u16 = 1024;
/// ATTITUDE_TARGET_TYPEMASK: attitude ignored.
const ATTITUDE_IGNORE: u8 = 128;
const TARGET_REPORT: Duration = Duration::from_secs(5);

impl Vehicle {
    /// The estimates now.
    pub fn estimate(&self, now: Now) -> Estimate {
        self.holds.est.estimate(now.mono)
    }

    /// The held depth (m) and heading (deg), where held.
    pub fn targets(&self) -> (Option<f64>, Option<f64>) {
        (
            self.holds.depth.target_m,
            self.holds.heading.target_rad.map(f64::to_degrees),
        )
    }

    /// Feeds a board reading to the estimator; returns what it made of it.
    pub(super) fn estimator_reading(
        &mut self,
        r: Reading,
        now: Now,
        out: &mut Vec<Output>,
    ) -> Fused {
        let fused = match r {
            Reading::Depth(d) => self.holds.est.depth_reading(now.mono, d),
            Reading::Heading(h) => self.holds.est.heading_reading(now.mono, h),
        };
        if let Fused::Relearned = fused {
            self.log(
                "estimator_relearned",
                None,
                format!("{r:?}: measurements kept disagreeing with the prediction; estimate restarted from them"),
                out,
            );
        }
        fused
    }

    fn measured(&self, now: Now) -> Measured {
        let e = self.holds.est.estimate(now.mono);
        Measured {
            depth_m: e.depth_m,
            heave_mps: e.heave_mps,
            heading_rad: e.heading_deg.to_radians(),
            yaw_rate_rps: e.yaw_rate_dps.to_radians(),
        }
    }

    /// One control step (every tick): predicts the estimates with the demand
    /// applied since the last step, then runs the controllers the mode needs.
    pub(super) fn holds_step(&mut self, now: Now, dt: Duration, out: &mut Vec<Output>) {
        let applied = self.holds.applied;
        self.holds.est.predict(now.mono, applied.heave, applied.yaw);
        let dt_s = dt.as_secs_f64().min(0.1);
        if !self.armed || dt_s <= 0.0 {
            self.holds.heave_out = None;
            self.holds.yaw_out = None;
            return;
        }
        let m = self.measured(now);
        let sticks = self.pilot_sticks(now);
        // A filter that has not seen its first reading (after a run-mode
        // switch) estimates nothing: its axis rests until it has, rather than
        // chase the default 0 m / north.
        let depth_known = self.holds.est.depth_filter().initialised();
        let heading_known = self.holds.est.heading_filter().initialised();
        self.holds.yaw_out = if self.mode.holds_heading() && !heading_known {
            Some(0.0)
        } else if self.mode.holds_heading() {
            let g = self.params.heading_gains();
            Some(self.holds.heading.step(&g, &m, sticks.yaw, dt_s))
        } else {
            None
        };
        self.holds.heave_out = match self.mode {
            Mode::AltHold | Mode::Surface if !depth_known => Some(0.0),
            Mode::AltHold => {
                let g = self.params.depth_gains();
                Some(self.holds.depth.step(&g, &m, sticks.heave, dt_s))
            }
            Mode::Surface => {
                // SURFACE_DEPTH is negative below the surface: −0.1 m → 0.1 m deep.
                let surfaced_at_m = -f64::from(self.params.surface_depth_m());
                if !self.holds.surfaced && m.depth_m <= surfaced_at_m {
                    self.holds.surfaced = true;
                    self.statustext(
                        Topic::ApDepth,
                        MavSeverity::MAV_SEVERITY_INFO,
                        "Surfaced",
                        out,
                    );
                    self.log("surfaced", None, format!("depth {:.2} m", m.depth_m), out);
                }
                if self.holds.surfaced {
                    Some(0.0)
                } else {
                    let g = self.params.depth_gains();
                    Some(self.holds.depth.step_surface(&g, &m, dt_s))
                }
            }
            _ => None,
        };
    }

    /// Resets controllers at a mode change, arming or a safety stop.
    pub(super) fn holds_reset(&mut self) {
        self.holds.heading.reset();
        self.holds.depth.reset();
        self.holds.surfaced = false;
        self.holds.heave_out = None;
        self.holds.yaw_out = None;
    }

    /// Why the autopilot `mode` cannot be entered now, if it cannot.
    pub(super) fn hold_unavailable(&self, mode: Mode, now: Now) -> Option<&'static str> {
        let e = self.holds.est.estimate(now.mono);
        if mode.holds_depth() && !e.depth_valid {
            return Some("no depth estimate (no fresh depth from the board)");
        }
        if mode.holds_heading() && !e.heading_valid {
            return Some("no heading estimate (no fresh heading from the board)");
        }
        None
    }

    /// The final demand in an autopilot mode: the pilot's axes scaled by the
    /// gain, the controllers' axes as they are.
    pub(super) fn hold_demand(&self, sticks: Demand) -> Demand {
        let gain = self.pilot.gain.clamp(0.0, 1.0);
        let thr = f64::from(self.params.js_thr_gain());
        Demand {
            surge: sticks.surge * gain,
            heave: self.holds.heave_out.unwrap_or(sticks.heave * gain * thr),
            yaw: self.holds.yaw_out.unwrap_or(sticks.yaw * gain),
        }
    }

    /// The demand three `go()` values really produce through the board's
    /// motor mapping (the estimator's input).
    pub(super) fn effective_demand(&self, go: [u16; 3]) -> Demand {
        mixer::unmix(self.params.board_motors().effective(go), &self.mixer())
    }

    /// SET_POSITION_TARGET_GLOBAL_INT: only `alt` (depth, negative below the
    /// surface) and yaw are used, as ArduSub does in ALT_HOLD.
    pub(super) fn on_position_target(
        &mut self,
        from: Sender,
        t: &SET_POSITION_TARGET_GLOBAL_INT_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let what = "SET_POSITION_TARGET_GLOBAL_INT";
        use MavFrame as F;
        let relative = matches!(
            t.coordinate_frame,
            F::MAV_FRAME_GLOBAL
                | F::MAV_FRAME_GLOBAL_INT
                | F::MAV_FRAME_GLOBAL_RELATIVE_ALT
                | F::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        );
        let mask = t.type_mask.bits();
        let depth =
            (mask & Z_IGNORE == 0 && relative && t.alt.is_finite()).then(|| -f64::from(t.alt));
        let yaw = (mask & YAW_IGNORE == 0 && t.yaw.is_finite()).then(|| f64::from(t.yaw));
        self.apply_targets(from, depth, yaw, what, now, out);
    }

    /// SET_ATTITUDE_TARGET: the heading from the quaternion's yaw.
    pub(super) fn on_attitude_target(
        &mut self,
        from: Sender,
        t: &SET_ATTITUDE_TARGET_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if t.type_mask.bits() & ATTITUDE_IGNORE != 0 {
            return;
        }
        let [w, x, y, z] = t.q.map(f64::from);
        let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
        self.apply_targets(
            from,
            None,
            yaw.is_finite().then_some(yaw),
            "SET_ATTITUDE_TARGET",
            now,
            out,
        );
    }

    /// Depth (m, down positive) and heading (rad) targets from the owner.
    /// A setpoint stream is pilot input: it keeps the input fresh.
    fn apply_targets(
        &mut self,
        from: Sender,
        depth_m: Option<f64>,
        heading_rad: Option<f64>,
        what: &str,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let mut used = false;
        if let Some(d) = depth_m
            && self.mode == Mode::AltHold
        {
            if self
                .holds
                .depth
                .target_m
                .is_none_or(|t| (t - d.max(0.0)).abs() > 1e-3)
            {
                self.log(
                    "autopilot_depth",
                    Some(from.sysid),
                    format!("target {d:.2} m ({what})"),
                    out,
                );
            }
            self.holds.depth.set_target(d);
            used = true;
        }
        if let Some(h) = heading_rad
            && self.mode.holds_heading()
        {
            self.holds.heading.set_target(h);
            used = true;
        }
        if used {
            self.pilot.last_input = Some(now.mono);
        } else if self
            .holds
            .ignored_target_report
            .is_none_or(|t| now.mono.saturating_sub(t) >= TARGET_REPORT)
        {
            self.holds.ignored_target_report = Some(now.mono);
            let topic = if depth_m.is_some() {
                Topic::ApDepth
            } else {
                Topic::ApHeading
            };
            self.statustext(
                topic,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("{what} ignored in {}: depth targets need ALT_HOLD, heading targets STABILIZE or ALT_HOLD", self.mode),
                out,
            );
        }
    }

    /// MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET: p1 depth (m), p2 heading (deg), NaN = unchanged.
    pub(super) fn autopilot_target_command(
        &mut self,
        from: Sender,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        if let Err(why) = self.check_control(from, Control::Command, now, out) {
            return self.refuse_command(from, "autopilot target", why, now, out);
        }
        let depth = super::given(p[0]).map(f64::from);
        let heading = super::given(p[1]).map(f64::from);
        if depth.is_some_and(|d| !(0.0..=1000.0).contains(&d))
            || heading.is_some_and(|h| !(0.0..=360.0).contains(&h))
        {
            return MavResult::MAV_RESULT_DENIED;
        }
        if (depth.is_some() && self.mode != Mode::AltHold)
            || (heading.is_some() && !self.mode.holds_heading())
        {
            let topic = if depth.is_some() {
                Topic::ApDepth
            } else {
                Topic::ApHeading
            };
            self.statustext(
                topic,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!(
                    "Autopilot target refused in {}: depth needs ALT_HOLD, heading STABILIZE or ALT_HOLD",
                    self.mode
                ),
                out,
            );
            return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
        }
        if let Some(d) = depth {
            self.holds.depth.set_target(d);
            self.log(
                "autopilot_depth",
                Some(from.sysid),
                format!("target {d:.2} m (command)"),
                out,
            );
        }
        if let Some(h) = heading {
            self.holds.heading.set_target(h.to_radians());
            self.log(
                "autopilot_heading",
                Some(from.sysid),
                format!("target {h:.1} deg (command)"),
                out,
            );
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// NAV_CONTROLLER_OUTPUT, NEPTUNUS_ESTIMATE or NEPTUNUS_AUTOPILOT.
    pub(super) fn build_holds(&self, id: u32, now: Now) -> Option<MavMessage> {
        let boot_ms = self.boot_ms(now);
        let e = self.holds.est.estimate(now.mono);
        let nan = f32::NAN;
        match id {
            NAV_CONTROLLER_OUTPUT_DATA::ID => {
                let heading_target = self.holds.heading.target_rad.map(f64::to_degrees);
                let bearing = heading_target.unwrap_or(e.heading_deg);
                let depth_error = self.holds.depth.target_m.map_or(0.0, |t| t - e.depth_m);
                Some(MavMessage::NAV_CONTROLLER_OUTPUT(
                    NAV_CONTROLLER_OUTPUT_DATA {
                        nav_roll: 0.0,
                        nav_pitch: 0.0,
                        // Altitude error is target minus current altitude: depth down, altitude up.
                        alt_error: -depth_error as f32,
                        aspd_error: 0.0,
                        xtrack_error: 0.0,
                        nav_bearing: (bearing.round() as i64).rem_euclid(360) as i16,
                        target_bearing: (bearing.round() as i64).rem_euclid(360) as i16,
                        wp_dist: 0,
                    },
                ))
            }
            NEPTUNUS_ESTIMATE_DATA::ID
                if self.holds.est.depth_filter().initialised()
                    || self.holds.est.heading_filter().initialised() =>
            {
                let mut flags = NeptunusEstimateFlags::empty();
                if self.run_mode == RunMode::Simulator {
                    flags |= NeptunusEstimateFlags::NEPTUNUS_ESTIMATE_FLAGS_SIMULATED;
                }
                if e.depth_valid {
                    flags |= NeptunusEstimateFlags::NEPTUNUS_ESTIMATE_FLAGS_DEPTH_VALID;
                }
                if e.heading_valid {
                    flags |= NeptunusEstimateFlags::NEPTUNUS_ESTIMATE_FLAGS_HEADING_VALID;
                }
                let est = &self.holds.est;
                Some(MavMessage::NEPTUNUS_ESTIMATE(NEPTUNUS_ESTIMATE_DATA {
                    time_boot_ms: boot_ms,
                    depth_measured: est.depth_measured_m.map_or(nan, |v| v as f32),
                    depth: e.depth_m as f32,
                    climb_rate: -e.heave_mps as f32,
                    depth_std: e.depth_std_m as f32,
                    heading_measured: est.heading_measured_deg.map_or(nan, |v| v as f32),
                    heading: e.heading_deg as f32,
                    yaw_rate: e.yaw_rate_dps as f32,
                    heading_std: e.heading_std_deg as f32,
                    depth_rejected: e.depth_rejected.min(u64::from(u32::MAX)) as u32,
                    heading_rejected: e.heading_rejected.min(u64::from(u32::MAX)) as u32,
                    flags,
                }))
            }
            NEPTUNUS_AUTOPILOT_DATA::ID => {
                let mut flags = NeptunusAutopilotFlags::empty();
                if self.holds.heave_out.is_some() && self.mode == Mode::AltHold {
                    flags |= NeptunusAutopilotFlags::NEPTUNUS_AUTOPILOT_FLAGS_DEPTH_HOLD;
                }
                if self.holds.yaw_out.is_some() {
                    flags |= NeptunusAutopilotFlags::NEPTUNUS_AUTOPILOT_FLAGS_HEADING_HOLD;
                }
                if self.mode == Mode::Surface && self.armed && !self.holds.surfaced {
                    flags |= NeptunusAutopilotFlags::NEPTUNUS_AUTOPILOT_FLAGS_SURFACING;
                }
                let h = &self.holds;
                Some(MavMessage::NEPTUNUS_AUTOPILOT(NEPTUNUS_AUTOPILOT_DATA {
                    time_boot_ms: boot_ms,
                    depth_target: h.depth.target_m.map_or(nan, |v| v as f32),
                    climb_target: if h.heave_out.is_some() {
                        -h.depth.heave_target_mps as f32
                    } else {
                        0.0
                    },
                    heading_target: h.heading.target_rad.map_or(nan, |v| v.to_degrees() as f32),
                    yaw_rate_target: if h.yaw_out.is_some() {
                        h.heading.rate_target_rps.to_degrees() as f32
                    } else {
                        0.0
                    },
                    heave_output: h.heave_out.unwrap_or(0.0) as f32,
                    yaw_output: h.yaw_out.unwrap_or(0.0) as f32,
                    flags,
                }))
            }
            _ => None,
        }
    }
}

impl Vehicle {
    /// The normalised demand the thrusters were last given.
    pub fn applied_demand(&self) -> Demand {
        self.holds.applied
    }

    /// The last depth the board reported (m).
    pub fn raw_depth_m(&self) -> Option<f64> {
        self.holds.est.depth_measured_m
    }

    /// The last heading the board reported (deg).
    pub fn raw_heading_deg(&self) -> Option<f64> {
        self.holds.est.heading_measured_deg
    }
}
