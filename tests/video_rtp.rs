//! H.264 over RTP from the built `neptunus --sim`, received the way
//! QGroundControl receives it: GStreamer's `udpsrc ! rtph264depay !
//! h264parse ! avdec_h264` (Debian's gst-launch-1.0), counting decoded
//! frames; the `auto` destination following a ground station (a bare UDP
//! socket sending GCS HEARTBEATs) from one loopback address to another; a
//! killed ffmpeg restarted; no destination, no ffmpeg child; a camera
//! that gives H.264 itself passed through (`-c:v copy`) to two receivers,
//! one joining late; a camera read through V4L2 (a named pipe in the
//! device's place) whose own H.264 reaches QGC's pipeline with no process
//! decoding or encoding it; `auto` never drawn to a station that may not control
//! (an unsigned stranger with the pilot's id while signing is on, a
//! stranger's id on UDP while the pilot is on TCP).
//!
//! Real processes and real time: every wait is for a condition with a
//! generous deadline. Missing tools fail the test with the install command
//! (`tests/run_all.sh` installs them), never skip it.
#![allow(clippy::unwrap_used, clippy::expect_used, deprecated)]

mod common;

use std::io::Read;
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use common::{Vehicle, free_udp_port, gcs_heartbeat};
use mavlink_core::MessageData as _;
use neptunus::dialect::neptunus::*;
use neptunus::mavlink::frame::{FrameStats, decode_datagram, encode_v2};
use neptunus::mavlink::signing::{Signer, SigningKey, timestamp_from_unix_us};

const GENEROUS: Duration = Duration::from_secs(20);

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

fn need(program: &str, args: &[&str], install: &str) {
    let ok = Command::new(program)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ok,
        "`{program}` is needed by this test and did not run — install it: {install} (tests/run_all.sh does)"
    );
}

/// Process ids of the `ffmpeg` children of `pid`, from /proc.
fn ffmpeg_children(pid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(child) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{child}/stat")) else {
            continue;
        };
        // pid (comm) state ppid …; comm may hold spaces, so split after ')'.
        let Some((head, tail)) = stat.rsplit_once(')') else {
            continue;
        };
        let ppid = tail.split_whitespace().nth(1).and_then(|p| p.parse().ok());
        if ppid == Some(pid) && head.ends_with("(ffmpeg") {
            out.push(child);
        }
    }
    out
}

