//! The ffmpeg child of `[camera.h264] passthrough`: it reads a camera that
//! gives H.264 itself (its input arguments are the setting) and copies the
//! stream to its stdout as an Annex B byte stream (`-c:v copy -f h264`),
//! without decoding it; `relay` cuts it into pictures and sends them.
//!
//! `h264_mp4toannexb` turns a length-prefixed stream (an MP4, some
//! cameras) into start codes; the SPS/PPS before every keyframe, which a
//! receiver that joins late needs, are the splitter's. The keyframe
//! interval is the camera's own.

use std::process::Stdio;
use std::time::Duration;

use tokio::process::{Child, Command};

use super::encoder::RtpError;

/// What one pass-through run reads.
#[derive(Debug, Clone, PartialEq)]
pub struct Copy {
    /// ffmpeg's input arguments, ending with `-i SOURCE`.
    pub input: Vec<String>,
    /// A run with no new picture for this long is ended.
    pub stall: Duration,
}

impl Copy {
    /// ffmpeg's arguments after the program name.
    pub fn args(&self) -> Vec<String> {
        let mut a: Vec<String> = [
            "-hide_banner",
            "-nostdin",
            "-loglevel",
            "error",
            "-fflags",
            "nobuffer",
        ]
        .map(String::from)
        .to_vec();
        a.extend(self.input.iter().cloned());
        a.extend(
            [
                "-an",
                "-c:v",
                "copy",
                "-bsf:v",
                "h264_mp4toannexb",
                "-flush_packets",
                "1",
                "-f",
                "h264",
                "pipe:1",
            ]
            .map(String::from),
        );
        a
    }

    /// Starts `program` for this copy, its stdout and stderr piped.
    pub fn spawn(&self, program: &str) -> Result<Child, RtpError> {
        let mut cmd = Command::new(program);
        cmd.args(self.args())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .kill_on_drop(true);
        cmd.spawn().map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                RtpError::NotFound(program.to_owned())
            } else {
                RtpError::Spawn {
                    program: program.to_owned(),
                    error: e,
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_camera_stream_is_copied_to_stdout_never_encoded() {
        let copy = Copy {
            input: ["-f", "v4l2", "-input_format", "h264", "-i", "/dev/video2"]
                .map(String::from)
                .to_vec(),
            stall: Duration::from_secs(5),
        };
        let a = copy.args().join(" ");
        assert!(
            a.contains("-f v4l2 -input_format h264 -i /dev/video2 -an -c:v copy"),
            "{a}"
        );
        assert!(a.contains("-bsf:v h264_mp4toannexb"), "{a}");
        assert!(!a.contains("libx264"), "{a}");
        assert!(a.ends_with("-f h264 pipe:1"), "{a}");
    }
}
