//! Onboard log download and MAVLink FTP, on the core with synthetic time
//! and the disk worker's own code on a temporary data directory (each
//! request the core hands out is done at once, in order, and its answer
//! fed back): what a station asks, what it gets, how fast, and what it may
//! not do.
// COMPONENT_INFORMATION is deprecated, and QGroundControl still asks for it.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::time::Duration;

use common::core_rig::{CoreRig, msgs};
use neptunus::dialect::neptunus::*;
use neptunus::files::worker::{WorkerConfig, execute};
use neptunus::files::{FileReply, MemFile, component};
use neptunus::mavlink::ftp::{self, Header, op};
use neptunus::mavlink::tlog::TlogRun;
use neptunus::vehicle::machine::{Identity, Input, Output, START_RATE, Sender, To, Vehicle};
use neptunus::vehicle::params::ParamStore;

/// An allowed station (SYSID_MYGCS) on UDP endpoint 0.
const GCS: Sender = Sender::new(0, 1, 255, 190);
/// A station that may only watch.
const WATCHER: Sender = Sender::new(0, 2, 77, 190);
/// Endpoint 1 is in-process (no file data over it).
const LOCAL: Sender = Sender::new(1, 9, 255, 190);

struct Bench {
    r: CoreRig,
    disk: WorkerConfig,
    _dir: tempfile::TempDir,
}

impl Bench {
    /// A vehicle with the logs `(name, bytes)` in its data directory.
    fn new(logs: &[(&str, Vec<u8>)]) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let tlogs = dir.path().join("tlogs");
        std::fs::create_dir(&tlogs).unwrap();
        for (name, bytes) in logs {
            std::fs::write(tlogs.join(name), bytes).unwrap();
        }
        std::fs::write(dir.path().join("params.toml"), b"SYSID_THISMAV = 1\n").unwrap();
        let v = Vehicle::new(Identity::Ardupilot, ParamStore::defaults(), 2)
            .with_transfer_rates(vec![4_000_000, 0]);
        Self {
            r: CoreRig::new(v),
            disk: WorkerConfig {
                data_dir: dir.path().to_path_buf(),
                running: None,
            },
            _dir: dir,
        }
    }

    /// Does the file requests in `out` (and those their answers bring),
    /// in order; everything else the core emitted.
    fn serve(&mut self, out: Vec<Output>) -> Vec<Output> {
        let mut queue: std::collections::VecDeque<Output> = out.into();
        let mut rest = Vec::new();
        while let Some(o) = queue.pop_front() {
            match o {
                Output::Files(req) => {
                    let result = execute(&self.disk, &req.op);
                    let reply = FileReply {
                        token: req.token,
                        result,
                    };
                    queue.extend(self.r.input(Input::Files(reply)));
                }
                other => rest.push(other),
            }
        }
        rest
    }

    fn msg(&mut self, from: Sender, msg: MavMessage) -> Vec<Output> {
        let out = self.r.msg(from, msg);
        self.serve(out)
    }

    /// Runs the transfers' passes when they are due, until they want none
    /// or `d` has passed (the clock stays at the last pass); everything sent.
    fn run(&mut self, d: Duration) -> Vec<Output> {
        let end = self.r.t + d;
        let mut all = Vec::new();
        while let Some(due) = self.r.v.next_transfer() {
            let at = due.max(self.r.t);
            if at > end {
                break;
            }
            self.r.t = at;
            let out = self.r.input(Input::Transfer);
            all.extend(self.serve(out));
        }
        all
    }

    fn ftp(&mut self, from: Sender, payload: [u8; 251]) -> Vec<Output> {
        self.msg(
            from,
            MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
                target_network: 0,
                target_system: 1,
                target_component: 1,
                payload,
            }),
        )
    }
}

