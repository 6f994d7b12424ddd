//! H.264 access units into MPEG-TS, sans-IO: bytes out, nothing written.
//!
//! MPEG-TS is what a cut power leaves playable: it has no index to write at
//! the end, every 188-byte packet stands alone, and a reader finds the
//! program again at the next PAT/PMT. So the PAT and PMT go first and
//! again before every keyframe, and a file cut anywhere plays up to the
//! last whole picture before the cut.
//!
//! One program, one H.264 stream (PID 0x100, also the PCR's), each access
//! unit one PES packet with its PTS (the pictures come in decoding order
//! with no B-frames — the encoder makes none, UVC cameras neither; RTP
//! carries no DTS — so the PTS is the DTS) and an access
//! unit delimiter in front when the picture has none, as H.264 in MPEG-TS
//! wants. The packets themselves are `mpeg2ts`'s.

use mpeg2ts::es::{StreamId, StreamType};
use mpeg2ts::pes::PesHeader;
use mpeg2ts::time::{ClockReference, Timestamp};
use mpeg2ts::ts::payload::{Bytes, Pat, Pes, Pmt};
use mpeg2ts::ts::{
    AdaptationField, ContinuityCounter, EsInfo, Pid, ProgramAssociation,
    TransportScramblingControl, TsHeader, TsPacket, TsPacketWriter, TsPayload, VersionNumber,
    WriteTsPacket,
};

const PMT_PID: u16 = 0x1000;
const VIDEO_PID: u16 = 0x100;
const PROGRAM: u16 = 1;
/// The PTS runs this far ahead of the PCR (ffmpeg's default mux delay):
/// room for a decoder to have the picture before it is shown.
const PTS_AHEAD_90KHZ: u64 = 63_000;
/// An access unit delimiter (NAL type 9, any slice type).
const AUD: [u8; 6] = [0, 0, 0, 1, 0x09, 0xf0];
/// 33-bit PTS.
const PTS_WRAP: u64 = 1 << 33;

/// Why a picture could not be put into packets (never from a valid
/// picture; a bug shows as this, not a panic).
#[derive(Debug, thiserror::Error)]
#[error("MPEG-TS packet: {0}")]
pub struct TsError(String);

/// The muxer of one file: its continuity counters.
#[derive(Debug, Default)]
pub struct TsMuxer {
    cc_pat: ContinuityCounter,
    cc_pmt: ContinuityCounter,
    cc_video: ContinuityCounter,
}

fn pid(n: u16) -> Result<Pid, TsError> {
    Pid::new(n).map_err(err)
}

fn header(pid_no: u16, cc: &mut ContinuityCounter) -> Result<TsHeader, TsError> {
    let h = TsHeader {
        transport_error_indicator: false,
        transport_priority: false,
        pid: pid(pid_no)?,
        transport_scrambling_control: TransportScramblingControl::NotScrambled,
        continuity_counter: *cc,
    };
    cc.increment();
    Ok(h)
}

fn err(e: mpeg2ts::Error) -> TsError {
    TsError(e.to_string())
}

/// Whether an Annex B access unit starts with an access unit delimiter.
fn has_aud(au: &[u8]) -> bool {
    let nal = match au {
        [0, 0, 1, n, ..] => *n,
        [0, 0, 0, 1, n, ..] => *n,
        _ => return false,
    };
    nal & 0x1f == 9
}

impl TsMuxer {
    pub fn new() -> Self {
        Self::default()
    }

    /// The PAT and the PMT: where a reader starts.
    pub fn tables(&mut self) -> Result<Vec<u8>, TsError> {
        let mut w = TsPacketWriter::new(Vec::with_capacity(2 * TsPacket::SIZE));
        let pat = TsPacket {
            header: header(0, &mut self.cc_pat)?,
            adaptation_field: None,
            payload: Some(TsPayload::Pat(Pat {
                transport_stream_id: 1,
                version_number: VersionNumber::new(),
                table: vec![ProgramAssociation {
                    program_num: PROGRAM,
                    program_map_pid: pid(PMT_PID)?,
                }],
            })),
        };
        let pmt = TsPacket {
            header: header(PMT_PID, &mut self.cc_pmt)?,
            adaptation_field: None,
            payload: Some(TsPayload::Pmt(Pmt {
                program_num: PROGRAM,
                pcr_pid: Some(pid(VIDEO_PID)?),
                version_number: VersionNumber::new(),
                program_info: Vec::new(),
                es_info: vec![EsInfo {
                    stream_type: StreamType::H264,
                    elementary_pid: pid(VIDEO_PID)?,
                    descriptors: Vec::new(),
                }],
            })),
        };
        w.write_ts_packet(&pat).map_err(err)?;
        w.write_ts_packet(&pmt).map_err(err)?;
        Ok(w.into_stream())
    }

