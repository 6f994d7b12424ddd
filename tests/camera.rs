//! The camera over real HTTP: the synthetic source, `/video.mjpg`,
//! `/snapshot.jpg` and `/camera/status`, ffmpeg as a supervised child, the
//! backoff on a missing program, a `url` source reading another camera, a
//! stand-in mjpg-streamer, and the JPEG splitter under random chunking.
//!
//! Servers bind 127.0.0.1:0. Waits are for events (a frame, a state) with a
//! generous give-up deadline, never a sleep standing in for timing; the
//! frame-rate and backoff checks run on paused tokio time.

use std::net::SocketAddr;
use std::time::Duration;

use bytes::{Bytes, BytesMut};
use http_body_util::{BodyExt, Empty};
use hyper::body::Incoming;
use hyper_util::rt::TokioIo;
use jpeg_encoder::{ColorType, Encoder};
use neptunus::camera::{Camera, CameraConfig, CameraState, Frame, JpegSplitter, Scene, SourceKind};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde_json::Value;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tokio::time::timeout;

/// Give-up time for anything that should happen within a second or two.
const GIVE_UP: Duration = Duration::from_secs(30);

// ---------------------------------------------------------------- helpers

async fn serve(router: axum::Router) -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("addr");
    tokio::spawn(async move {
        axum::serve(listener, router).await.expect("serve");
    });
    addr
}

async fn request(addr: SocketAddr, path: &str) -> hyper::Response<Incoming> {
    let tcp = TcpStream::connect(addr).await.expect("connect");
    let (mut sender, conn) = hyper::client::conn::http1::handshake(TokioIo::new(tcp))
        .await
        .expect("handshake");
    tokio::spawn(conn);
    let req = hyper::Request::get(path)
        .header("host", addr.to_string())
        .body(Empty::<Bytes>::new())
        .expect("request");
    sender.send_request(req).await.expect("response")
}

/// Status code, content type and whole body.
async fn get(addr: SocketAddr, path: &str) -> (u16, String, Bytes) {
    let resp = timeout(GIVE_UP, request(addr, path))
        .await
        .expect("in time");
    let status = resp.status().as_u16();
    let ct = content_type(&resp);
    let body = timeout(GIVE_UP, resp.into_body().collect())
        .await
        .expect("in time")
        .expect("body")
        .to_bytes();
    (status, ct, body)
}

async fn get_json(addr: SocketAddr, path: &str) -> (u16, Value) {
    let (status, ct, body) = get(addr, path).await;
    assert_eq!(ct, "application/json", "{path}");
    (status, serde_json::from_slice(&body).expect("json"))
}

fn content_type<B>(resp: &hyper::Response<B>) -> String {
    resp.headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_owned()
}

/// A strict reader of `/video.mjpg`: every part must be
/// `--BOUNDARY`, `Content-Type: image/jpeg`, `Content-Length: N`, then N bytes.
struct MjpegReader {
    body: Incoming,
    buf: BytesMut,
    boundary: String,
}

struct Part {
    content_type: String,
    jpeg: Bytes,
}

impl MjpegReader {
    async fn open(addr: SocketAddr) -> MjpegReader {
        let resp = timeout(GIVE_UP, request(addr, "/video.mjpg"))
            .await
            .expect("in time");
        assert_eq!(resp.status(), 200);
        let ct = content_type(&resp);
        let boundary = ct
            .strip_prefix("multipart/x-mixed-replace; boundary=")
            .unwrap_or_else(|| panic!("content type {ct}"))
            .to_owned();
        MjpegReader {
            body: resp.into_body(),
            buf: BytesMut::new(),
            boundary,
        }
    }

    async fn fill(&mut self, n: usize) {
        while self.buf.len() < n {
            let frame = timeout(GIVE_UP, self.body.frame())
                .await
                .expect("a frame in time")
                .expect("the stream goes on")
                .expect("no error");
            if let Ok(data) = frame.into_data() {
                self.buf.extend_from_slice(&data);
            }
        }
    }

    async fn line(&mut self) -> String {
        loop {
            if let Some(i) = self.buf.windows(2).position(|w| w == b"\r\n") {
                let line = self.buf.split_to(i + 2);
                return String::from_utf8(line[..i].to_vec()).expect("header text");
            }
            let more = self.buf.len() + 1;
            self.fill(more).await;
        }
    }