/// A tlog-looking file: `n` bytes, the first record stamped `unix_s`.
fn tlog_bytes(n: usize, unix_s: u64) -> Vec<u8> {
    let mut b = (unix_s * 1_000_000).to_be_bytes().to_vec();
    b.extend((0..n.saturating_sub(8)).map(|i| (i * 31 % 251) as u8));
    b
}

fn list_request(start: u16, end: u16) -> MavMessage {
    MavMessage::LOG_REQUEST_LIST(LOG_REQUEST_LIST_DATA {
        start,
        end,
        target_system: 1,
        target_component: 1,
    })
}

fn data_request(id: u16, ofs: u32, count: u32) -> MavMessage {
    MavMessage::LOG_REQUEST_DATA(LOG_REQUEST_DATA_DATA {
        ofs,
        count,
        id,
        target_system: 1,
        target_component: 1,
    })
}

/// The file data the core sent, as (to, message).
fn bulk(out: &[Output]) -> Vec<(To, MavMessage)> {
    out.iter()
        .filter_map(|o| match o {
            Output::Bulk { to, msg } => Some((*to, msg.clone())),
            _ => None,
        })
        .collect()
}

fn log_data(out: &[Output]) -> Vec<LOG_DATA_DATA> {
    bulk(out)
        .into_iter()
        .filter_map(|(_, m)| match m {
            MavMessage::LOG_DATA(d) => Some(d),
            _ => None,
        })
        .collect()
}

fn ftp_replies(out: &[Output]) -> Vec<(Header, Vec<u8>)> {
    bulk(out)
        .into_iter()
        .filter_map(|(_, m)| match m {
            MavMessage::FILE_TRANSFER_PROTOCOL(f) => {
                let h = Header::read(&f.payload);
                let data = f.payload[12..12 + usize::from(h.size).min(239)].to_vec();
                Some((h, data))
            }
            _ => None,
        })
        .collect()
}

fn texts(out: &[Output]) -> Vec<String> {
    msgs!(out, STATUSTEXT)
        .iter()
        .map(common::statustext)
        .collect()
}

/// An FTP request.
fn req(seq: u16, opcode: u8, session: u8, size: u8, offset: u32, data: &[u8]) -> [u8; 251] {
    let mut p = [0u8; 251];
    p[0..2].copy_from_slice(&seq.to_le_bytes());
    p[2] = session;
    p[3] = opcode;
    p[4] = size;
    p[8..12].copy_from_slice(&offset.to_le_bytes());
    p[12..12 + data.len()].copy_from_slice(data);
    p
}

fn path_req(seq: u16, opcode: u8, path: &str) -> [u8; 251] {
    req(seq, opcode, 0, path.len() as u8, 0, path.as_bytes())
}

/// The one FTP reply in `out`: (opcode, data) — the error code for a NAK.
fn one_reply(out: &[Output]) -> (Header, Vec<u8>) {
    let r = ftp_replies(out);
    assert_eq!(r.len(), 1, "one FTP reply expected: {r:?}");
    r.into_iter().next().unwrap()
}

fn nak_code(out: &[Output]) -> Vec<u8> {
    let (h, data) = one_reply(out);
    assert_eq!(h.opcode, op::NAK, "a NAK expected, got {h:?}");
    data
}

const LOG_A: &str = "neptunus-20260101-100000.tlog";
const LOG_B: &str = "neptunus-20260102-100000.tlog";

// ---------------------------------------------------------------------------
// Onboard logs
// ---------------------------------------------------------------------------

