//! The disk worker: one thread (`neptunus-files`) that lists, reads and
//! erases what the vehicle core asks for ([`FileRequest`]) and answers on
//! a channel the vehicle task reads ([`FileReply`]).
//!
//! Owns every file access of the transfers. It reads only inside the data
//! directory's tlogs, events and recordings folders, only names those
//! folders admit ([`DiskRoot::admits`]), and follows no symbolic link
//! inside them (the folders themselves may be links, say to a larger
//! disk). It never writes, except that [`FileOp::EraseLogs`] deletes
//! telemetry logs — never one this run is writing. Requests are answered
//! in order, one at a time; a request that cannot be done is answered with
//! its error, never dropped.

use std::fs::{File, OpenOptions};
use std::io::{self, Read as _};
use std::os::unix::fs::{FileExt as _, OpenOptionsExt as _};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc;
use std::thread::JoinHandle;

use tokio::sync::mpsc::UnboundedSender;

use super::tree::{DiskPath, DiskRoot, safe_name};
use super::{FileAnswer, FileError, FileOp, FileReply, FileRequest, LogFile};
use crate::mavlink::ftp::{DirEntry, crc32};
use crate::mavlink::tlog::{self, TlogRun};

/// The most entries a listing (and the log catalog) holds: a folder with
/// more shows its first ones by name (the catalog, its newest).
const MAX_ENTRIES: usize = 4096;
/// The most bytes one read returns.
pub const MAX_READ: u32 = 256 * 1024;

/// Where the worker finds the files.
#[derive(Debug, Clone)]
pub struct WorkerConfig {
    /// The data directory (`--data-dir`).
    pub data_dir: PathBuf,
    /// The telemetry logs this run writes: never erased.
    pub running: Option<TlogRun>,
}

/// The running worker.
pub struct FileWorker {
    tx: Option<mpsc::Sender<FileRequest>>,
    replies: UnboundedSender<FileReply>,
    thread: Option<JoinHandle<()>>,
}

impl FileWorker {
    /// Starts the thread; its answers go to `replies`.
    pub fn spawn(cfg: WorkerConfig, replies: UnboundedSender<FileReply>) -> io::Result<Self> {
        let (tx, rx) = mpsc::channel::<FileRequest>();
        let out = replies.clone();
        let thread = std::thread::Builder::new()
            .name("neptunus-files".into())
            .spawn(move || {
                for req in rx {
                    let result = execute(&cfg, &req.op);
                    if let Err(e) = &result {
                        tracing::debug!(op = ?req.op, error = %e, "file request failed");
                    }
                    if out
                        .send(FileReply {
                            token: req.token,
                            result,
                        })
                        .is_err()
                    {
                        break;
                    }
                }
            })?;
        Ok(Self {
            tx: Some(tx),
            replies,
            thread: Some(thread),
        })
    }

    /// Queues a request; never waits. Without a thread to do it, it is
    /// answered at once with an error.
    pub fn send(&self, req: FileRequest) {
        let token = req.token;
        let sent = self.tx.as_ref().is_some_and(|tx| tx.send(req).is_ok());
        if !sent {
            let _ = self.replies.send(FileReply {
                token,
                result: Err(FileError::Io(5)),
            });
        }
    }

    /// Lets the thread finish what is queued, and waits for it.
    pub fn stop(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take()
            && t.join().is_err()
        {
            tracing::warn!("the file worker thread panicked");
        }
    }
}

/// Does one request (synchronously: the worker thread, and tests, call it).
pub fn execute(cfg: &WorkerConfig, op: &FileOp) -> Result<FileAnswer, FileError> {
    match op {
        FileOp::LogCatalog => catalog(cfg).map(FileAnswer::Catalog),
        FileOp::List(dir) => list(cfg, dir).map(FileAnswer::Listing),
        FileOp::Stat(path) => {
            let file = open(cfg, path)?;
            let len = file.metadata().map_err(|e| FileError::of(&e))?.len();
            Ok(FileAnswer::Size(len))
        }
        FileOp::Read { path, offset, len } => {
            let file = open(cfg, path)?;
            let mut buf = vec![0u8; (*len).min(MAX_READ) as usize];
            let mut got = 0;
            while got < buf.len() {
                match file.read_at(&mut buf[got..], offset + got as u64) {
                    Ok(0) => break,
                    Ok(n) => got += n,
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(FileError::of(&e)),
                }
            }
            buf.truncate(got);
            Ok(FileAnswer::Data(Arc::from(buf)))
        }
        FileOp::Crc(path) => {
            let mut file = open(cfg, path)?;
            let mut buf = vec![0u8; 64 * 1024];
            let mut crc = 0;
            loop {
                match file.read(&mut buf) {
                    Ok(0) => break,
                    Ok(n) => crc = crc32(crc, &buf[..n]),
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(FileError::of(&e)),
                }
            }
            Ok(FileAnswer::Crc(crc))
        }
        FileOp::EraseLogs => Ok(erase_logs(cfg)),
    }
}

/// The folder of a disk root.
fn root_dir(cfg: &WorkerConfig, root: DiskRoot) -> PathBuf {
    cfg.data_dir.join(root.folder())
}

