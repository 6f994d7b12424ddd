//! `events.jsonl` on disk and its size-based rotation.
//!
//! Owns the file handle, ending a line torn by a crash before the next one,
//! rotation (`events.jsonl` → `events.1.jsonl` → …) and pruning. Synchronous:
//! only the writer thread calls it.

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::{EventLogConfig, EventLogError, FILE_NAME, rotated_file_name};

/// `events.jsonl` and its rotation; synchronous, run by the writer thread.
#[derive(Debug)]
pub(super) struct EventFile {
    pub(super) dir: PathBuf,
    path: PathBuf,
    max_bytes: u64,
    keep: usize,
    /// `None` after an error: reopened (and the folder recreated) at the
    /// next line, so the log recovers when the disk does.
    file: Option<File>,
    /// Bytes in the current file, including a torn line found on open.
    size: u64,
    /// The file does not end with a newline (a torn line): end it first.
    torn: bool,
}

impl EventFile {
    pub(super) fn open(cfg: &EventLogConfig) -> Result<Self, EventLogError> {
        if let Err(source) = std::fs::create_dir_all(&cfg.dir) {
            return Err(match file_in_the_way(&cfg.dir) {
                Some(blocker) => EventLogError::NotAFolder {
                    dir: cfg.dir.clone(),
                    blocker,
                },
                None => EventLogError::Folder {
                    dir: cfg.dir.clone(),
                    source,
                },
            });
        }
        let mut file = Self {
            dir: cfg.dir.clone(),
            path: cfg.dir.join(FILE_NAME),
            max_bytes: cfg.max_bytes,
            keep: cfg.keep,
            file: None,
            size: 0,
            torn: false,
        };
        file.reopen().map_err(|source| EventLogError::Open {
            path: file.path.clone(),
            source,
        })?;
        Ok(file)
    }

    /// Not open yet: the first event opens it (creating the folder).
    pub(super) fn closed(cfg: &EventLogConfig) -> Self {
        Self {
            dir: cfg.dir.clone(),
            path: cfg.dir.join(FILE_NAME),
            max_bytes: cfg.max_bytes,
            keep: cfg.keep,
            file: None,
            size: 0,
            torn: false,
        }
    }

    pub(super) fn path(&self) -> &Path {
        &self.path
    }

    fn reopen(&mut self) -> io::Result<()> {
        std::fs::create_dir_all(&self.dir)?;
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(&self.path)?;
        let size = file.metadata()?.len();
        let mut torn = false;
        if size > 0 {
            let mut last = [0u8];
            file.seek(SeekFrom::End(-1))?;
            file.read_exact(&mut last)?;
            torn = last[0] != b'\n';
        }
        self.file = Some(file);
        self.size = size;
        self.torn = torn;
        Ok(())
    }

    /// Rotate before writing `line_len` bytes? Never for an empty file, so
    /// an oversized line gets a file of its own instead of a rotation loop.
    pub(super) fn wants_rotation(&self, line_len: usize) -> bool {
        let line_len = line_len as u64 + u64::from(self.torn);
        self.size > 0 && self.size.saturating_add(line_len) > self.max_bytes
    }

    /// Writes one whole line with one `write` call (so it appears at once
    /// and is never interleaved), reopening the file first if needed.
    pub(super) fn append(&mut self, line: &[u8]) -> io::Result<()> {
        if self.file.is_none() {
            self.reopen()?;
        }
        let Some(file) = self.file.as_mut() else {
            return Err(io::Error::other("event log file not open"));
        };
        let result = if self.torn {
            let mut buf = Vec::with_capacity(line.len() + 1);
            buf.push(b'\n');
            buf.extend_from_slice(line);
            file.write_all(&buf).map(|()| buf.len())
        } else {
            file.write_all(line).map(|()| line.len())
        };
        match result {
            Ok(n) => {
                self.size += n as u64;
                self.torn = false;
                Ok(())
            }
            Err(e) => {
                // Part of the line may be on disk: reopen next time, which
                // looks at the last byte and ends a torn line.
                self.file = None;
                Err(e)
            }
        }
    }