#[test]
fn the_log_list_names_every_log_with_its_size_and_time() {
    let mut b = Bench::new(&[
        (LOG_B, tlog_bytes(5000, 1_767_348_000)),
        (LOG_A, tlog_bytes(1234, 1_767_261_600)),
        ("neptunus-20260103-100000.tlog", Vec::new()),
        ("other.bin", vec![1, 2, 3]),
    ]);
    let out = b.msg(GCS, list_request(0, 0xffff));
    assert!(log_entries(&out).is_empty(), "sent on the transfers' pass");
    let out = b.run(Duration::from_millis(10));
    let entries = log_entries(&out);
    // Oldest first, ids from 1 (ArduPilot's), the empty file not listed.
    assert_eq!(
        entries
            .iter()
            .map(|e| (e.id, e.num_logs, e.last_log_num, e.size, e.time_utc))
            .collect::<Vec<_>>(),
        vec![
            (1, 2, 2, 1234, 1_767_261_600),
            (2, 2, 2, 5000, 1_767_348_000)
        ]
    );
    // QGroundControl asks again for the entries it missed, by id.
    b.msg(GCS, list_request(2, 2));
    let again = log_entries(&b.run(Duration::from_millis(10)));
    assert_eq!(again.iter().map(|e| e.id).collect::<Vec<_>>(), vec![2]);
}

fn log_entries(out: &[Output]) -> Vec<LOG_ENTRY_DATA> {
    msgs!(out, LOG_ENTRY)
}

#[test]
fn no_logs_is_one_empty_entry() {
    let mut b = Bench::new(&[]);
    b.msg(GCS, list_request(0, 0xffff));
    let entries = log_entries(&b.run(Duration::from_millis(10)));
    assert_eq!(entries.len(), 1);
    assert_eq!((entries[0].num_logs, entries[0].size), (0, 0));
}

/// Downloads log `id` as QGroundControl does: chunks of 512 × 90 bytes,
/// the next asked for when one is complete, a missing piece asked again
/// after 500 ms of silence.
fn download_as_qgc(b: &mut Bench, id: u16, size: usize) -> (Vec<u8>, Duration) {
    const CHUNK: usize = 512 * 90;
    let start = b.r.t;
    let mut file = vec![0u8; size];
    let mut have = vec![false; size.div_ceil(90)];
    let mut chunk = 0;
    while chunk * CHUNK < size {
        let bins = (size - chunk * CHUNK).div_ceil(90).min(512);
        let missing = |have: &[bool]| {
            (chunk * 512..chunk * 512 + bins)
                .find(|&i| !have[i])
                .map(|i| {
                    let end = (i..chunk * 512 + bins)
                        .find(|&j| have[j])
                        .unwrap_or(chunk * 512 + bins);
                    (i, end)
                })
        };
        let Some((first, end)) = missing(&have) else {
            chunk += 1;
            continue;
        };
        let out = b.msg(
            GCS,
            data_request(id, (first * 90) as u32, ((end - first) * 90) as u32),
        );
        let mut got = log_data(&out);
        got.extend(log_data(&b.run(Duration::from_millis(500))));
        for d in got {
            assert_eq!(d.id, id);
            assert_eq!(d.ofs % 90, 0, "QGroundControl drops misaligned data");
            let at = d.ofs as usize;
            let n = usize::from(d.count);
            if n > 0 {
                file[at..at + n].copy_from_slice(&d.data[..n]);
                have[at / 90] = true;
            }
        }
    }
    (file, b.r.t - start)
}

#[test]
fn a_log_downloads_whole_as_qgroundcontrol_asks_at_the_paced_rate() {
    let bytes = tlog_bytes(300_000, 1_767_261_600);
    let mut b = Bench::new(&[(LOG_A, bytes.clone())]);
    b.msg(GCS, list_request(0, 0xffff));
    b.run(Duration::from_millis(10));
    let (got, took) = download_as_qgc(&mut b, 1, bytes.len());
    assert!(got == bytes, "the download differs from the file");
    // Faster than the starting rate (it climbs chunk by chunk), no faster
    // than the endpoint allows.
    let rate = bytes.len() as f64 / took.as_secs_f64();
    assert!(rate > START_RATE && rate <= 4.1e6, "{rate:.0} B/s");
}

