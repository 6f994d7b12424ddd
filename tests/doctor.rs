//! `neptunus doctor` against `neptunus emulate-board` on a real pty: every
//! check passes; each fails, with its fix line, when the device is missing,
//! unreadable, silent or speaks the other framing (and the camera, ports and
//! data directory checks when theirs are wrong); `--json` parses.

#![allow(
    clippy::unwrap_used,
    reason = "a test fails at the first unwrap, with its place"
)]

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_neptunus");

/// `neptunus emulate-board` as a child, killed on drop.
struct Board {
    child: Child,
    path: PathBuf,
}

impl Board {
    fn start(framing: &str) -> Self {
        let mut child = Command::new(BIN)
            .args(["emulate-board", "--framing", framing])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("cannot start neptunus emulate-board");
        let mut line = String::new();
        BufReader::new(child.stdout.take().expect("stdout"))
            .read_line(&mut line)
            .expect("the emulator prints its pty");
        Self {
            child,
            path: PathBuf::from(line.trim()),
        }
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A configuration file for a board on `serial` with `framing`, data in
/// `dir/data`, a free UDP port, the HMI on a free port; `extra` appended.
fn config(dir: &Path, serial: &Path, framing: &str, extra: &str) -> PathBuf {
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("a free port");
    let text = format!(
        "data_dir = \"{}\"\n\n[board]\nserial = \"{}\"\nframing = \"{framing}\"\n\n[mavlink]\nendpoints = [\"udpin:127.0.0.1:{port}\"]\n\n[hmi]\nhttp = \"127.0.0.1:0\"\n\n{extra}\n",
        dir.join("data").display(),
        serial.display(),
    );
    // The WebRTC signalling on a free port too: 6021 may be another
    // vehicle's on a machine running tests side by side. A test that sets
    // it itself says so in `extra`.
    let text = if extra.contains("[camera.webrtc]") {
        text
    } else {
        let free = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .expect("a free port");
        format!(
            "{text}\n[camera.webrtc]\nsignalling = \"127.0.0.1:{free}\"\nstreams = \"127.0.0.1:0\"\n"
        )
    };
    let path = dir.join("neptunus.toml");
    std::fs::write(&path, text).expect("config written");
    path
}

fn doctor(config: &Path, json: bool) -> Output {
    let mut cmd = Command::new(BIN);
    cmd.arg("--config").arg(config).arg("doctor");
    if json {
        cmd.arg("--json");
    }
    cmd.output().expect("neptunus doctor runs")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The `--json` report: parses, and its `ok` agrees with the exit status.
fn report(config: &Path) -> serde_json::Value {
    let o = doctor(config, true);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("--json does not parse ({e}):\n{}", stdout(&o)));
    assert_eq!(v["ok"].as_bool(), Some(o.status.success()), "{v}");
    v
}

/// The check `name` of a JSON report.
fn check<'a>(v: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    v["checks"]
        .as_array()
        .and_then(|a| a.iter().find(|c| c["name"] == name))
        .unwrap_or_else(|| panic!("no check {name} in {v}"))
}

/// The text report fails `name` with a fix line containing `fix`.
fn assert_fails(config: &Path, name: &str, fix: &str) {
    let o = doctor(config, false);
    let text = stdout(&o);
    assert!(!o.status.success(), "exit 0 with {name} wrong:\n{text}");
    let lines: Vec<&str> = text.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.starts_with("FAIL") && l.split_whitespace().nth(1) == Some(name))
        .unwrap_or_else(|| panic!("no FAIL line for {name}:\n{text}"));
    // The first fix line after it (a long detail may take several lines).
    let fix_line = lines[at + 1..]
        .iter()
        .find(|l| l.trim_start().starts_with("fix:"))
        .copied()
        .unwrap_or("");
    assert!(
        fix_line.contains("fix:") && fix_line.contains(fix),
        "the fix for {name} should mention {fix:?}:\n{text}"
    );
    let v = report(config);
    assert_eq!(check(&v, name)["ok"], false, "{v}");
}

