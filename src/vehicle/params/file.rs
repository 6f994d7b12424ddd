//! `params.toml` in the data directory ([`ParamFile`]): the TOML text of the
//! values that differ from their defaults, loading it (bad entries are
//! warnings, an unreadable file is moved aside), saving it with
//! [`crate::durable::write`] and removing a tmp file an interrupted save
//! left behind.
//!
//! The only part of the parameters that does I/O. Nothing a file contains
//! makes it panic or stops the vehicle from starting: the defaults apply.

use std::fmt::Write as _;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use super::defs::{definitions, format_value, wire_value};
use super::store::ParamStore;
use crate::durable;

/// The TOML text of a store (what [`ParamFile`] writes and reads).
impl ParamStore {
    /// Parameters that differ from their default, as TOML `NAME = value`
    /// lines sorted by name. Defaults are not written, so a later version's
    /// new defaults apply to everything the user never changed.
    pub fn to_toml(&self) -> String {
        let mut changed: Vec<(&str, String)> = definitions()
            .iter()
            .zip(&self.values)
            .filter(|(d, v)| **v != wire_value(d.ty, d.default))
            .map(|(d, v)| (d.name, format_value(d.ty, *v)))
            .collect();
        changed.sort_unstable();
        let mut out = String::from(
            "# Neptunus parameters that differ from their defaults.\n\
             # Written by Neptunus; edit only while it is stopped.\n",
        );
        for (name, value) in changed {
            let _ = writeln!(out, "{name} = {value}");
        }
        out
    }

    /// Parses what [`to_toml`](Self::to_toml) wrote, starting from defaults.
    /// Unknown names and bad values are skipped with a warning naming the
    /// line; everything else applies. Only text that is not TOML at all is an
    /// error.
    pub fn from_toml(text: &str) -> Result<(Self, Vec<String>), String> {
        let table: std::collections::BTreeMap<String, toml::Spanned<toml::Value>> =
            toml::from_str(text).map_err(|e| e.to_string())?;
        let line_of = |offset: usize| {
            1 + text
                .get(..offset)
                .map_or(0, |before| before.bytes().filter(|&b| b == b'\n').count())
        };
        let mut store = Self::defaults();
        let mut warnings: Vec<(usize, String)> = Vec::new();
        let mut pending = Vec::new();
        for (name, spanned) in &table {
            let line = line_of(spanned.span().start);
            let value = match spanned.get_ref() {
                toml::Value::Integer(i) => *i as f64,
                toml::Value::Float(f) => *f,
                other => {
                    warnings.push((line, format!("{name} = {other} is not a number")));
                    continue;
                }
            };
            pending.push((line, name.as_str(), value));
        }
        // Pairs checked against each other (the tilt range) may need the other
        // value first; retry until nothing more applies.
        let mut errors = Vec::new();
        loop {
            errors.clear();
            let before = pending.len();
            pending.retain(|&(line, name, value)| match store.set(name, value) {
                Ok(_) => false,
                Err(e) => {
                    errors.push((line, e.to_string()));
                    true
                }
            });
            if pending.is_empty() || pending.len() == before {
                break;
            }
        }
        warnings.append(&mut errors);
        warnings.sort();
        let warnings = warnings
            .into_iter()
            .map(|(line, w)| format!("line {line}: {w}; ignored"))
            .collect();
        Ok((store, warnings))
    }
}

/// Failures to store parameters.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("could not {action} {} while saving parameters: {source}", path.display())]
    Io {
        action: &'static str,
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}

/// `params.toml` in the data directory.
#[derive(Debug, Clone)]
pub struct ParamFile {
    path: PathBuf,
}

impl ParamFile {
    pub const FILE_NAME: &'static str = "params.toml";

    /// The file `dir/params.toml`.
    pub fn new(dir: &Path) -> Self {
        Self {
            path: dir.join(Self::FILE_NAME),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Reads the parameters. A missing file gives the defaults. A file that is
    /// not TOML (or not text) is moved aside to `params.toml.corrupt-<n>`
    /// (never overwriting an earlier one) and the defaults apply. A file with
    /// some bad entries applies the good ones. Every problem is a warning
    /// naming the file.
    pub fn load(&self) -> (ParamStore, Vec<String>) {
        let shown = self.path.display();
        let bytes = match fs::read(&self.path) {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return (ParamStore::defaults(), vec![]);
            }
            Err(e) => {
                return (
                    ParamStore::defaults(),
                    vec![format!(
                        "could not read {shown}: {e}; using default parameters (fix the file's permissions, or remove it)"
                    )],
                );
            }
        };
        let parsed = std::str::from_utf8(&bytes)
            .map_err(|e| format!("not UTF-8 text ({e})"))
            .and_then(ParamStore::from_toml);
        match parsed {
            Ok((store, warnings)) => (
                store,
                warnings
                    .into_iter()
                    .map(|w| format!("{shown}: {w}"))
                    .collect(),
            ),
            Err(why) => {
                let why = why.trim_end().replace('\n', " ");
                let warning = match self.move_aside() {
                    Ok(aside) => format!(
                        "{shown} is unreadable ({why}); moved it to {} and using default parameters",
                        aside.display()
                    ),
                    Err(e) => format!(
                        "{shown} is unreadable ({why}) and could not be moved aside ({e}); using default parameters, and the next parameter save will replace it"
                    ),
                };
                (ParamStore::defaults(), vec![warning])
            }
        }
    }

    /// Renames the file to the first free `params.toml.corrupt-<n>`.
    fn move_aside(&self) -> io::Result<PathBuf> {
        for n in 1..10_000u32 {
            let mut name = self.path.clone().into_os_string();
            name.push(format!(".corrupt-{n}"));
            let aside = PathBuf::from(name);
            if aside.symlink_metadata().is_ok() {
                continue;
            }
            // A hard link cannot replace an existing file, so a concurrent
            // writer can't make us overwrite an earlier aside file.
            match fs::hard_link(&self.path, &aside) {
                Ok(()) => {
                    fs::remove_file(&self.path)?;
                    return Ok(aside);
                }
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                // Filesystems without hard links (FAT on an SD card).
                Err(_) => {
                    fs::rename(&self.path, &aside)?;
                    return Ok(aside);
                }
            }
        }
        Err(io::Error::other(
            "10,000 corrupt-parameter files already exist",
        ))
    }

    /// `params.toml.tmp` beside the file.
    pub fn tmp_path(&self) -> PathBuf {
        durable::tmp_path(&self.path)
    }

    /// Removes a `params.toml.tmp` left by a save that was interrupted (a
    /// kill or power cut between write and rename). True when one was there.
    pub fn remove_stale_tmp(&self) -> io::Result<bool> {
        match fs::remove_file(self.tmp_path()) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// Writes atomically and durably ([`durable::write`]): a crash leaves
    /// either the old or the new file, never a torn one.
    pub fn save(&self, store: &ParamStore) -> Result<(), StoreError> {
        durable::write(
            &self.path,
            store.to_toml().as_bytes(),
            durable::Mode::LessUmask(0o666),
        )
        .map_err(|e| StoreError::Io {
            action: e.step,
            path: e.path,
            source: e.source,
        })
    }
}
