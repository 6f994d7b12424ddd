//! Checking incoming signed frames: the signature, then the replay state of
//! each (link id, sysid, compid) stream.
//!
//! Owns [`Verifier`], its [`Verdict`] and the persisted form of its replay
//! state ([`ReplayState`]). It never decides what to do with a frame (the
//! vehicle core applies the policy) and never reads a clock: `now_ts` is
//! passed in.

use std::collections::{BTreeMap, HashMap};
use std::fmt;

use super::frame::{
    Layout, SIGNATURE_BLOCK_LEN, SIGNATURE_LEN, TIMESTAMP_LEN, layout, read_timestamp,
    same_signature,
};
use super::key::SigningKey;

/// A stream we have not seen before may be this far behind the newest
/// timestamp (60 s in 10 µs units), as the MAVLink spec and pymavlink do.
pub const NEW_STREAM_WINDOW: u64 = 6_000_000;
/// Replay state is kept for at most this many (link id, sysid, compid) streams.
pub const MAX_STREAMS: usize = 256;
/// An incoming stream's persisted reservation is set this far (5 s) beyond
/// the timestamp that passed the previous one: normally one small synced
/// write per few seconds, and after an unclean stop a stream's genuine frames
/// are refused for at most this long (its clock must pass the reservation).
pub const REPLAY_RESERVATION_AHEAD: u64 = 500_000;

/// What [`Verifier::check`] made of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// MAVLink 1, or MAVLink 2 without the signed flag.
    Unsigned,
    /// Signed with our key, and newer than anything of its stream.
    Valid { link_id: u8, timestamp: u64 },
    /// Signed, but not with our key (or altered on the way).
    BadSignature,
    /// Correctly signed, but not newer than the last frame of its
    /// (link id, sysid, compid) stream: a replay or a duplicate.
    Replayed,
    /// Correctly signed, first of its stream, but more than
    /// [`NEW_STREAM_WINDOW`] behind the newest timestamp.
    TooOld,
    /// Not exactly one MAVLink frame.
    Malformed,
}

/// (link id, sysid, compid)
type StreamKey = (u8, u8, u8);

#[derive(Debug, Clone, Copy)]
struct Stream {
    last_timestamp: u64,
    /// Value of [`Verifier::tick`] when last accepted, for LRU eviction.
    used: u64,
    /// ≥ `last_timestamp` once persisted: what a restart starts from.
    reserved: u64,
}

/// The replay state that survives a restart: for each (link id, sysid,
/// compid) stream, a timestamp at or above the last one accepted. A restarted
/// [`Verifier`] refuses every frame of a stream at or below it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReplayState {
    pub streams: BTreeMap<(u8, u8, u8), u64>,
}

impl ReplayState {
    pub fn is_empty(&self) -> bool {
        self.streams.is_empty()
    }

    pub fn len(&self) -> usize {
        self.streams.len()
    }
}

/// Checks incoming signed frames against one key, keeping the replay state
/// of each (link id, sysid, compid) stream. One per key; the state is only
/// changed by frames found [`Verdict::Valid`], so nobody without the key can
/// influence it.
pub struct Verifier {
    key: SigningKey,
    /// The newest timestamp of any valid frame.
    newest: u64,
    streams: HashMap<StreamKey, Stream>,
    tick: u64,
    /// A stream passed its reservation: [`Verifier::take_reservation`] has one.
    reservation_due: bool,
}

impl fmt::Debug for Verifier {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Verifier")
            .field("key", &self.key)
            .field("newest", &self.newest)
            .field("streams", &self.streams.len())
            .finish()
    }
}

impl Verifier {
    pub fn new(key: SigningKey) -> Self {
        Self {
            key,
            newest: 0,
            streams: HashMap::new(),
            tick: 0,
            reservation_due: false,
        }
    }

    /// A verifier that starts where a persisted [`ReplayState`] left off:
    /// each stream refuses timestamps at or below its entry, and new streams
    /// are measured against the newest entry too. Keeps the
    /// [`MAX_STREAMS`] newest entries of an oversized state.
    pub fn with_replay_state(key: SigningKey, state: &ReplayState) -> Self {
        let mut v = Self::new(key);
        let mut entries: Vec<_> = state.streams.iter().map(|(k, ts)| (*k, *ts)).collect();
        entries.sort_by_key(|&(_, ts)| ts);
        let skip = entries.len().saturating_sub(MAX_STREAMS);
        for (stream, ts) in entries.into_iter().skip(skip) {
            v.tick += 1;
            v.streams.insert(
                stream,
                Stream {
                    last_timestamp: ts,
                    used: v.tick,
                    reserved: ts,
                },
            );
            v.newest = v.newest.max(ts);
        }
        v
    }

