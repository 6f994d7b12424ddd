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
//!   pictures as they came — no process decodes or encodes anything;
//! - the camera's JPEG pictures encoded by ffmpeg's libx264 (`encoder`),
//!   only where `[camera] encode` allows it;
//! - none: nothing runs, and the plan says why.
//!
//! Whatever the route, the pictures become one stream of access units that
//! fans out (`fanout`) to every consumer in the vehicle ([`VideoTap`]: the
//! WebRTC viewers' hub, [`super::webrtc`], and the recorder,
//! [`super::record`]): a relay hands over the pictures it cut; the encoder
//! sends one more copy of its RTP to a loopback port of this module, put
//! back together into pictures once (`h264::depay`). The consumers get the
//! stream while one of them wants it or whenever it runs anyway. So the
//! stream runs while a ground station has a destination, a WebRTC viewer
//! watches *or* a recording runs — `--video-rtp off` stops the RTP to
//! ground stations, not WebRTC nor recording — and the RTP stream
//! announced to ground stations never names the loopback one.

pub(super) mod config;
mod encoder;
mod fanout;
mod passthrough;
mod relay;
mod stations;

use std::net::{IpAddr, Ipv4Addr};
use std::sync::Mutex;

use futures_util::FutureExt;
use serde::Serialize;
use tokio::net::UdpSocket;
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
use super::h264::depay::Depay;
use super::plan::{H264Route, VideoPlan};
use encoder::{Encode, destinations};
use fanout::Fanout;
use passthrough::Copy;
use relay::Relay;

