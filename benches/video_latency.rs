//! Camera-to-screen latency of the five ways to watch the vehicle's camera,
//! printed as a table.
//!
//! The vehicle (`$NEPTUNUS_BIN`, else target/release, else target/debug)
//! runs `--sim` with its synthetic camera at 640×480 and 30 fps and
//! `[camera] synthetic_timecode = true`: every frame carries its capture
//! time in milliseconds (CLOCK_REALTIME) as a block code in its
//! bottom-left corner (`neptunus::camera::timecode`). Each way to watch
//! reads the code back from every frame it shows, and a frame's latency is
//! the reader's realtime clock then minus the code (same machine, same
//! clock):
//!
//! 1. **HMI MJPEG** — the operator page in Debian's Chromium playing
//!    `/video.mjpg` (WebRTC hidden from it), read back from its canvas
//!    right after each frame is drawn there;
//! 2. **HMI WebRTC** — the operator page as it is (WebRTC on `/webrtc`),
//!    shown by its own `<video>` over the canvas, read back from that
//!    `<video>` in `requestVideoFrameCallback`;
//! 3. **MCM WebRTC** — `tests/browser/mcm-viewer.html`, a client of
//!    mavlink-camera-manager's protocol (as Cockpit speaks it) on the
//!    dedicated signalling port, its `<video>` read back in
//!    `requestVideoFrameCallback`;
//! 4. **Cockpit WebRTC** — the real Cockpit (its web build, as
//!    tests/browser/cockpit.test.js runs it: `tests/browser/cockpit-harness.js`),
//!    given only the address of a vehicle of its own on port 80 of a
//!    loopback address, playing the vehicle's WebRTC in its own player;
//!    its code untouched, the `<video>` it plays the stream in read back in
//!    `requestVideoFrameCallback`;
//! 5. **RTP/GStreamer** — QGroundControl's receiving pipeline under
//!    `gst-launch-1.0` (`udpsrc ! rtph264depay ! h264parse ! avdec_h264`),
//!    then `videoconvert` to 8-bit grey and `fdsink sync=false` into this
//!    process, which reads each raw frame as it arrives (what an appsink
//!    would hand over) and decodes the code.
//!
//! 1–3 run in one Chromium (`tests/browser/latency-bench.js`, through
//! playwright-core: `npm ci` in tests/browser first) against one vehicle
//! with `--video-rtp off`; 4 in a Chromium of its own against a vehicle
//! the script starts (root, for port 80, and Cockpit's build at
//! ../shared/cockpit/dist or `COCKPIT_DIST`; else skipped with the
//! reason); 5 against one more vehicle sending RTP to the pipeline's port
//! with `--webrtc off`, so each way runs alone with what it needs. Each way is measured for `VIDEO_LATENCY_S` seconds (default
//! 10) after its first readable frame and 1 s of settling. A frame whose
//! code does not read (a half-updated picture) is counted as rejected, a
//! frame shown again as repeated; neither is a sample. For the WebRTC
//! pages the table also gives the age at the callback's `receiveTime`
//! (the frame's last packet in) and at its `expectedDisplayTime`, and the
//! time from asking (the page's `startSession`) to the first picture; for
//! the operator page, its own cost per frame (each `drawImage` of a picture
//! on its video canvas, each animation-frame callback: the HUD and the
//! rest).
//!
//! Under `cargo test --all-targets` (no `--bench`) a smoke run of 1 s per
//! way; a way whose tools are missing (node, Chromium, playwright-core,
//! Cockpit's build or port 80, gst-launch-1.0 with avdec_h264) is skipped
//! with the reason. Figures are
//! printed, never asserted.

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime};

use anyhow::{Context as _, bail};
use common::{Vehicle, free_udp_port};
use neptunus::camera::timecode;

const WIDTH: usize = 640;
const HEIGHT: usize = 480;
const FPS: u32 = 30;

fn knob(name: &str, full: u64, smoke: u64, is_full: bool) -> anyhow::Result<u64> {
    match std::env::var(name) {
        Ok(v) => v
            .trim()
            .parse::<u64>()
            .map(|n| n.max(1))
            .with_context(|| format!("{name}={v:?} is not a whole number")),
        Err(_) => Ok(if is_full { full } else { smoke }),
    }
}

