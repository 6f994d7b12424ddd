//! MAVLink framing, sans-IO: bytes in, [`Frame`]s out, and one message
//! encoded as MAVLink 2 bytes.
//!
//! Owns: finding frame boundaries in a byte stream or a datagram, checking
//! CRCs against our dialect's CRC_EXTRA, decoding payloads into
//! [`MavMessage`], and counting every kind of bad input. It never touches a
//! socket, never allocates more than one frame's worth of carry-over between
//! calls, never panics on any input, and never checks signatures (that needs
//! keys, which belong to the vehicle core; [`Frame::signed`] and
//! [`Frame::raw`] give it what it needs).
//!
//! We do our own boundary detection on top of `mavlink_core`'s CRC and
//! payload parsers because the crate's readers drop bad candidates silently,
//! and an operator chasing a flaky radio needs to tell garbage from CRC
//! errors from messages of a dialect we do not speak.

use mavlink_core::{
    MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message, MessageData, calculate_crc,
};
use serde::Serialize;

pub use crate::dialect::neptunus::MavMessage;
use crate::dialect::neptunus::{
    COMMAND_ACK_DATA, COMMAND_INT_DATA, COMMAND_LONG_DATA, MavCmd, MavParamType, MavResult,
    PARAM_SET_DATA,
};

const STX_V1: u8 = mavlink_core::MAV_STX;
const STX_V2: u8 = mavlink_core::MAV_STX_V2;
/// Marker plus header: `STX len seq sys comp msgid`.
const V1_HEADER_LEN: usize = 6;
/// Marker plus header: `STX len incompat compat seq sys comp msgid[3]`.
const V2_HEADER_LEN: usize = 10;
const CRC_LEN: usize = 2;
const SIGNATURE_LEN: usize = 13;
const IFLAG_SIGNED: u8 = 0x01;
/// The longest frame there is (signed MAVLink 2 with a full payload). The
/// stream decoder never carries more than this between pushes.
pub const MAX_FRAME_LEN: usize = V2_HEADER_LEN + 255 + CRC_LEN + SIGNATURE_LEN;

/// One decoded MAVLink frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub version: MavlinkVersion,
    pub sysid: u8,
    pub compid: u8,
    pub seq: u8,
    pub msg_id: u32,
    pub msg: MavMessage,
    /// MAVLink 2 incompat flag 0x01 is set. The signature is *not* verified here.
    pub signed: bool,
    /// The frame's exact bytes, for the telemetry log and signature checks.
    pub raw: Vec<u8>,
    /// A message the dialect cannot represent but the vehicle must still
    /// answer; `msg` is then a placeholder that carries what it can.
    pub undecodable: Option<Undecodable>,
}

/// Why a frame with a valid CRC is delivered with a placeholder message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Undecodable {
    /// A COMMAND_LONG or COMMAND_INT whose command number our dialect does
    /// not define: `msg` is a COMMAND_LONG with the targets and the placeholder
    /// MAV_CMD_NEPTUNUS_UNKNOWN_COMMAND; this is the number really sent, so
    /// the vehicle can still answer MAV_RESULT_UNSUPPORTED at once.
    Command(u16),
    /// A PARAM_SET whose `param_type` is no MAV_PARAM_TYPE: `msg` is the
    /// PARAM_SET with its targets and name (value 0, type REAL32 as a
    /// placeholder); this is the type really sent, so the vehicle can answer
    /// with the parameter's current value, as ArduPilot does.
    ParamType(u8),
}

/// What a decoder has seen. Counters only grow.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct FrameStats {
    /// Frames delivered.
    pub frames: u64,
    /// Of those, MAVLink 1 frames.
    pub v1_frames: u64,
    /// Candidates of a known message whose CRC did not match.
    pub bad_crc: u64,
    /// Candidates whose message id our dialect does not know (their CRC
    /// cannot be checked without the id's CRC_EXTRA).
    pub unknown_msg: u64,
    /// Frames with a valid CRC whose payload would not decode (an enum value
    /// out of range, unsupported incompat flags), and frames torn off at the
    /// end of a datagram.
    pub bad_payload: u64,
    /// Bytes dropped outside delivered frames (noise, and the bytes of the
    /// bad candidates above).
    pub garbage_bytes: u64,
}

