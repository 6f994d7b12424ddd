//! MAVLink FTP payloads (FILE_TRANSFER_PROTOCOL, message 110): the 12-byte
//! header, the opcodes and NAK codes, a request parsed out of the 251-byte
//! payload, the replies built into one, directory entries and the CRC-32
//! that CalcFileCRC32 answers with.
//!
//! Pure and total: any 251 bytes parse to a header and either a request or
//! the NAK that answers it (fuzzed: `fuzz/fuzz_targets/ftp_requests.rs`).
//! It knows nothing of files, sessions or who asks; the vehicle core's
//! `transfer/ftp.rs` does. Layout and codes are the protocol's
//! (mavlink.io, "File Transfer Protocol"), as ArduPilot, PX4,
//! QGroundControl and pymavlink's `mavftp` use them.

/// The payload of FILE_TRANSFER_PROTOCOL.
pub const PAYLOAD_LEN: usize = 251;
/// seq (u16), session, opcode, size, req_opcode, burst_complete, padding, offset (u32).
pub const HEADER_LEN: usize = 12;
/// Data bytes after the header.
pub const DATA_MAX: usize = PAYLOAD_LEN - HEADER_LEN;

/// The opcodes this side answers, and the two it answers with.
pub mod op {
    pub const NONE: u8 = 0;
    pub const TERMINATE_SESSION: u8 = 1;
    pub const RESET_SESSIONS: u8 = 2;
    pub const LIST_DIRECTORY: u8 = 3;
    pub const OPEN_FILE_RO: u8 = 4;
    pub const READ_FILE: u8 = 5;
    pub const CREATE_FILE: u8 = 6;
    pub const WRITE_FILE: u8 = 7;
    pub const REMOVE_FILE: u8 = 8;
    pub const CREATE_DIRECTORY: u8 = 9;
    pub const REMOVE_DIRECTORY: u8 = 10;
    pub const OPEN_FILE_WO: u8 = 11;
    pub const TRUNCATE_FILE: u8 = 12;
    pub const RENAME: u8 = 13;
    pub const CALC_FILE_CRC32: u8 = 14;
    pub const BURST_READ_FILE: u8 = 15;
    pub const ACK: u8 = 128;
    pub const NAK: u8 = 129;
}

/// Why a request is refused: the NAK's error code (and, for `FailErrno`,
/// the errno after it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Nak {
    Fail,
    /// A file-system error, with its errno.
    FailErrno(u8),
    InvalidDataSize,
    InvalidSession,
    NoSessionsAvailable,
    /// The offset is at or past the end of the file (or the directory has
    /// no entry at that index).
    EndOfFile,
    UnknownCommand,
    FileExists,
    /// The file or directory may not be written (every write here).
    FileProtected,
    FileNotFound,
}

/// errno values the NAKs carry (Linux's numbers, as ArduPilot's and PX4's do).
pub mod errno {
    /// Permission denied: the file is for stations that may control.
    pub const EACCES: u8 = 13;
    /// Too many requests of this station are waiting for the disk.
    pub const EBUSY: u8 = 16;
    /// The file is larger than FTP's 32-bit offsets reach.
    pub const EFBIG: u8 = 27;
    /// Not over this link (no bulk transfers to in-process stations).
    pub const ENOTSUP: u8 = 95;
    /// Any other read error.
    pub const EIO: u8 = 5;
}

impl Nak {
    /// The error code (and errno) bytes of the NAK's data.
    fn data(self) -> ([u8; 2], usize) {
        match self {
            Self::Fail => ([1, 0], 1),
            Self::FailErrno(e) => ([2, e], 2),
            Self::InvalidDataSize => ([3, 0], 1),
            Self::InvalidSession => ([4, 0], 1),
            Self::NoSessionsAvailable => ([5, 0], 1),
            Self::EndOfFile => ([6, 0], 1),
            Self::UnknownCommand => ([7, 0], 1),
            Self::FileExists => ([8, 0], 1),
            Self::FileProtected => ([9, 0], 1),
            Self::FileNotFound => ([10, 0], 1),
        }
    }
}

