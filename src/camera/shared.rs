//! The camera's state as the source task, the routes and
//! [`Camera`](super::Camera) share it: [`CameraState`], the counters behind
//! [`CameraStatus`], and the lock around them.
//!
//! The lock is held only to copy or bump a few fields, never across an
//! `.await`.

use std::sync::{Arc, Mutex, MutexGuard};

use serde::Serialize;
use tokio::sync::{broadcast, watch};
use tokio::time::Instant;

use super::config::{CameraConfig, SourceKind};
use super::h264::AccessUnit;
use super::meter::FpsMeter;
use super::plan::VideoPlan;

/// Pictures the H.264 bus holds for a reader that fell behind; a reader
/// further behind skips to the next keyframe.
const UNITS_BACKLOG: usize = 64;

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
    /// Started on demand and nobody wants frames now (no `/video.mjpg`
    /// viewer, no RTP destination): the source is not running.
    Idle,
}

/// `GET /camera/status`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraStatus {
    pub source: SourceKind,
    pub state: CameraState,
    /// Frames per second measured over the last [`FPS_WINDOW`](super::meter::FPS_WINDOW).
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
    /// The camera's own H.264, when it gives it: its profile and
    /// `profile-level-id` from its SPS (`constrained baseline 42c01e`).
    pub h264_profile: Option<String>,
}

/// What the source task, the routes and [`Camera`](super::Camera) share: counters and the
/// state, behind a lock held only to copy a few fields.
#[derive(Debug)]
pub(crate) struct Shared {
    source: SourceKind,
    rotation_deg: u16,
    inner: Mutex<Inner>,
    /// How many want frames now: open `/video.mjpg` streams and
    /// [`DemandGuard`]s (an RTP stream with a destination).
    demand: watch::Sender<usize>,
    /// The paths chosen ([`super::plan`]): set at the start, and again
    /// each time the camera is asked what it offers.
    plan: watch::Sender<VideoPlan>,
    /// The camera's own H.264 pictures, for RTP and WebRTC.
    units: broadcast::Sender<Arc<AccessUnit>>,
    /// The 90 kHz media clock's zero.
    pub(crate) epoch: Instant,
}

/// Wants the camera's frames for as long as it lives (see
/// [`Camera::demand`](super::Camera::demand)).
#[derive(Debug)]
pub struct DemandGuard(watch::Sender<usize>);

impl DemandGuard {
    pub(crate) fn new(shared: &Shared) -> Self {
        shared.demand.send_modify(|n| *n += 1);
        DemandGuard(shared.demand.clone())
    }
}

impl Drop for DemandGuard {
    fn drop(&mut self) {
        self.0.send_modify(|n| *n = n.saturating_sub(1));
    }
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
    pub h264_profile: Option<String>,
}

impl Shared {
    pub(super) fn new(cfg: &CameraConfig, plan: VideoPlan) -> Self {
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
                h264_profile: None,
            }),
            demand: watch::Sender::new(0),
            plan: watch::Sender::new(plan),
            units: broadcast::Sender::new(UNITS_BACKLOG),
            epoch: Instant::now(),
        }
    }

    pub(crate) fn plan(&self) -> watch::Receiver<VideoPlan> {
        self.plan.subscribe()
    }

    /// A new choice: logged when it differs from the last.
    pub(crate) fn set_plan(&self, plan: &VideoPlan) {
        let changed = self.plan.send_if_modified(|p| {
            if p == plan {
                false
            } else {
                *p = plan.clone();
                true
            }
        });
        if changed {
            tracing::info!("{plan}");
        }
    }

    pub(crate) fn units(&self) -> broadcast::Receiver<Arc<AccessUnit>> {
        self.units.subscribe()
    }

    pub(crate) fn send_unit(&self, unit: Arc<AccessUnit>) {
        // Nobody listening is fine: the picture is counted all the same.
        let _ = self.units.send(unit);
    }

    /// How many want frames, as it changes.
    pub(crate) fn demand(&self) -> watch::Receiver<usize> {
        self.demand.subscribe()
    }

    pub(crate) fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic elsewhere while holding the lock leaves plain counters:
        // still worth reporting.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub(crate) fn source(&self) -> SourceKind {
        self.source
    }

    pub(super) fn stopped(&self) {
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
            h264_profile: s.h264_profile.clone(),
        }
    }
}
