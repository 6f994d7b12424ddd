//! The `[camera]` configuration table and its validation.
//!
//! Every field has a default, unknown keys are errors, and
//! [`CameraConfig::validate`] names the key, the value and the fix, so a
//! misspelt or out-of-range setting never silently becomes a black video.

use std::fmt;
use std::time::Duration;

use axum::http::Uri;
use serde::{Deserialize, Serialize};

use super::encode::EncodeSetting;
use super::rtp::config::{H264Config, RtpDest, check_dests};
use super::v4l2::V4l2Config;
use super::webrtc::config::WebRtcConfig;

/// Where the camera's frames come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum SourceKind {
    /// No camera: the video routes answer 503.
    None,
    /// Frames drawn from the simulator's state (the default with `--sim`).
    Synthetic,
    /// `ffmpeg` as a supervised child, writing MJPEG to its stdout.
    Ffmpeg,
    /// `mjpg_streamer` as a supervised child (what the OpenROV image and the
    /// 2015 thesis ran), read over HTTP on a loopback port.
    #[default]
    #[serde(alias = "mjpg_streamer")]
    MjpgStreamer,
    /// An existing MJPEG HTTP stream (`multipart/x-mixed-replace`).
    Url,
    /// A V4L2 camera read by Neptunus itself (`[camera.v4l2]`): its own
    /// H.264 or JPEG passed through, chosen from what it offers.
    V4l2,
}

impl SourceKind {
    pub fn as_str(self) -> &'static str {
        match self {
            SourceKind::None => "none",
            SourceKind::Synthetic => "synthetic",
            SourceKind::Ffmpeg => "ffmpeg",
            SourceKind::MjpgStreamer => "mjpg-streamer",
            SourceKind::Url => "url",
            SourceKind::V4l2 => "v4l2",
        }
    }
}

impl fmt::Display for SourceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The camera's settings (`[camera]` in the TOML file).
///
/// `width`, `height`, `fps` and `jpeg_quality` shape the synthetic source;
/// the other sources take the size and rate the camera program gives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// `none`, `synthetic`, `ffmpeg`, `mjpg-streamer`, `url` or `v4l2`.
    pub source: SourceKind,
    /// Whether Neptunus may encode video itself: `auto` (never on a
    /// 32-bit ARM build, the BeagleBone; when needed elsewhere), `never`,
    /// `when-needed`. A camera's own H.264 is never encoded again.
    pub encode: EncodeSetting,
    /// Synthetic frame width in pixels (and the size asked of a `v4l2`
    /// camera: the nearest it offers).
    pub width: u32,
    /// Synthetic frame height in pixels.
    pub height: u32,
    /// Synthetic frame rate (and the rate asked of a `v4l2` camera, or a
    /// recorded stream's).
    pub fps: f64,
    /// Synthetic JPEG quality, 1–100.
    pub jpeg_quality: u8,
    /// The synthetic camera draws its own instruments (heading tape, depth,
    /// attitude, armed state) into the picture. Off by default: the
    /// browser's HUD draws them over any camera, and two would collide. On
    /// for viewers without the page (`/video.mjpg` in a video player).
    pub synthetic_overlay: bool,
    /// The synthetic camera paints each frame's capture time into its
    /// bottom-left corner as a block code ([`super::timecode`]), for the
    /// camera-to-screen latency bench. Off by default: the pilot's picture
    /// carries no code.
    pub synthetic_timecode: bool,
    /// How the image must be turned for display (0, 90, 180 or 270,
    /// clockwise). Only reported in the status: the browser applies it with
    /// CSS so every browser shows the same picture.
    pub rotation_deg: u16,
    /// A running child or stream that gives no frame for this long is
    /// restarted.
    pub stall_timeout_s: f64,
    /// Restart schedule of the `ffmpeg`, `mjpg-streamer` and `url` sources.
    pub backoff: BackoffConfig,
    pub ffmpeg: FfmpegConfig,
    pub mjpg_streamer: MjpgStreamerConfig,
    /// The stream read by `source = "url"`, e.g.
    /// `http://rov.local:8080/?action=stream`.
    pub url: Option<String>,
    /// The camera `source = "v4l2"` reads.
    pub v4l2: V4l2Config,
    /// Where H.264 over RTP goes: `auto`, `off` or `udp://HOST:PORT`
    /// entries (`--video-rtp`).
    pub rtp: Vec<RtpDest>,
    /// How the RTP stream is encoded (the WebRTC viewers get the same
    /// encode).
    pub h264: H264Config,
    /// Video over WebRTC (Cockpit, the browser page).
    pub webrtc: WebRtcConfig,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            source: SourceKind::default(),
            encode: EncodeSetting::default(),
            width: 640,
            height: 480,
            fps: 10.0,
            jpeg_quality: 80,
            synthetic_overlay: false,
            synthetic_timecode: false,
            rotation_deg: 0,
            stall_timeout_s: 5.0,
            backoff: BackoffConfig::default(),
            ffmpeg: FfmpegConfig::default(),
            mjpg_streamer: MjpgStreamerConfig::default(),
            url: None,
            v4l2: V4l2Config::default(),
            rtp: vec![RtpDest::Auto],
            h264: H264Config::default(),
            webrtc: WebRtcConfig::default(),
        }
    }
}

