//! Where the RTP video goes ([`RtpDest`], `--video-rtp` and `[camera] rtp`)
//! and how it is encoded (`[camera.h264]`, [`H264Config`]).
//!
//! Parsing only: a bad value is an error naming the value and the fix,
//! never a panic and never a silent default.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// One `--video-rtp` value.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum RtpDest {
    /// Port [`H264Config::auto_port`] at the address of the ground station
    /// in control, or of the first one heard on a UDP endpoint.
    Auto,
    /// No RTP video.
    Off,
    /// A fixed receiver: `udp://HOST:PORT`.
    Udp { host: String, port: u16 },
}

impl RtpDest {
    /// `udp://HOST:PORT` (IPv6 hosts in brackets).
    pub fn udp_uri(host: &str, port: u16) -> String {
        if host.contains(':') {
            format!("udp://[{host}]:{port}")
        } else {
            format!("udp://{host}:{port}")
        }
    }
}

impl fmt::Display for RtpDest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RtpDest::Auto => f.write_str("auto"),
            RtpDest::Off => f.write_str("off"),
            RtpDest::Udp { host, port } => f.write_str(&RtpDest::udp_uri(host, *port)),
        }
    }
}

/// A `--video-rtp` value that is not `auto`, `off` or `udp://HOST:PORT`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "video RTP destination {0:?} is not valid — use udp://HOST:PORT (e.g. udp://192.168.2.1:5600), auto or off"
)]
pub struct RtpDestError(pub String);

impl FromStr for RtpDest {
    type Err = RtpDestError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || RtpDestError(s.to_owned());
        match s.trim() {
            "auto" => return Ok(RtpDest::Auto),
            "off" => return Ok(RtpDest::Off),
            _ => {}
        }
        let rest = s.trim().strip_prefix("udp://").ok_or_else(bad)?;
        let (host, port) = rest.rsplit_once(':').ok_or_else(bad)?;
        let port: u16 = port.parse().map_err(|_| bad())?;
        let host = match host.strip_prefix('[') {
            Some(h) => h.strip_suffix(']').ok_or_else(bad)?,
            None if host.contains(':') => return Err(bad()),
            None => host,
        };
        let valid = |c: char| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | ':' | '_');
        if port == 0 || host.is_empty() || !host.chars().all(valid) {
            return Err(bad());
        }
        Ok(RtpDest::Udp {
            host: host.to_owned(),
            port,
        })
    }
}

impl Serialize for RtpDest {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for RtpDest {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// Checks a list of destinations: `off` stands alone.
pub fn check_dests(dests: &[RtpDest]) -> Result<(), RtpDestError> {
    if dests.len() > 1 && dests.contains(&RtpDest::Off) {
        let all: Vec<String> = dests.iter().map(ToString::to_string).collect();
        return Err(RtpDestError(format!(
            "{} (\"off\" cannot be combined with other destinations)",
            all.join(", ")
        )));
    }
    Ok(())
}

/// `[camera.h264]`: the encode of the RTP stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct H264Config {
    /// The encoder program (ffmpeg with libx264).
    pub program: String,
    /// Encoded size; 0 × 0 keeps the camera's.
    pub width: u32,
    pub height: u32,
    /// Frames per second sent; 0 takes `camera.fps`. The keyframe interval
    /// is this many frames (one second).
    pub fps: f64,
    pub bitrate_kbps: u32,
    /// The port `auto` sends to (QGroundControl listens on 5600).
    pub auto_port: u16,
    /// For a camera that gives H.264 itself: ffmpeg's input arguments for
    /// it, ending with `-i SOURCE` (e.g. `["-f", "v4l2", "-input_format",
    /// "h264", "-video_size", "1280x720", "-framerate", "30", "-i",
    /// "/dev/video2"]`). The stream is then copied, not encoded: `width`,
    /// `height`, `fps` and `bitrate_kbps` only describe it to the ground
    /// station. Empty (the default): the camera's pictures are encoded.
    pub passthrough: Vec<String>,
}

impl Default for H264Config {
    fn default() -> Self {
        H264Config {
            program: "ffmpeg".into(),
            width: 0,
            height: 0,
            fps: 0.0,
            bitrate_kbps: 1000,
            auto_port: 5600,
            passthrough: Vec::new(),
        }
    }
}

/// An `[camera.h264]` value out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum H264ConfigError {
    #[error(
        "camera.h264.width × height = {0}×{1} is not valid — use 0×0 (the camera's size) or even sizes from 16 to 4096"
    )]
    Size(u32, u32),
    #[error("camera.h264.fps = {0} is out of range — use 0 (camera.fps) or 1 to 60")]
    Fps(f64),
    #[error("camera.h264.bitrate_kbps = {0} is out of range — use 50 to 50000")]
    Bitrate(u32),
    #[error("camera.h264.auto_port = 0 — use a UDP port, 5600 for QGroundControl")]
    Port,
    #[error("camera.h264.program is empty — name the ffmpeg program (default \"ffmpeg\")")]
    Program,
    #[error(
        "camera.h264.passthrough = {0:?} does not name its source — end it with \"-i\", \"SOURCE\" (e.g. [\"-f\", \"v4l2\", \"-input_format\", \"h264\", \"-i\", \"/dev/video2\"])"
    )]
    Passthrough(Vec<String>),
}

