//! The synthetic source: one picture of the current scene per frame period.

use std::time::Duration;

use tokio::sync::watch;
use tokio::time::MissedTickBehavior;

use super::config::CameraConfig;
use super::frame::Scene;
use super::publisher::Publisher;
use super::render::{RenderError, SyntheticRenderer};

/// Renders at `cfg.fps` until aborted. Drawing and encoding take
/// milliseconds of CPU, so they run on the blocking pool, never on the
/// runtime's workers.
pub(crate) async fn run(
    cfg: &CameraConfig,
    scene: watch::Receiver<Scene>,
    out: &mut Publisher,
) -> Result<(), RenderError> {
    let mut renderer = SyntheticRenderer::new(cfg.width, cfg.height, cfg.jpeg_quality)
        .with_overlay(cfg.synthetic_overlay);
    let (w, h) = (renderer.width(), renderer.height());
    let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / cfg.fps));
    // A late frame is not made up for: the next one comes a period later.
    tick.set_missed_tick_behavior(MissedTickBehavior::Delay);
    out.starting(None);
    loop {
        tick.tick().await;
        let now = scene.borrow().clone();
        let job = tokio::task::spawn_blocking(move || {
            let jpeg = renderer.render_jpeg(&now);
            (renderer, jpeg)
        });
        let Ok((back, jpeg)) = job.await else {
            // The runtime is shutting down.
            return Ok(());
        };
        renderer = back;
        out.publish(jpeg?, w, h);
    }
}