    /// One picture (Annex B) shown at `time_90khz` from the file's start:
    /// the tables first when it is a keyframe, then its PES packet in TS
    /// packets, the first carrying the PCR.
    pub fn access_unit(
        &mut self,
        au: &[u8],
        time_90khz: u64,
        keyframe: bool,
    ) -> Result<Vec<u8>, TsError> {
        let mut out = if keyframe { self.tables()? } else { Vec::new() };
        let mut data = Vec::with_capacity(au.len() + AUD.len());
        if !has_aud(au) {
            data.extend_from_slice(&AUD);
        }
        data.extend_from_slice(au);
        let pts = (time_90khz + PTS_AHEAD_90KHZ) % PTS_WRAP;
        let pes_header = PesHeader {
            stream_id: StreamId::new(StreamId::VIDEO_MIN),
            priority: false,
            data_alignment_indicator: true,
            copyright: false,
            original_or_copy: true,
            pts: Some(Timestamp::new(pts).map_err(err)?),
            dts: None,
            escr: None,
        };
        let adaptation = AdaptationField {
            discontinuity_indicator: false,
            random_access_indicator: keyframe,
            es_priority_indicator: false,
            pcr: Some(ClockReference::new((time_90khz % PTS_WRAP) * 300).map_err(err)?),
            opcr: None,
            splice_countdown: None,
            transport_private_data: Vec::new(),
            extension: None,
        };
        // The first packet: 4 header bytes, the adaptation field with the
        // PCR (8), the PES header with its PTS (14), then the picture.
        let first_room = Bytes::MAX_SIZE - 8 - 14;
        let (first, mut rest) = data.split_at(data.len().min(first_room));
        let mut w = TsPacketWriter::new(Vec::with_capacity(
            (data.len() / Bytes::MAX_SIZE + 2) * TsPacket::SIZE,
        ));
        w.write_ts_packet(&TsPacket {
            header: header(VIDEO_PID, &mut self.cc_video)?,
            adaptation_field: Some(adaptation),
            payload: Some(TsPayload::PesStart(Pes {
                header: pes_header,
                // 0: unbounded, as video PES packets may be.
                pes_packet_len: 0,
                data: Bytes::new(first).map_err(err)?,
            })),
        })
        .map_err(err)?;
        while !rest.is_empty() {
            // A short last packet is padded by an adaptation field, which
            // needs at least one byte of the packet.
            let n = if rest.len() >= Bytes::MAX_SIZE {
                Bytes::MAX_SIZE
            } else {
                rest.len().min(Bytes::MAX_SIZE - 1)
            };
            let (chunk, more) = rest.split_at(n);
            rest = more;
            w.write_ts_packet(&TsPacket {
                header: header(VIDEO_PID, &mut self.cc_video)?,
                adaptation_field: None,
                payload: Some(TsPayload::PesContinuation(Bytes::new(chunk).map_err(err)?)),
            })
            .map_err(err)?;
        }
        out.extend(w.into_stream());
        Ok(out)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use mpeg2ts::pes::{PesPacketReader, ReadPesPacket};
    use mpeg2ts::ts::{ReadTsPacket, TsPacketReader};

    /// A fake picture: start code, NAL header, then `len` bytes.
    fn picture(nal: u8, len: usize) -> Vec<u8> {
        let mut p = vec![0, 0, 0, 1, nal];
        p.extend((0..len).map(|i| (i % 251) as u8 | 1));
        p
    }

    #[test]
    fn pictures_read_back_whole_with_their_times() {
        let mut m = TsMuxer::new();
        let mut file = Vec::new();
        let sizes = [0, 1, 161, 162, 163, 183, 184, 185, 346, 5000, 40_000];
        for (i, &n) in sizes.iter().enumerate() {
            let key = i % 4 == 0;
            file.extend(
                m.access_unit(
                    &picture(if key { 0x65 } else { 0x41 }, n),
                    i as u64 * 3000,
                    key,
                )
                .unwrap(),
            );
        }
        assert_eq!(file.len() % TsPacket::SIZE, 0);
        let mut r = PesPacketReader::new(TsPacketReader::new(&file[..]));
        for (i, &n) in sizes.iter().enumerate() {
            let p = r
                .read_pes_packet()
                .unwrap()
                .expect("a PES packet per picture");
            assert_eq!(
                p.header.pts.unwrap().as_u64(),
                i as u64 * 3000 + PTS_AHEAD_90KHZ
            );
            assert_eq!(&p.data[..AUD.len()], &AUD, "the delimiter first");
            assert_eq!(p.data.len(), AUD.len() + 5 + n, "picture {i} of {n} bytes");
        }
        assert!(r.read_pes_packet().unwrap().is_none());
    }

    #[test]
    fn tables_before_keyframes_only_and_counters_continue() {
        let mut m = TsMuxer::new();
        let key = m.access_unit(&picture(0x65, 10), 0, true).unwrap();
        let delta = m.access_unit(&picture(0x41, 10), 3000, false).unwrap();
        let pids = |b: &[u8]| {
            let mut r = TsPacketReader::new(b);
            let mut v = Vec::new();
            while let Some(p) = r.read_ts_packet().unwrap() {
                v.push((p.header.pid.as_u16(), p.header.continuity_counter.as_u8()));
            }
            v
        };
        assert_eq!(pids(&key), [(0, 0), (PMT_PID, 0), (VIDEO_PID, 0)]);
        let mut both = key.clone();
        both.extend(&delta);
        assert_eq!(pids(&both)[3..], [(VIDEO_PID, 1)]);
    }

    #[test]
    fn a_delimiter_already_there_is_not_doubled() {
        let mut m = TsMuxer::new();
        let mut au = AUD.to_vec();
        au.extend(picture(0x65, 20));
        let b = m.access_unit(&au, 0, true).unwrap();
        let mut r = PesPacketReader::new(TsPacketReader::new(&b[..]));
        let p = r.read_pes_packet().unwrap().unwrap();
        assert_eq!(p.data, au);
    }
}