#[test]
fn no_pass_sends_more_than_a_few_kilobytes() {
    let bytes = tlog_bytes(200_000, 1_767_261_600);
    let mut b = Bench::new(&[(LOG_A, bytes)]);
    b.msg(GCS, list_request(0, 0xffff));
    b.run(Duration::from_millis(10));
    b.msg(GCS, data_request(1, 0, 0xFFFF_FFFF));
    let mut passes = 0;
    while let Some(due) = b.r.v.next_transfer() {
        b.r.t = due.max(b.r.t);
        let out = b.r.input(Input::Transfer);
        let out = b.serve(out);
        let sent: usize = log_data(&out).iter().map(|d| usize::from(d.count)).sum();
        // 4 ms at the endpoint's 4 MB/s at most.
        assert!(sent <= 16_000, "{sent} bytes in one pass");
        passes += 1;
        assert!(passes < 100_000);
    }
    assert!(passes > 10);
}

#[test]
fn gaps_asked_again_are_served_and_a_request_past_the_end_gets_an_empty_log_data() {
    // 9000 bytes: a multiple of 90, so MAVProxy's whole-file request ends
    // with an empty LOG_DATA after the last full one.
    let bytes = tlog_bytes(9000, 1_767_261_600);
    let mut b = Bench::new(&[(LOG_A, bytes.clone())]);
    b.msg(GCS, list_request(0, 0xffff));
    b.run(Duration::from_millis(10));
    b.msg(GCS, data_request(1, 0, 0xFFFF_FFFF));
    let first = log_data(&b.run(Duration::from_secs(1)));
    assert_eq!(first.len(), 101);
    let last = first.last().unwrap();
    assert_eq!((last.ofs, last.count), (9000, 0));
    // MAVProxy's gap requests, many at once: every one served.
    for k in [3u32, 17, 50, 99] {
        b.msg(GCS, data_request(1, k * 90, 90));
    }
    let gaps = log_data(&b.run(Duration::from_secs(1)));
    assert_eq!(
        gaps.iter().map(|d| d.ofs / 90).collect::<Vec<_>>(),
        vec![3, 17, 50, 99]
    );
    for d in &gaps {
        let at = d.ofs as usize;
        assert_eq!(&d.data[..90], &bytes[at..at + 90]);
    }
    // Past the end: one empty LOG_DATA where it was asked.
    b.msg(GCS, data_request(1, 9090, 90));
    let end = log_data(&b.run(Duration::from_secs(1)));
    assert_eq!(
        end.iter().map(|d| (d.ofs, d.count)).collect::<Vec<_>>(),
        vec![(9090, 0)]
    );
}

#[test]
fn log_request_end_stops_the_download() {
    let mut b = Bench::new(&[(LOG_A, tlog_bytes(400_000, 1_767_261_600))]);
    b.msg(GCS, list_request(0, 0xffff));
    b.run(Duration::from_millis(10));
    b.msg(GCS, data_request(1, 0, 0xFFFF_FFFF));
    assert!(!log_data(&b.run(Duration::from_millis(20))).is_empty());
    b.msg(
        GCS,
        MavMessage::LOG_REQUEST_END(LOG_REQUEST_END_DATA {
            target_system: 1,
            target_component: 1,
        }),
    );
    assert!(log_data(&b.run(Duration::from_secs(1))).is_empty());
    assert_eq!(b.r.v.next_transfer(), None);
}

#[test]
fn a_watcher_gets_no_logs_and_cannot_erase_them() {
    let mut b = Bench::new(&[(LOG_A, tlog_bytes(1000, 1_767_261_600))]);
    let out = b.msg(WATCHER, list_request(0, 0xffff));
    let entries = log_entries(&out);
    assert_eq!(entries.len(), 1);
    assert_eq!(entries[0].num_logs, 0);
    assert!(
        texts(&out)
            .iter()
            .any(|t| t.contains("Refused the log list"))
    );
    let out = b.msg(WATCHER, data_request(1, 0, 90));
    assert!(log_data(&out).is_empty());
    assert!(log_data(&b.run(Duration::from_secs(1))).is_empty());
    let out = b.msg(
        WATCHER,
        MavMessage::LOG_ERASE(LOG_ERASE_DATA {
            target_system: 1,
            target_component: 1,
        }),
    );
    assert!(texts(&out).iter().any(|t| t.contains("Refused log erase")));
    assert!(b.disk.data_dir.join("tlogs").join(LOG_A).exists());
}

