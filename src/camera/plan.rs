//! Which way each picture takes, and why: the choice between passing the
//! camera's own H.264 or JPEG through and encoding, made from what the
//! camera offers and `[camera] encode`.
//!
//! Pure: [`choose`] is a function of the configuration and the device's
//! answers ([`Offer`]), so it is tested on recorded answers of cameras
//! nobody has here. The log, `GET /api/video` and `neptunus doctor` all
//! tell the one [`VideoPlan`] it returns.
//!
//! The rules: a camera's H.264 is never decoded or encoded again; a
//! camera's JPEG goes to the page as it came; an encoder (libx264 for
//! RTP and WebRTC, JPEG for a raw camera's page) runs only where `encode`
//! allows it, and by default not on the BeagleBone.

use std::fmt;

use serde::Serialize;

use super::config::{CameraConfig, SourceKind};
pub use super::encode::{Encode, EncodeSetting};
use super::v4l2::{
    Capture, DeviceCaps, FormatChoice, Interval, Kind, Node, V4l2Config, node, probe,
};

/// Where the H.264 for QGroundControl (RTP) and the WebRTC viewers comes
/// from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum H264Route {
    /// The camera's own H.264 (`source = "v4l2"`), as it came.
    Camera,
    /// `[camera.h264] passthrough`: ffmpeg reads a camera that gives H.264
    /// and copies it (`-c:v copy`), no decode, no encode.
    FfmpegCopy,
    /// The camera's pictures encoded by ffmpeg's libx264.
    Encoder,
    /// No H.264: QGroundControl and WebRTC get no video (`why` says why).
    None,
    /// The camera device did not answer yet: decided when it does.
    Pending,
}

/// Where `/video.mjpg`'s JPEG pictures (the page's fallback, Cockpit's
/// image widget, snapshots) come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum JpegRoute {
    /// The camera's own JPEG, as it came.
    Camera,
    /// A raw camera's pictures, JPEG-encoded by Neptunus.
    Encoded,
    /// Drawn from the simulator.
    Synthetic,
    /// What a camera program (`ffmpeg`, `mjpg-streamer`) or stream (`url`)
    /// gives.
    Program,
    /// No JPEG pictures (`why` says why).
    None,
    Pending,
}

/// What the camera offers, as far as it is known.
#[derive(Debug, Clone, PartialEq)]
pub enum Offer {
    /// The source is not a V4L2 device Neptunus reads.
    NotV4l2,
    /// A V4L2 device's answers.
    Device(DeviceCaps),
    /// A file or pipe in place of the device: a recorded stream of the
    /// format `camera.v4l2.format` names.
    Recorded,
    /// The device did not answer (missing, busy, not a camera).
    Unreadable(String),
}

/// The choice, and the reasons a person reads.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VideoPlan {
    pub encode_setting: EncodeSetting,
    /// What `encode_setting` comes to on this build.
    pub encode: Encode,
    pub source: SourceKind,
    /// `camera.v4l2.device` (`source = "v4l2"`).
    pub device: Option<String>,
    /// The camera's name and driver, when it answered.
    pub camera: Option<String>,
    /// The formats the camera offers (fourcc), in its order.
    pub offered: Vec<String>,
    /// What the camera is asked for.
    pub capture: Option<Capture>,
    pub h264: H264Route,
    pub jpeg: JpegRoute,
    /// One sentence: the path taken and why.
    pub why: String,
    /// What to change when a viewer gets no video.
    pub fix: Option<String>,
}

/// The fix when only an encoder could make H.264.
fn h264_fix(what: &str) -> String {
    format!(
        "QGroundControl gets no video: {what}; set [camera] encode = \"when-needed\" (libx264 on the vehicle's CPU: too slow for a BeagleBone) or use an H.264 UVC camera"
    )
}

