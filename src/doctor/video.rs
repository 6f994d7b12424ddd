//! `neptunus doctor`'s `video` check: which path each viewer's video takes
//! ([`VideoPlan`], the same choice the vehicle makes at its start) and,
//! when a viewer gets none, the fix.
//!
//! It fails when nobody gets video (nor the page, nor QGroundControl), or
//! when the path needs ffmpeg and there is none; it warns when only the
//! page gets video (QGroundControl and WebRTC get none: a camera that
//! offers MJPEG only while nothing may encode).

use super::Check;
use super::host::find_program;
use crate::camera::plan::{Offer, choose, offer};
use crate::camera::{CameraConfig, H264Route, JpegRoute, SourceKind, VideoPlan};

const NAME: &str = "video";

/// The plan for `c` and its check.
pub fn video(c: &CameraConfig) -> Check {
    let offer = if c.source == SourceKind::V4l2 {
        offer(&c.v4l2)
    } else {
        Offer::NotV4l2
    };
    judge(
        c,
        &choose(c, &offer),
        find_program(&c.h264.program).is_some(),
    )
}

/// The check for a plan (`ffmpeg`: the H.264 program is installed).
pub fn judge(c: &CameraConfig, plan: &VideoPlan, ffmpeg: bool) -> Check {
    let detail = plan.to_string();
    if c.source == SourceKind::None && plan.h264 == H264Route::None {
        return Check::pass(NAME, detail);
    }
    let needs_ffmpeg = matches!(plan.h264, H264Route::Encoder | H264Route::FfmpegCopy);
    if needs_ffmpeg && !ffmpeg {
        return Check::fail(
            NAME,
            format!(
                "{detail} — but `{}` (camera.h264.program) is not installed",
                c.h264.program
            ),
            "sudo apt install ffmpeg, or set [camera] encode = \"never\" (QGroundControl then gets video only from an H.264 camera)",
        );
    }
    let fix = plan
        .fix
        .clone()
        .unwrap_or_else(|| "check [camera] (docs: Video and camera)".into());
    match (plan.h264, plan.jpeg) {
        (H264Route::Pending, _) | (_, JpegRoute::Pending) => Check::fail(NAME, detail, fix),
        (H264Route::None, JpegRoute::None) => Check::fail(NAME, detail, fix),
        (H264Route::None, _) => Check::warn(NAME, detail, fix),
        _ => Check::pass(NAME, detail),
    }
}
