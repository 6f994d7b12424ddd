//! H.264 without decoding it: the byte stream cut into pictures
//! ([`annexb`]), pictures into RTP packets ([`rtp`]), and RTP packets back
//! into pictures ([`depay`]).
//!
//! Whatever route the H.264 takes (a camera that encodes it itself, a
//! camera's stream an ffmpeg copies, our own encoder's RTP read back), it
//! becomes one stream of [`AccessUnit`]s that the RTP sender hands to
//! every consumer in the vehicle (the WebRTC viewers, the recorder). Nothing
//! here decodes a picture; parsing stops at NAL unit headers and the SPS's
//! first bytes.

pub mod annexb;
pub mod depay;
pub mod rtp;

pub use annexb::{SplitterStats, Unit, UnitSplitter};
pub use rtp::{RtpPacketizer, profile_level_id, profile_name};

/// One picture for the RTP packetizers, the WebRTC viewers and the
/// recorder.
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
