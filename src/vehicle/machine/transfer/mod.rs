//! File transfers to ground stations: the onboard logs (LOG_REQUEST_LIST,
//! LOG_REQUEST_DATA, LOG_REQUEST_END, LOG_ERASE — `logs.rs`) and MAVLink
//! FTP's read side (`ftp.rs`), over the tree `crate::files::tree` shows.
//!
//! Sans-IO like the rest of the core: what a transfer needs from the disk
//! goes out as [`Output::Files`] and comes back as `Input::Files`; file
//! data goes out as [`Output::Bulk`] (to one station, never into the
//! telemetry log). Data streams (`stream.rs`) are paced (`pace.rs`): each
//! pass — `Input::Transfer`, when [`Vehicle::next_transfer`] says — sends
//! what the stream's rate allows since the last, a few kilobytes at most,
//! so a download never holds the vehicle's loop for long; the rate adapts
//! to what the station takes, within its endpoint's share
//! ([`Vehicle::with_transfer_rates`]).
//!
//! Who may read what: the logs and recordings are the vehicle's records,
//! for stations that may control it (as `/api/logs` is for pilots); the
//! component metadata is for anyone. Erasing logs is a change of the
//! vehicle: it passes the authority check. Everything a station asks is
//! bounded per station (sessions, requests waiting for the disk, ranges),
//! and every refusal is the protocol's answer to that station alone.

mod ftp;
mod logs;
mod pace;
mod stream;

use std::collections::HashMap;
use std::time::Duration;

pub use pace::START_RATE;

use super::{Now, Output, Sender, To, Vehicle};
use crate::dialect::neptunus::*;
use crate::files::{DiskPath, FileAnswer, FileError, FileReply, MemFile};
use crate::mavlink::ftp as wire;
use stream::Stream;

/// Bytes per second file transfers may send over a network endpoint
/// (UDP, TCP), all of its streams together.
pub const NETWORK_RATE: u32 = 4_000_000;
/// A station's requests waiting for the disk at once.
const PENDING_PER_STATION: usize = 8;
/// A log download or FTP session nobody used for this long is dropped.
const IDLE: Duration = Duration::from_secs(60);

/// A station as transfers know it: where replies go, and its ids.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Station {
    endpoint: usize,
    peer: u64,
    sysid: u8,
    compid: u8,
}

impl Station {
    fn of(from: Sender) -> Self {
        Self {
            endpoint: from.endpoint,
            peer: from.peer,
            sysid: from.sysid,
            compid: from.compid,
        }
    }

    fn to(&self) -> To {
        To::Peer(self.endpoint, self.peer)
    }

    /// The same station (its ids; it may have moved to another port).
    fn is(&self, other: &Station) -> bool {
        self.sysid == other.sysid && self.compid == other.compid
    }

    fn ftp_message(&self, payload: [u8; wire::PAYLOAD_LEN]) -> MavMessage {
        MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
            target_network: 0,
            target_system: self.sysid,
            target_component: self.compid,
            payload,
        })
    }
}

/// Where a transfer's bytes come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Source {
    Mem(MemFile),
    Disk(DiskPath),
}

/// A disk request waiting for its answer, and what to do with it.
#[derive(Debug, Clone)]
enum Pending {
    /// The log catalog (for whoever waits in `logs`).
    Catalog,
    /// Read-ahead of a stream (found by its token).
    StreamRead,
    EraseLogs(Station),
    Ftp(Station, ftp::FtpWait),
}

/// Everything the transfers keep.
#[derive(Debug, Default)]
pub(super) struct Transfers {
    next_token: u64,
    pending: HashMap<u64, Pending>,
    /// Per endpoint: bytes per second for file data (0: none over it).
    /// Endpoints past the end of the list: [`NETWORK_RATE`].
    rates: Vec<u32>,
    streams: Vec<Stream>,
    /// The stream the next pass starts with (each gets its turn first).
    turn: usize,
    logs: logs::LogState,
    ftp: ftp::FtpState,
}

impl Transfers {
    fn token(&mut self, pending: Pending) -> u64 {
        self.next_token += 1;
        self.pending.insert(self.next_token, pending);
        self.next_token
    }

    /// Bytes per second over `endpoint` (0: no file data over it).
    fn endpoint_rate(&self, endpoint: usize) -> u32 {
        self.rates.get(endpoint).copied().unwrap_or(NETWORK_RATE)
    }

    /// What one stream on `endpoint` may use: the endpoint's rate shared
    /// by its streams.
    fn share(&self, endpoint: usize) -> f64 {
        let n = self
            .streams
            .iter()
            .filter(|s| s.station.endpoint == endpoint && !s.spans.is_empty())
            .count()
            .max(1);
        f64::from(self.endpoint_rate(endpoint)) / n as f64
    }

    /// The station's requests waiting for the disk.
    fn pending_of(&self, station: &Station) -> usize {
        self.pending
            .values()
            .filter(|p| matches!(p, Pending::Ftp(s, _) | Pending::EraseLogs(s) if s.is(station)))
            .count()
    }
}

impl Vehicle {
    /// Bytes per second file transfers may use over each endpoint, in
    /// endpoint order (0: none — the in-process endpoints, whose clients
    /// have their own way to the logs). Default: [`NETWORK_RATE`] for all.
    pub fn with_transfer_rates(mut self, rates: Vec<u32>) -> Self {
        self.transfers.rates = rates;
        self
    }

