//! `neptunus.log`: the program's own log file, rotated by size so that no
//! amount of logging fills the disk.
//!
//! Owns: the file and its rotated copies (`neptunus.log.1` … newest first),
//! rotation before a write would take the file past its size, and the total
//! cap that follows (`max_bytes` × `files`). It never panics and never makes
//! logging fail: a file that cannot be reopened drops lines until it can
//! (the same lines still go to stderr).
//!
//! Why not a crate: `tracing-appender` rotates by time only; the size-rotating
//! crates pull in more than these few lines.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// `neptunus.log` rotates before it would pass this…
pub const DEFAULT_MAX_BYTES: u64 = 10 * 1024 * 1024;
/// …and this many files are kept, the live one included (50 MiB in all).
pub const DEFAULT_FILES: usize = 5;

/// An append-only file that rotates by size; a `std::io::Write` for
/// `tracing_subscriber`'s writer. Give it whole lines: rotation happens
/// between writes, never inside one.
#[derive(Debug)]
pub struct RotatingFile {
    path: PathBuf,
    max_bytes: u64,
    files: usize,
    file: Option<File>,
    written: u64,
}

impl RotatingFile {
    /// Opens `path` for appending (rotating first when it is already full).
    /// An error when it cannot be opened at all, so the caller can say so.
    pub fn open(path: impl Into<PathBuf>, max_bytes: u64, files: usize) -> io::Result<Self> {
        let mut f = Self {
            path: path.into(),
            max_bytes: max_bytes.max(1),
            files: files.max(1),
            file: None,
            written: 0,
        };
        // Only a regular file is ours to rotate (a directory there is an error below).
        let full = std::fs::metadata(&f.path).is_ok_and(|m| m.is_file() && m.len() >= f.max_bytes);
        if full {
            f.shift()?;
        }
        f.reopen()?;
        Ok(f)
    }

    /// The live file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// `neptunus.log.{n}`: `n` = 1 is the newest rotated file.
    pub fn rotated_path(&self, n: usize) -> PathBuf {
        let mut name = self.path.as_os_str().to_owned();
        name.push(format!(".{n}"));
        PathBuf::from(name)
    }

    fn reopen(&mut self) -> io::Result<()> {
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.path)?;
        self.written = file.metadata()?.len();
        self.file = Some(file);
        Ok(())
    }

    /// Drops the oldest copy and moves each one up: `.n-1` → `.n`, live → `.1`.
    fn shift(&mut self) -> io::Result<()> {
        self.file = None;
        if self.files == 1 {
            return match std::fs::remove_file(&self.path) {
                Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
                _ => Ok(()),
            };
        }
        let _ = std::fs::remove_file(self.rotated_path(self.files - 1));
        for n in (1..self.files - 1).rev() {
            let from = self.rotated_path(n);
            if from.exists() {
                std::fs::rename(&from, self.rotated_path(n + 1))?;
            }
        }
        std::fs::rename(&self.path, self.rotated_path(1))
    }
}

impl Write for RotatingFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if self.written > 0 && self.written + buf.len() as u64 > self.max_bytes {
            if let Some(f) = self.file.as_mut() {
                let _ = f.flush();
            }
            // A failed rotation must not grow the file past its cap: lines
            // are dropped until a reopen succeeds.
            let rotated = self.shift().and_then(|()| self.reopen());
            if rotated.is_err() {
                self.file = None;
            }
        }
        if self.file.is_none() && self.reopen().is_err() {
            // Pretend success: a logging error must not become an error of
            // whatever was logging.
            return Ok(buf.len());
        }
        let Some(f) = self.file.as_mut() else {
            return Ok(buf.len());
        };
        f.write_all(buf)?;
        self.written += buf.len() as u64;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        match self.file.as_mut() {
            Some(f) => f.flush(),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sizes(dir: &Path) -> Vec<(String, u64)> {
        let mut v: Vec<_> = std::fs::read_dir(dir)
            .map(|r| {
                r.flatten()
                    .map(|e| {
                        (
                            e.file_name().to_string_lossy().into_owned(),
                            e.metadata().map_or(0, |m| m.len()),
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }

    #[test]
    fn rotates_by_size_and_keeps_the_newest_files_under_the_cap() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("neptunus.log");
        let mut f = RotatingFile::open(&path, 100, 3).expect("open");
        for i in 0..100 {
            f.write_all(format!("line {i:04} ........\n").as_bytes())
                .expect("write");
        }
        f.flush().expect("flush");
        let files = sizes(dir.path());
        let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["neptunus.log", "neptunus.log.1", "neptunus.log.2"]);
        assert!(files.iter().all(|(_, len)| *len <= 100), "{files:?}");
        // Whole lines only, and the newest lines are in the live file.
        let live = std::fs::read_to_string(&path).expect("read");
        assert!(live.ends_with("line 0099 ........\n"), "{live}");
        let older = std::fs::read_to_string(f.rotated_path(1)).expect("read");
        assert!(older.lines().all(|l| l.len() == 18), "{older}");
    }

    #[test]
    fn a_full_file_from_the_last_run_is_rotated_at_open() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("neptunus.log");
        std::fs::write(&path, vec![b'x'; 150]).expect("write");
        std::fs::write(dir.path().join("neptunus.log.1"), b"older\n").expect("write");
        let mut f = RotatingFile::open(&path, 100, 2).expect("open");
        f.write_all(b"new\n").expect("write");
        let files = sizes(dir.path());
        assert_eq!(
            files,
            [
                ("neptunus.log".to_owned(), 4),
                ("neptunus.log.1".to_owned(), 150)
            ]
        );
    }

    #[test]
    fn an_unopenable_path_is_an_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        // A directory where the file should be: fails even for root.
        let path = dir.path().join("neptunus.log");
        std::fs::create_dir(&path).expect("mkdir");
        assert!(RotatingFile::open(&path, 100, 2).is_err());
    }
}
