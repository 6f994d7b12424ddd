//! MAVLink FTP's read side over the vehicle's file tree: OpenFileRO,
//! ReadFile, BurstReadFile, ListDirectory, CalcFileCRC32,
//! TerminateSession, ResetSessions. Everything that would write is
//! answered FileProtected; an unknown opcode UnknownCommand.
//!
//! Sessions belong to the station that opened them (its system and
//! component ids): a request naming a session that is not open, or is
//! another station's, is answered InvalidSession and changes nothing. A
//! station has at most [`SESSIONS_PER_STATION`] open (all together
//! [`SESSIONS_MAX`]); one unused for a minute (`IDLE`) is closed. A burst sends up
//! to [`BURST_BYTES`] (whole packets, so a short last packet always means
//! the end of the file, as pymavlink reads it), paced like a log download;
//! the station asks for the next one. Replies go to the asker alone, as
//! bulk (never into the telemetry log).

use std::sync::Arc;
use std::time::Duration;

use super::pace::{Pacer, START_RATE};
use super::stream::{Kind, READ_CHUNK, Span, Stream};
use super::{PENDING_PER_STATION, Pending, Source, Station};
use crate::dialect::neptunus::*;
use crate::files::tree::{self, Node, StaticDir};
use crate::files::{FileAnswer, FileError, FileOp, FileRequest, MemFile, component};
use crate::mavlink::ftp::{self as wire, DirEntry, Header, Nak, Request, errno};
use crate::vehicle::machine::{Now, Output, Sender, Vehicle};

/// Sessions one station may have open.
const SESSIONS_PER_STATION: usize = 4;
/// Sessions open at once, all stations together.
const SESSIONS_MAX: usize = 16;
/// The most one burst sends (whole packets of this size or less).
const BURST_BYTES: usize = 48 * 1024;

/// An FTP request waiting for the disk.
#[derive(Debug, Clone)]
pub(super) enum FtpWait {
    List {
        req: Header,
        index: u32,
    },
    Open {
        req: Header,
        source: Source,
    },
    Crc {
        req: Header,
    },
    Read {
        req: Header,
        session: u8,
        offset: u64,
    },
}

#[derive(Debug, Clone)]
struct Session {
    id: u8,
    station: Station,
    source: Source,
    size: u64,
    last_used: Duration,
    /// The rate its bursts go at (what the last one learnt).
    rate: f64,
    /// The last bytes read for a ReadFile: (offset, bytes).
    cache: Option<(u64, Arc<[u8]>)>,
}

#[derive(Debug, Default)]
pub(super) struct FtpState {
    sessions: Vec<Session>,
    next_id: u8,
}

impl FtpState {
    /// Closes the sessions nobody used for a minute.
    pub(super) fn expire(&mut self, now: Duration) {
        self.sessions
            .retain(|s| now.saturating_sub(s.last_used) < super::IDLE);
    }

    pub(super) fn session_ids(&self) -> Vec<u8> {
        self.sessions.iter().map(|s| s.id).collect()
    }

    /// A burst ended: its session keeps the rate it learnt.
    pub(super) fn burst_ended(&mut self, s: &Stream) {
        if let Kind::Burst { session, .. } = s.kind
            && let Some(sess) = self.sessions.iter_mut().find(|x| x.id == session)
        {
            sess.rate = s.pacer.rate();
        }
    }

    /// A new session for `station`, if it and everyone together have room.
    fn open(&mut self, station: Station, source: Source, size: u64, now: Duration) -> Option<u8> {
        self.expire(now);
        let mine = self
            .sessions
            .iter()
            .filter(|s| s.station.is(&station))
            .count();
        if mine >= SESSIONS_PER_STATION || self.sessions.len() >= SESSIONS_MAX {
            return None;
        }
        // The next free id, so a closed session's id is not at once reused.
        let id = (0..=u8::MAX)
            .map(|k| self.next_id.wrapping_add(k))
            .find(|id| !self.sessions.iter().any(|s| s.id == *id))?;
        self.next_id = id.wrapping_add(1);
        self.sessions.push(Session {
            id,
            station,
            source,
            size,
            last_used: now,
            rate: START_RATE,
            cache: None,
        });
        Some(id)
    }

    /// The station's open session `id`, marked used.
    fn session(&mut self, station: &Station, id: u8, now: Duration) -> Option<&mut Session> {
        let s = self
            .sessions
            .iter_mut()
            .find(|s| s.id == id && s.station.is(station))?;
        s.last_used = now;
        s.station = *station;
        Some(s)
    }
}

