//! Onboard log download, as QGroundControl's Analyze → Onboard Logs and
//! MAVProxy's `log` module ask for it: LOG_REQUEST_LIST answered with a
//! LOG_ENTRY per telemetry log (size, time of its first record),
//! LOG_REQUEST_DATA with LOG_DATA (90 bytes each) paced as `stream.rs`
//! does, LOG_REQUEST_END, LOG_ERASE.
//!
//! Ids are positions in the catalog of the telemetry logs, oldest first:
//! from 1 with the ArduPilot identity (ArduPilot's numbering, which
//! QGroundControl's ArduPilot code counts on), from 0 with the generic one.
//! The catalog is taken anew at each LOG_REQUEST_LIST and data is served
//! from the catalog the station was shown (a log deleted since is an
//! error, never another file under the same id); sizes are the catalog's
//! (the log being written grows past its entry; a download gets what the
//! entry said). Empty files are not listed (QGroundControl skips a zero
//! size with an ArduPilot vehicle).
//!
//! A station's requests for one log queue up (at most [`MAX_SPANS`],
//! overlapping ones merged): MAVProxy asks for many gaps at once. A
//! request for another log replaces them. A request past the end is
//! answered with an empty LOG_DATA (MAVProxy's end of file), as ArduPilot
//! does.

use std::collections::VecDeque;
use std::time::Duration;

use super::pace::{Pacer, START_RATE};
use super::stream::{Kind, Span, Stream};
use super::{Pending, Source, Station};
use crate::dialect::neptunus::*;
use crate::files::{DiskPath, DiskRoot, FileAnswer, FileError, FileOp, FileRequest, LogFile};
use crate::vehicle::machine::texts::ReplyKind;
use crate::vehicle::machine::{Identity, Now, Output, Sender, Vehicle};

/// Ranges of one log a station may have queued.
const MAX_SPANS: usize = 64;
/// LOG_ENTRY messages sent per pass of the transfers.
const ENTRIES_PER_PASS: usize = 16;

/// What waits for the catalog.
#[derive(Debug, Clone)]
enum Waiting {
    List {
        station: Station,
        start: u16,
        end: u16,
    },
    Data {
        station: Station,
        id: u16,
        ofs: u32,
        count: u32,
    },
}

/// LOG_ENTRY messages still to send to one station.
#[derive(Debug, Clone)]
struct ListJob {
    station: Station,
    entries: VecDeque<LOG_ENTRY_DATA>,
}

#[derive(Debug, Default)]
pub(super) struct LogState {
    /// The logs as last listed.
    catalog: Option<Vec<LogFile>>,
    /// A catalog is being taken.
    refreshing: bool,
    waiting: Vec<Waiting>,
    lists: Vec<ListJob>,
}

impl LogState {
    /// A list is being sent: the transfers want a pass now.
    pub(super) fn lists_due(&self) -> Option<Duration> {
        (!self.lists.is_empty()).then_some(Duration::ZERO)
    }

    /// Adds what waits for the catalog, one of each kind per station (a
    /// newer request replaces an older).
    fn wait(&mut self, w: Waiting) {
        let (station, is_list) = match &w {
            Waiting::List { station, .. } => (*station, true),
            Waiting::Data { station, .. } => (*station, false),
        };
        self.waiting.retain(|old| match old {
            Waiting::List { station: s, .. } => !(is_list && s.is(&station)),
            Waiting::Data { station: s, .. } => is_list || !s.is(&station),
        });
        self.waiting.push(w);
    }
}

impl Vehicle {
    /// The id of the first log in the catalog.
    fn first_log_id(&self) -> u16 {
        match self.identity {
            Identity::Ardupilot => 1,
            Identity::Generic => 0,
        }
    }

    pub(in crate::vehicle::machine) fn log_request_list(
        &mut self,
        from: Sender,
        m: &LOG_REQUEST_LIST_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if !self.records_allowed(from, "the log list", now, out) {
            out.push(Output::Send {
                to: from.reply(),
                msg: empty_list(),
            });
            return;
        }
        let station = Station::of(from);
        let (start, end) = (m.start.min(m.end), m.end.max(m.start));
        self.transfers.logs.wait(Waiting::List {
            station,
            start,
            end,
        });
        // The list is taken anew: new logs, new sizes.
        self.refresh_catalog(out);
    }

    pub(in crate::vehicle::machine) fn log_request_data(
        &mut self,
        from: Sender,
        m: &LOG_REQUEST_DATA_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if !self.records_allowed(from, "a log download", now, out) {
            return;
        }
        if self.transfers.endpoint_rate(from.endpoint) == 0 {
            self.reply_text(
                from,
                ReplyKind::Files,
                MavSeverity::MAV_SEVERITY_WARNING,
                "Log download is not offered over this link: the browser's Logs list downloads the logs",
                now,
                out,
            );
            return;
        }
        let w = Waiting::Data {
            station: Station::of(from),
            id: m.id,
            ofs: m.ofs,
            count: m.count,
        };
        if self.transfers.logs.catalog.is_some() {
            self.start_log_data(w, now, out);
        } else {
            self.transfers.logs.wait(w);
            self.refresh_catalog(out);
        }
    }

