//! mavlink2rest's frame: `{"header":{"system_id","component_id","sequence"},
//! "message":{"type":"NAME", …}}` — what a client sends and what it gets.
//!
//! Owns the conversion both ways and the one answer for anything that is not
//! such a frame. Never panics on input; never hands on a message that did not
//! convert completely.

use serde::{Deserialize, Serialize};

use crate::dialect::neptunus::MavMessage;

/// mavlink2rest's answer to a frame it could not turn into a message.
pub const NOT_CONVERTED: &str = "Could not convert input message.";

/// A frame's header as mavlink2rest writes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    pub system_id: u8,
    pub component_id: u8,
    pub sequence: u8,
}

/// A frame a client sent.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ClientFrame {
    pub header: Header,
    pub message: MavMessage,
}

/// Why a client's text is not a frame (counted and logged; the client only
/// hears [`NOT_CONVERTED`], as from mavlink2rest).
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error("not a mavlink2rest frame: {0}")]
    Json(#[from] serde_json::Error),
    #[error("header system_id 0 is the broadcast address, not a ground station")]
    BroadcastSender,
    #[error("header system_id {0} is the vehicle's own")]
    VehicleSender(u8),
    #[error("header system_id {0} is lent to browser HMI sessions ([hmi] sysid_min..sysid_max)")]
    HmiSender(u8),
}

/// Who a client may not claim to be: the vehicle, and the system ids the
/// HMI lends its sessions (a client speaking as one could end that
/// session's control when it closes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reserved {
    pub vehicle_sysid: u8,
    pub hmi_sysids: (u8, u8),
}

impl Reserved {
    /// Only the vehicle's own id (tests, tools).
    pub const fn vehicle(vehicle_sysid: u8) -> Self {
        Self {
            vehicle_sysid,
            hmi_sysids: (1, 0),
        }
    }
}

/// Parses one client frame; a sender `reserved` names is refused.
pub fn parse(text: &str, reserved: Reserved) -> Result<ClientFrame, ConvertError> {
    let frame: ClientFrame = serde_json::from_str(text)?;
    let (lo, hi) = reserved.hmi_sysids;
    match frame.header.system_id {
        0 => Err(ConvertError::BroadcastSender),
        s if s == reserved.vehicle_sysid => Err(ConvertError::VehicleSender(s)),
        s if (lo..=hi).contains(&s) => Err(ConvertError::HmiSender(s)),
        _ => Ok(frame),
    }
}

/// The message alone, as JSON (what the REST tree keeps).
pub fn message_json(msg: &MavMessage) -> Result<String, serde_json::Error> {
    serde_json::to_string(msg)
}

/// A whole frame from the message's JSON (serialised once, shared by all
/// clients and the REST tree).
pub fn frame_json(header: Header, message_json: &str) -> String {
    format!(
        "{{\"header\":{{\"system_id\":{},\"component_id\":{},\"sequence\":{}}},\"message\":{message_json}}}",
        header.system_id, header.component_id, header.sequence
    )
}