/// Chooses the paths for `cfg` and what the camera offers.
pub fn choose(cfg: &CameraConfig, offer: &Offer) -> VideoPlan {
    let encode = cfg.encode.resolve();
    let copy = !cfg.h264.passthrough.is_empty();
    let mut plan = VideoPlan {
        encode_setting: cfg.encode,
        encode,
        source: cfg.source,
        device: (cfg.source == SourceKind::V4l2).then(|| cfg.v4l2.device.clone()),
        camera: None,
        offered: Vec::new(),
        capture: None,
        h264: H264Route::None,
        jpeg: JpegRoute::None,
        why: String::new(),
        fix: None,
    };
    // H.264 for pictures that are not H.264: the explicit pass-through, or
    // the encoder where allowed.
    let h264_for_pictures = |plan: &mut VideoPlan, what: &str| {
        if copy {
            plan.h264 = H264Route::FfmpegCopy;
            format!(
                "H.264 from the camera ffmpeg reads ([camera.h264] passthrough), copied without decoding; {what}"
            )
        } else if encode == Encode::WhenNeeded {
            plan.h264 = H264Route::Encoder;
            format!(
                "{what}; H.264 for QGroundControl and WebRTC encoded by libx264 (encode = \"{}\")",
                cfg.encode.as_str()
            )
        } else {
            plan.h264 = H264Route::None;
            plan.fix = Some(h264_fix(what));
            format!(
                "{what}; no H.264 for QGroundControl or WebRTC: nothing is encoded (encode = \"{}\"{})",
                cfg.encode.as_str(),
                auto_note(cfg.encode)
            )
        }
    };
    match cfg.source {
        SourceKind::None => {
            plan.why = if copy {
                plan.h264 = H264Route::FfmpegCopy;
                "no JPEG camera (source = \"none\"); H.264 from the camera ffmpeg reads ([camera.h264] passthrough), copied without decoding".into()
            } else {
                "no camera (camera.source = \"none\")".into()
            };
        }
        SourceKind::Synthetic => {
            plan.jpeg = JpegRoute::Synthetic;
            plan.why = h264_for_pictures(&mut plan, "the synthetic camera draws JPEG pictures");
        }
        SourceKind::Ffmpeg | SourceKind::MjpgStreamer | SourceKind::Url => {
            plan.jpeg = JpegRoute::Program;
            let what = format!("the {} source gives JPEG pictures", cfg.source);
            plan.why = h264_for_pictures(&mut plan, &what);
        }
        SourceKind::V4l2 => choose_v4l2(cfg, offer, &mut plan, copy, h264_for_pictures),
    }
    plan
}

fn auto_note(s: EncodeSetting) -> &'static str {
    if s == EncodeSetting::Auto {
        if cfg!(target_arch = "arm") {
            ": auto is never on this 32-bit ARM build"
        } else {
            ""
        }
    } else {
        ""
    }
}

