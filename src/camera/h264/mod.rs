//! H.264 as the camera gives it, without decoding it: the byte stream cut
//! into pictures ([`annexb`]), and pictures into RTP packets ([`rtp`]).
//!
//! This is the path of a camera that encodes H.264 itself: its pictures go
//! to QGroundControl (RTP) and to the WebRTC viewers as they came, so no
//! encoder runs on the vehicle. Nothing here decodes a picture; parsing
//! stops at NAL unit headers and the SPS's first bytes.

pub mod annexb;
pub mod rtp;

pub use annexb::{SplitterStats, Unit, UnitSplitter};
pub use rtp::{RtpPacketizer, profile_level_id, profile_name};

/// One picture for the RTP packetizers and the WebRTC viewers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AccessUnit {
    /// NAL units with Annex B start codes.
    pub data: Vec<u8>,
    /// The media clock at 90 kHz, monotonic across restarts of the source.
    pub time_90khz: u64,
    /// Holds an IDR picture (with the SPS and PPS before it): a viewer may
    /// start here.
    pub keyframe: bool,
}
