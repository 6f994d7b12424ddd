//! Handover: MAV_CMD_REQUEST_OPERATOR_CONTROL (take, request, release)
//! and the owner's answer to a forwarded request (its COMMAND_ACK). The
//! rules of who holds control and what a change of owner does live in
//! `authority.rs`.

use std::time::Duration;

use super::authority::{DEFAULT_REQUEST_TIMEOUT_S, Grant, Pending, Refusal, Station};
use super::texts::ReplyKind;
use super::texts::Topic;
use super::{Now, Output, Sender, Vehicle, given};
use crate::dialect::neptunus::*;

impl Vehicle {
    /// MAV_CMD_REQUEST_OPERATOR_CONTROL (32100): p1 0 release / 1 request,
    /// p2 allow takeover, p3 request timeout s (3..60), p4 requesting sysid.
    pub(super) fn operator_control(
        &mut self,
        from: Sender,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        if self.signing_active && !from.signed {
            return self.refuse_command(from, "control request", Refusal::Unsigned, now, out);
        }
        if let Some(id) = given(p[3])
            && id != 0.0
            && (id.round() - f32::from(from.sysid)).abs() > 0.5
        {
            self.reply_text(
                from,
                ReplyKind::Control,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!(
                    "Control request from sysid {} names sysid {id}: a station requests for itself",
                    from.sysid
                ),
                now,
                out,
            );
            return MavResult::MAV_RESULT_DENIED;
        }
        let takeover = given(p[1]).is_some_and(|v| v >= 0.5);
        let timeout_s = given(p[2])
            .filter(|t| t.is_finite() && *t > 0.0)
            .map_or(DEFAULT_REQUEST_TIMEOUT_S, |t| t.clamp(3.0, 60.0));
        let me = Station::of(from);
        match given(p[0]).map(|a| a.round() as i64) {
            Some(0) => {
                if self.owner() == Some(from.sysid) {
                    self.drop_owner("control_released", "released", now, out);
                } else if self
                    .auth
                    .pending
                    .is_some_and(|p| p.from.sysid == from.sysid)
                {
                    self.auth.pending = None;
                    self.log(
                        "control_refused",
                        Some(from.sysid),
                        "request withdrawn by the requester".into(),
                        out,
                    );
                }
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(1) => {
                if !self.allowed(from) {
                    let text = format!(
                        "Control request from sysid {} refused: {}",
                        from.sysid,
                        Refusal::NotAllowed.reason()
                    );
                    if self.reply_text(
                        from,
                        ReplyKind::Control,
                        MavSeverity::MAV_SEVERITY_WARNING,
                        &text,
                        now,
                        out,
                    ) {
                        self.log("control_refused", Some(from.sysid), text, out);
                    }
                    return MavResult::MAV_RESULT_DENIED;
                }
                self.log(
                    "control_requested",
                    Some(from.sysid),
                    format!("takeover allowed {takeover}, timeout {timeout_s} s"),
                    out,
                );
                match self.auth.owner {
                    None => {
                        self.grant(me, Grant::Request, takeover, now, out);
                        MavResult::MAV_RESULT_ACCEPTED
                    }
                    Some(o) if o.sysid == from.sysid => {
                        self.set_takeover_allowed(takeover, out);
                        // Re-requesting with takeover allowed is the owner's yes.
                        if takeover && let Some(p) = self.auth.pending.take() {
                            self.grant(p.from, Grant::Handover, false, now, out);
                        }
                        MavResult::MAV_RESULT_ACCEPTED
                    }
                    Some(_) if self.auth.takeover_allowed => {
                        self.grant(me, Grant::Request, takeover, now, out);
                        MavResult::MAV_RESULT_ACCEPTED
                    }
                    Some(o) if from.sysid == self.params.sysid_mygcs() => {
                        // DNV practice: the main station takes control without
                        // acknowledgement, after a warning.
                        self.statustext(
                            Topic::Control,
                            MavSeverity::MAV_SEVERITY_WARNING,
                            &format!(
                                "Control taken over by primary GCS {} from GCS {}",
                                from.sysid, o.sysid
                            ),
                            out,
                        );
                        self.grant(me, Grant::PrimaryTakeover, takeover, now, out);
                        MavResult::MAV_RESULT_ACCEPTED
                    }
                    Some(o) => {
                        self.auth.pending = Some(Pending {
                            from: me,
                            deadline: now.mono + Duration::from_secs_f32(timeout_s),
                            last_life: now.mono,
                        });
                        out.push(Output::Send {
                            to: o.reply,
                            msg: MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                                param1: 1.0,
                                param2: 0.0,
                                param3: timeout_s,
                                param4: f32::from(from.sysid),
                                param5: 0.0,
                                param6: 0.0,
                                param7: 0.0,
                                command: MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
                                target_system: o.sysid,
                                target_component: o.compid,
                                confirmation: 0,
                            }),
                        });
                        self.statustext(
                Topic::Control,
                            MavSeverity::MAV_SEVERITY_WARNING,
                            &format!(
                                "GCS {} requests control from GCS {} (answer within {timeout_s:.0} s)",
                                from.sysid, o.sysid
                            ),
                            out,
                        );
                        self.log(
                            "control_forwarded",
                            Some(from.sysid),
                            format!("asked GCS {}", o.sysid),
                            out,
                        );
                        MavResult::MAV_RESULT_FAILED
                    }
                }
            }
            _ => MavResult::MAV_RESULT_DENIED,
        }
    }

    fn set_takeover_allowed(&mut self, allowed: bool, out: &mut Vec<Output>) {
        if self.auth.takeover_allowed != allowed {
            self.auth.takeover_allowed = allowed;
            self.send_control_status(out);
        }
    }

    /// A COMMAND_ACK from a ground station: the owner's answer to a forwarded request.
    pub(super) fn on_gcs_ack(
        &mut self,
        from: Sender,
        ack: &COMMAND_ACK_DATA,
        out: &mut Vec<Output>,
    ) {
        if ack.command != MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL
            || self.owner() != Some(from.sysid)
            || (self.signing_active && !from.signed)
        {
            return;
        }
        let Some(p) = self.auth.pending else {
            return;
        };
        use MavResult as R;
        match ack.result {
            R::MAV_RESULT_DENIED | R::MAV_RESULT_FAILED | R::MAV_RESULT_TEMPORARILY_REJECTED => {
                self.auth.pending = None;
                let text = format!(
                    "Control request from GCS {} refused by GCS {}",
                    p.from.sysid, from.sysid
                );
                self.statustext(
                    Topic::Control,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &text,
                    out,
                );
                self.log("control_refused", Some(p.from.sysid), text, out);
            }
            _ => {}
        }
    }
}