/// The NAK for a disk error.
pub(super) fn nak_of(err: FileError) -> Nak {
    match err {
        FileError::NotFound => Nak::FileNotFound,
        FileError::TooLarge => Nak::FailErrno(errno::EFBIG),
        FileError::Io(e) => Nak::FailErrno(u8::try_from(e).unwrap_or(errno::EIO)),
    }
}

fn reply(station: Station, payload: [u8; wire::PAYLOAD_LEN], out: &mut Vec<Output>) {
    out.push(Output::Bulk {
        to: station.to(),
        msg: station.ftp_message(payload),
    });
}

fn mem_len(m: MemFile) -> u64 {
    component::file(m).bytes.len() as u64
}

impl Vehicle {
    /// A FILE_TRANSFER_PROTOCOL request (addressed to us).
    pub(in crate::vehicle::machine) fn on_ftp(
        &mut self,
        from: Sender,
        m: &FILE_TRANSFER_PROTOCOL_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let station = Station::of(from);
        let (h, request) = wire::parse(&m.payload);
        let request = match request {
            Ok(r) => r,
            Err(nak) => return reply(station, wire::nak(&h, nak), out),
        };
        let t = now.mono;
        let answer = match request {
            Request::TerminateSession { session } => {
                match self.transfers.ftp.session(&station, session, t) {
                    Some(_) => {
                        self.close_session(session);
                        wire::ack(&h, &[])
                    }
                    None => wire::nak(&h, Nak::InvalidSession),
                }
            }
            Request::ResetSessions => {
                let mine: Vec<u8> = self
                    .transfers
                    .ftp
                    .sessions
                    .iter()
                    .filter(|s| s.station.is(&station))
                    .map(|s| s.id)
                    .collect();
                for id in mine {
                    self.close_session(id);
                }
                wire::ack(&h, &[])
            }
            Request::Write { .. } => wire::nak(&h, Nak::FileProtected),
            Request::ListDirectory { path, index } => match tree::resolve(path) {
                Some(Node::Static(dir)) => list_reply(&h, &static_listing(dir), index),
                Some(Node::Disk(dir)) => {
                    return self.ftp_disk(
                        from,
                        h,
                        FileOp::List(dir),
                        |req| FtpWait::List { req, index },
                        now,
                        out,
                    );
                }
                Some(Node::Mem(_)) | None => wire::nak(&h, Nak::FileNotFound),
            },
            Request::OpenFileRO { path } => match tree::resolve(path) {
                Some(Node::Mem(m)) => {
                    match self
                        .transfers
                        .ftp
                        .open(station, Source::Mem(m), mem_len(m), t)
                    {
                        Some(id) => wire::ack_open(&h, id, mem_len(m) as u32),
                        None => wire::nak(&h, Nak::NoSessionsAvailable),
                    }
                }
                Some(Node::Disk(file)) if !file.parts.is_empty() => {
                    let source = Source::Disk(file.clone());
                    return self.ftp_disk(
                        from,
                        h,
                        FileOp::Stat(file),
                        |req| FtpWait::Open { req, source },
                        now,
                        out,
                    );
                }
                _ => wire::nak(&h, Nak::FileNotFound),
            },
            Request::CalcFileCRC32 { path } => match tree::resolve(path) {
                Some(Node::Mem(m)) => wire::ack(&h, &component::file(m).crc.to_le_bytes()),
                Some(Node::Disk(file)) if !file.parts.is_empty() => {
                    return self.ftp_disk(
                        from,
                        h,
                        FileOp::Crc(file),
                        |req| FtpWait::Crc { req },
                        now,
                        out,
                    );
                }
                _ => wire::nak(&h, Nak::FileNotFound),
            },
            // A record's session is read only by a station that still may
            // control (with signing on: signed; its ids alone are not enough).
            Request::ReadFile { session, .. } | Request::BurstReadFile { session, .. }
                if self.session_is_record(&station, session) && !self.may_control(from) =>
            {
                wire::nak(&h, Nak::FailErrno(errno::EACCES))
            }
            Request::ReadFile {
                session,
                offset,
                size,
            } => match self.ftp_read(station, &h, session, offset, size, t, out) {
                Some(answer) => answer,
                None => return,
            },
            Request::BurstReadFile {
                session,
                offset,
                size,
            } => match self.ftp_burst(station, &h, session, offset, size, t) {
                Some(answer) => answer,
                None => return,
            },
        };
        reply(station, answer, out);
    }