impl FrameStats {
    /// Candidates that looked like frames but had to be dropped.
    pub fn malformed(&self) -> u64 {
        self.bad_crc + self.unknown_msg + self.bad_payload
    }

    /// Adds another set of counters to this one.
    pub fn add(&mut self, other: &FrameStats) {
        self.frames += other.frames;
        self.v1_frames += other.v1_frames;
        self.bad_crc += other.bad_crc;
        self.unknown_msg += other.unknown_msg;
        self.bad_payload += other.bad_payload;
        self.garbage_bytes += other.garbage_bytes;
    }
}

/// Stream decoder for TCP and serial: accepts any chunking, and resyncs on
/// the next magic byte (0xFD for v2, 0xFE for v1) after garbage or a bad
/// frame. The output does not depend on how the input was chunked.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    /// Unconsumed bytes: always less than one [`MAX_FRAME_LEN`] after a push.
    buf: Vec<u8>,
    /// Bytes at the front of `buf` that belong to a candidate already
    /// counted as bad; see [`Scanner::quiet_end`].
    quiet: usize,
    stats: FrameStats,
}

impl FrameDecoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes; every complete frame is appended to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Frame>) {
        self.buf.extend_from_slice(bytes);
        let mut scanner = Scanner {
            stats: &mut self.stats,
            quiet_end: self.quiet,
            at_end_is_torn: false,
        };
        let consumed = scanner.scan(&self.buf, out);
        self.quiet = scanner.quiet_end.saturating_sub(consumed);
        self.buf.drain(..consumed);
    }

    pub fn stats(&self) -> &FrameStats {
        &self.stats
    }

    /// Returns the counters gathered since the last call and resets them, so
    /// several decoders (one per TCP client) can feed one endpoint's totals.
    pub fn take_stats(&mut self) -> FrameStats {
        std::mem::take(&mut self.stats)
    }
}

/// Decodes one UDP datagram. It may hold several frames; a torn frame at the
/// end is malformed, and nothing carries over to the next datagram (UDP
/// keeps message boundaries, so a frame never spans two datagrams).
pub fn decode_datagram(bytes: &[u8], stats: &mut FrameStats, out: &mut Vec<Frame>) {
    let mut scanner = Scanner {
        stats,
        quiet_end: 0,
        at_end_is_torn: true,
    };
    // In datagram mode the scanner consumes everything.
    scanner.scan(bytes, out);
}

/// MAVLink 2 encoding of one message (unsigned).
pub fn encode_v2(sysid: u8, compid: u8, seq: u8, msg: &MavMessage) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: u32::from(sysid),
            component_id: compid,
            sequence: seq,
        },
        msg,
    );
    raw.raw_bytes().to_vec()
}

/// What a candidate starting at a magic byte turned out to be.
enum Candidate {
    /// More bytes needed; the candidate is at least this long.
    Incomplete(usize),
    Valid(Box<Frame>),
    /// Not a frame we can use; `len` is how long it claimed to be.
    Bad {
        kind: BadKind,
        len: usize,
    },
}

#[derive(Clone, Copy)]
enum BadKind {
    Crc,
    Unknown,
    /// CRC valid (so it really was a frame): skip it whole.
    Payload,
}

struct Scanner<'a> {
    stats: &'a mut FrameStats,
    /// A bad candidate is retried from its second byte so that a real frame
    /// inside it is not lost; but a magic byte inside a broken frame is not a
    /// second broken frame. Failures of candidates starting before this
    /// position are therefore counted as garbage only, so one flipped bit
    /// counts as one bad frame.
    quiet_end: usize,
    /// Datagram mode: an incomplete candidate is torn, not "wait for more".
    at_end_is_torn: bool,
}

