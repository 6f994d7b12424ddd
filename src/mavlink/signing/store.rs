//! The signing files in the data directory: `signing.key`,
//! `signing.timestamp` and `signing.replay`.
//!
//! Owns [`SigningStore`], its errors and warnings, the file formats and the
//! atomic, synced writes. It never quotes a key file's content in an error
//! or a log line, and never reads a file larger than what it writes.

use std::fmt;
use std::fs::File;
use std::io::{self, Read};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};

use super::MAX_TIMESTAMP;
use super::key::{KEY_LEN, SigningKey};
use super::verify::ReplayState;
use crate::durable;

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
/// `signing.replay`: [`MAX_STREAMS`](super::MAX_STREAMS) lines of at most 32 bytes, and a header.
const MAX_REPLAY_FILE_LEN: u64 = 16 * 1024;
/// First line of `signing.replay`.
const REPLAY_HEADER: &str = "# neptunus signing replay state v1: link_id sysid compid timestamp";

/// The signing files in the data directory:
/// - `signing.key`: the key as 64 lowercase hex digits and a newline, mode
///   0600. Written to a temporary file created 0600 and renamed into place,
///   so it is never readable by others, not even briefly.
/// - `signing.timestamp`: the reservation (see [`Signer`](super::Signer)) as a decimal
///   number and a newline, replaced atomically.
/// - `signing.replay`: the incoming streams' replay reservations (see
///   [`Verifier::take_reservation`](super::Verifier::take_reservation)), one `link_id sysid compid timestamp`
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
            return match durable::remove(&path) {
                Ok(_) => Ok(()),
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

/// Writes `dir/name` with [`durable::write`], with exactly `mode`.
fn write_atomic(dir: &Path, name: &str, contents: &[u8], mode: u32) -> Result<(), SigningError> {
    let path = dir.join(name);
    durable::write(&path, contents, durable::Mode::Exactly(mode)).map_err(|e| SigningError::Write {
        path: path.clone(),
        source: e.into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