    /// `raw` = exactly one complete MAVLink frame (v1 or v2), as
    /// [`FrameDecoder`](crate::mavlink::FrameDecoder) delivers it in
    /// [`Frame::raw`](crate::mavlink::Frame::raw); `now_ts` = our clock as a signing
    /// timestamp.
    ///
    /// The signature is checked first, so [`Verdict::Replayed`] and
    /// [`Verdict::TooOld`] always mean "genuinely signed with our key":
    /// worth telling apart from forgeries in a log.
    pub fn check(&mut self, raw: &[u8], now_ts: u64) -> Verdict {
        let crc_end = match layout(raw) {
            None => return Verdict::Malformed,
            Some(Layout::Unsigned) => return Verdict::Unsigned,
            Some(Layout::Signed { crc_end }) => crc_end,
        };
        let Some((through_crc, block)) = raw.split_at_checked(crc_end) else {
            return Verdict::Malformed;
        };
        let Ok(block) = <&[u8; SIGNATURE_BLOCK_LEN]>::try_from(block) else {
            return Verdict::Malformed;
        };
        let link_id = block[0];
        let mut ts_bytes = [0u8; TIMESTAMP_LEN];
        ts_bytes.copy_from_slice(&block[1..1 + TIMESTAMP_LEN]);
        let mut given = [0u8; SIGNATURE_LEN];
        given.copy_from_slice(&block[1 + TIMESTAMP_LEN..]);
        if !same_signature(&self.key.signature(through_crc, link_id, &ts_bytes), &given) {
            return Verdict::BadSignature;
        }

        let timestamp = read_timestamp(&ts_bytes);
        // layout() checked the frame is v2, so bytes 5 and 6 are sysid and compid.
        let stream = (link_id, raw[5], raw[6]);
        match self.streams.get(&stream) {
            Some(s) if timestamp <= s.last_timestamp => return Verdict::Replayed,
            Some(_) => {}
            None => {
                let newest = self.newest.max(now_ts);
                if timestamp.saturating_add(NEW_STREAM_WINDOW) < newest {
                    return Verdict::TooOld;
                }
                if self.streams.len() >= MAX_STREAMS {
                    self.evict_least_recently_used();
                }
            }
        }
        self.tick += 1;
        let reserved = self.streams.get(&stream).map_or(0, |s| s.reserved);
        let reserved = if timestamp > reserved {
            self.reservation_due = true;
            timestamp.saturating_add(REPLAY_RESERVATION_AHEAD)
        } else {
            reserved
        };
        self.streams.insert(
            stream,
            Stream {
                last_timestamp: timestamp,
                used: self.tick,
                reserved,
            },
        );
        self.newest = self.newest.max(timestamp);
        Verdict::Valid { link_id, timestamp }
    }

    /// After a [`Verdict::Valid`]: the replay state to persist *before the
    /// frame is acted on*, when its timestamp passed its stream's reservation
    /// (the first frame of every stream does). `None` most of the time.
    ///
    /// Streams within half a margin of their own reservation are topped up in
    /// the same write, so several live stations share one write.
    pub fn take_reservation(&mut self) -> Option<ReplayState> {
        if !std::mem::take(&mut self.reservation_due) {
            return None;
        }
        for s in self.streams.values_mut() {
            if s.last_timestamp
                .saturating_add(REPLAY_RESERVATION_AHEAD / 2)
                >= s.reserved
            {
                s.reserved = s.last_timestamp.saturating_add(REPLAY_RESERVATION_AHEAD);
            }
        }
        Some(ReplayState {
            streams: self.streams.iter().map(|(k, s)| (*k, s.reserved)).collect(),
        })
    }

    /// The exact last timestamp of every stream: what a graceful shutdown
    /// persists, so a clean restart refuses no genuine frame.
    pub fn replay_state(&self) -> ReplayState {
        ReplayState {
            streams: self
                .streams
                .iter()
                .map(|(k, s)| (*k, s.last_timestamp))
                .collect(),
        }
    }

    /// How many streams have replay state (at most [`MAX_STREAMS`]).
    pub fn stream_count(&self) -> usize {
        self.streams.len()
    }

    /// An evicted stream's frames count as a new stream again, so they are
    /// only refused when older than [`NEW_STREAM_WINDOW`]: only a sender with
    /// the key can make streams, so this takes more than 256 live stations
    /// sharing one key.
    fn evict_least_recently_used(&mut self) {
        if let Some(oldest) = self
            .streams
            .iter()
            .min_by_key(|(_, s)| s.used)
            .map(|(k, _)| *k)
        {
            self.streams.remove(&oldest);
        }
    }
}
