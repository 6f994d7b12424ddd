//! MAVLink 2 message signing, sans-IO, plus the two small files that make it
//! survive a restart.
//!
//! Owns: the signing key type ([`SigningKey`]), checking incoming signed
//! frames against a key and per-stream replay state ([`Verifier`]), signing
//! our outgoing frames with timestamps that never go backwards, even across
//! restarts ([`Signer`]), and reading and writing `signing.key`,
//! `signing.timestamp` and `signing.replay` in the data directory
//! ([`SigningStore`]).
//!
//! Replay protection survives restarts the way our own timestamps do: by
//! write-ahead reservations. Before a frame is acted on whose timestamp
//! passes its stream's reservation, the caller persists a new one
//! [`REPLAY_RESERVATION_AHEAD`] beyond it ([`Verifier::take_reservation`]);
//! after a restart (even `kill -9` or a power cut) every stream refuses
//! timestamps at or below what was persisted, so nothing accepted before the
//! restart is accepted again.
//!
//! It never reads a clock: every "now" is a MAVLink signing timestamp passed
//! in by the caller (see [`timestamp_from_unix_us`]), so tests and replays
//! drive it with synthetic time. It never logs, formats or Debug-prints a key
//! (its `Debug` is redacted, and error messages never quote key files), it
//! never panics on any input, and it never decides what to do with a frame:
//! it returns a [`Verdict`] and the vehicle core applies the policy
//! (which unsigned messages may only watch, what gets logged).
//!
//! Why not `mavlink_core::SigningData`: it reads the system clock, cannot be
//! given a time, keeps its state behind a mutex and has no notion of a
//! persisted timestamp, so a vehicle that restarts (or whose clock is behind
//! a SETUP_SIGNING `initial_timestamp`) would sign with timestamps the ground
//! station has already seen and have its frames dropped as replays.

use std::collections::HashMap;
use std::fmt;
use std::fs::{self, File, OpenOptions, Permissions};
use std::io::{self, Read, Write};
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

use mavlink_core::{Message, calculate_crc};
use sha2::{Digest, Sha256};

use crate::dialect::neptunus::MavMessage;

pub const KEY_LEN: usize = 32;

/// The Unix time of the MAVLink signing epoch, 2015-01-01T00:00:00Z, in µs.
const EPOCH_2015_UNIX_US: u64 = 1_420_070_400 * 1_000_000;
/// Timestamps are 48 bits on the wire.
pub const MAX_TIMESTAMP: u64 = (1 << 48) - 1;
/// A stream we have not seen before may be this far behind the newest
/// timestamp (60 s in 10 µs units), as the MAVLink spec and pymavlink do.
pub const NEW_STREAM_WINDOW: u64 = 6_000_000;
/// When a timestamp comes this close to the persisted reservation (30 s)…
pub const RESERVATION_MARGIN: u64 = 3_000_000;
/// …a new reservation this far ahead of it (60 s) is handed out for persisting.
pub const RESERVATION_AHEAD: u64 = 6_000_000;
/// Replay state is kept for at most this many (link id, sysid, compid) streams.
pub const MAX_STREAMS: usize = 256;
/// An incoming stream's persisted reservation is set this far (5 s) beyond
/// the timestamp that passed the previous one: normally one small synced
/// write per few seconds, and after an unclean stop a stream's genuine frames
/// are refused for at most this long (its clock must pass the reservation).
pub const REPLAY_RESERVATION_AHEAD: u64 = 500_000;

const STX_V1: u8 = mavlink_core::MAV_STX;
const STX_V2: u8 = mavlink_core::MAV_STX_V2;
const V1_HEADER_LEN: usize = 6;
const V2_HEADER_LEN: usize = 10;
const CRC_LEN: usize = 2;
/// Link id (1), timestamp (6), signature (6).
const SIGNATURE_BLOCK_LEN: usize = 13;
const TIMESTAMP_LEN: usize = 6;
const SIGNATURE_LEN: usize = 6;
const IFLAG_SIGNED: u8 = 0x01;

/// MAVLink signing time (10 µs units since 2015-01-01T00:00:00Z) of a Unix
/// time in µs. Times before 2015 give 0.
pub fn timestamp_from_unix_us(unix_us: u64) -> u64 {
    unix_us.saturating_sub(EPOCH_2015_UNIX_US) / 10
}

// ---------------------------------------------------------------------------
// key
// ---------------------------------------------------------------------------

