//! The synthetic source: one picture of the current scene per frame period.

use std::time::{Duration, SystemTime};

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
    let timecode = cfg.synthetic_timecode;
    out.starting(None);
    loop {
        tick.tick().await;
        // The capture instant: drawing and encoding count as the camera's
        // own delay, as a real camera's readout and encoding would.
        let captured_ms = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as u64);
        let now = scene.borrow().clone();
        let job = tokio::task::spawn_blocking(move || {
            renderer.render(&now);
            if timecode {
                renderer.stamp(captured_ms);
            }
            let jpeg = renderer.encode();
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
