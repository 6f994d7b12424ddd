//! What the browser sends: its JSON messages turned into actions.
//!
//! Owns the dispatch of each [`ClientMsg`] (refusing a watcher's input,
//! at most now and then for streamed input) and the count of malformed
//! messages. The MAVLink itself is built in `vehicle`.

use std::time::Instant;

use super::{REFUSAL_REPLY, REQUEST_TIMEOUT_S, Session};
use crate::dialect::neptunus::*;
use crate::hmi::model::ControlAsk;
use crate::hmi::protocol::{ClientMsg, RunMode, ServerMsg};
use crate::vehicle::machine::{CAMERA_COMPONENT_ID, COMPONENT_ID, HmiEvent};

impl Session {
    pub(super) fn bad_message(&mut self, why: &str) -> Option<ServerMsg> {
        self.bad += 1;
        self.shared.note_bad_message(self.id, why);
        Some(ServerMsg::Error {
            message: why.to_owned(),
        })
    }

    pub(super) async fn on_text(&mut self, text: &str) -> Option<ServerMsg> {
        let msg = match ClientMsg::parse(text) {
            Ok(m) => m,
            Err(why) => return self.bad_message(&why),
        };
        self.last_life = Instant::now();
        // Messages that only matter from a station with an id: without one
        // they are no-ops (a watcher's page says input_mode at start).
        let harmless = matches!(
            msg,
            ClientMsg::Alive {}
                | ClientMsg::Login { .. }
                | ClientMsg::Stop {}
                | ClientMsg::FocusLost {}
                | ClientMsg::InputMode { .. }
                | ClientMsg::ReleaseControl {}
        );
        if !harmless && self.ensure_sysid().is_none() {
            // Streamed input is answered now and then, not per message: a
            // watcher's held key would otherwise earn 20 errors a second.
            let streamed = matches!(
                msg,
                ClientMsg::Sticks { .. } | ClientMsg::Thrusters { .. } | ClientMsg::Tilt { .. }
            );
            if streamed
                && self
                    .last_refusal
                    .is_some_and(|t| t.elapsed() < REFUSAL_REPLY)
            {
                return None;
            }
            self.last_refusal = Some(Instant::now());
            let why = self
                .watch_only_reason()
                .unwrap_or_else(|| "no system id is free".into());
            return Some(ServerMsg::Error {
                message: format!("this session may only watch: {why}"),
            });
        }
        match msg {
            ClientMsg::Alive {} => {}
            ClientMsg::Login { password } => return Some(self.login(&password).await),
            ClientMsg::Sticks {
                surge,
                sway,
                heave_up,
                yaw,
            } => {
                self.to_vehicle(self.manual_control(surge, sway, heave_up, yaw))
                    .await
            }
            ClientMsg::Thrusters {
                port,
                vertical,
                starboard,
            } => {
                self.to_vehicle(self.thrusters(port, vertical, starboard))
                    .await
            }
            ClientMsg::Stop {} => self.stop().await,
            ClientMsg::FocusLost {} => {
                self.stop().await;
                self.hmi_event(HmiEvent::FocusLost).await;
            }
            ClientMsg::InputMode { .. } => {
                self.stop().await;
                self.hmi_event(HmiEvent::InputModeChanged).await;
            }
            ClientMsg::Arm { arm } => {
                self.command(
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                    [if arm { 1.0 } else { 0.0 }],
                )
                .await
            }
            ClientMsg::Mode { mode } => {
                self.command(MavCmd::MAV_CMD_DO_SET_MODE, [1.0, mode as f32])
                    .await
            }
            ClientMsg::RunMode { mode } => {
                let m = match mode {
                    RunMode::Normal => 0.0,
                    RunMode::Simulator => 1.0,
                };
                self.command(MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE, [m])
                    .await
            }
            ClientMsg::AutopilotTarget {
                depth_m,
                heading_deg,
            } => {
                let p = |v: Option<f64>| v.map_or(f32::NAN, |v| v as f32);
                self.command(
                    MavCmd::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET,
                    [p(depth_m), p(heading_deg)],
                )
                .await
            }
            ClientMsg::Gain { value } => {
                self.to_vehicle(MavMessage::PARAM_SET(PARAM_SET_DATA {
                    param_value: value as f32,
                    target_system: self.shared.vehicle_sysid,
                    target_component: COMPONENT_ID,
                    param_id: "JS_GAIN_DEFAULT".into(),
                    param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
                }))
                .await
            }
            ClientMsg::Lights { level } => {
                let pct = (level / 255.0 * 100.0) as f32;
                self.command(MavCmd::MAV_CMD_DO_ILLUMINATOR_CONFIGURE, [0.0, pct])
                    .await
            }
            ClientMsg::Laser { on } => {
                // Output 6 is the laser (SERVO6_FUNCTION 60).
                let pwm = if on { 1900.0 } else { 1100.0 };
                self.command(MavCmd::MAV_CMD_DO_SET_SERVO, [6.0, pwm]).await
            }
            ClientMsg::Record { on } => {
                let cmd = if on {
                    MavCmd::MAV_CMD_VIDEO_START_CAPTURE
                } else {
                    MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE
                };
                // To the camera component, like any station's record button:
                // stream 0 (all), CAMERA_CAPTURE_STATUS at its default rate.
                self.command_to(CAMERA_COMPONENT_ID, cmd, [0.0, 0.0]).await
            }
            ClientMsg::Tilt { deg } => {
                // The core takes the legacy MOUNT_CONTROL (centidegrees), as ArduSub does.
                #[allow(deprecated)]
                self.command(MavCmd::MAV_CMD_DO_MOUNT_CONTROL, [(deg * 100.0) as f32])
                    .await
            }
            ClientMsg::RequestControl { takeover_allowed } => {
                let p2 = if takeover_allowed { 1.0 } else { 0.0 };
                self.model.asked_control(ControlAsk::Request {
                    timeout_s: REQUEST_TIMEOUT_S,
                });
                self.command(
                    MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
                    [1.0, p2, REQUEST_TIMEOUT_S],
                )
                .await
            }
            ClientMsg::ReleaseControl {} => {
                // A watcher has nothing to release and sends nothing.
                self.sysid()?;
                self.model.asked_control(ControlAsk::Release);
                self.command(MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL, [0.0])
                    .await
            }
            ClientMsg::AnswerRequest { accept } => {
                if accept {
                    // The owner's yes is letting go: the core hands control to the requester.
                    self.model.asked_control(ControlAsk::Release);
                    self.command(MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL, [0.0])
                        .await
                } else {
                    self.to_vehicle(MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                        command: MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
                        result: MavResult::MAV_RESULT_DENIED,
                        progress: 0,
                        result_param2: 0,
                        target_system: self.shared.vehicle_sysid,
                        target_component: COMPONENT_ID,
                    }))
                    .await
                }
            }
        }
        None
    }
}
