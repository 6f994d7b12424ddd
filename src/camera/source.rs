//! Running the configured source: the supervision loop that starts a run,
//! waits out the backoff after it ends, and starts it again.
//!
//! The sources themselves (`client`, `process`, `synthetic`) know nothing
//! of this loop: they get a [`Publisher`] and return why their run ended.

use std::time::Duration;

use tokio::sync::watch;
use tokio::time::Instant;

use super::backoff::Backoff;
use super::config::{CameraConfig, SourceKind, StreamUrl};
use super::frame::Scene;
use super::publisher::Publisher;
use super::shared::CameraState;
use super::{client, process, synthetic};

/// After the last viewer left, a camera started on demand keeps its source
/// this long: a page reload must not restart a camera program.
pub(crate) const DEMAND_LINGER: Duration = Duration::from_secs(3);

/// The source task of a camera started on demand: the source runs while
/// someone wants frames (and [`DEMAND_LINGER`] after), and is stopped —
/// its child killed, nothing rendered — while nobody does.
pub(crate) async fn run_on_demand(
    cfg: CameraConfig,
    scene: watch::Receiver<Scene>,
    mut out: Publisher,
    mut demand: watch::Receiver<usize>,
) {
    loop {
        idle(&out);
        if demand.wait_for(|&n| n > 0).await.is_err() {
            return;
        }
        tracing::debug!("camera: frames wanted, starting the source");
        let lapsed = async {
            loop {
                if demand.wait_for(|&n| n == 0).await.is_err() {
                    return std::future::pending().await;
                }
                tokio::time::sleep(DEMAND_LINGER).await;
                if *demand.borrow_and_update() == 0 {
                    return;
                }
            }
        };
        tokio::select! {
            () = run(cfg.clone(), scene.clone(), &mut out) => return,
            () = lapsed => tracing::debug!("camera: nobody wants frames, source stopped"),
        }
    }
}

fn idle(out: &Publisher) {
    let mut s = out.shared.lock();
    s.state = CameraState::Idle;
    s.pid = None;
    s.retry_at = None;
}

/// The source task: runs until aborted by [`Camera`](super::Camera).
pub(crate) async fn run(cfg: CameraConfig, scene: watch::Receiver<Scene>, out: &mut Publisher) {
    let url = match cfg.source {
        SourceKind::None => return,
        SourceKind::Synthetic => {
            if let Err(e) = synthetic::run(&cfg, scene, out).await {
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
        SourceKind::Ffmpeg | SourceKind::MjpgStreamer | SourceKind::V4l2 => None,
    };
    let mut backoff = Backoff::from_config(&cfg.backoff);
    loop {
        let started = Instant::now();
        let err = match (&url, cfg.source) {
            (Some(url), _) => {
                out.starting(None);
                client::run_url(url, cfg.stall_timeout(), out).await
            }
            (None, SourceKind::Ffmpeg) => process::run_ffmpeg(&cfg, out).await,
            (None, SourceKind::V4l2) => super::v4l2::run::run(&cfg, out).await,
            (None, _) => process::run_mjpg_streamer(&cfg, out).await,
        };
        let wait = backoff.after_run(started.elapsed());
        out.failed(&err, wait);
        tokio::time::sleep(wait).await;
        out.restarted();
    }
}
