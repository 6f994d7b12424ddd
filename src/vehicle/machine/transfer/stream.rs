//! One stream of file data to one station — a log download's LOG_DATA or
//! an FTP burst's packets — and the pass that sends what its pacing
//! allows.
//!
//! A stream sends the ranges it was asked for, in order, from the file's
//! bytes read ahead: a file made in memory is all there; a disk file is
//! read [`READ_CHUNK`] at a time by the disk worker, the next chunk asked
//! for while the current one is being sent. A pass never waits: without
//! the bytes it needs, a stream sends nothing until they come.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;

use super::pace::Pacer;
use super::{Source, Station};
use crate::dialect::neptunus::*;
use crate::files::{FileOp, FileRequest, component};
use crate::mavlink::ftp;
use crate::vehicle::machine::Output;

/// Bytes of a disk file read at a time.
pub const READ_CHUNK: u32 = 32 * 1024;
/// How far ahead of what it sends a stream has the file read.
const READ_AHEAD: u64 = 2 * READ_CHUNK as u64;
/// LOG_DATA's data bytes.
pub const LOG_DATA_LEN: usize = 90;
/// A LOG_DATA frame beside its data (header, the rest of the payload, CRC).
const LOG_DATA_FRAME: f64 = 23.0;
/// An FTP frame beside its data.
const FTP_FRAME: f64 = 26.0;

/// What the stream is.
#[derive(Debug, Clone)]
pub enum Kind {
    /// A log download: LOG_DATA of log `id`.
    Log { id: u16 },
    /// An FTP burst answering `req` on `session`, packets of `packet` bytes.
    Burst {
        session: u8,
        req: ftp::Header,
        packet: usize,
        /// Packets sent so far (their sequence numbers count on).
        sent: u32,
    },
}

/// One range asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Span {
    pub start: u64,
    /// The next byte to send.
    pub pos: u64,
    /// One past the last byte to send (at most the file's size).
    pub end: u64,
    /// The station asked for more than the file holds: a log download
    /// ends it with an empty LOG_DATA where the last one was full.
    pub past_eof: bool,
}

impl Span {
    pub fn new(start: u64, requested_end: u64, size: u64) -> Self {
        let end = requested_end.min(size).max(start);
        Self {
            start,
            pos: start,
            end,
            past_eof: requested_end > size,
        }
    }
}

#[derive(Debug, Clone)]
pub struct Stream {
    pub station: Station,
    pub kind: Kind,
    pub source: Source,
    /// The file's size as the transfer knows it.
    pub size: u64,
    pub spans: VecDeque<Span>,
    /// Bytes read ahead: (offset, bytes), in file order.
    bufs: VecDeque<(u64, Arc<[u8]>)>,
    /// The read in flight: (token, offset).
    pub reading: Option<(u64, u64)>,
    pub pacer: Pacer,
    /// One past the highest byte sent.
    pub sent_high: u64,
    /// The station asked again for sent data since the current span began.
    pub lost: bool,
    /// The disk could not give the bytes: the stream ends.
    pub failed: bool,
    /// When the station last asked it for something.
    pub last_used: Duration,
}

/// What a pass did that the protocol around it must know.
#[derive(Debug, Default)]
pub struct PassResult {
    /// The stream sent all it was asked for.
    pub done: bool,
}

impl Stream {
    pub fn new(
        station: Station,
        kind: Kind,
        source: Source,
        size: u64,
        pacer: Pacer,
        now: Duration,
    ) -> Self {
        Self {
            station,
            kind,
            source,
            size,
            spans: VecDeque::new(),
            bufs: VecDeque::new(),
            reading: None,
            pacer,
            sent_high: 0,
            lost: false,
            failed: false,
            last_used: now,
        }
    }

    /// Takes over what `old` (the stream this one replaces) had read.
    pub fn inherit(&mut self, old: Stream) {
        if old.source == self.source {
            self.bufs = old.bufs;
            // Its read in flight is not this stream's: it is dropped on arrival.
        }
    }

    /// The bytes from `pos` on that are at hand, if any.
    pub fn data_at(&self, pos: u64) -> Option<&[u8]> {
        match &self.source {
            Source::Mem(m) => {
                let bytes = &component::file(*m).bytes;
                bytes.get(usize::try_from(pos).ok()?..)
            }
            Source::Disk(_) => self.bufs.iter().find_map(|(at, b)| {
                let rel = usize::try_from(pos.checked_sub(*at)?).ok()?;
                (rel < b.len()).then(|| &b[rel..])
            }),
        }
    }

