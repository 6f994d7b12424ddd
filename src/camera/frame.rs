//! What flows through the camera: the [`Scene`] the synthetic source draws
//! and the [`Frame`]s every source produces.
//!
//! Plain data shared by the sources, the renderer and the routes. It
//! depends on no other camera module, so any of them can use it without
//! importing one another.

use bytes::Bytes;
use tokio::time::Instant;

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