fn choose_v4l2(
    cfg: &CameraConfig,
    offer: &Offer,
    plan: &mut VideoPlan,
    copy: bool,
    h264_for_pictures: impl Fn(&mut VideoPlan, &str) -> String,
) {
    let dev = cfg.v4l2.device.as_str();
    let caps = match offer {
        Offer::Device(caps) => {
            plan.camera = Some(format!("{} ({})", caps.card, caps.driver));
            plan.offered = caps.fourccs();
            caps.clone()
        }
        Offer::Recorded => {
            let Some(kind) = cfg.v4l2.format.kind().filter(|k| *k != Kind::Yuyv) else {
                plan.why = format!(
                    "{dev} is not a V4L2 device, and camera.v4l2.format = \"{}\" does not say what it holds",
                    cfg.v4l2.format.as_str()
                );
                plan.fix = Some("set camera.v4l2.format = \"h264\" or \"mjpeg\" for a recorded stream, or name the camera's /dev/videoN".into());
                return;
            };
            plan.offered = vec![fourcc(kind).into()];
            plan.capture = Some(Capture {
                kind,
                fourcc: fourcc(kind).into(),
                width: cfg.width,
                height: cfg.height,
                interval: Interval::from_fps(cfg.fps),
            });
            let what = format!(
                "{dev} is not a V4L2 device: read as a recorded {} stream at {} fps",
                kind_name(kind),
                cfg.fps
            );
            after_capture(plan, kind, &what, h264_for_pictures);
            return;
        }
        Offer::Unreadable(e) => {
            plan.h264 = if copy {
                H264Route::FfmpegCopy
            } else {
                H264Route::Pending
            };
            plan.jpeg = JpegRoute::Pending;
            plan.why = format!("{e}: the path is chosen when the camera answers");
            plan.fix = Some(format!(
                "plug in the camera, or name its device in camera.v4l2.device (`v4l2-ctl --list-devices`); `ls -l {dev}`"
            ));
            return;
        }
        Offer::NotV4l2 => {
            plan.why = "the camera is not read through V4L2".into();
            return;
        }
    };
    let usable: Vec<Kind> = caps
        .formats
        .iter()
        .filter_map(|f| Kind::of_fourcc(&f.fourcc))
        .collect();
    let kind = match cfg.v4l2.format.kind() {
        Some(k) if usable.contains(&k) => k,
        Some(k) => {
            plan.why = format!(
                "{dev} offers {} but not {} (camera.v4l2.format = \"{}\")",
                list(&plan.offered),
                fourcc(k),
                cfg.v4l2.format.as_str()
            );
            plan.fix =
                Some("set camera.v4l2.format = \"auto\" or to a format the camera offers".into());
            return;
        }
        None => {
            // H.264 first: nothing to encode; then JPEG for the page.
            let order: &[Kind] = if copy {
                &[Kind::Mjpeg, Kind::Yuyv, Kind::H264]
            } else {
                &[Kind::H264, Kind::Mjpeg, Kind::Yuyv]
            };
            match order.iter().find(|k| usable.contains(k)) {
                Some(k) => *k,
                None => {
                    plan.why = format!(
                        "{dev} offers no format Neptunus reads ({}; H264, MJPG, JPEG or YUYV wanted)",
                        list(&plan.offered)
                    );
                    plan.fix = Some("use a UVC camera that gives H.264 or MJPEG (the OpenROV camera gives MJPEG)".into());
                    return;
                }
            }
        }
    };
    if kind == Kind::Yuyv && plan.encode == Encode::Never && !copy {
        plan.why = format!(
            "{dev} offers {}: raw pictures only, and nothing is encoded (encode = \"{}\"{})",
            list(&plan.offered),
            cfg.encode.as_str(),
            auto_note(cfg.encode)
        );
        plan.fix = Some("neither the page nor QGroundControl gets video: the camera offers raw YUYV only; set [camera] encode = \"when-needed\" (costly on a BeagleBone) or use an MJPEG or H.264 UVC camera".into());
        return;
    }
    let Some(format) = caps.format(kind) else {
        return;
    };
    let Some((w, h, interval)) = format.nearest(cfg.width, cfg.height, cfg.fps) else {
        plan.why = format!(
            "{dev} lists {} without a usable size or frame interval",
            format.fourcc
        );
        plan.fix = Some("check the camera with `v4l2-ctl --list-formats-ext`".into());
        return;
    };
    plan.capture = Some(Capture {
        kind,
        fourcc: format.fourcc.clone(),
        width: w,
        height: h,
        interval,
    });
    let what = format!(
        "{dev} offers {}: {} {w}×{h} at {} fps",
        list(&plan.offered),
        format.fourcc,
        round_fps(interval.fps())
    );
    after_capture(plan, kind, &what, h264_for_pictures);
}