fn unix_ms() -> u64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

fn pct(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// One way to watch: its samples, or why there are none.
struct Row {
    name: &'static str,
    outcome: Result<Measured, String>,
}

#[derive(Default)]
struct Measured {
    /// Age when the reader had the frame in hand, ms.
    shown: Vec<f64>,
    /// Age at the WebRTC callback's receiveTime / expectedDisplayTime.
    received: Vec<f64>,
    displayed: Vec<f64>,
    rejected: u64,
    repeated: u64,
    seconds: f64,
    /// From opening the page (or starting the vehicle) to the first picture.
    first_frame_ms: Option<f64>,
    /// From the page's `startSession` to its first picture (WebRTC).
    asked_ms: Option<f64>,
    /// The operator page's own cost per frame: [p50, p95, count] ms.
    draw_ms: Option<[f64; 3]>,
    animation_frame_ms: Option<[f64; 3]>,
    /// Over the window, by the page's `<video>`s given a stream: frames
    /// decoded, frames dropped, how many `<video>`s.
    video_frames: Option<[f64; 3]>,
}

const BROWSER_WAYS: [(&str, &str); 4] = [
    ("hmi-mjpeg", "HMI MJPEG"),
    ("hmi-webrtc", "HMI WebRTC"),
    ("mcm-webrtc", "MCM WebRTC"),
    ("cockpit-webrtc", "Cockpit WebRTC"),
];

fn main() -> anyhow::Result<()> {
    let full = std::env::args().any(|a| a == "--bench");
    let seconds = knob("VIDEO_LATENCY_S", 10, 1, full)?;
    let bin = match common::neptunus_bin() {
        Ok(b) => b,
        Err(e) if !full => {
            println!("video_latency: skipped (smoke run): {e}");
            return Ok(());
        }
        Err(e) => return Err(e),
    };
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let mut rows = Vec::new();
    match browser_missing() {
        Some(why) => {
            for (_, name) in BROWSER_WAYS {
                rows.push(Row {
                    name,
                    outcome: Err(format!("skipped: {why}")),
                });
            }
        }
        None => rows.extend(browser_paths(&bin, seconds, full)?),
    }
    rows.push(Row {
        name: "RTP/GStreamer",
        outcome: match gstreamer_missing() {
            Some(why) => Err(format!("skipped: {why}")),
            None => gstreamer_path(&bin, seconds, full).map_err(|e| format!("{e:#}")),
        },
    });
    print_table(&rows, &bin, seconds, full, load.trim());
    Ok(())
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn on_path(program: &str) -> bool {
    Command::new(program)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn browser_missing() -> Option<String> {
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    if !on_path("node") {
        return Some("no node on PATH (apt install nodejs npm)".into());
    }
    if !Path::new(&chromium).is_file() {
        return Some(format!(
            "no Chromium at {chromium} (apt install chromium, or set CHROMIUM)"
        ));
    }
    if !repo()
        .join("tests/browser/node_modules/playwright-core")
        .is_dir()
    {
        return Some(
            "no playwright-core in tests/browser/node_modules (run `npm ci` there)".into(),
        );
    }
    None
}

fn gstreamer_missing() -> Option<String> {
    let ok = |el: &str| {
        Command::new("gst-inspect-1.0")
            .arg(el)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    if !ok("rtph264depay") || !ok("h264parse") || !ok("avdec_h264") {
        return Some(
            "GStreamer's rtph264depay, h264parse or avdec_h264 missing (apt install \
             gstreamer1.0-tools gstreamer1.0-plugins-good gstreamer1.0-plugins-bad gstreamer1.0-libav)"
                .into(),
        );
    }
    None
}

/// The bench's camera, as a config file's section.
fn camera_toml() -> String {
    format!(
        "[camera]\nsource = \"synthetic\"\nwidth = {WIDTH}\nheight = {HEIGHT}\nfps = {FPS}\nsynthetic_timecode = true\n"
    )
}

/// The vehicle with the bench's camera; `extra`: the video arguments;
/// `more_toml`: appended to its config file.
fn vehicle(
    bin: &Path,
    dir: &Path,
    extra: &[&str],
    more_toml: &str,
) -> anyhow::Result<(Vehicle, std::net::SocketAddr)> {
    std::fs::create_dir_all(dir)?;
    let config = dir.join("neptunus.toml");
    std::fs::write(&config, format!("{}{more_toml}", camera_toml()))?;
    let mav = format!("udpin:127.0.0.1:{}", free_udp_port()?);
    let config = config.to_string_lossy().into_owned();
    let mut args = vec!["--sim", "--config", &config, "--mavlink", &mav];
    args.extend_from_slice(extra);
    let mut v = Vehicle::spawn(bin, &args, dir, "")?;
    let addr = v.http_addr(Duration::from_secs(30))?;
    Ok((v, addr))
}

/// 1–4: one vehicle (and Cockpit's, which the script starts), the node
/// script, its JSON.
fn browser_paths(bin: &Path, seconds: u64, full: bool) -> anyhow::Result<Vec<Row>> {
    let dir = tempfile::tempdir()?;
    // The MCM viewer's page is served from an origin of its own, as
    // Cockpit's is, which the vehicle must list.
    let viewer_port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    let (mut v, addr) = vehicle(
        bin,
        dir.path(),
        &["--video-rtp", "off", "--webrtc-signalling", "127.0.0.1:0"],
        &format!("[hmi]\nallowed_origins = [\"http://127.0.0.1:{viewer_port}\"]\n"),
    )?;
    let (warmup_ms, first_ms) = if full { (1000, 30_000) } else { (300, 8000) };
    let mut node = Command::new("node")
        .arg("latency-bench.js")
        .arg(format!("http://{addr}/"))
        .arg(viewer_port.to_string())
        .arg(seconds.to_string())
        .arg(warmup_ms.to_string())
        .arg(first_ms.to_string())
        .current_dir(repo().join("tests/browser"))
        .env("NEPTUNUS_BIN", bin)
        .env("LATENCY_VEHICLE_TOML", camera_toml())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("cannot start node")?;
    // Read as it comes: a long run prints more than a pipe holds.
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut text = String::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_string(&mut text);
            }
            text
        })
    };
    let out = drain(
        node.stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let err = drain(
        node.stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    // Four ways, each: its first frame (Cockpit's app loading first: four
    // times as long), settling, the measurement.
    let deadline = Instant::now()
        + Duration::from_millis(
            4 * (warmup_ms + seconds * 1000) + 3 * first_ms + 4 * first_ms + 60_000,
        );
    let status = loop {
        if let Some(s) = node.try_wait()? {
            break s;
        }
        if Instant::now() > deadline {
            let _ = node.kill();
            let _ = node.wait();
            bail!("the browser half (node latency-bench.js) did not finish in time");
        }
        v.check_running()?;
        std::thread::sleep(Duration::from_millis(100));
    };
    let out = out.join().unwrap_or_default();
    let err = err.join().unwrap_or_default();
    if !status.success() {
        bail!("node latency-bench.js failed ({status}):\n{}", tail(&err));
    }
    let json: serde_json::Value = serde_json::from_str(out.trim()).with_context(|| {
        format!(
            "node latency-bench.js printed no JSON: {out:?}\n{}",
            tail(&err)
        )
    })?;
    println!(
        "Chromium {}",
        json["chromium"].as_str().unwrap_or("(version unknown)")
    );
    let mut rows = Vec::new();
    let spread = |v: &serde_json::Value| -> Option<[f64; 3]> {
        Some([v[0].as_f64()?, v[1].as_f64()?, v[2].as_f64()?])
    };
    for (key, name) in BROWSER_WAYS {
        let p = &json["paths"][key];
        let outcome = if let Some(e) = p["error"].as_str() {
            if e.starts_with("skipped:") {
                rows.push(Row {
                    name,
                    outcome: Err(e.to_owned()),
                });
                continue;
            }
            Err(format!(
                "{e}\n--- neptunus stderr (tail) ---\n{}",
                v.stderr_tail()
            ))
        } else {
            let mut m = Measured {
                rejected: p["rejected"].as_u64().unwrap_or(0),
                repeated: p["repeated"].as_u64().unwrap_or(0),
                seconds: p["seconds"].as_f64().unwrap_or(f64::NAN),
                first_frame_ms: p["first_frame_ms"].as_f64(),
                asked_ms: p["asked_ms"].as_f64(),
                draw_ms: spread(&p["draw_ms"]),
                animation_frame_ms: spread(&p["animation_frame_ms"]),
                video_frames: spread(&p["video_frames"]),
                ..Measured::default()
            };
            for s in p["samples"].as_array().into_iter().flatten() {
                if let Some(a) = s[0].as_f64() {
                    m.shown.push(a);
                }
                if let Some(a) = s[1].as_f64() {
                    m.displayed.push(a);
                }
                if let Some(a) = s[2].as_f64() {
                    m.received.push(a);
                }
            }
            Ok(m)
        };
        rows.push(Row { name, outcome });
    }
    Ok(rows)
}

fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(15)..].join("\n")
}

