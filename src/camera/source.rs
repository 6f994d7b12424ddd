//! Running the configured source: the supervision loop that starts a run,
//! waits out the backoff after it ends, and starts it again.
//!
//! The sources themselves (`client`, `process`, `synthetic`) know nothing
//! of this loop: they get a [`Publisher`] and return why their run ended.

use tokio::sync::watch;
use tokio::time::Instant;

use super::backoff::Backoff;
use super::config::{CameraConfig, SourceKind, StreamUrl};
use super::frame::Scene;
use super::publisher::Publisher;
use super::shared::CameraState;
use super::{client, process, synthetic};

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