/// The header of a request or a reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Header {
    pub seq: u16,
    pub session: u8,
    pub opcode: u8,
    /// Bytes of data after the header.
    pub size: u8,
    /// In a reply: the opcode it answers.
    pub req_opcode: u8,
    /// In a burst reply: the last packet of the burst.
    pub burst_complete: u8,
    pub offset: u32,
}

impl Header {
    pub fn read(p: &[u8; PAYLOAD_LEN]) -> Self {
        Self {
            seq: u16::from_le_bytes([p[0], p[1]]),
            session: p[2],
            opcode: p[3],
            size: p[4],
            req_opcode: p[5],
            burst_complete: p[6],
            offset: u32::from_le_bytes([p[8], p[9], p[10], p[11]]),
        }
    }

    fn write(&self, p: &mut [u8; PAYLOAD_LEN]) {
        p[0..2].copy_from_slice(&self.seq.to_le_bytes());
        p[2] = self.session;
        p[3] = self.opcode;
        p[4] = self.size;
        p[5] = self.req_opcode;
        p[6] = self.burst_complete;
        p[7] = 0;
        p[8..12].copy_from_slice(&self.offset.to_le_bytes());
    }
}

/// What a request asks. Paths are the request's bytes (a single trailing
/// NUL removed); whether they name anything is the file tree's question.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request<'a> {
    TerminateSession {
        session: u8,
    },
    ResetSessions,
    /// The entries of `path` from the `index`-th on.
    ListDirectory {
        path: &'a [u8],
        index: u32,
    },
    OpenFileRO {
        path: &'a [u8],
    },
    /// Up to `size` bytes at `offset` (at most [`DATA_MAX`] are sent).
    ReadFile {
        session: u8,
        offset: u32,
        size: u8,
    },
    /// The file from `offset` on, in packets of up to `size` bytes.
    BurstReadFile {
        session: u8,
        offset: u32,
        size: u8,
    },
    CalcFileCRC32 {
        path: &'a [u8],
    },
    /// Create, write, remove, make or remove a directory, open for
    /// writing, truncate or rename: nothing here may be written.
    Write {
        opcode: u8,
    },
}

/// Parses a request: its header, and what it asks or the NAK that answers it.
pub fn parse(payload: &[u8; PAYLOAD_LEN]) -> (Header, Result<Request<'_>, Nak>) {
    let h = Header::read(payload);
    let size = usize::from(h.size);
    if size > DATA_MAX {
        return (h, Err(Nak::InvalidDataSize));
    }
    let data = &payload[HEADER_LEN..HEADER_LEN + size];
    let path = data.strip_suffix(&[0]).unwrap_or(data);
    let request = match h.opcode {
        op::TERMINATE_SESSION => Request::TerminateSession { session: h.session },
        op::RESET_SESSIONS => Request::ResetSessions,
        op::LIST_DIRECTORY => Request::ListDirectory {
            path,
            index: h.offset,
        },
        op::OPEN_FILE_RO => Request::OpenFileRO { path },
        op::READ_FILE => Request::ReadFile {
            session: h.session,
            offset: h.offset,
            size: h.size,
        },
        op::BURST_READ_FILE => Request::BurstReadFile {
            session: h.session,
            offset: h.offset,
            size: h.size,
        },
        op::CALC_FILE_CRC32 => Request::CalcFileCRC32 { path },
        op::CREATE_FILE
        | op::WRITE_FILE
        | op::REMOVE_FILE
        | op::CREATE_DIRECTORY
        | op::REMOVE_DIRECTORY
        | op::OPEN_FILE_WO
        | op::TRUNCATE_FILE
        | op::RENAME => Request::Write { opcode: h.opcode },
        _ => return (h, Err(Nak::UnknownCommand)),
    };
    (h, Ok(request))
}

