//! H.264 over RTP for ground stations (QGroundControl's "UDP h.264 video
//! stream"): the camera's JPEG frames, encoded by a supervised `ffmpeg`
//! child, sent to each destination (`--video-rtp`, `[camera] rtp`).
//!
//! `auto` follows the address the app publishes in a `watch` (the ground
//! station in control if it is heard on a UDP endpoint, else the first
//! heard there of those that may control — never one that may only watch:
//! see [`GroundStations`]). The encoder runs only while there is a destination:
//! with none, no child runs and the camera is not asked for frames. The
//! stream's current shape is published as [`RtpStream`] for the MAVLink
//! camera component.
//!
//! Two ways to make the stream: the camera's JPEG pictures encoded
//! (`encoder`, the synthetic camera and MJPEG cameras), or, when
//! `[camera.h264] passthrough` names a camera that gives H.264 itself, its
//! stream copied without decoding (`passthrough`, `-c:v copy`). This module
//! must never send to an address nobody configured or heard from, nor panic
//! on what the child does.
//!
//! The WebRTC viewers ([`super::webrtc`]) and the recorder
//! ([`super::record`]) get the same encode: while one of them wants it, or
//! whenever the encoder runs anyway, each one's loopback port is one more
//! destination ([`LoopbackFeed`]). So the encoder runs while a ground
//! station has a destination, a WebRTC viewer watches *or* a recording
//! runs — `--video-rtp off` stops the RTP to ground stations, not WebRTC
//! nor recording — and the RTP stream announced to ground stations never
//! names a loopback one.

pub(super) mod config;
mod encoder;
mod passthrough;
mod stations;

use std::net::IpAddr;

use futures_util::FutureExt;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub use config::{H264Config, H264ConfigError, RtpDest, RtpDestError, check_dests};
pub use encoder::{RTP_PACKET_BYTES, RtpError};
pub use stations::{GroundStations, STATION_TIMEOUT};

use super::Camera;
use super::backoff::Backoff;
use super::config::CameraConfig;
use encoder::{Encode, destinations};
use passthrough::Copy;

/// One more destination on loopback that reads the encoder's packets back
/// in this process (the WebRTC viewers', the recorder's): its port, and
/// whether it wants the encoder to run now.
#[derive(Debug, Clone)]
pub struct LoopbackFeed {
    pub port: u16,
    pub wanted: watch::Receiver<bool>,
}

/// The RTP stream being sent, for the MAVLink camera component
/// (VIDEO_STREAM_INFORMATION).
#[derive(Debug, Clone, PartialEq)]
pub struct RtpStream {
    /// `udp://HOST:PORT` the (first) receiver listens on.
    pub uri: String,
    pub width: u16,
    pub height: u16,
    pub fps: f32,
    pub bitrate_kbps: u32,
}

/// The running RTP sender. Dropping it (or [`shutdown`](RtpVideo::shutdown))
/// kills its child.
#[derive(Debug)]
pub struct RtpVideo {
    stream: watch::Receiver<Option<RtpStream>>,
    pid: watch::Receiver<Option<u32>>,
    task: Option<JoinHandle<()>>,
}

impl RtpVideo {
    /// Starts sending `camera`'s frames to `cfg.rtp`; `auto` destinations
    /// take their address from `station`. Each of `taps` (the WebRTC
    /// viewers', the recorder's) is a destination too whenever the encoder
    /// runs, and the encoder runs while any of them wants it.
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub fn start(
        cfg: &CameraConfig,
        camera: &Camera,
        station: watch::Receiver<Option<IpAddr>>,
        taps: Vec<LoopbackFeed>,
    ) -> RtpVideo {
        let (stream_tx, stream) = watch::channel(None);
        let (pid_tx, pid) = watch::channel(None);
        let off = cfg.rtp.iter().all(|d| *d == RtpDest::Off);
        let task = (!off || !taps.is_empty()).then(|| {
            let sup = Supervisor {
                dests: cfg.rtp.clone(),
                taps: taps.iter().map(|w| w.port).collect(),
                h264: cfg.h264.clone(),
                camera_fps: cfg.fps,
                stall: cfg.stall_timeout(),
                backoff: Backoff::from_config(&cfg.backoff),
                stream: stream_tx,
                pid: pid_tx,
            };
            let wanted = taps.into_iter().map(|w| w.wanted).collect();
            tokio::spawn(sup.run(camera.clone_handle(), Wants { station, wanted }))
        });
        RtpVideo { stream, pid, task }
    }

    /// The stream as it is sent now; `None` while nothing is sent.
    pub fn stream(&self) -> watch::Receiver<Option<RtpStream>> {
        self.stream.clone()
    }

    /// The encoder child's process id while it runs, as it changes.
    pub fn encoder(&self) -> watch::Receiver<Option<u32>> {
        self.pid.clone()
    }

    /// The encoder child's process id while it runs.
    pub fn pid(&self) -> Option<u32> {
        *self.pid.borrow()
    }

    pub async fn shutdown(mut self) {
        if let Some(t) = self.task.take() {
            t.abort();
            let _ = t.await;
        }
    }
}

impl Drop for RtpVideo {
    fn drop(&mut self) {
        if let Some(t) = self.task.take() {
            t.abort();
        }
    }
}

/// What the destinations follow: the ground station's address, and
/// whether a loopback tap (a WebRTC viewer, a recording) wants the stream.
struct Wants {
    station: watch::Receiver<Option<IpAddr>>,
    wanted: Vec<watch::Receiver<bool>>,
}

