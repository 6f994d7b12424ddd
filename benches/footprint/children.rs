//! The other processes of a scenario: the board emulator (`neptunus
//! emulate-board`, its own process so that only the vehicle's process is
//! measured) and MAVProxy, the baseline forwarding hop, with its install
//! into `target/interop-venv` exactly as `tests/run_all.sh` does it. Every
//! child is a [`Guarded`]: terminated, then killed, when it drops — also on
//! an error or a panic.

use std::fs::File;
use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// A child process, ended when this drops: SIGCONT + SIGTERM, SIGKILL after 2 s.
pub struct Guarded {
    pub child: Child,
    name: &'static str,
    log: PathBuf,
}

impl Guarded {
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// An error with the end of its output if it has exited.
    pub fn check_running(&mut self) -> anyhow::Result<()> {
        if let Ok(Some(status)) = self.child.try_wait() {
            bail!("{} exited ({status}):\n{}", self.name, self.tail());
        }
        Ok(())
    }

    /// The last lines of what it wrote.
    pub fn tail(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(12)..].join("\n")
    }
}

impl Drop for Guarded {
    fn drop(&mut self) {
        let pid = Pid::from_raw(self.child.id() as i32);
        let _ = kill(pid, Signal::SIGCONT);
        let _ = kill(pid, Signal::SIGTERM);
        let end = Instant::now() + Duration::from_secs(2);
        while Instant::now() < end {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `neptunus emulate-board` in its own process; returns it and its pty.
pub fn board(bin: &Path, dir: &Path) -> anyhow::Result<(Guarded, String)> {
    let log = dir.join("board.stderr");
    let child = Command::new(bin)
        .arg("emulate-board")
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(File::create(&log)?)
        .spawn()
        .with_context(|| format!("cannot start {} emulate-board", bin.display()))?;
    let mut board = Guarded {
        child,
        name: "neptunus emulate-board",
        log,
    };
    // It prints the pty's path on its first line, then nothing.
    let stdout = board.child.stdout.take().context("no stdout")?;
    let mut line = String::new();
    BufReader::new(stdout).read_line(&mut line)?;
    let path = line.trim().to_owned();
    if path.is_empty() {
        board.check_running()?;
        bail!("emulate-board printed no pty path");
    }
    Ok((board, path))
}

/// The venv's python with MAVProxy in it, installed if missing (as
/// `tests/run_all.sh` does: a venv at target/interop-venv with the pins of
/// tests/interop/requirements.txt, and the libraries cv2 needs from apt).
/// Prints each step it has to take.
#[allow(
    clippy::print_stdout,
    reason = "a bench says what it installs before it takes the time"
)]
pub fn mavproxy_python(root: &Path, target: &Path) -> anyhow::Result<PathBuf> {
    let venv = target.join("interop-venv");
    let reqs = root.join("tests/interop/requirements.txt");
    let python = venv.join("bin/python");
    let run = |what: &str, cmd: &mut Command| -> anyhow::Result<()> {
        println!("MAVProxy install: {what}");
        let out = cmd.stdin(Stdio::null()).output()?;
        if !out.status.success() {
            bail!(
                "{what} failed ({}):\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            );
        }
        Ok(())
    };
    let ok = |cmd: &mut Command| {
        cmd.stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    let apt = |what: &str, pkgs: &[&str]| -> anyhow::Result<()> {
        run(
            "apt-get update",
            Command::new("apt-get").args(["update", "-q"]),
        )?;
        run(
            what,
            Command::new("apt-get")
                .args(["install", "-y", "-q"])
                .args(pkgs)
                .env("DEBIAN_FRONTEND", "noninteractive"),
        )
    };
    if !ok(Command::new("python3").args(["-c", "import ensurepip, venv"])) {
        apt("apt-get install python3-venv", &["python3-venv"])?;
    }
    if !python.is_file() {
        run(
            &format!("python3 -m venv {}", venv.display()),
            Command::new("python3").args(["-m", "venv"]).arg(&venv),
        )?;
    }
    let installed = venv.join("requirements.installed");
    if std::fs::read(&reqs)? != std::fs::read(&installed).unwrap_or_default() {
        run(
            &format!("pip install -r {}", reqs.display()),
            Command::new(&python)
                .args([
                    "-m",
                    "pip",
                    "install",
                    "-q",
                    "--disable-pip-version-check",
                    "-r",
                ])
                .arg(&reqs),
        )?;
        std::fs::copy(&reqs, &installed)?;
    }
    // MAVProxy pulls in opencv-python, which needs libGL and glib at import time.
    if !ok(Command::new(&python).args(["-c", "import cv2"])) {
        apt(
            "apt-get install libgl1 libglib2.0-0",
            &["libgl1", "libglib2.0-0"],
        )?;
    }
    if !venv.join("bin/mavproxy.py").is_file() {
        bail!("{} has no mavproxy.py after the install", venv.display());
    }
    Ok(python)
}

/// MAVProxy's flags besides its links: see [`mavproxy`].
pub const MAVPROXY_FLAGS: [&str; 5] = [
    "--non-interactive",
    "--no-state",
    "--default-modules=",
    "--streamrate=-1",
    "--heartbeat-rate=0",
];

/// MAVProxy as a plain forwarding hop: the vehicle sends to `master_port`
/// (MAVProxy's `udpin`), MAVProxy forwards to the station listening on
/// `out_port` and back. No modules beyond its core `link`, no stream-rate
/// requests of its own (the station gets the vehicle's default rates), no
/// heartbeat of its own (the vehicle sees the station's traffic alone), no
/// logs written.
pub fn mavproxy(
    python: &Path,
    master_port: u16,
    out_port: u16,
    dir: &Path,
) -> anyhow::Result<Guarded> {
    let home = dir.join("mavproxy-home");
    std::fs::create_dir_all(&home)?;
    let log = dir.join("mavproxy.out");
    let out = File::create(&log)?;
    let script = python.with_file_name("mavproxy.py");
    let child = Command::new(python)
        .arg(&script)
        .arg(format!("--master=udpin:127.0.0.1:{master_port}"))
        .arg(format!("--out=udpout:127.0.0.1:{out_port}"))
        .args(MAVPROXY_FLAGS)
        .current_dir(&home)
        .env("HOME", &home)
        .env("TERM", "dumb")
        .stdin(Stdio::null())
        .stdout(out.try_clone()?)
        .stderr(out)
        .spawn()
        .with_context(|| format!("cannot start {}", script.display()))?;
    Ok(Guarded {
        child,
        name: "MAVProxy",
        log,
    })
}