#[test]
fn every_check_passes_against_the_emulated_board() {
    let dir = tempfile::tempdir().unwrap();
    let board = Board::start("crc8");
    let cfg = config(
        dir.path(),
        &board.path,
        "crc8",
        "[camera]\nsource = \"synthetic\"\n",
    );
    let o = doctor(&cfg, false);
    let text = stdout(&o);
    assert!(o.status.success(), "doctor failed:\n{text}");
    for name in [
        "config", "serial", "board", "camera", "video", "ports", "data_dir", "clock",
    ] {
        assert!(
            text.lines()
                .any(|l| l.starts_with("ok") && l.split_whitespace().nth(1) == Some(name)),
            "no ok line for {name}:\n{text}"
        );
    }
    assert!(text.contains("crc8"), "{text}");
    let v = report(&cfg);
    assert_eq!(v["checks"].as_array().map(Vec::len), Some(8), "{v}");
    // A plain (December 2014) board passes when the configuration says plain.
    let plain = Board::start("plain");
    let cfg = config(
        dir.path(),
        &plain.path,
        "plain",
        "[camera]\nsource = \"none\"\n",
    );
    let v = report(&cfg);
    assert_eq!(check(&v, "board")["ok"], true, "{v}");
}

#[test]
fn a_missing_device_fails_with_its_fix() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), Path::new("/dev/ttyO1-missing"), "crc8", "");
    assert_fails(&cfg, "serial", "UART1");
}

#[test]
fn a_device_this_user_cannot_open_fails_with_its_fix() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = tempfile::tempdir().unwrap();
    let board = Board::start("crc8");
    std::fs::set_permissions(&board.path, std::fs::Permissions::from_mode(0o000)).unwrap();
    // Root opens anything: then doctor runs as nobody (the config and the
    // data directory readable and writable by it).
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o777)).unwrap();
    let cfg = config(
        dir.path(),
        &board.path,
        "crc8",
        "[camera]\nsource = \"none\"\n",
    );
    std::fs::set_permissions(&cfg, std::fs::Permissions::from_mode(0o644)).unwrap();
    let mut cmd = if nix::unistd::geteuid().is_root() {
        let mut c = Command::new("setpriv");
        c.args(["--reuid=65534", "--regid=65534", "--clear-groups", BIN]);
        c
    } else {
        Command::new(BIN)
    };
    let o = cmd
        .arg("--config")
        .arg(&cfg)
        .arg("doctor")
        .output()
        .unwrap();
    let text = stdout(&o);
    assert!(!o.status.success(), "{text}");
    let at = text
        .lines()
        .position(|l| l.starts_with("FAIL  serial"))
        .unwrap_or_else(|| {
            panic!(
                "serial should fail:\n{text}\n{}",
                String::from_utf8_lossy(&o.stderr)
            )
        });
    let fix = text.lines().nth(at + 1).unwrap_or("");
    assert!(fix.contains("fix:") && fix.contains("dialout"), "{text}");
}

#[test]
fn a_silent_device_fails_with_its_fix() {
    let dir = tempfile::tempdir().unwrap();
    // A pty nobody answers on.
    let pty = nix::pty::openpty(None, None).unwrap();
    let slave = std::fs::read_link(format!(
        "/proc/self/fd/{}",
        std::os::fd::AsRawFd::as_raw_fd(&pty.slave)
    ))
    .unwrap();
    let cfg = config(dir.path(), &slave, "crc8", "[camera]\nsource = \"none\"\n");
    assert_fails(&cfg, "board", "P9.24");
    drop(pty);
}

#[test]
fn the_other_framing_fails_with_its_fix() {
    let dir = tempfile::tempdir().unwrap();
    let plain = Board::start("plain");
    let cfg = config(
        dir.path(),
        &plain.path,
        "crc8",
        "[camera]\nsource = \"none\"\n",
    );
    assert_fails(&cfg, "board", "framing = \"plain\"");
    let crc8 = Board::start("crc8");
    let cfg = config(
        dir.path(),
        &crc8.path,
        "plain",
        "[camera]\nsource = \"none\"\n",
    );
    assert_fails(&cfg, "board", "framing = \"crc8\"");
}

