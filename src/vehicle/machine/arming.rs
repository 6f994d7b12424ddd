//! Arming and disarming, and the pre-arm checks: arming starts from
//! neutral, disarming is always possible, and every refusal says why.

use super::texts::Topic;
use super::{Now, Output, Vehicle};
use crate::dialect::neptunus::*;
use crate::firmware::link::LinkState;

impl Vehicle {
    pub(super) fn battery_ok(&self, now: Now) -> bool {
        let low = f64::from(self.params.batt_low_volt());
        self.fresh(&self.board.vout_v, now) && (low <= 0.0 || self.board.vout_v.value > low)
    }

    /// Why the vehicle cannot arm, if it cannot.
    pub fn prearm_failure(&self, now: Now) -> Option<String> {
        if self.board.link != LinkState::Up {
            return Some(format!(
                "board link down ({})",
                self.board
                    .link_reason
                    .clone()
                    .unwrap_or_else(|| "no telemetry".into())
            ));
        }
        if !self.fresh(&self.board.heading_deg, now) {
            return Some("no fresh attitude from the board".into());
        }
        // A depth is needed only by the modes that hold one (as in ArduSub):
        // the basic OpenROV kit has no depth sensor and drives in MANUAL.
        if let Some(why) = self.hold_unavailable(self.mode, now) {
            return Some(format!("{} needs it: {why}", self.mode.name()));
        }
        if !self.fresh(&self.board.vout_v, now) {
            return Some("no fresh battery voltage from the board".into());
        }
        if !self.battery_ok(now) {
            return Some(format!(
                "battery below BATT_LOW_VOLT {:.1} V",
                self.params.batt_low_volt()
            ));
        }
        if !self.params.some_button_disarms() {
            return Some("no joystick button is mapped to disarm (BTNn_FUNCTION 2 or 4)".into());
        }
        None
    }

    pub(super) fn arm(
        &mut self,
        force: bool,
        by: Option<u8>,
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        if self.armed {
            return MavResult::MAV_RESULT_ACCEPTED;
        }
        if self.board.link != LinkState::Up {
            let why = self
                .prearm_failure(now)
                .unwrap_or_else(|| "board link down".into());
            self.statustext(
                Topic::Stop,
                MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("Arm: {why}"),
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        if !force && let Some(why) = self.prearm_failure(now) {
            self.statustext(
                Topic::Stop,
                MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("PreArm: {why}"),
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        self.armed = true;
        self.armed_at = Some(now.mono);
        // Arming starts from neutral: sticks sent while disarmed do not move
        // the vehicle the instant it arms.
        self.stop_pilot();
        self.holds_reset();
        self.send_neutral(out);
        self.statustext(Topic::Stop, MavSeverity::MAV_SEVERITY_INFO, "Armed", out);
        self.log(
            "armed",
            by,
            if force {
                "forced"
            } else {
                "pre-arm checks passed"
            }
            .into(),
            out,
        );
        MavResult::MAV_RESULT_ACCEPTED
    }

    pub(super) fn disarm(&mut self, why: &str, by: Option<u8>, out: &mut Vec<Output>) -> MavResult {
        self.pilot.hold = None;
        self.stop_pilot();
        if self.armed {
            self.armed = false;
            self.statustext(
                Topic::Stop,
                MavSeverity::MAV_SEVERITY_INFO,
                &format!("Disarmed ({why})"),
                out,
            );
            self.log("disarmed", by, why.to_owned(), out);
        }
        self.send_neutral(out);
        MavResult::MAV_RESULT_ACCEPTED
    }
}