/// A 32-byte MAVLink signing key. Never all zeros (that means "signing off").
/// Its `Debug` prints `SigningKey(<redacted>)`; it has no `Display`.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; KEY_LEN]);

impl SigningKey {
    /// `None` for the all-zero key, which SETUP_SIGNING uses to turn signing off.
    pub fn from_bytes(b: [u8; KEY_LEN]) -> Option<Self> {
        if b == [0; KEY_LEN] {
            None
        } else {
            Some(Self(b))
        }
    }

    /// SHA-256 of the UTF-8 passphrase: how QGroundControl and MAVProxy
    /// (`signing setup PASSPHRASE`) turn a passphrase into a key, so the same
    /// passphrase typed on both sides gives the same key.
    pub fn from_passphrase(p: &str) -> Self {
        // SHA-256 of anything is all zeros with probability 2^-256.
        Self(Sha256::digest(p.as_bytes()).into())
    }

    pub fn as_bytes(&self) -> &[u8; KEY_LEN] {
        &self.0
    }

    /// The first 6 bytes of SHA-256(key ‖ frame through CRC ‖ link id ‖ timestamp).
    fn signature(
        &self,
        through_crc: &[u8],
        link_id: u8,
        timestamp: &[u8; TIMESTAMP_LEN],
    ) -> [u8; SIGNATURE_LEN] {
        let digest = Sha256::new()
            .chain_update(self.0)
            .chain_update(through_crc)
            .chain_update([link_id])
            .chain_update(timestamp)
            .finalize();
        let mut sig = [0; SIGNATURE_LEN];
        sig.copy_from_slice(&digest[..SIGNATURE_LEN]);
        sig
    }
}

impl fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("SigningKey(<redacted>)")
    }
}

// ---------------------------------------------------------------------------
// frame layout
// ---------------------------------------------------------------------------

/// Where things are in one complete frame.
enum Layout {
    Unsigned,
    Signed {
        /// End of the CRC: everything before is covered by the signature.
        crc_end: usize,
    },
}

/// Checks that `raw` is exactly one frame (by its own length byte and
/// flags); the CRC is not checked (the signature covers it).
fn layout(raw: &[u8]) -> Option<Layout> {
    let payload_len = usize::from(*raw.get(1)?);
    match *raw.first()? {
        STX_V1 => (raw.len() == V1_HEADER_LEN + payload_len + CRC_LEN).then_some(Layout::Unsigned),
        STX_V2 => {
            let crc_end = V2_HEADER_LEN + payload_len + CRC_LEN;
            if raw.get(2)? & IFLAG_SIGNED == 0 {
                (raw.len() == crc_end).then_some(Layout::Unsigned)
            } else {
                (raw.len() == crc_end + SIGNATURE_BLOCK_LEN).then_some(Layout::Signed { crc_end })
            }
        }
        _ => None,
    }
}

fn read_timestamp(bytes: &[u8; TIMESTAMP_LEN]) -> u64 {
    let mut le = [0u8; 8];
    le[..TIMESTAMP_LEN].copy_from_slice(bytes);
    u64::from_le_bytes(le)
}

/// Compares without an early exit, so the time taken does not tell an
/// attacker how many leading signature bytes were right.
fn same_signature(a: &[u8; SIGNATURE_LEN], b: &[u8; SIGNATURE_LEN]) -> bool {
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

// ---------------------------------------------------------------------------
// verifying
// ---------------------------------------------------------------------------

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
    pub streams: std::collections::BTreeMap<(u8, u8, u8), u64>,
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
    /// [`FrameDecoder`](super::FrameDecoder) delivers it in
    /// [`Frame::raw`](super::Frame::raw); `now_ts` = our clock as a signing
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

// ---------------------------------------------------------------------------
// signing
// ---------------------------------------------------------------------------

/// Signs our outgoing MAVLink 2 frames with strictly increasing timestamps.
///
/// A timestamp that goes backwards, even across a restart, gets our frames
/// dropped as replays by every ground station that saw the earlier ones. So
/// the signer hands out *reservations*: a timestamp ahead of every one used,
/// which the caller persists ([`SigningStore::save_reservation`]) before the
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

    /// Turns an unsigned MAVLink 2 frame (as [`encode_v2`](super::encode_v2)
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
    /// [`is_signed`] to tell.
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

/// `raw` is a MAVLink 2 frame with the signed flag set (signature not checked).
pub fn is_signed(raw: &[u8]) -> bool {
    matches!(layout(raw), Some(Layout::Signed { .. }))
}

// ---------------------------------------------------------------------------
// files
// ---------------------------------------------------------------------------

/// Something about the key file the operator should fix, though the key
/// still loaded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SigningWarning {
    /// Group or others may read the key file (`mode` = its permission bits).
    KeyFileExposed { path: PathBuf, mode: u32 },
}

