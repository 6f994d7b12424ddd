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
//! Where the H.264 comes from is the camera's [`VideoPlan`]
//! ([`super::plan`]), followed as it changes:
//! - the camera's own H.264 (`source = "v4l2"` on a camera that offers
//!   it), or a camera's stream that an ffmpeg child copies without
//!   decoding (`[camera.h264] passthrough`): `relay` packetizes the
//!   pictures as they came and hands them to the WebRTC hub directly —
//!   no process decodes or encodes anything;
//! - the camera's JPEG pictures encoded by ffmpeg's libx264 (`encoder`),
//!   only where `[camera] encode` allows it;
//! - none: nothing runs, and the plan says why.
//!
//! This module must never send to an address nobody configured or heard
//! from, nor panic on what the child does.
//!
//! The WebRTC viewers ([`super::webrtc`]) get the same pictures: while one
//! watches, or whenever the stream runs anyway, they are one more
//! destination (for the encoder, the loopback port the WebRTC side reads).
//! So the stream runs while a ground station has a destination *or* a
//! WebRTC viewer watches — `--video-rtp off` stops the RTP to ground
//! stations, not WebRTC — and the RTP stream announced to ground stations
//! never names the loopback one.

pub(super) mod config;
mod encoder;
mod passthrough;
mod relay;
mod stations;

use std::net::IpAddr;

use futures_util::FutureExt;
use serde::Serialize;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub use config::{H264Config, H264ConfigError, RtpDest, RtpDestError, check_dests};
pub use encoder::{RTP_PACKET_BYTES, RtpError};
pub use stations::{GroundStations, STATION_TIMEOUT};

use super::Camera;
use super::backoff::Backoff;
use super::config::CameraConfig;
use super::h264::AccessUnit;
use super::plan::{H264Route, VideoPlan};
use super::webrtc::WebRtcFeed;
use encoder::{Encode, destinations};
use passthrough::Copy;
use relay::Relay;

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

/// What the sender runs now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Running {
    /// Where its pictures come from: `camera` and `ffmpeg-copy` encode
    /// nothing, `encoder` is libx264.
    pub route: H264Route,
    /// Its child's process id: the encoder, or the ffmpeg that copies; none
    /// for the camera's own H.264.
    pub pid: Option<u32>,
}

/// The running RTP sender. Dropping it (or [`shutdown`](RtpVideo::shutdown))
/// kills its child.
#[derive(Debug)]
pub struct RtpVideo {
    stream: watch::Receiver<Option<RtpStream>>,
    running: watch::Receiver<Option<Running>>,
    task: Option<JoinHandle<()>>,
}

impl RtpVideo {
    /// Starts sending `camera`'s frames to `cfg.rtp`; `auto` destinations
    /// take their address from `station`. With `webrtc`, its loopback port
    /// is a destination too whenever the encoder runs, and the encoder
    /// runs while a WebRTC viewer wants it.
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub fn start(
        cfg: &CameraConfig,
        camera: &Camera,
        station: watch::Receiver<Option<IpAddr>>,
        webrtc: Option<WebRtcFeed>,
    ) -> RtpVideo {
        let (stream_tx, stream) = watch::channel(None);
        let (running_tx, running) = watch::channel(None);
        let off = cfg.rtp.iter().all(|d| *d == RtpDest::Off);
        let task = (!off || webrtc.is_some()).then(|| {
            let sup = Supervisor {
                dests: cfg.rtp.clone(),
                webrtc: webrtc.as_ref().map(|w| w.port),
                webrtc_units: webrtc.as_ref().map(|w| w.units.clone()),
                h264: cfg.h264.clone(),
                camera_fps: cfg.fps,
                stall: cfg.stall_timeout(),
                backoff: Backoff::from_config(&cfg.backoff),
                stream: stream_tx,
                running: running_tx,
                epoch: Instant::now(),
            };
            let wanted = webrtc.map(|w| w.wanted);
            let handle = camera.clone_handle();
            let plan = handle.plan();
            tokio::spawn(sup.run(
                handle,
                Wants {
                    station,
                    wanted,
                    plan,
                },
            ))
        });
        RtpVideo {
            stream,
            running,
            task,
        }
    }