    /// LOG_REQUEST_END: the station's download stops (only a station that
    /// may control has one; its ids alone do not stop it).
    pub(in crate::vehicle::machine) fn log_request_end(&mut self, from: Sender) {
        if !self.may_control(from) {
            return;
        }
        let station = Station::of(from);
        self.transfers
            .streams
            .retain(|s| !(matches!(s.kind, Kind::Log { .. }) && s.station.is(&station)));
        self.transfers
            .logs
            .lists
            .retain(|j| !j.station.is(&station));
        self.transfers.logs.waiting.retain(|w| match w {
            Waiting::List { station: s, .. } | Waiting::Data { station: s, .. } => !s.is(&station),
        });
    }

    /// LOG_ERASE: deletes the telemetry logs (never the ones this run
    /// writes), for a station that may change the vehicle.
    pub(in crate::vehicle::machine) fn log_erase(
        &mut self,
        from: Sender,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        use crate::vehicle::machine::authority::Control;
        if let Err(why) = self.check_control(from, Control::Command, now, out) {
            self.refuse_command(from, "log erase", why, now, out);
            return;
        }
        let station = Station::of(from);
        if self
            .transfers
            .pending
            .values()
            .any(|p| matches!(p, Pending::EraseLogs(_)))
        {
            return;
        }
        // What is being downloaded may go: the downloads stop, the ids change.
        self.transfers
            .streams
            .retain(|s| !matches!(s.kind, Kind::Log { .. }));
        self.transfers.logs.catalog = None;
        let token = self.transfers.token(Pending::EraseLogs(station));
        out.push(Output::Files(FileRequest {
            token,
            op: FileOp::EraseLogs,
        }));
    }

    pub(super) fn on_logs_erased(
        &mut self,
        station: Station,
        result: Result<FileAnswer, FileError>,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let from = Sender::new(
            station.endpoint,
            station.peer,
            station.sysid,
            station.compid,
        );
        let text = match result {
            Ok(FileAnswer::Erased { deleted, kept }) => {
                format!("Erased {deleted} telemetry logs; kept {kept} (this run's)")
            }
            Ok(_) | Err(_) => "Could not erase the telemetry logs".to_owned(),
        };
        self.log("logs_erased", Some(station.sysid), text.clone(), out);
        self.reply_text(
            from,
            ReplyKind::Files,
            MavSeverity::MAV_SEVERITY_INFO,
            &text,
            now,
            out,
        );
    }

    /// Asks the disk for the catalog, unless it is being taken already.
    fn refresh_catalog(&mut self, out: &mut Vec<Output>) {
        let logs = &mut self.transfers.logs;
        if logs.refreshing {
            return;
        }
        logs.refreshing = true;
        let token = self.transfers.token(super::Pending::Catalog);
        out.push(Output::Files(FileRequest {
            token,
            op: FileOp::LogCatalog,
        }));
    }

    pub(super) fn on_log_catalog(
        &mut self,
        result: Result<FileAnswer, FileError>,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let logs = &mut self.transfers.logs;
        logs.refreshing = false;
        logs.catalog = Some(match result {
            Ok(FileAnswer::Catalog(c)) => c,
            // No folder to read: no logs.
            _ => Vec::new(),
        });
        for w in std::mem::take(&mut logs.waiting) {
            match w {
                Waiting::List {
                    station,
                    start,
                    end,
                } => self.start_log_list(station, start, end),
                Waiting::Data { .. } => self.start_log_data(w, now, out),
            }
        }
    }

    /// The LOG_ENTRY messages for ids `start..=end`, queued for the station
    /// (one LOG_ENTRY with no logs if there are none).
    fn start_log_list(&mut self, station: Station, start: u16, end: u16) {
        let first = self.first_log_id();
        let catalog = self.transfers.logs.catalog.as_deref().unwrap_or(&[]);
        let n = catalog.len().min(usize::from(u16::MAX - first)) as u16;
        let entries: VecDeque<LOG_ENTRY_DATA> = if n == 0 {
            [entry_none()].into()
        } else {
            let last = first + n - 1;
            catalog
                .iter()
                .zip(first..)
                .filter(|(_, id)| (start..=end).contains(id))
                .map(|(log, id)| LOG_ENTRY_DATA {
                    time_utc: log.time_utc,
                    size: u32::try_from(log.size).unwrap_or(u32::MAX),
                    id,
                    num_logs: n,
                    last_log_num: last,
                })
                .collect()
        };
        let lists = &mut self.transfers.logs.lists;
        lists.retain(|j| !j.station.is(&station));
        lists.push(ListJob { station, entries });
    }