/// The `video` check: a camera in V4L2's place (a recording of MJPEG, as
/// the OpenROV camera gives) with nothing to be encoded warns that
/// QGroundControl gets no video, with the fix; a recording of H.264 passes
/// through and passes; a raw camera's format with nothing encoded fails.
#[test]
fn the_video_check_says_which_path_and_gives_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let board = Board::start("crc8");
    let clip = dir.path().join("camera.rec");
    std::fs::write(&clip, b"recorded").unwrap();
    let cam = |format: &str, encode: &str| {
        format!(
            "[camera]\nsource = \"v4l2\"\nencode = \"{encode}\"\n[camera.v4l2]\ndevice = \"{}\"\nformat = \"{format}\"\n",
            clip.display()
        )
    };
    let cfg = config(dir.path(), &board.path, "crc8", &cam("mjpeg", "never"));
    let o = doctor(&cfg, false);
    let text = stdout(&o);
    assert!(o.status.success(), "a warning is not a failure:\n{text}");
    let lines: Vec<&str> = text.lines().collect();
    let at = lines
        .iter()
        .position(|l| l.starts_with("warn") && l.split_whitespace().nth(1) == Some("video"))
        .unwrap_or_else(|| panic!("no warn line for video:\n{text}"));
    assert!(lines[at].contains("JPEG from the camera"), "{text}");
    let fix = lines[at + 1..]
        .iter()
        .find(|l| l.trim_start().starts_with("fix:"))
        .unwrap();
    assert!(
        fix.contains("QGroundControl gets no video: the camera offers MJPEG only; set [camera] encode = \"when-needed\"")
            && fix.contains("or use an H.264 UVC camera"),
        "{text}"
    );
    assert!(text.contains("read as a recorded mjpeg stream"), "{text}");
    let cfg = config(dir.path(), &board.path, "crc8", &cam("h264", "never"));
    let v = report(&cfg);
    let c = check(&v, "video");
    assert_eq!(
        (c["ok"].as_bool(), c["warning"].as_bool()),
        (Some(true), Some(false)),
        "{v}"
    );
    assert!(
        c["detail"]
            .as_str()
            .unwrap()
            .contains("H.264 from the camera"),
        "{v}"
    );
    assert!(
        c["detail"]
            .as_str()
            .unwrap()
            .contains("no decode, no encode"),
        "{v}"
    );
    // A recording cannot be asked what it holds: auto is refused.
    let cfg = config(dir.path(), &board.path, "crc8", &cam("auto", "never"));
    assert_fails(&cfg, "video", "camera.v4l2.format = \"h264\"");
}

#[test]
fn camera_ports_and_data_dir_fail_with_their_fixes() {
    let dir = tempfile::tempdir().unwrap();
    let board = Board::start("crc8");
    // A camera device that is not there.
    let cam = "[camera]\nsource = \"ffmpeg\"\n[camera.ffmpeg]\nprogram = \"sh\"\ninput_args = [\"-f\", \"v4l2\", \"-i\", \"/dev/video-missing\"]\n";
    let cfg = config(dir.path(), &board.path, "crc8", cam);
    assert_fails(&cfg, "camera", "USB camera");
    // A port someone else listens on.
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let cfg = config(
        dir.path(),
        &board.path,
        "crc8",
        "[camera]\nsource = \"none\"\n",
    );
    let text = std::fs::read_to_string(&cfg).unwrap().replace(
        "endpoints = [",
        &format!("endpoints = [\"tcpin:127.0.0.1:{port}\", "),
    );
    std::fs::write(&cfg, text).unwrap();
    assert_fails(&cfg, "ports", "already running");
    // A data directory under a file.
    let file = dir.path().join("a-file");
    std::fs::write(&file, b"").unwrap();
    let cfg = config(
        dir.path(),
        &board.path,
        "crc8",
        "[camera]\nsource = \"none\"\n",
    );
    let text = std::fs::read_to_string(&cfg).unwrap().replace(
        &dir.path().join("data").display().to_string(),
        &file.join("data").display().to_string(),
    );
    std::fs::write(&cfg, text).unwrap();
    assert_fails(&cfg, "data_dir", "writable");
    // And a configuration that does not parse fails first, with the others not checked.
    std::fs::write(&cfg, "[board]\nbaud = \"fast\"\n").unwrap();
    assert_fails(&cfg, "config", "--check");
}