    async fn next_part(&mut self) -> Part {
        let mut first = self.line().await;
        if first.is_empty() {
            // The CRLF that ends the previous part.
            first = self.line().await;
        }
        assert_eq!(first, format!("--{}", self.boundary));
        let mut content_type = String::new();
        let mut len = None;
        loop {
            let line = self.line().await;
            if line.is_empty() {
                break;
            }
            let (k, v) = line.split_once(':').expect("header");
            match k.trim().to_ascii_lowercase().as_str() {
                "content-type" => content_type = v.trim().to_owned(),
                "content-length" => len = Some(v.trim().parse::<usize>().expect("length")),
                _ => {}
            }
        }
        let len = len.expect("every part has a Content-Length");
        self.fill(len).await;
        let jpeg = self.buf.split_to(len).freeze();
        Part { content_type, jpeg }
    }
}

struct Decoded {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

fn decode(jpeg: &[u8]) -> Decoded {
    let mut d = jpeg_decoder::Decoder::new(jpeg);
    let rgb = d.decode().expect("a valid JPEG");
    let info = d.info().expect("info");
    assert_eq!(info.pixel_format, jpeg_decoder::PixelFormat::RGB24);
    Decoded {
        width: usize::from(info.width),
        height: usize::from(info.height),
        rgb,
    }
}

impl Decoded {
    fn luma(&self, x: usize, y: usize) -> f64 {
        let i = (y * self.width + x) * 3;
        let p = &self.rgb[i..i + 3];
        0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2])
    }

    /// Mean luma of a 9×9 block, so JPEG noise does not decide a test.
    fn area(&self, x: usize, y: usize) -> f64 {
        let mut sum = 0.0;
        for yy in y - 4..=y + 4 {
            for xx in x - 4..=x + 4 {
                sum += self.luma(xx, yy);
            }
        }
        sum / 81.0
    }
}

fn synthetic(width: u32, height: u32, fps: f64) -> CameraConfig {
    CameraConfig {
        width,
        height,
        fps,
        ..CameraConfig::synthetic()
    }
}

/// The first frame with a sequence number above `after`.
async fn frame_after(frames: &mut watch::Receiver<Option<Frame>>, after: u64) -> Frame {
    let f = timeout(
        GIVE_UP,
        frames.wait_for(|f| f.as_ref().is_some_and(|f| f.seq > after)),
    )
    .await
    .expect("a frame in time")
    .expect("camera running");
    f.clone().expect("some")
}