impl Wants {
    /// The next change of any (pending forever once all are gone).
    async fn changed(&mut self) {
        let Wants { station, wanted } = self;
        let viewers = async {
            if wanted.is_empty() {
                std::future::pending::<()>().await;
            }
            // The first tap that changes; one whose sender is gone waits
            // forever (the others may still change).
            let each = wanted.iter_mut().map(|w| {
                Box::pin(async move {
                    if w.changed().await.is_err() {
                        std::future::pending::<()>().await;
                    }
                })
            });
            futures_util::future::select_all(each).await;
        };
        let moved = async {
            if station.changed().await.is_err() {
                std::future::pending::<()>().await;
            }
        };
        tokio::select! {
            () = moved => {}
            () = viewers => {}
        }
    }
}

/// Where one run sends: the ground stations' destinations (announced)
/// and the loopback taps (the WebRTC viewers', the recorder's).
#[derive(Debug, Clone, PartialEq)]
struct Dests {
    stations: Vec<(String, u16)>,
    taps: Vec<(String, u16)>,
}

impl Dests {
    fn all(&self) -> Vec<(String, u16)> {
        self.stations.iter().chain(&self.taps).cloned().collect()
    }
}

struct Supervisor {
    dests: Vec<RtpDest>,
    /// The loopback taps' ports (the WebRTC side's, the recorder's).
    taps: Vec<u16>,
    h264: H264Config,
    camera_fps: f64,
    stall: std::time::Duration,
    backoff: Backoff,
    stream: watch::Sender<Option<RtpStream>>,
    pid: watch::Sender<Option<u32>>,
}

impl Supervisor {
    /// The destinations now: the ground stations', and every loopback tap
    /// while any tap wants the stream or the encoder runs anyway (so a
    /// viewer or a recording coming or going never restarts another's
    /// stream).
    fn current(&self, wants: &Wants) -> Dests {
        let auto = *wants.station.borrow();
        let stations = destinations(&self.dests, auto, self.h264.auto_port);
        let wanted = wants.wanted.iter().any(|w| *w.borrow());
        let taps = if wanted || !stations.is_empty() {
            self.taps
                .iter()
                .map(|port| ("127.0.0.1".to_owned(), *port))
                .collect()
        } else {
            Vec::new()
        };
        Dests { stations, taps }
    }

    /// One run encoding the camera's pictures.
    async fn encode(&self, camera: &super::CameraHandle, dests: &Dests) -> RtpError {
        let enc = Encode::new(&self.h264, self.camera_fps, dests.all());
        tracing::info!(to = ?dests.stations, taps = dests.taps.len(), fps = enc.fps, "RTP video: starting the H.264 encoder");
        // Frames are wanted while the encoder runs.
        let _demand = camera.demand();
        let mut frames = camera.subscribe();
        encoder::run(&self.h264.program, &enc, &mut frames, |p, (w, h)| {
            self.announce(p, &dests.stations, (w, h), enc.fps);
        })
        .await
    }

    /// One run copying the H.264 the camera gives: the camera's pictures
    /// are not asked for.
    async fn copy(&self, dests: &Dests) -> RtpError {
        let copy = Copy {
            input: self.h264.passthrough.clone(),
            dests: dests.all(),
            stall: self.stall,
        };
        tracing::info!(to = ?dests.stations, taps = dests.taps.len(), "RTP video: passing the camera's H.264 through");
        let (w, h, fps) = self.h264.passthrough_shape();
        passthrough::run(&self.h264.program, &copy, |p| {
            self.announce(p, &dests.stations, (w, h), fps);
        })
        .await
    }

    /// The stream runs: say so to the camera component, naming the first
    /// ground station's destination (none: only WebRTC viewers watch, and
    /// no RTP stream is announced).
    fn announce(&self, pid: Option<u32>, stations: &[(String, u16)], (w, h): (u32, u32), fps: f64) {
        self.pid.send_replace(pid);
        let Some((host, port)) = stations.first() else {
            self.stream.send_replace(None);
            return;
        };
        let uri = RtpDest::udp_uri(host, *port);
        self.stream.send_replace(Some(RtpStream {
            uri,
            width: u16::try_from(w).unwrap_or(u16::MAX),
            height: u16::try_from(h).unwrap_or(u16::MAX),
            fps: fps as f32,
            bitrate_kbps: self.h264.bitrate_kbps,
        }));
    }

    async fn run(mut self, camera: super::CameraHandle, mut wants: Wants) {
        let mut logged_not_found = false;
        loop {
            let dests = self.current(&wants);
            if dests.stations.is_empty() && dests.taps.is_empty() {
                self.stream.send_replace(None);
                self.pid.send_replace(None);
                tracing::info!("RTP video: no destination, not sending");
                wants.changed().await;
                continue;
            }
            let started = Instant::now();
            let run = if self.h264.passthrough.is_empty() {
                self.encode(&camera, &dests).boxed()
            } else {
                self.copy(&dests).boxed()
            };
            let this = &self;
            let wants = &mut wants;
            let moved = async {
                loop {
                    wants.changed().await;
                    if this.current(wants) != dests {
                        return;
                    }
                }
            };
            let err = tokio::select! {
                e = run => e,
                () = moved => {
                    tracing::info!("RTP video: the destination changed");
                    continue;
                }
            };
            self.stream.send_replace(None);
            self.pid.send_replace(None);
            let wait = self.backoff.after_run(started.elapsed());
            match err {
                RtpError::CameraGone => return,
                RtpError::NotFound(_) if logged_not_found => tracing::debug!("{err}"),
                RtpError::NotFound(_) => {
                    logged_not_found = true;
                    tracing::error!("{err}");
                }
                _ => tracing::warn!("{err} (in {:.1} s)", wait.as_secs_f64()),
            }
            tokio::time::sleep(wait).await;
        }
    }
}