/// The real path of `path`, every part checked again (admitted names, no
/// symbolic link on the way); `want_dir` says what the last part must be.
fn real_path(cfg: &WorkerConfig, path: &DiskPath, want_dir: bool) -> Result<PathBuf, FileError> {
    let depth_ok = path.root.nests() || path.parts.len() <= 1;
    if !depth_ok {
        return Err(FileError::NotFound);
    }
    let mut real = root_dir(cfg, path.root);
    let last = path.parts.len().saturating_sub(1);
    for (i, part) in path.parts.iter().enumerate() {
        let is_last = i == last;
        let admitted = if is_last && !want_dir {
            path.root.admits(part)
        } else {
            path.root.nests() && safe_name(part)
        };
        if !admitted {
            return Err(FileError::NotFound);
        }
        real.push(part);
        let meta = std::fs::symlink_metadata(&real).map_err(|e| FileError::of(&e))?;
        let ok = if is_last && !want_dir {
            meta.is_file()
        } else {
            meta.is_dir()
        };
        if !ok {
            return Err(FileError::NotFound);
        }
    }
    Ok(real)
}

/// Opens a file for reading, refusing a symbolic link in its place.
fn open(cfg: &WorkerConfig, path: &DiskPath) -> Result<File, FileError> {
    if path.parts.is_empty() {
        return Err(FileError::NotFound);
    }
    let real = real_path(cfg, path, false)?;
    OpenOptions::new()
        .read(true)
        .custom_flags(nix::libc::O_NOFOLLOW)
        .open(real)
        .map_err(|e| FileError::of(&e))
}

/// The entries of a disk folder, by name: files its root admits, and the
/// recordings' folders. Anything else (links, devices, other names) is
/// not shown.
fn list(cfg: &WorkerConfig, dir: &DiskPath) -> Result<Vec<DirEntry>, FileError> {
    let real = real_path(cfg, dir, true)?;
    let read = match std::fs::read_dir(&real) {
        Ok(r) => r,
        // A folder that does not exist yet (no recording made): empty.
        Err(e) if e.kind() == io::ErrorKind::NotFound && dir.parts.is_empty() => {
            return Ok(Vec::new());
        }
        Err(e) => return Err(FileError::of(&e)),
    };
    let may_nest = dir.root.nests() && dir.parts.len() + 1 < super::tree::MAX_DEPTH;
    let mut entries = Vec::new();
    for entry in read.flatten() {
        let Ok(name) = entry.file_name().into_string() else {
            continue;
        };
        let Ok(meta) = std::fs::symlink_metadata(entry.path()) else {
            continue;
        };
        if meta.is_file() && dir.root.admits(&name) {
            entries.push(DirEntry::File {
                name,
                size: meta.len(),
            });
        } else if meta.is_dir() && may_nest && safe_name(&name) {
            entries.push(DirEntry::Dir { name });
        }
    }
    entries.sort_by(|a, b| entry_name(a).cmp(entry_name(b)));
    entries.truncate(MAX_ENTRIES);
    Ok(entries)
}

fn entry_name(e: &DirEntry) -> &str {
    match e {
        DirEntry::File { name, .. } | DirEntry::Dir { name } => name,
    }
}

/// Our telemetry logs in the tlogs folder, in the order they were
/// written: `(session, index, name, size)`.
fn tlog_files(cfg: &WorkerConfig) -> Result<Vec<(String, u32, String, u64)>, FileError> {
    let read = match std::fs::read_dir(root_dir(cfg, DiskRoot::Tlogs)) {
        Ok(r) => r,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(FileError::of(&e)),
    };
    let mut files: Vec<(String, u32, String, u64)> = read
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let (session, index) = tlog::parse_file_name(&name)?;
            let meta = std::fs::symlink_metadata(e.path()).ok()?;
            meta.is_file()
                .then(|| (session.to_owned(), index, name.clone(), meta.len()))
        })
        .collect();
    files.sort();
    Ok(files)
}

/// The logs with something in them, oldest first (the newest
/// [`MAX_ENTRIES`] of them), each with the time of its first record.
fn catalog(cfg: &WorkerConfig) -> Result<Vec<LogFile>, FileError> {
    let mut files = tlog_files(cfg)?;
    files.retain(|f| f.3 > 0);
    let skip = files.len().saturating_sub(MAX_ENTRIES);
    let dir = root_dir(cfg, DiskRoot::Tlogs);
    Ok(files
        .into_iter()
        .skip(skip)
        .map(|(_, _, name, size)| {
            let time_utc = first_record_s(&dir.join(&name)).unwrap_or(0);
            LogFile {
                name,
                size,
                time_utc,
            }
        })
        .collect())
}