/// The header of the reply to `req`: the next sequence number, the same
/// session and offset, the request's opcode as `req_opcode`.
fn reply_header(req: &Header, opcode: u8, size: usize) -> Header {
    Header {
        seq: req.seq.wrapping_add(1),
        session: req.session,
        opcode,
        size: size.min(DATA_MAX) as u8,
        req_opcode: req.opcode,
        burst_complete: 0,
        offset: req.offset,
    }
}

fn payload(h: &Header, data: &[u8]) -> [u8; PAYLOAD_LEN] {
    let mut p = [0u8; PAYLOAD_LEN];
    h.write(&mut p);
    let n = data.len().min(DATA_MAX);
    p[HEADER_LEN..HEADER_LEN + n].copy_from_slice(&data[..n]);
    p
}

/// An ACK to `req` carrying `data` (at most [`DATA_MAX`] bytes).
pub fn ack(req: &Header, data: &[u8]) -> [u8; PAYLOAD_LEN] {
    payload(&reply_header(req, op::ACK, data.len()), data)
}

/// The ACK to OpenFileRO: the new session and the file's size.
pub fn ack_open(req: &Header, session: u8, size: u32) -> [u8; PAYLOAD_LEN] {
    let mut h = reply_header(req, op::ACK, 4);
    h.session = session;
    payload(&h, &size.to_le_bytes())
}

/// The ACK to ReadFile: `data` read at `offset`.
pub fn ack_read(req: &Header, offset: u32, data: &[u8]) -> [u8; PAYLOAD_LEN] {
    let mut h = reply_header(req, op::ACK, data.len());
    h.offset = offset;
    payload(&h, data)
}

/// The `index`-th packet (0-based) of a burst answering `req`: `data` at
/// `offset`, its sequence number counting on from the request's, `last`
/// marking the end of the burst.
pub fn burst_packet(
    req: &Header,
    index: u32,
    offset: u32,
    data: &[u8],
    last: bool,
) -> [u8; PAYLOAD_LEN] {
    let mut h = reply_header(req, op::ACK, data.len());
    h.seq = req.seq.wrapping_add(1).wrapping_add(index as u16);
    h.offset = offset;
    h.burst_complete = u8::from(last);
    payload(&h, data)
}

/// The NAK answering `req`.
pub fn nak(req: &Header, why: Nak) -> [u8; PAYLOAD_LEN] {
    let (data, n) = why.data();
    payload(&reply_header(req, op::NAK, n), &data[..n])
}

/// One entry of a ListDirectory reply.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DirEntry {
    File { name: String, size: u64 },
    Dir { name: String },
}

impl DirEntry {
    /// `F<name>\t<size>` or `D<name>`, without the NUL that ends it.
    pub fn encode(&self) -> String {
        match self {
            Self::File { name, size } => format!("F{name}\t{size}"),
            Self::Dir { name } => format!("D{name}"),
        }
    }
}

/// The data of a ListDirectory reply: as many entries from `from` on as
/// fit, each ended by a NUL; and how many went in (0: `from` is past the
/// end, or the first entry alone is too long — both answered with EOF).
pub fn list_data(entries: &[DirEntry], from: usize) -> (Vec<u8>, usize) {
    let mut data = Vec::with_capacity(DATA_MAX);
    let mut n = 0;
    for e in entries.iter().skip(from) {
        let s = e.encode();
        if data.len() + s.len() + 1 > DATA_MAX {
            break;
        }
        data.extend_from_slice(s.as_bytes());
        data.push(0);
        n += 1;
    }
    (data, n)
}

