//! Shared by the tests and benches that run the `neptunus` binary as a child
//! process: finding the binary, the process itself (never left behind, not
//! even stopped), a bare UDP ground station (sysid 255, MAVLink 2 through our
//! dialect) and the board emulator on a real pty. The `*_core` tests, which
//! drive the vehicle core alone on synthetic time, share [`core_rig`].
//!
//! Tests include it as `mod common;`, benches as
//! `#[path = "../tests/common/mod.rs"] mod common;`. Waiting is always for a
//! condition with a deadline; nothing here sleeps to let time pass.
#![allow(
    dead_code,
    reason = "each test or bench binary uses a part of this module"
)]

pub mod core_rig;
pub mod stick;

use std::fs::File;
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc as std_mpsc;
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use neptunus::dialect::neptunus::*;
use neptunus::firmware::emulator::{BoardRecord, BoardSnapshot, EmulatorOptions, PtyBoard};
use neptunus::mavlink::frame::{FrameStats, decode_datagram, encode_v2};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// The ground station's system id: SYSID_MYGCS, the primary GCS.
pub const GCS_SYSID: u8 = 255;
const GCS_COMPID: u8 = 190;
const VEHICLE_SYSID: u8 = 1;
/// What the board executes when the thrusters stop.
pub const NEUTRAL_GO: &str = "go(1500,1500,1500)";
pub const NEUTRAL_US: [u16; 3] = [1500; 3];
const HEARTBEAT_PERIOD: Duration = Duration::from_secs(1);
/// MANUAL_CONTROL at 25 Hz, as a joystick GCS sends it.
const STICK_PERIOD: Duration = Duration::from_millis(40);
/// How long one `recv` waits: short, so the send schedule keeps its rate
/// even when the vehicle is silent (stopped, or between datagrams).
const RECV_WAIT: Duration = Duration::from_millis(5);

// ---------------------------------------------------------------------------
// The binary under test (benches)
// ---------------------------------------------------------------------------

