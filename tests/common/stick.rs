//! Timing stick input to `go()` on the board's pty, for the benches that
//! measure it (`latency`, `transfer`): MANUAL_CONTROL datagrams sent on a
//! fixed schedule, each changing the thruster command, and every `go()`
//! frame the board emulator reads matched to the datagram that carried its
//! values (by content, not by order).

use std::collections::HashMap;
use std::sync::mpsc as std_mpsc;
use std::thread;
use std::time::{Duration, Instant};

use neptunus::firmware::codec::{self, Framing};
use neptunus::firmware::emulator::{BoardRecord, PtyBoard};
use neptunus::mavlink::frame::encode_v2;

use super::{Gcs, gcs_heartbeat, manual_control, pct_ms};

/// One datagram sent: when, and the MAVLink sequence number it carried.
#[derive(Clone, Copy)]
pub struct Sent {
    pub at: Instant,
    pub seq: u8,
    pub stick: usize,
}

/// Sends `count` MANUAL_CONTROL datagrams on a fixed schedule (a late one
/// does not make the next ones early), cycling through `sticks`, with a GCS
/// heartbeat each second if `heartbeats`.
pub fn paced_send(
    gcs: &mut Gcs,
    sticks: &[i16],
    count: usize,
    period: Duration,
    heartbeats: bool,
) -> anyhow::Result<Vec<Sent>> {
    paced_send_while(gcs, sticks, count, period, heartbeats, || true)
}

/// As [`paced_send`], stopping early (before a datagram) once `go_on`
/// says no more.
pub fn paced_send_while(
    gcs: &mut Gcs,
    sticks: &[i16],
    count: usize,
    period: Duration,
    heartbeats: bool,
    mut go_on: impl FnMut() -> bool,
) -> anyhow::Result<Vec<Sent>> {
    let mut sent = Vec::with_capacity(count.min(1 << 20));
    let start = Instant::now() + period;
    let mut next_hb = start;
    for i in 0..count {
        if !go_on() {
            break;
        }
        let due = start + period * i as u32;
        if heartbeats && Instant::now() >= next_hb {
            next_hb += Duration::from_secs(1);
            gcs.send(&gcs_heartbeat())?;
        }
        let now = Instant::now();
        if due > now {
            thread::sleep(due - now);
        }
        let stick = i % sticks.len();
        let bytes = encode_v2(255, 190, gcs.seq, &manual_control(sticks[stick]));
        let at = Instant::now();
        gcs.sock.send(&bytes)?;
        sent.push(Sent {
            at,
            seq: gcs.seq,
            stick,
        });
        gcs.seq = gcs.seq.wrapping_add(1);
    }
    Ok(sent)
}

// ---------------------------------------------------------------------------
// Timing go() frames at the emulator
// ---------------------------------------------------------------------------

/// A `go()` frame's text without its CRC byte and padding, e.g. `go(1300,1500,1700)`.
pub fn go_text(frame: &[u8]) -> Option<String> {
    let text = frame.get(1..)?;
    if !text.starts_with(b"go(") {
        return None;
    }
    let s: String = String::from_utf8_lossy(text)
        .chars()
        .filter(|c| !c.is_whitespace() && *c != ';')
        .collect();
    Some(s)
}

/// Forwards every `go()` frame the board reads, with the time the emulator
/// woke to read it, to a std channel (so blocking code can consume it).
pub fn watch_go_frames(
    rt: &tokio::runtime::Runtime,
    board: &PtyBoard,
) -> std_mpsc::Receiver<(Instant, String)> {
    super::forward_records(rt, board, |r| match r {
        BoardRecord::Frame(f) => go_text(f),
        BoardRecord::Executed(_) => None,
    })
}

/// Latencies of one path.
pub struct Outcome {
    pub latencies: Vec<Duration>,
    /// Latencies of datagrams sent at least [`line_busy`] after the one
    /// before: the serial line was free, nothing waited for pacing.
    pub line_free: Vec<Duration>,
    pub sent: usize,
    /// No `go()` of its own, but the next datagram's arrived: superseded
    /// while waiting for the line (the link's coalescing).
    pub coalesced: usize,
    /// No `go()` and the next datagram's did not arrive either.
    pub lost: usize,
}

