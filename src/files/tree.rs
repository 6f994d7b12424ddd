//! The virtual file tree MAVLink FTP shows, and the one place a path from a
//! ground station is turned into something the vehicle may serve.
//!
//! ```text
//! /component/general.json       the general component metadata (in memory)
//! /component/parameters.json    the parameter metadata (in memory)
//! /logs/tlogs/                  DATA_DIR/tlogs: our telemetry logs
//! /logs/events/                 DATA_DIR/events: the event log and its rotations
//! /recordings/                  DATA_DIR/recordings: what the vehicle records
//! ```
//!
//! Nothing else of the data directory (keys, the password, parameters,
//! settings, certificates) has a name here. A path resolves only through
//! this table: components are split on `/` (empty and `.` ones skipped),
//! `..`, a backslash, a NUL or any byte outside printable ASCII makes the
//! whole path name nothing, and inside a disk folder only names of the
//! kinds that folder holds are admitted. Pure: it never touches the disk
//! (the disk worker checks what the names are there, and follows no
//! symbolic link).

use crate::mavlink::tlog;

/// The directory of the component metadata.
pub const COMPONENT_DIR: &str = "component";
/// The general component metadata file (COMP_METADATA_TYPE_GENERAL).
pub const GENERAL_FILE: &str = "general.json";
/// The parameter metadata file (COMP_METADATA_TYPE_PARAMETER).
pub const PARAMETERS_FILE: &str = "parameters.json";

/// The deepest a path into the recordings may go (a folder per recording,
/// a few levels of segments at most).
pub const MAX_DEPTH: usize = 4;
/// The longest name a component may have.
const MAX_NAME: usize = 128;

/// A folder of the data directory the tree shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DiskRoot {
    /// `/logs/tlogs`: the telemetry logs ([`tlog::parse_file_name`] names).
    Tlogs,
    /// `/logs/events`: `events.jsonl` and its rotations.
    Events,
    /// `/recordings`: the recordings (folders allowed, [`MAX_DEPTH`] deep).
    Recordings,
}

impl DiskRoot {
    /// Its folder in the data directory.
    pub fn folder(self) -> &'static str {
        match self {
            Self::Tlogs => "tlogs",
            Self::Events => "events",
            Self::Recordings => "recordings",
        }
    }

    /// Whether `name` may appear in this folder (the disk says whether it
    /// is a file or a folder; only the recordings have folders).
    pub fn admits(self, name: &str) -> bool {
        match self {
            Self::Tlogs => tlog::parse_file_name(name).is_some(),
            Self::Events => crate::eventlog::is_event_log_name(name),
            Self::Recordings => safe_name(name),
        }
    }

    /// Whether it may hold folders.
    pub fn nests(self) -> bool {
        self == Self::Recordings
    }
}

/// A path inside one of the disk folders; every part admitted.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct DiskPath {
    pub root: DiskRoot,
    /// Empty: the folder itself.
    pub parts: Vec<String>,
}

impl DiskPath {
    /// The path inside the tree, for messages (`/logs/tlogs/NAME`).
    pub fn display(&self) -> String {
        let base = match self.root {
            DiskRoot::Tlogs => "/logs/tlogs",
            DiskRoot::Events => "/logs/events",
            DiskRoot::Recordings => "/recordings",
        };
        std::iter::once(base)
            .chain(self.parts.iter().map(String::as_str))
            .collect::<Vec<_>>()
            .join("/")
    }
}

/// A file the vehicle makes in memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MemFile {
    General,
    Parameters,
}

impl MemFile {
    pub const ALL: [MemFile; 2] = [MemFile::General, MemFile::Parameters];

    pub fn name(self) -> &'static str {
        match self {
            Self::General => GENERAL_FILE,
            Self::Parameters => PARAMETERS_FILE,
        }
    }

    /// Its path in the tree.
    pub fn path(self) -> String {
        format!("/{COMPONENT_DIR}/{}", self.name())
    }
}

/// A folder of the tree itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StaticDir {
    Root,
    Component,
    Logs,
}

/// What a path names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Node {
    Static(StaticDir),
    Mem(MemFile),
    /// A disk folder or something in one (file or, in the recordings,
    /// folder: the disk decides).
    Disk(DiskPath),
}

impl Node {
    /// Whether reading it is for stations that may control the vehicle:
    /// the logs and recordings are the vehicle's records (positions,
    /// stations' addresses), like `/api/logs` in the browser HMI. The
    /// component metadata and the tree's own folders are for anyone, as
    /// the parameters are.
    pub fn is_record(&self) -> bool {
        matches!(self, Self::Disk(_))
    }
}

/// The entries of a folder of the tree itself: `(name, is_dir)`.
pub fn static_entries(dir: StaticDir) -> &'static [(&'static str, bool)] {
    match dir {
        StaticDir::Root => &[(COMPONENT_DIR, true), ("logs", true), ("recordings", true)],
        StaticDir::Component => &[(GENERAL_FILE, false), (PARAMETERS_FILE, false)],
        StaticDir::Logs => &[("tlogs", true), ("events", true)],
    }
}