/// `$NEPTUNUS_BIN`, else `target/release/neptunus`, else
/// `target/debug/neptunus` with a warning. Benches measure the release
/// build; tests use `env!("CARGO_BIN_EXE_neptunus")` instead.
#[allow(
    clippy::print_stdout,
    reason = "the warning is part of a bench's output"
)]
pub fn neptunus_bin() -> anyhow::Result<PathBuf> {
    if let Ok(p) = std::env::var("NEPTUNUS_BIN") {
        let p = PathBuf::from(p);
        if !p.is_file() {
            bail!(
                "NEPTUNUS_BIN={} is not a file — point it at a built neptunus binary",
                p.display()
            );
        }
        return Ok(p);
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .map(|t| if t.is_relative() { root.join(t) } else { t })
        .unwrap_or_else(|| root.join("target"));
    let release = target.join("release/neptunus");
    let debug = target.join("debug/neptunus");
    let bin = if release.is_file() {
        release
    } else if debug.is_file() {
        println!(
            "WARNING: {} not found, measuring the debug build — run `cargo build --release` first for meaningful figures",
            release.display()
        );
        debug
    } else {
        bail!(
            "no neptunus binary at {} — run `cargo build --release` before `cargo bench`, or set NEPTUNUS_BIN",
            release.display()
        );
    };
    // A binary older than the sources measures something else.
    if let (Ok(built), Some(newest)) = (
        std::fs::metadata(&bin).and_then(|m| m.modified()),
        newest_mtime(&root.join("src")),
    ) && newest > built
    {
        println!(
            "WARNING: {} is older than the sources — rebuild with `cargo build --release`",
            bin.display()
        );
    }
    Ok(bin)
}

fn newest_mtime(dir: &Path) -> Option<std::time::SystemTime> {
    let mut newest = None;
    for entry in std::fs::read_dir(dir).ok()?.flatten() {
        let path = entry.path();
        let t = if path.is_dir() {
            newest_mtime(&path)
        } else {
            entry.metadata().and_then(|m| m.modified()).ok()
        };
        newest = newest.max(t);
    }
    newest
}

// ---------------------------------------------------------------------------
// The vehicle process
// ---------------------------------------------------------------------------

/// Runs `BIN ARGS --data-dir DATA` (a CLI command such as `hmi
/// set-password`) to its end with `stdin` piped in.
pub fn run_cli(bin: &Path, data: &Path, args: &[&str], stdin: &str) -> std::process::Output {
    use std::io::Write as _;
    let mut child = Command::new(bin)
        .args(args)
        .arg("--data-dir")
        .arg(data)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot start neptunus");
    if let Some(mut pipe) = child.stdin.take() {
        // A command that does not read its input may have exited already.
        let _ = pipe.write_all(stdin.as_bytes());
    }
    child.wait_with_output().expect("neptunus did not finish")
}

/// The `neptunus` child process. On drop it is continued (it may have been
/// stopped with SIGSTOP), sent SIGTERM, and killed if it has not exited
/// within 2 s — also when the test using it panics.
pub struct Vehicle {
    pub child: Child,
    stderr_path: PathBuf,
    data_dir: PathBuf,
}

impl Vehicle {
    /// Starts `bin args… --data-dir DIR/data` with its stderr in
    /// `DIR/neptunus.stderr`. A non-empty `params_toml` is written to
    /// `DIR/data/params.toml` first (flat TOML, `NAME = value` lines).
    /// Without `--http` in `args`, the browser HMI listens on a free
    /// loopback port (never the default 8080: tests run side by side).
    pub fn spawn(bin: &Path, args: &[&str], dir: &Path, params_toml: &str) -> anyhow::Result<Self> {
        Self::spawn_env(bin, args, dir, params_toml, &[])
    }

    /// [`spawn`](Self::spawn) with extra environment variables.
    pub fn spawn_env(
        bin: &Path,
        args: &[&str],
        dir: &Path,
        params_toml: &str,
        env: &[(&str, &str)],
    ) -> anyhow::Result<Self> {
        let stderr_path = dir.join("neptunus.stderr");
        let stderr = File::create(&stderr_path)?;
        let mut vehicle = Self::spawn_to(bin, args, dir, params_toml, env, stderr.into())?;
        vehicle.stderr_path = stderr_path;
        Ok(vehicle)
    }

    /// [`spawn_env`](Self::spawn_env) with its stderr going to `stderr`
    /// (a pipe, say) instead of `DIR/neptunus.stderr`: then
    /// [`stderr_text`](Self::stderr_text) is empty.
    pub fn spawn_to(
        bin: &Path,
        args: &[&str],
        dir: &Path,
        params_toml: &str,
        env: &[(&str, &str)],
        stderr: Stdio,
    ) -> anyhow::Result<Self> {
        let data = dir.join("data");
        if !params_toml.is_empty() {
            std::fs::create_dir_all(&data)?;
            std::fs::write(data.join("params.toml"), params_toml)?;
        }
        let stderr_path = dir.join("neptunus.stderr.absent");
        let mut cmd = Command::new(bin);
        cmd.args(args);
        // Its own process group: a wrapper (`faketime`) runs the vehicle as
        // its child, and the group is what is stopped at the end.
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        if !args.contains(&"--http") {
            cmd.args(["--http", "127.0.0.1:0"]);
        }
        let child = cmd
            .arg("--data-dir")
            .arg(&data)
            .env("RUST_LOG", "warn")
            .envs(env.iter().copied())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr)
            .spawn()
            .with_context(|| format!("cannot start {}", bin.display()))?;
        Ok(Self {
            child,
            stderr_path,
            data_dir: data,
        })
    }

    /// The browser HMI's address, from `DATA_DIR/http.addr` (waits for it;
    /// the file holds `ADDR`, or `https://ADDR/` with TLS on).
    pub fn http_addr(&mut self, within: Duration) -> anyhow::Result<std::net::SocketAddr> {
        let path = self.data_dir.join("http.addr");
        let end = Instant::now() + within;
        loop {
            if let Ok(text) = std::fs::read_to_string(&path)
                && let Ok(addr) = text
                    .trim()
                    .trim_start_matches("https://")
                    .trim_end_matches('/')
                    .parse()
            {
                return Ok(addr);
            }
            self.check_running()?;
            if Instant::now() >= end {
                bail!("no {} within {within:?}", path.display());
            }
            thread::sleep(Duration::from_millis(20));
        }
    }

    /// Its data directory (`DIR/data`).
    pub fn data_dir(&self) -> &Path {
        &self.data_dir
    }

    /// The whole of its stderr.
    pub fn stderr_text(&self) -> String {
        std::fs::read_to_string(&self.stderr_path).unwrap_or_default()
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    fn nix_pid(&self) -> Pid {
        Pid::from_raw(self.child.id() as i32)
    }

    /// Sends `signal` to the process.
    pub fn signal(&self, signal: Signal) -> anyhow::Result<()> {
        kill(self.nix_pid(), signal).with_context(|| format!("kill -{signal} {}", self.pid()))
    }

    /// The last lines of its stderr, for error messages.
    pub fn stderr_tail(&self) -> String {
        let text = std::fs::read_to_string(&self.stderr_path).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(10)..].join("\n")
    }

    /// An error (with its stderr) if the process has exited.
    pub fn check_running(&mut self) -> anyhow::Result<()> {
        if let Ok(Some(status)) = self.child.try_wait() {
            bail!("neptunus exited ({status}):\n{}", self.stderr_tail());
        }
        Ok(())
    }
}