impl Scanner<'_> {
    /// Scans `buf`, returning how many bytes are consumed (the rest is an
    /// incomplete candidate to keep for the next push).
    fn scan(&mut self, buf: &[u8], out: &mut Vec<Frame>) -> usize {
        let mut pos = 0;
        while pos < buf.len() {
            let Some(skip) = buf[pos..].iter().position(|&b| b == STX_V2 || b == STX_V1) else {
                self.stats.garbage_bytes += (buf.len() - pos) as u64;
                return buf.len();
            };
            self.stats.garbage_bytes += skip as u64;
            pos += skip;
            match examine(&buf[pos..]) {
                Candidate::Incomplete(len) => {
                    if !self.at_end_is_torn {
                        return pos;
                    }
                    self.reject(BadKind::Payload, pos, len);
                    self.stats.garbage_bytes += 1;
                    pos += 1;
                }
                Candidate::Valid(frame) => {
                    pos += frame.raw.len();
                    self.stats.frames += 1;
                    if frame.version == MavlinkVersion::V1 {
                        self.stats.v1_frames += 1;
                    }
                    out.push(*frame);
                }
                Candidate::Bad {
                    kind: BadKind::Payload,
                    len,
                } => {
                    self.reject(BadKind::Payload, pos, len);
                    self.stats.garbage_bytes += len as u64;
                    pos += len;
                }
                Candidate::Bad { kind, len } => {
                    // Only the magic byte is dropped now; the rest is rescanned.
                    self.reject(kind, pos, len);
                    self.stats.garbage_bytes += 1;
                    pos += 1;
                }
            }
        }
        pos
    }

    fn reject(&mut self, kind: BadKind, pos: usize, len: usize) {
        if pos >= self.quiet_end {
            match kind {
                BadKind::Crc => self.stats.bad_crc += 1,
                BadKind::Unknown => self.stats.unknown_msg += 1,
                BadKind::Payload => self.stats.bad_payload += 1,
            }
        }
        self.quiet_end = self.quiet_end.max(pos + len);
    }
}

/// Examines the candidate frame at the start of `buf` (which starts with a
/// magic byte).
fn examine(buf: &[u8]) -> Candidate {
    let (version, header_len) = match buf.first() {
        Some(&STX_V1) => (MavlinkVersion::V1, V1_HEADER_LEN),
        _ => (MavlinkVersion::V2, V2_HEADER_LEN),
    };
    // Length (byte 1) and, for v2, the incompat flags (byte 2) fix the size.
    let Some(&payload_len) = buf.get(1) else {
        return Candidate::Incomplete(header_len + CRC_LEN);
    };
    let payload_len = usize::from(payload_len);
    let incompat = match version {
        MavlinkVersion::V1 => 0,
        MavlinkVersion::V2 => match buf.get(2) {
            Some(&flags) => flags,
            None => return Candidate::Incomplete(header_len + payload_len + CRC_LEN),
        },
    };
    let signature_len = if incompat & IFLAG_SIGNED != 0 {
        SIGNATURE_LEN
    } else {
        0
    };
    let crc_at = header_len + payload_len;
    let len = crc_at + CRC_LEN + signature_len;
    let Some(bytes) = buf.get(..len) else {
        return Candidate::Incomplete(len);
    };

    let (seq, sysid, compid, msg_id) = match version {
        MavlinkVersion::V1 => (bytes[2], bytes[3], bytes[4], u32::from(bytes[5])),
        MavlinkVersion::V2 => (
            bytes[4],
            bytes[5],
            bytes[6],
            u32::from_le_bytes([bytes[7], bytes[8], bytes[9], 0]),
        ),
    };
    let given_crc = u16::from_le_bytes([bytes[crc_at], bytes[crc_at + 1]]);
    let crc = calculate_crc(&bytes[1..crc_at], MavMessage::extra_crc(msg_id));
    if crc != given_crc {
        let kind = if MavMessage::default_message_from_id(msg_id).is_some() {
            BadKind::Crc
        } else {
            BadKind::Unknown
        };
        return Candidate::Bad { kind, len };
    }
    if incompat & !IFLAG_SIGNED != 0 {
        // A flag we do not understand changes the frame's meaning (the spec
        // says drop it); the CRC held, so it really was one whole frame.
        return Candidate::Bad {
            kind: BadKind::Payload,
            len,
        };
    }
    match MavMessage::parse(version, msg_id, &bytes[header_len..crc_at]) {
        Ok(msg) => Candidate::Valid(Box::new(Frame {
            version,
            sysid,
            compid,
            seq,
            msg_id,
            msg,
            signed: signature_len != 0,
            raw: bytes.to_vec(),
            undecodable: None,
        })),
        Err(mavlink_core::error::ParserError::InvalidEnum {
            enum_type: "MavCmd",
            ..
        }) if msg_id == COMMAND_LONG_ID || msg_id == COMMAND_INT_ID => {
            // Both messages keep command (u16), target_system and
            // target_component at payload bytes 28..32; MAVLink 2 may have
            // truncated trailing zeros.
            let mut payload = [0u8; 35];
            let given = &bytes[header_len..crc_at];
            payload[..given.len().min(35)].copy_from_slice(&given[..given.len().min(35)]);
            let command = u16::from_le_bytes([payload[28], payload[29]]);
            Candidate::Valid(Box::new(Frame {
                version,
                sysid,
                compid,
                seq,
                msg_id,
                msg: MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                    command: MavCmd::MAV_CMD_NEPTUNUS_UNKNOWN_COMMAND,
                    target_system: payload[30],
                    target_component: payload[31],
                    ..Default::default()
                }),
                signed: signature_len != 0,
                raw: bytes.to_vec(),
                undecodable: Some(Undecodable::Command(command)),
            }))
        }
        Err(mavlink_core::error::ParserError::InvalidEnum {
            enum_type: "MavParamType",
            ..
        }) if msg_id == PARAM_SET_ID => {
            // value 0..4, target_system 4, target_component 5, param_id
            // 6..22, param_type 22; MAVLink 2 may have truncated trailing zeros.
            let mut payload = [0u8; 23];
            let given = &bytes[header_len..crc_at];
            payload[..given.len().min(23)].copy_from_slice(&given[..given.len().min(23)]);
            let mut name = [0u8; 16];
            name.copy_from_slice(&payload[6..22]);
            Candidate::Valid(Box::new(Frame {
                version,
                sysid,
                compid,
                seq,
                msg_id,
                msg: MavMessage::PARAM_SET(PARAM_SET_DATA {
                    param_value: 0.0,
                    target_system: payload[4],
                    target_component: payload[5],
                    param_id: name.into(),
                    param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
                }),
                signed: signature_len != 0,
                raw: bytes.to_vec(),
                undecodable: Some(Undecodable::ParamType(payload[22])),
            }))
        }
        Err(mavlink_core::error::ParserError::UnknownMessage { .. }) => Candidate::Bad {
            kind: BadKind::Unknown,
            len,
        },
        Err(_) => Candidate::Bad {
            kind: BadKind::Payload,
            len,
        },
    }
}

