//! The camera: where video frames come from, and the HTTP routes that serve
//! them to the browser from the HMI's own origin.
//!
//! [`Camera::start`] runs one source, chosen by [`CameraConfig::source`]:
//! - `synthetic`: pictures drawn from the simulator's [`Scene`] (water,
//!   horizon, light shafts; the instruments too with `synthetic_overlay`,
//!   the capture time as a block code with `synthetic_timecode`) and
//!   encoded as JPEG in-process;
//! - `ffmpeg` / `mjpg-streamer`: a supervised child process, restarted with
//!   exponential backoff when it exits, stalls or cannot be found;
//! - `url`: an MJPEG HTTP stream elsewhere, reconnected with the same
//!   backoff;
//! - `v4l2`: a camera read by Neptunus itself ([`v4l2`]): its own H.264
//!   or JPEG passed through as it comes, the format chosen from what it
//!   offers ([`plan`]);
//! - `none`: no camera.
//!
//! The choice of paths — the camera's H.264 or an encoder for RTP and
//! WebRTC, the camera's JPEG or an encoder for the page — is [`plan`]'s,
//! published as a `watch` of [`VideoPlan`] ([`Camera::plan`]). The camera's
//! own H.264 pictures go out on a broadcast ([`Camera::units`]) that the
//! RTP sender and the WebRTC viewers read; JPEG pictures on the `watch`
//! below.
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
mod encode;
mod error;
mod font;
mod frame;
pub mod h264;
mod http;
mod meter;
pub mod plan;
mod process;
mod publisher;
pub mod record;
mod render;
pub mod rtp;
mod shared;
mod source;
pub mod splitter;
mod synthetic;
pub mod timecode;
pub mod v4l2;
pub mod webrtc;

use std::sync::Arc;

use serde::Serialize;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub use backoff::Backoff;
pub use config::{
    BackoffConfig, CameraConfig, CameraConfigError, FfmpegConfig, MjpgStreamerConfig, SourceKind,
};
pub use error::SourceError;
pub use frame::{Frame, Scene};
pub use meter::FPS_WINDOW;
pub use plan::{Encode, EncodeSetting, H264Route, JpegRoute, VideoPlan};
pub use render::{RenderError, SyntheticRenderer};
pub use shared::{CameraState, CameraStatus, DemandGuard};
pub use splitter::{JpegFrame, JpegSplitter, SplitterStats};

use publisher::Publisher;
use shared::Shared;

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
        Camera::start_with(cfg, scene, false)
    }

    /// Like [`start`](Camera::start), but the source runs only while
    /// someone wants frames: a `/video.mjpg` viewer or a [`DemandGuard`]
    /// from [`demand`](Camera::demand) (the RTP stream holds one while it
    /// has a destination). In between it is `idle`: no picture is drawn,
    /// no camera program runs, and `/snapshot.jpg` has no new frame.
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub fn start_on_demand(cfg: CameraConfig, scene: watch::Receiver<Scene>) -> Camera {
        Camera::start_with(cfg, scene, true)
    }

    /// Like [`start_on_demand`](Camera::start_on_demand), with the paths
    /// already chosen ([`plan::initial`]) by the caller.
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub fn start_on_demand_planned(
        cfg: CameraConfig,
        scene: watch::Receiver<Scene>,
        plan: VideoPlan,
    ) -> Camera {
        Camera::start_with_plan(cfg, scene, true, plan)
    }

    fn start_with(cfg: CameraConfig, scene: watch::Receiver<Scene>, on_demand: bool) -> Camera {
        let plan = plan::initial(&cfg);
        Camera::start_with_plan(cfg, scene, on_demand, plan)
    }

    fn start_with_plan(
        cfg: CameraConfig,
        scene: watch::Receiver<Scene>,
        on_demand: bool,
        plan: VideoPlan,
    ) -> Camera {
        if cfg.validate().is_ok() {
            tracing::info!("{plan}");
        }
        let shared = Arc::new(Shared::new(&cfg, plan));
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
                let mut publisher = Publisher::new(shared.clone(), tx);
                Some(if on_demand {
                    let demand = shared.demand();
                    tokio::spawn(source::run_on_demand(cfg, scene, publisher, demand))
                } else {
                    tokio::spawn(async move { source::run(cfg, scene, &mut publisher).await })
                })
            }
        };
        Camera {
            shared,
            frames,
            task,
        }
    }

    /// How many want frames now (`/video.mjpg` viewers and
    /// [`DemandGuard`]s), as it changes.
    pub fn watched(&self) -> watch::Receiver<usize> {
        self.shared.demand()
    }

    pub fn status(&self) -> CameraStatus {
        self.shared.status(Instant::now())
    }

    /// [`status`](Camera::status) without the camera's lifetime.
    pub fn status_handle(&self) -> impl Fn() -> CameraStatus + Send + Sync + 'static {
        let shared = self.shared.clone();
        move || shared.status(Instant::now())
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

    /// The paths chosen and why, as they change (each start of a `v4l2`
    /// camera asks it again).
    pub fn plan(&self) -> watch::Receiver<VideoPlan> {
        self.shared.plan()
    }

    /// The camera's own H.264 pictures as they come (none unless the
    /// camera gives H.264); a reader that falls behind by more than the
    /// backlog is told how many it missed.
    pub fn units(&self) -> tokio::sync::broadcast::Receiver<Arc<h264::AccessUnit>> {
        self.shared.units()
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

    /// Wants frames until dropped: a camera started on demand runs its
    /// source meanwhile.
    pub fn demand(&self) -> DemandGuard {
        DemandGuard::new(&self.shared)
    }

    /// What the RTP sender needs of the camera: its frames and its demand.
    pub(crate) fn clone_handle(&self) -> CameraHandle {
        CameraHandle {
            shared: self.shared.clone(),
            frames: self.frames.clone(),
        }
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

/// The frames and the demand of a [`Camera`], without its lifetime.
#[derive(Debug, Clone)]
pub(crate) struct CameraHandle {
    shared: Arc<Shared>,
    frames: watch::Receiver<Option<Frame>>,
}

impl CameraHandle {
    pub(crate) fn demand(&self) -> DemandGuard {
        DemandGuard::new(&self.shared)
    }

    pub(crate) fn subscribe(&self) -> watch::Receiver<Option<Frame>> {
        self.frames.clone()
    }

    pub(crate) fn plan(&self) -> watch::Receiver<VideoPlan> {
        self.shared.plan()
    }

    pub(crate) fn units(&self) -> tokio::sync::broadcast::Receiver<Arc<h264::AccessUnit>> {
        self.shared.units()
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

/// The JSON `GET /api/video` adds: `path` (the plan), `mjpeg` (whether
/// `/video.mjpg` has pictures: not while the camera streams H.264),
/// `h264` (what the sender runs now: its route and child, or `null`),
/// `encoder_running` (a libx264 encoder runs now) and `h264_profile` (the
/// camera's own H.264, from its SPS).
pub fn api_json(
    plan: &VideoPlan,
    running: Option<rtp::Running>,
    h264_profile: Option<String>,
) -> serde_json::Value {
    serde_json::json!({
        "mjpeg": !matches!(plan.jpeg, plan::JpegRoute::None),
        "path": plan,
        "h264": running,
        "encoder_running": running.is_some_and(|r| r.route == plan::H264Route::Encoder && r.pid.is_some()),
        "h264_profile": h264_profile,
    })
}