impl Drop for Vehicle {
    fn drop(&mut self) {
        // A stopped process holds SIGTERM pending: continue it first, or it
        // would outlive us, frozen.
        let _ = kill(self.nix_pid(), Signal::SIGCONT);
        let _ = kill(self.nix_pid(), Signal::SIGTERM);
        // A wrapper's child too (the group's id is the leader's pid).
        let group = nix::unistd::Pid::from_raw(-self.nix_pid().as_raw());
        let _ = kill(group, Signal::SIGCONT);
        let _ = kill(group, Signal::SIGTERM);
        let end = Instant::now() + Duration::from_secs(2);
        while Instant::now() < end {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            thread::sleep(Duration::from_millis(20));
        }
        let _ = kill(group, Signal::SIGKILL);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The state letter in `/proc/<pid>/stat`: `R`, `S`, `T` when stopped, ….
pub fn proc_state(pid: u32) -> Option<char> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) may contain spaces; the state follows its `)`.
    let (_, rest) = stat.rsplit_once(')')?;
    rest.trim_start().chars().next()
}

/// A loopback port nobody uses right now, for `udpin:` (the vehicle binds it).
pub fn free_udp_port() -> anyhow::Result<u16> {
    Ok(UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port())
}

// ---------------------------------------------------------------------------
// The ground station
// ---------------------------------------------------------------------------

pub fn manual_control(x: i16) -> MavMessage {
    sticks(x, 500, 0)
}

/// MANUAL_CONTROL with forward `x`, throttle `z` (500 neutral, below dives)
/// and yaw `r`.
pub fn sticks(x: i16, z: i16, r: i16) -> MavMessage {
    MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
        x,
        y: 0,
        z,
        r,
        target: VEHICLE_SYSID,
        ..Default::default()
    })
}

pub fn gcs_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
        ..Default::default()
    })
}

/// What the ground station sends while it waits for something.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Traffic {
    /// Nothing: the station has gone silent.
    Silent,
    /// HEARTBEAT at 1 Hz.
    Heartbeats,
    /// HEARTBEAT at 1 Hz and MANUAL_CONTROL with this `x` (z neutral) at 25 Hz.
    Drive(i16),
    /// HEARTBEAT at 1 Hz and MANUAL_CONTROL with these `x`, `z`, `r` at 25 Hz.
    Sticks { x: i16, z: i16, r: i16 },
}

/// Whether a HEARTBEAT says the vehicle is armed.
pub fn armed(hb: &HEARTBEAT_DATA) -> bool {
    hb.base_mode
        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
}

/// A STATUSTEXT's text (one chunk).
pub fn statustext(s: &STATUSTEXT_DATA) -> String {
    let b: &[u8] = s.text.as_ref();
    String::from_utf8_lossy(b).trim_end_matches('\0').to_owned()
}

/// A bare UDP ground station, sysid [`GCS_SYSID`] unless changed.
pub struct Gcs {
    pub sock: UdpSocket,
    /// The system id it sends as ([`GCS_SYSID`] by default; the footprint
    /// bench runs several stations side by side).
    pub sysid: u8,
    pub seq: u8,
    next_heartbeat: Instant,
    next_stick: Instant,
    /// When the last HEARTBEAT or MANUAL_CONTROL was sent: the last sign of
    /// life the vehicle has from us.
    pub last_life: Option<Instant>,
}

