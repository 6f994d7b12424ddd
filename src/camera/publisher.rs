//! The handle a running source publishes through ([`Publisher`]): it
//! sends each frame to the `watch` channel and keeps the shared state and
//! counters current (starting, streaming, failed, restarted).
//!
//! A source gets a `&mut Publisher` and nothing else of the camera; the
//! supervision loop in `source` owns it between runs.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;

use bytes::Bytes;
use tokio::sync::watch;
use tokio::time::Instant;

use super::config::SourceKind;
use super::error::SourceError;
use super::frame::Frame;
use super::h264::{AccessUnit, Unit, profile_level_id, profile_name};
use super::plan::VideoPlan;
use super::shared::{CameraState, Shared};

/// The source task's handle on the shared state and the frame channel.
pub(crate) struct Publisher {
    pub(super) shared: Arc<Shared>,
    tx: watch::Sender<Option<Frame>>,
    seq: u64,
    logged: HashSet<&'static str>,
}

impl Publisher {
    pub fn new(shared: Arc<Shared>, tx: watch::Sender<Option<Frame>>) -> Self {
        Publisher {
            shared,
            tx,
            seq: 0,
            logged: HashSet::new(),
        }
    }

    pub fn kind(&self) -> SourceKind {
        self.shared.source()
    }

    /// Pictures published by this camera so far (JPEG and H.264).
    pub fn frames(&self) -> u64 {
        self.seq
    }

    /// Counts a picture of `width` × `height` that arrived `at`.
    fn count(&mut self, at: Instant, width: u32, height: u32, what: &str) {
        self.seq += 1;
        let mut s = self.shared.lock();
        s.frames_total += 1;
        s.meter.record(at);
        s.latest_at = Some(at);
        s.size = Some((width, height));
        if s.state != CameraState::Streaming {
            s.state = CameraState::Streaming;
            tracing::info!(
                "camera source {}: streaming {what} {width}×{height}",
                self.shared.source()
            );
        }
    }

    /// The paths chosen when the camera was asked what it offers.
    pub fn set_plan(&self, plan: &VideoPlan) {
        self.shared.set_plan(plan);
    }

    /// One picture of the camera's own H.264, to RTP and WebRTC as it is.
    pub fn publish_unit(&mut self, unit: Unit, width: u32, height: u32, sps: Option<&[u8]>) {
        let at = Instant::now();
        self.count(at, width, height, "H.264");
        if let Some(sps) = sps {
            let profile = format!(
                "{} {}",
                profile_name(sps),
                profile_level_id(sps).unwrap_or_default()
            );
            let mut s = self.shared.lock();
            if s.h264_profile.as_deref() != Some(profile.as_str()) {
                tracing::info!("camera: the camera's H.264 is {profile}");
                s.h264_profile = Some(profile);
            }
        }
        let since = at.saturating_duration_since(self.shared.epoch);
        let time_90khz = (since.as_micros() * 9 / 100) as u64;
        self.shared.send_unit(std::sync::Arc::new(AccessUnit {
            data: unit.data,
            time_90khz,
            keyframe: unit.keyframe,
        }));
    }

    pub fn publish(&mut self, jpeg: Bytes, width: u32, height: u32) {
        let at = Instant::now();
        self.count(at, width, height, "JPEG");
        self.tx.send_replace(Some(Frame {
            jpeg,
            at,
            seq: self.seq,
            width,
            height,
        }));
    }

    /// A run started (a child with `pid`, or a connection).
    pub fn starting(&self, pid: Option<u32>) {
        let mut s = self.shared.lock();
        s.state = CameraState::Starting;
        s.pid = pid;
        s.retry_at = None;
    }

    pub(super) fn failed(&mut self, err: &SourceError, retry_in: Duration) {
        let kind = err.kind_name();
        if self.logged.insert(kind) {
            tracing::warn!("{err} (retrying in {:.1} s)", retry_in.as_secs_f64());
        } else {
            tracing::debug!("{err} (retrying in {:.1} s)", retry_in.as_secs_f64());
        }
        let mut s = self.shared.lock();
        s.state = CameraState::Retrying;
        s.last_error = Some(err.to_string());
        s.pid = None;
        s.retry_at = Some(Instant::now() + retry_in);
    }

    pub(super) fn restarted(&self) {
        self.shared.lock().restarts += 1;
    }
}
