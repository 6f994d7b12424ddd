//! The choice of video paths on recorded device answers: what
//! `VIDIOC_QUERYCAP`, `VIDIOC_ENUM_FMT`, `VIDIOC_ENUM_FRAMESIZES` and
//! `VIDIOC_ENUM_FRAMEINTERVALS` return for cameras nobody has here, as
//! `v4l2-ctl --info --list-formats-ext` prints them (what the vehicle asks
//! and reads), kept in `tests/data/v4l2/`:
//! - `c920.txt`: a Logitech C920 of the firmware that lists H.264 on its
//!   capture node: YUYV, H264 and MJPG (one at a time);
//! - `openrov-mjpeg.txt`: an OpenROV-like HD camera: MJPEG only;
//! - `yuyv-webcam.txt`: a plain webcam: raw YUYV only;
//! - `h264-node.txt`: the H.264-only node of a camera that shows its
//!   encoder as a second device.
//!
//! For each: which path the H.264 (RTP, WebRTC) and the JPEG (the page)
//! take under each `[camera] encode`, what is asked of the device, and the
//! lines `/api/video` and `neptunus doctor` show.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use neptunus::camera::plan::{Offer, choose};
use neptunus::camera::v4l2::{DeviceCaps, FormatChoice, Interval, Intervals, Kind, Sizes};
use neptunus::camera::{
    CameraConfig, Encode, EncodeSetting, H264Route, JpegRoute, SourceKind, VideoPlan,
};

fn recorded(name: &str) -> DeviceCaps {
    let path = format!("{}/tests/data/v4l2/{name}.txt", env!("CARGO_MANIFEST_DIR"));
    neptunus::camera::v4l2::parse(&std::fs::read_to_string(&path).unwrap())
}

#[test]
fn the_recorded_answers_read_as_the_device_gave_them() {
    let c = recorded("c920");
    assert_eq!(
        (c.driver.as_str(), c.card.as_str()),
        ("uvcvideo", "HD Pro Webcam C920")
    );
    assert_eq!(c.fourccs(), ["YUYV", "H264", "MJPG"]);
    assert!(c.formats[1].compressed && !c.formats[0].compressed);
    let Sizes::Discrete(sizes) = &c.formats[0].sizes else {
        panic!("discrete sizes");
    };
    assert_eq!((sizes[0].width, sizes[0].height), (640, 480));
    let Intervals::Discrete(iv) = &sizes[0].intervals else {
        panic!("discrete intervals");
    };
    assert_eq!(iv.len(), 7);
    assert_eq!(iv[5], iv_of(2, 15));
    assert_eq!(recorded("openrov-mjpeg").fourccs(), ["MJPG"]);
    assert_eq!(recorded("yuyv-webcam").fourccs(), ["YUYV"]);
    assert_eq!(recorded("h264-node").fourccs(), ["H264"]);
    // What the vehicle then asks ffmpeg to read: copied, not encoded.
    let p = plan(&v4l2(EncodeSetting::Never), "c920");
    let args = neptunus::camera::v4l2::device_args("/dev/video0", p.capture.as_ref().unwrap(), 80)
        .join(" ");
    assert!(
        args.contains("-input_format h264 -video_size 640x480 -framerate 10/1 -i /dev/video0 -an -c:v copy -f h264"),
        "{args}"
    );
    assert!(!args.contains("libx264"), "{args}");
}

fn iv_of(numerator: u32, denominator: u32) -> Interval {
    Interval {
        numerator,
        denominator,
    }
}

fn v4l2(encode: EncodeSetting) -> CameraConfig {
    let mut c: CameraConfig = toml::from_str("source = \"v4l2\"").unwrap();
    c.encode = encode;
    c.validate().unwrap();
    c
}

fn plan(cfg: &CameraConfig, camera: &str) -> VideoPlan {
    choose(cfg, &Offer::Device(recorded(camera)))
}

fn iv(n: u32, d: u32) -> Interval {
    Interval {
        numerator: n,
        denominator: d,
    }
}

