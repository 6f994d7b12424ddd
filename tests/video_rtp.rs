//! H.264 over RTP from the built `neptunus --sim`, received the way
//! QGroundControl receives it: GStreamer's `udpsrc ! rtph264depay !
//! h264parse ! avdec_h264` (Debian's gst-launch-1.0), counting decoded
//! frames; the `auto` destination following a ground station (a bare UDP
//! socket sending GCS HEARTBEATs) from one loopback address to another; a
//! killed ffmpeg restarted; no destination, no ffmpeg child; a camera
//! that gives H.264 itself passed through (`-c:v copy`) to two receivers,
//! one joining late.
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
use std::time::{Duration, Instant};

use common::{Vehicle, free_udp_port};
use neptunus::dialect::neptunus::*;
use neptunus::mavlink::frame::encode_v2;

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

struct Station {
    sock: UdpSocket,
    seq: u8,
}

impl Station {
    fn at(ip: &str, vehicle_port: u16) -> Station {
        let sock = UdpSocket::bind((ip, 0)).unwrap();
        sock.connect(("127.0.0.1", vehicle_port)).unwrap();
        Station { sock, seq: 0 }
    }

    fn heartbeat(&mut self) {
        let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            mavtype: MavType::MAV_TYPE_GCS,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
            ..Default::default()
        });
        let _ = self.sock.send(&encode_v2(255, 190, self.seq, &hb));
        self.seq = self.seq.wrapping_add(1);
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
