//! COMMAND_LONG and COMMAND_INT: one match from command number to the
//! handler of its concern, each answered with exactly one COMMAND_ACK to
//! the sender (then any message the command asked for).
//!
//! Adding a command: one arm in [`Vehicle::run_command`], its handler in
//! the file of its concern (see `docs/ARCHITECTURE.md`); the authority
//! check comes first for anything that changes the vehicle.

use mavlink_core::MessageData;

use super::authority::{self, Control};
use super::{Now, Output, Sender, To, Vehicle, given};
use crate::dialect::neptunus::*;

/// What a command produced: its result, and messages for the asker alone.
type Answer = (MavResult, Vec<MavMessage>);

fn only(result: MavResult) -> Answer {
    (result, Vec::new())
}

impl Vehicle {
    /// One command from `from` (COMMAND_LONG, or COMMAND_INT with x, y as
    /// floats): handled, then acknowledged.
    pub(super) fn command(
        &mut self,
        from: Sender,
        cmd: MavCmd,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let (result, replies) = self.run_command(from, cmd, p, now, out);
        let to = from.reply();
        out.push(Output::Send {
            to,
            msg: ack(cmd, result, from),
        });
        out.extend(replies.into_iter().map(|msg| Output::Send { to, msg }));
    }

    fn run_command(
        &mut self,
        from: Sender,
        cmd: MavCmd,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) -> Answer {
        use MavCmd as C;
        use MavResult as R;
        match cmd {
            C::MAV_CMD_COMPONENT_ARM_DISARM => only(self.arm_disarm_command(from, p, now, out)),
            C::MAV_CMD_REQUEST_OPERATOR_CONTROL => only(self.operator_control(from, p, now, out)),
            C::MAV_CMD_NEPTUNUS_SET_RUN_MODE => only(self.run_mode_command(from, p, now, out)),
            C::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET => {
                only(self.autopilot_target_command(from, p, now, out))
            }
            C::MAV_CMD_DO_SET_MODE => {
                let mode = given(p[1]).map_or(u32::MAX, |m| m.max(0.0) as u32);
                only(self.set_mode_by(from, mode, now, out))
            }
            C::MAV_CMD_SET_MESSAGE_INTERVAL => only(self.set_message_interval(from, p, now, out)),
            C::MAV_CMD_GET_MESSAGE_INTERVAL => match self.message_interval(from, p) {
                Some(msg) => (R::MAV_RESULT_ACCEPTED, vec![msg]),
                None => only(R::MAV_RESULT_UNSUPPORTED),
            },
            C::MAV_CMD_REQUEST_MESSAGE => {
                let msgs = self.requested_message(p, now);
                let id = given(p[0]).map_or(u32::MAX, |v| v as u32);
                if msgs.is_empty() && crate::vehicle::telemetry::nothing_to_send(id) {
                    // As ArduSub: accepted, and nothing to send (no home yet, no GPS…).
                    only(R::MAV_RESULT_ACCEPTED)
                } else if msgs.is_empty() {
                    only(R::MAV_RESULT_UNSUPPORTED)
                } else {
                    (R::MAV_RESULT_ACCEPTED, msgs)
                }
            }
            C::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
                (R::MAV_RESULT_ACCEPTED, vec![self.autopilot_version()])
            }
            C::MAV_CMD_REQUEST_PROTOCOL_VERSION => (
                R::MAV_RESULT_ACCEPTED,
                vec![super::stubs::protocol_version()],
            ),
            C::MAV_CMD_DO_MOTOR_TEST => {
                only(match self.check_control(from, Control::Drive, now, out) {
                    Ok(()) => self.motor_test(p, now, out),
                    Err(why) => self.refuse_command(from, "motor test", why, now, out),
                })
            }
            C::MAV_CMD_DO_SET_SERVO
            | C::MAV_CMD_DO_MOUNT_CONTROL
            | C::MAV_CMD_ILLUMINATOR_ON_OFF
            | C::MAV_CMD_DO_ILLUMINATOR_CONFIGURE => {
                only(match self.check_control(from, Control::Command, now, out) {
                    Ok(()) => self.payload_command(cmd, p, out),
                    Err(why) => self.refuse_command(from, "command", why, now, out),
                })
            }
            // Taking the gimbal (QGC asks before moving it): gimbal control
            // is vehicle control, so this only says whether the asker has it.
            C::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE => {
                only(match self.check_control(from, Control::Command, now, out) {
                    Ok(()) => R::MAV_RESULT_ACCEPTED,
                    Err(why) => self.refuse_command(from, "gimbal control", why, now, out),
                })
            }
            C::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW => {
                only(match self.check_control(from, Control::Command, now, out) {
                    Ok(()) => self.gimbal_pitchyaw_command(p, now, out),
                    Err(why) => self.refuse_command(from, "gimbal pitch", why, now, out),
                })
            }
            _ => only(R::MAV_RESULT_UNSUPPORTED),
        }
    }

    /// MAV_CMD_COMPONENT_ARM_DISARM: p1 1 arm / 0 disarm, p2 the force magic
    /// numbers (2989 or 21196). Disarming is open to every station
    /// (stopping is never the wrong answer), but with signing on only to
    /// signed ones.
    fn arm_disarm_command(
        &mut self,
        from: Sender,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        let arm = given(p[0]).unwrap_or(0.0) >= 0.5;
        let force =
            given(p[1]).is_some_and(|v| (v - 2989.0).abs() < 0.5 || (v - 21196.0).abs() < 0.5);
        if arm {
            match self.check_control(from, Control::Arm, now, out) {
                Ok(()) => self.arm(force, Some(from.sysid), now, out),
                Err(why) => self.refuse_command(from, "arm", why, now, out),
            }
        } else if self.signing_active && !from.signed {
            self.refuse_command(from, "disarm", authority::Refusal::Unsigned, now, out)
        } else {
            self.disarm("commanded", Some(from.sysid), out)
        }
    }

    /// MAV_CMD_REQUEST_MESSAGE (p1 message id, p2 its index where it has
    /// one): the message now, or nothing when there is nothing honest to send.
    fn requested_message(&self, p: [f32; 7], now: Now) -> Vec<MavMessage> {
        let id = given(p[0]).map_or(u32::MAX, |v| v as u32);
        match id {
            AVAILABLE_MODES_DATA::ID => self.available_modes(given(p[1]).unwrap_or(0.0) as u32),
            // PARAM_VALUE by index (param2).
            PARAM_VALUE_DATA::ID => self
                .param_value(given(p[1]).unwrap_or(-1.0).max(0.0) as usize)
                .into_iter()
                .collect(),
            PROTOCOL_VERSION_DATA::ID => vec![super::stubs::protocol_version()],
            COMPONENT_METADATA_DATA::ID => vec![self.component_metadata(now)],
            COMPONENT_INFORMATION_DATA::ID => vec![self.component_information(now)],
            _ => self.build(id, now),
        }
    }
}

