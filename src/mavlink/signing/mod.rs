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
//!
//! One file per concern: `key` (the key and the signature function), `frame`
//! (where the signature sits in a raw frame), `verify` ([`Verifier`]), `sign`
//! ([`Signer`]) and `store` ([`SigningStore`]); everything public is
//! re-exported here.

mod frame;
mod key;
mod sign;
mod store;
mod verify;

pub use frame::is_signed;
pub use key::{KEY_LEN, SigningKey};
pub use sign::{RESERVATION_AHEAD, RESERVATION_MARGIN, Signer};
pub use store::{SigningError, SigningStore, SigningWarning};
pub use verify::{
    MAX_STREAMS, NEW_STREAM_WINDOW, REPLAY_RESERVATION_AHEAD, ReplayState, Verdict, Verifier,
};

/// The Unix time of the MAVLink signing epoch, 2015-01-01T00:00:00Z, in µs.
const EPOCH_2015_UNIX_US: u64 = 1_420_070_400 * 1_000_000;
/// Timestamps are 48 bits on the wire.
pub const MAX_TIMESTAMP: u64 = (1 << 48) - 1;

/// MAVLink signing time (10 µs units since 2015-01-01T00:00:00Z) of a Unix
/// time in µs. Times before 2015 give 0.
pub fn timestamp_from_unix_us(unix_us: u64) -> u64 {
    unix_us.saturating_sub(EPOCH_2015_UNIX_US) / 10
}