    /// The stream as it is sent now; `None` while nothing is sent.
    pub fn stream(&self) -> watch::Receiver<Option<RtpStream>> {
        self.stream.clone()
    }

    /// The child's process id while one runs (the encoder, or the
    /// ffmpeg that copies a camera's stream).
    pub fn pid(&self) -> Option<u32> {
        self.running.borrow().and_then(|r| r.pid)
    }

    /// What runs now, as it changes; `None` while nothing is sent.
    pub fn running(&self) -> watch::Receiver<Option<Running>> {
        self.running.clone()
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

/// What the destinations follow: the ground station's address, whether
/// a WebRTC viewer wants the stream, and where the H.264 comes from.
struct Wants {
    station: watch::Receiver<Option<IpAddr>>,
    wanted: Option<watch::Receiver<bool>>,
    plan: watch::Receiver<VideoPlan>,
}

impl Wants {
    /// The next change of any (pending forever once all are gone).
    async fn changed(&mut self) {
        let Wants {
            station,
            wanted,
            plan,
        } = self;
        let replanned = async {
            if plan.changed().await.is_err() {
                std::future::pending::<()>().await;
            }
        };
        let viewers = async {
            if let Some(w) = wanted.as_mut()
                && w.changed().await.is_ok()
            {
                return;
            }
            std::future::pending::<()>().await;
        };
        let moved = async {
            if station.changed().await.is_err() {
                std::future::pending::<()>().await;
            }
        };
        tokio::select! {
            () = moved => {}
            () = viewers => {}
            () = replanned => {}
        }
    }
}

/// Where one run sends: the ground stations' destinations (announced)
/// and, for the WebRTC viewers, the loopback port.
#[derive(Debug, Clone, PartialEq)]
struct Dests {
    stations: Vec<(String, u16)>,
    webrtc: Option<(String, u16)>,
    /// Where the pictures come from (`pending` is read as the camera's).
    route: H264Route,
}

impl Dests {
    fn all(&self) -> Vec<(String, u16)> {
        self.stations
            .iter()
            .cloned()
            .chain(self.webrtc.clone())
            .collect()
    }
}

struct Supervisor {
    dests: Vec<RtpDest>,
    /// The WebRTC side's loopback port (for the encoder's RTP).
    webrtc: Option<u16>,
    /// The WebRTC hub's input for pictures that need no depacketizing.
    webrtc_units: Option<mpsc::Sender<AccessUnit>>,
    h264: H264Config,
    camera_fps: f64,
    stall: std::time::Duration,
    backoff: Backoff,
    stream: watch::Sender<Option<RtpStream>>,
    running: watch::Sender<Option<Running>>,
    /// The media clock's zero for pictures ffmpeg copies.
    epoch: Instant,
}

impl Supervisor {
    /// The destinations now: the ground stations', and the WebRTC
    /// loopback while a viewer wants it or the encoder runs anyway (so a
    /// viewer coming or going never restarts a ground station's stream).
    fn current(&self, wants: &Wants) -> Dests {
        let auto = *wants.station.borrow();
        let stations = destinations(&self.dests, auto, self.h264.auto_port);
        let wanted = wants.wanted.as_ref().is_some_and(|w| *w.borrow());
        let webrtc = self
            .webrtc
            .filter(|_| wanted || !stations.is_empty())
            .map(|port| ("127.0.0.1".to_owned(), port));
        let route = wants.plan.borrow().h264;
        Dests {
            stations,
            webrtc,
            route,
        }
    }

    /// One run encoding the camera's pictures.
    async fn encode(&self, camera: &super::CameraHandle, dests: &Dests) -> RtpError {
        let enc = Encode::new(&self.h264, self.camera_fps, dests.all());
        tracing::info!(to = ?dests.stations, webrtc = dests.webrtc.is_some(), fps = enc.fps, "RTP video: starting the H.264 encoder");
        // Frames are wanted while the encoder runs.
        let _demand = camera.demand();
        let mut frames = camera.subscribe();
        encoder::run(&self.h264.program, &enc, &mut frames, |p, (w, h)| {
            self.announce(p, H264Route::Encoder, &dests.stations, (w, h), enc.fps);
        })
        .await
    }

    /// The WebRTC hub's input, while a viewer is among the destinations.
    fn hub(&self, dests: &Dests) -> Option<mpsc::Sender<AccessUnit>> {
        dests.webrtc.as_ref().and(self.webrtc_units.clone())
    }

    /// One run relaying the camera's own H.264: nothing is encoded.
    async fn relay_camera(&self, camera: &super::CameraHandle, dests: &Dests) -> RtpError {
        let mut relay = match Relay::new(&dests.stations, self.hub(dests)).await {
            Ok(r) => r,
            Err(e) => return e,
        };
        tracing::info!(to = ?dests.stations, webrtc = dests.webrtc.is_some(), "RTP video: sending the camera's own H.264 (no encoder)");
        let capture = camera.plan().borrow().capture.clone();
        let (w, h, fps) = capture.map_or((0, 0, 0.0), |c| (c.width, c.height, c.fps()));
        self.running.send_replace(Some(Running {
            route: H264Route::Camera,
            pid: None,
        }));
        relay::from_camera(camera, &mut relay, || {
            self.announce(None, H264Route::Camera, &dests.stations, (w, h), fps);
        })
        .await
    }

    /// One run relaying the H.264 an ffmpeg child copies from a camera
    /// (`[camera.h264] passthrough`): the camera's pictures are not asked
    /// for, nothing is decoded or encoded.
    async fn relay_copy(&self, dests: &Dests) -> RtpError {
        let mut relay = match Relay::new(&dests.stations, self.hub(dests)).await {
            Ok(r) => r,
            Err(e) => return e,
        };
        let copy = Copy {
            input: self.h264.passthrough.clone(),
            stall: self.stall,
        };
        tracing::info!(to = ?dests.stations, webrtc = dests.webrtc.is_some(), "RTP video: passing the camera's H.264 through (ffmpeg -c:v copy)");
        let (w, h, fps) = self.h264.passthrough_shape();
        relay::from_ffmpeg(&self.h264.program, &copy, self.epoch, &mut relay, |p| {
            self.announce(p, H264Route::FfmpegCopy, &dests.stations, (w, h), fps);
        })
        .await
    }

    /// The stream runs: say so to the camera component, naming the first
    /// ground station's destination (none: only WebRTC viewers watch, and
    /// no RTP stream is announced).
    fn announce(
        &self,
        pid: Option<u32>,
        route: H264Route,
        stations: &[(String, u16)],
        (w, h): (u32, u32),
        fps: f64,
    ) {
        self.running.send_replace(Some(Running { route, pid }));
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
            if dests.route == H264Route::None {
                self.stream.send_replace(None);
                self.running.send_replace(None);
                tracing::info!("RTP video: no H.264 to send — {}", wants.plan.borrow().why);
                wants.changed().await;
                continue;
            }
            if dests.stations.is_empty() && dests.webrtc.is_none() {
                self.stream.send_replace(None);
                self.running.send_replace(None);
                tracing::info!("RTP video: no destination, not sending");
                wants.changed().await;
                continue;
            }
            let started = Instant::now();
            let run = match dests.route {
                H264Route::Encoder => self.encode(&camera, &dests).boxed(),
                H264Route::FfmpegCopy => self.relay_copy(&dests).boxed(),
                _ => self.relay_camera(&camera, &dests).boxed(),
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
            self.running.send_replace(None);
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
