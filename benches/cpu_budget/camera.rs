//! The camera paths of the CPU budget, per frame at 640×480: the vehicle
//! (armhf, under qemu's logs) with one camera path and its one consumer,
//! against the board emulator, counting the instructions over a fixed
//! number of frames the consumer received.
//!
//! The paths that exist today:
//! - `mjpeg-page`: an MJPEG camera (the bench serves one, as mjpg-streamer
//!   serves the ROV's) relayed to one `/video.mjpg` viewer — no decode;
//! - `synthetic-page`: the synthetic camera draws and JPEG-encodes each
//!   frame in the vehicle, for one `/video.mjpg` viewer;
//! - `synthetic-rtp`: the synthetic camera into the H.264 encoder (the
//!   vehicle decodes each JPEG and feeds ffmpeg raw pictures) for one RTP
//!   receiver;
//! - `h264-passthrough`: `[camera.h264] passthrough`, ffmpeg copying a
//!   camera's H.264 into RTP, for one RTP receiver.
//!
//! ffmpeg is a child process: here the host's, so the encode (x264) and the
//! copy are not in the count — only what the vehicle itself does per frame.
//! A new path is one more [`Path`] variant: its configuration in
//! [`Path::config`], its consumer in [`Path::consumer`].

use std::io::{Read as _, Write as _};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};

use crate::common::{Gcs, Vehicle};
use crate::trace::Tracer;
use crate::{Arm, Knobs, children, load, share_pct};

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;
/// The camera's rate: frames come as fast as the logged vehicle makes them, up to this.
const FPS: f64 = 10.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Path {
    MjpegPage,
    SyntheticPage,
    SyntheticRtp,
    H264Passthrough,
}

impl Path {
    pub const ALL: [Path; 4] = [
        Path::MjpegPage,
        Path::SyntheticPage,
        Path::SyntheticRtp,
        Path::H264Passthrough,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Path::MjpegPage => "mjpeg-page",
            Path::SyntheticPage => "synthetic-page",
            Path::SyntheticRtp => "synthetic-rtp",
            Path::H264Passthrough => "h264-passthrough",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == s.trim())
    }

    fn describe(self) -> &'static str {
        match self {
            Path::MjpegPage => "MJPEG camera relayed to the page's /video.mjpg (no decode)",
            Path::SyntheticPage => "synthetic camera: draw + JPEG encode, to /video.mjpg",
            Path::SyntheticRtp => {
                "synthetic camera -> JPEG decode -> ffmpeg's H.264 encoder (encode not counted) -> RTP"
            }
            Path::H264Passthrough => {
                "[camera.h264] passthrough: ffmpeg copies the camera's H.264 to RTP (copy not counted)"
            }
        }
    }

    fn rtp(self) -> bool {
        matches!(self, Path::SyntheticRtp | Path::H264Passthrough)
    }

    /// The vehicle's configuration file for this path.
    fn config(
        self,
        arm: &Arm,
        stop: &Arc<AtomicBool>,
        threads: &mut Vec<JoinHandle<()>>,
    ) -> anyhow::Result<String> {
        let size = format!("width = {WIDTH}\nheight = {HEIGHT}\nfps = {FPS}\n");
        Ok(match self {
            Path::MjpegPage => {
                let jpeg = neptunus::camera::SyntheticRenderer::new(WIDTH, HEIGHT, 80)
                    .render_jpeg(&neptunus::camera::Scene::default())?;
                let (cam, t) = load::mjpeg_camera(jpeg, FPS, Arc::clone(stop))?;
                threads.push(t);
                format!("[camera]\nsource = \"url\"\nurl = \"http://{cam}/?action=stream\"\n{size}")
            }
            Path::SyntheticPage | Path::SyntheticRtp => {
                format!("[camera]\nsource = \"synthetic\"\n{size}")
            }
            Path::H264Passthrough => {
                let clip = arm.dir.path().join("camera.mp4");
                if !clip.is_file() {
                    let made = std::process::Command::new("ffmpeg")
                        .args(["-hide_banner", "-loglevel", "error", "-y", "-f", "lavfi"])
                        .arg("-i")
                        .arg(format!("testsrc2=size={WIDTH}x{HEIGHT}:rate={FPS}"))
                        .args([
                            "-t",
                            "30",
                            "-c:v",
                            "libx264",
                            "-preset",
                            "ultrafast",
                            "-g",
                            "10",
                        ])
                        .args(["-pix_fmt", "yuv420p"])
                        .arg(&clip)
                        .status()
                        .context("ffmpeg makes the H.264 clip (apt install ffmpeg)")?;
                    if !made.success() {
                        bail!("ffmpeg could not make the H.264 clip: {made}");
                    }
                }
                format!(
                    "[camera]\nsource = \"synthetic\"\n{size}[camera.h264]\npassthrough = [\"-re\", \"-stream_loop\", \"-1\", \"-i\", {:?}]\n",
                    clip.display().to_string()
                )
            }
        })
    }
}

