//! The event log: what happened to the vehicle, one JSON object per line.
//!
//! (Placeholder for the writer; the record type is what the core emits.)

/// One thing worth an operator's later attention. Pure data: the vehicle core creates these.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LogEvent {
    /// snake_case event name, e.g. "armed", "control_granted", "failsafe_raised".
    pub kind: &'static str,
    /// The ground station involved, if any.
    pub sysid: Option<u8>,
    /// Human-readable detail.
    pub detail: String,
}

impl LogEvent {
    pub fn new(kind: &'static str, sysid: Option<u8>, detail: impl Into<String>) -> Self {
        Self {
            kind,
            sysid,
            detail: detail.into(),
        }
    }
}