    /// A request the disk answers: for stations that may control (the
    /// logs and recordings are records), a few at a time per station.
    fn ftp_disk(
        &mut self,
        from: Sender,
        h: Header,
        op: FileOp,
        wait: impl FnOnce(Header) -> FtpWait,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let station = Station::of(from);
        if !self.records_allowed(from, "file access", now, out) {
            return reply(station, wire::nak(&h, Nak::FailErrno(errno::EACCES)), out);
        }
        if self.transfers.pending_of(&station) >= PENDING_PER_STATION {
            return reply(station, wire::nak(&h, Nak::FailErrno(errno::EBUSY)), out);
        }
        let token = self.transfers.token(Pending::Ftp(station, wait(h)));
        out.push(Output::Files(FileRequest { token, op }));
    }

    /// ReadFile: the bytes at hand now (None: asked of the disk, answered then).
    #[allow(clippy::too_many_arguments)]
    fn ftp_read(
        &mut self,
        station: Station,
        h: &Header,
        session: u8,
        offset: u32,
        size: u8,
        t: Duration,
        out: &mut Vec<Output>,
    ) -> Option<[u8; wire::PAYLOAD_LEN]> {
        let want = match usize::from(size) {
            0 => wire::DATA_MAX,
            n => n.min(wire::DATA_MAX),
        };
        let offset = u64::from(offset);
        let Some(s) = self.transfers.ftp.session(&station, session, t).cloned() else {
            return Some(wire::nak(h, Nak::InvalidSession));
        };
        if offset >= s.size {
            return Some(wire::nak(h, Nak::EndOfFile));
        }
        let want = want.min((s.size - offset) as usize);
        // The session's burst has the bytes, or sent them already (a gap:
        // the station lost some, the burst slows down).
        let burst = self
            .transfers
            .streams
            .iter_mut()
            .find(|st| matches!(st.kind, Kind::Burst { session: id, .. } if id == session));
        if let Some(st) = burst {
            if offset < st.sent_high {
                st.pacer.loss();
                st.lost = true;
            }
            if let Some(d) = st.data_at(offset) {
                let n = want.min(d.len());
                return Some(wire::ack_read(h, offset as u32, &d[..n]));
            }
        }
        let at_hand: Option<&[u8]> = match &s.source {
            Source::Mem(m) => component::file(*m).bytes.get(offset as usize..),
            Source::Disk(_) => s.cache.as_ref().and_then(|(at, b)| {
                let rel = usize::try_from(offset.checked_sub(*at)?).ok()?;
                b.get(rel..).filter(|d| !d.is_empty())
            }),
        };
        if let Some(d) = at_hand {
            let n = want.min(d.len());
            return Some(wire::ack_read(h, offset as u32, &d[..n]));
        }
        let Source::Disk(path) = s.source else {
            return Some(wire::nak(h, Nak::EndOfFile));
        };
        if self.transfers.pending_of(&station) >= PENDING_PER_STATION {
            return Some(wire::nak(h, Nak::FailErrno(errno::EBUSY)));
        }
        let wait = FtpWait::Read {
            req: *h,
            session,
            offset,
        };
        let token = self.transfers.token(Pending::Ftp(station, wait));
        out.push(Output::Files(FileRequest {
            token,
            op: FileOp::Read {
                path,
                offset,
                len: READ_CHUNK,
            },
        }));
        None
    }

    /// BurstReadFile: starts the session's burst (None: it answers by itself).
    fn ftp_burst(
        &mut self,
        station: Station,
        h: &Header,
        session: u8,
        offset: u32,
        size: u8,
        t: Duration,
    ) -> Option<[u8; wire::PAYLOAD_LEN]> {
        let Some(s) = self.transfers.ftp.session(&station, session, t).cloned() else {
            return Some(wire::nak(h, Nak::InvalidSession));
        };
        if self.transfers.endpoint_rate(station.endpoint) == 0 {
            return Some(wire::nak(h, Nak::FailErrno(errno::ENOTSUP)));
        }
        let offset = u64::from(offset);
        if offset >= s.size {
            return Some(wire::nak(h, Nak::EndOfFile));
        }
        let packet = match usize::from(size) {
            0 => wire::DATA_MAX,
            n => n.min(wire::DATA_MAX),
        };
        let len = (BURST_BYTES / packet * packet) as u64;
        let streams = &mut self.transfers.streams;
        // A new burst of the session replaces the one running.
        let old = streams
            .iter()
            .position(|st| matches!(st.kind, Kind::Burst { session: id, .. } if id == session))
            .map(|i| streams.remove(i));
        let mut pacer = Pacer::new(s.rate);
        if let Some(old) = &old {
            pacer = old.pacer.clone();
            if offset < old.sent_high {
                pacer.loss();
            }
        }
        let kind = Kind::Burst {
            session,
            req: *h,
            packet,
            sent: 0,
        };
        let mut st = Stream::new(station, kind, s.source.clone(), s.size, pacer, t);
        if let Some(old) = old {
            st.inherit(old);
        }
        st.spans.push_back(Span::new(offset, offset + len, s.size));
        streams.push(st);
        None
    }

