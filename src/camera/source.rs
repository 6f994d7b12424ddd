//! Running the configured source: the supervision loop with its backoff,
//! what a run's failure says to the user, and publishing frames.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;

use bytes::Bytes;
use tokio::sync::watch;
use tokio::time::Instant;

use super::backoff::Backoff;
use super::config::{CameraConfig, SourceKind, StreamUrl};
use super::{CameraState, Frame, Scene, Shared, client, process, synthetic};

/// Why a run of a source ended. Each message names the source, the thing
/// that failed and what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error(
        "camera source {kind}: program `{program}` not found{on_path} — {install} or set camera.source = \"synthetic\""
    )]
    ProgramNotFound {
        kind: SourceKind,
        program: String,
        /// " on PATH" when the program was given by name.
        on_path: &'static str,
        install: &'static str,
    },
    #[error(
        "camera source {kind}: cannot start `{program}`: {error} — check that it is an executable program (camera.{key}.program)"
    )]
    Spawn {
        kind: SourceKind,
        program: String,
        key: &'static str,
        error: std::io::Error,
    },
    #[error("camera source {kind}: `{program}` exited ({status}){stderr} — {hint}")]
    Exited {
        kind: SourceKind,
        program: String,
        status: String,
        /// ": " and its last lines on stderr, when it printed any.
        stderr: String,
        hint: &'static str,
    },
    #[error(
        "camera source {kind}: no frame for {secs:.1} s from {what} — restarting it (camera.stall_timeout_s)"
    )]
    Stalled {
        kind: SourceKind,
        what: String,
        secs: f64,
    },
    #[error(
        "camera source {kind}: cannot connect to {url}: {error} — check camera.url and that the stream is up"
    )]
    Connect {
        kind: SourceKind,
        url: String,
        error: String,
    },
    #[error(
        "camera source {kind}: {url} answered {status} — expected 200 with an MJPEG stream; check camera.url"
    )]
    HttpStatus {
        kind: SourceKind,
        url: String,
        status: String,
    },
    #[error(
        "camera source {kind}: {url} sent Content-Type {content_type:?} — expected multipart/x-mixed-replace (an MJPEG stream); check camera.url"
    )]
    NotMjpeg {
        kind: SourceKind,
        url: String,
        content_type: String,
    },
    #[error("camera source {kind}: the stream from {url} ended{detail} — reconnecting")]
    StreamEnded {
        kind: SourceKind,
        url: String,
        detail: String,
    },
    #[error("camera source {kind}: reading {what} failed: {error}")]
    Read {
        kind: SourceKind,
        what: String,
        error: String,
    },
    #[error(transparent)]
    Render(#[from] super::render::RenderError),
}

impl SourceError {
    /// Logged once per kind (then at debug level) so a camera unplugged for
    /// an hour does not flood the log.
    fn kind_name(&self) -> &'static str {
        match self {
            SourceError::ProgramNotFound { .. } => "not-found",
            SourceError::Spawn { .. } => "spawn",
            SourceError::Exited { .. } => "exited",
            SourceError::Stalled { .. } => "stalled",
            SourceError::Connect { .. } => "connect",
            SourceError::HttpStatus { .. } => "http-status",
            SourceError::NotMjpeg { .. } => "not-mjpeg",
            SourceError::StreamEnded { .. } => "stream-ended",
            SourceError::Read { .. } => "read",
            SourceError::Render(_) => "render",
        }
    }
}

/// The source task's handle on the shared state and the frame channel.
pub(crate) struct Publisher {
    shared: Arc<Shared>,
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

    pub fn publish(&mut self, jpeg: Bytes, width: u32, height: u32) {
        let at = Instant::now();
        self.seq += 1;
        {
            let mut s = self.shared.lock();
            s.frames_total += 1;
            s.meter.record(at);
            s.latest_at = Some(at);
            s.size = Some((width, height));
            if s.state != CameraState::Streaming {
                s.state = CameraState::Streaming;
                tracing::info!(
                    "camera source {}: streaming {width}×{height}",
                    self.shared.source()
                );
            }
        }
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

    fn failed(&mut self, err: &SourceError, retry_in: Duration) {
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

    fn restarted(&self) {
        self.shared.lock().restarts += 1;
    }
}

/// The source task: runs until aborted by [`Camera`](super::Camera).
pub(crate) async fn run(cfg: CameraConfig, scene: watch::Receiver<Scene>, mut out: Publisher) {
    let url = match cfg.source {
        SourceKind::None => return,
        SourceKind::Synthetic => {
            if let Err(e) = synthetic::run(&cfg, scene, &mut out).await {
                // Encoding a valid size does not fail; if it does, say so
                // and stop rather than spin.
                tracing::error!("{e}");
                let mut s = out.shared.lock();
                s.state = CameraState::Failed;
                s.last_error = Some(e.to_string());
            }
            return;
        }
        SourceKind::Url => match cfg.url.as_deref().map(StreamUrl::parse) {
            Some(Ok(url)) => Some(url),
            // validate() already refused these.
            _ => return,
        },
        SourceKind::Ffmpeg | SourceKind::MjpgStreamer => None,
    };
    let mut backoff = Backoff::from_config(&cfg.backoff);
    loop {
        let started = Instant::now();
        let err = match (&url, cfg.source) {
            (Some(url), _) => {
                out.starting(None);
                client::run_url(url, cfg.stall_timeout(), &mut out).await
            }
            (None, SourceKind::Ffmpeg) => process::run_ffmpeg(&cfg, &mut out).await,
            (None, _) => process::run_mjpg_streamer(&cfg, &mut out).await,
        };
        let wait = backoff.after_run(started.elapsed());
        out.failed(&err, wait);
        tokio::time::sleep(wait).await;
        out.restarted();
    }
}