/// The time of a tlog's first record (its first 8 bytes: µs since the
/// epoch, big-endian), else the file's modification time; in seconds.
fn first_record_s(path: &std::path::Path) -> Option<u32> {
    let file = OpenOptions::new()
        .read(true)
        .custom_flags(nix::libc::O_NOFOLLOW)
        .open(path)
        .ok()?;
    let mut stamp = [0u8; 8];
    let from_record = file
        .read_exact_at(&mut stamp, 0)
        .ok()
        .map(|()| u64::from_be_bytes(stamp) / 1_000_000)
        // A plausible time (2001 .. 2100), not garbage.
        .filter(|s| (1_000_000_000..4_102_444_800).contains(s));
    let s = match from_record {
        Some(s) => s,
        None => file
            .metadata()
            .ok()?
            .modified()
            .ok()?
            .duration_since(std::time::UNIX_EPOCH)
            .ok()?
            .as_secs(),
    };
    u32::try_from(s).ok()
}

/// Deletes every telemetry log this run does not write.
fn erase_logs(cfg: &WorkerConfig) -> FileAnswer {
    let dir = root_dir(cfg, DiskRoot::Tlogs);
    let (mut deleted, mut kept) = (0, 0);
    for (_, _, name, _) in tlog_files(cfg).unwrap_or_default() {
        let path = dir.join(&name);
        if cfg.running.as_ref().is_some_and(|r| r.contains(&path)) {
            kept += 1;
            continue;
        }
        match std::fs::remove_file(&path) {
            Ok(()) => {
                deleted += 1;
                tracing::info!(path = %path.display(), "telemetry log erased (LOG_ERASE)");
            }
            Err(e) => {
                kept += 1;
                tracing::warn!(path = %path.display(), error = %e, "cannot erase a telemetry log");
            }
        }
    }
    FileAnswer::Erased { deleted, kept }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    fn cfg(dir: &std::path::Path) -> WorkerConfig {
        WorkerConfig {
            data_dir: dir.to_path_buf(),
            running: None,
        }
    }

    fn tlog(parts: &[&str]) -> DiskPath {
        DiskPath {
            root: DiskRoot::Tlogs,
            parts: parts.iter().map(|s| (*s).to_owned()).collect(),
        }
    }

    #[test]
    fn reads_lists_and_refuses_links() {
        let dir = tempfile::tempdir().unwrap();
        let tlogs = dir.path().join("tlogs");
        std::fs::create_dir(&tlogs).unwrap();
        let name = "neptunus-20260101-000000.tlog";
        let mut bytes = 1_800_000_000_000_000u64.to_be_bytes().to_vec();
        bytes.extend((0..1000u32).map(|i| i as u8));
        std::fs::write(tlogs.join(name), &bytes).unwrap();
        std::fs::write(tlogs.join("notes.txt"), b"x").unwrap();
        std::fs::write(dir.path().join("params.toml"), b"secret").unwrap();
        let link = "neptunus-20260102-000000.tlog";
        std::os::unix::fs::symlink(dir.path().join("params.toml"), tlogs.join(link)).unwrap();
        let c = cfg(dir.path());

        let listing = execute(&c, &FileOp::List(tlog(&[]))).unwrap();
        assert_eq!(
            listing,
            FileAnswer::Listing(vec![DirEntry::File {
                name: name.into(),
                size: bytes.len() as u64
            }])
        );
        let read = execute(
            &c,
            &FileOp::Read {
                path: tlog(&[name]),
                offset: 1000,
                len: 100,
            },
        )
        .unwrap();
        assert_eq!(read, FileAnswer::Data(Arc::from(&bytes[1000..])));
        assert_eq!(
            execute(&c, &FileOp::Stat(tlog(&[link]))),
            Err(FileError::NotFound)
        );
        assert_eq!(
            execute(&c, &FileOp::Crc(tlog(&[name]))),
            Ok(FileAnswer::Crc(crc32(0, &bytes)))
        );
        let FileAnswer::Catalog(cat) = execute(&c, &FileOp::LogCatalog).unwrap() else {
            panic!()
        };
        assert_eq!(
            cat,
            vec![LogFile {
                name: name.into(),
                size: bytes.len() as u64,
                time_utc: 1_800_000_000
            }]
        );
        // No recordings folder yet: an empty listing, not an error.
        let rec = DiskPath {
            root: DiskRoot::Recordings,
            parts: vec![],
        };
        assert_eq!(
            execute(&c, &FileOp::List(rec)),
            Ok(FileAnswer::Listing(vec![]))
        );
    }

    #[test]
    fn erase_keeps_what_this_run_writes() {
        let dir = tempfile::tempdir().unwrap();
        let tlogs = dir.path().join("tlogs");
        std::fs::create_dir(&tlogs).unwrap();
        let old = tlogs.join("neptunus-20260101-000000.tlog");
        let live = tlogs.join("neptunus-20260102-000000.tlog");
        let other = tlogs.join("keep-me.txt");
        for p in [&old, &live, &other] {
            std::fs::write(p, b"12345678").unwrap();
        }
        let running = TlogRun::default();
        running.add(live.clone());
        let c = WorkerConfig {
            data_dir: dir.path().to_path_buf(),
            running: Some(running),
        };
        assert_eq!(
            execute(&c, &FileOp::EraseLogs),
            Ok(FileAnswer::Erased {
                deleted: 1,
                kept: 1
            })
        );
        assert!(!old.exists() && live.exists() && other.exists());
    }
}