#[test]
fn erase_keeps_the_running_log() {
    let mut b = Bench::new(&[
        (LOG_A, tlog_bytes(1000, 1_767_261_600)),
        (LOG_B, tlog_bytes(1000, 1_767_348_000)),
    ]);
    let running = TlogRun::default();
    let live = b.disk.data_dir.join("tlogs").join(LOG_B);
    running.add(live.clone());
    b.disk.running = Some(running);
    let out = b.msg(
        GCS,
        MavMessage::LOG_ERASE(LOG_ERASE_DATA {
            target_system: 1,
            target_component: 1,
        }),
    );
    assert!(
        texts(&out)
            .iter()
            .any(|t| t.contains("Erased 1 telemetry logs; kept 1")),
        "{:?}",
        texts(&out)
    );
    assert!(!b.disk.data_dir.join("tlogs").join(LOG_A).exists());
    assert!(live.exists());
    // The list now holds the running log alone, as id 1.
    b.msg(GCS, list_request(0, 0xffff));
    let entries = log_entries(&b.run(Duration::from_millis(10)));
    assert_eq!(entries.len(), 1);
    assert_eq!((entries[0].id, entries[0].num_logs), (1, 1));
}

#[test]
fn no_log_data_over_an_in_process_endpoint() {
    let mut b = Bench::new(&[(LOG_A, tlog_bytes(1000, 1_767_261_600))]);
    b.msg(LOCAL, list_request(0, 0xffff));
    b.run(Duration::from_millis(10));
    let out = b.msg(LOCAL, data_request(1, 0, 90));
    assert!(
        texts(&out)
            .iter()
            .any(|t| t.contains("not offered over this link"))
    );
    assert!(log_data(&b.run(Duration::from_secs(1))).is_empty());
}

// ---------------------------------------------------------------------------
// MAVLink FTP
// ---------------------------------------------------------------------------

/// Opens `path`: the session and the size.
fn open(b: &mut Bench, from: Sender, path: &str) -> (u8, u32) {
    let (h, data) = one_reply(&b.ftp(from, path_req(1, op::OPEN_FILE_RO, path)));
    assert_eq!(
        (h.opcode, h.req_opcode, h.seq),
        (op::ACK, op::OPEN_FILE_RO, 2),
        "{path}"
    );
    (h.session, u32::from_le_bytes(data[..4].try_into().unwrap()))
}

/// Reads a whole file with bursts, as pymavlink's client does (the next
/// burst from where the last ended).
fn burst_read(b: &mut Bench, from: Sender, session: u8, packet: u8) -> Vec<u8> {
    let mut file = Vec::new();
    let mut seq = 10u16;
    loop {
        let out = b.ftp(
            from,
            req(
                seq,
                op::BURST_READ_FILE,
                session,
                packet,
                file.len() as u32,
                &[],
            ),
        );
        let mut replies = ftp_replies(&out);
        replies.extend(ftp_replies(&b.run(Duration::from_secs(5))));
        let mut complete = false;
        for (i, (h, data)) in replies.iter().enumerate() {
            if h.opcode == op::NAK {
                assert_eq!(data[0], 6, "only EOF ends a burst read");
                return file;
            }
            assert_eq!(h.seq, seq.wrapping_add(1 + i as u16), "burst sequence");
            assert_eq!(h.offset as usize, file.len());
            file.extend_from_slice(data);
            complete = h.burst_complete == 1;
            if complete && data.len() < usize::from(packet) {
                return file;
            }
        }
        assert!(complete, "a burst ends with burst_complete");
        seq = seq.wrapping_add(replies.len() as u16 + 1);
    }
}