impl fmt::Display for SigningWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::KeyFileExposed { path, mode } => write!(
                f,
                "signing key file {} can be read by other users (mode {mode:04o}) — \
                 run `chmod 600 {}`, and set a new key if others may have copied it",
                path.display(),
                path.display()
            ),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SigningError {
    #[error(
        "cannot read signing file {}: {source} — check its owner and permissions, \
         or remove it (removing signing.key turns signing off)",
        .path.display()
    )]
    Read { path: PathBuf, source: io::Error },
    #[error(
        "signing key file {} {problem}; it must hold the key as 64 hex digits — \
         set a new key with `neptunus signing set-passphrase PASSPHRASE --data-dir DIR`, \
         or remove the file to turn signing off",
        .path.display()
    )]
    BadKeyFile { path: PathBuf, problem: String },
    #[error(
        "cannot write signing file {}: {source} — check that the data directory \
         exists and is writable by this user (or pass another --data-dir)",
        .path.display()
    )]
    Write { path: PathBuf, source: io::Error },
    #[error(
        "cannot remove signing key file {}: {source} — remove it by hand to turn signing off",
        .path.display()
    )]
    Remove { path: PathBuf, source: io::Error },
    #[error(
        "signing replay file {} {problem}; it is rewritten with the next signed frame \
         (remove it if this repeats)",
        .path.display()
    )]
    BadReplayFile { path: PathBuf, problem: String },
}

/// Files longer than this are not what we wrote; don't read a huge file into memory.
const MAX_FILE_LEN: u64 = 256;
/// `signing.replay`: [`MAX_STREAMS`] lines of at most 32 bytes, and a header.
const MAX_REPLAY_FILE_LEN: u64 = 16 * 1024;
/// First line of `signing.replay`.
const REPLAY_HEADER: &str = "# neptunus signing replay state v1: link_id sysid compid timestamp";

/// The signing files in the data directory:
/// - `signing.key`: the key as 64 lowercase hex digits and a newline, mode
///   0600. Written to a temporary file created 0600 and renamed into place,
///   so it is never readable by others, not even briefly.
/// - `signing.timestamp`: the reservation (see [`Signer`]) as a decimal
///   number and a newline, replaced atomically.
/// - `signing.replay`: the incoming streams' replay reservations (see
///   [`Verifier::take_reservation`]), one `link_id sysid compid timestamp`
///   line each, replaced atomically.
///
/// Every write is synced (file and directory) before returning: a
/// reservation must survive a power cut to keep timestamps from going back
/// and recorded frames from being accepted again.
#[derive(Debug, Clone)]
pub struct SigningStore {
    dir: PathBuf,
}

impl SigningStore {
    pub const KEY_FILE: &'static str = "signing.key";
    pub const TIMESTAMP_FILE: &'static str = "signing.timestamp";
    pub const REPLAY_FILE: &'static str = "signing.replay";

