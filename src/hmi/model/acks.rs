//! A COMMAND_ACK in the operator's words: what the command was for and
//! how it went ("Arm/disarm: refused", "Lights: done").
//!
//! Also what a forwarded control request becomes: not a failure but
//! `request_pending`. Which acks reach a session is decided in `mod.rs`.

use super::{ControlAsk, Model};
use crate::dialect::neptunus::{COMMAND_ACK_DATA, MavCmd, MavResult};
use crate::hmi::protocol::ServerMsg;

impl Model {
    /// This session's COMMAND_ACK, in words; a control request the vehicle
    /// passed to the owner becomes `request_pending`.
    pub(super) fn on_ack(&mut self, a: &COMMAND_ACK_DATA) -> ServerMsg {
        let mut what = command_words(a.command);
        if a.command == MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL {
            match self.asks.pop_front() {
                // The core's rule (vehicle/machine/handover.rs): a request
                // while another station owns the vehicle, takeover not
                // allowed, is forwarded to the owner and acked FAILED, as
                // MAVLink's operator-control protocol says. Every other
                // outcome of a request is ACCEPTED or DENIED.
                Some(ControlAsk::Request { timeout_s })
                    if a.result == MavResult::MAV_RESULT_FAILED =>
                {
                    if let Some(owner) = self.tel.control.owner
                        && Some(owner) != self.me
                    {
                        return ServerMsg::RequestPending { owner, timeout_s };
                    }
                }
                Some(ControlAsk::Release) => what = "Control release".to_owned(),
                _ => {}
            }
        }
        ServerMsg::Ack {
            command: a.command as u32,
            command_name: short_name(a.command, "MAV_CMD_"),
            result: a.result as u32,
            result_name: short_name(a.result, "MAV_RESULT_"),
            text: ack_text(&what, a.result),
        }
    }
}

/// What a command the HMI sends is for, as the operator knows it; any other
/// command by its MAVLink name in words ("Request message").
pub(super) fn command_words(cmd: MavCmd) -> String {
    use MavCmd as C;
    #[allow(deprecated)]
    let words = match cmd {
        C::MAV_CMD_COMPONENT_ARM_DISARM => "Arm/disarm",
        C::MAV_CMD_DO_SET_MODE => "Mode change",
        C::MAV_CMD_REQUEST_OPERATOR_CONTROL => "Control request",
        C::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET => "Autopilot setpoint",
        C::MAV_CMD_NEPTUNUS_SET_RUN_MODE => "Run mode change",
        C::MAV_CMD_DO_MOUNT_CONTROL => "Camera tilt",
        C::MAV_CMD_DO_ILLUMINATOR_CONFIGURE => "Lights",
        C::MAV_CMD_DO_SET_SERVO => "Laser",
        C::MAV_CMD_VIDEO_START_CAPTURE => "Recording on the vehicle",
        C::MAV_CMD_VIDEO_STOP_CAPTURE => "Stopping the recording",
        other => return name_words(&format!("{other:?}"), "MAV_CMD_"),
    };
    words.to_owned()
}

/// How a command went, in words.
pub(super) fn result_words(result: MavResult) -> String {
    use MavResult as R;
    let words = match result {
        R::MAV_RESULT_ACCEPTED => "done",
        R::MAV_RESULT_DENIED => "refused",
        R::MAV_RESULT_TEMPORARILY_REJECTED => "refused for now",
        R::MAV_RESULT_FAILED => "failed",
        R::MAV_RESULT_UNSUPPORTED => "not supported",
        R::MAV_RESULT_IN_PROGRESS => "in progress",
        R::MAV_RESULT_CANCELLED => "cancelled",
        R::MAV_RESULT_NOT_IN_CONTROL => "refused: not in control",
        other => return name_words(&format!("{other:?}"), "MAV_RESULT_").to_lowercase(),
    };
    words.to_owned()
}

/// "MAV_CMD_REQUEST_MESSAGE" → "Request message".
fn name_words(name: &str, prefix: &str) -> String {
    let words = name
        .trim_start_matches(prefix)
        .replace('_', " ")
        .to_lowercase();
    let mut chars = words.chars();
    match chars.next() {
        Some(first) => first.to_uppercase().chain(chars).collect(),
        None => words,
    }
}

/// The whole sentence: "Mode change: refused".
pub(super) fn ack_text(what: &str, result: MavResult) -> String {
    format!("{what}: {}", result_words(result))
}

