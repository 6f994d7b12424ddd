//! The RTP video's cost and delay, printed as a table.
//!
//! 1. **Encode path** at 640×480, 10 and 15 fps: the synthetic camera and
//!    [`RtpVideo`] in this process, sending to a UDP socket on loopback
//!    that this process reads. CPU over `VIDEO_SOAK_S` seconds (default
//!    10): this process (getrusage: the camera's drawing and JPEG encoding,
//!    feeding ffmpeg, receiving) and the ffmpeg child (/proc/PID/stat),
//!    each as a share of one core.
//! 2. **Delay** from a frame leaving the source (its publish time, the
//!    instant a viewer or the encoder can have it) to the last RTP packet
//!    of its picture (one RTP timestamp) arriving on the local socket,
//!    p50/p99.
//!    Pictures are matched to frames as "the newest frame published before
//!    the packet": exact while the delay is under one frame period (100 ms
//!    at 10 fps, 67 ms at 15); the table shows the frames and pictures
//!    counted, which agree when no frame was dropped.
//! 3. **Pass-through** (`[camera.h264] passthrough`): a 640×480 15 fps
//!    H.264 clip read in real time stands for a camera that gives H.264;
//!    CPU of this process and of the ffmpeg child that copies it into RTP,
//!    next to the encode at the same size and rate.
//! 4. **The camera's own H.264** (`source = "v4l2"`): the same clip as an
//!    Annex B stream in a file in the device's place, played at 15 fps:
//!    CPU of this process, which reads, cuts and packetizes it (no child
//!    process runs).
//! 5. **Nobody watching**: the vehicle binary (`$NEPTUNUS_BIN`, else
//!    target/release, else target/debug) with `--sim --video-rtp off`, its
//!    CPU over the soak without a viewer and then with one `/video.mjpg`
//!    viewer reading.
//!
//! Under `cargo test --all-targets` (no `--bench`) a 2 s smoke run. Needs
//! ffmpeg with libx264. Figures are printed, never asserted.

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context as _, bail};
use neptunus::camera::rtp::{RtpDest, RtpVideo};
use neptunus::camera::{Camera, CameraConfig, Scene};
use nix::sys::resource::{UsageWho, getrusage};
use tokio::sync::watch;
use tokio::time::Instant;

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

fn self_cpu_s() -> anyhow::Result<f64> {
    let u = getrusage(UsageWho::RUSAGE_SELF)?;
    let tv = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 * 1e-6;
    Ok(tv(u.user_time()) + tv(u.system_time()))
}

/// CPU seconds of another process (utime + stime, clock ticks of 1/100 s
/// on Linux).
fn proc_cpu_s(pid: u32) -> anyhow::Result<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    let tail = stat.rsplit_once(')').context("stat")?.1;
    let f: Vec<&str> = tail.split_whitespace().collect();
    let ticks: f64 = f[11].parse::<f64>()? + f[12].parse::<f64>()?;
    Ok(ticks / 100.0)
}