/// A consumer of the one H.264 stream in the vehicle (the WebRTC viewers'
/// hub, the recorder): whether it wants the stream to run now, and its
/// queue for the pictures (a full queue skips it to the next keyframe).
#[derive(Debug, Clone)]
pub struct VideoTap {
    pub wanted: watch::Receiver<bool>,
    pub units: mpsc::Sender<AccessUnit>,
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
    /// take their address from `station`. Each of `taps` (the WebRTC
    /// viewers', the recorder's) gets the pictures whenever the stream
    /// runs, and the stream runs while any of them wants it.
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub fn start(
        cfg: &CameraConfig,
        camera: &Camera,
        station: watch::Receiver<Option<IpAddr>>,
        taps: Vec<VideoTap>,
    ) -> RtpVideo {
        let (stream_tx, stream) = watch::channel(None);
        let (running_tx, running) = watch::channel(None);
        let off = cfg.rtp.iter().all(|d| *d == RtpDest::Off);
        let task = (!off || !taps.is_empty()).then(|| {
            let sup = Supervisor {
                dests: cfg.rtp.clone(),
                taps: taps.iter().map(|w| w.units.clone()).collect(),
                readback: None,
                depay: Mutex::new(Depay::new()),
                h264: cfg.h264.clone(),
                camera_fps: cfg.fps,
                stall: cfg.stall_timeout(),
                backoff: Backoff::from_config(&cfg.backoff),
                stream: stream_tx,
                running: running_tx,
                epoch: Instant::now(),
            };
            let wanted = taps.into_iter().map(|w| w.wanted).collect();
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
/// a consumer (a WebRTC viewer, a recording) wants the stream, and
/// where the H.264 comes from.
struct Wants {
    station: watch::Receiver<Option<IpAddr>>,
    wanted: Vec<watch::Receiver<bool>>,
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
            () = replanned => {}
        }
    }
}

/// Where one run sends: the ground stations' destinations (announced)
/// and whether the consumers in the vehicle (the WebRTC viewers, the
/// recorder) get the pictures.
#[derive(Debug, Clone, PartialEq)]
struct Dests {
    stations: Vec<(String, u16)>,
    taps: bool,
    /// Where the pictures come from (`pending` is read as the camera's).
    route: H264Route,
}

struct Supervisor {
    dests: Vec<RtpDest>,
    /// The consumers' queues (the WebRTC hub's, the recorder's).
    taps: Vec<mpsc::Sender<AccessUnit>>,
    /// Where the encoder's RTP comes back on loopback for the consumers
    /// (bound when there are any).
    readback: Option<UdpSocket>,
    /// Puts the encoder's RTP back into pictures, once for all consumers;
    /// kept across runs so the media clock never goes back.
    depay: Mutex<Depay>,
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
    /// The destinations now: the ground stations', and the consumers
    /// while any of them wants the stream or it runs anyway (so a viewer
    /// or a recording coming or going never restarts another's stream).
    fn current(&self, wants: &Wants) -> Dests {
        let auto = *wants.station.borrow();
        let stations = destinations(&self.dests, auto, self.h264.auto_port);
        let wanted = wants.wanted.iter().any(|w| *w.borrow());
        let taps = !self.taps.is_empty() && (wanted || !stations.is_empty());
        let route = wants.plan.borrow().h264;
        Dests {
            stations,
            taps,
            route,
        }
    }

    /// One run encoding the camera's pictures: its RTP goes to the ground
    /// stations and, for the consumers, to the loopback port read back
    /// here.
    async fn encode(&self, camera: &super::CameraHandle, dests: &Dests) -> RtpError {
        let readback = self.readback.as_ref().filter(|_| dests.taps);
        let mut to = dests.stations.clone();
        if let Some(addr) = readback.and_then(|s| s.local_addr().ok()) {
            to.push((addr.ip().to_string(), addr.port()));
        }
        let enc = Encode::new(&self.h264, self.camera_fps, to);
        tracing::info!(to = ?dests.stations, taps = dests.taps, fps = enc.fps, "RTP video: starting the H.264 encoder");
        // Frames are wanted while the encoder runs.
        let _demand = camera.demand();
        let mut frames = camera.subscribe();
        let run = encoder::run(&self.h264.program, &enc, &mut frames, |p, (w, h)| {
            self.announce(p, H264Route::Encoder, &dests.stations, (w, h), enc.fps);
        });
        let Some(socket) = readback else {
            return run.await;
        };
        let mut fanout = self.fanout(dests);
        tokio::select! {
            e = run => e,
            never = self.read_back(socket, &mut fanout) => match never {},
        }
    }

    /// The encoder's RTP on loopback, put back into pictures (once) and
    /// handed to every consumer; never returns.
    async fn read_back(&self, socket: &UdpSocket, fanout: &mut Fanout) -> std::convert::Infallible {
        let mut buf = vec![0u8; 2048];
        loop {
            let (n, from) = match socket.recv_from(&mut buf).await {
                Ok(got) => got,
                Err(e) => {
                    // Not expected on a bound UDP socket; never spin on it.
                    tracing::debug!("RTP video: loopback read failed: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                    continue;
                }
            };
            // Only the encoder on this machine may feed the consumers.
            if !from.ip().is_loopback() {
                continue;
            }
            let units = match self.depay.lock() {
                Ok(mut d) => d.push(&buf[..n]),
                Err(_) => Vec::new(),
            };
            for au in &units {
                fanout.send(au);
            }
        }
    }

    /// The consumers' fan-out for one run: empty while they do not get
    /// the stream.
    fn fanout(&self, dests: &Dests) -> Fanout {
        Fanout::new(if dests.taps { &self.taps } else { &[] })
    }

    /// One run relaying the camera's own H.264: nothing is encoded.
    async fn relay_camera(&self, camera: &super::CameraHandle, dests: &Dests) -> RtpError {
        let mut relay = match Relay::new(&dests.stations, self.fanout(dests)).await {
            Ok(r) => r,
            Err(e) => return e,
        };
        tracing::info!(to = ?dests.stations, taps = dests.taps, "RTP video: sending the camera's own H.264 (no encoder)");
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
        let mut relay = match Relay::new(&dests.stations, self.fanout(dests)).await {
            Ok(r) => r,
            Err(e) => return e,
        };
        let copy = Copy {
            input: self.h264.passthrough.clone(),
            stall: self.stall,
        };
        tracing::info!(to = ?dests.stations, taps = dests.taps, "RTP video: passing the camera's H.264 through (ffmpeg -c:v copy)");
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
        if !self.taps.is_empty() {
            match UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).await {
                Ok(s) => self.readback = Some(s),
                Err(e) => tracing::error!(
                    "RTP video: cannot bind a loopback port to read the encoder back ({e}): the WebRTC viewers and recordings get no encoded pictures"
                ),
            }
        }
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
            if dests.stations.is_empty() && !dests.taps {
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