fn after_capture(
    plan: &mut VideoPlan,
    kind: Kind,
    what: &str,
    h264_for_pictures: impl Fn(&mut VideoPlan, &str) -> String,
) {
    match kind {
        Kind::H264 => {
            plan.h264 = H264Route::Camera;
            plan.jpeg = JpegRoute::None;
            plan.why = format!(
                "{what}; its H.264 goes to QGroundControl and WebRTC as it came (no decode, no encode); no JPEG pictures (a camera streams one format at a time): the page plays WebRTC"
            );
        }
        Kind::Mjpeg => {
            plan.jpeg = JpegRoute::Camera;
            let w = format!("{what}; its JPEG goes to the page as it came");
            plan.why = h264_for_pictures(plan, &w);
            if plan.h264 == H264Route::None {
                plan.fix = Some(h264_fix("the camera offers MJPEG only"));
            }
        }
        Kind::Yuyv => {
            plan.jpeg = JpegRoute::Encoded;
            let w = format!("{what}; raw pictures JPEG-encoded for the page");
            plan.why = h264_for_pictures(plan, &w);
        }
    }
}

fn fourcc(k: Kind) -> &'static str {
    match k {
        Kind::H264 => "H264",
        Kind::Mjpeg => "MJPG",
        Kind::Yuyv => "YUYV",
    }
}

fn kind_name(k: Kind) -> &'static str {
    match k {
        Kind::H264 => "H.264",
        Kind::Mjpeg => "MJPEG",
        Kind::Yuyv => "YUYV",
    }
}

fn list(v: &[String]) -> String {
    if v.is_empty() {
        "no format".into()
    } else {
        v.join(", ")
    }
}

fn round_fps(f: f64) -> String {
    if (f - f.round()).abs() < 0.01 {
        format!("{}", f.round())
    } else {
        format!("{f:.2}")
    }
}

/// The choice at the start: a `v4l2` camera is asked what it offers
/// (blocking: a few ioctls), any other source needs no asking.
pub fn initial(cfg: &CameraConfig) -> VideoPlan {
    let offer = if cfg.source == SourceKind::V4l2 {
        offer(&cfg.v4l2)
    } else {
        Offer::NotV4l2
    };
    choose(cfg, &offer)
}

/// What the camera at `cfg.device` offers (blocking: a few ioctls).
pub fn offer(cfg: &V4l2Config) -> Offer {
    let path = std::path::Path::new(&cfg.device);
    match node(path) {
        Node::File | Node::Pipe => Offer::Recorded,
        Node::Missing => Offer::Unreadable(format!("camera device {} does not exist", cfg.device)),
        Node::Device => match probe(path) {
            Ok(caps) => Offer::Device(caps),
            Err(e) => Offer::Unreadable(e.to_string()),
        },
    }
}

impl VideoPlan {
    /// Neither path gives pictures and the reason is known.
    pub fn is_blind(&self) -> bool {
        self.h264 == H264Route::None && self.jpeg == JpegRoute::None
    }
}

impl fmt::Display for VideoPlan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "video: H.264 {}, JPEG {} — {}",
            route_name(self.h264),
            jpeg_name(self.jpeg),
            self.why
        )
    }
}

fn route_name(r: H264Route) -> &'static str {
    match r {
        H264Route::Camera => "from the camera",
        H264Route::FfmpegCopy => "copied by ffmpeg",
        H264Route::Encoder => "encoded",
        H264Route::None => "none",
        H264Route::Pending => "pending",
    }
}

fn jpeg_name(r: JpegRoute) -> &'static str {
    match r {
        JpegRoute::Camera => "from the camera",
        JpegRoute::Encoded => "encoded",
        JpegRoute::Synthetic => "synthetic",
        JpegRoute::Program => "from the camera program",
        JpegRoute::None => "none",
        JpegRoute::Pending => "pending",
    }
}

/// A recorded-answers helper for `FormatChoice` in messages.
impl FormatChoice {
    pub fn kind(self) -> Option<Kind> {
        match self {
            FormatChoice::Auto => None,
            FormatChoice::H264 => Some(Kind::H264),
            FormatChoice::Mjpeg => Some(Kind::Mjpeg),
            FormatChoice::Yuyv => Some(Kind::Yuyv),
        }
    }
}