impl CameraConfig {
    /// The camera of `--sim`: frames drawn from the simulator, 640×480 at
    /// 10 fps.
    pub fn synthetic() -> Self {
        CameraConfig {
            source: SourceKind::Synthetic,
            ..CameraConfig::default()
        }
    }

    /// No camera.
    pub fn none() -> Self {
        CameraConfig {
            source: SourceKind::None,
            ..CameraConfig::default()
        }
    }

    /// Checks every value the chosen source uses.
    pub fn validate(&self) -> Result<(), CameraConfigError> {
        if !(MIN_SIDE..=MAX_SIDE).contains(&self.width)
            || !(MIN_SIDE..=MAX_SIDE).contains(&self.height)
        {
            return Err(CameraConfigError::Size {
                width: self.width,
                height: self.height,
            });
        }
        if !(self.fps.is_finite() && (MIN_FPS..=MAX_FPS).contains(&self.fps)) {
            return Err(CameraConfigError::Fps(self.fps));
        }
        if self.synthetic_timecode && !super::timecode::fits(self.width, self.height) {
            return Err(CameraConfigError::TimecodeSize {
                width: self.width,
                height: self.height,
            });
        }
        if !(1..=100).contains(&self.jpeg_quality) {
            return Err(CameraConfigError::Quality(self.jpeg_quality));
        }
        if !matches!(self.rotation_deg, 0 | 90 | 180 | 270) {
            return Err(CameraConfigError::Rotation(self.rotation_deg));
        }
        if !(self.stall_timeout_s.is_finite() && (0.1..=600.0).contains(&self.stall_timeout_s)) {
            return Err(CameraConfigError::StallTimeout(self.stall_timeout_s));
        }
        self.backoff.validate()?;
        check_dests(&self.rtp).map_err(|e| CameraConfigError::Rtp(e.to_string()))?;
        self.h264
            .validate()
            .map_err(|e| CameraConfigError::Rtp(e.to_string()))?;
        self.webrtc
            .validate()
            .map_err(|e| CameraConfigError::Rtp(e.to_string()))?;
        match self.source {
            SourceKind::None | SourceKind::Synthetic => {}
            SourceKind::Ffmpeg => {
                if self.ffmpeg.program.trim().is_empty() {
                    return Err(CameraConfigError::EmptyProgram("ffmpeg"));
                }
                let last = self.ffmpeg.output_args.last().map(String::as_str);
                if !matches!(last, Some("pipe:1" | "pipe:" | "-")) {
                    return Err(CameraConfigError::FfmpegOutput(
                        self.ffmpeg.output_args.clone(),
                    ));
                }
            }
            SourceKind::MjpgStreamer => {
                if self.mjpg_streamer.program.trim().is_empty() {
                    return Err(CameraConfigError::EmptyProgram("mjpg_streamer"));
                }
                if !self.mjpg_streamer.stream_path.starts_with('/') {
                    return Err(CameraConfigError::StreamPath(
                        self.mjpg_streamer.stream_path.clone(),
                    ));
                }
            }
            SourceKind::Url => {
                let Some(url) = &self.url else {
                    return Err(CameraConfigError::UrlMissing);
                };
                StreamUrl::parse(url)?;
            }
            SourceKind::V4l2 => {
                if self.v4l2.device.trim().is_empty() {
                    return Err(CameraConfigError::V4l2Device);
                }
            }
        }
        Ok(())
    }