impl Gcs {
    fn new(sock: UdpSocket) -> anyhow::Result<Self> {
        sock.set_read_timeout(Some(RECV_WAIT))?;
        let now = Instant::now();
        Ok(Self {
            sock,
            sysid: GCS_SYSID,
            seq: 0,
            next_heartbeat: now,
            next_stick: now,
            last_life: None,
        })
    }

    /// A station talking to a `udpin:127.0.0.1:<port>` vehicle.
    pub fn connect(port: u16) -> anyhow::Result<Self> {
        let sock = UdpSocket::bind("127.0.0.1:0")?;
        sock.connect(("127.0.0.1", port))?;
        Self::new(sock)
    }

    /// A station for a `udpout:127.0.0.1:<port>` vehicle: bound here, it
    /// learns the vehicle's address from its first datagram
    /// ([`Gcs::await_vehicle`]).
    pub fn bind() -> anyhow::Result<(Self, u16)> {
        let sock = UdpSocket::bind("127.0.0.1:0")?;
        let port = sock.local_addr()?.port();
        Ok((Self::new(sock)?, port))
    }

    /// Waits for the vehicle's first datagram and talks to its sender from
    /// then on.
    pub fn await_vehicle(&mut self, vehicle: &mut Vehicle, within: Duration) -> anyhow::Result<()> {
        let end = Instant::now() + within;
        let mut buf = [0u8; 4096];
        loop {
            vehicle.check_running()?;
            if Instant::now() > end {
                bail!(
                    "no datagram from neptunus within {within:?}:\n{}",
                    vehicle.stderr_tail()
                );
            }
            if let Ok((n, from)) = self.sock.recv_from(&mut buf) {
                let mut frames = Vec::new();
                decode_datagram(&buf[..n], &mut FrameStats::default(), &mut frames);
                if frames.iter().any(|f| f.sysid == VEHICLE_SYSID) {
                    self.sock.connect(from)?;
                    return Ok(());
                }
            }
        }
    }

    /// Sends one message; returns the moment just before it went out.
    pub fn send(&mut self, msg: &MavMessage) -> anyhow::Result<Instant> {
        let bytes = encode_v2(self.sysid, GCS_COMPID, self.seq, msg);
        self.seq = self.seq.wrapping_add(1);
        let at = Instant::now();
        // Before a udpin vehicle has bound its port (or after it exited),
        // loopback answers ECONNREFUSED on a connected socket: not an error
        // here; a vehicle that exited is caught by `check_running`.
        match self.sock.send(&bytes) {
            Ok(_) => Ok(at),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => Ok(at),
            Err(e) => Err(e.into()),
        }
    }

    /// The vehicle's (its autopilot's, component 1: not the camera
    /// component's) messages in one datagram, or none after a short wait.
    pub fn recv(&self) -> Vec<MavMessage> {
        let mut buf = [0u8; 4096];
        let mut out = Vec::new();
        if let Ok(n) = self.sock.recv(&mut buf) {
            decode_datagram(&buf[..n], &mut FrameStats::default(), &mut out);
        }
        out.into_iter()
            .filter(|f| f.sysid == VEHICLE_SYSID && f.compid == 1)
            .map(|f| f.msg)
            .collect()
    }

    /// Sends whatever `traffic` has due now.
    pub fn pump(&mut self, traffic: Traffic) -> anyhow::Result<()> {
        if traffic == Traffic::Silent {
            return Ok(());
        }
        let now = Instant::now();
        if now >= self.next_heartbeat {
            self.next_heartbeat = now + HEARTBEAT_PERIOD;
            self.last_life = Some(self.send(&gcs_heartbeat())?);
        }
        let stick = match traffic {
            Traffic::Drive(x) => Some(manual_control(x)),
            Traffic::Sticks { x, z, r } => Some(sticks(x, z, r)),
            Traffic::Silent | Traffic::Heartbeats => None,
        };
        if let Some(msg) = stick
            && now >= self.next_stick
        {
            self.next_stick = now + STICK_PERIOD;
            self.last_life = Some(self.send(&msg)?);
        }
        Ok(())
    }

    /// Sends `traffic` and reads the vehicle until `done` (called after
    /// every read, with what it brought, possibly nothing) says so: `true`,
    /// or `false` when `within` has passed first.
    pub fn run_until(
        &mut self,
        vehicle: &mut Vehicle,
        traffic: Traffic,
        within: Duration,
        mut done: impl FnMut(&[MavMessage]) -> bool,
    ) -> anyhow::Result<bool> {
        let end = Instant::now() + within;
        loop {
            vehicle.check_running()?;
            self.pump(traffic)?;
            if done(&self.recv()) {
                return Ok(true);
            }
            if Instant::now() >= end {
                return Ok(false);
            }
        }
    }