#[test]
fn a_signalling_port_in_use_is_a_warning_the_vehicle_starts_without_it() {
    let dir = tempfile::tempdir().unwrap();
    let board = Board::start("crc8");
    // Another program (mavlink-camera-manager, say) holds the port.
    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = held.local_addr().unwrap().port();
    let cfg = config(
        dir.path(),
        &board.path,
        "crc8",
        &format!(
            "[camera]\nsource = \"synthetic\"\n[camera.webrtc]\nsignalling = \"127.0.0.1:{port}\"\nstreams = \"127.0.0.1:0\"\n"
        ),
    );
    let o = doctor(&cfg, false);
    let text = stdout(&o);
    assert!(
        o.status.success(),
        "a busy signalling port fails doctor:\n{text}"
    );
    let line = text
        .lines()
        .find(|l| l.split_whitespace().nth(1) == Some("ports"))
        .unwrap_or_else(|| panic!("no ports line:\n{text}"));
    assert!(
        line.starts_with("warn") && line.contains(&format!("127.0.0.1:{port}")),
        "{text}"
    );
    assert!(
        text.contains("[camera.webrtc] signalling"),
        "no fix naming the setting:\n{text}"
    );
    let v = report(&cfg);
    let c = check(&v, "ports");
    assert_eq!(
        (c["ok"].clone(), c["warning"].clone()),
        (true.into(), true.into()),
        "{v}"
    );
    drop(held);
}

/// The service binds port 80 with a capability `sudo -u neptunus … doctor`
/// does not have: there, the port is free when nothing answers on it, and
/// taken when something does — never "in use" for want of the capability.
#[test]
fn port_80_is_judged_by_who_answers_there_not_by_this_users_rights() {
    use std::os::unix::fs::PermissionsExt as _;
    if !nix::unistd::geteuid().is_root() {
        // Only root can make an unprivileged user here (and bind port 80
        // for the second half); the test command runs as root.
        panic!("this test starts doctor as nobody: run it as root, as the test command does");
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o777)).unwrap();
    let board = Board::start("crc8");
    std::fs::set_permissions(&board.path, std::fs::Permissions::from_mode(0o666)).unwrap();
    let ip = format!("127.0.{}.9", rand::random::<u8>() % 200 + 20);
    let cfg = config(
        dir.path(),
        &board.path,
        "crc8",
        "[camera]\nsource = \"none\"\n",
    );
    // The HMI on port 80 of an address of its own.
    let text = std::fs::read_to_string(&cfg)
        .unwrap()
        .replace("http = \"127.0.0.1:0\"", &format!("http = \"{ip}:80\""));
    std::fs::write(&cfg, text).unwrap();
    std::fs::set_permissions(&cfg, std::fs::Permissions::from_mode(0o644)).unwrap();
    let as_nobody = || {
        let o = Command::new("setpriv")
            .args([
                "--reuid=65534",
                "--regid=65534",
                "--clear-groups",
                BIN,
                "--config",
            ])
            .arg(&cfg)
            .args(["doctor", "--json"])
            .output()
            .unwrap();
        let v: serde_json::Value = serde_json::from_slice(&o.stdout)
            .unwrap_or_else(|e| panic!("--json does not parse ({e}): {}", stdout(&o)));
        check(&v, "ports").clone()
    };
    let free = as_nobody();
    assert_eq!(free["ok"], true, "port 80 with nothing there: {free}");
    let held = std::net::TcpListener::bind(format!("{ip}:80")).unwrap();
    let taken = as_nobody();
    assert_eq!(
        taken["ok"], false,
        "port 80 with something answering: {taken}"
    );
    assert!(taken.to_string().contains(&format!("{ip}:80")), "{taken}");
    drop(held);
}
