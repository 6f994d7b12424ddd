//! The board emulator is the genuine firmware's twin: one scripted session
//! — boot, pings, `go()` forward, reverse and out of range, the board's own
//! `thro`/`yaw`/`lift` mixing, lights, laser, tilt, `dms` by argument
//! count, an unknown command, a bad-CRC frame, a frame longer than the
//! 80-byte buffer, a dead-man trip and its recovery, `escp`, and `rcap()`
//! with a burst sent into its 5-second blindness that overruns the internal
//! command queue — goes to the genuine firmware in simavr (feature `hil`)
//! and to the emulator ([`Board`] driven with the same times from boot),
//! for 30.0.2 and 2014-12. Both boards have no I2C sensors wired, so their
//! set-up chatter is the same.
//!
//! # How the two outputs are compared
//! Each byte stream is cut into items: the text up to a `;` (terminated)
//! or up to a line end (unterminated, as `log:Failed to read Depth from
//! I2C`), each marked with whether `\r\n` follows it at once. Then:
//! - set-up chatter (up to `boot:1;`): the same items, exactly;
//! - replies (command echoes, `crc:`, `pong:`, `LIGT`, `claser`, `CAPA`
//!   and the scan, `icmd:`, overruns, the pilot's and the dead-man's
//!   lines …): the same sequence, exactly — text, `;` and line break —
//!   except `pong:`'s milliseconds;
//! - `motors:` (written when the targets change, on a 50 ms timer that
//!   interleaves with the replies by timing): the same sequence of values;
//! - the dead-man's blinking (`icmd:ligt(50|0)` and its `LIGT`/`LIGP`,
//!   every 500 ms while tripped): per trip, the same first level, strictly
//!   alternating, and as many blinks as the trip's length in navigation
//!   lines (≈ 100 ms each, on the board's own clock) allows, ±1;
//! - periodic lines (navigation, the status cycle, `BRDT…AVCC`, `mtarg`,
//!   `mtrmod`, the depth sensor's failure): numbers become `9` and signs
//!   go, so a line's shape is its keys, separators, number formats and
//!   line break. Both streams must show the same set of shapes, every
//!   status cycle (`motorAttached` … `alps`) the same lines in the same
//!   order, and each shape at the same rate per second of the board's own
//!   clock (±15 %, ±0.15/s).
//!
//! Timing, where periodic lines fall between replies, and sensor values
//! may differ; a different echo, a missing, extra or reordered reply, a
//! line break added or lost, a renamed key or a status cycle cut into
//! other lines fails. The comparator's own tests (at the end) check that
//! it catches each of those on doctored streams.
#![cfg(feature = "hil")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::{Read as _, Write as _};
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use neptunus::firmware::codec::crc8;
use neptunus::firmware::emulator::{Board, EmulatorOptions, FirmwareVersion, FittedSensors};
use neptunus::hil::{Analog, GenuineBoard, Wiring, prepare};

/// One thing the host sends, `at` after `boot:1;`.
struct Step {
    at_ms: u64,
    send: Send,
}