/// What `path` (a request's bytes) names in the tree, if anything.
pub fn resolve(path: &[u8]) -> Option<Node> {
    if path
        .iter()
        .any(|&b| !(0x20..0x7f).contains(&b) || b == b'\\')
    {
        return None;
    }
    // Printable ASCII: valid UTF-8.
    let text = std::str::from_utf8(path).ok()?;
    let mut parts = Vec::new();
    for part in text.split('/') {
        match part {
            "" | "." => {}
            ".." => return None,
            p => parts.push(p),
        }
    }
    let (first, rest) = match parts.split_first() {
        None => return Some(Node::Static(StaticDir::Root)),
        Some((first, rest)) => (*first, rest),
    };
    match (first, rest) {
        (COMPONENT_DIR, []) => Some(Node::Static(StaticDir::Component)),
        (COMPONENT_DIR, [name]) => MemFile::ALL
            .into_iter()
            .find(|f| f.name() == *name)
            .map(Node::Mem),
        ("logs", []) => Some(Node::Static(StaticDir::Logs)),
        ("logs", ["tlogs", inside @ ..]) => disk(DiskRoot::Tlogs, inside),
        ("logs", ["events", inside @ ..]) => disk(DiskRoot::Events, inside),
        ("recordings", inside) => disk(DiskRoot::Recordings, inside),
        _ => None,
    }
}

fn disk(root: DiskRoot, inside: &[&str]) -> Option<Node> {
    let depth = if root.nests() { MAX_DEPTH } else { 1 };
    if inside.len() > depth {
        return None;
    }
    // Every part a name the folder admits; the folders on the way to a
    // recording need only be safe names.
    let last = inside.len().saturating_sub(1);
    for (i, part) in inside.iter().enumerate() {
        let ok = if i == last {
            root.admits(part)
        } else {
            safe_name(part)
        };
        if !ok {
            return None;
        }
    }
    Some(Node::Disk(DiskPath {
        root,
        parts: inside.iter().map(|s| (*s).to_owned()).collect(),
    }))
}

/// A name a file or folder of the recordings may have: letters, digits,
/// `.`, `_`, `-`, not starting with a dot (no hidden files, no `..`).
pub fn safe_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= MAX_NAME
        && !name.starts_with('.')
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    fn disk_path(root: DiskRoot, parts: &[&str]) -> Option<Node> {
        Some(Node::Disk(DiskPath {
            root,
            parts: parts.iter().map(|s| (*s).to_owned()).collect(),
        }))
    }

    #[test]
    fn the_tree_names_what_it_shows() {
        for root in ["", "/", "//", "/.", "./"] {
            assert_eq!(
                resolve(root.as_bytes()),
                Some(Node::Static(StaticDir::Root)),
                "{root:?}"
            );
        }
        assert_eq!(
            resolve(b"/component/general.json"),
            Some(Node::Mem(MemFile::General))
        );
        // QGroundControl keeps a slash of the URI's `mftp://`.
        assert_eq!(
            resolve(b"//component/parameters.json"),
            Some(Node::Mem(MemFile::Parameters))
        );
        assert_eq!(
            resolve(b"component/parameters.json"),
            Some(Node::Mem(MemFile::Parameters))
        );
        assert_eq!(resolve(b"/logs/tlogs"), disk_path(DiskRoot::Tlogs, &[]));
        assert_eq!(
            resolve(b"/logs/tlogs/neptunus-20261124-223000-2.tlog"),
            disk_path(DiskRoot::Tlogs, &["neptunus-20261124-223000-2.tlog"])
        );
        assert_eq!(
            resolve(b"/logs/events/events.3.jsonl"),
            disk_path(DiskRoot::Events, &["events.3.jsonl"])
        );
        assert_eq!(
            resolve(b"/recordings/dive-1/segment-0001.ts"),
            disk_path(DiskRoot::Recordings, &["dive-1", "segment-0001.ts"])
        );
    }

    #[test]
    fn nothing_else_of_the_data_directory_has_a_name() {
        for bad in [
            "/params.toml",
            "/signing.key",
            "/hmi-password",
            "/logs/tlogs/../../params.toml",
            "/logs/../component/general.json",
            "..",
            "/component/../component/general.json",
            "/component/general.json\0/x",
            "/logs/tlogs/x.tlog",
            "/logs/tlogs/neptunus-20261124-223000.tlog/more",
            "/logs/events/neptunus.log",
            "/logs/other",
            "/recordings/.hidden",
            "/recordings/a/b/c/d/e",
            "/recordings/dive\\1",
            "/recordings/dive 1",
            "@PARAM/param.pck",
            "/etc/passwd",
            "/component/Parameters.json",
        ] {
            assert_eq!(resolve(bad.as_bytes()), None, "{bad:?}");
        }
        assert_eq!(resolve(&[b'/', 0xC3, 0xA9]), None);
        assert_eq!(resolve(b"/logs/tlogs/\x01"), None);
    }

    #[test]
    fn records_are_the_disk_folders() {
        assert!(resolve(b"/recordings").unwrap().is_record());
        assert!(resolve(b"/logs/tlogs").unwrap().is_record());
        assert!(!resolve(b"/logs").unwrap().is_record());
        assert!(!resolve(b"/component/general.json").unwrap().is_record());
    }
}