/// The logged idle run's rates per wall second: what the vehicle does
/// besides the camera, taken off each path's count over the same time.
pub struct Idle {
    pub insns_per_s: f64,
    pub syscalls_per_s: f64,
}

/// One path's figures.
pub struct Frames {
    path: Path,
    frames: u64,
    insns_per_frame: f64,
    syscalls_per_frame: f64,
    seconds_per_frame: f64,
}

/// Counts frames received: `/video.mjpg` (JPEG start markers) or RTP
/// (packets with the marker bit: the last of a frame).
fn consumer(
    path: Path,
    http: SocketAddr,
    rtp: Option<UdpSocket>,
    stop: Arc<AtomicBool>,
    frames: Arc<AtomicU64>,
) -> JoinHandle<()> {
    std::thread::spawn(move || {
        let run = || -> anyhow::Result<()> {
            if let Some(sock) = rtp {
                sock.set_read_timeout(Some(Duration::from_millis(200)))?;
                let mut buf = [0u8; 2048];
                while !stop.load(Ordering::Relaxed) {
                    if let Ok(n) = sock.recv(&mut buf)
                        && n >= 12
                        && buf[1] & 0x80 != 0
                    {
                        frames.fetch_add(1, Ordering::Relaxed);
                    }
                }
                return Ok(());
            }
            let mut s = TcpStream::connect(http)?;
            s.set_read_timeout(Some(Duration::from_millis(200)))?;
            write!(
                s,
                "GET /video.mjpg HTTP/1.1\r\nHost: {http}\r\nAccept: */*\r\n\r\n"
            )?;
            let mut buf = vec![0u8; 64 * 1024];
            let mut tail: Vec<u8> = Vec::new();
            while !stop.load(Ordering::Relaxed) {
                match s.read(&mut buf) {
                    Ok(0) => bail!("the vehicle ended the stream"),
                    Ok(n) => {
                        tail.extend_from_slice(&buf[..n]);
                        let soi = tail.windows(3).filter(|w| *w == [0xff, 0xd8, 0xff]).count();
                        frames.fetch_add(soi as u64, Ordering::Relaxed);
                        let keep = tail.len().saturating_sub(2);
                        tail.drain(..keep);
                    }
                    Err(e)
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                        ) => {}
                    Err(e) => return Err(e.into()),
                }
            }
            Ok(())
        };
        // An error after the stop (the vehicle ending its stream as it
        // exits) is the end of the run, not a failure of the path.
        if let Err(e) = run()
            && !stop.load(Ordering::Relaxed)
        {
            println!("{}: consumer: {e:#}", path.name());
        }
    })
}

/// Waits until `frames` reaches `n` or `limit` passes; false on the limit.
fn wait_frames(
    frames: &AtomicU64,
    n: u64,
    limit: Duration,
    vehicle: &mut Vehicle,
) -> anyhow::Result<bool> {
    let end = Instant::now() + limit;
    while frames.load(Ordering::Relaxed) < n {
        if Instant::now() >= end {
            return Ok(false);
        }
        vehicle.check_running()?;
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(true)
}

/// Runs `path` under qemu's logs for `k.frames` frames.
pub fn measure(path: Path, arm: &Arm, k: &Knobs, idle: &Idle) -> anyhow::Result<Frames> {
    let dir = tempfile::tempdir()?;
    let stop = Arc::new(AtomicBool::new(false));
    let mut threads = Vec::new();
    let result = run(path, arm, k, idle, dir.path(), &stop, &mut threads);
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        let _ = t.join();
    }
    result
}