    /// When (as `Now::mono`) the file transfers next want
    /// `Input::Transfer`; None while they have nothing to send or wait
    /// for the disk.
    pub fn next_transfer(&self) -> Option<Duration> {
        let lists = self.transfers.logs.lists_due();
        let streams = self.transfers.streams.iter().filter_map(Stream::due).min();
        [lists, streams].into_iter().flatten().min()
    }

    /// A pass of the transfers: each stream sends what its pacing allows.
    pub(super) fn transfer_pass(&mut self, now: Now, out: &mut Vec<Output>) {
        self.send_log_entries(out);
        let t = &mut self.transfers;
        let n = t.streams.len();
        if n == 0 {
            return;
        }
        let first = t.turn % n;
        t.turn = t.turn.wrapping_add(1);
        let mut finished = Vec::new();
        for k in 0..n {
            let i = (first + k) % n;
            let cap = t.share(t.streams[i].station.endpoint);
            let mut token = t.next_token;
            let result = t.streams[i].pass(now.mono, cap, &mut token, out);
            for tok in t.next_token + 1..=token {
                t.pending.insert(tok, Pending::StreamRead);
            }
            t.next_token = token;
            if result.done {
                finished.push(i);
            }
        }
        // Finished bursts end; a finished log download stays, idle, for
        // the station's next range (it keeps the rate it learnt).
        for i in finished.into_iter().rev() {
            if matches!(t.streams[i].kind, stream::Kind::Burst { .. }) {
                let s = t.streams.remove(i);
                t.ftp.burst_ended(&s);
            }
        }
    }

    /// An answer of the disk worker.
    pub(super) fn on_file_reply(&mut self, reply: FileReply, now: Now, out: &mut Vec<Output>) {
        let Some(pending) = self.transfers.pending.remove(&reply.token) else {
            return;
        };
        match pending {
            Pending::Catalog => self.on_log_catalog(reply.result, now, out),
            Pending::EraseLogs(station) => self.on_logs_erased(station, reply.result, now, out),
            Pending::Ftp(station, wait) => self.on_ftp_disk(station, wait, reply.result, now, out),
            Pending::StreamRead => {
                let Some(s) = self
                    .transfers
                    .streams
                    .iter_mut()
                    .find(|s| s.reading.is_some_and(|(t, _)| t == reply.token))
                else {
                    return;
                };
                let offset = s.reading.map_or(0, |(_, o)| o);
                match reply.result {
                    Ok(FileAnswer::Data(data)) => s.read_done(offset, data),
                    other => {
                        s.reading = None;
                        s.failed = true;
                        let err = match other {
                            Err(e) => e,
                            Ok(_) => FileError::Io(wire::errno::EIO.into()),
                        };
                        self.streams_failed(err, now, out);
                    }
                }
            }
        }
    }

    /// A stream's file could not be read: it ends, and its station hears why.
    fn streams_failed(&mut self, err: FileError, now: Now, out: &mut Vec<Output>) {
        let failed: Vec<Stream> = {
            let t = &mut self.transfers;
            let (gone, kept) = std::mem::take(&mut t.streams)
                .into_iter()
                .partition(|s| s.failed);
            t.streams = kept;
            gone
        };
        for s in failed {
            match &s.kind {
                stream::Kind::Burst { req, .. } => {
                    let payload = wire::nak(req, ftp::nak_of(err));
                    out.push(Output::Bulk {
                        to: s.station.to(),
                        msg: s.station.ftp_message(payload),
                    });
                    self.transfers.ftp.burst_ended(&s);
                }
                stream::Kind::Log { id } => {
                    let st = s.station;
                    let from = Sender::new(st.endpoint, st.peer, st.sysid, st.compid);
                    let text =
                        format!("Log {id} cannot be read any more ({err}): list the logs again");
                    self.reply_text(
                        from,
                        super::texts::ReplyKind::Files,
                        MavSeverity::MAV_SEVERITY_WARNING,
                        &text,
                        now,
                        out,
                    );
                }
            }
        }
    }

    /// Drops the log downloads and FTP sessions nobody used for [`IDLE`]
    /// (a station that went away). Run on the core's tick.
    /// Whether `from` may have the vehicle's records (logs, recordings): a
    /// station that may control. If not, it alone is told why; what it asked
    /// (`what`) is then refused by the caller, the protocol's way.
    fn records_allowed(
        &mut self,
        from: Sender,
        what: &str,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        if self.may_control(from) {
            return true;
        }
        let text = format!(
            "Refused {what} from sysid {}: the logs and recordings are for stations that may control (SYSID_MYGCS, NEPT_GCS_ALLOWn{})",
            from.sysid,
            if self.signing_active { ", signed" } else { "" }
        );
        self.reply_text(
            from,
            super::texts::ReplyKind::Files,
            MavSeverity::MAV_SEVERITY_WARNING,
            &text,
            now,
            out,
        );
        false
    }

    pub(super) fn transfers_tick(&mut self, now: Now) {
        self.transfers.ftp.expire(now.mono);
        let live = self.transfers.ftp.session_ids();
        self.transfers.streams.retain(|s| match &s.kind {
            stream::Kind::Burst { session, .. } => live.contains(session),
            stream::Kind::Log { .. } => {
                !s.spans.is_empty() || now.mono.saturating_sub(s.last_used) < IDLE
            }
        });
    }
}