impl Vehicle {
    /// COMPONENT_METADATA: where the general metadata file is (MAVLink
    /// FTP) and its CRC.
    fn component_metadata(&self, now: Now) -> MavMessage {
        use crate::files::{MemFile, component};
        MavMessage::COMPONENT_METADATA(COMPONENT_METADATA_DATA {
            time_boot_ms: self.boot_ms(now),
            file_crc: component::file(MemFile::General).crc,
            uri: super::chars(&component::uri(MemFile::General)),
        })
    }

    /// COMPONENT_INFORMATION, the older form QGroundControl still asks
    /// for: the same file, no peripherals.
    fn component_information(&self, now: Now) -> MavMessage {
        use crate::files::{MemFile, component};
        MavMessage::COMPONENT_INFORMATION(COMPONENT_INFORMATION_DATA {
            time_boot_ms: self.boot_ms(now),
            general_metadata_file_crc: component::file(MemFile::General).crc,
            peripherals_metadata_file_crc: 0,
            general_metadata_uri: super::chars(&component::uri(MemFile::General)),
            peripherals_metadata_uri: super::chars(""),
        })
    }
}

pub(super) fn ack(command: MavCmd, result: MavResult, from: Sender) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        progress: 0,
        result_param2: 0,
        target_system: from.sysid,
        target_component: from.compid,
    })
}

/// COMMAND_ACK for the SET_MODE message: ArduPilot puts the message id (11)
/// in `command`, and clients wait for exactly that.
pub(super) fn ack_set_mode(result: MavResult, from: Sender) -> MavMessage {
    ack(MavCmd::MAV_CMD_NEPTUNUS_SET_MODE_MESSAGE, result, from)
}

/// COMMAND_ACK (UNSUPPORTED) for a command number the dialect cannot represent.
pub(super) fn ack_unknown(from: Sender, command: u16, compid: u8) -> Output {
    Output::AckUnknown {
        to: To::Peer(from.endpoint, from.peer),
        compid,
        command,
        result: MavResult::MAV_RESULT_UNSUPPORTED,
        target_system: from.sysid,
        target_component: from.compid,
    }
}