enum Send {
    /// A command, framed as the firmware expects (CRC byte or plain).
    Text(&'static str),
    /// These bytes exactly.
    Raw(&'static [u8]),
    /// Several framed commands in one write.
    Burst(&'static [&'static str]),
}

const fn text(at_ms: u64, t: &'static str) -> Step {
    Step {
        at_ms,
        send: Send::Text(t),
    }
}

/// The session. Commands are 300 ms apart (the board's 50 ms motor timer
/// and its loop settle in between); while the dead-man is armed a ping
/// comes at least every 1.5 s except where the trip is wanted; waits that
/// must outlast the board's timers have margin for a genuine board that
/// runs at 60 % of real time on a loaded machine.
const SESSION: &[Step] = &[
    text(500, "ping(0);"),
    text(800, "go(1600,1500,1400);"),
    text(1100, "go(1400,1500,1600);"),
    text(1400, "go(999,1500,1500);"),
    text(1700, "go(2000,1000,1500);"),
    text(2000, "go(1500,1500,2001);"),
    text(2300, "go(1500,1500,1500);"),
    text(2600, "ligt(51);"),
    text(2900, "claser(255);"),
    text(3200, "tilt(1600);"),
    // The board's own mixing, back to neutral at the end (its throttle
    // and yaw persist, and the dead-man's yaw(0) would use them).
    text(3500, "thro(33);"),
    text(3800, "yaw(-20);"),
    text(4100, "lift(50);"),
    text(4400, "thro(-60);"),
    text(4700, "yaw(90);"),
    text(5000, "thro(0);"),
    text(5300, "yaw(0);"),
    text(5600, "lift(0);"),
    // dms by argument count: none disarms, any (even 0) arms.
    text(5900, "dms();"),
    text(6200, "ping(1);"),
    text(6500, "dms(0);"),
    text(6800, "ping( 7 , 8x);"),
    text(7100, "frob(1,2);"),
    Step {
        at_ms: 7400,
        send: Send::Raw(b"\x00ligt(9);"),
    },
    Step {
        at_ms: 7700,
        send: Send::Raw(
            b"\xe7go(1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500,1500);",
        ),
    },
    text(8000, "ping(2);"),
    text(8300, "go(1700,1500,1700);"),
    // No ping for 4 s: the dead-man trips 2 s after ping(2), blinks, and
    // still obeys go().
    text(12_300, "go(1600,1500,1600);"),
    text(13_000, "ping(3);"),
    text(13_300, "escp(0);"),
    text(13_600, "escp(1);"),
    text(13_900, "ping(4);"),
    text(14_200, "rcap();"),
    // Into the scan's 5 s delay: five frames wait in the receive ring,
    // then run one a pass, each pushing yaw(0) onto the internal queue the
    // dead-man (tripped by the delay) has just filled.
    Step {
        at_ms: 14_300,
        send: Send::Burst(&[
            "headloff();",
            "headloff();",
            "headloff();",
            "headloff();",
            "headloff();",
        ]),
    },
    text(23_500, "ping(5);"),
    text(23_800, "dms();"),
    text(24_100, "ping(6);"),
];

/// The session ends here (before the absent IMU's 30 s re-probe).
const END_MS: u64 = 25_500;

/// Only one genuine board at a time: simavr takes a core.
static GENUINE: Mutex<()> = Mutex::new(());

fn framed(version: FirmwareVersion, t: &str) -> Vec<u8> {
    match version {
        FirmwareVersion::V30_0_2 => {
            let mut v = vec![crc8(t.as_bytes())];
            v.extend_from_slice(t.as_bytes());
            v
        }
        FirmwareVersion::V2014_12 => t.as_bytes().to_vec(),
    }
}

fn bytes_of(version: FirmwareVersion, send: &Send) -> Vec<u8> {
    match send {
        Send::Text(t) => framed(version, t),
        Send::Raw(b) => b.to_vec(),
        Send::Burst(ts) => ts.iter().flat_map(|t| framed(version, t)).collect(),
    }
}

fn contains(hay: &[u8], needle: &[u8]) -> bool {
    hay.windows(needle.len()).any(|w| w == needle)
}

/// What a board printed in the session, and how long its own clock ran
/// from `boot:1;` to the end.
struct Capture {
    bytes: Vec<u8>,
    board_s: f64,
}

/// The session's times as written.
fn nominal() -> Vec<Duration> {
    SESSION
        .iter()
        .map(|s| Duration::from_millis(s.at_ms))
        .collect()
}

/// The emulator, driven as the pty wrapper drives it (woken at its
/// deadlines), each step `sent[i]` after its own boot.
fn run_emulator(version: FirmwareVersion, sent: &[Duration]) -> Capture {
    let mut board = Board::new(EmulatorOptions {
        firmware: version,
        sensors: FittedSensors::none(),
        ..EmulatorOptions::default()
    });
    let mut out = Vec::new();
    let mut t = Duration::ZERO;
    board.start(t, &mut out);
    let advance = |board: &mut Board, t: &mut Duration, until: Duration, out: &mut Vec<u8>| {
        while *t < until {
            *t = board
                .next_deadline()
                .max(*t + Duration::from_micros(1))
                .min(until);
            board.tick(*t, out);
        }
    };
    while !contains(&out, b"boot:1;") {
        assert!(t < Duration::from_secs(5), "the emulator never booted");
        let next = t + Duration::from_millis(1);
        advance(&mut board, &mut t, next, &mut out);
    }
    let boot = t;
    for (step, at) in SESSION.iter().zip(sent) {
        advance(&mut board, &mut t, boot + *at, &mut out);
        board.receive(&bytes_of(version, &step.send), t, &mut out);
    }
    advance(
        &mut board,
        &mut t,
        boot + Duration::from_millis(END_MS),
        &mut out,
    );
    Capture {
        bytes: out,
        board_s: END_MS as f64 / 1000.0,
    }
}

/// The genuine firmware in simavr, fed the session on the wall clock;
/// with when each step was written (after `boot:1;` was read), which a
/// loaded machine may make later than asked.
fn run_genuine(version: FirmwareVersion) -> (Capture, Vec<Duration>) {
    let _one = GENUINE.lock().unwrap_or_else(|p| p.into_inner());
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("openrov-firmware");
    let firmware = prepare(&common::firmware_dir(&version.to_string()), &cache)
        .unwrap_or_else(|e| panic!("building the genuine firmware {version}: {e}"));
    // No I2C sensor wired, as on the emulator's side.
    let wiring = Wiring {
        analog: Analog::default(),
        depth_sensor: false,
        imu: false,
    };
    let board = GenuineBoard::spawn(firmware, wiring, None)
        .unwrap_or_else(|e| panic!("starting the genuine firmware {version}: {e}"));
    let mut port = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(nix::fcntl::OFlag::O_NOCTTY.bits())
        .open(board.path())
        .expect("the genuine board's pty");
    let mut reader = port.try_clone().expect("a second handle on the pty");
    let (tx, rx) = std::sync::mpsc::channel::<Vec<u8>>();
    let thread = std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        while let Ok(n) = reader.read(&mut buf) {
            if n == 0 || tx.send(buf[..n].to_vec()).is_err() {
                break;
            }
        }
    });
    let mut bytes = Vec::new();
    let started = Instant::now();
    while !contains(&bytes, b"boot:1;") {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the genuine firmware {version} never printed boot:1; — it printed {:?}",
            String::from_utf8_lossy(&bytes)
        );
        if let Ok(chunk) = rx.recv_timeout(Duration::from_millis(1)) {
            bytes.extend(chunk);
        }
    }
    let boot = Instant::now();
    let control = board.control();
    let boot_sim_s = control.snapshot().sim_time_s;
    let sleep_until = |t: Instant| {
        let now = Instant::now();
        if t > now {
            std::thread::sleep(t - now);
        }
    };
    let mut sent = Vec::with_capacity(SESSION.len());
    for step in SESSION {
        sleep_until(boot + Duration::from_millis(step.at_ms));
        sent.push(boot.elapsed());
        port.write_all(&bytes_of(version, &step.send))
            .expect("writing to the genuine board");
    }
    sleep_until(boot + Duration::from_millis(END_MS));
    let snap = control.snapshot();
    drop(board);
    drop(port);
    let _ = thread.join();
    bytes.extend(rx.try_iter().flatten());
    eprintln!(
        "genuine {version}: {:.2} s of board time in {:.2} s, last realtime ratio {:.2}, {} slips",
        snap.sim_time_s - boot_sim_s,
        END_MS as f64 / 1000.0,
        snap.realtime_ratio,
        snap.slips
    );
    assert!(
        snap.error.is_none(),
        "the simulator stopped: {:?}",
        snap.error
    );
    let capture = Capture {
        bytes,
        board_s: snap.sim_time_s - boot_sim_s,
    };
    (capture, sent)
}

