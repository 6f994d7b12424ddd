//! The RTP encoder's own packets, read back on loopback, turned into whole
//! H.264 access units (Annex B), sans-IO: once, for every consumer in the
//! vehicle (the WebRTC viewers, the recorder).
//!
//! The RTP header is read here; the H.264 payload formats (single NAL
//! units, STAP-A, FU-A) by str0m's depacketizer. Packets of one picture
//! share a timestamp and the last carries the marker bit. A lost packet
//! (a gap in the sequence numbers) spoils its picture and everything after
//! it up to the next keyframe, so nothing undecodable goes out: the rest of
//! the spoiled picture is not taken, up to and including its marker — the
//! lost packets may have been its first ones (SPS, PPS, a slice), which only
//! a single gap right after an unfinished picture rules out. A payload that
//! does not parse spoils its picture the same way. A new SSRC (the encoder
//! restarted; its first packet starts a picture) starts over. The 32-bit
//! RTP timestamps become a 64-bit media clock that never goes back.
//!
//! Garbage never panics: a packet that is not RTP, or whose payload does
//! not parse, is counted and dropped.

use str0m::format::CodecExtra;
use str0m::unversioned::{Depacketizer, H264Depacketizer};

pub use crate::camera::h264::AccessUnit;

/// What went by, for the log and the tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DepayStats {
    pub packets: u64,
    pub units: u64,
    /// Datagrams that were not RTP, or whose payload did not parse.
    pub bad: u64,
    /// Packets missing from the sequence.
    pub lost: u64,
    /// Pictures dropped: spoiled by a loss, or while waiting for a keyframe.
    pub skipped: u64,
}

/// The RTP fixed header's fields we use, and the payload.
struct Rtp<'a> {
    marker: bool,
    seq: u16,
    timestamp: u32,
    ssrc: u32,
    payload: &'a [u8],
}

fn parse_rtp(p: &[u8]) -> Option<Rtp<'_>> {
    let b0 = *p.first()?;
    if b0 >> 6 != 2 || p.len() < 12 {
        return None;
    }
    let csrcs = usize::from(b0 & 0x0f);
    let mut start = 12 + 4 * csrcs;
    if b0 & 0x10 != 0 {
        let ext = p.get(start..start + 4)?;
        start += 4 + 4 * usize::from(u16::from_be_bytes([ext[2], ext[3]]));
    }
    let mut end = p.len();
    if b0 & 0x20 != 0 {
        end = end.checked_sub(usize::from(*p.last()?))?;
    }
    Some(Rtp {
        marker: p[1] & 0x80 != 0,
        seq: u16::from_be_bytes([p[2], p[3]]),
        timestamp: u32::from_be_bytes([p[4], p[5], p[6], p[7]]),
        ssrc: u32::from_be_bytes([p[8], p[9], p[10], p[11]]),
        payload: p.get(start..end).filter(|s| !s.is_empty())?,
    })
}

/// The picture being put together.
struct Partial {
    timestamp: u32,
    data: Vec<u8>,
    extra: CodecExtra,
}

/// Packets in, access units out.
#[derive(Default)]
pub struct Depay {
    depacketizer: H264Depacketizer,
    partial: Option<Partial>,
    ssrc: Option<u32>,
    next_seq: Option<u16>,
    /// Until a keyframe: after a loss, a new stream, or at the start.
    need_keyframe: bool,
    /// The rest of a spoiled picture is going by: nothing is taken up to
    /// and including its marker.
    spoiled: bool,
    /// The media clock: the last RTP timestamp and its extended value.
    clock: Option<(u32, u64)>,
    stats: DepayStats,
}

/// A jump of the RTP clock longer than this (or backwards) is a new
/// stream, not time passing.
const MAX_STEP_90KHZ: u32 = 10 * 90_000;

impl Depay {
    pub fn new() -> Self {
        Depay {
            need_keyframe: true,
            ..Depay::default()
        }
    }

    pub fn stats(&self) -> DepayStats {
        self.stats
    }

    /// One datagram from the encoder; the pictures this packet ended,
    /// oldest first: none, one, or two (a picture whose marker never came,
    /// ended by this packet's new timestamp, and this packet's own when it
    /// is a whole picture with its marker).
    pub fn push(&mut self, datagram: &[u8]) -> Vec<AccessUnit> {
        let mut out = Vec::new();
        self.push_into(datagram, &mut out);
        out
    }

    fn push_into(&mut self, datagram: &[u8], out: &mut Vec<AccessUnit>) {
        self.stats.packets += 1;
        let Some(rtp) = parse_rtp(datagram) else {
            self.stats.bad += 1;
            return;
        };
        if self.ssrc != Some(rtp.ssrc) {
            // The encoder restarted: its sequence starts anywhere, with a
            // picture.
            self.ssrc = Some(rtp.ssrc);
            self.restart();
            self.spoiled = false;
        } else if let Some(expected) = self.next_seq
            && rtp.seq != expected
        {
            let missing = rtp.seq.wrapping_sub(expected);
            self.stats.lost += u64::from(missing.min(1000));
            // This packet starts a picture only when the one packet lost was
            // the last of the picture in progress (its marker never came).
            let starts = missing == 1
                && self
                    .partial
                    .as_ref()
                    .is_some_and(|p| p.timestamp != rtp.timestamp);
            self.restart();
            self.spoiled = !starts;
        }
        self.next_seq = Some(rtp.seq.wrapping_add(1));
        if self.spoiled {
            if rtp.marker {
                self.spoiled = false;
                self.stats.skipped += 1;
            }
            return;
        }
        if self
            .partial
            .as_ref()
            .is_some_and(|p| p.timestamp != rtp.timestamp)
        {
            // A picture whose last packet (the marker) went missing.
            out.extend(self.finish());
        }
        let partial = self.partial.get_or_insert_with(|| Partial {
            timestamp: rtp.timestamp,
            data: Vec::new(),
            extra: CodecExtra::None,
        });
        if self
            .depacketizer
            .depacketize(rtp.payload, &mut partial.data, &mut partial.extra)
            .is_err()
        {
            self.stats.bad += 1;
            self.restart();
            // The rest of this picture is spoiled (unless this was its end).
            self.spoiled = !rtp.marker;
            return;
        }
        if rtp.marker {
            out.extend(self.finish());
        }
    }

    /// Drops the picture in progress and waits for a keyframe.
    fn restart(&mut self) {
        self.partial = None;
        self.depacketizer = H264Depacketizer::default();
        self.need_keyframe = true;
    }

    fn finish(&mut self) -> Option<AccessUnit> {
        let p = self.partial.take()?;
        if p.data.is_empty() {
            return None;
        }
        let keyframe = matches!(p.extra, CodecExtra::H264(e) if e.is_keyframe);
        if self.need_keyframe && !keyframe {
            self.stats.skipped += 1;
            return None;
        }
        self.need_keyframe = false;
        let time_90khz = self.tick(p.timestamp);
        self.stats.units += 1;
        Some(AccessUnit {
            data: p.data,
            time_90khz,
            keyframe,
        })
    }

    /// The extended media clock for an RTP timestamp: it follows the
    /// encoder's steps and moves one tick where the stream jumps.
    fn tick(&mut self, ts: u32) -> u64 {
        let t = match self.clock {
            None => 0,
            Some((last, t)) => {
                let step = ts.wrapping_sub(last);
                if step == 0 || step > MAX_STEP_90KHZ {
                    t + 1
                } else {
                    t + u64::from(step)
                }
            }
        };
        self.clock = Some((ts, t));
        t
    }
}