#[test]
fn the_component_metadata_reads_by_burst_read_and_crc() {
    let mut b = Bench::new(&[]);
    let general = component::file(MemFile::General);
    let (session, size) = open(&mut b, GCS, "/component/general.json");
    assert_eq!(size as usize, general.bytes.len());
    assert!(burst_read(&mut b, GCS, session, 80) == general.bytes.to_vec());
    let params = component::file(MemFile::Parameters);
    let (session, _) = open(&mut b, WATCHER, "//component/parameters.json");
    assert!(burst_read(&mut b, WATCHER, session, 239) == params.bytes.to_vec());
    let (h, data) = one_reply(&b.ftp(
        GCS,
        path_req(3, op::CALC_FILE_CRC32, "/component/parameters.json"),
    ));
    assert_eq!(h.opcode, op::ACK);
    assert_eq!(
        u32::from_le_bytes(data[..4].try_into().unwrap()),
        params.crc
    );
    // ReadFile: the bytes at an offset; past the end, EOF.
    let (h, data) = one_reply(&b.ftp(WATCHER, req(5, op::READ_FILE, session, 100, 50, &[])));
    assert_eq!((h.opcode, h.offset), (op::ACK, 50));
    assert!(data == params.bytes[50..150].to_vec());
    let past = params.bytes.len() as u32;
    assert_eq!(
        nak_code(&b.ftp(WATCHER, req(6, op::READ_FILE, session, 100, past, &[]))),
        vec![6]
    );
}

#[test]
fn a_log_reads_over_ftp_for_a_station_that_may_control() {
    let bytes = tlog_bytes(100_000, 1_767_261_600);
    let mut b = Bench::new(&[(LOG_A, bytes.clone())]);
    let path = format!("/logs/tlogs/{LOG_A}");
    let (session, size) = open(&mut b, GCS, &path);
    assert_eq!(size as usize, bytes.len());
    assert!(
        burst_read(&mut b, GCS, session, 239) == bytes,
        "the file read differs"
    );
    let (h, data) = one_reply(&b.ftp(GCS, path_req(3, op::CALC_FILE_CRC32, &path)));
    assert_eq!(h.opcode, op::ACK);
    assert_eq!(
        u32::from_le_bytes(data[..4].try_into().unwrap()),
        ftp::crc32(0, &bytes)
    );
    // The listing, as pymavlink pages it.
    let (h, data) = one_reply(&b.ftp(GCS, path_req(4, op::LIST_DIRECTORY, "/logs/tlogs")));
    assert_eq!(h.opcode, op::ACK);
    assert_eq!(data, format!("F{LOG_A}\t{}\0", bytes.len()).into_bytes());
    let mut next = req(5, op::LIST_DIRECTORY, 0, 11, 1, b"/logs/tlogs");
    next[4] = 11;
    assert_eq!(nak_code(&b.ftp(GCS, next)), vec![6]);
    // The root shows the tree's folders only.
    let (_, data) = one_reply(&b.ftp(WATCHER, path_req(6, op::LIST_DIRECTORY, "/")));
    assert_eq!(data, b"Dcomponent\0Dlogs\0Drecordings\0".to_vec());
}