/// The CRC-32 CalcFileCRC32 answers (and ArduPilot's and PX4's servers
/// compute): the IEEE polynomial, reflected, from `state` (0 to start), no
/// final inversion. Feed a file's bytes in pieces, the result of each
/// piece as the next `state`.
pub fn crc32(state: u32, data: &[u8]) -> u32 {
    // crc32fast keeps the standard (inverted) CRC: start it from the
    // inverse of ours and invert its result back.
    let mut h = crc32fast::Hasher::new_with_initial(!state);
    h.update(data);
    !h.finalize()
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    fn request(opcode: u8, session: u8, offset: u32, data: &[u8]) -> [u8; PAYLOAD_LEN] {
        let h = Header {
            seq: 41,
            session,
            opcode,
            size: data.len() as u8,
            req_opcode: 0,
            burst_complete: 0,
            offset,
        };
        payload(&h, data)
    }

    /// The CRC bit by bit, as the protocol's servers define it.
    fn reference_crc(data: &[u8]) -> u32 {
        let mut crc = 0u32;
        for &b in data {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        crc
    }

    #[test]
    fn crc_is_the_servers_and_goes_in_pieces() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 7 + 3) as u8).collect();
        assert_eq!(crc32(0, &data), reference_crc(&data));
        let (a, b) = data.split_at(333);
        assert_eq!(crc32(crc32(0, a), b), reference_crc(&data));
        assert_eq!(crc32(0, b""), 0);
    }

    #[test]
    fn a_request_parses_and_its_replies_answer_it() {
        let p = request(op::OPEN_FILE_RO, 0, 0, b"/logs/tlogs/x.tlog\0");
        let (h, r) = parse(&p);
        assert_eq!(
            r,
            Ok(Request::OpenFileRO {
                path: b"/logs/tlogs/x.tlog"
            })
        );
        let reply = ack_open(&h, 3, 1234);
        let rh = Header::read(&reply);
        assert_eq!(
            (rh.seq, rh.session, rh.opcode, rh.req_opcode, rh.size),
            (42, 3, op::ACK, op::OPEN_FILE_RO, 4)
        );
        assert_eq!(reply[12..16], 1234u32.to_le_bytes());

        let n = nak(&h, Nak::FailErrno(errno::EACCES));
        let nh = Header::read(&n);
        assert_eq!((nh.opcode, nh.size, n[12], n[13]), (op::NAK, 2, 2, 13));
    }

    #[test]
    fn sizes_past_the_payload_and_unknown_opcodes_are_naked() {
        let mut p = request(op::READ_FILE, 1, 0, &[]);
        p[4] = 240;
        assert_eq!(parse(&p).1, Err(Nak::InvalidDataSize));
        for opcode in [op::NONE, 16, 100, op::ACK, op::NAK, 255] {
            assert_eq!(
                parse(&request(opcode, 0, 0, &[])).1,
                Err(Nak::UnknownCommand)
            );
        }
        for opcode in [
            op::CREATE_FILE,
            op::WRITE_FILE,
            op::REMOVE_FILE,
            op::CREATE_DIRECTORY,
            op::REMOVE_DIRECTORY,
            op::OPEN_FILE_WO,
            op::TRUNCATE_FILE,
            op::RENAME,
        ] {
            assert_eq!(
                parse(&request(opcode, 0, 0, b"x")).1,
                Ok(Request::Write { opcode })
            );
        }
    }

    #[test]
    fn burst_packets_count_their_sequence_on() {
        let (h, _) = parse(&request(op::BURST_READ_FILE, 2, 0, &[]));
        let p = burst_packet(&h, 3, 717, &[9; 239], true);
        let ph = Header::read(&p);
        assert_eq!(
            (ph.seq, ph.offset, ph.size, ph.burst_complete),
            (45, 717, 239, 1)
        );
    }

    #[test]
    fn directory_entries_fill_a_reply_and_no_more() {
        let entries: Vec<DirEntry> = (0..40)
            .map(|i| DirEntry::File {
                name: format!("file-{i:02}.tlog"),
                size: 1000 + i,
            })
            .collect();
        let (data, n) = list_data(&entries, 0);
        assert!(data.len() <= DATA_MAX && n > 0 && n < entries.len());
        assert!(data.starts_with(b"Ffile-00.tlog\t1000\0"));
        let (rest, m) = list_data(&entries, n);
        assert!(m > 0);
        assert!(rest.starts_with(format!("Ffile-{n:02}.tlog").as_bytes()));
        assert_eq!(list_data(&entries, 40), (Vec::new(), 0));
        assert_eq!(
            DirEntry::Dir {
                name: "logs".into()
            }
            .encode(),
            "Dlogs"
        );
    }
}