#[test]
fn a_camera_that_offers_h264_is_passed_through_whatever_encode_says() {
    for encode in [
        EncodeSetting::Never,
        EncodeSetting::WhenNeeded,
        EncodeSetting::Auto,
    ] {
        let cfg = v4l2(encode);
        let p = plan(&cfg, "c920");
        assert_eq!(p.h264, H264Route::Camera, "{encode:?}: {p}");
        let cap = p.capture.as_ref().unwrap();
        assert_eq!(cap.kind, Kind::H264);
        assert_eq!(cap.fourcc, "H264");
        // camera.width × height × fps: 640×480 at 10 fps, offered as such.
        assert_eq!((cap.width, cap.height, cap.interval), (640, 480, iv(1, 10)));
        assert_eq!(p.offered, ["YUYV", "H264", "MJPG"]);
        assert_eq!(p.camera.as_deref(), Some("HD Pro Webcam C920 (uvcvideo)"));
        // One format at a time: the page plays WebRTC, not MJPEG.
        assert_eq!(p.jpeg, JpegRoute::None);
        assert!(p.why.contains("as it came (no decode, no encode)"), "{p}");
        assert!(p.why.contains("the page plays WebRTC"), "{p}");
        assert_eq!(p.fix, None);
        // The doctor passes it.
        let c = neptunus::doctor::judge_video(&cfg, &p, false);
        assert!(c.ok && !c.warning, "{c:?}");
        assert!(c.detail.contains("H.264 from the camera"), "{c:?}");
    }
    // Asked for 1280×720 at 30 fps, it gets exactly that.
    let mut cfg = v4l2(EncodeSetting::Never);
    (cfg.width, cfg.height, cfg.fps) = (1280, 720, 30.0);
    let cap = plan(&cfg, "c920").capture.unwrap();
    assert_eq!(
        (cap.width, cap.height, cap.interval),
        (1280, 720, iv(1, 30))
    );
    // The H.264-only node of another camera: 640×480 at 15 is the nearest
    // to 10 fps it offers.
    let p = plan(&v4l2(EncodeSetting::Never), "h264-node");
    assert_eq!(p.h264, H264Route::Camera);
    assert_eq!(p.capture.unwrap().interval, iv(1, 15));
}

#[test]
fn an_mjpeg_only_camera_feeds_the_page_and_qgc_only_where_encoding_is_allowed() {
    let cfg = v4l2(EncodeSetting::Never);
    let p = plan(&cfg, "openrov-mjpeg");
    assert_eq!(p.jpeg, JpegRoute::Camera);
    assert_eq!(p.h264, H264Route::None);
    assert_eq!(p.capture.as_ref().unwrap().fourcc, "MJPG");
    let fix = p.fix.clone().unwrap();
    assert!(
        fix.starts_with("QGroundControl gets no video: the camera offers MJPEG only; set [camera] encode = \"when-needed\""),
        "{fix}"
    );
    assert!(fix.contains("or use an H.264 UVC camera"), "{fix}");
    assert!(
        p.why.contains("its JPEG goes to the page as it came"),
        "{p}"
    );
    // The doctor warns (the page still gets video), with the fix.
    let c = neptunus::doctor::judge_video(&cfg, &p, true);
    assert!(c.ok && c.warning, "{c:?}");
    assert_eq!(c.fix.as_deref(), Some(fix.as_str()));

    let cfg = v4l2(EncodeSetting::WhenNeeded);
    let p = plan(&cfg, "openrov-mjpeg");
    assert_eq!((p.jpeg, p.h264), (JpegRoute::Camera, H264Route::Encoder));
    assert!(p.why.contains("encoded by libx264"), "{p}");
    // The encoder is ffmpeg: without it the doctor fails, with the fix.
    let c = neptunus::doctor::judge_video(&cfg, &p, false);
    assert!(!c.ok, "{c:?}");
    assert!(c.fix.unwrap().contains("apt install ffmpeg"));
    assert!(neptunus::doctor::judge_video(&cfg, &p, true).ok);

    // The C920 asked for MJPEG: the same rules.
    let mut cfg = v4l2(EncodeSetting::Never);
    cfg.v4l2.format = FormatChoice::Mjpeg;
    let p = plan(&cfg, "c920");
    assert_eq!((p.jpeg, p.h264), (JpegRoute::Camera, H264Route::None));
}

#[test]
fn a_raw_camera_gives_nothing_unless_encoding_is_allowed() {
    let cfg = v4l2(EncodeSetting::Never);
    let p = plan(&cfg, "yuyv-webcam");
    assert!(p.is_blind(), "{p}");
    assert_eq!(p.capture, None);
    assert!(p.why.contains("raw pictures only"), "{p}");
    let fix = p.fix.clone().unwrap();
    assert!(fix.contains("encode = \"when-needed\""), "{fix}");
    assert!(fix.contains("MJPEG or H.264 UVC camera"), "{fix}");
    let c = neptunus::doctor::judge_video(&cfg, &p, true);
    assert!(!c.ok, "{c:?}");

    let p = plan(&v4l2(EncodeSetting::WhenNeeded), "yuyv-webcam");
    assert_eq!((p.jpeg, p.h264), (JpegRoute::Encoded, H264Route::Encoder));
    assert_eq!(p.capture.unwrap().fourcc, "YUYV");
}

#[test]
fn a_format_the_camera_does_not_offer_is_named_with_what_it_does() {
    let mut cfg = v4l2(EncodeSetting::WhenNeeded);
    cfg.v4l2.format = FormatChoice::Yuyv;
    let p = plan(&cfg, "h264-node");
    assert!(p.is_blind());
    assert!(p.why.contains("offers H264 but not YUYV"), "{p}");
    assert!(p.fix.unwrap().contains("camera.v4l2.format = \"auto\""));
}