// ---------------------------------------------------------------------------
// The comparison
// ---------------------------------------------------------------------------

/// A piece of output: text up to a `;` (terminated) or up to a line end.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Item {
    text: String,
    terminated: bool,
    /// `\r\n` right after it.
    line_end: bool,
}

impl std::fmt::Display for Item {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}{}{}",
            self.text,
            if self.terminated { ";" } else { "" },
            if self.line_end { "⏎" } else { "" }
        )
    }
}

fn items(bytes: &[u8]) -> Vec<Item> {
    let mut out: Vec<Item> = Vec::new();
    let mut cur: Vec<u8> = Vec::new();
    let text = |b: &[u8]| b.escape_ascii().to_string();
    for &b in bytes {
        match b {
            b';' => {
                out.push(Item {
                    text: text(&cur),
                    terminated: true,
                    line_end: false,
                });
                cur.clear();
            }
            b'\n' => {
                if cur.last() == Some(&b'\r') {
                    cur.pop();
                }
                if cur.is_empty() {
                    if let Some(last) = out.last_mut() {
                        last.line_end = true;
                    }
                } else {
                    out.push(Item {
                        text: text(&cur),
                        terminated: false,
                        line_end: true,
                    });
                    cur.clear();
                }
            }
            _ => cur.push(b),
        }
    }
    // Bytes after the last `;` or line end are an item the end of the
    // capture cut (`rol` of a `roll:` line): not an item of either board.
    out
}