    pub fn new(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
        }
    }

    pub fn key_path(&self) -> PathBuf {
        self.dir.join(Self::KEY_FILE)
    }

    pub fn timestamp_path(&self) -> PathBuf {
        self.dir.join(Self::TIMESTAMP_FILE)
    }

    pub fn replay_path(&self) -> PathBuf {
        self.dir.join(Self::REPLAY_FILE)
    }

    /// The persisted replay state; `Ok(None)` when there is no file yet. An
    /// unreadable or corrupt file is an error (the caller decides: Neptunus
    /// starts with the one-minute stale rule only, and says so).
    pub fn load_replay(&self) -> Result<Option<ReplayState>, SigningError> {
        let path = self.replay_path();
        let Some((text, _)) = read_limited(&path, MAX_REPLAY_FILE_LEN)? else {
            return Ok(None);
        };
        parse_replay(&text)
            .map(Some)
            .map_err(|problem| SigningError::BadReplayFile { path, problem })
    }

    pub fn save_replay(&self, state: &ReplayState) -> Result<(), SigningError> {
        let mut text = String::with_capacity(REPLAY_HEADER.len() + 1 + 24 * state.len());
        text.push_str(REPLAY_HEADER);
        text.push('\n');
        for ((link, sysid, compid), ts) in &state.streams {
            text.push_str(&format!("{link} {sysid} {compid} {ts}\n"));
        }
        write_atomic(&self.dir, Self::REPLAY_FILE, text.as_bytes(), 0o644)
    }

    /// The key, or `None` when there is no key file (or it holds the all-zero
    /// key, which means "signing off"). A key file others can read still
    /// loads, with a `tracing` warning naming the fix; use
    /// [`SigningStore::load_key_checked`] to get the warnings instead.
    pub fn load_key(&self) -> Result<Option<SigningKey>, SigningError> {
        let (key, warnings) = self.load_key_checked()?;
        for w in &warnings {
            tracing::warn!("{w}");
        }
        Ok(key)
    }

    /// [`SigningStore::load_key`], returning the warnings rather than logging them.
    pub fn load_key_checked(
        &self,
    ) -> Result<(Option<SigningKey>, Vec<SigningWarning>), SigningError> {
        let path = self.key_path();
        let Some((text, mode)) = read_small(&path)? else {
            return Ok((None, Vec::new()));
        };
        let bytes = parse_key(&text).map_err(|problem| SigningError::BadKeyFile {
            path: path.clone(),
            problem,
        })?;
        let mut warnings = Vec::new();
        if mode & 0o077 != 0 {
            warnings.push(SigningWarning::KeyFileExposed {
                path,
                mode: mode & 0o7777,
            });
        }
        Ok((SigningKey::from_bytes(bytes), warnings))
    }

    /// Writes the key (mode 0600), or removes the key file for `None`.
    pub fn save_key(&self, key: Option<&SigningKey>) -> Result<(), SigningError> {
        let path = self.key_path();
        let Some(key) = key else {
            return match fs::remove_file(&path) {
                Ok(()) => {
                    sync_dir(&self.dir);
                    Ok(())
                }
                Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
                Err(source) => Err(SigningError::Remove { path, source }),
            };
        };
        let mut text = String::with_capacity(2 * KEY_LEN + 1);
        for b in key.as_bytes() {
            text.push(char::from(HEX_DIGITS[usize::from(b >> 4)]));
            text.push(char::from(HEX_DIGITS[usize::from(b & 0x0f)]));
        }
        text.push('\n');
        write_atomic(&self.dir, Self::KEY_FILE, text.as_bytes(), 0o600)
    }

    /// The persisted reservation; `None` when missing or unreadable (a bad
    /// file is logged as a warning: signing then starts from the clock).
    pub fn load_reservation(&self) -> Option<u64> {
        let path = self.timestamp_path();
        let text = match read_small(&path) {
            Ok(Some((text, _))) => text,
            Ok(None) => return None,
            Err(e) => {
                tracing::warn!("{e}; signing timestamps start from the clock");
                return None;
            }
        };
        match text.trim().parse() {
            Ok(ts) => Some(ts),
            Err(_) => {
                tracing::warn!(
                    "signing timestamp file {} does not hold a decimal number; signing \
                     timestamps start from the clock (it is rewritten with the next signed frame)",
                    path.display()
                );
                None
            }
        }
    }

    pub fn save_reservation(&self, ts: u64) -> Result<(), SigningError> {
        write_atomic(
            &self.dir,
            Self::TIMESTAMP_FILE,
            format!("{ts}\n").as_bytes(),
            0o644,
        )
    }
}

const HEX_DIGITS: &[u8; 16] = b"0123456789abcdef";

/// Parses `signing.replay`; the problem names the line.
fn parse_replay(text: &str) -> Result<ReplayState, String> {
    let mut lines = text.lines();
    if lines.next().map(str::trim) != Some(REPLAY_HEADER) {
        return Err("does not start with the replay-state header".to_owned());
    }
    let mut state = ReplayState::default();
    for (i, line) in lines.enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let bad = || format!("line {} is not `link_id sysid compid timestamp`", i + 2);
        let fields: Vec<&str> = line.split_ascii_whitespace().collect();
        let [link, sysid, compid, ts] = fields[..] else {
            return Err(bad());
        };
        let key = (
            link.parse().map_err(|_| bad())?,
            sysid.parse().map_err(|_| bad())?,
            compid.parse().map_err(|_| bad())?,
        );
        let ts: u64 = ts.parse().map_err(|_| bad())?;
        if ts > MAX_TIMESTAMP {
            return Err(format!("line {} has a timestamp beyond 48 bits", i + 2));
        }
        state.streams.insert(key, ts);
    }
    Ok(state)
}

