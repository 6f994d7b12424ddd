//! Message signing on the MAVLink side of the wiring: signature checks on
//! what comes in, signatures on what goes out, and the key, timestamp and
//! replay files behind them.

use std::time::Duration;

use super::AppError;
use crate::eventlog::{EventLog, LogEvent};
use crate::mavlink::frame::Frame;
use crate::mavlink::signing::{
    REPLAY_RESERVATION_AHEAD, ReplayState, Signer, SigningError, SigningKey, SigningStore, Verdict,
    Verifier, timestamp_from_unix_us,
};
use crate::vehicle::machine::Now;

/// Signature checks on what comes in, signatures on what goes out, and the
/// key, timestamp and replay files behind them. The vehicle core decides
/// policy from the per-frame result; this only verifies, signs and persists.
pub(super) struct LinkSigning {
    store: SigningStore,
    keyed: Option<(Verifier, Signer)>,
    /// Floor for a new key's timestamps: ours never go backwards.
    last_timestamp: u64,
    /// Incoming replay state loaded at start, for the first verifier (a key
    /// set later by SETUP_SIGNING inherits the running verifier's state).
    replay: ReplayState,
    rejected: u64,
    last_report: Option<Duration>,
    /// When a replay reservation last failed to be written (logged at most this often).
    last_replay_error: Option<Duration>,
}

/// Rejected signatures are logged at most this often.
const SIGNATURE_REPORT: Duration = Duration::from_secs(5);

impl LinkSigning {
    /// The link signing at start, from the files in `data_dir`, and whether
    /// control traffic must be signed (a key is set, or one may exist that
    /// cannot be read: then nothing verifies and MAVLink stations only watch).
    pub(super) fn start(data_dir: &std::path::Path) -> (Self, bool) {
        let (signing, fail_closed) = match Self::load(SigningStore::new(data_dir)) {
            Ok(s) => (s, false),
            Err(e) => {
                // A data directory that cannot hold a file holds no key either.
                let no_key = matches!(&e, AppError::Signing(SigningError::Read { source, .. })
                    if matches!(source.kind(), std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory));
                if no_key {
                    tracing::warn!("message signing off: {e}");
                } else {
                    // A key may exist that we cannot read: never run open. Only
                    // signed traffic may control, and nothing can be signed, so
                    // MAVLink stations watch; the browser HMI still controls.
                    tracing::error!(
                        "message signing key unusable: {e} — MAVLink ground stations may only watch until it is fixed; the browser HMI can still control after the pilot login"
                    );
                }
                (Self::unkeyed(SigningStore::new(data_dir)), !no_key)
            }
        };
        if signing.active() {
            tracing::info!(
                "message signing on: unsigned MAVLink stations may watch but not control; browser \
                 (HMI) sessions may control only after the pilot login; a signed frame is accepted \
                 once (replays refused, also across restarts; after an unclean stop a station's \
                 signed frames may be refused for up to {} s)",
                REPLAY_RESERVATION_AHEAD / 100_000
            );
        } else {
            tracing::warn!(
                "message signing off: any station that can reach a MAVLink endpoint and uses an \
                 allowed system id (SYSID_MYGCS, NEPT_GCS_ALLOWn) may control the vehicle — set a \
                 key with `neptunus signing set-passphrase` on untrusted links"
            );
        }
        let must_sign = signing.active() || fail_closed;
        (signing, must_sign)
    }

    /// No key and no replay state: signing off, or a key we cannot read
    /// (then the core is told signing is on, and nothing verifies).
    fn unkeyed(store: SigningStore) -> Self {
        Self {
            store,
            keyed: None,
            last_timestamp: 0,
            replay: ReplayState::default(),
            rejected: 0,
            last_report: None,
            last_replay_error: None,
        }
    }

    fn load(store: SigningStore) -> Result<Self, AppError> {
        let key = store.load_key()?;
        let reservation = store.load_reservation();
        // Loaded without a key too: a key set later by SETUP_SIGNING may be
        // the one frames were recorded under.
        let replay = load_replay(&store, key.is_some());
        let mut s = Self {
            store,
            keyed: None,
            last_timestamp: reservation.unwrap_or(0),
            replay,
            rejected: 0,
            last_report: None,
            last_replay_error: None,
        };
        if let Some(key) = key {
            s.keyed = Some(s.pair(key));
        }
        Ok(s)
    }

    fn pair(&self, key: SigningKey) -> (Verifier, Signer) {
        let reservation = self.store.load_reservation().max(Some(self.last_timestamp));
        // Frames accepted under the old key stay refused under the new one.
        let replay = match &self.keyed {
            Some((verifier, _)) => verifier.replay_state(),
            None => self.replay.clone(),
        };
        (
            Verifier::with_replay_state(key.clone(), &replay),
            Signer::new(key, 0, reservation),
        )
    }

    pub(super) fn active(&self) -> bool {
        self.keyed.is_some()
    }

