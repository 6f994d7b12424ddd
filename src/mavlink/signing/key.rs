//! The signing key: 32 bytes, never all zeros, never printed.
//!
//! Owns [`SigningKey`] and the one signature function both directions use
//! (SHA-256 over key, frame, link id and timestamp). It never formats the key
//! bytes: `Debug` is redacted and there is no `Display`.

use std::fmt;

use sha2::{Digest, Sha256};

use super::frame::{SIGNATURE_LEN, TIMESTAMP_LEN};

pub const KEY_LEN: usize = 32;

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
    pub(super) fn signature(
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