    /// The `n` bytes from `pos`, if all are at hand (across read chunks).
    fn bytes(&self, pos: u64, n: usize) -> Option<Vec<u8>> {
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            let d = self.data_at(pos + out.len() as u64)?;
            let k = (n - out.len()).min(d.len());
            out.extend_from_slice(&d[..k]);
        }
        Some(out)
    }

    /// Bytes read at `offset` arrived for this stream.
    pub fn read_done(&mut self, offset: u64, data: Arc<[u8]>) {
        self.reading = None;
        if data.is_empty() {
            // The file ends earlier than it did: nothing more to send past here.
            self.size = self.size.min(offset);
            for s in &mut self.spans {
                s.end = s.end.min(self.size).max(s.pos);
            }
            return;
        }
        self.bufs.push_back((offset, data));
        while self.bufs.len() > 3 {
            self.bufs.pop_front();
        }
    }

    /// Whether the stream wants a pass now or later (None: it waits for
    /// the disk, or has nothing to send). Bytes it needs and has not asked
    /// for yet make it due at once: the pass asks for them.
    pub fn due(&self) -> Option<Duration> {
        let span = self.spans.front()?;
        let n = self.packet_len().min((span.end - span.pos) as usize);
        if span.pos < span.end && self.bytes(span.pos, n).is_none() {
            return (self.reading.is_none() && !self.failed).then_some(Duration::ZERO);
        }
        Some(self.pacer.due())
    }

    /// Sends what the pacing allows; asks the disk for what comes next.
    pub fn pass(
        &mut self,
        now: Duration,
        cap: f64,
        next_token: &mut u64,
        out: &mut Vec<Output>,
    ) -> PassResult {
        self.pacer.refill(now, cap);
        loop {
            let Some(span) = self.spans.front().copied() else {
                return PassResult { done: true };
            };
            if span.pos >= span.end {
                self.finish_span(span, cap, out);
                continue;
            }
            let n = self.packet_len().min((span.end - span.pos) as usize);
            // A whole packet or none (a short one would read as the end).
            let Some(data) = self.bytes(span.pos, n) else {
                break;
            };
            let frame = match self.kind {
                Kind::Log { .. } => LOG_DATA_FRAME,
                Kind::Burst { .. } => FTP_FRAME,
            } + n as f64;
            if !self.pacer.take(frame) {
                break;
            }
            let last = span.pos + n as u64 >= span.end;
            self.send(span.pos, &data, last, out);
            let pos = span.pos + n as u64;
            self.sent_high = self.sent_high.max(pos);
            if let Some(s) = self.spans.front_mut() {
                s.pos = pos;
            }
        }
        self.read_ahead(next_token, out);
        PassResult {
            done: self.spans.is_empty(),
        }
    }

    fn packet_len(&self) -> usize {
        match self.kind {
            Kind::Log { .. } => LOG_DATA_LEN,
            Kind::Burst { packet, .. } => packet,
        }
    }

    /// The span is sent: a log download past the end of the file ends with
    /// an empty LOG_DATA (where the last one was full: a shorter one told
    /// the station already).
    fn finish_span(&mut self, span: Span, cap: f64, out: &mut Vec<Output>) {
        if let Kind::Log { .. } = self.kind
            && span.past_eof
            && (span.end - span.start).is_multiple_of(LOG_DATA_LEN as u64)
        {
            self.send(span.end, &[], true, out);
        }
        if !self.lost {
            self.pacer.good(cap);
        }
        self.lost = false;
        self.spans.pop_front();
    }

    fn send(&mut self, offset: u64, data: &[u8], last: bool, out: &mut Vec<Output>) {
        let to = self.station.to();
        let msg = match &mut self.kind {
            Kind::Log { id } => {
                let mut d = [0u8; LOG_DATA_LEN];
                d[..data.len()].copy_from_slice(data);
                MavMessage::LOG_DATA(LOG_DATA_DATA {
                    ofs: offset as u32,
                    id: *id,
                    count: data.len() as u8,
                    data: d,
                })
            }
            Kind::Burst { req, sent, .. } => {
                let payload = ftp::burst_packet(req, *sent, offset as u32, data, last);
                *sent += 1;
                self.station.ftp_message(payload)
            }
        };
        out.push(Output::Bulk { to, msg });
    }

    /// Asks the disk for the next bytes the spans need, one read at a time,
    /// at most [`READ_AHEAD`] past what is being sent.
    fn read_ahead(&mut self, next_token: &mut u64, out: &mut Vec<Output>) {
        let Source::Disk(path) = &self.source else {
            return;
        };
        if self.reading.is_some() || self.failed {
            return;
        }
        let Some(pos) = self.spans.front().map(|s| s.pos) else {
            return;
        };
        // What lies before what is being sent is not needed any more.
        while self
            .bufs
            .front()
            .is_some_and(|(at, b)| at + b.len() as u64 <= pos)
        {
            self.bufs.pop_front();
        }
        // Where the bytes at hand (from `pos` on, without a hole) end.
        let mut have = pos;
        while let Some(n) = self.data_at(have).map(<[u8]>::len) {
            have += n as u64;
        }
        if have >= self.size || have >= pos + READ_AHEAD {
            return;
        }
        if self.data_at(pos).is_none() {
            // A jump (a new span elsewhere): start over from here.
            self.bufs.clear();
        }
        *next_token += 1;
        let token = *next_token;
        self.reading = Some((token, have));
        out.push(Output::Files(FileRequest {
            token,
            op: FileOp::Read {
                path: path.clone(),
                offset: have,
                len: READ_CHUNK,
            },
        }));
    }
}