impl H264Config {
    pub fn validate(&self) -> Result<(), H264ConfigError> {
        let side = |v: u32| (16..=4096).contains(&v) && v.is_multiple_of(2);
        if !((self.width == 0 && self.height == 0) || (side(self.width) && side(self.height))) {
            return Err(H264ConfigError::Size(self.width, self.height));
        }
        if !(self.fps == 0.0 || (self.fps.is_finite() && (1.0..=60.0).contains(&self.fps))) {
            return Err(H264ConfigError::Fps(self.fps));
        }
        if !(50..=50_000).contains(&self.bitrate_kbps) {
            return Err(H264ConfigError::Bitrate(self.bitrate_kbps));
        }
        if self.auto_port == 0 {
            return Err(H264ConfigError::Port);
        }
        if self.program.trim().is_empty() {
            return Err(H264ConfigError::Program);
        }
        let names_source = self
            .passthrough
            .windows(2)
            .any(|w| w[0] == "-i" && !w[1].trim().is_empty());
        if !self.passthrough.is_empty() && !names_source {
            return Err(H264ConfigError::Passthrough(self.passthrough.clone()));
        }
        Ok(())
    }

    /// The size and rate a pass-through stream is announced with: the
    /// configured ones, else what its input arguments ask the camera for
    /// (`-video_size WxH`, `-framerate N`), else unknown (0).
    pub fn passthrough_shape(&self) -> (u32, u32, f64) {
        let arg = |name: &str| {
            self.passthrough
                .windows(2)
                .find(|w| w[0] == name)
                .map(|w| w[1].as_str())
        };
        let (mut w, mut h) = (self.width, self.height);
        if w == 0
            && let Some((aw, ah)) = arg("-video_size").and_then(|s| s.split_once('x'))
        {
            w = aw.parse().unwrap_or(0);
            h = ah.parse().unwrap_or(0);
        }
        let fps = if self.fps > 0.0 {
            self.fps
        } else {
            arg("-framerate")
                .or_else(|| arg("-r"))
                .and_then(|s| s.parse().ok())
                .unwrap_or(0.0)
        };
        (w, h, fps)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn destinations_parse_and_bad_ones_are_named() {
        assert_eq!("auto".parse(), Ok(RtpDest::Auto));
        assert_eq!("off".parse(), Ok(RtpDest::Off));
        let d: RtpDest = "udp://192.168.2.1:5600".parse().expect("v4");
        assert_eq!(d.to_string(), "udp://192.168.2.1:5600");
        let d: RtpDest = "udp://[::1]:5602".parse().expect("v6");
        assert_eq!(
            d,
            RtpDest::Udp {
                host: "::1".into(),
                port: 5602
            }
        );
        assert_eq!(d.to_string(), "udp://[::1]:5602");
        for bad in [
            "",
            "5600",
            "rtp://h:5600",
            "udp://h",
            "udp://h:0",
            "udp://h:99999",
            "udp://:5600",
            "udp://::1:5600",
            "udp://a b:5600",
            "udp://h;rm:5600",
        ] {
            let e = bad.parse::<RtpDest>().expect_err(bad).to_string();
            assert!(e.contains("udp://HOST:PORT"), "{e}");
        }
        assert!(check_dests(&[RtpDest::Off, RtpDest::Auto]).is_err());
        assert!(check_dests(&[RtpDest::Off]).is_ok());
    }

    #[test]
    fn encode_settings_are_checked() {
        assert!(H264Config::default().validate().is_ok());
        let bad = |f: &dyn Fn(&mut H264Config)| {
            let mut c = H264Config::default();
            f(&mut c);
            c.validate().expect_err("invalid").to_string()
        };
        assert!(bad(&|c| c.width = 640).contains("640×0"));
        assert!(bad(&|c| c.fps = 0.5).contains("h264.fps = 0.5"));
        assert!(bad(&|c| c.bitrate_kbps = 1).contains("bitrate_kbps = 1"));
        assert!(bad(&|c| c.auto_port = 0).contains("5600"));
        let no_source = |c: &mut H264Config| c.passthrough = vec!["-f".into(), "v4l2".into()];
        assert!(bad(&no_source).contains("end it with \"-i\""));
    }

    #[test]
    fn a_passthrough_stream_is_described_by_its_input_arguments() {
        let mut c = H264Config {
            passthrough: ["-f", "v4l2", "-video_size", "1280x720", "-framerate", "30"]
                .into_iter()
                .chain(["-i", "/dev/video2"])
                .map(String::from)
                .collect(),
            ..H264Config::default()
        };
        assert!(c.validate().is_ok());
        assert_eq!(c.passthrough_shape(), (1280, 720, 30.0));
        c.width = 640;
        c.height = 480;
        c.fps = 15.0;
        assert_eq!(c.passthrough_shape(), (640, 480, 15.0));
        c.passthrough = vec!["-i".into(), "x.mp4".into()];
        c.width = 0;
        c.height = 0;
        c.fps = 0.0;
        assert_eq!(c.passthrough_shape(), (0, 0, 0.0));
    }
}