fn wait_for(what: &str, v: &Vehicle, mut cond: impl FnMut() -> bool) {
    let end = Instant::now() + GENEROUS;
    while Instant::now() < end {
        if cond() {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    panic!("{what} within {GENEROUS:?}\n{}", v.stderr_tail());
}

/// An RTP packet (version 2) of payload type 96.
fn is_rtp_96(p: &[u8]) -> bool {
    p.len() > 12 && p[0] >> 6 == 2 && p[1] & 0x7f == 96
}

/// RTP packets received within `window`.
fn rtp_packets(sock: &UdpSocket, window: Duration) -> usize {
    sock.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let mut buf = [0u8; 2048];
    let (mut n, end) = (0, Instant::now() + window);
    while Instant::now() < end {
        if let Ok(len) = sock.recv(&mut buf)
            && is_rtp_96(&buf[..len])
        {
            n += 1;
        }
    }
    n
}

/// Decoded frames whose presentation time lies in a 10 s window starting
/// 1 s after the first, from `identity silent=false` lines under `-v`.
fn frames_in_ten_seconds(log: &str) -> (usize, usize) {
    let pts: Vec<f64> = log
        .lines()
        .filter(|l| l.contains("identity0") && l.contains("chain"))
        .filter_map(|l| {
            let t = l.split("pts: ").nth(1)?.split(',').next()?;
            let mut parts = t.split(':');
            let h: f64 = parts.next()?.trim().parse().ok()?;
            let m: f64 = parts.next()?.parse().ok()?;
            let s: f64 = parts.next()?.parse().ok()?;
            Some(h * 3600.0 + m * 60.0 + s)
        })
        .collect();
    let Some(first) = pts.first().copied() else {
        return (0, 0);
    };
    let inside = pts
        .iter()
        .filter(|&&t| t >= first + 1.0 && t < first + 11.0)
        .count();
    (inside, pts.len())
}

/// QGC's receive pipeline decodes the stream steadily. The rate itself is a
/// figure of `benches/video_rtp.rs`: here only a floor a busy machine still
/// clears (a fifth of the frames), so a stalled or undecodable stream fails.
#[test]
fn qgc_receive_pipeline_decodes_the_stream() {
    need("ffmpeg", &["-version"], "apt install ffmpeg");
    need(
        "gst-inspect-1.0",
        &["avdec_h264"],
        "apt install gstreamer1.0-tools gstreamer1.0-plugins-good gstreamer1.0-plugins-bad gstreamer1.0-libav",
    );
    need(
        "gst-inspect-1.0",
        &["h264parse"],
        "apt install gstreamer1.0-plugins-bad",
    );
    need(
        "gst-inspect-1.0",
        &["rtph264depay"],
        "apt install gstreamer1.0-plugins-good",
    );
    let dir = tempfile::tempdir().unwrap();
    let video = free_udp_port().unwrap();
    let mav = free_udp_port().unwrap();
    let caps = "application/x-rtp,media=video,clock-rate=90000,encoding-name=H264";
    let mut gst = Command::new("gst-launch-1.0")
        .args([
            "-v",
            "udpsrc",
            &format!("port={video}"),
            &format!("caps={caps}"),
        ])
        .args(["!", "rtph264depay", "!", "h264parse", "!", "avdec_h264"])
        .args([
            "!",
            "identity",
            "silent=false",
            "!",
            "fakesink",
            "sync=false",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("gst-launch-1.0");
    let to = format!("udp://127.0.0.1:{video}");
    let mav_url = format!("udpin:127.0.0.1:{mav}");
    let args = [
        "--sim",
        "--http",
        "off",
        "--mavlink",
        &mav_url,
        "--video-rtp",
        &to,
    ];
    let v = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();
    // 10 fps (the synthetic camera's default) for 10 s, after the start.
    std::thread::sleep(Duration::from_secs(14));
    let _ = gst.kill();
    let mut log = String::new();
    gst.stdout.take().unwrap().read_to_string(&mut log).unwrap();
    let _ = gst.wait();
    let (in_window, total) = frames_in_ten_seconds(&log);
    eprintln!("{in_window} frames decoded in 10 s at 10 fps ({total} in all)");
    assert!(
        in_window >= 20,
        "{in_window} frames decoded in 10 s ({total} in all), want ≥ 20 of the 100 sent\n{}",
        v.stderr_tail()
    );
}

/// The command line of process `pid`, arguments joined by spaces.
fn cmdline(pid: u32) -> String {
    std::fs::read(format!("/proc/{pid}/cmdline"))
        .map(|b| String::from_utf8_lossy(&b).replace('\0', " "))
        .unwrap_or_default()
}

/// A camera that gives H.264 itself, as ffmpeg reads it: an MP4 file (the
/// SPS/PPS only in its header, never in the stream: the hard case for a
/// receiver that joins late) played in real time.
#[test]
fn a_camera_giving_h264_is_passed_through_to_every_receiver_and_a_late_one_decodes() {
    need("ffmpeg", &["-version"], "apt install ffmpeg");
    need(
        "gst-inspect-1.0",
        &["avdec_h264"],
        "apt install gstreamer1.0-tools gstreamer1.0-plugins-good gstreamer1.0-plugins-bad gstreamer1.0-libav",
    );
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("camera.mp4");
    let made = Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-y", "-f", "lavfi"])
        .args(["-i", "testsrc2=size=640x480:rate=15", "-t", "40"])
        .args(["-c:v", "libx264", "-preset", "ultrafast", "-g", "15"])
        .args(["-pix_fmt", "yuv420p"])
        .arg(&clip)
        .status()
        .unwrap();
    assert!(made.success(), "ffmpeg could not make the test clip");
    let (late, early) = (free_udp_port().unwrap(), free_udp_port().unwrap());
    let early_rx = UdpSocket::bind(("127.0.0.1", early)).unwrap();
    let mav = free_udp_port().unwrap();
    let cfg = dir.path().join("neptunus.toml");
    std::fs::write(
        &cfg,
        format!(
            "[camera]\nsource = \"synthetic\"\nrtp = [\"udp://127.0.0.1:{late}\", \"udp://127.0.0.1:{early}\"]\n\
             [camera.h264]\npassthrough = [\"-re\", \"-i\", {:?}]\n",
            clip.to_str().unwrap()
        ),
    )
    .unwrap();
    let mav_url = format!("udpin:127.0.0.1:{mav}");
    let args = [
        "--sim",
        "--http",
        "off",
        "--mavlink",
        &mav_url,
        "--config",
        cfg.to_str().unwrap(),
    ];
    let v = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();
    wait_for("RTP at the second destination", &v, || {
        rtp_packets(&early_rx, Duration::from_millis(200)) > 0
    });
    let pids = ffmpeg_children(v.pid());
    assert_eq!(pids.len(), 1, "one ffmpeg for both receivers: {pids:?}");
    let line = cmdline(pids[0]);
    assert!(
        line.contains("-c:v copy") && !line.contains("libx264"),
        "the camera's H.264 is copied, not encoded again: {line}"
    );
    // The first receiver joins seconds into the stream.
    std::thread::sleep(Duration::from_secs(3));
    let caps = "application/x-rtp,media=video,clock-rate=90000,encoding-name=H264";
    let mut gst = Command::new("gst-launch-1.0")
        .args([
            "-v",
            "udpsrc",
            &format!("port={late}"),
            &format!("caps={caps}"),
        ])
        .args(["!", "rtph264depay", "!", "h264parse", "!", "avdec_h264"])
        .args([
            "!",
            "identity",
            "silent=false",
            "!",
            "fakesink",
            "sync=false",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("gst-launch-1.0");
    std::thread::sleep(Duration::from_secs(13));
    let _ = gst.kill();
    let mut log = String::new();
    gst.stdout.take().unwrap().read_to_string(&mut log).unwrap();
    let _ = gst.wait();
    let (in_window, total) = frames_in_ten_seconds(&log);
    eprintln!("the late receiver decoded {in_window} frames in 10 s at 15 fps ({total} in all)");
    assert!(
        in_window >= 30,
        "{in_window} frames decoded in 10 s by the late receiver ({total} in all), want ≥ 30 of the 150 sent\n{}",
        v.stderr_tail()
    );
    assert!(
        rtp_packets(&early_rx, Duration::from_secs(1)) > 0,
        "the second receiver stopped getting RTP"
    );
}

/// The process ids of every child of `pid` (any program), from /proc.
fn children(pid: u32) -> Vec<(u32, String)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(child) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{child}/stat")) else {
            continue;
        };
        let (Some(open), Some((head, tail))) = (stat.find('('), stat.rsplit_once(')')) else {
            continue;
        };
        let ppid = tail.split_whitespace().nth(1).and_then(|p| p.parse().ok());
        if ppid == Some(pid) {
            out.push((child, head[open + 1..].to_owned()));
        }
    }
    out
}

/// `GET path` on the vehicle's HMI, the body as JSON.
fn get_json(addr: std::net::SocketAddr, path: &str) -> serde_json::Value {
    use std::io::Write as _;
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(GENEROUS)).unwrap();
    write!(s, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n").unwrap();
    let mut reply = String::new();
    s.read_to_string(&mut reply).unwrap();
    let body = reply.split_once("\r\n\r\n").map_or("", |(_, b)| b);
    serde_json::from_str(body).unwrap_or_else(|e| panic!("{path}: {e}: {reply}"))
}

/// A camera that encodes H.264 itself, read by Neptunus through V4L2 — a
/// named pipe in the device's place, fed what such a camera gives: an
/// Annex B stream of access units (libx264 from testsrc, 640×480 at
/// 15 fps, constrained baseline, SPS/PPS only at its start, a keyframe
/// every second) in real time. QGroundControl's pipeline, joining seconds
/// in, decodes it (the vehicle puts the SPS/PPS before every keyframe);
/// the vehicle runs no child process at all — nothing decodes or encodes —
/// and `/api/video` says the camera's H.264 goes out as it came.
#[test]
fn a_v4l2_camera_giving_h264_reaches_qgc_with_no_encoder_running() {
    need("ffmpeg", &["-version"], "apt install ffmpeg");
    need(
        "gst-inspect-1.0",
        &["avdec_h264"],
        "apt install gstreamer1.0-tools gstreamer1.0-plugins-good gstreamer1.0-plugins-bad gstreamer1.0-libav",
    );
    let dir = tempfile::tempdir().unwrap();
    let device = dir.path().join("video0");
    nix::unistd::mkfifo(&device, nix::sys::stat::Mode::from_bits_truncate(0o600)).unwrap();
    // The camera: writes to the pipe once the vehicle opens it.
    let mut camera = Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-re", "-f", "lavfi"])
        .args(["-i", "testsrc2=size=640x480:rate=15", "-t", "60"])
        .args([
            "-c:v",
            "libx264",
            "-preset",
            "ultrafast",
            "-profile:v",
            "baseline",
        ])
        .args(["-g", "15", "-pix_fmt", "yuv420p", "-f", "h264", "-y"])
        .arg(&device)
        .stdin(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let (late, early) = (free_udp_port().unwrap(), free_udp_port().unwrap());
    let early_rx = UdpSocket::bind(("127.0.0.1", early)).unwrap();
    let mav = free_udp_port().unwrap();
    let cfg = dir.path().join("neptunus.toml");
    std::fs::write(
        &cfg,
        format!(
            "[camera]\nsource = \"v4l2\"\nfps = 15\nrtp = [\"udp://127.0.0.1:{late}\", \"udp://127.0.0.1:{early}\"]\n\
             [camera.v4l2]\ndevice = {:?}\nformat = \"h264\"\n",
            device.to_str().unwrap()
        ),
    )
    .unwrap();
    let mav_url = format!("udpin:127.0.0.1:{mav}");
    let args = [
        "--sim",
        "--mavlink",
        &mav_url,
        "--config",
        cfg.to_str().unwrap(),
    ];
    let mut v = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();
    let http = v.http_addr(GENEROUS).unwrap();
    wait_for("RTP from the camera at the first destination", &v, || {
        rtp_packets(&early_rx, Duration::from_millis(200)) > 0
    });
    let info = get_json(http, "/api/video");
    assert_eq!(info["path"]["h264"], "camera", "{info}");
    assert_eq!(info["path"]["capture"]["fourcc"], "H264", "{info}");
    assert_eq!(info["h264"]["route"], "camera", "{info}");
    assert_eq!(info["h264"]["pid"], serde_json::Value::Null, "{info}");
    assert_eq!(info["encoder_running"], false, "{info}");
    assert_eq!(info["mjpeg"], false, "{info}");
    // The camera's own profile, read from its SPS: libx264's baseline.
    assert!(
        info["h264_profile"]
            .as_str()
            .is_some_and(|p| p.starts_with("constrained baseline 42c0")),
        "{info}"
    );
    assert!(
        info["path"]["why"]
            .as_str()
            .unwrap()
            .contains("as it came (no decode, no encode)"),
        "{info}"
    );
    std::thread::sleep(Duration::from_secs(3));
    let caps = "application/x-rtp,media=video,clock-rate=90000,encoding-name=H264";
    let mut gst = Command::new("gst-launch-1.0")
        .args([
            "-v",
            "udpsrc",
            &format!("port={late}"),
            &format!("caps={caps}"),
        ])
        .args(["!", "rtph264depay", "!", "h264parse", "!", "avdec_h264"])
        .args([
            "!",
            "identity",
            "silent=false",
            "!",
            "fakesink",
            "sync=false",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("gst-launch-1.0");
    // While QGC watches, the vehicle has no child: no encoder, no ffmpeg.
    let end = Instant::now() + Duration::from_secs(13);
    while Instant::now() < end {
        let kids = children(v.pid());
        assert!(kids.is_empty(), "the vehicle started {kids:?}");
        std::thread::sleep(Duration::from_millis(250));
    }
    let _ = gst.kill();
    let mut log = String::new();
    gst.stdout.take().unwrap().read_to_string(&mut log).unwrap();
    let _ = gst.wait();
    let _ = camera.kill();
    let _ = camera.wait();
    let (in_window, total) = frames_in_ten_seconds(&log);
    eprintln!(
        "QGC's pipeline decoded {in_window} frames of the camera's H.264 in 10 s at 15 fps ({total} in all)"
    );
    assert!(
        in_window >= 30,
        "{in_window} frames decoded in 10 s ({total} in all), want ≥ 30 of the 150 sent\n{}",
        v.stderr_tail()
    );
    let status = get_json(http, "/camera/status");
    assert_eq!(status["source"], "v4l2", "{status}");
    assert!(status["frames_total"].as_u64().unwrap() >= 150, "{status}");
}

/// A bare UDP ground station: system id 255 (SYSID_MYGCS) unless told,
/// its frames signed when it has a key.
struct Station {
    sock: UdpSocket,
    seq: u8,
    sysid: u8,
    signer: Option<Signer>,
}

impl Station {
    fn at(ip: &str, vehicle_port: u16) -> Station {
        let sock = UdpSocket::bind((ip, 0)).unwrap();
        sock.connect(("127.0.0.1", vehicle_port)).unwrap();
        Station {
            sock,
            seq: 0,
            sysid: 255,
            signer: None,
        }
    }

    fn with_sysid(mut self, sysid: u8) -> Station {
        self.sysid = sysid;
        self
    }

    fn signing(mut self, passphrase: &str) -> Station {
        self.signer = Some(Signer::new(
            SigningKey::from_passphrase(passphrase),
            0,
            None,
        ));
        self
    }

    fn send(&mut self, msg: &MavMessage) {
        let mut bytes = encode_v2(self.sysid, 190, self.seq, msg);
        self.seq = self.seq.wrapping_add(1);
        if let Some(signer) = self.signer.as_mut() {
            let now_us = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .unwrap()
                .as_micros() as u64;
            signer.sign(&mut bytes, timestamp_from_unix_us(now_us));
        }
        let _ = self.sock.send(&bytes);
    }

    fn heartbeat(&mut self) {
        self.send(&gcs_heartbeat());
    }

    /// The camera component's messages in what the vehicle sent us since
    /// the last call.
    fn camera_messages(&self) -> Vec<MavMessage> {
        self.sock.set_nonblocking(true).unwrap();
        let (mut buf, mut frames) = ([0u8; 4096], Vec::new());
        while let Ok(n) = self.sock.recv(&mut buf) {
            decode_datagram(&buf[..n], &mut FrameStats::default(), &mut frames);
        }
        self.sock.set_nonblocking(false).unwrap();
        frames
            .into_iter()
            .filter(|f| f.sysid == 1 && f.compid == 100)
            .map(|f| f.msg)
            .collect()
    }
}

/// Sends HEARTBEATs at 2 Hz from `st` while receiving on `rx` for `window`;
/// the RTP packets received.
fn beat_and_count(st: &mut Station, rx: &UdpSocket, window: Duration) -> usize {
    let (mut n, end) = (0, Instant::now() + window);
    while Instant::now() < end {
        st.heartbeat();
        n += rtp_packets(rx, Duration::from_millis(500));
    }
    n
}

#[test]
fn auto_follows_the_ground_station_restarts_a_killed_ffmpeg_and_stops_without_one() {
    need("ffmpeg", &["-version"], "apt install ffmpeg");
    let dir = tempfile::tempdir().unwrap();
    let mav = free_udp_port().unwrap();
    // `auto` sends to this port instead of 5600 (a test uses no fixed port).
    let video = free_udp_port().unwrap();
    let rx1 = UdpSocket::bind(("127.0.0.1", video)).unwrap();
    let rx2 = UdpSocket::bind(("127.0.0.2", video)).unwrap();
    let cfg = dir.path().join("neptunus.toml");
    std::fs::write(
        &cfg,
        format!("[camera]\nsource = \"synthetic\"\n[camera.h264]\nauto_port = {video}\n"),
    )
    .unwrap();
    let mav_url = format!("udpin:127.0.0.1:{mav}");
    let args = [
        "--sim",
        "--http",
        "off",
        "--mavlink",
        &mav_url,
        "--config",
        cfg.to_str().unwrap(),
    ];
    let v = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();

    // Nobody heard: no ffmpeg, no packet.
    assert_eq!(rtp_packets(&rx1, Duration::from_secs(3)), 0);
    assert!(
        ffmpeg_children(v.pid()).is_empty(),
        "an encoder runs with no destination"
    );

    // A ground station on 127.0.0.1: video to 127.0.0.1.
    let mut st = Station::at("127.0.0.1", mav);
    let mut got = 0;
    let end = Instant::now() + GENEROUS;
    while got < 20 && Instant::now() < end {
        got += beat_and_count(&mut st, &rx1, Duration::from_millis(500));
    }
    assert!(
        got >= 20,
        "no RTP at the station's address\n{}",
        v.stderr_tail()
    );

    // The same station (sysid 255) now speaks from 127.0.0.2: video follows.
    let mut moved = Station::at("127.0.0.2", mav);
    let mut got = 0;
    let end = Instant::now() + GENEROUS;
    while got < 20 && Instant::now() < end {
        got += beat_and_count(&mut moved, &rx2, Duration::from_millis(500));
    }
    assert!(
        got >= 20,
        "video did not follow the station\n{}",
        v.stderr_tail()
    );
    let _ = rtp_packets(&rx1, Duration::from_millis(500));
    assert_eq!(
        beat_and_count(&mut moved, &rx1, Duration::from_secs(2)),
        0,
        "video still goes to the old address"
    );

    // ffmpeg killed: restarted (a new pid) and packets flow again.
    let pids = ffmpeg_children(v.pid());
    assert_eq!(pids.len(), 1, "{pids:?}");
    let killed = pids[0];
    let _ = Command::new("kill")
        .args(["-KILL", &killed.to_string()])
        .status();
    wait_for("a new ffmpeg", &v, || {
        moved.heartbeat();
        let now = ffmpeg_children(v.pid());
        now.len() == 1 && now[0] != killed
    });
    let mut got = 0;
    let end = Instant::now() + GENEROUS;
    while got < 20 && Instant::now() < end {
        got += beat_and_count(&mut moved, &rx2, Duration::from_millis(500));
    }
    assert!(got >= 20, "no RTP after the restart\n{}", v.stderr_tail());

    // The station goes silent: once it is forgotten, no ffmpeg runs.
    wait_for("no ffmpeg after the station left", &v, || {
        ffmpeg_children(v.pid()).is_empty()
    });
    // What was queued before it stopped, then silence.
    let _ = rtp_packets(&rx2, Duration::from_millis(500));
    assert_eq!(rtp_packets(&rx2, Duration::from_secs(1)), 0);
}

const PASSPHRASE: &str = "video follows the pilot";

/// The vehicle's data directory gets a signing key, as the operator sets it.
fn set_passphrase(data: &Path) {
    let ok = Command::new(bin())
        .args(["signing", "set-passphrase", PASSPHRASE, "--data-dir"])
        .arg(data)
        .stdout(Stdio::null())
        .status()
        .unwrap()
        .success();
    assert!(ok, "neptunus signing set-passphrase failed");
}

/// RTP packets received at each of `rxs` over `window`, calling `beat`
/// about every 100 ms meanwhile.
fn count_while<const N: usize>(
    rxs: [&UdpSocket; N],
    window: Duration,
    mut beat: impl FnMut(),
) -> [usize; N] {
    let mut counts = [0; N];
    let end = Instant::now() + window;
    while Instant::now() < end {
        beat();
        for (rx, n) in rxs.iter().zip(&mut counts) {
            *n += rtp_packets(rx, Duration::from_millis(50));
        }
    }
    counts
}

fn synthetic_camera_config(dir: &Path, video_port: u16) -> String {
    let cfg = dir.join("neptunus.toml");
    std::fs::write(
        &cfg,
        format!("[camera]\nsource = \"synthetic\"\n[camera.h264]\nauto_port = {video_port}\n"),
    )
    .unwrap();
    cfg.to_str().unwrap().to_owned()
}

/// MAV_CMD_REQUEST_MESSAGE for message `id`.
fn request_message(id: u32, component: u8) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: id as f32,
        command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
        target_system: 1,
        target_component: component,
        ..Default::default()
    })
}

/// A security probe with signing on: a stranger on another address sends
/// unsigned GCS HEARTBEATs carrying the pilot's system id, ten a second.
/// The video stays with the pilot, whose frames are signed: the stranger
/// gets no RTP packet, and VIDEO_STREAM_INFORMATION names the pilot's
/// address.
#[test]
fn with_signing_on_an_unsigned_stranger_with_the_pilots_id_does_not_draw_the_video() {
    need("ffmpeg", &["-version"], "apt install ffmpeg");
    let dir = tempfile::tempdir().unwrap();
    set_passphrase(&dir.path().join("data"));
    let mav = free_udp_port().unwrap();
    let video = free_udp_port().unwrap();
    let rx_pilot = UdpSocket::bind(("127.0.0.1", video)).unwrap();
    let rx_stranger = UdpSocket::bind(("127.0.0.2", video)).unwrap();
    let cfg = synthetic_camera_config(dir.path(), video);
    let mav_url = format!("udpin:127.0.0.1:{mav}");
    let args = [
        "--sim",
        "--http",
        "off",
        "--mavlink",
        &mav_url,
        "--config",
        &cfg,
    ];
    let v = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();

    // The pilot, signed, on 127.0.0.1: its video flows.
    let mut pilot = Station::at("127.0.0.1", mav).signing(PASSPHRASE);
    let mut got = 0;
    let end = Instant::now() + GENEROUS;
    while got < 20 && Instant::now() < end {
        got += beat_and_count(&mut pilot, &rx_pilot, Duration::from_millis(500));
    }
    assert!(got >= 20, "no RTP for the pilot\n{}", v.stderr_tail());

    // The attack: 8 s of the stranger's unsigned HEARTBEATs as 255 from
    // 127.0.0.2, beside the pilot's signed ones.
    let mut stranger = Station::at("127.0.0.2", mav);
    let mut beat = 0u32;
    let [to_pilot, to_stranger] =
        count_while([&rx_pilot, &rx_stranger], Duration::from_secs(8), || {
            stranger.heartbeat();
            if beat.is_multiple_of(5) {
                pilot.heartbeat();
            }
            beat += 1;
        });
    eprintln!(
        "8 s of an unsigned stranger's HEARTBEATs ({beat}): {to_pilot} RTP packets to the pilot, \
         {to_stranger} to the stranger"
    );
    assert_eq!(to_stranger, 0, "the stranger drew the video");
    assert!(
        to_pilot >= 20,
        "the pilot lost the video: {to_pilot} packets in 8 s\n{}",
        v.stderr_tail()
    );

    // What the camera component tells the pilot: the stream goes to it.
    let want = format!("udp://127.0.0.1:{video}");
    let mut uri = None;
    let end = Instant::now() + GENEROUS;
    while uri.is_none() {
        assert!(
            Instant::now() < end,
            "no VIDEO_STREAM_INFORMATION with a uri\n{}",
            v.stderr_tail()
        );
        pilot.send(&request_message(VIDEO_STREAM_INFORMATION_DATA::ID, 100));
        stranger.heartbeat();
        assert_eq!(rtp_packets(&rx_stranger, Duration::from_millis(300)), 0);
        uri = pilot.camera_messages().into_iter().find_map(|m| match m {
            MavMessage::VIDEO_STREAM_INFORMATION(i) => {
                let b: &[u8] = i.uri.as_ref();
                let u = String::from_utf8_lossy(b).trim_end_matches('\0').to_owned();
                (!u.is_empty()).then_some(u)
            }
            _ => None,
        });
    }
    assert_eq!(uri.as_deref(), Some(want.as_str()));
}

/// A ground station on TCP, signing off.
struct TcpPilot {
    stream: std::net::TcpStream,
    decoder: neptunus::mavlink::FrameDecoder,
    seq: u8,
}

impl TcpPilot {
    fn connect(port: u16, v: &Vehicle) -> TcpPilot {
        let end = Instant::now() + GENEROUS;
        let stream = loop {
            match std::net::TcpStream::connect(("127.0.0.1", port)) {
                Ok(s) => break s,
                Err(e) => {
                    assert!(
                        Instant::now() < end,
                        "cannot connect to tcpin:{port}: {e}\n{}",
                        v.stderr_tail()
                    );
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        };
        stream
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        TcpPilot {
            stream,
            decoder: neptunus::mavlink::FrameDecoder::new(),
            seq: 0,
        }
    }

    fn send(&mut self, msg: &MavMessage) {
        use std::io::Write as _;
        let bytes = encode_v2(255, 190, self.seq, msg);
        self.seq = self.seq.wrapping_add(1);
        self.stream.write_all(&bytes).unwrap();
    }

    /// The autopilot's messages read now (waits up to 20 ms).
    fn recv(&mut self) -> Vec<MavMessage> {
        let mut buf = [0u8; 8192];
        let mut frames = Vec::new();
        if let Ok(n) = self.stream.read(&mut buf) {
            self.decoder.push(&buf[..n], &mut frames);
        }
        frames
            .into_iter()
            .filter(|f| f.sysid == 1 && f.compid == 1)
            .map(|f| f.msg)
            .collect()
    }

    /// Arms (and so takes control), asking again while pre-arm checks fail.
    fn arm(&mut self, v: &Vehicle) {
        let arm = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: 1.0,
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        });
        let end = Instant::now() + GENEROUS;
        let mut next = Instant::now();
        loop {
            assert!(
                Instant::now() < end,
                "arming over TCP refused\n{}",
                v.stderr_tail()
            );
            if Instant::now() >= next {
                next = Instant::now() + Duration::from_secs(1);
                self.send(&gcs_heartbeat());
                self.send(&arm);
            }
            let accepted = self.recv().iter().any(|m| {
                matches!(m, MavMessage::COMMAND_ACK(a)
                    if a.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM
                        && a.result == MavResult::MAV_RESULT_ACCEPTED)
            });
            if accepted {
                return;
            }
        }
    }
}

/// Signing off, the pilot in control over TCP: a stranger whose system id
/// is not an allowed one sends GCS HEARTBEATs on UDP. It gets no video
/// (no encoder even runs); an allowed station that joins on UDP does.
#[test]
fn with_the_pilot_on_tcp_a_stranger_on_udp_does_not_get_the_video() {
    need("ffmpeg", &["-version"], "apt install ffmpeg");
    let dir = tempfile::tempdir().unwrap();
    let mav = free_udp_port().unwrap();
    let tcp = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let video = free_udp_port().unwrap();
    let rx_stranger = UdpSocket::bind(("127.0.0.2", video)).unwrap();
    let rx_allowed = UdpSocket::bind(("127.0.0.3", video)).unwrap();
    let cfg = synthetic_camera_config(dir.path(), video);
    let (udp_url, tcp_url) = (
        format!("udpin:127.0.0.1:{mav}"),
        format!("tcpin:127.0.0.1:{tcp}"),
    );
    let args = [
        "--sim",
        "--http",
        "off",
        "--mavlink",
        &udp_url,
        "--mavlink",
        &tcp_url,
        "--config",
        &cfg,
    ];
    let v = Vehicle::spawn(bin(), &args, dir.path(), "").unwrap();
    let mut pilot = TcpPilot::connect(tcp, &v);
    pilot.arm(&v);

    // The pilot keeps control (HEARTBEAT, neutral sticks); the stranger,
    // system id 66, beats on UDP from 127.0.0.2.
    let mut stranger = Station::at("127.0.0.2", mav).with_sysid(66);
    let mut beat = 0u32;
    let pilot_life = |pilot: &mut TcpPilot, beat: u32| {
        if beat.is_multiple_of(10) {
            pilot.send(&gcs_heartbeat());
        }
        pilot.send(&common::manual_control(0));
        let _ = pilot.recv();
    };
    let [to_stranger] = count_while([&rx_stranger], Duration::from_secs(8), || {
        stranger.heartbeat();
        pilot_life(&mut pilot, beat);
        beat += 1;
    });
    eprintln!(
        "8 s of a stranger's HEARTBEATs on UDP ({beat}), the pilot on TCP: {to_stranger} RTP packets \
         to the stranger, ffmpeg children {:?}",
        ffmpeg_children(v.pid())
    );
    assert_eq!(to_stranger, 0, "the stranger got the video");
    assert!(
        ffmpeg_children(v.pid()).is_empty(),
        "an encoder runs for a station that may not control"
    );

    // A station that may control (NEPT_GCS_ALLOW1, 245) joins on UDP: the
    // video goes to it, and still not to the stranger.
    let mut allowed = Station::at("127.0.0.3", mav).with_sysid(245);
    let (mut to_allowed, mut to_stranger) = (0, 0);
    let end = Instant::now() + GENEROUS;
    while to_allowed < 20 && Instant::now() < end {
        let [a, s] = count_while(
            [&rx_allowed, &rx_stranger],
            Duration::from_millis(500),
            || {
                allowed.heartbeat();
                stranger.heartbeat();
                pilot_life(&mut pilot, beat);
                beat += 1;
            },
        );
        to_allowed += a;
        to_stranger += s;
    }
    eprintln!("an allowed station on UDP: {to_allowed} RTP packets; the stranger {to_stranger}");
    assert!(
        to_allowed >= 20,
        "no video for the allowed station\n{}",
        v.stderr_tail()
    );
    assert_eq!(to_stranger, 0, "the stranger got the video");
}
