//! The pilot password: an argon2 PHC string in `DATA_DIR/hmi-password`.
//!
//! Owns [`PilotPassword`] (hash and check) and [`PasswordStore`] (the file,
//! mode 0600, replaced whole). It never logs or formats a password, and
//! refuses to check one longer than [`MAX_PASSWORD_BYTES`].

use std::path::{Path, PathBuf};

use crate::durable;
use argon2::{Argon2, PasswordHash, PasswordHasher as _, PasswordVerifier as _};
use rand::RngCore as _;

/// The pilot password's file in the data directory.
pub const PASSWORD_FILE: &str = "hmi-password";
/// Shortest pilot password `set-password` accepts.
pub const MIN_PASSWORD_CHARS: usize = 8;
/// Longest password a login may carry (longer ones are refused unchecked).
pub const MAX_PASSWORD_BYTES: usize = 256;

/// Errors of the password file.
#[derive(Debug, thiserror::Error)]
pub enum PasswordError {
    #[error(
        "cannot read the HMI pilot password file {path}: {source} — set the password again with `neptunus hmi set-password`"
    )]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "the HMI pilot password file {path} does not hold an argon2 PHC string ({why}) — set the password again with `neptunus hmi set-password`"
    )]
    Corrupt { path: PathBuf, why: String },
    #[error("cannot write the HMI pilot password file {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "the pilot password has {chars} characters — use at least {MIN_PASSWORD_CHARS} (and at most {MAX_PASSWORD_BYTES} bytes)"
    )]
    Length { chars: usize },
    #[error("cannot hash the pilot password: {0}")]
    Hash(String),
}

/// A verified-to-parse argon2 PHC string. Checking a password against it
/// takes tens of milliseconds on purpose.
#[derive(Clone, PartialEq, Eq)]
pub struct PilotPassword {
    phc: String,
}

impl std::fmt::Debug for PilotPassword {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PilotPassword(argon2 hash)")
    }
}

impl PilotPassword {
    /// Hashes `password` with a fresh random salt (argon2id, the crate's
    /// recommended parameters).
    pub fn hash(password: &str) -> Result<Self, PasswordError> {
        let chars = password.chars().count();
        if chars < MIN_PASSWORD_CHARS || password.len() > MAX_PASSWORD_BYTES {
            return Err(PasswordError::Length { chars });
        }
        let mut salt = [0u8; 16];
        rand::rng().fill_bytes(&mut salt);
        let salt = argon2::password_hash::SaltString::encode_b64(&salt)
            .map_err(|e| PasswordError::Hash(e.to_string()))?;
        let phc = Argon2::default()
            .hash_password(password.as_bytes(), &salt)
            .map_err(|e| PasswordError::Hash(e.to_string()))?
            .to_string();
        Ok(Self { phc })
    }

    /// Takes a PHC string as stored.
    pub fn from_phc(phc: &str) -> Result<Self, String> {
        let parsed = PasswordHash::new(phc.trim()).map_err(|e| e.to_string())?;
        if !parsed.algorithm.as_str().starts_with("argon2") {
            return Err(format!("algorithm {} is not argon2", parsed.algorithm));
        }
        Ok(Self {
            phc: phc.trim().to_owned(),
        })
    }

    pub fn phc(&self) -> &str {
        &self.phc
    }

    /// Whether `password` is the pilot's (the crate compares in constant time).
    pub fn verify(&self, password: &str) -> bool {
        if password.len() > MAX_PASSWORD_BYTES {
            return false;
        }
        PasswordHash::new(&self.phc).is_ok_and(|h| {
            Argon2::default()
                .verify_password(password.as_bytes(), &h)
                .is_ok()
        })
    }
}

/// The pilot password's file: `DATA_DIR/hmi-password`, mode 0600, written
/// whole to a temporary file and renamed (never half a hash).
#[derive(Debug, Clone)]
pub struct PasswordStore {
    path: PathBuf,
}

impl PasswordStore {
    pub fn new(data_dir: &Path) -> Self {
        Self {
            path: data_dir.join(PASSWORD_FILE),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The stored password, or `None` when none is set.
    pub fn load(&self) -> Result<Option<PilotPassword>, PasswordError> {
        match std::fs::read_to_string(&self.path) {
            Ok(text) => {
                PilotPassword::from_phc(&text)
                    .map(Some)
                    .map_err(|why| PasswordError::Corrupt {
                        path: self.path.clone(),
                        why,
                    })
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(source) => Err(PasswordError::Read {
                path: self.path.clone(),
                source,
            }),
        }
    }

    /// Hashes and stores `password`.
    pub fn set(&self, password: &str) -> Result<(), PasswordError> {
        let hashed = PilotPassword::hash(password)?;
        self.write(&format!("{}\n", hashed.phc()))
    }

    /// Removes the password; true if there was one.
    pub fn clear(&self) -> Result<bool, PasswordError> {
        match durable::remove(&self.path) {
            Ok(there) => Ok(there),
            Err(source) => Err(PasswordError::Write {
                path: self.path.clone(),
                source,
            }),
        }
    }

    /// Owner-only (0600), atomically and durably.
    fn write(&self, text: &str) -> Result<(), PasswordError> {
        durable::write(&self.path, text.as_bytes(), durable::Mode::Exactly(0o600)).map_err(|e| {
            PasswordError::Write {
                path: self.path.clone(),
                source: e.into(),
            }
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn password_hash_roundtrip_and_file() {
        let dir = tempfile::tempdir().unwrap();
        let store = PasswordStore::new(dir.path());
        assert!(store.load().unwrap().is_none());
        assert!(matches!(
            store.set("short"),
            Err(PasswordError::Length { chars: 5 })
        ));
        store.set("tide-pool-42").unwrap();
        let text = std::fs::read_to_string(store.path()).unwrap();
        assert!(text.starts_with("$argon2id$"), "{text}");
        assert!(!text.contains("tide-pool"));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(store.path())
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let p = store.load().unwrap().unwrap();
        assert!(p.verify("tide-pool-42"));
        assert!(!p.verify("tide-pool-41"));
        assert!(!format!("{p:?}").contains("argon2id$"));
        std::fs::write(store.path(), "plain text").unwrap();
        assert!(matches!(store.load(), Err(PasswordError::Corrupt { .. })));
        assert!(store.clear().unwrap());
        assert!(!store.clear().unwrap());
    }
}
