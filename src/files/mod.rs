//! The files the vehicle serves to ground stations over MAVLink (onboard
//! log download and MAVLink FTP): which names exist ([`tree`]), the
//! component metadata made in memory ([`component`]), and the thread that
//! does the disk's part ([`worker`]).
//!
//! The vehicle core decides everything about a transfer (who may read
//! what, sessions, pacing, the replies) and never touches a file: what it
//! needs from the disk it asks as a [`FileRequest`] (an `Output` of the
//! core) and gets back as a [`FileReply`] (an `Input`). The worker answers
//! requests in the order they came, one at a time, on its own thread, so
//! a slow disk holds up no socket and no control loop. It reads only
//! through [`tree::DiskPath`]s, which only the tree makes.

pub mod component;
pub mod tree;
pub mod worker;

use std::sync::Arc;

pub use tree::{DiskPath, DiskRoot, MemFile, Node};
pub use worker::{FileWorker, WorkerConfig};

use crate::mavlink::ftp::DirEntry;

/// One job for the disk worker; its reply carries the same token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileRequest {
    pub token: u64,
    pub op: FileOp,
}

/// What the disk worker is asked.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileOp {
    /// The telemetry logs with something in them, oldest first.
    LogCatalog,
    /// The entries of a disk folder (only the names it admits), by name.
    List(DiskPath),
    /// A file's size.
    Stat(DiskPath),
    /// Up to `len` bytes of a file from `offset` (fewer at its end).
    Read {
        path: DiskPath,
        offset: u64,
        len: u32,
    },
    /// The CRC-32 of a whole file, as MAVLink FTP's CalcFileCRC32 gives it.
    Crc(DiskPath),
    /// Deletes the telemetry logs, except the ones this run writes.
    EraseLogs,
}

/// The disk worker's answer to the request with this token.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileReply {
    pub token: u64,
    pub result: Result<FileAnswer, FileError>,
}

/// What the disk worker found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileAnswer {
    Catalog(Vec<LogFile>),
    Listing(Vec<DirEntry>),
    Size(u64),
    Data(Arc<[u8]>),
    Crc(u32),
    Erased { deleted: usize, kept: usize },
}

/// One telemetry log of the catalog.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogFile {
    /// Its name in the tlogs folder.
    pub name: String,
    pub size: u64,
    /// When its first record was written (s since the Unix epoch; the
    /// file's modification time if it has none), 0 when unknown.
    pub time_utc: u32,
}

/// Why the disk worker could not do it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FileError {
    #[error("no such file or folder")]
    NotFound,
    #[error("the file is larger than 4 GiB, the most MAVLink FTP can address")]
    TooLarge,
    #[error("file-system error {0}")]
    Io(i32),
}

impl FileError {
    /// The error of a failed file-system call.
    pub fn of(e: &std::io::Error) -> Self {
        match e.kind() {
            std::io::ErrorKind::NotFound => Self::NotFound,
            // EIO for an error the OS gave no number for.
            _ => Self::Io(e.raw_os_error().unwrap_or(5)),
        }
    }
}
