//! The `neptunus` binary as a user runs it.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;

const BIN: &str = env!("CARGO_BIN_EXE_neptunus");

#[test]
fn missing_serial_device_is_one_clear_line_suggesting_sim() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(BIN)
        .args(["--serial", "/dev/does-not-exist-neptunus", "--data-dir"])
        .arg(dir.path())
        .env("RUST_LOG", "error")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("/dev/does-not-exist-neptunus"), "{err}");
    assert!(lines[0].contains("--sim"), "{err}");
}

/// The genuine firmware's scenarios need the `hil` feature; without it the
/// flag is there and says how to get a build that has it, before running
/// anything.
#[cfg(not(feature = "hil"))]
#[test]
fn sim_report_with_the_firmware_in_the_loop_says_how_to_get_a_build_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("report");
    let out = Command::new(BIN)
        .args(["sim-report", "--hil", "../shared/openrov-firmware/30.0.2"])
        .arg(&report)
        .arg("--data-dir")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("the `hil` feature"), "{err}");
    assert!(err.contains("sim-report --hil FIRMWARE DIR"), "{err}");
    assert!(err.contains("gcc-avr"), "{err}");
    assert!(!report.exists(), "nothing written");
}

/// The package's build has no plotting stack: `sim-report` says how to get
/// a build that has it, before running anything.
#[cfg(not(feature = "report"))]
#[test]
fn sim_report_without_the_report_feature_says_how_to_get_it() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("report");
    let out = Command::new(BIN)
        .arg("sim-report")
        .arg(&report)
        .arg("--data-dir")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("`report` feature"), "{err}");
    assert!(err.contains("--features report"), "{err}");
    assert!(!report.exists(), "nothing written");
}

#[test]
fn bad_config_file_names_line_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("n.toml");
    std::fs::write(
        &cfg,
        "sim = true\n[board]\nbaud = 115200\nframming = \"crc8\"\n",
    )
    .unwrap();
    let out = Command::new(BIN)
        .arg("--config")
        .arg(&cfg)
        .arg("--data-dir")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("framming"), "{err}");
    assert!(err.contains("line 4"), "{err}");
}

#[test]
fn bad_framing_flag_is_refused() {
    let out = Command::new(BIN)
        .args(["--sim", "--framing", "crc16"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("crc16"));
}

#[test]
fn emulate_board_prints_a_tty_path() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("board");
    let mut child = Command::new(BIN)
        .args(["emulate-board", "--link"])
        .arg(&link)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert_eq!(line.trim(), link.to_str().unwrap());
    let target = std::fs::read_link(&link).unwrap();
    assert!(target.starts_with("/dev/pts/"), "{target:?}");
    child.kill().unwrap();
    child.wait().unwrap();
}

/// `neptunus --sim` brings the board link up through the emulator's pty and
/// logs decoded telemetry once a second.
#[test]
fn sim_runs_and_logs_telemetry() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(BIN)
        .arg("--sim")
        .arg("--data-dir")
        .arg(dir.path())
        // Ephemeral ports: tests never take the well-known ones.
        .args([
            "--mavlink",
            "udpin:127.0.0.1:0",
            "--mavlink",
            "tcpin:127.0.0.1:0",
            "--http",
            "127.0.0.1:0",
        ])
        .env("RUST_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = BufReader::new(child.stderr.take().unwrap());
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut up = false;
    let mut telemetry = 0;
    for line in stderr.lines() {
        let line = line.unwrap();
        up |= line.contains("board link up");
        if up && line.contains("telemetry") && line.contains("heading_deg") && !line.contains("NaN")
        {
            telemetry += 1;
        }
        if telemetry >= 2 || Instant::now() > deadline {
            break;
        }
    }
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let status = child.wait().unwrap();
    assert!(up, "board link never came up");
    assert!(telemetry >= 2, "telemetry lines: {telemetry}");
    assert!(status.success(), "clean exit on SIGTERM: {status:?}");
    let log = std::fs::read_to_string(dir.path().join("neptunus.log")).unwrap();
    assert!(log.contains("board link up"));
}

#[test]
fn bad_profiles_dir_stops_the_vehicle_at_start_with_the_place() {
    let dir = tempfile::tempdir().unwrap();
    let profiles = dir.path().join("profiles");
    std::fs::create_dir(&profiles).unwrap();
    std::fs::write(
        profiles.join("mine.toml"),
        "name = \"mine\"\nsysids = [250]\nz_convention = \"sideways\"\n",
    )
    .unwrap();
    let out = Command::new(BIN)
        .args(["--sim", "--mavlink", "udpin:127.0.0.1:0", "--profiles"])
        .arg(&profiles)
        .arg("--data-dir")
        .arg(dir.path())
        .env("RUST_LOG", "error")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("mine.toml") && err.contains(":3:"), "{err}");
}

/// `neptunus hmi set-password` reads one line from a pipe, stores an argon2
/// PHC string with mode 0600, and never prints the password;
/// `clear-password` removes it.
#[test]
fn hmi_set_and_clear_password() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str], stdin: &str| {
        let out = common::run_cli(std::path::Path::new(BIN), dir.path(), args, stdin);
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        (out.status.success(), text)
    };
    let (ok, text) = run(&["hmi", "set-password"], "short\n");
    assert!(!ok && text.contains("at least 8"), "{text}");
    let (ok, text) = run(&["hmi", "set-password"], "tide-pool-42\n");
    assert!(ok, "{text}");
    assert!(!text.contains("tide-pool-42"), "{text}");
    let file = dir.path().join("hmi-password");
    let phc = std::fs::read_to_string(&file).unwrap();
    assert!(phc.starts_with("$argon2id$v=19$"), "{phc}");
    assert_eq!(
        std::fs::metadata(&file).unwrap().permissions().mode() & 0o777,
        0o600
    );
    let (ok, text) = run(&["hmi", "status"], "");
    assert!(ok && text.contains("password set"), "{text}");
    let (ok, text) = run(&["hmi", "clear-password"], "");
    assert!(ok && text.contains("removed"), "{text}");
    assert!(!file.exists());
}
