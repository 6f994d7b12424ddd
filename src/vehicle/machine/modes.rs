//! The flight mode: changing it (MAV_CMD_DO_SET_MODE, the SET_MODE
//! message, mode buttons) and listing the modes (AVAILABLE_MODES). What a
//! mode is — its number, name, whether Neptunus honours it — lives in
//! [`crate::vehicle::mode::Mode`]; what it does lives with its concern
//! (`driving.rs`, `holds.rs`).

use super::authority::Control;
use super::texts::Topic;
use super::{Mode, Now, Output, Sender, Vehicle, chars};
use crate::dialect::neptunus::*;

impl Vehicle {
    /// A mode change asked by `from`: the authority check, then [`Self::set_mode`].
    pub(super) fn set_mode_by(
        &mut self,
        from: Sender,
        mode: u32,
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        match self.check_control(from, Control::Command, now, out) {
            Ok(()) => self.set_mode(mode, Some(from.sysid), now, out),
            Err(why) => self.refuse_command(from, "mode change", why, now, out),
        }
    }

    pub(super) fn set_mode(
        &mut self,
        mode: u32,
        by: Option<u8>,
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        let Some(m) = Mode::from_number(mode) else {
            self.statustext(
                Topic::Stop,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Mode {mode} does not exist"),
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        };
        if let Some(why) = m.refused() {
            self.statustext(
                Topic::Stop,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Mode {m} refused: {why}"),
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        if self.mode != m {
            if let Some(why) = self.hold_unavailable(m, now) {
                self.statustext(
                    Topic::Stop,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("Mode {m} refused: {why}"),
                    out,
                );
                return MavResult::MAV_RESULT_FAILED;
            }
            let old = self.mode;
            self.mode = m;
            // A mode change is a safety-mode stop.
            self.stop_pilot();
            self.holds_reset();
            self.send_neutral(out);
            self.statustext(
                Topic::Stop,
                MavSeverity::MAV_SEVERITY_INFO,
                &format!("Mode {m}"),
                out,
            );
            self.log("mode", by, format!("{old} -> {m}"), out);
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    pub(super) fn available_modes(&self, index: u32) -> Vec<MavMessage> {
        let n = Mode::ALL.len() as u8;
        Mode::ALL
            .iter()
            .enumerate()
            .filter(|(i, _)| index == 0 || *i as u32 + 1 == index)
            .map(|(i, m)| {
                MavMessage::AVAILABLE_MODES(AVAILABLE_MODES_DATA {
                    custom_mode: m.number(),
                    properties: if m.refused().is_some() {
                        MavModeProperty::MAV_MODE_PROPERTY_NOT_USER_SELECTABLE
                    } else {
                        MavModeProperty::empty()
                    },
                    number_modes: n,
                    mode_index: i as u8 + 1,
                    standard_mode: MavStandardMode::MAV_STANDARD_MODE_NON_STANDARD,
                    mode_name: chars(m.name()),
                })
            })
            .collect()
    }
}