    /// Some(signed) for a frame to hand to the vehicle, None for one to drop.
    pub(super) fn check(&mut self, frame: &Frame, now: Now, events: &EventLog) -> Option<bool> {
        let Some((verifier, _)) = self.keyed.as_mut() else {
            return Some(false);
        };
        let why = match verifier.check(&frame.raw, timestamp_from_unix_us(now.unix_us)) {
            Verdict::Valid { .. } => {
                // Write-ahead: the reservation is on disk before the frame acts.
                if let Some(state) = verifier.take_reservation()
                    && let Err(e) = self.store.save_replay(&state)
                    && self
                        .last_replay_error
                        .is_none_or(|t| now.mono.saturating_sub(t) >= SIGNATURE_REPORT)
                {
                    // Refusing the frame would cost the pilot control of the
                    // vehicle whenever the disk fails; accepting it weakens
                    // only replay protection across a restart. Say so.
                    self.last_replay_error = Some(now.mono);
                    tracing::error!(
                        "{e}; signed frames are still accepted, but frames accepted since the \
                         last successful write could be replayed after a restart"
                    );
                }
                return Some(true);
            }
            Verdict::Unsigned => return Some(false),
            Verdict::BadSignature => "bad signature",
            Verdict::Replayed => {
                "replayed (timestamp not newer than the last of its stream, in this run or before a restart)"
            }
            Verdict::TooOld => "stale timestamp (more than 1 min old)",
            Verdict::Malformed => "malformed signature",
        };
        self.rejected += 1;
        if self
            .last_report
            .is_none_or(|t| now.mono.saturating_sub(t) >= SIGNATURE_REPORT)
        {
            self.last_report = Some(now.mono);
            let detail = format!(
                "msg {} from {}/{}: {why} ({} rejected)",
                frame.msg_id, frame.sysid, frame.compid, self.rejected
            );
            tracing::warn!("signature rejected: {detail}");
            events.record(
                now.unix_us,
                now.mono,
                &LogEvent::new("signature_rejected", Some(frame.sysid), detail),
            );
        }
        None
    }

    pub(super) fn sign(&mut self, bytes: &mut Vec<u8>, now: Now) {
        let Some((_, signer)) = self.keyed.as_mut() else {
            return;
        };
        if let Some(reservation) = signer.sign(bytes, timestamp_from_unix_us(now.unix_us))
            && let Err(e) = self.store.save_reservation(reservation)
        {
            tracing::error!("signing timestamp not saved: {e}");
        }
        self.last_timestamp = signer.last_timestamp();
    }

    pub(super) fn set_key(
        &mut self,
        key: [u8; 32],
        initial_timestamp: u64,
    ) -> Result<(), SigningError> {
        match SigningKey::from_bytes(key) {
            None => {
                self.store.save_key(None)?;
                if let Some((verifier, _)) = &self.keyed {
                    self.replay = verifier.replay_state();
                }
                self.keyed = None;
            }
            Some(key) => {
                self.store.save_key(Some(&key))?;
                let (verifier, mut signer) = self.pair(key);
                signer.raise_floor(initial_timestamp);
                self.keyed = Some((verifier, signer));
            }
        }
        Ok(())
    }

    /// At shutdown: the timestamp in use, so the next start begins above it,
    /// and the exact last timestamp of every incoming stream, so a clean
    /// restart refuses replays without refusing any genuine frame.
    pub(super) fn persist(&self) {
        let Some((verifier, signer)) = &self.keyed else {
            return;
        };
        if let Err(e) = self
            .store
            .save_reservation(signer.last_timestamp().saturating_add(1))
        {
            tracing::error!("signing timestamp not saved: {e}");
        }
        if let Err(e) = self.store.save_replay(&verifier.replay_state()) {
            tracing::error!("signing replay state not saved: {e}");
        }
    }
}

/// The incoming replay state persisted by the last run. Missing or corrupt:
/// start with the one-minute stale rule only, loudly, never refuse to start.
fn load_replay(store: &SigningStore, keyed: bool) -> ReplayState {
    match store.load_replay() {
        Ok(state) if !keyed => state.unwrap_or_default(),
        Err(_) if !keyed => ReplayState::default(),
        Ok(Some(state)) => {
            tracing::info!(
                path = %store.replay_path().display(),
                streams = state.len(),
                "signing replay state loaded: signed frames accepted before this start are refused"
            );
            state
        }
        Ok(None) => {
            tracing::warn!(
                path = %store.replay_path().display(),
                "no signing replay state (normal on the first start with a key): until a \
                 station's frames are seen, signed frames recorded before this start are \
                 refused only when more than 1 min old"
            );
            ReplayState::default()
        }
        Err(e) => {
            tracing::error!(
                "{e}. REPLAY PROTECTION ACROSS THE RESTART IS LOST: signed frames recorded \
                 before this start are refused only when more than 1 min old"
            );
            ReplayState::default()
        }
    }
}