#[test]
fn a_watcher_may_not_read_the_records() {
    let mut b = Bench::new(&[(LOG_A, tlog_bytes(1000, 1_767_261_600))]);
    let mut said = Vec::new();
    for (opcode, path) in [
        (op::LIST_DIRECTORY, "/logs/tlogs".to_owned()),
        (op::OPEN_FILE_RO, format!("/logs/tlogs/{LOG_A}")),
        (op::CALC_FILE_CRC32, format!("/logs/tlogs/{LOG_A}")),
        (op::LIST_DIRECTORY, "/recordings".to_owned()),
    ] {
        let out = b.ftp(WATCHER, path_req(1, opcode, &path));
        // FailErrno, EACCES.
        assert_eq!(nak_code(&out), vec![2, 13], "{path}");
        said.extend(texts(&out));
    }
    // Told why (once: the replies are rate-limited per station), in as
    // many STATUSTEXT chunks as the text takes.
    let told = said.concat();
    assert_eq!(told.matches("Refused").count(), 1, "{said:?}");
    assert!(
        told.starts_with("Refused file access from sysid 77"),
        "{said:?}"
    );
    // Reading the tree's folders and the metadata stays open to it.
    let (h, _) = one_reply(&b.ftp(WATCHER, path_req(2, op::LIST_DIRECTORY, "/logs")));
    assert_eq!(h.opcode, op::ACK);
}

#[test]
fn bad_requests_get_the_protocols_naks_and_change_nothing() {
    let mut b = Bench::new(&[(LOG_A, tlog_bytes(1000, 1_767_261_600))]);
    // Paths that name nothing: FileNotFound.
    for path in [
        "/params.toml",
        "/../params.toml",
        "/logs/tlogs/../../params.toml",
        "/logs/tlogs/neptunus-20260101-100000.tlog\0/x",
        "@PARAM/param.pck",
        "/etc/passwd",
        "/component",
    ] {
        let out = b.ftp(GCS, path_req(1, op::OPEN_FILE_RO, path));
        assert_eq!(nak_code(&out), vec![10], "{path:?}");
    }
    // Writes: FileProtected; an unknown opcode: UnknownCommand; a size past
    // the payload: InvalidDataSize.
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
            nak_code(&b.ftp(GCS, path_req(1, opcode, "/logs/tlogs/x"))),
            vec![9]
        );
    }
    assert_eq!(nak_code(&b.ftp(GCS, req(1, 99, 0, 0, 0, &[]))), vec![7]);
    assert_eq!(
        nak_code(&b.ftp(GCS, req(1, op::READ_FILE, 0, 250, 0, &[]))),
        vec![3]
    );
    // Sessions nobody opened, or another station's: InvalidSession.
    assert_eq!(
        nak_code(&b.ftp(GCS, req(1, op::READ_FILE, 42, 10, 0, &[]))),
        vec![4]
    );
    let (session, _) = open(&mut b, GCS, "/component/general.json");
    for opcode in [op::READ_FILE, op::BURST_READ_FILE, op::TERMINATE_SESSION] {
        assert_eq!(
            nak_code(&b.ftp(WATCHER, req(1, opcode, session, 10, 0, &[]))),
            vec![4]
        );
    }
    // A watcher's ResetSessions closes its own sessions only.
    let (h, _) = one_reply(&b.ftp(WATCHER, req(1, op::RESET_SESSIONS, 0, 0, 0, &[])));
    assert_eq!(h.opcode, op::ACK);
    let (h, _) = one_reply(&b.ftp(GCS, req(2, op::READ_FILE, session, 10, 0, &[])));
    assert_eq!(h.opcode, op::ACK, "the pilot's session is still open");
    // Terminated, the session is gone.
    let (h, _) = one_reply(&b.ftp(GCS, req(3, op::TERMINATE_SESSION, session, 0, 0, &[])));
    assert_eq!(h.opcode, op::ACK);
    assert_eq!(
        nak_code(&b.ftp(GCS, req(4, op::READ_FILE, session, 10, 0, &[]))),
        vec![4]
    );
    // Nothing was written.
    assert_eq!(
        std::fs::read(b.disk.data_dir.join("params.toml")).unwrap(),
        b"SYSID_THISMAV = 1\n"
    );
}