/// 4: QGroundControl's pipeline, its decoded frames read from its stdout.
fn gstreamer_path(bin: &Path, seconds: u64, full: bool) -> anyhow::Result<Measured> {
    let port = free_udp_port()?;
    let caps = "application/x-rtp,media=video,clock-rate=90000,encoding-name=H264,payload=96";
    let mut gst = Command::new("gst-launch-1.0")
        .args([
            "-q",
            "udpsrc",
            &format!("port={port}"),
            &format!("caps={caps}"),
        ])
        .args(["!", "rtph264depay", "!", "h264parse", "!", "avdec_h264"])
        .args(["!", "videoconvert", "!", "video/x-raw,format=GRAY8"])
        .args(["!", "fdsink", "fd=1", "sync=false"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .context("cannot start gst-launch-1.0")?;
    let mut pipe = gst.stdout.take().context("stdout")?;
    let (tx, rx) = mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut frame = vec![0u8; WIDTH * HEIGHT];
        while pipe.read_exact(&mut frame).is_ok() {
            let at = unix_ms();
            let code = timecode::read(&frame, WIDTH, HEIGHT);
            if tx.send((code, at)).is_err() {
                return;
            }
        }
    });
    let dir = tempfile::tempdir()?;
    let dest = format!("udp://127.0.0.1:{port}");
    let result = (|| {
        let (mut v, _) = vehicle(
            bin,
            dir.path(),
            &["--video-rtp", &dest, "--webrtc", "off"],
            "",
        )?;
        let opened = Instant::now();
        let first_wait = Duration::from_secs(if full { 30 } else { 8 });
        let warmup = Duration::from_millis(if full { 1000 } else { 300 });
        let mut m = Measured::default();
        let mut last = None;
        let mut first: Option<Instant> = None;
        let mut measure_from = None;
        loop {
            let (code, at) = match rx.recv_timeout(Duration::from_millis(500)) {
                Ok(x) => x,
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    v.check_running()?;
                    if first.is_none() && opened.elapsed() > first_wait {
                        bail!("no decoded frame from GStreamer in {first_wait:?}");
                    }
                    continue;
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => bail!("gst-launch-1.0 ended"),
            };
            let now = Instant::now();
            let on = measure_from.is_some_and(|t| now >= t);
            if measure_from.is_some_and(|t| now >= t + Duration::from_secs(seconds)) {
                break;
            }
            match code {
                Err(_) => m.rejected += u64::from(on),
                Ok(c) if Some(c) == last => m.repeated += u64::from(on),
                Ok(c) => {
                    last = Some(c);
                    if first.is_none() {
                        first = Some(now);
                        measure_from = Some(now + warmup);
                        m.first_frame_ms = Some(opened.elapsed().as_secs_f64() * 1000.0);
                    }
                    if on {
                        m.shown.push(timecode::age_ms(c, at) as f64);
                    }
                }
            }
        }
        m.seconds = seconds as f64;
        Ok(m)
    })();
    let _ = gst.kill();
    let _ = gst.wait();
    drop(rx);
    let _ = reader.join();
    result
}