fn key(text: &str) -> &str {
    text.split(':').next().unwrap_or("")
}

const PERIODIC_KEYS: &[&str] = &[
    "hdgd",
    "deap",
    "pitc",
    "roll",
    "yaw",
    "fthr",
    "motorAttached",
    "servo",
    "starg",
    "fmem",
    "vout",
    "iout",
    "atmp",
    "ver",
    "cmpd",
    "time",
    "pres",
    "temp",
    "dlms",
    "alps",
    "BRDT",
    "SC1I",
    "SC2I",
    "SC3I",
    "BRDI",
    "BT1I",
    "BT2I",
    "BRDV",
    "AVCC",
    "mtarg",
    "mtrmod",
];

/// A sensor that is not there, probed again every 30 s: periodic, if the
/// session ran that long.
fn is_reprobe(text: &str) -> bool {
    text.starts_with("BNO055.")
        || text.starts_with("MPU9150.")
        || text.starts_with("mpu_init failed")
        || text.starts_with("log:Trying other MPU9150")
        || text.starts_with("log:IMU Address was")
        || text.starts_with("log:Failed to init on both")
}

/// A stream sorted into what the comparison looks at.
#[derive(Debug, Default)]
struct Sorted {
    chatter: Vec<Item>,
    replies: Vec<Item>,
    motors: Vec<String>,
    /// Per trip (ended by `icmd:start()`): the blink levels, and the
    /// navigation lines printed from its first blink to its end.
    blinks: Vec<(Vec<String>, usize)>,
    /// Periodic lines, in order, as shapes.
    periodic: Vec<String>,
    /// The raw `pong:` values, in order.
    pongs: Vec<String>,
}

fn digits_to_nines(v: &str) -> String {
    let mut out = String::with_capacity(v.len());
    let mut in_number = false;
    for c in v.chars() {
        if c.is_ascii_digit() {
            if !in_number {
                out.push('9');
            }
            in_number = true;
        } else {
            in_number = false;
            if c != '-' {
                out.push(c);
            }
        }
    }
    out
}