/// MAVLink's name without its prefix, as the protocol's `*_name` fields carry it.
pub(super) fn short_name<T: std::fmt::Debug>(v: T, prefix: &str) -> String {
    format!("{v:?}").trim_start_matches(prefix).to_owned()
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use super::*;
    use crate::dialect::neptunus::*;

    #[test]
    fn the_hmis_commands_in_the_operators_words() {
        #[allow(deprecated)]
        let table = [
            (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, "Arm/disarm"),
            (MavCmd::MAV_CMD_DO_SET_MODE, "Mode change"),
            (MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL, "Control request"),
            (
                MavCmd::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET,
                "Autopilot setpoint",
            ),
            (MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE, "Run mode change"),
            (MavCmd::MAV_CMD_DO_MOUNT_CONTROL, "Camera tilt"),
            (MavCmd::MAV_CMD_DO_ILLUMINATOR_CONFIGURE, "Lights"),
            (MavCmd::MAV_CMD_DO_SET_SERVO, "Laser"),
            (MavCmd::MAV_CMD_REQUEST_MESSAGE, "Request message"),
        ];
        for (cmd, words) in table {
            assert_eq!(command_words(cmd), words, "{cmd:?}");
        }
    }

    #[test]
    fn results_in_words() {
        use MavResult as R;
        for (r, words) in [
            (R::MAV_RESULT_ACCEPTED, "done"),
            (R::MAV_RESULT_DENIED, "refused"),
            (R::MAV_RESULT_TEMPORARILY_REJECTED, "refused for now"),
            (R::MAV_RESULT_FAILED, "failed"),
            (R::MAV_RESULT_UNSUPPORTED, "not supported"),
            (R::MAV_RESULT_IN_PROGRESS, "in progress"),
            (R::MAV_RESULT_CANCELLED, "cancelled"),
            (R::MAV_RESULT_NOT_IN_CONTROL, "refused: not in control"),
            (R::MAV_RESULT_COMMAND_INT_ONLY, "command int only"),
        ] {
            assert_eq!(result_words(r), words, "{r:?}");
        }
        assert_eq!(
            ack_text("Arm/disarm", R::MAV_RESULT_DENIED),
            "Arm/disarm: refused"
        );
        assert_eq!(
            short_name(R::MAV_RESULT_TEMPORARILY_REJECTED, "MAV_RESULT_"),
            "TEMPORARILY_REJECTED"
        );
    }

    fn ack(cmd: MavCmd, result: MavResult, to: u8) -> MavMessage {
        MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: cmd,
            result,
            progress: 0,
            result_param2: 0,
            target_system: to,
            target_component: 190,
        })
    }

    fn owned_by(m: &mut Model, owner: u8, now: Instant) {
        m.on_message(
            &MavMessage::CONTROL_STATUS(CONTROL_STATUS_DATA {
                flags: GcsControlStatusFlags::GCS_CONTROL_STATUS_FLAGS_SYSTEM_MANAGER,
                gcs_main: owner,
                gcs_secondary: [0; 10],
            }),
            now,
            &mut Vec::new(),
        );
    }

    #[test]
    fn acks_in_words_and_a_forwarded_request_is_pending() {
        let now = Instant::now();
        let mut m = Model::new(Some(201), now);
        let mut ev = Vec::new();
        let c = MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL;
        m.on_message(
            &ack(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                MavResult::MAV_RESULT_DENIED,
                201,
            ),
            now,
            &mut ev,
        );
        // Another station's ack is not this session's business.
        m.on_message(
            &ack(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                MavResult::MAV_RESULT_ACCEPTED,
                200,
            ),
            now,
            &mut ev,
        );
        assert_eq!(
            ev,
            [ServerMsg::Ack {
                command: 400,
                command_name: "COMPONENT_ARM_DISARM".into(),
                result: 2,
                result_name: "DENIED".into(),
                text: "Arm/disarm: refused".into(),
            }]
        );
        ev.clear();
        // GCS 200 owns the vehicle: the vehicle forwards our request and acks FAILED.
        owned_by(&mut m, 200, now);
        m.asked_control(ControlAsk::Request { timeout_s: 10.0 });
        m.on_message(&ack(c, MavResult::MAV_RESULT_FAILED, 201), now, &mut ev);
        assert_eq!(
            ev,
            [ServerMsg::RequestPending {
                owner: 200,
                timeout_s: 10.0
            }]
        );
        assert_eq!(
            ev[0].to_json(),
            r#"{"type":"request_pending","owner":200,"timeout_s":10.0}"#
        );
        ev.clear();
        // Refused outright (not an allowed station): an ack in words.
        m.asked_control(ControlAsk::Request { timeout_s: 10.0 });
        m.on_message(&ack(c, MavResult::MAV_RESULT_DENIED, 201), now, &mut ev);
        // Granted, then released.
        m.asked_control(ControlAsk::Request { timeout_s: 10.0 });
        m.on_message(&ack(c, MavResult::MAV_RESULT_ACCEPTED, 201), now, &mut ev);
        owned_by(&mut m, 201, now);
        m.asked_control(ControlAsk::Release);
        m.on_message(&ack(c, MavResult::MAV_RESULT_ACCEPTED, 201), now, &mut ev);
        // A FAILED ack with nobody else in control is not a pending request.
        m.asked_control(ControlAsk::Request { timeout_s: 10.0 });
        m.on_message(&ack(c, MavResult::MAV_RESULT_FAILED, 201), now, &mut ev);
        let texts: Vec<&str> = ev
            .iter()
            .filter_map(|e| match e {
                ServerMsg::Ack { text, .. } => Some(text.as_str()),
                ServerMsg::Control(_) => None,
                other => panic!("unexpected {other:?}"),
            })
            .collect();
        assert_eq!(
            texts,
            [
                "Control request: refused",
                "Control request: done",
                "Control release: done",
                "Control request: failed"
            ]
        );
    }
}