    pub(crate) fn stall_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.stall_timeout_s)
    }
}

const MIN_SIDE: u32 = 16;
const MAX_SIDE: u32 = 4096;
const MIN_FPS: f64 = 0.1;
const MAX_FPS: f64 = 60.0;

/// Restart schedule: the first retry after `initial_s`, doubling up to
/// `max_s`; a run that lasted `healthy_s` starts the schedule over.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BackoffConfig {
    pub initial_s: f64,
    pub max_s: f64,
    pub healthy_s: f64,
}

impl Default for BackoffConfig {
    fn default() -> Self {
        BackoffConfig {
            initial_s: 0.5,
            max_s: 10.0,
            healthy_s: 60.0,
        }
    }
}

impl BackoffConfig {
    fn validate(&self) -> Result<(), CameraConfigError> {
        let ok = |v: f64| v.is_finite() && (0.001..=3600.0).contains(&v);
        if ok(self.initial_s)
            && ok(self.max_s)
            && ok(self.healthy_s)
            && self.initial_s <= self.max_s
        {
            Ok(())
        } else {
            Err(CameraConfigError::Backoff(self.clone()))
        }
    }
}

/// `source = "ffmpeg"`: `PROGRAM -hide_banner -nostdin -loglevel error
/// INPUT_ARGS… OUTPUT_ARGS…`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FfmpegConfig {
    /// Program name (looked up on PATH) or path.
    pub program: String,
    /// Where ffmpeg reads video from.
    pub input_args: Vec<String>,
    /// How it writes: MJPEG on stdout (must end with `pipe:1`).
    pub output_args: Vec<String>,
}

impl Default for FfmpegConfig {
    fn default() -> Self {
        let strings = |a: &[&str]| a.iter().map(|s| (*s).to_owned()).collect();
        FfmpegConfig {
            program: "ffmpeg".into(),
            input_args: strings(&["-f", "v4l2", "-i", "/dev/video0"]),
            output_args: strings(&["-f", "mjpeg", "-q:v", "5", "pipe:1"]),
        }
    }
}

/// `source = "mjpg-streamer"`: `PROGRAM -i INPUT -o "OUTPUT_PLUGIN -p PORT"`,
/// read at `http://127.0.0.1:PORT` + `stream_path`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MjpgStreamerConfig {
    pub program: String,
    /// The input plugin and its options, one string as mjpg_streamer takes it.
    pub input: String,
    /// The output plugin (a path when it is not on the library path).
    pub output_plugin: String,
    /// Loopback port for the output plugin; 0 picks a free one at each start.
    pub port: u16,
    pub stream_path: String,
}

impl Default for MjpgStreamerConfig {
    fn default() -> Self {
        MjpgStreamerConfig {
            program: "mjpg_streamer".into(),
            input: "input_uvc.so -d /dev/video0 -r 640x480 -f 10".into(),
            output_plugin: "output_http.so".into(),
            port: 0,
            stream_path: "/?action=stream".into(),
        }
    }
}

