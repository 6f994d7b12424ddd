//! One run of the RTP encoder: an `ffmpeg` child reading the camera's
//! frames, decoded to raw pictures, on its stdin and sending H.264 over RTP to every destination.
//!
//! The run ends when the child exits, its stdin breaks, the camera stops or
//! the destinations change; the restart schedule is the caller's. The child
//! is spawned with `kill_on_drop`, so dropping the run kills it.

use std::process::Stdio;
use std::time::Duration;

use tokio::io::AsyncWriteExt;
use tokio::process::{Child, Command};
use tokio::sync::watch;

use super::config::{H264Config, RtpDest};
use crate::camera::frame::Frame;
use crate::camera::process::StderrTail;

pub use crate::camera::h264::rtp::RTP_PACKET_BYTES;

/// Why a run of the encoder ended.
#[derive(Debug, thiserror::Error)]
pub enum RtpError {
    #[error(
        "RTP video: program `{0}` not found — install ffmpeg (apt install ffmpeg), set camera.h264.program, or pass --video-rtp off"
    )]
    NotFound(String),
    #[error("RTP video: cannot start `{program}`: {error} — check camera.h264.program")]
    Spawn {
        program: String,
        error: std::io::Error,
    },
    #[error("RTP video: `{program}` exited ({status}){stderr} — restarting it")]
    Exited {
        program: String,
        status: String,
        stderr: String,
    },
    #[error("RTP video: the camera stopped")]
    CameraGone,
    #[error(
        "RTP video: no frame from `{program}` for {secs:.1} s — restarting it (check camera.h264.passthrough and the camera; camera.stall_timeout_s)"
    )]
    Stalled { program: String, secs: f64 },
    #[error("RTP video: cannot send to {dest}: {error} — check camera.rtp (--video-rtp)")]
    Destination { dest: String, error: String },
    #[error(
        "RTP video: the camera's pictures changed from {from:?} to {to:?} — restarting the encoder"
    )]
    SizeChanged { from: Raw, to: Raw },
}

/// What one run encodes and where it sends it.
#[derive(Debug, Clone, PartialEq)]
pub struct Encode {
    pub dests: Vec<(String, u16)>,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    pub bitrate_kbps: u32,
    /// Scale to `width` × `height` (else the camera's size is kept).
    pub scale: bool,
}

impl Encode {
    pub fn new(cfg: &H264Config, camera_fps: f64, dests: Vec<(String, u16)>) -> Self {
        Encode {
            dests,
            width: cfg.width,
            height: cfg.height,
            fps: if cfg.fps > 0.0 { cfg.fps } else { camera_fps },
            bitrate_kbps: cfg.bitrate_kbps,
            scale: cfg.width > 0,
        }
    }

    /// The keyframe interval in frames: one second at most.
    pub fn gop(&self) -> u32 {
        (self.fps.floor() as u32).max(1)
    }

    /// ffmpeg's arguments after the program name, for raw pictures of
    /// `input` on its stdin.
    pub fn args(&self, input: &Raw) -> Vec<String> {
        let mut a: Vec<String> = [
            "-hide_banner",
            "-nostdin",
            "-loglevel",
            "error",
            // Frames are read as they come: no probing, no input buffer;
            // each frame is stamped with its arrival time.
            "-fflags",
            "nobuffer",
            "-probesize",
            "32",
            "-analyzeduration",
            "0",
            "-use_wallclock_as_timestamps",
            "1",
            "-f",
            "rawvideo",
            "-pix_fmt",
            input.pix_fmt,
        ]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
        a.push("-video_size".into());
        a.push(format!("{}x{}", input.width, input.height));
        a.extend(["-i", "pipe:0", "-an"].map(String::from));
        if self.scale {
            a.push("-vf".into());
            a.push(format!("scale={}:{}", self.width, self.height));
        }
        let gop = self.gop().to_string();
        let rate = format!("{}k", self.bitrate_kbps);
        let buf = format!("{}k", self.bitrate_kbps.max(1));
        for s in [
            "-c:v",
            "libx264",
            // Constrained baseline: what every WebRTC browser decodes
            // (profile-level-id 42e01f in the WebRTC offer), and QGC too.
            "-profile:v",
            "baseline",
            "-preset",
            "ultrafast",
            "-tune",
            "zerolatency",
            "-pix_fmt",
            "yuv420p",
            "-g",
            &gop,
            "-keyint_min",
            &gop,
            "-b:v",
            &rate,
            "-maxrate",
            &rate,
            "-bufsize",
            &buf,
            // SPS/PPS before every IDR: QGC has no SDP to learn them from.
            "-x264-params",
            "repeat-headers=1",
            // Each frame goes out when it comes in: no frame is duplicated
            // or held back to make a constant rate.
            "-fps_mode",
            "passthrough",
        ] {
            a.push(s.to_owned());
        }
        a.extend(rtp_output(&self.dests));
        a
    }
}

