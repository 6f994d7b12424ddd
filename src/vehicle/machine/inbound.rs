//! Inbound dispatch: every MAVLink message and HMI event reaches its
//! handler from here. Two checks are made here and nowhere else:
//!
//! - **addressing**: a message with a target (system, component) is ours
//!   when each is 0 (broadcast) or our own id, as ArduPilot routes; what
//!   names the camera component (100) goes to `camera.rs` first;
//! - **control input** (sticks, RC override, per-thruster commands,
//!   setpoints): from the station in control, else refused, counted and
//!   answered; accepted input is a sign of the owner's life.
//!
//! Adding an inbound message: one arm in [`Vehicle::on_mavlink`], the
//! handler in the file of its concern (see `docs/ARCHITECTURE.md`).

use mavlink_core::Message;

use super::authority::Control;
use super::command::ack_set_mode;
use super::{CAMERA_COMPONENT_ID, COMPONENT_ID, HmiEvent, Now, Output, Sender, Vehicle};
use crate::dialect::neptunus::*;

impl Vehicle {
    /// Whether a target (system, component) names this vehicle's autopilot
    /// or everyone.
    pub(super) fn for_us(&self, target_system: u8, target_component: u8) -> bool {
        (target_system == 0 || target_system == self.sysid())
            && (target_component == 0 || target_component == COMPONENT_ID)
    }

    /// Whether a target (system, component) names this vehicle's camera
    /// component (which exists only when the vehicle has a camera).
    pub(super) fn for_camera(&self, target_system: u8, target_component: u8) -> bool {
        self.has_camera()
            && (target_system == 0 || target_system == self.sysid())
            && target_component == CAMERA_COMPONENT_ID
    }

    /// Whether `msg`'s targets, where it has them, name us or everyone.
    fn addressed_to_us(&self, msg: &MavMessage) -> bool {
        msg.target_system_id()
            .is_none_or(|s| s == 0 || s == self.sysid())
            && msg
                .target_component_id()
                .is_none_or(|c| c == 0 || c == COMPONENT_ID)
    }

    /// The one check every control input passes: from the station in
    /// control (a refusal is counted and answered, rate-limited, to the
    /// sender alone), and then a sign of its life. Stick-like input
    /// (`aimed_at` given) must also name this vehicle's own id: a broadcast
    /// stick command would drive every vehicle on the network (ArduSub
    /// ignores it too); setpoints may be broadcast.
    fn accept_control_input(
        &mut self,
        from: Sender,
        what: &str,
        aimed_at: Option<u8>,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        if aimed_at.is_some_and(|s| s != self.sysid()) {
            return false;
        }
        if let Err(why) = self.check_control(from, Control::Drive, now, out) {
            self.refuse_input(from, what, why, now, out);
            return false;
        }
        self.note_life(from, now);
        true
    }