/// A periodic item's shape: its key, and its value with numbers as `9`;
/// the build stamp `cmpd` as its form alone.
fn shape(item: &Item) -> String {
    let k = key(&item.text);
    let v = item.text.get(k.len() + 1..).unwrap_or("");
    let v = if k == "cmpd" {
        let re = regex::Regex::new(
            r"^[A-Z][a-z]{2} [ 0-9][0-9] [0-9]{4}, [0-9]{2}:[0-9]{2}:[0-9]{2}, [0-9.]+$",
        )
        .unwrap();
        if re.is_match(v) {
            "<date>, <time>, <compiler>".to_owned()
        } else {
            format!("<unlike __DATE__, __TIME__, __VERSION__: {v}>")
        }
    } else {
        digits_to_nines(v)
    };
    let sep = if item.text.contains(':') { ":" } else { "" };
    format!(
        "{k}{sep}{v}{}{}",
        if item.terminated { ";" } else { "" },
        if item.line_end { "⏎" } else { "" }
    )
}

fn sort(all: &[Item]) -> Sorted {
    let mut s = Sorted::default();
    let mut booted = false;
    let mut line: Vec<String> = Vec::new();
    let mut blink_follow = 0;
    let mut trip: Option<(Vec<String>, usize)> = None;
    let mut prev_key = String::new();
    for item in all {
        let k = key(&item.text).to_owned();
        if !booted {
            booted = item.text == "boot:1" && item.terminated;
            s.chatter.push(item.clone());
            prev_key = k;
            continue;
        }
        let periodic = PERIODIC_KEYS.contains(&k.as_str())
            || (item.text.is_empty() && prev_key == "cmpd")
            || (item.text == "log:Failed to read Depth from I2C" && !item.terminated)
            || is_reprobe(&item.text);
        if periodic {
            line.push(shape(item));
            if item.line_end {
                let l = line.join("");
                if l.starts_with("hdgd:")
                    && let Some((_, navs)) = trip.as_mut()
                {
                    *navs += 1;
                }
                s.periodic.push(l);
                line.clear();
            }
        } else if k == "motors" {
            s.motors.push(item.text.clone());
        } else if item.text.starts_with("icmd:ligt(") {
            let level = item.text["icmd:ligt(".len()..]
                .trim_end_matches(')')
                .to_owned();
            trip.get_or_insert_with(|| (Vec::new(), 0)).0.push(level);
            blink_follow = 2;
        } else if blink_follow > 0 && (k == "LIGT" || k == "LIGP") {
            blink_follow -= 1;
        } else {
            blink_follow = 0;
            if k == "pong" {
                s.pongs.push(item.text.clone());
            }
            if item.text == "icmd:start()"
                && let Some(t) = trip.take()
            {
                s.blinks.push(t);
            }
            let mut r = item.clone();
            if k == "pong" {
                // pong:<argument count>,<millis>
                let argc = r.text["pong:".len()..]
                    .split(',')
                    .next()
                    .unwrap_or("")
                    .to_owned();
                r.text = format!("pong:{argc},<millis>");
            }
            s.replies.push(r);
        }
        prev_key = k;
    }
    if let Some(t) = trip {
        s.blinks.push(t);
    }
    s
}