    /// Whether the station's session `id` reads a record (a disk file).
    fn session_is_record(&self, station: &Station, id: u8) -> bool {
        self.transfers
            .ftp
            .sessions
            .iter()
            .any(|s| s.id == id && s.station.is(station) && matches!(s.source, Source::Disk(_)))
    }

    fn close_session(&mut self, id: u8) {
        self.transfers.ftp.sessions.retain(|s| s.id != id);
        self.transfers
            .streams
            .retain(|st| !matches!(st.kind, Kind::Burst { session, .. } if session == id));
    }

    /// The disk answered an FTP request.
    pub(super) fn on_ftp_disk(
        &mut self,
        station: Station,
        wait: FtpWait,
        result: Result<FileAnswer, FileError>,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let answer = match (wait, result) {
            (FtpWait::List { req, index }, Ok(FileAnswer::Listing(entries))) => {
                list_reply(&req, &entries, index)
            }
            (FtpWait::Open { req, source }, Ok(FileAnswer::Size(size))) => {
                match u32::try_from(size) {
                    Err(_) => wire::nak(&req, Nak::FailErrno(errno::EFBIG)),
                    Ok(len) => match self.transfers.ftp.open(station, source, size, now.mono) {
                        Some(id) => wire::ack_open(&req, id, len),
                        None => wire::nak(&req, Nak::NoSessionsAvailable),
                    },
                }
            }
            (FtpWait::Crc { req }, Ok(FileAnswer::Crc(crc))) => wire::ack(&req, &crc.to_le_bytes()),
            (
                FtpWait::Read {
                    req,
                    session,
                    offset,
                },
                Ok(FileAnswer::Data(data)),
            ) => {
                let want = match usize::from(req.size) {
                    0 => wire::DATA_MAX,
                    n => n.min(wire::DATA_MAX),
                };
                match self.transfers.ftp.session(&station, session, now.mono) {
                    None => wire::nak(&req, Nak::InvalidSession),
                    Some(_) if data.is_empty() => wire::nak(&req, Nak::EndOfFile),
                    Some(s) => {
                        let n = want.min(data.len());
                        let payload = wire::ack_read(&req, offset as u32, &data[..n]);
                        s.cache = Some((offset, data));
                        payload
                    }
                }
            }
            (
                FtpWait::List { req, .. }
                | FtpWait::Open { req, .. }
                | FtpWait::Crc { req }
                | FtpWait::Read { req, .. },
                result,
            ) => wire::nak(
                &req,
                nak_of(result.err().unwrap_or(FileError::Io(errno::EIO.into()))),
            ),
        };
        reply(station, answer, out);
    }
}

/// The entries of a folder of the tree itself.
fn static_listing(dir: StaticDir) -> Vec<DirEntry> {
    tree::static_entries(dir)
        .iter()
        .map(|(name, is_dir)| {
            if *is_dir {
                DirEntry::Dir {
                    name: (*name).to_owned(),
                }
            } else {
                let size = MemFile::ALL
                    .into_iter()
                    .find(|m| m.name() == *name)
                    .map_or(0, mem_len);
                DirEntry::File {
                    name: (*name).to_owned(),
                    size,
                }
            }
        })
        .collect()
}

/// The ListDirectory reply: the entries from `index` on that fit, or EOF.
fn list_reply(req: &Header, entries: &[DirEntry], index: u32) -> [u8; wire::PAYLOAD_LEN] {
    let (data, n) = wire::list_data(entries, index as usize);
    if n == 0 {
        wire::nak(req, Nak::EndOfFile)
    } else {
        wire::ack(req, &data)
    }
}