    /// Heartbeats until a SYS_STATUS reports PREARM_CHECK healthy (fresh
    /// board telemetry, the link up): arming can succeed.
    pub fn wait_ready(&mut self, vehicle: &mut Vehicle) -> anyhow::Result<()> {
        let ready = self.run_until(vehicle, Traffic::Heartbeats, Duration::from_secs(30), |msgs| {
            msgs.iter().any(|m| {
                matches!(m, MavMessage::SYS_STATUS(s) if s.onboard_control_sensors_health.contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK))
            })
        })?;
        if !ready {
            bail!(
                "neptunus did not report PREARM_CHECK healthy within 30 s:\n{}",
                vehicle.stderr_tail()
            );
        }
        Ok(())
    }

    /// Sends COMMAND_LONG `command` to the vehicle; returns when it went out.
    pub fn send_command(&mut self, command: MavCmd, param1: f32) -> anyhow::Result<Instant> {
        self.send(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1,
            command,
            target_system: VEHICLE_SYSID,
            target_component: 1,
            ..Default::default()
        }))
    }

    /// Waits (with heartbeats) for the COMMAND_ACK of `command`.
    pub fn await_ack(
        &mut self,
        vehicle: &mut Vehicle,
        command: MavCmd,
    ) -> anyhow::Result<MavResult> {
        let mut result = None;
        self.run_until(
            vehicle,
            Traffic::Heartbeats,
            Duration::from_secs(5),
            |msgs| {
                result = msgs.iter().find_map(|m| match m {
                    MavMessage::COMMAND_ACK(a) if a.command == command => Some(a.result),
                    _ => None,
                });
                result.is_some()
            },
        )?;
        result.with_context(|| format!("no COMMAND_ACK for {command:?} within 5 s"))
    }

    /// COMMAND_LONG `command` with all seven parameters; its result.
    pub fn command_with(
        &mut self,
        vehicle: &mut Vehicle,
        command: MavCmd,
        p: [f32; 7],
    ) -> anyhow::Result<MavResult> {
        self.send(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            command,
            target_system: VEHICLE_SYSID,
            target_component: 1,
            ..Default::default()
        }))?;
        self.await_ack(vehicle, command)
    }

    /// COMMAND_LONG `command` with `param1`; its result.
    pub fn command(
        &mut self,
        vehicle: &mut Vehicle,
        command: MavCmd,
        param1: f32,
    ) -> anyhow::Result<MavResult> {
        self.send_command(command, param1)?;
        self.await_ack(vehicle, command)
    }

    /// Waits until the vehicle is ready, then arms it (which claims control
    /// for us if nobody has it).
    pub fn arm(&mut self, vehicle: &mut Vehicle) -> anyhow::Result<()> {
        self.wait_ready(vehicle)?;
        match self.command(vehicle, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0)? {
            MavResult::MAV_RESULT_ACCEPTED => Ok(()),
            r => bail!("arming refused: {r:?}:\n{}", vehicle.stderr_tail()),
        }
    }

    /// A parameter's value, read with PARAM_REQUEST_READ.
    pub fn param(&mut self, vehicle: &mut Vehicle, name: &str) -> anyhow::Result<f32> {
        self.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system: VEHICLE_SYSID,
            target_component: 1,
            param_id: name.into(),
        }))?;
        let mut value = None;
        self.run_until(
            vehicle,
            Traffic::Heartbeats,
            Duration::from_secs(5),
            |msgs| {
                value = msgs.iter().find_map(|m| match m {
                    MavMessage::PARAM_VALUE(v) if v.param_id.to_str() == Ok(name) => {
                        Some(v.param_value)
                    }
                    _ => None,
                });
                value.is_some()
            },
        )?;
        value.with_context(|| format!("no PARAM_VALUE for {name} within 5 s"))
    }

    /// Reads (and drops) the vehicle's datagrams on a clone of the socket
    /// until `stop`, so they never pile up; returns how many arrived.
    pub fn drain(&self, stop: Arc<AtomicBool>) -> anyhow::Result<thread::JoinHandle<u64>> {
        let sock = self.sock.try_clone()?;
        Ok(thread::spawn(move || {
            let mut buf = [0u8; 4096];
            let mut n = 0;
            while !stop.load(Ordering::Relaxed) {
                if sock.recv(&mut buf).is_ok() {
                    n += 1;
                }
            }
            n
        }))
    }
}