impl Outcome {
    /// Matches every send with the first frame of its content that arrived
    /// after it and before the next send of the same content.
    pub fn match_up(
        sent: &[Sent],
        key: impl Fn(&Sent) -> String,
        frames: &[(Instant, String)],
    ) -> Self {
        let mut arrivals: HashMap<&str, Vec<Instant>> = HashMap::new();
        for (at, text) in frames {
            arrivals.entry(text.as_str()).or_default().push(*at);
        }
        for v in arrivals.values_mut() {
            v.sort();
        }
        let keys: Vec<String> = sent.iter().map(&key).collect();
        let mut next_same: Vec<Option<Instant>> = vec![None; sent.len()];
        let mut last_seen: HashMap<&str, usize> = HashMap::new();
        for (i, k) in keys.iter().enumerate().rev() {
            if let Some(&j) = last_seen.get(k.as_str()) {
                next_same[i] = Some(sent[j].at);
            }
            last_seen.insert(k.as_str(), i);
        }
        let matched: Vec<Option<Duration>> = sent
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let times = arrivals.get(keys[i].as_str())?;
                let first = times.partition_point(|t| *t < s.at);
                let t = *times.get(first)?;
                if next_same[i].is_some_and(|limit| t >= limit) {
                    return None;
                }
                Some(t - s.at)
            })
            .collect();
        let busy = line_busy();
        let mut out = Outcome {
            latencies: matched.iter().flatten().copied().collect(),
            line_free: (1..sent.len())
                .filter(|&i| sent[i].at - sent[i - 1].at >= busy)
                .filter_map(|i| matched[i])
                .collect(),
            sent: sent.len(),
            coalesced: 0,
            lost: 0,
        };
        for i in 0..matched.len() {
            if matched[i].is_some() {
                continue;
            }
            // Superseded if a newer command made it to the board soon after:
            // the link wrote the newest one instead (by design).
            let superseded = (i + 1..matched.len())
                .take_while(|&j| sent[j].at - sent[i].at < Duration::from_millis(100))
                .any(|j| matched[j].is_some());
            if superseded {
                out.coalesced += 1;
            } else {
                out.lost += 1;
            }
        }
        out.latencies.sort();
        out.line_free.sort();
        out
    }

    pub fn pct_ms(&self, q: f64) -> f64 {
        pct_ms(&self.latencies, q)
    }

    #[allow(clippy::print_stdout, reason = "the benches print their figures")]
    pub fn print(&self, name: &str) {
        println!(
            "  {name}: {} of {} matched, p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms; coalesced {}, lost {}",
            self.latencies.len(),
            self.sent,
            self.pct_ms(0.5),
            self.pct_ms(0.99),
            self.pct_ms(1.0),
            self.coalesced,
            self.lost
        );
    }
}

/// How long the link keeps the serial line after writing a `go()` frame
/// (its wire time at 115200 baud plus the frame gap): a datagram arriving
/// sooner after the previous one waits for the line.
pub fn line_busy() -> Duration {
    let link = neptunus::firmware::link::LinkConfig::new("/dev/null");
    let go = codec::encoded(
        &codec::Command::Go {
            port_us: 1500,
            vertical_us: 1500,
            starboard_us: 1000,
        },
        Framing::Crc8,
    );
    link.wire_time(go.len()) + link.frame_gap
}

/// Waits for frames to stop arriving, then takes everything received.
pub fn collect_frames(rx: &std_mpsc::Receiver<(Instant, String)>) -> Vec<(Instant, String)> {
    let mut frames = Vec::new();
    while let Ok(f) = rx.recv_timeout(Duration::from_millis(300)) {
        frames.push(f);
    }
    frames
}

/// Learns which `go()` each stick position produces (full forward at gain
/// 0.5 is go(1300,1500,1700)): `steps` positions, forward only, away from
/// any deadzone, each a different command.
pub fn learn_sticks(
    gcs: &mut Gcs,
    frames_rx: &std_mpsc::Receiver<(Instant, String)>,
    steps: usize,
) -> anyhow::Result<(Vec<i16>, Vec<String>)> {
    use anyhow::{Context as _, bail};
    let sticks: Vec<i16> = (0..steps).map(|k| 1000 - 10 * k as i16).collect();
    let _ = collect_frames(frames_rx);
    let mut learned: Vec<String> = Vec::with_capacity(sticks.len());
    for &x in &sticks {
        gcs.send(&manual_control(x))?;
        let (_, text) = frames_rx
            .recv_timeout(Duration::from_secs(2))
            .with_context(|| format!("no go() on the serial line after MANUAL_CONTROL x={x}"))?;
        if learned.contains(&text) {
            bail!("MANUAL_CONTROL x={x} gave {text}, as another stick position did");
        }
        learned.push(text);
        thread::sleep(Duration::from_millis(20));
    }
    Ok((sticks, learned))
}