#[test]
fn sessions_and_waiting_requests_are_bounded_per_station() {
    let mut b = Bench::new(&[(LOG_A, tlog_bytes(1000, 1_767_261_600))]);
    for _ in 0..4 {
        open(&mut b, GCS, "/component/general.json");
    }
    assert_eq!(
        nak_code(&b.ftp(
            GCS,
            path_req(1, op::OPEN_FILE_RO, "/component/general.json")
        )),
        vec![5]
    );
    // Another station still has its own room.
    open(&mut b, WATCHER, "/component/general.json");
    // A flood of disk requests: beyond eight waiting, EBUSY at once.
    let mut busy = 0;
    let mut pending = Vec::new();
    for i in 0..20u16 {
        let out = b.r.msg(
            GCS,
            MavMessage::FILE_TRANSFER_PROTOCOL(FILE_TRANSFER_PROTOCOL_DATA {
                target_network: 0,
                target_system: 1,
                target_component: 1,
                payload: path_req(i, op::LIST_DIRECTORY, "/logs/tlogs"),
            }),
        );
        for o in out {
            match o {
                Output::Files(r) => pending.push(r),
                Output::Bulk { .. } => {
                    busy += 1;
                }
                _ => {}
            }
        }
    }
    assert_eq!((pending.len(), busy), (8, 12));
    // Answered, the room is back.
    let out: Vec<Output> = pending.into_iter().map(Output::Files).collect();
    let replies = ftp_replies(&b.serve(out));
    assert_eq!(replies.len(), 8);
    assert!(replies.iter().all(|(h, _)| h.opcode == op::ACK));
}

#[test]
fn component_metadata_names_the_general_file_with_its_crc() {
    let mut b = Bench::new(&[]);
    for id in [397.0, 395.0] {
        let out = b.r.cmd(GCS, MavCmd::MAV_CMD_REQUEST_MESSAGE, &[id]);
        assert_eq!(
            common::core_rig::acks(&out)[0].result,
            MavResult::MAV_RESULT_ACCEPTED
        );
        let general = component::file(MemFile::General);
        if id == 397.0 {
            let m = &msgs!(&out, COMPONENT_METADATA)[0];
            assert_eq!(m.file_crc, general.crc);
            assert_eq!(m.uri.to_str().unwrap(), "mftp://component/general.json");
        } else {
            let m = &msgs!(&out, COMPONENT_INFORMATION)[0];
            assert_eq!(m.general_metadata_file_crc, general.crc);
            assert_eq!(
                m.general_metadata_uri.to_str().unwrap(),
                "mftp://component/general.json"
            );
        }
    }
}

#[test]
fn with_signing_on_an_unsigned_frame_with_the_pilots_ids_reads_nothing() {
    let bytes = tlog_bytes(5000, 1_767_261_600);
    let mut b = Bench::new(&[(LOG_A, bytes)]);
    b.r.v.set_signing_active(true);
    let pilot = Sender {
        signed: true,
        ..GCS
    };
    // The same ids, unsigned, from another port.
    let spoofer = Sender::new(0, 7, 255, 190);
    let (session, _) = open(&mut b, pilot, &format!("/logs/tlogs/{LOG_A}"));
    for opcode in [op::READ_FILE, op::BURST_READ_FILE] {
        let out = b.ftp(spoofer, req(1, opcode, session, 100, 0, &[]));
        assert_eq!(nak_code(&out), vec![2, 13]);
    }
    assert_eq!(
        nak_code(&b.ftp(
            spoofer,
            path_req(2, op::OPEN_FILE_RO, &format!("/logs/tlogs/{LOG_A}"))
        )),
        vec![2, 13]
    );
    let mut out = b.msg(spoofer, list_request(0, 0xffff));
    out.extend(b.run(Duration::from_millis(10)));
    let entries = log_entries(&out);
    assert_eq!(entries.len(), 1);
    assert_eq!(entries[0].num_logs, 0);
    // The pilot's own reads go on.
    let (h, _) = one_reply(&b.ftp(pilot, req(3, op::READ_FILE, session, 100, 0, &[])));
    assert_eq!(h.opcode, op::ACK);
}