// ---------------------------------------------------------------------------
// The board emulator
// ---------------------------------------------------------------------------

/// A runtime for board emulators. One worker keeps the test or bench off the
/// second core as much as it can (the machine may have only two).
pub fn board_runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?)
}

/// A board emulator on a fresh pty, optionally reachable at `symlink`.
pub fn spawn_board(
    rt: &tokio::runtime::Runtime,
    symlink: Option<PathBuf>,
) -> anyhow::Result<PtyBoard> {
    let _rt = rt.enter();
    Ok(PtyBoard::spawn(EmulatorOptions::default(), symlink)?)
}

/// Forwards the board's records that `pick` turns into text, with the time
/// the emulator woke to handle them, to a std channel (blocking code can
/// wait on it). Records from now on; the channel is unbounded.
pub fn forward_records(
    rt: &tokio::runtime::Runtime,
    board: &PtyBoard,
    pick: fn(&BoardRecord) -> Option<String>,
) -> std_mpsc::Receiver<(Instant, String)> {
    let mut records = board.control().timed_records();
    let (tx, rx) = std_mpsc::channel();
    rt.spawn(async move {
        loop {
            match records.recv().await {
                Ok(r) => {
                    if let Some(text) = pick(&r.record)
                        && tx.send((r.at, text)).is_err()
                    {
                        break;
                    }
                }
                Err(tokio::sync::broadcast::error::RecvError::Lagged(n)) => {
                    tracing::warn!("lagged {n} board records");
                }
                Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
            }
        }
    });
    rx
}

/// The text of an executed command, `go(1500,1500,1500)`, `ping(0)`, ….
pub fn executed_text(r: &BoardRecord) -> Option<String> {
    match r {
        BoardRecord::Executed(text) => Some(text.clone()),
        BoardRecord::Frame(_) => None,
    }
}

/// `neptunus --serial <pty>` against a board emulator in this process, and a
/// ground station it sends to (`udpout`). Fields drop in order: the vehicle
/// process first, the runtime and the data directory last.
pub struct Rig {
    pub vehicle: Vehicle,
    pub gcs: Gcs,
    pub board: PtyBoard,
    /// Every command the board executed since before the vehicle started,
    /// with the time: `go(1500,1500,1500)`, `ping(0)`, ….
    pub executed: std_mpsc::Receiver<(Instant, String)>,
    pub rt: tokio::runtime::Runtime,
    _dir: tempfile::TempDir,
}

impl Rig {
    /// Starts the board, then `bin --serial <pty>` with `params_toml`
    /// preset, and waits for the vehicle's first datagram.
    pub fn start(bin: &Path, params_toml: &str) -> anyhow::Result<Self> {
        Self::start_with(bin, params_toml, &[], None)
    }

    /// [`start`](Self::start) with extra environment variables and, when
    /// given, the vehicle's stderr going to `stderr`.
    pub fn start_with(
        bin: &Path,
        params_toml: &str,
        env: &[(&str, &str)],
        stderr: Option<Stdio>,
    ) -> anyhow::Result<Self> {
        let dir = tempfile::tempdir()?;
        let rt = board_runtime()?;
        let board = spawn_board(&rt, None)?;
        let executed = forward_records(&rt, &board, executed_text);
        let (mut gcs, port) = Gcs::bind()?;
        let serial = board.path().to_string_lossy().into_owned();
        let endpoint = format!("udpout:127.0.0.1:{port}");
        let args = ["--serial", serial.as_str(), "--mavlink", endpoint.as_str()];
        let mut vehicle = match stderr {
            Some(to) => Vehicle::spawn_to(bin, &args, dir.path(), params_toml, env, to)?,
            None => Vehicle::spawn_env(bin, &args, dir.path(), params_toml, env)?,
        };
        gcs.await_vehicle(&mut vehicle, Duration::from_secs(30))?;
        Ok(Self {
            vehicle,
            gcs,
            board,
            executed,
            rt,
            _dir: dir,
        })
    }