/// One counted run of `path` (see [`measure`]).
fn run(
    path: Path,
    arm: &Arm,
    k: &Knobs,
    idle: &Idle,
    dir: &std::path::Path,
    stop: &Arc<AtomicBool>,
    threads: &mut Vec<JoinHandle<()>>,
) -> anyhow::Result<Frames> {
    let config = dir.join("neptunus.toml");
    std::fs::write(&config, path.config(arm, stop, threads)?)?;
    let (board, pty) = children::board(&arm.host_bin, dir)?;
    let (_gcs, port) = Gcs::bind()?;
    let rtp = if path.rtp() {
        Some(UdpSocket::bind("127.0.0.1:0")?)
    } else {
        None
    };
    let video_rtp = match &rtp {
        Some(s) => format!("--video-rtp=udp://{}", s.local_addr()?),
        None => "--video-rtp=off".into(),
    };
    let name = format!("camera-{}", path.name());
    let fifo = arm.fifo(&name);
    let tracer = Tracer::start(&fifo)?;
    let launcher = arm.launcher(&name, Some(&fifo))?;
    let args = [
        "--serial".to_owned(),
        pty,
        format!("--mavlink=udpout:127.0.0.1:{port}"),
        format!("--config={}", config.display()),
        video_rtp,
        "--webrtc=off".into(),
    ];
    let argv: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut vehicle = Vehicle::spawn(&launcher, &argv, dir, "")?;
    let http = vehicle
        .http_addr(Duration::from_secs(120))
        .context("the HMI's address")?;
    let frames = Arc::new(AtomicU64::new(0));
    threads.push(consumer(
        path,
        http,
        rtp,
        Arc::clone(stop),
        Arc::clone(&frames),
    ));
    // Frames flowing first (the encoder's start is not a frame's cost).
    if !wait_frames(&frames, 2, Duration::from_secs(300), &mut vehicle)? {
        bail!(
            "{}: no frame within 300 s:\n{}",
            path.name(),
            vehicle.stderr_tail()
        );
    }
    let (c0, f0, t0) = (
        tracer.totals.counts(),
        frames.load(Ordering::Relaxed),
        Instant::now(),
    );
    if !wait_frames(
        &frames,
        f0 + k.frames,
        Duration::from_secs(600),
        &mut vehicle,
    )? {
        bail!("{}: not {} frames within 600 s", path.name(), k.frames);
    }
    let (c1, f1, wall) = (
        tracer.totals.counts(),
        frames.load(Ordering::Relaxed),
        t0.elapsed().as_secs_f64(),
    );
    // The consumer stops before the vehicle ends its stream under it.
    stop.store(true, Ordering::Relaxed);
    drop(vehicle);
    drop(board);
    tracer.finish()?;
    let d = c1 - c0;
    let n = (f1 - f0) as f64;
    Ok(Frames {
        path,
        frames: f1 - f0,
        insns_per_frame: (d.insns as f64 - idle.insns_per_s * wall).max(0.0) / n,
        syscalls_per_frame: (d.syscalls as f64 - idle.syscalls_per_s * wall).max(0.0) / n,
        seconds_per_frame: wall / n,
    })
}

pub fn print(rows: &[Frames], k: &Knobs) {
    println!(
        "\ncamera paths at {WIDTH}×{HEIGHT}, per frame (the idle scenario's instructions and system calls over the same time taken off)"
    );
    println!(
        "{:<17} {:>7} {:>13} {:>10} {:>12} {:>12} {:>11}  path",
        "path", "frames", "Minsns/frame", "sys/frame", "% at 10 fps", "% at 30 fps", "s/frame log"
    );
    for r in rows {
        println!(
            "{:<17} {:>7} {:>13.3} {:>10.1} {:>12.2} {:>12.2} {:>11.2}  {}",
            r.path.name(),
            r.frames,
            r.insns_per_frame / 1e6,
            r.syscalls_per_frame,
            share_pct(r.insns_per_frame * 10.0, k),
            share_pct(r.insns_per_frame * 30.0, k),
            r.seconds_per_frame,
            r.path.describe()
        );
    }
}