fn print_table(rows: &[Row], bin: &Path, seconds: u64, full: bool, load: &str) {
    println!();
    println!(
        "camera-to-screen latency, {WIDTH}×{HEIGHT} at {FPS} fps, {seconds} s per way{} — {}",
        if full { "" } else { " (smoke run)" },
        bin.display()
    );
    println!("load average at the start: {load}");
    println!(
        "| way to watch | frames seen (of ~{}) | p50 ms | p95 ms | max ms | rejected | repeated | first picture after opening | after asking |",
        u64::from(FPS) * seconds
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let secs = |ms: Option<f64>| ms.map_or("—".into(), |ms| format!("{:.2} s", ms / 1000.0));
    for r in rows {
        match &r.outcome {
            Ok(m) => {
                let mut s = m.shown.clone();
                s.sort_by(f64::total_cmp);
                println!(
                    "| {} | {} | {:.1} | {:.1} | {:.1} | {} | {} | {} | {} |",
                    r.name,
                    s.len(),
                    pct(&s, 0.5),
                    pct(&s, 0.95),
                    s.last().copied().unwrap_or(f64::NAN),
                    m.rejected,
                    m.repeated,
                    secs(m.first_frame_ms),
                    secs(m.asked_ms),
                );
            }
            Err(why) => println!(
                "| {} | — | — | — | — | | | | {} |",
                r.name,
                why.replace('\n', " ⏎ ")
            ),
        }
    }
    let webrtc: Vec<_> = rows
        .iter()
        .filter_map(|r| Some((r.name, r.outcome.as_ref().ok()?)))
        .filter(|(_, m)| !m.received.is_empty() || !m.displayed.is_empty())
        .collect();
    if !webrtc.is_empty() {
        println!();
        println!("WebRTC, by requestVideoFrameCallback's own times (p50 / p95 ms):");
        println!(
            "| way to watch | age at receiveTime (last packet in) | age at expectedDisplayTime | decoded / dropped by its <video>s (how many) |"
        );
        println!("|---|---|---|---|");
        for (name, m) in webrtc {
            let mut rx = m.received.clone();
            rx.sort_by(f64::total_cmp);
            let mut dp = m.displayed.clone();
            dp.sort_by(f64::total_cmp);
            println!(
                "| {name} | {:.1} / {:.1} ({}) | {:.1} / {:.1} ({}) | {} |",
                pct(&rx, 0.5),
                pct(&rx, 0.95),
                rx.len(),
                pct(&dp, 0.5),
                pct(&dp, 0.95),
                dp.len(),
                m.video_frames
                    .map_or("—".into(), |[d, x, n]| format!("{d} / {x} ({n})")),
            );
        }
    }
    let costs: Vec<_> = rows
        .iter()
        .filter_map(|r| Some((r.name, r.outcome.as_ref().ok()?)))
        .filter(|(_, m)| m.draw_ms.is_some() || m.animation_frame_ms.is_some())
        .collect();
    if !costs.is_empty() {
        println!();
        println!("The operator page's own cost per frame (p50 / p95 ms, count):");
        println!(
            "| way to watch | drawImage of a picture on its canvas | an animation frame (HUD, gamepad, view) |"
        );
        println!("|---|---|---|");
        let cell = |c: Option<[f64; 3]>| {
            c.map_or("—".into(), |[p50, p95, n]| {
                format!("{p50:.2} / {p95:.2} ({n})")
            })
        };
        for (name, m) in costs {
            println!(
                "| {name} | {} | {} |",
                cell(m.draw_ms),
                cell(m.animation_frame_ms)
            );
        }
    }
    for r in rows {
        if let Ok(m) = &r.outcome
            && m.seconds.is_finite()
            && (m.seconds - seconds as f64).abs() > 1.0
        {
            println!("({}: measured over {:.1} s)", r.name, m.seconds);
        }
    }
}