    pub fn snapshot(&self) -> BoardSnapshot {
        self.board.control().snapshot()
    }

    /// Arms, then drives forward until the board's motors leave neutral.
    pub fn arm_and_drive(&mut self, x: i16) -> anyhow::Result<()> {
        self.gcs.arm(&mut self.vehicle)?;
        let control = self.board.control();
        let moving = self.gcs.run_until(
            &mut self.vehicle,
            Traffic::Drive(x),
            Duration::from_secs(10),
            |_| control.snapshot().motors_us != NEUTRAL_US,
        )?;
        if !moving {
            bail!(
                "the board's motors stayed neutral for 10 s of MANUAL_CONTROL x={x} (snapshot {:?}):\n{}",
                control.snapshot(),
                self.vehicle.stderr_tail()
            );
        }
        Ok(())
    }
}

/// Nearest-rank percentile of sorted durations, in ms.
pub fn pct_ms(sorted: &[Duration], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1].as_secs_f64() * 1e3
}

/// utime + stime of a process (all its threads, living and exited), in
/// clock ticks, from `/proc/PID/stat`.
pub fn proc_cpu_ticks(pid: u32) -> anyhow::Result<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .with_context(|| format!("process {pid} has exited"))?;
    // The command name (field 2) may contain spaces; fields follow its `)`:
    // `rest` starts at field 3, utime and stime are fields 14 and 15.
    let rest = stat
        .rsplit_once(')')
        .map(|(_, r)| r)
        .context("unexpected /proc/PID/stat format")?;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: u64 = fields.get(11).context("no utime")?.parse()?;
    let stime: u64 = fields.get(12).context("no stime")?.parse()?;
    Ok(utime + stime)
}

/// Clock ticks per second (`getconf CLK_TCK`; 100 if it cannot tell).
pub fn clock_ticks_per_s() -> f64 {
    static TICKS: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *TICKS.get_or_init(|| {
        Command::new("getconf")
            .arg("CLK_TCK")
            .output()
            .ok()
            .and_then(|o| String::from_utf8(o.stdout).ok())
            .and_then(|s| s.trim().parse().ok())
            .unwrap_or(100.0)
    })
}

/// (message id, Hz): the 36 SET_MESSAGE_INTERVALs Cockpit sends at
/// connect, plus NAMED_VALUE_FLOAT and NEPTUNUS_ESTIMATE (the benches'
/// Cockpit-like clients).
pub const COCKPIT_RATES: [(u32, f32); 38] = [
    (30, 16.0),
    (178, 16.0),
    (74, 16.0),
    (44102, 16.0),
    (0, 1.0),
    (1, 2.0),
    (2, 1.0),
    (33, 5.0),
    (36, 5.0),
    (137, 2.0),
    (147, 2.0),
    (251, 2.0),
    (22, 1.0),
    (24, 1.0),
    (27, 2.0),
    (29, 2.0),
    (35, 2.0),
    (65, 2.0),
    (100, 1.0),
    (116, 2.0),
    (124, 1.0),
    (125, 1.0),
    (127, 1.0),
    (128, 1.0),
    (129, 2.0),
    (132, 2.0),
    (143, 2.0),
    (152, 1.0),
    (162, 1.0),
    (163, 2.0),
    (173, 2.0),
    (191, 1.0),
    (192, 1.0),
    (193, 2.0),
    (194, 2.0),
    (241, 1.0),
    (242, 1.0),
    (285, 5.0),
];

/// The genuine OpenROV firmware's sources of `version` (`30.0.2`,
/// `2014-12`): `$OPENROV_FIRMWARE_DIR/<version>`, else
/// `../shared/openrov-firmware/<version>` beside the repository.
pub fn firmware_dir(version: &str) -> PathBuf {
    let root = std::env::var_os("OPENROV_FIRMWARE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/openrov-firmware")
        });
    let dir = root.join(version);
    assert!(
        dir.join("OpenROV/OpenROV.ino").is_file(),
        "the genuine OpenROV firmware {version} is not at {} — set OPENROV_FIRMWARE_DIR to a folder \
         holding {version}/ (git clone https://github.com/OpenROV/openrov-software-arduino {version} \
         && git -C {version} checkout {version}; the 2014-12 snapshot is commit 60a085280663; \
         docs/guide/src/hil.md says more)",
        dir.display()
    );
    dir
}