/// The first place two item sequences differ, with context.
fn first_difference(what: &str, genuine: &[Item], twin: &[Item]) -> Option<String> {
    let n = genuine.len().max(twin.len());
    let at = (0..n).find(|&i| genuine.get(i) != twin.get(i))?;
    let window = |v: &[Item]| {
        v[at.saturating_sub(4)..(at + 5).min(v.len())]
            .iter()
            .map(|i| format!("  {i}"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    Some(format!(
        "{what} differ at item {at} (genuine {} items, emulator {}):\n genuine:\n{}\n emulator:\n{}",
        genuine.len(),
        twin.len(),
        window(genuine),
        window(twin)
    ))
}

/// The status cycles (`motorAttached` … `alps`), each as its lines.
fn status_cycles(periodic: &[String]) -> Vec<Vec<String>> {
    let mut cycles = Vec::new();
    let mut cur: Option<Vec<String>> = None;
    for l in periodic {
        if l.starts_with("motorAttached:") {
            cur = Some(Vec::new());
        }
        if let Some(c) = cur.as_mut() {
            // Lines of other timers never fall inside a cycle: the board
            // prints it from one function.
            c.push(l.clone());
            if l.starts_with("alps:") {
                cycles.extend(cur.take());
            }
        }
    }
    cycles.extend(cur);
    cycles
}

/// Compares the genuine board's capture with the emulator's; `Err` says
/// every difference found.
fn compare(genuine: &Capture, twin: &Capture) -> Result<(), String> {
    let g = sort(&items(&genuine.bytes));
    let t = sort(&items(&twin.bytes));
    let mut problems = Vec::new();
    problems.extend(first_difference("set-up chatter", &g.chatter, &t.chatter));
    problems.extend(first_difference("replies", &g.replies, &t.replies));
    if g.motors != t.motors {
        problems.push(format!(
            "motors: lines differ:\n genuine  {:?}\n emulator {:?}",
            g.motors, t.motors
        ));
    }
    // The dead-man's blinking.
    if g.blinks.len() != t.blinks.len() {
        problems.push(format!(
            "dead-man trips with blinking: genuine {}, emulator {}",
            g.blinks.len(),
            t.blinks.len()
        ));
    }
    for (i, ((gb, gn), (tb, tn))) in g.blinks.iter().zip(&t.blinks).enumerate() {
        // The firmware's blink state outlives a trip, and a blink queued
        // just before the ping may run after it: where a later trip starts
        // depends on timing, not behaviour. Only the first is compared.
        if i == 0 && gb.first() != tb.first() {
            problems.push(format!(
                "trip {i}: first blink {:?} (genuine) vs {:?} (emulator)",
                gb.first(),
                tb.first()
            ));
        }
        for (who, b, navs) in [("genuine", gb, gn), ("emulator", tb, tn)] {
            if b.windows(2).any(|w| w[0] == w[1]) || b.iter().any(|l| l != "0" && l != "50") {
                problems.push(format!(
                    "trip {i}: {who} blinks {b:?} do not alternate 50/0"
                ));
            }
            // 500 ms a blink, about 101 ms a navigation line.
            let expected = *navs as f64 * 101.0 / 501.0;
            if (b.len() as f64 - expected).abs() > 2.0 {
                problems.push(format!(
                    "trip {i}: {who} blinked {} times over {navs} navigation lines (≈ {expected:.1} expected)",
                    b.len()
                ));
            }
        }
    }
    // Periodic lines: the same shapes, the same status cycle, the same rates.
    let gs: BTreeSet<&String> = g.periodic.iter().collect();
    let ts: BTreeSet<&String> = t.periodic.iter().collect();
    for s in gs.difference(&ts) {
        problems.push(format!("periodic line only the genuine board prints: {s}"));
    }
    for s in ts.difference(&gs) {
        problems.push(format!("periodic line only the emulator prints: {s}"));
    }
    let gc = status_cycles(&g.periodic);
    let tc = status_cycles(&t.periodic);
    let reference = gc.first().cloned().unwrap_or_default();
    if reference.is_empty() {
        problems.push("the genuine board printed no status cycle".into());
    }
    for (who, cycles) in [("genuine", &gc), ("emulator", &tc)] {
        // The last one may be cut by the end of the capture.
        for c in cycles.iter().take(cycles.len().saturating_sub(1)) {
            if *c != reference {
                problems.push(format!(
                    "{who} status cycle {c:#?} is not the genuine board's {reference:#?}"
                ));
                break;
            }
        }
    }
    let count = |v: &[String]| {
        let mut m: BTreeMap<String, usize> = BTreeMap::new();
        for l in v {
            *m.entry(l.clone()).or_default() += 1;
        }
        m
    };
    let (gn, tn) = (count(&g.periodic), count(&t.periodic));
    for (shape, n) in &gn {
        let rg = *n as f64 / genuine.board_s;
        let rt = tn.get(shape).copied().unwrap_or(0) as f64 / twin.board_s;
        if (rg - rt).abs() > 0.15 * rg.max(rt) + 0.15 {
            problems.push(format!(
                "{shape}: {rg:.2}/s on the genuine board, {rt:.2}/s on the emulator"
            ));
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(problems.join("\n"))
    }
}

fn keep(name: &str, c: &Capture) -> PathBuf {
    let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::write(&path, &c.bytes);
    path
}

fn twin(version: FirmwareVersion) {
    let (genuine, sent) = run_genuine(version);
    let emulator = run_emulator(version, &sent);
    let gp = keep(&format!("twin-{version}-genuine.txt"), &genuine);
    let ep = keep(&format!("twin-{version}-emulator.txt"), &emulator);
    if let Err(e) = compare(&genuine, &emulator) {
        panic!(
            "the emulator is not the genuine firmware {version}'s twin (outputs kept in {} and {}):\n{e}",
            gp.display(),
            ep.display()
        );
    }
    // The session did what it was written for, on both boards.
    for (who, c) in [("genuine", &genuine), ("emulator", &emulator)] {
        let s = sort(&items(&c.bytes));
        let has = |t: &str| s.replies.iter().any(|r| r.text == t);
        assert!(has("log: CommandBufferOverrun"), "{who}: no overrun");
        assert!(has("icmd:deptloff()"), "{who}: no dead-man trip");
        assert_eq!(s.blinks.len(), 2, "{who}: two trips");
        assert!(
            s.motors.contains(&"motors:1640,1500,1270".to_owned())
                && s.motors.contains(&"motors:1270,1500,1640".to_owned()),
            "{who}: {:?}",
            s.motors
        );
    }
}

#[test]
fn the_emulator_is_the_twin_of_firmware_30_0_2() {
    twin(FirmwareVersion::V30_0_2);
}

#[test]
fn the_emulator_is_the_twin_of_firmware_2014_12() {
    twin(FirmwareVersion::V2014_12);
}

// ---------------------------------------------------------------------------
// The comparator catches what it must (on the emulator's own stream, so
// these need no simulator).
// ---------------------------------------------------------------------------

fn doctored(f: impl Fn(&[u8]) -> Vec<u8>) -> Result<(), String> {
    let reference = run_emulator(FirmwareVersion::V30_0_2, &nominal());
    let changed = Capture {
        bytes: f(&reference.bytes),
        board_s: reference.board_s,
    };
    assert_ne!(
        changed.bytes, reference.bytes,
        "the doctoring changed nothing"
    );
    compare(&reference, &changed)
}

fn replace_nth(hay: &[u8], from: &[u8], to: &[u8], nth: usize) -> Vec<u8> {
    let mut seen = 0;
    let mut out = Vec::with_capacity(hay.len());
    let mut i = 0;
    while i < hay.len() {
        if hay[i..].starts_with(from) {
            if seen == nth {
                out.extend_from_slice(to);
                out.extend_from_slice(&hay[i + from.len()..]);
                return out;
            }
            seen += 1;
        }
        out.push(hay[i]);
        i += 1;
    }
    out
}

fn replace_all(hay: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(hay.len());
    let mut i = 0;
    while i < hay.len() {
        if hay[i..].starts_with(from) {
            out.extend_from_slice(to);
            i += from.len();
        } else {
            out.push(hay[i]);
            i += 1;
        }
    }
    out
}

#[test]
fn the_comparison_accepts_the_same_stream() {
    let a = run_emulator(FirmwareVersion::V30_0_2, &nominal());
    compare(&a, &a).unwrap();
}

#[test]
fn the_comparison_ignores_an_item_cut_by_the_end_of_the_capture() {
    let a = run_emulator(FirmwareVersion::V30_0_2, &nominal());
    let mut cut = a.bytes.clone();
    cut.extend_from_slice(b"rol");
    let b = Capture {
        bytes: cut,
        board_s: a.board_s,
    };
    compare(&a, &b).unwrap();
    compare(&b, &a).unwrap();
}

#[test]
fn the_comparison_catches_a_line_break_added_after_crc_pass_or_pong() {
    assert!(doctored(|b| replace_all(b, b"crc:pass;", b"crc:pass;\r\n")).is_err());
    let e = doctored(|b| {
        let i = b.windows(5).position(|w| w == b"pong:").unwrap();
        let j = i + b[i..].iter().position(|&c| c == b';').unwrap() + 1;
        [&b[..j], b"\r\n", &b[j..]].concat()
    });
    assert!(e.is_err());
}

#[test]
fn the_comparison_catches_a_different_echo_or_crc_report() {
    assert!(doctored(|b| replace_nth(b, b"rawcmd:9E,", b"rawcmd:9e,", 0)).is_err());
    assert!(doctored(|b| replace_all(b, b"crc:fail,", b"crc:fail:")).is_err());
    assert!(doctored(|b| replace_nth(b, b"cmd:ping(7,8x)", b"cmd:ping(7,8)", 0)).is_err());
}

#[test]
fn the_comparison_catches_a_missing_extra_or_reordered_reply() {
    assert!(doctored(|b| replace_nth(b, b"claser:255;", b"", 0)).is_err());
    assert!(
        doctored(|b| replace_nth(
            b,
            b"log:escpower=0;\r\n",
            b"log:escpower=0;\r\nlog:UnknownCommand frob;\r\n",
            0
        ))
        .is_err()
    );
    assert!(
        doctored(|b| replace_nth(
            b,
            b"cmd:ligt(51);\r\nLIGT:51;LIGP:0.20;\r\n",
            b"LIGT:51;LIGP:0.20;\r\ncmd:ligt(51);\r\n",
            0
        ))
        .is_err()
    );
    assert!(
        doctored(|b| replace_nth(b, b"motors:1640,1500,1270;", b"motors:1600,1500,1400;", 0))
            .is_err()
    );
}

#[test]
fn the_comparison_catches_a_wrong_key_or_status_line_structure() {
    assert!(doctored(|b| replace_all(b, b"deap:", b"deep:")).is_err());
    assert!(doctored(|b| replace_all(b, b"4.8.1\r\n;time:", b"4.8.1;time:")).is_err());
    assert!(doctored(|b| replace_all(b, b"BT1I:", b"btti:")).is_err());
    assert!(
        doctored(|b| replace_all(
            b,
            b"log:Failed to read Depth from I2C\r\n",
            b"log:Failed to read Depth from I2C;\r\n"
        ))
        .is_err()
    );
}

#[test]
fn the_comparison_lets_periodic_lines_move_in_time() {
    // A navigation line moved past the reply after it, and one dropped.
    let moved = doctored(|b| {
        let nav = b"hdgd:0.00;deap:0.00;pitc:0.00;roll:0.00;yaw:0.00;fthr:0.00;\r\n";
        let cut = replace_nth(b, nav, b"", 20);
        replace_nth(
            &cut,
            b"cmd:dms(0);\r\n",
            &[b"cmd:dms(0);\r\n".as_slice(), nav].concat(),
            0,
        )
    });
    assert!(moved.is_ok(), "{moved:?}");
    let dropped = doctored(|b| {
        replace_nth(
            b,
            b"hdgd:0.00;deap:0.00;pitc:0.00;roll:0.00;yaw:0.00;fthr:0.00;\r\n",
            b"",
            5,
        )
    });
    assert!(dropped.is_ok(), "{dropped:?}");
}