    /// A pass's share of the LOG_ENTRY lists being sent.
    pub(super) fn send_log_entries(&mut self, out: &mut Vec<Output>) {
        for job in &mut self.transfers.logs.lists {
            for e in job.entries.drain(..ENTRIES_PER_PASS.min(job.entries.len())) {
                out.push(Output::Send {
                    to: job.station.to(),
                    msg: MavMessage::LOG_ENTRY(e),
                });
            }
        }
        self.transfers.logs.lists.retain(|j| !j.entries.is_empty());
    }

    /// Starts (or adds to) the station's download of a log of the catalog.
    fn start_log_data(&mut self, w: Waiting, now: Now, out: &mut Vec<Output>) {
        let Waiting::Data {
            station,
            id,
            ofs,
            count,
        } = w
        else {
            return;
        };
        let first = self.first_log_id();
        let log = id.checked_sub(first).and_then(|i| {
            self.transfers
                .logs
                .catalog
                .as_ref()
                .and_then(|c| c.get(usize::from(i)))
                .cloned()
        });
        let Some(log) = log else {
            let from = Sender::new(
                station.endpoint,
                station.peer,
                station.sysid,
                station.compid,
            );
            let text = format!("No log {id}: list the logs again");
            self.reply_text(
                from,
                ReplyKind::Files,
                MavSeverity::MAV_SEVERITY_WARNING,
                &text,
                now,
                out,
            );
            return;
        };
        let span = Span::new(u64::from(ofs), u64::from(ofs) + u64::from(count), log.size);
        let streams = &mut self.transfers.streams;
        let existing = streams.iter().position(|s| {
            matches!(s.kind, Kind::Log { id: i } if i == id) && s.station.is(&station)
        });
        match existing {
            Some(i) => {
                let s = &mut streams[i];
                // Asked again for what was sent: lost on the way.
                if span.start < s.sent_high {
                    s.pacer.loss();
                    s.lost = true;
                }
                s.station = station;
                s.last_used = now.mono;
                add_span(&mut s.spans, span);
            }
            None => {
                // Another log replaces the station's download; its rate goes on.
                let rate = streams
                    .iter()
                    .find(|s| matches!(s.kind, Kind::Log { .. }) && s.station.is(&station))
                    .map_or(START_RATE, |s| s.pacer.rate());
                streams.retain(|s| !(matches!(s.kind, Kind::Log { .. }) && s.station.is(&station)));
                let source = Source::Disk(DiskPath {
                    root: DiskRoot::Tlogs,
                    parts: vec![log.name.clone()],
                });
                let mut s = Stream::new(
                    station,
                    Kind::Log { id },
                    source,
                    log.size,
                    Pacer::new(rate),
                    now.mono,
                );
                s.spans.push_back(span);
                streams.push(s);
            }
        }
    }
}

/// Queues `span`, unless it is already covered; merged with one it
/// overlaps; at most [`MAX_SPANS`] (more are dropped: the station asks again).
fn add_span(spans: &mut VecDeque<Span>, span: Span) {
    if spans
        .iter()
        .any(|s| s.pos <= span.start && span.end <= s.end && s.past_eof >= span.past_eof)
    {
        return;
    }
    if let Some(s) = spans
        .iter_mut()
        .skip(1)
        .find(|s| s.start <= span.end && span.start <= s.end)
    {
        // Not the one being sent (its progress must stay): widen a queued one.
        s.start = s.start.min(span.start);
        s.pos = s.start;
        s.end = s.end.max(span.end);
        s.past_eof |= span.past_eof;
        return;
    }
    if spans.len() < MAX_SPANS {
        spans.push_back(span);
    }
}

/// The LOG_ENTRY that says there are no logs.
fn entry_none() -> LOG_ENTRY_DATA {
    LOG_ENTRY_DATA {
        time_utc: 0,
        size: 0,
        id: 0,
        num_logs: 0,
        last_log_num: 0,
    }
}

fn empty_list() -> MavMessage {
    MavMessage::LOG_ENTRY(entry_none())
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    #[test]
    fn spans_queue_merge_and_stay_bounded() {
        let mut q = VecDeque::new();
        add_span(&mut q, Span::new(0, 900, 10_000));
        // Inside the one being sent: nothing to add.
        add_span(&mut q, Span::new(90, 180, 10_000));
        assert_eq!(q.len(), 1);
        add_span(&mut q, Span::new(2000, 2090, 10_000));
        add_span(&mut q, Span::new(2090, 2180, 10_000));
        assert_eq!(q.len(), 2);
        assert_eq!((q[1].start, q[1].end), (2000, 2180));
        for i in 0..200 {
            add_span(
                &mut q,
                Span::new(3000 + i * 100, 3000 + i * 100 + 10, 100_000),
            );
        }
        assert_eq!(q.len(), MAX_SPANS);
    }

    #[test]
    fn a_span_past_the_end_is_cut_and_says_so() {
        let s = Span::new(900, 900 + 0xFFFF_FFFF, 1000);
        assert_eq!((s.start, s.end, s.past_eof), (900, 1000, true));
        let s = Span::new(2000, 2090, 1000);
        assert_eq!((s.start, s.end, s.past_eof), (2000, 2000, true));
    }
}