/// Waits for a condition on the status; the status has no channel of its
/// own, so this polls it (the wait is for a state, not for a duration).
async fn status_until(
    camera: &Camera,
    what: &str,
    ok: impl Fn(&neptunus::camera::CameraStatus) -> bool,
) -> neptunus::camera::CameraStatus {
    let deadline = tokio::time::Instant::now() + GIVE_UP;
    loop {
        let s = camera.status();
        if ok(&s) {
            return s;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "gave up waiting for {what}: {s:?}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

fn need_ffmpeg() {
    let found = std::process::Command::new("ffmpeg")
        .arg("-version")
        .stdout(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        found,
        "ffmpeg is not on PATH — tests/run_all.sh installs it (apt-get install ffmpeg)"
    );
}

// ---------------------------------------------------------------- synthetic

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn synthetic_frames_arrive_over_http_at_the_configured_size() {
    let (_scene_tx, scene) = watch::channel(Scene {
        simulated: true,
        ..Scene::default()
    });
    let camera = Camera::start(synthetic(320, 240, 10.0), scene);
    let addr = serve(camera.routes()).await;

    let mut video = MjpegReader::open(addr).await;
    for _ in 0..5 {
        let part = video.next_part().await;
        assert_eq!(part.content_type, "image/jpeg");
        let img = decode(&part.jpeg);
        assert_eq!((img.width, img.height), (320, 240));
        assert_eq!(img.rgb.len(), 320 * 240 * 3);
    }

    let (code, status) = get_json(addr, "/camera/status").await;
    assert_eq!(code, 200);
    for key in [
        "source",
        "state",
        "fps",
        "frame_age_ms",
        "frames_total",
        "restarts",
        "last_error",
        "rotation_deg",
        "width",
        "height",
        "pid",
        "retry_in_ms",
        "viewers",
    ] {
        assert!(status.get(key).is_some(), "status lacks {key}: {status}");
    }
    assert_eq!(status["source"], "synthetic");
    assert_eq!(status["state"], "streaming");
    assert_eq!(status["rotation_deg"], 0);
    assert_eq!(
        (status["width"].as_u64(), status["height"].as_u64()),
        (Some(320), Some(240))
    );
    assert!(status["frames_total"].as_u64() >= Some(5), "{status}");
    assert!(status["frame_age_ms"].as_u64().is_some(), "{status}");
    assert_eq!(status["restarts"], 0);
    assert_eq!(status["viewers"], 1);
    assert!(status["last_error"].is_null());

    // Over a couple of seconds of real time the rate is near 10 fps; the
    // bound is loose because the machine is shared (the exact check is the
    // paused-time test below).
    for _ in 0..20 {
        video.next_part().await;
    }
    let fps = camera.status().fps;
    assert!((3.0..=20.0).contains(&fps), "fps {fps}");

    // The viewer goes away: its stream ends and it is no longer counted.
    drop(video);
    status_until(&camera, "the viewer to be gone", |s| s.viewers == 0).await;
}

#[tokio::test(start_paused = true)]
async fn frame_rate_and_age_are_measured() {
    let (_scene_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start(synthetic(160, 120, 10.0), scene);
    tokio::time::sleep(Duration::from_secs(5)).await;
    let s = camera.status();
    assert_eq!(s.state, CameraState::Streaming);
    assert!((9.5..=10.5).contains(&s.fps), "{s:?}");
    assert!((49..=52).contains(&s.frames_total), "{s:?}");
    let age = s.frame_age_ms.expect("age");
    assert!(age <= 100, "{s:?}");
    tokio::time::sleep(Duration::from_millis(30)).await;
    let t = camera.telemetry();
    assert_eq!(t.state, CameraState::Streaming);
    assert!(t.frame_age_ms.expect("age") <= 100);
    assert!(t.frames_total >= s.frames_total);
    let latest = camera.latest().expect("a frame");
    assert_eq!((latest.width, latest.height), (160, 120));
    assert_eq!(latest.seq, t.frames_total);
}

/// Started on demand (as the vehicle starts it), the synthetic camera
/// draws nothing until someone wants frames, and stops a few seconds after
/// the last one left.
#[tokio::test(start_paused = true)]
async fn a_camera_on_demand_draws_only_while_frames_are_wanted() {
    let (_scene_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start_on_demand(synthetic(160, 120, 10.0), scene);
    tokio::time::sleep(Duration::from_secs(3)).await;
    let s = camera.status();
    assert_eq!((s.state, s.frames_total), (CameraState::Idle, 0), "{s:?}");

    let wanted = camera.demand();
    tokio::time::sleep(Duration::from_secs(2)).await;
    let s = camera.status();
    assert_eq!(s.state, CameraState::Streaming);
    assert!((19..=22).contains(&s.frames_total), "{s:?}");

    drop(wanted);
    // A moment later (a page reload) it still runs ...
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert_eq!(camera.status().state, CameraState::Streaming);
    // ... and then stops: no more frames are drawn.
    tokio::time::sleep(Duration::from_secs(3)).await;
    let stopped = camera.status();
    assert_eq!(stopped.state, CameraState::Idle, "{stopped:?}");
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert_eq!(camera.status().frames_total, stopped.frames_total);
}

/// A `/video.mjpg` viewer is someone who wants frames.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_viewer_starts_a_camera_on_demand() {
    let (_scene_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start_on_demand(synthetic(160, 120, 10.0), scene);
    let addr = serve(camera.routes()).await;
    let (_, status) = get_json(addr, "/camera/status").await;
    assert_eq!(status["state"], "idle", "{status}");
    let mut video = MjpegReader::open(addr).await;
    let part = video.next_part().await;
    assert_eq!(decode(&part.jpeg).width, 160);
    let (_, status) = get_json(addr, "/camera/status").await;
    assert_eq!(
        (&status["state"], &status["viewers"]),
        (&Value::from("streaming"), &Value::from(1))
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_picture_follows_heading_roll_and_pitch() {
    let (scene_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start(synthetic(320, 240, 20.0), scene);
    let addr = serve(camera.routes()).await;
    let mut frames = camera.subscribe();

    // A frame rendered after the change: a render may be under way when the
    // scene changes, so skip one.
    let mut snapshot_of = async |s: Scene| {
        let seq = frame_after(&mut frames, 0).await.seq;
        scene_tx.send_replace(s);
        let seq = frame_after(&mut frames, seq + 1).await.seq;
        let (code, ct, body) = get(addr, "/snapshot.jpg").await;
        assert_eq!((code, ct.as_str()), (200, "image/jpeg"));
        let img = decode(&body);
        assert_eq!((img.width, img.height), (320, 240));
        assert!(camera.latest().expect("frame").seq >= seq);
        img
    };

    let level = snapshot_of(Scene::default()).await;
    let east = snapshot_of(Scene {
        heading_deg: 90.0,
        ..Scene::default()
    })
    .await;
    // The light shafts high above the horizon (top rows) swept across as
    // the vehicle turned; count clearly different pixels.
    let tape_rows = 20 * 320 * 3;
    let changed = level.rgb[..tape_rows]
        .iter()
        .zip(&east.rgb[..tape_rows])
        .filter(|(a, b)| a.abs_diff(**b) > 40)
        .count();
    assert!(changed > 200, "only {changed} tape bytes changed");

    let (left, right, y) = (60, 260, 110);
    let flat = level.area(left, y) - level.area(right, y);
    assert!(flat.abs() < 4.0, "level horizon: {flat}");
    let rolled = snapshot_of(Scene {
        roll_deg: 20.0,
        ..Scene::default()
    })
    .await;
    // Starboard down: the horizon's right end rises above row 110, so the
    // right side there shows the darker water below the horizon.
    let tilt = rolled.area(left, y) - rolled.area(right, y);
    assert!(tilt > 15.0, "rolled horizon: {tilt}");

    let nose_up = snapshot_of(Scene {
        pitch_deg: 10.0,
        ..Scene::default()
    })
    .await;
    assert!(
        nose_up.area(left, 135) > level.area(left, 135) + 15.0,
        "nose up moves the horizon down: {} vs {}",
        nose_up.area(left, 135),
        level.area(left, 135)
    );
}

// ---------------------------------------------------------------- no camera

#[tokio::test]
async fn no_camera_answers_503_with_the_reason() {
    let (_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start(CameraConfig::none(), scene);
    let addr = serve(camera.routes()).await;
    for path in ["/video.mjpg", "/snapshot.jpg"] {
        let (code, body) = get_json(addr, path).await;
        assert_eq!(code, 503, "{path}");
        let reason = body["error"].as_str().expect("error text");
        assert!(reason.contains("camera.source is \"none\""), "{reason}");
        assert!(reason.contains("\"synthetic\""), "{reason}");
        assert_eq!(body["source"], "none");
    }
    let (code, status) = get_json(addr, "/camera/status").await;
    assert_eq!(code, 200);
    assert_eq!(status["state"], "off");
    assert!(camera.latest().is_none());
}

#[tokio::test]
async fn an_invalid_configuration_fails_visibly_without_panicking() {
    let (_tx, scene) = watch::channel(Scene::default());
    let cfg = CameraConfig {
        rotation_deg: 45,
        ..CameraConfig::synthetic()
    };
    let camera = Camera::start(cfg, scene);
    let s = camera.status();
    assert_eq!(s.state, CameraState::Failed);
    let err = s.last_error.expect("the reason");
    assert!(err.contains("rotation_deg = 45"), "{err}");
    let addr = serve(camera.routes()).await;
    let (code, body) = get_json(addr, "/snapshot.jpg").await;
    assert_eq!(code, 503);
    assert!(
        body["error"]
            .as_str()
            .is_some_and(|e| e.contains("rotation_deg = 45")),
        "{body}"
    );
}

#[tokio::test]
async fn rotation_is_reported_for_the_page() {
    let (_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start(
        CameraConfig {
            rotation_deg: 180,
            ..CameraConfig::none()
        },
        scene,
    );
    let addr = serve(camera.routes()).await;
    let (_, status) = get_json(addr, "/camera/status").await;
    assert_eq!(status["rotation_deg"], 180);
}

// ---------------------------------------------------------------- ffmpeg

fn ffmpeg_testsrc() -> CameraConfig {
    let mut cfg = CameraConfig {
        source: SourceKind::Ffmpeg,
        ..CameraConfig::default()
    };
    // -re: read the test source at its own rate, not as fast as possible.
    cfg.ffmpeg.input_args = ["-re", "-f", "lavfi", "-i", "testsrc=size=320x240:rate=10"]
        .map(String::from)
        .to_vec();
    cfg
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ffmpeg_frames_are_served_and_a_killed_child_is_restarted() {
    need_ffmpeg();
    let (_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start(ffmpeg_testsrc(), scene);
    let addr = serve(camera.routes()).await;
    let mut video = MjpegReader::open(addr).await;
    for _ in 0..3 {
        let img = decode(&video.next_part().await.jpeg);
        assert_eq!((img.width, img.height), (320, 240));
    }
    let before = camera.status();
    assert_eq!(before.state, CameraState::Streaming);
    assert_eq!(before.restarts, 0);
    let pid = before.pid.expect("the child's pid");

    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(i32::try_from(pid).expect("pid")),
        nix::sys::signal::Signal::SIGKILL,
    )
    .expect("kill the child");

    let after = status_until(&camera, "a new ffmpeg", |s| {
        s.restarts >= 1 && s.pid.is_some_and(|p| p != pid)
    })
    .await;
    let err = after.last_error.expect("why it restarted");
    assert!(
        err.contains("camera source ffmpeg: `ffmpeg` exited"),
        "{err}"
    );
    assert!(err.contains("signal: 9"), "{err}");

    // Frames resume on the same viewer's stream.
    let mut frames = camera.subscribe();
    let resumed_from = camera.status().frames_total;
    frame_after(&mut frames, resumed_from).await;
    for _ in 0..3 {
        let img = decode(&video.next_part().await.jpeg);
        assert_eq!((img.width, img.height), (320, 240));
    }
    let s = camera.status();
    assert_eq!(s.state, CameraState::Streaming);
    assert!(s.frames_total > resumed_from);

    // Shutting down kills the child.
    let pid = s.pid.expect("pid");
    camera.shutdown().await;
    let deadline = tokio::time::Instant::now() + GIVE_UP;
    while process_alive(pid) {
        assert!(
            tokio::time::Instant::now() < deadline,
            "ffmpeg {pid} survived shutdown"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Running, not a zombie waiting to be reaped.
fn process_alive(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => stat
            .rsplit_once(')')
            .is_some_and(|(_, rest)| !rest.trim_start().starts_with('Z')),
        Err(_) => false,
    }
}

#[tokio::test(start_paused = true)]
async fn a_missing_program_is_reported_and_retried_on_the_backoff_schedule() {
    let (_tx, scene) = watch::channel(Scene::default());
    let mut cfg = CameraConfig {
        source: SourceKind::Ffmpeg,
        ..CameraConfig::default()
    };
    cfg.ffmpeg.program = "/nonexistent/neptunus-test/ffmpeg".into();
    let camera = Camera::start(cfg, scene);

    // Starts at 0, 0.5, 1.5, 3.5, 7.5, 15.5 and 25.5 s: six restarts in 30 s.
    tokio::time::sleep(Duration::from_secs(30)).await;
    let s = camera.status();
    assert_eq!(s.state, CameraState::Retrying);
    assert_eq!(s.restarts, 6, "{s:?}");
    assert_eq!(s.frames_total, 0);
    assert!(s.retry_in_ms.is_some_and(|ms| ms <= 10_000), "{s:?}");
    let err = s.last_error.expect("the reason");
    assert_eq!(
        err,
        "camera source ffmpeg: program `/nonexistent/neptunus-test/ffmpeg` not found — install it (apt install ffmpeg) or set camera.source = \"synthetic\""
    );
    // Then one start per 10 s, and still no panic.
    tokio::time::sleep(Duration::from_secs(20)).await;
    assert_eq!(camera.status().restarts, 8);
}

#[tokio::test]
async fn a_program_not_on_path_says_so_and_snapshot_gives_the_reason() {
    let (_tx, scene) = watch::channel(Scene::default());
    let mut cfg = CameraConfig {
        source: SourceKind::Ffmpeg,
        ..CameraConfig::default()
    };
    cfg.ffmpeg.program = "neptunus-no-such-ffmpeg".into();
    let camera = Camera::start(cfg, scene);
    let addr = serve(camera.routes()).await;
    status_until(&camera, "the spawn error", |s| s.last_error.is_some()).await;
    let (code, body) = get_json(addr, "/snapshot.jpg").await;
    assert_eq!(code, 503);
    let reason = body["error"].as_str().expect("reason");
    assert!(
        reason.contains("no frame yet from camera source ffmpeg"),
        "{reason}"
    );
    assert!(
        reason.contains(
            "program `neptunus-no-such-ffmpeg` not found on PATH — install it (apt install ffmpeg)"
        ),
        "{reason}"
    );
    let (code, status) = get_json(addr, "/camera/status").await;
    assert_eq!(code, 200);
    // Retrying, or for an instant starting again.
    assert!(
        status["state"] == "retrying" || status["state"] == "starting",
        "{status}"
    );
    assert!(
        status["last_error"]
            .as_str()
            .is_some_and(|e| e.contains("not found on PATH"))
    );
}

// ---------------------------------------------------------------- url

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_url_source_reads_another_cameras_stream() {
    let (_tx, scene) = watch::channel(Scene::default());
    let upstream = Camera::start(synthetic(320, 240, 10.0), scene.clone());
    let up_addr = serve(upstream.routes()).await;

    let relay = Camera::start(
        CameraConfig {
            source: SourceKind::Url,
            url: Some(format!("http://{up_addr}/video.mjpg")),
            ..CameraConfig::default()
        },
        scene.clone(),
    );
    let relay_addr = serve(relay.routes()).await;
    let mut video = MjpegReader::open(relay_addr).await;

    // The scene stays still and the renderer is deterministic, so every
    // upstream frame has the same bytes: the relay must serve exactly them.
    for _ in 0..3 {
        let part = video.next_part().await;
        let img = decode(&part.jpeg);
        assert_eq!((img.width, img.height), (320, 240));
        let upstream_jpeg = upstream.latest().expect("upstream frame").jpeg;
        assert!(
            part.jpeg == upstream_jpeg,
            "the relay changed the frame's bytes"
        );
    }
    let s = relay.status();
    assert_eq!(
        (s.source, s.state),
        (SourceKind::Url, CameraState::Streaming)
    );
    assert_eq!((s.width, s.height), (Some(320), Some(240)));

    // The upstream goes away: the relay says so and keeps retrying.
    drop(upstream);
    let s = status_until(&relay, "the relay to notice", |s| s.restarts >= 1).await;
    let err = s.last_error.expect("reason");
    assert!(err.starts_with("camera source url: "), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_url_that_is_not_a_stream_is_named_in_the_error() {
    let (_tx, scene) = watch::channel(Scene::default());
    let other = Camera::start(CameraConfig::none(), scene.clone());
    let addr = serve(other.routes()).await;

    let cases = [
        (
            format!("http://{addr}/camera/status"),
            "sent Content-Type \"application/json\" — expected multipart/x-mixed-replace",
        ),
        (
            format!("http://{addr}/video.mjpg"),
            "answered 503 Service Unavailable",
        ),
        (
            format!("http://{addr}/nothing-here"),
            "answered 404 Not Found",
        ),
    ];
    for (url, expected) in cases {
        let relay = Camera::start(
            CameraConfig {
                source: SourceKind::Url,
                url: Some(url.clone()),
                ..CameraConfig::default()
            },
            scene.clone(),
        );
        let s = status_until(&relay, "an error", |s| s.last_error.is_some()).await;
        let err = s.last_error.expect("reason");
        assert!(err.contains(&url) && err.contains(expected), "{err}");
    }

    // Nobody listening.
    let closed = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let port = closed.local_addr().expect("addr").port();
    drop(closed);
    let relay = Camera::start(
        CameraConfig {
            source: SourceKind::Url,
            url: Some(format!("http://127.0.0.1:{port}/video.mjpg")),
            ..CameraConfig::default()
        },
        scene,
    );
    let s = status_until(&relay, "an error", |s| s.last_error.is_some()).await;
    let err = s.last_error.expect("reason");
    assert!(err.contains("cannot connect to http://127.0.0.1:"), "{err}");
}

// ---------------------------------------------------------------- mjpg-streamer

/// A stand-in `mjpg_streamer`: checks it got `-i INPUT -o "output_http.so
/// -p PORT"`, then serves an MJPEG stream on that port with ffmpeg's HTTP
/// server (mjpg-streamer itself is not packaged in Debian).
const FAKE_MJPG_STREAMER: &str = r#"#!/bin/sh
set -eu
input="" output=""
while [ $# -gt 0 ]; do
    case "$1" in
        -i) input="$2"; shift ;;
        -o) output="$2"; shift ;;
    esac
    shift
done
[ "$input" = "input_uvc.so -d /dev/video7 -r 160x120 -f 10" ] || { echo "bad input: $input" >&2; exit 3; }
case "$output" in
    "output_http.so -p "*) port="${output#output_http.so -p }" ;;
    *) echo "bad output: $output" >&2; exit 4 ;;
esac
exec ffmpeg -hide_banner -loglevel error -nostdin -re -f lavfi -i testsrc=size=160x120:rate=10 \
    -f mpjpeg -content_type "multipart/x-mixed-replace;boundary=ffmpeg" -listen 1 "http://127.0.0.1:$port/"
"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mjpg_streamer_is_run_with_its_plugins_and_read_over_http() {
    need_ffmpeg();
    let dir = tempfile::tempdir().expect("tempdir");
    let program = dir.path().join("mjpg_streamer");
    std::fs::write(&program, FAKE_MJPG_STREAMER).expect("write");
    std::fs::set_permissions(
        &program,
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .expect("chmod");

    let mut cfg = CameraConfig::default();
    assert_eq!(cfg.source, SourceKind::MjpgStreamer);
    cfg.mjpg_streamer.program = program.display().to_string();
    cfg.mjpg_streamer.input = "input_uvc.so -d /dev/video7 -r 160x120 -f 10".into();
    let (_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start(cfg, scene);
    let mut frames = camera.subscribe();
    for seq in 0..3 {
        let f = frame_after(&mut frames, seq).await;
        let img = decode(&f.jpeg);
        assert_eq!((img.width, img.height), (160, 120));
    }
    let s = camera.status();
    assert_eq!(
        (s.source, s.state),
        (SourceKind::MjpgStreamer, CameraState::Streaming)
    );
    assert!(s.pid.is_some());
    camera.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_mjpg_streamer_that_exits_reports_its_stderr() {
    let dir = tempfile::tempdir().expect("tempdir");
    let program = dir.path().join("mjpg_streamer");
    std::fs::write(
        &program,
        "#!/bin/sh\necho 'Unable to open /dev/video0' >&2\nexit 1\n",
    )
    .expect("write");
    std::fs::set_permissions(
        &program,
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .expect("chmod");
    let mut cfg = CameraConfig::default();
    cfg.mjpg_streamer.program = program.display().to_string();
    let (_tx, scene) = watch::channel(Scene::default());
    let camera = Camera::start(cfg, scene);
    let s = status_until(&camera, "the exit", |s| s.last_error.is_some()).await;
    let err = s.last_error.expect("reason");
    assert!(
        err.contains("exited (exit status: 1): Unable to open /dev/video0"),
        "{err}"
    );
    assert!(err.contains("check camera.mjpg_streamer.input"), "{err}");
}

// ---------------------------------------------------------------- splitter

fn random_jpeg(rng: &mut SmallRng) -> Vec<u8> {
    let w = rng.random_range(8..48u16);
    let h = rng.random_range(8..48u16);
    let rgb: Vec<u8> = (0..usize::from(w) * usize::from(h) * 3)
        .map(|_| rng.random())
        .collect();
    let mut out = Vec::new();
    let mut enc = Encoder::new(&mut out, rng.random_range(10..=100));
    match rng.random_range(0..4) {
        0 => enc.set_progressive(true),
        1 => enc.set_restart_interval(rng.random_range(1..4)),
        2 => {
            // An APP segment full of marker-like bytes (as EXIF thumbnails are).
            let junk: Vec<u8> = (0..rng.random_range(0..200))
                .map(|i| if i % 2 == 0 { 0xFF } else { rng.random() })
                .collect();
            enc.add_app_segment(rng.random_range(1..15), junk)
                .expect("app");
        }
        _ => {}
    }
    enc.encode(&rgb, w, h, ColorType::Rgb).expect("encode");
    out
}

/// Bytes between frames that never form a start-of-image (FF D8).
fn garbage(rng: &mut SmallRng) -> Vec<u8> {
    let mut g: Vec<u8> = (0..rng.random_range(0..64)).map(|_| rng.random()).collect();
    for i in 1..g.len() {
        if g[i - 1] == 0xFF && g[i] == 0xD8 {
            g[i] = 0xD7;
        }
    }
    g
}

#[test]
fn the_splitter_returns_every_frame_exactly_under_random_chunking() {
    for seed in 0..150u64 {
        let mut rng = SmallRng::seed_from_u64(seed);
        let frames: Vec<Vec<u8>> = (0..rng.random_range(1..12))
            .map(|_| random_jpeg(&mut rng))
            .collect();
        let mut stream = Vec::new();
        for f in &frames {
            stream.extend(garbage(&mut rng));
            stream.extend_from_slice(f);
        }
        stream.extend(garbage(&mut rng));

        let mut splitter = JpegSplitter::new();
        let mut out = Vec::new();
        let mut rest = &stream[..];
        while !rest.is_empty() {
            let n = rng.random_range(1..=rest.len().min(700));
            splitter.push(&rest[..n]);
            rest = &rest[n..];
            while let Some(f) = splitter.next_frame() {
                out.push(f);
            }
        }
        assert_eq!(out.len(), frames.len(), "seed {seed}");
        for (got, want) in out.iter().zip(&frames) {
            assert_eq!(got.jpeg, want[..], "seed {seed}");
            let img = decode(&got.jpeg);
            assert_eq!(
                (img.width as u32, img.height as u32),
                (got.width, got.height),
                "seed {seed}"
            );
        }
        let stats = splitter.stats();
        assert_eq!(stats.dropped_frames, 0, "seed {seed}");
        assert!(splitter.buffered() <= 1, "seed {seed}");
    }
}

#[test]
fn the_splitter_survives_random_bytes() {
    // Not a frame in sight, but never a panic and never unbounded memory.
    let mut rng = SmallRng::seed_from_u64(7);
    let mut splitter = JpegSplitter::with_max_frame_bytes(4096);
    for _ in 0..2000 {
        let mut chunk: Vec<u8> = (0..rng.random_range(1..300))
            .map(|_| rng.random())
            .collect();
        // Plenty of starts and markers.
        for b in chunk.iter_mut() {
            if rng.random_ratio(1, 8) {
                *b = [0xFF, 0xD8, 0xD9, 0xDA, 0xC0][rng.random_range(0..5)];
            }
        }
        splitter.push(&chunk);
        while let Some(f) = splitter.next_frame() {
            assert!(f.jpeg.starts_with(&[0xFF, 0xD8]) && f.jpeg.ends_with(&[0xFF, 0xD9]));
        }
        assert!(splitter.buffered() <= 4096 + 300);
    }
    assert!(splitter.stats().skipped_bytes > 0);
}

// ---------------------------------------------------------------- config

#[test]
fn the_guides_camera_config_parses_and_is_valid() {
    let page = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/docs/guide/src/video.md"
    ))
    .expect("the guide's video page");
    let start = page
        .find("```toml\n[camera]")
        .expect("docs/guide/src/video.md has the camera config");
    let body = &page[start + "```toml\n".len()..];
    let text = &body[..body.find("```").expect("end of block")];
    let table: toml::Table = toml::from_str(text).expect("TOML");
    let cfg: CameraConfig = table
        .get("camera")
        .expect("[camera]")
        .clone()
        .try_into()
        .expect("a camera config");
    cfg.validate().expect("valid");
    assert_eq!(cfg.source, SourceKind::Ffmpeg);
    assert_eq!(cfg.rotation_deg, 180);
    assert_eq!(cfg.ffmpeg, CameraConfig::default().ffmpeg);
    assert_eq!(cfg.mjpg_streamer, CameraConfig::default().mjpg_streamer);
    assert_eq!(cfg.backoff, CameraConfig::default().backoff);
}