fn pct(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

struct Row {
    fps: f64,
    self_pct: f64,
    ffmpeg_pct: f64,
    p50_ms: f64,
    p99_ms: f64,
    frames: usize,
    pictures: usize,
}

async fn encode_path(fps: f64, soak: Duration) -> anyhow::Result<Row> {
    let rx = tokio::net::UdpSocket::bind("127.0.0.1:0").await?;
    let port = rx.local_addr()?.port();
    let cfg = CameraConfig {
        fps,
        rtp: vec![RtpDest::Udp {
            host: "127.0.0.1".into(),
            port,
        }],
        ..CameraConfig::synthetic()
    };
    let (_scene_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start_on_demand(cfg.clone(), scene);
    let (_station_tx, station) = watch::channel(None);
    let rtp = RtpVideo::start(&cfg, &camera, station, Vec::new());
    let mut stream = rtp.stream();
    tokio::time::timeout(Duration::from_secs(20), stream.wait_for(|s| s.is_some()))
        .await
        .context("the RTP stream did not start in 20 s (is ffmpeg with libx264 installed?)")??;
    let pid = rtp.pid().context("no encoder pid")?;
    // Settle, then measure.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let published: Arc<Mutex<Vec<Instant>>> = Arc::default();
    let mut frames = camera.subscribe();
    let log = published.clone();
    let watcher = tokio::spawn(async move {
        while frames.changed().await.is_ok() {
            if let Some(f) = frames.borrow_and_update().as_ref() {
                log.lock().expect("lock").push(f.at);
            }
        }
    });
    // Packets of the settling second are not measured.
    let mut buf = [0u8; 2048];
    while rx.try_recv(&mut buf).is_ok() {}
    let (cpu0, ff0, wall0) = (self_cpu_s()?, proc_cpu_s(pid)?, Instant::now());
    let mut delays = Vec::new();
    let mut pictures = 0;
    // A picture is the packets of one RTP timestamp; it has left when its
    // last packet arrived.
    let mut current: Option<(u32, Instant)> = None;
    let newest_before = |at: Instant| {
        published
            .lock()
            .expect("lock")
            .iter()
            .rev()
            .find(|&&t| t <= at)
            .copied()
    };
    while wall0.elapsed() < soak {
        let Ok(Ok(n)) = tokio::time::timeout(Duration::from_millis(200), rx.recv(&mut buf)).await
        else {
            continue;
        };
        let at = Instant::now();
        if n <= 12 {
            continue;
        }
        let ts = u32::from_be_bytes([buf[4], buf[5], buf[6], buf[7]]);
        if let Some((prev, last)) = current
            && prev != ts
        {
            pictures += 1;
            if let Some(t) = newest_before(last) {
                delays.push((last - t).as_secs_f64() * 1e3);
            }
        }
        current = Some((ts, at));
    }
    let wall = wall0.elapsed().as_secs_f64();
    let (cpu1, ff1) = (self_cpu_s()?, proc_cpu_s(pid)?);
    watcher.abort();
    let frames = published.lock().expect("lock").len();
    rtp.shutdown().await;
    camera.shutdown().await;
    delays.sort_by(f64::total_cmp);
    Ok(Row {
        fps,
        self_pct: (cpu1 - cpu0) / wall * 100.0,
        ffmpeg_pct: (ff1 - ff0) / wall * 100.0,
        p50_ms: pct(&delays, 0.5),
        p99_ms: pct(&delays, 0.99),
        frames,
        pictures,
    })
}

/// CPU of the pass-through path (this process, the ffmpeg child) over
/// `soak`, and the RTP packets received.
async fn passthrough_path(soak: Duration) -> anyhow::Result<(f64, f64, usize)> {
    let dir = tempfile::tempdir()?;
    let clip = dir.path().join("camera.mp4");
    let secs = (soak.as_secs() + 30).to_string();
    let made = std::process::Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-y", "-f", "lavfi"])
        .args(["-i", "testsrc2=size=640x480:rate=15", "-t", &secs])
        .args(["-c:v", "libx264", "-preset", "ultrafast", "-g", "15"])
        .args(["-pix_fmt", "yuv420p", "-b:v", "1000k"])
        .arg(&clip)
        .status()?;
    if !made.success() {
        bail!("ffmpeg could not make the pass-through clip");
    }
    let rx = tokio::net::UdpSocket::bind("127.0.0.1:0").await?;
    let port = rx.local_addr()?.port();
    let mut cfg = CameraConfig {
        rtp: vec![RtpDest::Udp {
            host: "127.0.0.1".into(),
            port,
        }],
        ..CameraConfig::none()
    };
    cfg.h264.passthrough = ["-re", "-i"]
        .map(String::from)
        .into_iter()
        .chain([clip.display().to_string()])
        .collect();
    let (_scene_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start_on_demand(cfg.clone(), scene);
    let (_station_tx, station) = watch::channel(None);
    let rtp = RtpVideo::start(&cfg, &camera, station, Vec::new());
    let mut stream = rtp.stream();
    tokio::time::timeout(Duration::from_secs(20), stream.wait_for(|s| s.is_some()))
        .await
        .context("the pass-through stream did not start in 20 s")??;
    let pid = rtp.pid().context("no pass-through pid")?;
    tokio::time::sleep(Duration::from_secs(1)).await;
    let mut buf = [0u8; 2048];
    while rx.try_recv(&mut buf).is_ok() {}
    let (cpu0, ff0, wall0) = (self_cpu_s()?, proc_cpu_s(pid)?, Instant::now());
    let mut packets = 0;
    while wall0.elapsed() < soak {
        if let Ok(Ok(_)) = tokio::time::timeout(Duration::from_millis(200), rx.recv(&mut buf)).await
        {
            packets += 1;
        }
    }
    let wall = wall0.elapsed().as_secs_f64();
    let (cpu1, ff1) = (self_cpu_s()?, proc_cpu_s(pid)?);
    rtp.shutdown().await;
    camera.shutdown().await;
    Ok((
        (cpu1 - cpu0) / wall * 100.0,
        (ff1 - ff0) / wall * 100.0,
        packets,
    ))
}

/// CPU of the camera's-own-H.264 path (this process only: no child runs)
/// over `soak`, and the RTP packets received.
async fn camera_h264_path(soak: Duration) -> anyhow::Result<(f64, usize)> {
    let dir = tempfile::tempdir()?;
    let clip = dir.path().join("camera.h264");
    let secs = (soak.as_secs() + 30).to_string();
    let made = std::process::Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-y", "-f", "lavfi"])
        .args(["-i", "testsrc2=size=640x480:rate=15", "-t", &secs])
        .args(["-c:v", "libx264", "-preset", "ultrafast", "-g", "15"])
        .args([
            "-profile:v",
            "baseline",
            "-pix_fmt",
            "yuv420p",
            "-b:v",
            "1000k",
        ])
        .args(["-f", "h264"])
        .arg(&clip)
        .status()?;
    if !made.success() {
        bail!("ffmpeg could not make the camera's clip");
    }
    let rx = tokio::net::UdpSocket::bind("127.0.0.1:0").await?;
    let port = rx.local_addr()?.port();
    let mut cfg: CameraConfig = toml::from_str(&format!(
        "source = \"v4l2\"\nfps = 15\n[v4l2]\ndevice = {:?}\nformat = \"h264\"\n",
        clip.display().to_string()
    ))?;
    cfg.rtp = vec![RtpDest::Udp {
        host: "127.0.0.1".into(),
        port,
    }];
    let (_scene_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start_on_demand(cfg.clone(), scene);
    let (_station_tx, station) = watch::channel(None);
    let rtp = RtpVideo::start(&cfg, &camera, station, Vec::new());
    let mut stream = rtp.stream();
    tokio::time::timeout(Duration::from_secs(20), stream.wait_for(|s| s.is_some()))
        .await
        .context("the camera's H.264 did not start in 20 s")??;
    if let Some(pid) = rtp.pid() {
        bail!("a child ({pid}) runs for the camera's own H.264");
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    let mut buf = [0u8; 2048];
    while rx.try_recv(&mut buf).is_ok() {}
    let (cpu0, wall0) = (self_cpu_s()?, Instant::now());
    let mut packets = 0;
    while wall0.elapsed() < soak {
        if let Ok(Ok(_)) = tokio::time::timeout(Duration::from_millis(200), rx.recv(&mut buf)).await
        {
            packets += 1;
        }
    }
    let wall = wall0.elapsed().as_secs_f64();
    let cpu1 = self_cpu_s()?;
    rtp.shutdown().await;
    camera.shutdown().await;
    Ok(((cpu1 - cpu0) / wall * 100.0, packets))
}

/// The vehicle process's CPU share over `soak`, with or without one
/// `/video.mjpg` viewer.
fn vehicle_cpu(soak: Duration) -> anyhow::Result<(f64, f64, String)> {
    let bin = common::neptunus_bin()?;
    let dir = tempfile::tempdir()?;
    let mut v = common::Vehicle::spawn(&bin, &["--sim", "--video-rtp", "off"], dir.path(), "")?;
    let addr = v.http_addr(Duration::from_secs(30))?;
    std::thread::sleep(Duration::from_secs(2));
    let measure = |v: &common::Vehicle| -> anyhow::Result<f64> {
        let c0 = proc_cpu_s(v.pid())?;
        let t0 = std::time::Instant::now();
        std::thread::sleep(soak);
        Ok((proc_cpu_s(v.pid())? - c0) / t0.elapsed().as_secs_f64() * 100.0)
    };
    let idle = measure(&v)?;
    let mut viewer = TcpStream::connect(addr)?;
    write!(
        viewer,
        "GET /video.mjpg HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )?;
    let reader = std::thread::spawn(move || {
        let mut buf = [0u8; 65536];
        let mut total = 0usize;
        while let Ok(n) = viewer.read(&mut buf) {
            if n == 0 {
                break;
            }
            total += n;
        }
        total
    });
    std::thread::sleep(Duration::from_secs(1));
    let watched = measure(&v)?;
    v.check_running()?;
    drop(v);
    let bytes = reader.join().unwrap_or(0);
    if bytes == 0 {
        bail!("the viewer got no video");
    }
    Ok((idle, watched, bin.display().to_string()))
}

fn main() -> anyhow::Result<()> {
    let full = std::env::args().any(|a| a == "--bench");
    let soak = Duration::from_secs(knob("VIDEO_SOAK_S", 10, 2, full)?);
    if !full {
        println!("smoke run (cargo bench runs the full one)");
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    println!(
        "| 640×480 | this process CPU | ffmpeg CPU | frame → last RTP packet p50 | p99 | frames / pictures |"
    );
    println!("|---|---|---|---|---|---|");
    for fps in [10.0, 15.0] {
        let r = rt.block_on(encode_path(fps, soak))?;
        println!(
            "| {:.0} fps | {:.1} % | {:.1} % | {:.1} ms | {:.1} ms | {} / {} |",
            r.fps, r.self_pct, r.ffmpeg_pct, r.p50_ms, r.p99_ms, r.frames, r.pictures
        );
    }
    let (own, ff, packets) = rt.block_on(passthrough_path(soak))?;
    println!(
        "| 15 fps pass-through (`-c:v copy`) | {own:.1} % | {ff:.1} % | — | — | {packets} RTP packets |"
    );
    let (own, packets) = rt.block_on(camera_h264_path(soak))?;
    println!(
        "| 15 fps the camera's own H.264 (`v4l2`, no child) | {own:.1} % | — | — | — | {packets} RTP packets |"
    );
    let (idle, watched, bin) = vehicle_cpu(soak)?;
    println!();
    println!("vehicle process `--sim --video-rtp off` ({bin}), CPU of one core:");
    println!("| nobody watching | one /video.mjpg viewer |");
    println!("|---|---|");
    println!("| {idle:.1} % | {watched:.1} % |");
    Ok(())
}