#[test]
fn with_a_passthrough_elsewhere_the_camera_is_asked_for_jpeg() {
    // The old way of naming an H.264 camera still works, and the v4l2
    // camera then serves the page.
    let cfg: CameraConfig = toml::from_str(
        "source = \"v4l2\"\nencode = \"never\"\n[h264]\npassthrough = [\"-f\", \"v4l2\", \"-input_format\", \"h264\", \"-i\", \"/dev/video2\"]\n",
    )
    .unwrap();
    cfg.validate().unwrap();
    let p = plan(&cfg, "c920");
    assert_eq!((p.jpeg, p.h264), (JpegRoute::Camera, H264Route::FfmpegCopy));
    assert!(p.why.contains("copied without decoding"), "{p}");
}

#[test]
fn an_unreadable_device_leaves_the_choice_for_later_and_a_recording_needs_its_format() {
    let cfg = v4l2(EncodeSetting::Never);
    let p = choose(
        &cfg,
        &Offer::Unreadable("camera device /dev/video0 does not exist".into()),
    );
    assert_eq!((p.h264, p.jpeg), (H264Route::Pending, JpegRoute::Pending));
    assert!(p.fix.unwrap().contains("plug in the camera"));

    let p = choose(&cfg, &Offer::Recorded);
    assert_eq!(p.capture, None);
    assert!(p.fix.unwrap().contains("camera.v4l2.format = \"h264\""));
    let mut cfg = cfg;
    cfg.v4l2.format = FormatChoice::H264;
    cfg.fps = 30.0;
    let p = choose(&cfg, &Offer::Recorded);
    assert_eq!(p.h264, H264Route::Camera);
    let cap = p.capture.unwrap();
    assert_eq!((cap.width, cap.height, cap.fps()), (640, 480, 30.0));
    assert!(
        p.why.contains("read as a recorded H.264 stream"),
        "{}",
        p.why
    );
}

#[test]
fn pictures_drawn_or_from_a_program_are_encoded_only_where_allowed() {
    let mut cfg = CameraConfig::synthetic();
    cfg.encode = EncodeSetting::Never;
    let p = choose(&cfg, &Offer::NotV4l2);
    assert_eq!((p.jpeg, p.h264), (JpegRoute::Synthetic, H264Route::None));
    assert!(p.fix.unwrap().contains("encode = \"when-needed\""));
    cfg.encode = EncodeSetting::WhenNeeded;
    assert_eq!(choose(&cfg, &Offer::NotV4l2).h264, H264Route::Encoder);
    cfg.source = SourceKind::MjpgStreamer;
    let p = choose(&cfg, &Offer::NotV4l2);
    assert_eq!((p.jpeg, p.h264), (JpegRoute::Program, H264Route::Encoder));
    // auto: never on the BeagleBone's 32-bit ARM build, when needed here.
    let want = if cfg!(target_arch = "arm") {
        Encode::Never
    } else {
        Encode::WhenNeeded
    };
    assert_eq!(EncodeSetting::Auto.resolve(), want);
    assert_eq!(CameraConfig::default().encode, EncodeSetting::Auto);
}

#[test]
fn the_settings_parse_and_bad_ones_are_named() {
    let c: CameraConfig =
        toml::from_str("source = \"v4l2\"\nencode = \"when-needed\"\n[v4l2]\ndevice = \"/dev/video2\"\nformat = \"mjpeg\"\n")
            .unwrap();
    assert_eq!(c.source, SourceKind::V4l2);
    assert_eq!(c.encode, EncodeSetting::WhenNeeded);
    assert_eq!(c.v4l2.device, "/dev/video2");
    assert_eq!(c.v4l2.format, FormatChoice::Mjpeg);
    let e = toml::from_str::<CameraConfig>("encode = \"sometimes\"").unwrap_err();
    assert!(e.to_string().contains("sometimes"), "{e}");
    let e = toml::from_str::<CameraConfig>("[v4l2]\nformat = \"h265\"").unwrap_err();
    assert!(e.to_string().contains("h265"), "{e}");
    let c: CameraConfig = toml::from_str("source = \"v4l2\"\n[v4l2]\ndevice = \" \"").unwrap();
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("camera.v4l2.device is empty"), "{e}");
}

#[test]
fn api_video_tells_the_path_and_what_runs() {
    let p = plan(&v4l2(EncodeSetting::Never), "c920");
    let v = neptunus::camera::api_json(&p, None, Some("constrained baseline 42c01e".into()));
    assert_eq!(v["mjpeg"], false);
    assert_eq!(v["path"]["h264"], "camera");
    assert_eq!(v["path"]["jpeg"], "none");
    assert_eq!(v["path"]["encode"], "never");
    assert_eq!(v["path"]["capture"]["fourcc"], "H264");
    assert_eq!(v["path"]["capture"]["interval"], "1/10");
    assert_eq!(v["path"]["offered"][1], "H264");
    assert_eq!(v["encoder_running"], false);
    assert_eq!(v["h264_profile"], "constrained baseline 42c01e");
    assert!(
        v["path"]["why"]
            .as_str()
            .unwrap()
            .contains("no decode, no encode")
    );
}