    /// `events.jsonl` → `events.1.jsonl`, `.1` → `.2` … and delete what
    /// would go past `keep`; the next [`append`](Self::append) starts a new
    /// `events.jsonl`.
    pub(super) fn rotate(&mut self) -> io::Result<()> {
        // Closed first: after the rename this handle would write into the
        // rotated file. On failure the next append reopens `events.jsonl`.
        self.file = None;
        self.prune()?;
        for n in (1..self.keep).rev() {
            let from = self.dir.join(rotated_file_name(n));
            match std::fs::rename(&from, self.dir.join(rotated_file_name(n + 1))) {
                Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
        if self.keep == 0 {
            std::fs::remove_file(&self.path)?;
        } else {
            std::fs::rename(&self.path, self.dir.join(rotated_file_name(1)))?;
        }
        tracing::info!(path = %self.path.display(), "event log rotated");
        self.reopen()
    }

    /// Deletes rotated files numbered `keep` or more: after the shift they
    /// would be past `keep`. Scans the folder so leftovers of a larger
    /// `keep` from an earlier run go too.
    fn prune(&self) -> io::Result<()> {
        for entry in std::fs::read_dir(&self.dir)? {
            let entry = entry?;
            let name = entry.file_name();
            let Some(n) = name.to_str().and_then(rotated_index) else {
                continue;
            };
            if n >= self.keep {
                match std::fs::remove_file(entry.path()) {
                    Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
                    _ => {}
                }
            }
        }
        Ok(())
    }
}

/// `n` of a file named exactly `events.{n}.jsonl`, n ≥ 1.
pub(super) fn rotated_index(name: &str) -> Option<usize> {
    let digits = name.strip_prefix("events.")?.strip_suffix(".jsonl")?;
    let n: usize = digits.parse().ok()?;
    (n >= 1 && rotated_file_name(n) == name).then_some(n)
}

/// The first existing path on the way to `dir` that is not a folder.
fn file_in_the_way(dir: &Path) -> Option<PathBuf> {
    let mut ancestors: Vec<&Path> = dir.ancestors().collect();
    ancestors.reverse();
    ancestors
        .into_iter()
        .filter(|p| !p.as_os_str().is_empty())
        .find(|p| p.exists() && !p.is_dir())
        .map(Path::to_path_buf)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn cfg(dir: &Path, max_bytes: u64, keep: usize) -> EventLogConfig {
        EventLogConfig {
            dir: dir.to_path_buf(),
            max_bytes,
            keep,
        }
    }

    #[test]
    fn rotated_names_are_recognised_exactly() {
        assert_eq!(rotated_index("events.1.jsonl"), Some(1));
        assert_eq!(rotated_index("events.12.jsonl"), Some(12));
        for other in [
            "events.jsonl",
            "events.0.jsonl",
            "events.01.jsonl",
            "events.+1.jsonl",
            "events.1.jsonl.bak",
            "tlog.1.jsonl",
        ] {
            assert_eq!(rotated_index(other), None, "{other}");
        }
    }

    /// A write error loses that line only: the writer reopens the file for
    /// the next line and carries on where the disk works again.
    #[cfg(target_os = "linux")]
    #[test]
    fn recovers_after_a_write_error() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join(FILE_NAME);
        // /dev/full fails every write with ENOSPC, even for root.
        std::os::unix::fs::symlink("/dev/full", &path).unwrap();
        let mut file = EventFile::open(&cfg(tmp.path(), 1 << 20, 2)).unwrap();
        let err = file.append(b"{\"lost\":1}\n").unwrap_err();
        assert_eq!(err.raw_os_error(), Some(28), "{err}"); // ENOSPC
        assert!(file.append(b"{\"lost\":2}\n").is_err());
        std::fs::remove_file(&path).unwrap();
        file.append(b"{\"kept\":3}\n").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "{\"kept\":3}\n");
    }

    /// With nothing to shift into (keep = 0) a rotation starts over.
    #[test]
    fn keep_zero_rotation_keeps_no_old_file() {
        let tmp = tempfile::tempdir().unwrap();
        let mut file = EventFile::open(&cfg(tmp.path(), 8, 0)).unwrap();
        file.append(b"0123456\n").unwrap();
        assert!(file.wants_rotation(2));
        file.rotate().unwrap();
        file.append(b"a\n").unwrap();
        let mut names: Vec<_> = std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, [FILE_NAME]);
        assert_eq!(std::fs::read_to_string(file.path()).unwrap(), "a\n");
    }
}
