//! Access units into RTP packets (RFC 6184, packetization mode 1: single
//! NAL units, the SPS and PPS together in one STAP-A, FU-A for the large
//! ones), sans-IO: what QGroundControl's `rtph264depay` and Janus take, the
//! same payload the ffmpeg encoder's RTP has (payload type 96, at most
//! [`RTP_PACKET_BYTES`] a packet, the marker on a picture's last packet).
//!
//! The NAL unit payloads are str0m's H.264 packetizer's; the 12-byte RTP
//! header (sequence, 90 kHz timestamp, SSRC) is written here.

use str0m::unversioned::{H264Packetizer, Packetizer};

/// RTP packets stay under a typical path MTU with room for tunnels.
pub const RTP_PACKET_BYTES: u32 = 1200;

const HEADER_BYTES: usize = 12;
pub const PAYLOAD_TYPE: u8 = 96;

/// One RTP stream: its SSRC and sequence numbers.
#[derive(Debug)]
pub struct RtpPacketizer {
    packetizer: H264Packetizer,
    ssrc: u32,
    seq: u16,
}

impl RtpPacketizer {
    /// A stream with this SSRC, starting at sequence number `seq`.
    pub fn new(ssrc: u32, seq: u16) -> Self {
        RtpPacketizer {
            packetizer: H264Packetizer::default(),
            ssrc,
            seq,
        }
    }

    /// The packets of one picture (Annex B), stamped `time_90khz` (its low
    /// 32 bits).
    pub fn packets(&mut self, unit: &[u8], time_90khz: u64) -> Vec<Vec<u8>> {
        let payloads = self
            .packetizer
            .packetize(RTP_PACKET_BYTES as usize - HEADER_BYTES, unit)
            .unwrap_or_default();
        let last = payloads.len().saturating_sub(1);
        let ts = (time_90khz & 0xffff_ffff) as u32;
        payloads
            .into_iter()
            .enumerate()
            .map(|(i, payload)| {
                let mut p = Vec::with_capacity(HEADER_BYTES + payload.len());
                p.push(0x80);
                p.push(if i == last { 0x80 } else { 0 } | PAYLOAD_TYPE);
                p.extend_from_slice(&self.seq.to_be_bytes());
                p.extend_from_slice(&ts.to_be_bytes());
                p.extend_from_slice(&self.ssrc.to_be_bytes());
                p.extend_from_slice(&payload);
                self.seq = self.seq.wrapping_add(1);
                p
            })
            .collect()
    }
}

/// `profile-level-id` (six hex digits) of an SPS NAL unit (without start
/// code): profile, constraint flags and level, as a browser's offer names
/// them (`42e01f`: constrained baseline, level 3.1).
pub fn profile_level_id(sps: &[u8]) -> Option<String> {
    let b = sps.get(1..4)?;
    Some(format!("{:02x}{:02x}{:02x}", b[0], b[1], b[2]))
}

/// A plain name for an SPS's profile.
pub fn profile_name(sps: &[u8]) -> &'static str {
    let (Some(&profile), Some(&flags)) = (sps.get(1), sps.get(2)) else {
        return "unknown";
    };
    match profile {
        66 if flags & 0x40 != 0 => "constrained baseline",
        66 => "baseline",
        77 => "main",
        88 => "extended",
        100 => "high",
        110 => "high 10",
        122 => "high 4:2:2",
        244 => "high 4:4:4",
        _ => "other",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::h264::depay::Depay;

    fn nal(kind: u8, body: &[u8]) -> Vec<u8> {
        let mut v = vec![0, 0, 0, 1, 0x60 | kind];
        v.extend_from_slice(body);
        v
    }

    #[test]
    fn packets_carry_the_header_and_read_back_into_the_same_picture() {
        let mut big = vec![0x88];
        big.extend((0..5000u32).map(|i| (i % 251) as u8 | 1));
        let idr = [
            nal(7, &[0x42, 0xc0, 0x1e, 0xda]),
            nal(8, &[0xce, 0x3c, 0x80]),
            nal(5, &big),
        ]
        .concat();
        let mut p = RtpPacketizer::new(0x1234_5678, 65534);
        let packets = p.packets(&idr, 90_000);
        assert!(packets.len() >= 5, "{}", packets.len());
        for (i, pk) in packets.iter().enumerate() {
            assert!(pk.len() <= RTP_PACKET_BYTES as usize);
            assert_eq!(pk[0], 0x80);
            assert_eq!(pk[1] & 0x7f, 96);
            assert_eq!(
                pk[1] & 0x80 != 0,
                i == packets.len() - 1,
                "marker on the last"
            );
            assert_eq!(&pk[4..8], &90_000u32.to_be_bytes());
            assert_eq!(&pk[8..12], &0x1234_5678u32.to_be_bytes());
        }
        // The sequence wraps.
        assert_eq!(&packets[0][2..4], &[0xff, 0xfe]);
        assert_eq!(&packets[2][2..4], &[0, 0]);
        // Our own depacketizer (the WebRTC side's) gets the picture back.
        let mut d = Depay::new();
        let mut out = None;
        for pk in &packets {
            out = d.push(pk).pop().or(out);
        }
        let au = out.expect("a picture");
        assert!(au.keyframe);
        assert_eq!(au.data, idr);
        let p_frame = nal(1, &[0x9a, 1, 2]);
        let later = p.packets(&p_frame, 93_000);
        assert_eq!(later.len(), 1);
        assert_eq!(d.push(&later[0]).pop().expect("the next").data, p_frame);
    }

    #[test]
    fn a_picture_whose_marker_never_came_is_not_lost_behind_a_one_packet_picture() {
        let mut p = RtpPacketizer::new(0x1234_5678, 7);
        let idr = [
            nal(7, &[0x42, 0xc0, 0x1e]),
            nal(8, &[0xce]),
            nal(5, &vec![0x88; 3000]),
        ]
        .concat();
        let mut packets = p.packets(&idr, 90_000);
        assert!(packets.len() > 1);
        // A sender that never sets the marker: the next picture's first
        // packet, with its new timestamp, ends this one.
        let last = packets.len() - 1;
        packets[last][1] &= 0x7f;
        let mut d = Depay::new();
        for pk in &packets {
            assert!(d.push(pk).is_empty());
        }
        let p_frame = nal(1, &[0x9a, 1, 2]);
        let later = p.packets(&p_frame, 93_000);
        assert_eq!(later.len(), 1);
        let out = d.push(&later[0]);
        assert_eq!(out.len(), 2, "both pictures, oldest first");
        assert!(out[0].keyframe);
        assert_eq!(out[0].data, idr);
        assert_eq!(out[1].data, p_frame);
        assert_eq!(d.stats().units, 2);
    }

    #[test]
    fn the_profile_is_read_from_the_sps() {
        let sps = [0x67, 0x42, 0xc0, 0x1e, 0xda];
        assert_eq!(profile_level_id(&sps).as_deref(), Some("42c01e"));
        assert_eq!(profile_name(&sps), "constrained baseline");
        assert_eq!(profile_name(&[0x67, 0x64, 0x00, 0x28]), "high");
        assert_eq!(profile_level_id(&[0x67]), None);
    }
}