    pub(super) fn on_mavlink(
        &mut self,
        from: Sender,
        msg: MavMessage,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        // The camera component answers what is aimed at it, and camera
        // requests broadcast to component 0 (the autopilot then stays silent).
        if self.on_camera_message(from, &msg, now, out) || !self.addressed_to_us(&msg) {
            return;
        }
        match msg {
            MavMessage::COMMAND_LONG(c) => {
                let p = [
                    c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7,
                ];
                self.command(from, c.command, p, now, out);
            }
            MavMessage::COMMAND_INT(c) => {
                let p = [
                    c.param1, c.param2, c.param3, c.param4, c.x as f32, c.y as f32, c.z,
                ];
                self.command(from, c.command, p, now, out);
            }
            MavMessage::MANUAL_CONTROL(m) => {
                if self.accept_control_input(from, "MANUAL_CONTROL", Some(m.target), now, out) {
                    self.on_manual_control(from, &m, now, out);
                }
            }
            MavMessage::RC_CHANNELS_OVERRIDE(r) => {
                let aim = Some(r.target_system);
                if self.accept_control_input(from, "RC override", aim, now, out) {
                    self.on_rc_override(from, &r, now, out);
                }
            }
            MavMessage::NEPTUNUS_THRUSTERS(t) => {
                let aim = Some(t.target_system);
                if self.accept_control_input(from, "NEPTUNUS_THRUSTERS", aim, now, out) {
                    self.on_thrusters_message(&t, now, out);
                }
            }
            MavMessage::SET_POSITION_TARGET_GLOBAL_INT(t) => {
                let what = "SET_POSITION_TARGET_GLOBAL_INT";
                if self.accept_control_input(from, what, None, now, out) {
                    self.on_position_target(from, &t, now, out);
                }
            }
            MavMessage::SET_ATTITUDE_TARGET(t) => {
                if self.accept_control_input(from, "SET_ATTITUDE_TARGET", None, now, out) {
                    self.on_attitude_target(from, &t, now, out);
                }
            }
            MavMessage::HEARTBEAT(h) if h.mavtype == MavType::MAV_TYPE_GCS => {
                // Only a ground station's own heartbeats keep it in control.
                self.note_life(from, now);
            }
            // An answer to our own request: it names us, not everyone.
            MavMessage::COMMAND_ACK(a) if a.target_system == self.sysid() => {
                self.on_gcs_ack(from, &a, out);
            }
            MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(_)
            | MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(_) => {
                self.on_gimbal_message(from, &msg, now, out);
            }
            MavMessage::SETUP_SIGNING(k) => self.setup_signing(from, &k, now, out),
            MavMessage::SYSTEM_TIME(t) => self.on_system_time(from, &t, now, out),
            MavMessage::SET_MODE(m) => {
                let result = self.set_mode_by(from, m.custom_mode, now, out);
                out.push(Output::Send {
                    to: from.reply(),
                    msg: ack_set_mode(result, from),
                });
            }
            MavMessage::PARAM_REQUEST_LIST(_) => self.param_request_list(from),
            MavMessage::PARAM_REQUEST_READ(p) => self.param_request_read(from, &p, out),
            MavMessage::PARAM_SET(p) => self.param_set(from, &p, now, out),
            MavMessage::REQUEST_DATA_STREAM(r) => self.request_data_stream(from, &r, now, out),
            MavMessage::FILE_TRANSFER_PROTOCOL(f) => self.on_ftp(from, &f, now, out),
            MavMessage::LOG_REQUEST_LIST(m) => self.log_request_list(from, &m, now, out),
            MavMessage::LOG_REQUEST_DATA(m) => self.log_request_data(from, &m, now, out),
            MavMessage::LOG_REQUEST_END(_) => self.log_request_end(from),
            MavMessage::LOG_ERASE(_) => self.log_erase(from, now, out),
            other => {
                self.answer_stub(from, &other, now, out);
            }
        }
    }

    /// A browser HMI session's safety events: the owner's window losing
    /// focus or changing input device is a safety stop; its session
    /// closing releases control.
    pub(super) fn on_hmi(&mut self, sysid: u8, event: HmiEvent, now: Now, out: &mut Vec<Output>) {
        let owner = self.owner() == Some(sysid);
        match event {
            HmiEvent::FocusLost | HmiEvent::InputModeChanged => {
                if owner {
                    self.safety_stop(true, out);
                }
                let kind = if event == HmiEvent::FocusLost {
                    "hmi_focus_lost"
                } else {
                    "hmi_input_mode"
                };
                self.log(kind, Some(sysid), format!("owner: {owner}"), out);
            }
            HmiEvent::Disconnected => {
                self.log(
                    "hmi_disconnected",
                    Some(sysid),
                    format!("owner: {owner}"),
                    out,
                );
                if self.auth.pending.is_some_and(|p| p.from.sysid == sysid) {
                    self.withdraw_request("its HMI session closed", out);
                }
                if owner {
                    self.drop_owner("control_released", "HMI session closed", now, out);
                }
            }
        }
    }
}
