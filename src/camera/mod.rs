//! The camera: where video frames come from, and the HTTP routes that serve
//! them to the browser from the HMI's own origin.
//!
//! [`Camera::start`] runs one source, chosen by [`CameraConfig::source`]:
//! - `synthetic`: pictures drawn from the simulator's [`Scene`] (horizon,
//!   heading tape, depth) and encoded as JPEG in-process;
//! - `ffmpeg` / `mjpg-streamer`: a supervised child process, restarted with
//!   exponential backoff when it exits, stalls or cannot be found;
//! - `url`: an MJPEG HTTP stream elsewhere, reconnected with the same
//!   backoff;
//! - `none`: no camera.
//!
//! The latest frame lives in a `watch` channel: every viewer and
//! [`Camera::latest`] see the newest frame, and a slow viewer skips frames
//! instead of queueing them. [`Camera::routes`] serves `GET /video.mjpg`,
//! `GET /snapshot.jpg` and `GET /camera/status`.
//!
//! This module must never block the vehicle's task, panic on what a camera
//! program or a remote server sends, or outlive its [`Camera`]: dropping it
//! stops its task and kills its child process. It never touches the vehicle
//! state: the scene comes in through a `watch` receiver.

mod backoff;
mod client;
mod config;
mod font;
mod http;
mod meter;
mod process;
mod render;
mod source;
pub mod splitter;
mod synthetic;

use std::sync::{Arc, Mutex, MutexGuard};

use bytes::Bytes;
use serde::Serialize;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub use backoff::Backoff;
pub use config::{
    BackoffConfig, CameraConfig, CameraConfigError, FfmpegConfig, MjpgStreamerConfig, SourceKind,
};
pub use meter::FPS_WINDOW;
pub use render::{RenderError, SyntheticRenderer};
pub use source::SourceError;
pub use splitter::{JpegFrame, JpegSplitter, SplitterStats};

use meter::FpsMeter;

/// What the synthetic camera draws: the vehicle's attitude, depth and
/// camera tilt, from the simulator (or the real sensors).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scene {
    pub depth_m: f64,
    pub heading_deg: f64,
    /// Positive: starboard down.
    pub roll_deg: f64,
    /// Positive: nose up.
    pub pitch_deg: f64,
    /// Camera tilt servo, positive up.
    pub tilt_deg: f64,
    /// Draws the `SIM` marker.
    pub simulated: bool,
    pub armed: bool,
}

/// One JPEG picture.
#[derive(Debug, Clone)]
pub struct Frame {
    pub jpeg: Bytes,
    /// When it arrived (tokio's clock, so paused-time tests see it move).
    pub at: Instant,
    /// 1 for the first frame of this camera, counting on across restarts of
    /// its source.
    pub seq: u64,
    pub width: u32,
    pub height: u32,
}

/// What the camera is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraState {
    /// `source = "none"`.
    Off,
    /// Started (or restarted); no frame yet from this run.
    Starting,
    /// Frames are arriving.
    Streaming,
    /// The source failed; waiting out the backoff before starting it again.
    Retrying,
    /// The configuration is invalid: nothing runs (see `last_error`).
    Failed,
    /// The camera was shut down.
    Stopped,
}

/// `GET /camera/status`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraStatus {
    pub source: SourceKind,
    pub state: CameraState,
    /// Frames per second measured over the last [`FPS_WINDOW`].
    pub fps: f64,
    /// Age of the latest frame, `None` before the first.
    pub frame_age_ms: Option<u64>,
    pub frames_total: u64,
    /// Starts of the source after the first (child exits, stalls, failed
    /// spawns, lost connections).
    pub restarts: u64,
    /// The most recent failure, kept after the source recovers.
    pub last_error: Option<String>,
    /// How the page must turn the picture (clockwise), as configured.
    pub rotation_deg: u16,
    /// Size of the latest frame.
    pub width: Option<u32>,
    pub height: Option<u32>,
    /// The running child's process id (`ffmpeg`, `mjpg-streamer`).
    pub pid: Option<u32>,
    /// Time left before the next start while `retrying`.
    pub retry_in_ms: Option<u64>,
    /// Open `/video.mjpg` streams.
    pub viewers: u64,
}

/// Frame rate and age for the HMI's telemetry.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CameraTelemetry {
    pub state: CameraState,
    pub fps: f64,
    pub frame_age_ms: Option<u64>,
    pub frames_total: u64,
}

/// A running camera. Dropping it (or [`shutdown`](Camera::shutdown)) stops
/// its task and kills its child process; routes already handed out then
/// end their streams and answer 503.
#[derive(Debug)]
pub struct Camera {
    shared: Arc<Shared>,
    frames: watch::Receiver<Option<Frame>>,
    task: Option<JoinHandle<()>>,
}

