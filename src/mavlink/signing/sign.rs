//! Signing our outgoing frames with timestamps that never go backwards,
//! even across restarts.
//!
//! Owns [`Signer`] and its reservation rule. It never reads a clock (`now_ts`
//! is passed in) and never writes a file: it hands the caller a reservation
//! to persist before the frame leaves.

use std::fmt;

use mavlink_core::{Message, calculate_crc};

use super::MAX_TIMESTAMP;
use super::frame::{CRC_LEN, IFLAG_SIGNED, Layout, STX_V2, TIMESTAMP_LEN, layout};
use super::key::SigningKey;
use crate::dialect::neptunus::MavMessage;

/// When a timestamp comes this close to the persisted reservation (30 s)…
pub const RESERVATION_MARGIN: u64 = 3_000_000;
/// …a new reservation this far ahead of it (60 s) is handed out for persisting.
pub const RESERVATION_AHEAD: u64 = 6_000_000;

/// Signs our outgoing MAVLink 2 frames with strictly increasing timestamps.
///
/// A timestamp that goes backwards, even across a restart, gets our frames
/// dropped as replays by every ground station that saw the earlier ones. So
/// the signer hands out *reservations*: a timestamp ahead of every one used,
/// which the caller persists ([`SigningStore::save_reservation`](super::SigningStore::save_reservation)) before the
/// frame leaves, and passes back to [`Signer::new`] after a restart.
pub struct Signer {
    key: SigningKey,
    link_id: u8,
    /// The last timestamp used (0 before the first frame).
    last: u64,
    /// No timestamp below this: the reservation we started from plus one,
    /// and SETUP_SIGNING's `initial_timestamp`.
    floor: u64,
    /// The last reservation handed out (or given to `new`): ≥ every timestamp used.
    reserved: u64,
}

impl fmt::Debug for Signer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Signer")
            .field("key", &self.key)
            .field("link_id", &self.link_id)
            .field("last", &self.last)
            .field("floor", &self.floor)
            .field("reserved", &self.reserved)
            .finish()
    }
}

impl Signer {
    /// `reservation`: the value last persisted, if any; every timestamp will
    /// be above it.
    pub fn new(key: SigningKey, link_id: u8, reservation: Option<u64>) -> Self {
        Self {
            key,
            link_id,
            last: 0,
            floor: reservation.map_or(0, |r| r.saturating_add(1)),
            reserved: reservation.unwrap_or(0),
        }
    }

    /// Turns an unsigned MAVLink 2 frame (as [`encode_v2`](crate::mavlink::encode_v2)
    /// makes them) into a signed one in place: sets the signed flag,
    /// recomputes the CRC (the flag is inside the CRC'd header) and appends
    /// link id, timestamp and signature. The timestamp is the largest of
    /// `now_ts`, the last one plus one and the floor.
    ///
    /// Returns a new reservation when the caller must persist one: whenever
    /// the timestamp comes within [`RESERVATION_MARGIN`] of the last
    /// reservation, which includes the first frame after [`Signer::new`]
    /// (unless timestamps are stuck at [`MAX_TIMESTAMP`] below a larger
    /// persisted reservation: nothing new to reserve). Write it before
    /// sending the frame, or a crash in between could reuse timestamps.
    ///
    /// Left untouched (returns `None`): anything that is not exactly one
    /// unsigned MAVLink 2 frame whose CRC checks with our dialect's CRC_EXTRA
    /// (MAVLink 1, already signed, torn, corrupted, or of a message our
    /// dialect does not know, whose CRC we could not recompute). Use
    /// [`is_signed`](super::is_signed) to tell.
    ///
    /// At [`MAX_TIMESTAMP`] (the year 2104, or a SETUP_SIGNING
    /// `initial_timestamp` that far ahead) timestamps stop increasing.
    pub fn sign(&mut self, frame: &mut Vec<u8>, now_ts: u64) -> Option<u64> {
        if !matches!(layout(frame), Some(Layout::Unsigned)) || frame.first() != Some(&STX_V2) {
            return None;
        }
        let crc_at = frame.len() - CRC_LEN;
        let msg_id = u32::from_le_bytes([frame[7], frame[8], frame[9], 0]);
        let extra = MavMessage::extra_crc(msg_id);
        let given_crc = u16::from_le_bytes([frame[crc_at], frame[crc_at + 1]]);
        if calculate_crc(&frame[1..crc_at], extra) != given_crc {
            return None;
        }

        let timestamp = now_ts
            .max(self.last.saturating_add(1))
            .max(self.floor)
            .min(MAX_TIMESTAMP);
        frame[2] |= IFLAG_SIGNED;
        let crc = calculate_crc(&frame[1..crc_at], extra);
        frame[crc_at..].copy_from_slice(&crc.to_le_bytes());
        let mut ts_bytes = [0u8; TIMESTAMP_LEN];
        ts_bytes.copy_from_slice(&timestamp.to_le_bytes()[..TIMESTAMP_LEN]);
        let signature = self.key.signature(frame, self.link_id, &ts_bytes);
        frame.push(self.link_id);
        frame.extend_from_slice(&ts_bytes);
        frame.extend_from_slice(&signature);
        self.last = timestamp;

        // The first frame after `new` always lands here: its timestamp is
        // above the reservation we started from.
        if timestamp.saturating_add(RESERVATION_MARGIN) >= self.reserved {
            self.reserved = self
                .reserved
                .max(timestamp.saturating_add(RESERVATION_AHEAD));
            return Some(self.reserved);
        }
        None
    }

    /// SETUP_SIGNING's `initial_timestamp`: no later timestamp goes below it.
    pub fn raise_floor(&mut self, initial_timestamp: u64) {
        self.floor = self.floor.max(initial_timestamp);
    }

    /// The timestamp of the last frame signed (0 before the first).
    pub fn last_timestamp(&self) -> u64 {
        self.last
    }

    pub fn link_id(&self) -> u8 {
        self.link_id
    }
}
