//! The profiles in use: loading `gcs_profiles/*.toml` (or the embedded
//! copies), checking them against each other, and picking one per sender.
//!
//! Owns [`Profiles`] and [`ProfileError`]; every error names the file, the
//! line and column, and the fix.

use std::path::{Path, PathBuf};

use super::DEFAULT_PROFILE_NAME;
use super::locate::{Seg, line_column, locate};
use super::profile::Profile;

/// Errors of the profile loader; each names the file, the place and the fix.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    #[error(
        "cannot read ground-station profile directory {}: {source} — pass a directory of *.toml profiles",
        dir.display()
    )]
    ReadDir {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot read ground-station profile {}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("no ground-station profiles (*.toml) in {} — pass the directory holding them", dir.display())]
    Empty { dir: PathBuf },
    #[error("{file}:{line}:{column}: {message}")]
    Invalid {
        file: String,
        line: usize,
        column: usize,
        message: String,
    },
}

impl ProfileError {
    fn at(file: &str, text: &str, offset: usize, message: String) -> Self {
        let (line, column) = line_column(text, offset);
        Self::Invalid {
            file: file.into(),
            line,
            column,
            message,
        }
    }
}

/// The profiles in use: one per convention, and the fallback.
#[derive(Debug, Clone, PartialEq)]
pub struct Profiles {
    profiles: Vec<Profile>,
    fallback: Profile,
}

/// The shipped profiles, embedded so the binary needs no files at run time.
const BUILTIN: [(&str, &str); 6] = [
    (
        "qgroundcontrol.toml",
        include_str!("../../../gcs_profiles/qgroundcontrol.toml"),
    ),
    (
        "cockpit.toml",
        include_str!("../../../gcs_profiles/cockpit.toml"),
    ),
    (
        "mavproxy.toml",
        include_str!("../../../gcs_profiles/mavproxy.toml"),
    ),
    (
        "mavsdk.toml",
        include_str!("../../../gcs_profiles/mavsdk.toml"),
    ),
    (
        "pymavlink.toml",
        include_str!("../../../gcs_profiles/pymavlink.toml"),
    ),
    (
        "neptunus-web.toml",
        include_str!("../../../gcs_profiles/neptunus-web.toml"),
    ),
];

impl Profiles {
    /// Loads every `*.toml` in `dir` (in file-name order).
    pub fn load_dir(dir: &Path) -> Result<Self, ProfileError> {
        let entries = std::fs::read_dir(dir).map_err(|source| ProfileError::ReadDir {
            dir: dir.into(),
            source,
        })?;
        let mut paths = Vec::new();
        for entry in entries {
            let path = entry
                .map_err(|source| ProfileError::ReadDir {
                    dir: dir.into(),
                    source,
                })?
                .path();
            if path.extension().is_some_and(|e| e == "toml") && path.is_file() {
                paths.push(path);
            }
        }
        if paths.is_empty() {
            return Err(ProfileError::Empty { dir: dir.into() });
        }
        paths.sort();
        let mut sources = Vec::with_capacity(paths.len());
        for path in paths {
            let text = std::fs::read_to_string(&path).map_err(|source| ProfileError::Read {
                path: path.clone(),
                source,
            })?;
            sources.push((path.display().to_string(), text));
        }
        let refs: Vec<(&str, &str)> = sources
            .iter()
            .map(|(f, t)| (f.as_str(), t.as_str()))
            .collect();
        Self::from_sources(&refs)
    }

    /// Parses and validates one profile; `name` (usually the file) labels errors.
    pub fn parse(name: &str, text: &str) -> Result<Profile, ProfileError> {
        let profile: Profile = toml::from_str(text).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            ProfileError::at(name, text, offset, e.message().trim_end().to_owned())
        })?;
        profile
            .validate()
            .map_err(|inv| ProfileError::at(name, text, inv.offset(text), inv.message))?;
        Ok(profile)
    }

    /// Profiles from `(file, text)` pairs: each parsed, then checked against
    /// the others (a sysid and a name may appear in one profile only).
    pub fn from_sources(sources: &[(&str, &str)]) -> Result<Self, ProfileError> {
        let mut profiles: Vec<Profile> = Vec::with_capacity(sources.len());
        let mut files: Vec<&str> = Vec::with_capacity(sources.len());
        for &(file, text) in sources {
            let p = Self::parse(file, text)?;
            if let Some(j) = profiles.iter().position(|q| q.name == p.name) {
                return Err(ProfileError::at(
                    file,
                    text,
                    locate(text, &[Seg::Key("name")]).0,
                    format!(
                        "profile name \"{}\" is already used by {} — give each profile its own name",
                        p.name, files[j]
                    ),
                ));
            }
            for (i, s) in p.sysids.iter().enumerate() {
                if let Some(j) = profiles.iter().position(|q| q.sysids.contains(s)) {
                    return Err(ProfileError::at(
                        file,
                        text,
                        locate(text, &[Seg::Key("sysids"), Seg::Index(i)]).0,
                        format!(
                            "sysid {s} is already claimed by profile \"{}\" ({}) — a sysid may \
                             appear in only one profile; remove it from one of them \
                             (`sysids = []` keeps a profile as a reference convention)",
                            profiles[j].name, files[j]
                        ),
                    ));
                }
            }
            profiles.push(p);
            files.push(file);
        }
        Ok(Self {
            profiles,
            fallback: Profile::ardusub_default(),
        })
    }

    /// The shipped profiles, or the error if one of them is broken (a test
    /// keeps that from ever shipping).
    pub fn try_builtin() -> Result<Self, ProfileError> {
        Self::from_sources(&BUILTIN)
    }

    /// The shipped profiles (`gcs_profiles/*.toml`, embedded at build time).
    pub fn builtin() -> Self {
        Self::try_builtin().unwrap_or_else(|e| {
            tracing::error!("built-in ground-station profiles are broken ({e}); every sender gets {DEFAULT_PROFILE_NAME}");
            Self {
                profiles: Vec::new(),
                fallback: Profile::ardusub_default(),
            }
        })
    }

    /// The profile for a sender, or the ArduSub default when none claims it.
    pub fn for_sysid(&self, sysid: u8) -> &Profile {
        self.profiles
            .iter()
            .find(|p| p.sysids.contains(&sysid))
            .unwrap_or(&self.fallback)
    }

    /// A profile by name (the fallback included).
    pub fn get(&self, name: &str) -> Option<&Profile> {
        self.profiles
            .iter()
            .chain(std::iter::once(&self.fallback))
            .find(|p| p.name == name)
    }

    /// The loaded profiles, in load order (without the fallback).
    pub fn profiles(&self) -> &[Profile] {
        &self.profiles
    }

    /// The profile of senders no profile claims.
    pub fn fallback(&self) -> &Profile {
        &self.fallback
    }
}