/// A configuration value out of range, with the fix.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraConfigError {
    /// `rtp`, `[camera.h264]` or `[camera.webrtc]` (the message names the
    /// key and the fix).
    #[error("{0}")]
    Rtp(String),
    #[error(
        "camera.width × camera.height = {width}×{height} is out of range — use 16 to 4096 pixels on each side (default 640×480)"
    )]
    Size { width: u32, height: u32 },
    #[error(
        "camera.synthetic_timecode needs a picture of at least 256×32 pixels, not {width}×{height} — make camera.width/camera.height larger or turn the time code off"
    )]
    TimecodeSize { width: u32, height: u32 },
    #[error("camera.fps = {0} is out of range — use 0.1 to 60 frames per second (default 10)")]
    Fps(f64),
    #[error("camera.jpeg_quality = {0} is out of range — use 1 to 100 (default 80)")]
    Quality(u8),
    #[error("camera.rotation_deg = {0} is not a right angle — use 0, 90, 180 or 270")]
    Rotation(u16),
    #[error("camera.stall_timeout_s = {0} is out of range — use 0.1 to 600 seconds (default 5)")]
    StallTimeout(f64),
    #[error(
        "camera.backoff (initial_s = {}, max_s = {}, healthy_s = {}) is not usable — give positive seconds with initial_s ≤ max_s (default 0.5, 10, 60)",
        .0.initial_s, .0.max_s, .0.healthy_s
    )]
    Backoff(BackoffConfig),
    #[error("camera.{0}.program is empty — give the program's name or path")]
    EmptyProgram(&'static str),
    #[error(
        "camera.ffmpeg.output_args = {0:?} does not write to stdout — end it with \"pipe:1\" (default [\"-f\", \"mjpeg\", \"-q:v\", \"5\", \"pipe:1\"])"
    )]
    FfmpegOutput(Vec<String>),
    #[error(
        "camera.mjpg_streamer.stream_path = {0:?} must start with '/' (default \"/?action=stream\")"
    )]
    StreamPath(String),
    #[error(
        "camera.v4l2.device is empty — name the camera's device, e.g. \"/dev/video0\" (`v4l2-ctl --list-devices` lists them)"
    )]
    V4l2Device,
    #[error(
        "camera.source = \"url\" needs camera.url — set it to an MJPEG stream such as \"http://rov.local:8080/?action=stream\""
    )]
    UrlMissing,
    #[error(
        "camera.url = {url:?} is not usable: {reason} — give an http:// address such as \"http://rov.local:8080/?action=stream\""
    )]
    Url { url: String, reason: String },
}

/// A parsed `http://host[:port]/path` stream address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct StreamUrl {
    pub host: String,
    pub port: u16,
    /// `host:port` as sent in the Host header.
    pub authority: String,
    pub path_and_query: String,
    /// The address as configured, for messages.
    pub text: String,
}