/// ffmpeg's output arguments for `dests`: plain RTP to one receiver, a
/// `tee` of one stream to several.
pub fn rtp_output(dests: &[(String, u16)]) -> Vec<String> {
    let url = |h: &str, p: u16| {
        let h = if h.contains(':') {
            format!("[{h}]")
        } else {
            h.to_owned()
        };
        format!("rtp://{h}:{p}?pkt_size={RTP_PACKET_BYTES}")
    };
    let mut a = Vec::new();
    if let [(h, p)] = dests {
        a.extend(["-f", "rtp", "-payload_type", "96"].map(String::from));
        a.push(url(h, *p));
    } else {
        // One stream, several receivers.
        let outs: Vec<String> = dests
            .iter()
            .map(|(h, p)| format!("[f=rtp:payload_type=96]{}", url(h, *p)))
            .collect();
        a.extend(["-map", "0:v", "-f", "tee"].map(String::from));
        a.push(outs.join("|"));
    }
    a
}

/// The raw pictures ffmpeg reads: one decoded JPEG each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Raw {
    pub width: u32,
    pub height: u32,
    pub pix_fmt: &'static str,
}

/// Decodes a JPEG to the pixels ffmpeg reads; `None` for a picture it
/// cannot decode or a pixel format other than RGB and grey.
fn decode(jpeg: &[u8]) -> Option<(Raw, Vec<u8>)> {
    let mut d = jpeg_decoder::Decoder::new(jpeg);
    let pixels = d.decode().ok()?;
    let info = d.info()?;
    let pix_fmt = match info.pixel_format {
        jpeg_decoder::PixelFormat::RGB24 => "rgb24",
        jpeg_decoder::PixelFormat::L8 => "gray",
        _ => return None,
    };
    let raw = Raw {
        width: u32::from(info.width),
        height: u32::from(info.height),
        pix_fmt,
    };
    Some((raw, pixels))
}

/// The RTP destinations of a configuration and an `auto` address, in
/// order, without repeats.
pub fn destinations(
    cfg: &[RtpDest],
    auto: Option<std::net::IpAddr>,
    auto_port: u16,
) -> Vec<(String, u16)> {
    let mut out: Vec<(String, u16)> = Vec::new();
    for d in cfg {
        let d = match d {
            RtpDest::Off => continue,
            RtpDest::Auto => match auto {
                Some(ip) => (ip.to_string(), auto_port),
                None => continue,
            },
            RtpDest::Udp { host, port } => (host.clone(), *port),
        };
        if !out.contains(&d) {
            out.push(d);
        }
    }
    out
}

/// The next frame due (at most `fps` a second, with a quarter period of
/// slack for a source's jitter), decoded; `None` when the camera stopped.
async fn next_picture(
    frames: &mut watch::Receiver<Option<Frame>>,
    next_due: &mut Option<tokio::time::Instant>,
    period: Duration,
) -> Option<(Raw, Vec<u8>, Frame)> {
    loop {
        frames.changed().await.ok()?;
        let Some(frame) = frames.borrow_and_update().clone() else {
            continue;
        };
        if next_due.is_some_and(|due| frame.at + period / 4 < due) {
            continue;
        }
        let due = next_due.map_or(frame.at, |d| d + period);
        *next_due = Some(if due + period < frame.at {
            frame.at
        } else {
            due
        });
        let jpeg = frame.jpeg.clone();
        // Decoding takes milliseconds of CPU: off the runtime's workers.
        match tokio::task::spawn_blocking(move || decode(&jpeg)).await {
            Ok(Some((raw, pixels))) => return Some((raw, pixels, frame)),
            Ok(None) => tracing::debug!("RTP video: a frame could not be decoded, skipped"),
            Err(_) => return None,
        }
    }
}

