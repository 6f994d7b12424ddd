//! One run of the RTP sender for a camera that gives H.264 itself (most UVC
//! HD webcams): `ffmpeg` reads the camera (`[camera.h264] passthrough`, its
//! input arguments) and copies the stream into RTP without decoding it.
//!
//! Two bitstream filters make a copied stream playable by a receiver that
//! joins late and has no SDP (QGroundControl): `h264_mp4toannexb` turns a
//! length-prefixed stream into start codes, and `dump_extra` repeats the
//! SPS/PPS before every keyframe even when the camera sends them once. The
//! keyframe interval is the camera's own.
//!
//! ffmpeg's `-progress` report on stdout says when frames flow: the stream
//! is announced once the first frame went out, and a run whose frame count
//! stops growing for `camera.stall_timeout_s` is ended (to start again).

use std::process::Stdio;
use std::time::Duration;

use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::Command;
use tokio::time::Instant;

use super::encoder::{RtpError, exited, rtp_output};
use crate::camera::process::StderrTail;

/// What one pass-through run reads and where it sends it.
#[derive(Debug, Clone, PartialEq)]
pub struct Copy {
    /// ffmpeg's input arguments, ending with `-i SOURCE`.
    pub input: Vec<String>,
    pub dests: Vec<(String, u16)>,
    /// A run with no new frame for this long is ended.
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
                "h264_mp4toannexb,dump_extra=freq=keyframe",
                "-progress",
                "pipe:1",
                "-stats_period",
                "0.5",
            ]
            .map(String::from),
        );
        a.extend(rtp_output(&self.dests));
        a
    }
}

/// The value of a `-progress` line `frame=N`.
fn frame_count(line: &str) -> Option<u64> {
    line.strip_prefix("frame=")?.trim().parse().ok()
}

/// Runs `program` once for `copy`. `started(pid)` is called once the first
/// frame went out.
pub async fn run(program: &str, copy: &Copy, mut started: impl FnMut(Option<u32>)) -> RtpError {
    let mut cmd = Command::new(program);
    cmd.args(copy.args())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true);
    let mut child = match cmd.spawn() {
        Ok(c) => c,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return RtpError::NotFound(program.to_owned());
        }
        Err(error) => {
            return RtpError::Spawn {
                program: program.to_owned(),
                error,
            };
        }
    };
    let pid = child.id();
    let mut stderr = StderrTail::new(child.stderr.take(), program);
    let Some(stdout) = child.stdout.take() else {
        return exited(child, stderr, program).await;
    };
    let mut progress = BufReader::new(stdout).lines();
    let mut frames = 0u64;
    let mut last_new_frame = Instant::now();
    loop {
        let stall_at = last_new_frame + copy.stall;
        tokio::select! {
            _ = child.wait() => break,
            () = stderr.next() => {}
            line = progress.next_line() => match line {
                Ok(Some(line)) => {
                    if let Some(n) = frame_count(&line).filter(|&n| n > frames) {
                        if frames == 0 {
                            started(pid);
                        }
                        frames = n;
                        last_new_frame = Instant::now();
                    }
                }
                // stdout closed: the child is ending.
                Ok(None) | Err(_) => break,
            },
            () = tokio::time::sleep_until(stall_at) => {
                let _ = child.kill().await;
                return RtpError::Stalled {
                    program: program.to_owned(),
                    secs: copy.stall.as_secs_f64(),
                };
            }
        }
    }
    exited(child, stderr, program).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_camera_stream_is_copied_with_headers_before_every_keyframe() {
        let copy = Copy {
            input: ["-f", "v4l2", "-input_format", "h264", "-i", "/dev/video2"]
                .map(String::from)
                .to_vec(),
            dests: vec![("127.0.0.1".into(), 5600)],
            stall: Duration::from_secs(5),
        };
        let a = copy.args().join(" ");
        assert!(
            a.contains("-f v4l2 -input_format h264 -i /dev/video2 -an -c:v copy"),
            "{a}"
        );
        assert!(
            a.contains("-bsf:v h264_mp4toannexb,dump_extra=freq=keyframe"),
            "{a}"
        );
        assert!(!a.contains("libx264"), "{a}");
        assert!(
            a.ends_with("-f rtp -payload_type 96 rtp://127.0.0.1:5600?pkt_size=1200"),
            "{a}"
        );
    }

    #[test]
    fn progress_lines_give_the_frame_count() {
        assert_eq!(frame_count("frame=42"), Some(42));
        assert_eq!(frame_count("fps=15.0"), None);
        assert_eq!(frame_count("frame=x"), None);
    }
}
