//! The run mode: the real board, or the built-in simulator standing in for
//! it (the board then stays stopped). A switch is a safety-mode stop.

use super::authority::Control;
use super::texts::Topic;
use super::{Now, Output, Sender, Vehicle, given};
use crate::dialect::neptunus::*;
use crate::firmware::codec::Command;
use crate::vehicle::estimator::Estimator;

/// Where thruster commands go and telemetry comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RunMode {
    /// The board drives the thrusters and reports the vehicle.
    #[default]
    Normal,
    /// The board is stopped; the built-in simulator gets the thruster
    /// commands and its telemetry stands in for the board's.
    Simulator,
}

impl Vehicle {
    /// MAV_CMD_NEPTUNUS_SET_RUN_MODE: a safety-mode stop, then the switch.
    pub(super) fn run_mode_command(
        &mut self,
        from: Sender,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        if let Err(why) = self.check_control(from, Control::Command, now, out) {
            return self.refuse_command(from, "run mode change", why, now, out);
        }
        let mode = match given(p[0]).map(|v| v.round() as i64) {
            Some(0) => RunMode::Normal,
            Some(1) => RunMode::Simulator,
            _ => return MavResult::MAV_RESULT_DENIED,
        };
        self.set_run_mode(mode, Some(from.sysid), now, out);
        MavResult::MAV_RESULT_ACCEPTED
    }

    pub(super) fn set_run_mode(
        &mut self,
        mode: RunMode,
        by: Option<u8>,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if mode == self.run_mode {
            return;
        }
        let old = self.run_mode;
        // The pilot's setpoints are the pilot's, not the source's: they
        // survive the switch (the controllers and the estimates do not).
        let (depth_target, heading_target) =
            (self.holds.depth.target_m, self.holds.heading.target_rad);
        // Both the board and the simulator get neutral before anything moves on.
        self.safety_stop(true, out);
        out.push(Output::SimBoard(super::NEUTRAL_GO));
        self.run_mode = mode;
        let e = self.holds.est.estimate(now.mono);
        match mode {
            RunMode::Simulator => {
                // The real thrusters stay stopped while the simulator flies.
                out.push(Output::Board(Command::Stop));
                out.push(Output::RunMode {
                    mode,
                    start_depth_m: e.depth_m.max(0.0),
                    start_heading_deg: e.heading_deg,
                });
                self.statustext(
                    Topic::Stop,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "Run mode SIMULATOR: telemetry is simulated, the thrusters are stopped",
                    out,
                );
            }
            RunMode::Normal => {
                out.push(Output::RunMode {
                    mode,
                    start_depth_m: e.depth_m,
                    start_heading_deg: e.heading_deg,
                });
                self.statustext(
                    Topic::Stop,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "Run mode NORMAL: real vehicle",
                    out,
                );
            }
        }
        // The other source's estimates are not this one's.
        self.holds.est = Estimator::default();
        self.holds_reset();
        self.holds.depth.target_m = depth_target;
        self.holds.heading.target_rad = heading_target;
        let kept: Vec<String> = depth_target
            .map(|d| format!("depth {d:.2} m"))
            .into_iter()
            .chain(heading_target.map(|h| format!("heading {:.0}°", h.to_degrees())))
            .collect();
        if !kept.is_empty() {
            let topic = if depth_target.is_some() {
                Topic::ApDepth
            } else {
                Topic::ApHeading
            };
            self.statustext(
                topic,
                MavSeverity::MAV_SEVERITY_INFO,
                &format!("Setpoints kept: {}", kept.join(", ")),
                out,
            );
        }
        self.log("run_mode", by, format!("{old:?} -> {mode:?}"), out);
    }

    /// Where thruster commands go and telemetry comes from now.
    pub fn run_mode(&self) -> RunMode {
        self.run_mode
    }
}