impl StreamUrl {
    pub fn parse(text: &str) -> Result<StreamUrl, CameraConfigError> {
        let err = |reason: &str| CameraConfigError::Url {
            url: text.to_owned(),
            reason: reason.to_owned(),
        };
        let uri: Uri = text.parse().map_err(|e| err(&format!("{e}")))?;
        match uri.scheme_str() {
            Some("http") => {}
            Some("https") => {
                return Err(err("https is not supported (no TLS in the camera client)"));
            }
            Some(other) => return Err(err(&format!("scheme {other:?} is not http"))),
            None => return Err(err("it has no scheme")),
        }
        let authority = uri.authority().ok_or_else(|| err("it has no host"))?;
        if authority.as_str().contains('@') {
            return Err(err(
                "user names and passwords in the address are not supported",
            ));
        }
        let host = authority
            .host()
            .trim_start_matches('[')
            .trim_end_matches(']');
        if host.is_empty() {
            return Err(err("it has no host"));
        }
        let port = authority.port_u16().unwrap_or(80);
        Ok(StreamUrl {
            host: host.to_owned(),
            port,
            authority: authority.as_str().to_owned(),
            path_and_query: uri
                .path_and_query()
                .map_or_else(|| "/".to_owned(), |p| p.as_str().to_owned()),
            text: text.to_owned(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_sim_is_synthetic() {
        CameraConfig::default().validate().expect("default");
        let sim = CameraConfig::synthetic();
        sim.validate().expect("synthetic");
        assert_eq!(sim.source, SourceKind::Synthetic);
        assert_eq!((sim.width, sim.height, sim.fps), (640, 480, 10.0));
        // The page's HUD draws the instruments: the picture carries none.
        assert!(!sim.synthetic_overlay);
        let on: CameraConfig = toml::from_str("synthetic_overlay = true").expect("parses");
        assert!(on.synthetic_overlay);
        let err = toml::from_str::<CameraConfig>("synthetic_overlay = \"yes\"")
            .expect_err("not a boolean");
        assert!(err.to_string().contains("synthetic_overlay"), "{err}");
        // The time code is for the latency bench only.
        assert!(!sim.synthetic_timecode);
        let small: CameraConfig =
            toml::from_str("synthetic_timecode = true\nwidth = 200").expect("parses");
        let err = small.validate().expect_err("too narrow for the code");
        assert!(err.to_string().contains("256×32"), "{err}");
    }

    #[test]
    fn toml_round_trip_and_unknown_keys() {
        let cfg: CameraConfig = toml::from_str(
            r#"
            source = "ffmpeg"
            fps = 5
            rotation_deg = 180
            [ffmpeg]
            input_args = ["-f", "lavfi", "-i", "testsrc"]
            "#,
        )
        .expect("parses");
        assert_eq!(cfg.source, SourceKind::Ffmpeg);
        assert_eq!(cfg.fps, 5.0);
        assert_eq!(cfg.rotation_deg, 180);
        assert_eq!(cfg.ffmpeg.program, "ffmpeg");
        assert_eq!(
            cfg.ffmpeg.output_args.last().map(String::as_str),
            Some("pipe:1")
        );
        cfg.validate().expect("valid");

        let alias: CameraConfig = toml::from_str("source = \"mjpg_streamer\"").expect("alias");
        assert_eq!(alias.source, SourceKind::MjpgStreamer);

        let err = toml::from_str::<CameraConfig>("sorce = \"url\"").expect_err("unknown key");
        assert!(err.to_string().contains("sorce"), "{err}");
        let err = toml::from_str::<CameraConfig>("[ffmpeg]\ninput = \"x\"").expect_err("nested");
        assert!(err.to_string().contains("input"), "{err}");
        let err = toml::from_str::<CameraConfig>("source = \"webcam\"").expect_err("kind");
        assert!(err.to_string().contains("webcam"), "{err}");
    }

    #[test]
    fn errors_name_the_key_the_value_and_the_fix() {
        let bad = |f: &dyn Fn(&mut CameraConfig)| {
            let mut c = CameraConfig::synthetic();
            f(&mut c);
            c.validate().expect_err("invalid").to_string()
        };
        let m = bad(&|c| c.rotation_deg = 45);
        assert!(
            m.contains("rotation_deg = 45") && m.contains("0, 90, 180 or 270"),
            "{m}"
        );
        let m = bad(&|c| c.fps = 0.0);
        assert!(
            m.contains("camera.fps = 0") && m.contains("0.1 to 60"),
            "{m}"
        );
        let m = bad(&|c| c.fps = f64::NAN);
        assert!(m.contains("camera.fps"), "{m}");
        let m = bad(&|c| c.width = 5);
        assert!(m.contains("5×480"), "{m}");
        let m = bad(&|c| c.jpeg_quality = 0);
        assert!(m.contains("jpeg_quality = 0"), "{m}");
        let m = bad(&|c| c.backoff.max_s = 0.1);
        assert!(m.contains("initial_s ≤ max_s"), "{m}");
        let m = bad(&|c| c.source = SourceKind::Url);
        assert!(m.contains("needs camera.url"), "{m}");
        let m = bad(&|c| {
            c.source = SourceKind::Url;
            c.url = Some("https://cam/x".into());
        });
        assert!(m.contains("https is not supported"), "{m}");
        let m = bad(&|c| {
            c.source = SourceKind::Ffmpeg;
            c.ffmpeg.output_args = vec!["out.mjpg".into()];
        });
        assert!(m.contains("pipe:1"), "{m}");
        let m = bad(&|c| {
            c.source = SourceKind::MjpgStreamer;
            c.mjpg_streamer.program = " ".into();
        });
        assert!(m.contains("camera.mjpg_streamer.program is empty"), "{m}");
    }

    #[test]
    fn stream_urls() {
        let u = StreamUrl::parse("http://127.0.0.1:8080/?action=stream").expect("url");
        assert_eq!((u.host.as_str(), u.port), ("127.0.0.1", 8080));
        assert_eq!(u.path_and_query, "/?action=stream");
        assert_eq!(u.authority, "127.0.0.1:8080");
        let u = StreamUrl::parse("http://cam").expect("url");
        assert_eq!((u.port, u.path_and_query.as_str()), (80, "/"));
        let u = StreamUrl::parse("http://[::1]:81/v").expect("v6");
        assert_eq!(u.host, "::1");
        for bad in ["", "cam:80/x", "ftp://cam/x", "http://u:p@cam/x"] {
            assert!(StreamUrl::parse(bad).is_err(), "{bad}");
        }
    }
}
