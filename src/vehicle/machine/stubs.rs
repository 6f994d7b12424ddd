//! The services Neptunus answers without implementing them, so ground
//! stations move on at once instead of timing out: missions (none, and
//! none accepted), PROTOCOL_VERSION, TIMESYNC and PING.

use super::{Now, Output, Sender, Vehicle};
use crate::dialect::neptunus::*;

impl Vehicle {
    /// A message of one of these services, already addressed to us; `false`
    /// when `msg` is none of them.
    pub(super) fn answer_stub(
        &self,
        from: Sender,
        msg: &MavMessage,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        let reply = match msg {
            MavMessage::MISSION_REQUEST_LIST(m) => MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
                count: 0,
                target_system: from.sysid,
                target_component: from.compid,
                mission_type: m.mission_type,
                opaque_id: 0,
            }),
            MavMessage::MISSION_COUNT(m) => mission_ack(
                from,
                m.mission_type,
                MavMissionResult::MAV_MISSION_UNSUPPORTED,
            ),
            MavMessage::MISSION_CLEAR_ALL(m) => {
                mission_ack(from, m.mission_type, MavMissionResult::MAV_MISSION_ACCEPTED)
            }
            // A request (tc1 0), not an answer to someone else's.
            MavMessage::TIMESYNC(t) if t.tc1 == 0 => MavMessage::TIMESYNC(TIMESYNC_DATA {
                tc1: now.mono.as_nanos().min(i64::MAX as u128) as i64,
                ts1: t.ts1,
                target_system: from.sysid,
                target_component: from.compid,
            }),
            // A request (targets 0), not a reply to ours.
            MavMessage::PING(p) if p.target_system == 0 && p.target_component == 0 => {
                MavMessage::PING(PING_DATA {
                    time_usec: p.time_usec,
                    seq: p.seq,
                    target_system: from.sysid,
                    target_component: from.compid,
                })
            }
            _ => return false,
        };
        out.push(Output::Send {
            to: from.reply(),
            msg: reply,
        });
        true
    }
}

fn mission_ack(from: Sender, mission_type: MavMissionType, result: MavMissionResult) -> MavMessage {
    MavMessage::MISSION_ACK(MISSION_ACK_DATA {
        target_system: from.sysid,
        target_component: from.compid,
        mavtype: result,
        mission_type,
        opaque_id: 0,
    })
}

/// PROTOCOL_VERSION: MAVLink 2.
pub(super) fn protocol_version() -> MavMessage {
    MavMessage::PROTOCOL_VERSION(PROTOCOL_VERSION_DATA {
        version: 200,
        min_version: 100,
        max_version: 200,
        spec_version_hash: [0; 8],
        library_version_hash: [0; 8],
    })
}