impl Camera {
    /// Starts the configured source on the current tokio runtime.
    ///
    /// An invalid configuration does not panic: the camera is then
    /// `failed`, with the reason in [`status`](Camera::status) and the log.
    /// Check it beforehand with [`CameraConfig::validate`] to refuse to start.
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub fn start(cfg: CameraConfig, scene: watch::Receiver<Scene>) -> Camera {
        let shared = Arc::new(Shared::new(&cfg));
        let (tx, frames) = watch::channel(None);
        let task = match cfg.validate() {
            Err(e) => {
                tracing::error!("{e}");
                let mut s = shared.lock();
                s.state = CameraState::Failed;
                s.last_error = Some(e.to_string());
                None
            }
            Ok(()) if cfg.source == SourceKind::None => {
                tracing::info!("camera: none configured (camera.source = \"none\")");
                None
            }
            Ok(()) => {
                let publisher = source::Publisher::new(shared.clone(), tx);
                Some(tokio::spawn(source::run(cfg, scene, publisher)))
            }
        };
        Camera {
            shared,
            frames,
            task,
        }
    }

    pub fn status(&self) -> CameraStatus {
        self.shared.status(Instant::now())
    }

    pub fn telemetry(&self) -> CameraTelemetry {
        let s = self.status();
        CameraTelemetry {
            state: s.state,
            fps: s.fps,
            frame_age_ms: s.frame_age_ms,
            frames_total: s.frames_total,
        }
    }

    /// The newest frame, if any arrived.
    pub fn latest(&self) -> Option<Frame> {
        self.frames.borrow().clone()
    }

    /// Every new frame as it arrives (a `watch`: a slow reader sees the
    /// newest and skips the rest); closed when the camera stops.
    pub fn subscribe(&self) -> watch::Receiver<Option<Frame>> {
        self.frames.clone()
    }

    /// `GET /video.mjpg`, `GET /snapshot.jpg` and `GET /camera/status`, with
    /// their state: merge into the HMI's router.
    pub fn routes(&self) -> axum::Router {
        http::routes(self.shared.clone(), self.frames.clone())
    }

    /// Stops the source and waits until its task ended (its child, if any,
    /// has been sent SIGKILL).
    pub async fn shutdown(mut self) {
        if let Some(task) = self.task.take() {
            task.abort();
            let _ = task.await;
        }
        self.shared.stopped();
    }
}

impl Drop for Camera {
    fn drop(&mut self) {
        if let Some(task) = self.task.take() {
            task.abort();
        }
        self.shared.stopped();
    }
}

/// What the source task, the routes and [`Camera`] share: counters and the
/// state, behind a lock held only to copy a few fields.
#[derive(Debug)]
pub(crate) struct Shared {
    source: SourceKind,
    rotation_deg: u16,
    inner: Mutex<Inner>,
}

#[derive(Debug)]
pub(crate) struct Inner {
    pub state: CameraState,
    pub frames_total: u64,
    pub restarts: u64,
    pub last_error: Option<String>,
    pub pid: Option<u32>,
    pub meter: FpsMeter,
    pub latest_at: Option<Instant>,
    pub size: Option<(u32, u32)>,
    pub retry_at: Option<Instant>,
    pub viewers: u64,
}

impl Shared {
    fn new(cfg: &CameraConfig) -> Self {
        Shared {
            source: cfg.source,
            rotation_deg: cfg.rotation_deg,
            inner: Mutex::new(Inner {
                state: if cfg.source == SourceKind::None {
                    CameraState::Off
                } else {
                    CameraState::Starting
                },
                frames_total: 0,
                restarts: 0,
                last_error: None,
                pid: None,
                meter: FpsMeter::default(),
                latest_at: None,
                size: None,
                retry_at: None,
                viewers: 0,
            }),
        }
    }

    pub(crate) fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic elsewhere while holding the lock leaves plain counters:
        // still worth reporting.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub(crate) fn source(&self) -> SourceKind {
        self.source
    }

    fn stopped(&self) {
        let mut s = self.lock();
        if !matches!(s.state, CameraState::Off | CameraState::Failed) {
            s.state = CameraState::Stopped;
        }
        s.pid = None;
        s.retry_at = None;
    }

    pub(crate) fn status(&self, now: Instant) -> CameraStatus {
        let s = self.lock();
        let ms = |d: std::time::Duration| u64::try_from(d.as_millis()).unwrap_or(u64::MAX);
        CameraStatus {
            source: self.source,
            state: s.state,
            fps: (s.meter.fps(now) * 100.0).round() / 100.0,
            frame_age_ms: s.latest_at.map(|t| ms(now.saturating_duration_since(t))),
            frames_total: s.frames_total,
            restarts: s.restarts,
            last_error: s.last_error.clone(),
            rotation_deg: self.rotation_deg,
            width: s.size.map(|(w, _)| w),
            height: s.size.map(|(_, h)| h),
            pid: s.pid,
            retry_in_ms: match s.state {
                CameraState::Retrying => s.retry_at.map(|t| ms(t.saturating_duration_since(now))),
                _ => None,
            },
            viewers: s.viewers,
        }
    }
}