/// Runs `program` once for `enc`, feeding it `frames` decoded.
/// `started(pid, size)` is called once the first picture went in. The run
/// also ends (to start again) when the camera's picture size changes.
pub async fn run(
    program: &str,
    enc: &Encode,
    frames: &mut watch::Receiver<Option<Frame>>,
    mut started: impl FnMut(Option<u32>, (u32, u32)),
) -> RtpError {
    let period = Duration::from_secs_f64(1.0 / enc.fps);
    let mut next_due = None;
    frames.mark_changed();
    // ffmpeg is told the picture's size up front: start it with the first.
    let Some((raw, first, _)) = next_picture(frames, &mut next_due, period).await else {
        return RtpError::CameraGone;
    };
    let mut cmd = Command::new(program);
    cmd.args(enc.args(&raw))
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
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
    let Some(mut stdin) = child.stdin.take() else {
        return exited(child, stderr, program).await;
    };
    if stdin.write_all(&first).await.is_err() {
        drop(stdin);
        return exited(child, stderr, program).await;
    }
    let size = if enc.scale {
        (enc.width, enc.height)
    } else {
        (raw.width, raw.height)
    };
    started(pid, size);
    loop {
        tokio::select! {
            _ = child.wait() => break,
            () = stderr.next() => {}
            picture = next_picture(frames, &mut next_due, period) => {
                let Some((this, pixels, _)) = picture else {
                    let _ = child.kill().await;
                    return RtpError::CameraGone;
                };
                if this != raw {
                    let _ = child.kill().await;
                    return RtpError::SizeChanged { from: raw, to: this };
                }
                if stdin.write_all(&pixels).await.is_err() {
                    break;
                }
            }
        }
    }
    drop(stdin);
    exited(child, stderr, program).await
}

pub(super) async fn exited(mut child: Child, mut stderr: StderrTail, program: &str) -> RtpError {
    let status = match tokio::time::timeout(Duration::from_secs(2), child.wait()).await {
        Ok(Ok(s)) => s.to_string(),
        Ok(Err(e)) => format!("wait failed: {e}"),
        Err(_) => {
            let _ = child.kill().await;
            "stopped reading and was killed".into()
        }
    };
    stderr.drain(Duration::from_secs(1)).await;
    RtpError::Exited {
        program: program.to_owned(),
        status,
        stderr: stderr.tail(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_destination_is_plain_rtp_several_go_through_tee() {
        let cfg = H264Config::default();
        let raw = Raw {
            width: 640,
            height: 480,
            pix_fmt: "rgb24",
        };
        let one = Encode::new(&cfg, 15.0, vec![("127.0.0.1".into(), 5600)]);
        let a = one.args(&raw).join(" ");
        assert!(
            a.contains("-f rawvideo -pix_fmt rgb24 -video_size 640x480 -i pipe:0"),
            "{a}"
        );
        assert!(a.contains("-g 15 "), "{a}");
        assert!(a.contains("repeat-headers=1"), "{a}");
        assert!(a.contains("-c:v libx264 -profile:v baseline"), "{a}");
        assert!(
            a.ends_with("-f rtp -payload_type 96 rtp://127.0.0.1:5600?pkt_size=1200"),
            "{a}"
        );
        let two = Encode::new(
            &cfg,
            10.0,
            vec![("::1".into(), 5600), ("10.0.0.2".into(), 5602)],
        );
        let a = two.args(&raw).join(" ");
        assert!(
            a.ends_with("-f tee [f=rtp:payload_type=96]rtp://[::1]:5600?pkt_size=1200|[f=rtp:payload_type=96]rtp://10.0.0.2:5602?pkt_size=1200"),
            "{a}"
        );
    }

    #[test]
    fn auto_joins_the_fixed_destinations_once() {
        let cfg = vec![RtpDest::Auto, "udp://10.0.0.2:5600".parse().expect("dest")];
        assert_eq!(
            destinations(&cfg, None, 5600),
            [("10.0.0.2".to_owned(), 5600)]
        );
        let ip = "10.0.0.2".parse().ok();
        assert_eq!(
            destinations(&cfg, ip, 5600),
            [("10.0.0.2".to_owned(), 5600)]
        );
        assert!(destinations(&[RtpDest::Off], ip, 5600).is_empty());
    }
}