const PARAM_SET_ID: u32 = PARAM_SET_DATA::ID;
const COMMAND_INT_ID: u32 = COMMAND_INT_DATA::ID;
const COMMAND_LONG_ID: u32 = COMMAND_LONG_DATA::ID;
const COMMAND_ACK_ID: u32 = COMMAND_ACK_DATA::ID;

/// COMMAND_ACK for a command number our dialect cannot represent (the
/// generated `MavCmd` enum has no value for it): encoded with a placeholder,
/// then the command bytes patched and the CRC recomputed.
pub fn encode_command_ack_raw(
    sysid: u8,
    compid: u8,
    seq: u8,
    command: u16,
    result: MavResult,
    target_system: u8,
    target_component: u8,
) -> Vec<u8> {
    // A non-zero placeholder keeps MAVLink 2 from truncating the command bytes away.
    let msg = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command: MavCmd::MAV_CMD_NAV_WAYPOINT,
        result,
        progress: 0,
        result_param2: 0,
        target_system,
        target_component,
    });
    let mut frame = encode_v2(sysid, compid, seq, &msg);
    let [lo, hi] = command.to_le_bytes();
    frame[V2_HEADER_LEN] = lo;
    frame[V2_HEADER_LEN + 1] = hi;
    let crc_at = frame.len() - CRC_LEN;
    let crc = calculate_crc(&frame[1..crc_at], MavMessage::extra_crc(COMMAND_ACK_ID));
    frame[crc_at..].copy_from_slice(&crc.to_le_bytes());
    frame
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_frame_len_matches_the_crate() {
        assert_eq!(MAX_FRAME_LEN, mavlink_core::consts::v2::FRAME_SIZE - 3);
    }
}
