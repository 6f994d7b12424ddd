//! A camera read through V4L2 (`source = "v4l2"`): what the device offers
//! (`caps`, `probe`: `v4l2-ctl --list-formats-ext`), and its frames
//! (`capture`: an ffmpeg child copying them) — the camera's own H.264 or
//! JPEG as the driver hands them over, with nothing decoded or encoded on
//! the way.
//!
//! A path that is not a V4L2 device (a file, a named pipe) is read as a
//! recorded stream of the format `format` names: the same code path from
//! the bytes on, which is how the tests and benchmarks feed it a camera's
//! stream without a camera.
//!
//! This module must never block the runtime, nor panic on what a driver
//! or a tool answers.

mod caps;
pub(crate) mod capture;
mod probe;
pub(crate) mod run;

use std::fmt;

use serde::{Deserialize, Serialize};

pub use caps::{
    Capture, DeviceCaps, FormatCaps, Interval, Intervals, Kind, SizeCaps, Sizes, StepwiseSizes,
};
pub use capture::device_args;
pub use probe::{ProbeError, parse, probe};

/// `camera.v4l2.format`: the format asked of the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FormatChoice {
    /// H.264 if the camera offers it, else MJPEG, else YUYV.
    #[default]
    Auto,
    H264,
    Mjpeg,
    Yuyv,
}

impl FormatChoice {
    pub fn as_str(self) -> &'static str {
        match self {
            FormatChoice::Auto => "auto",
            FormatChoice::H264 => "h264",
            FormatChoice::Mjpeg => "mjpeg",
            FormatChoice::Yuyv => "yuyv",
        }
    }
}

impl fmt::Display for FormatChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// `[camera.v4l2]`: the device `source = "v4l2"` reads. The size and rate
/// asked of it are `camera.width`, `camera.height` and `camera.fps` (the
/// nearest it offers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct V4l2Config {
    /// The camera's device node; a file or named pipe is read as a
    /// recorded stream of `format`.
    pub device: String,
    pub format: FormatChoice,
}

impl Default for V4l2Config {
    fn default() -> Self {
        V4l2Config {
            device: "/dev/video0".into(),
            format: FormatChoice::Auto,
        }
    }
}

/// What kind of thing `path` is, for the choice of how to read it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Node {
    /// A character device: asked through V4L2.
    Device,
    /// A regular file: a recording, played at `camera.fps`.
    File,
    /// A named pipe: a stream as its writer paces it.
    Pipe,
    Missing,
}

/// What `path` is now.
pub fn node(path: &std::path::Path) -> Node {
    use std::os::unix::fs::FileTypeExt;
    match std::fs::metadata(path) {
        Ok(m) if m.file_type().is_char_device() => Node::Device,
        Ok(m) if m.file_type().is_fifo() => Node::Pipe,
        Ok(m) if m.is_file() => Node::File,
        Ok(_) => Node::Device,
        Err(_) => Node::Missing,
    }
}