/// The file's text and permission bits, `None` if it does not exist.
fn read_small(path: &Path) -> Result<Option<(String, u32)>, SigningError> {
    read_limited(path, MAX_FILE_LEN)
}

/// [`read_small`] with another size limit.
fn read_limited(path: &Path, max_len: u64) -> Result<Option<(String, u32)>, SigningError> {
    let read_err = |source| SigningError::Read {
        path: path.to_path_buf(),
        source,
    };
    let file = match File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(read_err(e)),
    };
    let mode = file.metadata().map_err(read_err)?.permissions().mode();
    let mut bytes = Vec::new();
    file.take(max_len + 1)
        .read_to_end(&mut bytes)
        .map_err(read_err)?;
    if bytes.len() as u64 > max_len {
        return Err(read_err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("longer than {max_len} bytes"),
        )));
    }
    // Not UTF-8 is reported by the parsers as "not hex"/"not a number".
    Ok(Some((String::from_utf8_lossy(&bytes).into_owned(), mode)))
}

/// Parses 64 hex digits (either case) with optional surrounding whitespace.
/// The problem it returns never quotes the file's content.
fn parse_key(text: &str) -> Result<[u8; KEY_LEN], String> {
    let digits = text.trim().as_bytes();
    if digits.is_empty() {
        return Err("is empty".to_owned());
    }
    if let Some(pos) = digits.iter().position(|b| !b.is_ascii_hexdigit()) {
        return Err(format!(
            "has a character that is not a hex digit at position {}",
            pos + 1
        ));
    }
    if digits.len() != 2 * KEY_LEN {
        return Err(format!("holds {} hex digits, not 64", digits.len()));
    }
    let mut key = [0u8; KEY_LEN];
    for (byte, pair) in key.iter_mut().zip(digits.chunks_exact(2)) {
        *byte = (hex_value(pair[0]) << 4) | hex_value(pair[1]);
    }
    Ok(key)
}

fn hex_value(digit: u8) -> u8 {
    match digit {
        b'0'..=b'9' => digit - b'0',
        b'a'..=b'f' => digit - b'a' + 10,
        b'A'..=b'F' => digit - b'A' + 10,
        _ => 0,
    }
}

/// Writes `dir/name` by way of `dir/name.tmp`, created with `mode` (and
/// chmod'ed to it whatever the umask), synced, then renamed over the old file.
fn write_atomic(dir: &Path, name: &str, contents: &[u8], mode: u32) -> Result<(), SigningError> {
    let path = dir.join(name);
    let tmp = dir.join(format!("{name}.tmp"));
    let write_err = |p: &Path| {
        let p = p.to_path_buf();
        move |source| SigningError::Write { path: p, source }
    };
    fs::create_dir_all(dir).map_err(write_err(dir))?;
    // A temporary file left by a crash may have other permissions;
    // create_new with our mode guarantees ours.
    if let Err(e) = fs::remove_file(&tmp)
        && e.kind() != io::ErrorKind::NotFound
    {
        return Err(write_err(&tmp)(e));
    }
    let result = (|| {
        let mut file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(mode)
            .open(&tmp)?;
        file.set_permissions(Permissions::from_mode(mode))?;
        file.write_all(contents)?;
        file.sync_all()?;
        fs::rename(&tmp, &path)
    })();
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(write_err(&path)(e));
    }
    sync_dir(dir);
    Ok(())
}

/// Makes a rename or removal durable. Best effort: some file systems cannot
/// sync a directory, and the data is already written.
fn sync_dir(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_match_the_crate() {
        assert_eq!(
            SIGNATURE_BLOCK_LEN,
            mavlink_core::consts::v2::SIGNATURE_SIZE
        );
        assert_eq!(
            TIMESTAMP_LEN,
            mavlink_core::consts::v2::SIGNATURE_TIMESTAMP_SIZE
        );
        assert_eq!(
            SIGNATURE_LEN,
            mavlink_core::consts::v2::SIGNATURE_VALUE_SIZE
        );
        assert_eq!(IFLAG_SIGNED, mavlink_core::consts::v2::IFLAG_SIGNED);
    }

    #[test]
    fn key_parsing_never_quotes_the_file() {
        let secret = "zz".repeat(32);
        let err = parse_key(&secret).expect_err("not hex");
        assert!(!err.contains("zz"), "{err}");
        assert_eq!(parse_key(&"Ab".repeat(32)), Ok([0xab; 32]));
        assert!(parse_key(&"ab".repeat(31)).is_err());
        assert!(parse_key("").is_err());
    }
}
