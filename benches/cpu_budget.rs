//! The vehicle's CPU budget on the BeagleBone (one Cortex-A8 core at 1 GHz):
//! the ARM instructions the armhf build executes, counted under Debian 13's
//! `qemu-arm -cpu cortex-a8`, per unit of work, scaled to a second of each
//! footprint scenario and to a frame of each camera path at 640×480.
//!
//! How it counts (`cpu_budget/trace.rs`): qemu logs every translated block's
//! instructions and every executed block (`-d in_asm,exec,nochain`) and
//! every system call (`-d strace`) into a FIFO the bench reads as it comes.
//! That logging slows the guest far below real time, so a count per wall
//! second would be distorted; each figure is per unit of work instead:
//!
//! - **scenarios** (`idle`, `standard` of `benches/footprint.rs`, their
//!   board, station and HMI session): each runs twice under qemu, first
//!   without logging (the vehicle keeps real time there) to count the units
//!   it delivers per second — datagrams to the station plus HMI messages —
//!   then with logging, where the instructions and the units are counted
//!   over the same window. Instructions per second = instructions per unit
//!   × units per second at real time. "kept up" is the logged run's units
//!   per second over the reference's: below 1, the vehicle lagged under
//!   logging and the inputs it still handled in full (25 Hz sticks, board
//!   lines) are charged to fewer outputs — the figure errs high.
//! - **camera paths**: a fixed number of frames through each path, the
//!   instructions and system calls over them less the logged idle run's
//!   rates, per frame received by the path's consumer
//!   (`cpu_budget/camera.rs`).
//!
//! Shares of the BeagleBone: instructions per second / (IPC × 1 GHz). The
//! IPC is an assumption (`CPU_BUDGET_IPC`, default 0.5: half the Cortex-A8's
//! dual-issue peak of 2 per cycle, ARM's Cortex-A8 Technical Reference
//! Manual, DDI 0344; in-order cores lose much of it to cache misses and
//! branches in code like this). Kernel time is not in the count: the system
//! calls are, and the bench estimates the kernel's share from their rate at
//! `CPU_BUDGET_SYSCALL_US` (default 5 µs each on the A8, an estimate).
//!
//! Before the scenarios, a method check counts `neptunus --version` both
//! ways: block sizes × executions, and qemu's one-instruction-per-block mode
//! where every logged block is one instruction; they must agree.
//!
//! Environment: `NEPTUNUS_ARMHF_BIN` (default
//! `target/armv7-unknown-linux-gnueabihf/rov/neptunus`, `bash
//! debian/build-armhf.sh`), `NEPTUNUS_QEMU_ARM` (default
//! `target/qemu-trixie/root/usr/bin/qemu-arm`, fetched by `tests/armhf.sh`),
//! `NEPTUNUS_BIN` (the host build that runs the board emulator),
//! `CPU_BUDGET_WINDOW_S` (20; 3 under `cargo test`), `CPU_BUDGET_FRAMES`
//! (20; 3), `CPU_BUDGET_IPC`, `CPU_BUDGET_SYSCALL_US`, `CPU_BUDGET_PATHS`
//! (a comma list of the camera paths, default all). Figures are printed,
//! never asserted. Without the armhf binary or qemu the bench says what is
//! missing and stops with an error under `--bench`, and skips with that
//! line under `cargo test` (the test command's armhf step runs it for real).

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

#[path = "cpu_budget/camera.rs"]
mod camera;
#[allow(
    dead_code,
    reason = "shared with the footprint bench, which uses the rest"
)]
#[path = "footprint/children.rs"]
mod children;
#[path = "footprint/load.rs"]
mod load;
#[allow(
    dead_code,
    reason = "shared with the footprint bench, which uses the rest"
)]
#[path = "footprint/scenario.rs"]
mod scenario;
#[path = "cpu_budget/trace.rs"]
mod trace;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use scenario::Scenario;
use trace::{Counts, Tracer};

/// The BeagleBone Black's AM3358: one Cortex-A8 core at 1 GHz.
const CLOCK_HZ: f64 = 1e9;

pub struct Knobs {
    pub full: bool,
    pub window: Duration,
    pub settle: Duration,
    pub frames: u64,
    ipc: f64,
    syscall_us: f64,
    paths: Vec<camera::Path>,
}

/// The armhf vehicle and how to run it.
pub struct Arm {
    qemu: PathBuf,
    pub bin: PathBuf,
    /// The host build: the board emulator, the test clip's ffmpeg steps.
    pub host_bin: PathBuf,
    pub dir: tempfile::TempDir,
}

impl Arm {
    /// A launcher script: qemu-arm as a Cortex-A8 on the armhf binary, the
    /// vehicle's arguments after; with `log`, qemu's block, execution and
    /// system-call logs into that FIFO.
    pub fn launcher(&self, name: &str, log: Option<&Path>) -> anyhow::Result<PathBuf> {
        let path = self.dir.path().join(format!("{name}.sh"));
        let logging = match log {
            Some(fifo) => format!("-d in_asm,exec,nochain,strace -D '{}' ", fifo.display()),
            None => String::new(),
        };
        std::fs::write(
            &path,
            format!(
                "#!/bin/sh\nexec '{}' -cpu cortex-a8 -L /usr/arm-linux-gnueabihf {logging}'{}' \"$@\"\n",
                self.qemu.display(),
                self.bin.display()
            ),
        )?;
        let mut perm = std::fs::metadata(&path)?.permissions();
        std::os::unix::fs::PermissionsExt::set_mode(&mut perm, 0o755);
        std::fs::set_permissions(&path, perm)?;
        Ok(path)
    }

    pub fn fifo(&self, name: &str) -> PathBuf {
        self.dir.path().join(format!("{name}.log"))
    }
}

fn knobs() -> anyhow::Result<Knobs> {
    let full = std::env::args().any(|a| a == "--bench");
    let num = |name: &str, default: f64| -> anyhow::Result<f64> {
        match std::env::var(name).ok().filter(|v| !v.trim().is_empty()) {
            Some(v) => v
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite() && *x > 0.0)
                .with_context(|| format!("{name}={v} — use a number > 0")),
            None => Ok(default),
        }
    };
    let paths = match std::env::var("CPU_BUDGET_PATHS")
        .ok()
        .filter(|v| !v.trim().is_empty())
    {
        Some(v) => v
            .split(',')
            .map(|s| {
                camera::Path::parse(s).with_context(|| {
                    format!(
                        "CPU_BUDGET_PATHS: unknown path {s:?} — use a comma list of {}",
                        camera::Path::ALL.map(camera::Path::name).join(", ")
                    )
                })
            })
            .collect::<anyhow::Result<Vec<_>>>()?,
        None => camera::Path::ALL.to_vec(),
    };
    Ok(Knobs {
        full,
        window: Duration::from_secs_f64(num("CPU_BUDGET_WINDOW_S", if full { 20.0 } else { 3.0 })?),
        settle: Duration::from_secs(if full { 5 } else { 2 }),
        frames: num("CPU_BUDGET_FRAMES", if full { 20.0 } else { 3.0 })?.round() as u64,
        ipc: num("CPU_BUDGET_IPC", 0.5)?,
        syscall_us: num("CPU_BUDGET_SYSCALL_US", 5.0)?,
        paths,
    })
}

fn arm() -> anyhow::Result<Arm> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let pick = |var: &str, default: &str| {
        std::env::var_os(var)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
            .unwrap_or_else(|| root.join(default))
    };
    let bin = pick(
        "NEPTUNUS_ARMHF_BIN",
        "target/armv7-unknown-linux-gnueabihf/rov/neptunus",
    );
    let qemu = pick(
        "NEPTUNUS_QEMU_ARM",
        "target/qemu-trixie/root/usr/bin/qemu-arm",
    );
    if !bin.is_file() {
        bail!(
            "no armhf binary at {} — `bash debian/build-armhf.sh`, or set NEPTUNUS_ARMHF_BIN",
            bin.display()
        );
    }
    if !qemu.is_file() {
        bail!(
            "no qemu-arm at {} — `bash tests/armhf.sh` fetches Debian 13's, or set NEPTUNUS_QEMU_ARM",
            qemu.display()
        );
    }
    Ok(Arm {
        qemu,
        bin,
        host_bin: common::neptunus_bin()?,
        dir: tempfile::tempdir()?,
    })
}

fn main() -> anyhow::Result<()> {
    let k = knobs()?;
    let arm = match arm() {
        Ok(a) => a,
        Err(e) if !k.full => {
            println!("cpu_budget: smoke run skipped: {e:#}");
            return Ok(());
        }
        Err(e) => return Err(e),
    };
    header(&arm, &k);
    method_check(&arm)?;
    let mut rows = Vec::new();
    for s in [Scenario::Idle, Scenario::Standard] {
        rows.push(scenario_budget(s, &arm, &k)?);
    }
    print_scenarios(&rows, &k);
    let idle = camera::Idle {
        insns_per_s: rows[0].raw_per_s,
        syscalls_per_s: rows[0].raw_syscalls_per_s,
    };
    let mut frames = Vec::new();
    for &p in &k.paths {
        frames.push(camera::measure(p, &arm, &k, &idle)?);
    }
    camera::print(&frames, &k);
    Ok(())
}

fn header(arm: &Arm, k: &Knobs) {
    let out = |cmd: &Path, args: &[&str]| {
        std::process::Command::new(cmd)
            .args(args)
            .output()
            .ok()
            .map(|o| {
                String::from_utf8_lossy(&o.stdout)
                    .lines()
                    .next()
                    .unwrap_or("?")
                    .to_owned()
            })
            .unwrap_or_else(|| "?".into())
    };
    println!("neptunus CPU budget on the BeagleBone (armhf under qemu-arm -cpu cortex-a8)");
    println!(
        "date:     {}",
        out(Path::new("date"), &["-u", "+%Y-%m-%d %H:%M:%S UTC"])
    );
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|c| {
            c.lines()
                .find_map(|l| l.strip_prefix("model name"))
                .map(|v| v.trim_start_matches([' ', '\t', ':']).to_owned())
        })
        .unwrap_or_else(|| "?".into());
    println!(
        "host:     {cpu}, nproc {}",
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    println!(
        "binary:   {} ({} bytes)",
        arm.bin.display(),
        std::fs::metadata(&arm.bin).map_or(0, |m| m.len())
    );
    println!("qemu:     {}", out(&arm.qemu, &["--version"]));
    println!("board:    {} emulate-board (host)", arm.host_bin.display());
    println!(
        "window:   {:.0} s per run after {} s of settling; {} frames per camera path{}",
        k.window.as_secs_f64(),
        k.settle.as_secs(),
        k.frames,
        if k.full {
            ""
        } else {
            " — smoke run (no --bench)"
        }
    );
    println!(
        "CPU:      1 GHz Cortex-A8 at an assumed {} instructions per cycle; kernel time at an assumed {} µs per system call",
        k.ipc, k.syscall_us
    );
}

/// `neptunus --version` counted both ways.
fn method_check(arm: &Arm) -> anyhow::Result<()> {
    let run = |name: &str, flags: &[&str]| -> anyhow::Result<Counts> {
        let fifo = arm.fifo(name);
        let tracer = Tracer::start(&fifo)?;
        let status = std::process::Command::new(&arm.qemu)
            .args(["-cpu", "cortex-a8", "-L", "/usr/arm-linux-gnueabihf"])
            .args(flags)
            .arg("-D")
            .arg(&fifo)
            .arg(&arm.bin)
            .arg("--version")
            .stdout(std::process::Stdio::null())
            .status()?;
        let counts = tracer.finish()?;
        if !status.success() {
            bail!("qemu-arm {flags:?} neptunus --version: {status}");
        }
        Ok(counts)
    };
    let blocks = run("check-blocks", &["-d", "in_asm,exec,nochain"])?;
    let single = run("check-single", &["-one-insn-per-tb", "-d", "exec,nochain"])?;
    let ratio = blocks.insns as f64 / single.blocks.max(1) as f64;
    println!(
        "\nmethod check, `neptunus --version`: {} instructions from block sizes × executions ({} blocks, {} unknown, {} resized), {} one instruction per block: ratio {ratio:.4}",
        blocks.insns, blocks.blocks, blocks.unknown, blocks.resized, single.blocks
    );
    if !(0.98..=1.02).contains(&ratio) {
        bail!(
            "the two ways of counting disagree by more than 2 % ({ratio:.4}): the block-size count cannot be trusted"
        );
    }
    Ok(())
}

/// One scenario's figures.
struct Row {
    scenario: Scenario,
    /// The guest's resident memory at the end of the reference run, MB.
    guest_mb: f64,
    /// Units (datagrams to the station + HMI messages) per second, reference run.
    units_per_s: f64,
    /// The logged run's units per second over the reference's.
    kept_up: f64,
    insns_per_unit: f64,
    syscalls_per_unit: f64,
    /// Instructions per wall second in the logged run (for the camera paths' baseline).
    raw_per_s: f64,
    /// System calls per wall second in the logged run (the same baseline).
    raw_syscalls_per_s: f64,
    insns_per_s: f64,
    syscalls_per_s: f64,
}

fn units(t: [u64; 5]) -> u64 {
    t[0] + t[2]
}

fn scenario_budget(s: Scenario, arm: &Arm, k: &Knobs) -> anyhow::Result<Row> {
    let secs = k.window.as_secs_f64();
    // Reference: real time, no logging.
    let plain = arm.launcher("plain", None)?;
    let (reference, guest_mb) = {
        let mut r = scenario::start_on(s, &plain, &arm.host_bin, None)?;
        std::thread::sleep(k.settle);
        r.check()?;
        let t0 = r.tally.counts();
        std::thread::sleep(k.window);
        let t1 = r.tally.counts();
        r.check()?;
        let guest_mb = guest_resident_kb(r.vehicle.pid(), &arm.bin)? as f64 / 1024.0;
        (units(t1) - units(t0), guest_mb)
    };
    // Counting: the same scenario under qemu's logs.
    let name = format!("{}-count", s.name());
    let fifo = arm.fifo(&name);
    let tracer = Tracer::start(&fifo)?;
    let logged = arm.launcher(&name, Some(&fifo))?;
    let (counted, got, wall) = {
        let mut r = scenario::start_on(s, &logged, &arm.host_bin, None)
            .with_context(|| format!("{}: starting the vehicle under qemu's logs", s.name()))?;
        std::thread::sleep(k.settle);
        r.check()?;
        let (c0, t0, at) = (tracer.totals.counts(), r.tally.counts(), Instant::now());
        std::thread::sleep(k.window);
        let (c1, t1) = (tracer.totals.counts(), r.tally.counts());
        let wall = at.elapsed().as_secs_f64();
        r.check()?;
        (c1 - c0, units(t1) - units(t0), wall)
    };
    tracer.finish()?;
    if reference == 0 || got == 0 {
        bail!(
            "{}: no datagram or HMI message in a window (reference {reference}, logged {got})",
            s.name()
        );
    }
    let units_per_s = reference as f64 / secs;
    let insns_per_unit = counted.insns as f64 / got as f64;
    let syscalls_per_unit = counted.syscalls as f64 / got as f64;
    Ok(Row {
        scenario: s,
        guest_mb,
        units_per_s,
        kept_up: got as f64 / wall / units_per_s,
        insns_per_unit,
        syscalls_per_unit,
        raw_per_s: counted.insns as f64 / wall,
        raw_syscalls_per_s: counted.syscalls as f64 / wall,
        insns_per_s: insns_per_unit * units_per_s,
        syscalls_per_s: syscalls_per_unit * units_per_s,
    })
}

/// What the ARM program holds in memory under qemu-arm `pid`: the resident
/// pages of the guest's mappings, which qemu places in one reserved run of
/// the host's address space (the mappings around the binary's, with no gap
/// between them); qemu's own code, heap and translation cache lie outside.
fn guest_resident_kb(pid: u32, bin: &Path) -> anyhow::Result<u64> {
    let smaps = std::fs::read_to_string(format!("/proc/{pid}/smaps"))?;
    let bin = std::fs::canonicalize(bin)?;
    // (start, end, path, Rss kB) per mapping.
    let mut maps: Vec<(u64, u64, String, u64)> = Vec::new();
    for line in smaps.lines() {
        let mut f = line.split_whitespace();
        let first = f.next().unwrap_or("");
        if let Some((a, b)) = first.split_once('-')
            && let (Ok(a), Ok(b)) = (u64::from_str_radix(a, 16), u64::from_str_radix(b, 16))
        {
            let path = f.nth(4).unwrap_or("").to_owned();
            maps.push((a, b, path, 0));
        } else if first == "Rss:"
            && let Some(m) = maps.last_mut()
        {
            m.3 = f.next().and_then(|v| v.parse().ok()).unwrap_or(0);
        }
    }
    let at = maps
        .iter()
        .position(|m| Path::new(&m.2) == bin)
        .with_context(|| format!("{} is not mapped in process {pid}", bin.display()))?;
    let (mut lo, mut hi) = (at, at);
    while lo > 0 && maps[lo - 1].1 == maps[lo].0 {
        lo -= 1;
    }
    while hi + 1 < maps.len() && maps[hi + 1].0 == maps[hi].1 {
        hi += 1;
    }
    Ok(maps[lo..=hi].iter().map(|m| m.3).sum())
}

/// Share of the 1 GHz core, %.
pub fn share_pct(insns_per_s: f64, k: &Knobs) -> f64 {
    100.0 * insns_per_s / (k.ipc * CLOCK_HZ)
}

fn kernel_pct(syscalls_per_s: f64, k: &Knobs) -> f64 {
    100.0 * syscalls_per_s * k.syscall_us * 1e-6
}

fn print_scenarios(rows: &[Row], k: &Knobs) {
    println!(
        "\n{:<9} {:>10} {:>8} {:>12} {:>10} {:>11} {:>9} {:>10} {:>9} {:>9}  goal",
        "scenario",
        "units/s",
        "kept up",
        "insns/unit",
        "sys/unit",
        "Minsns/s",
        "user %",
        "syscall/s",
        "kernel %",
        "guest MB"
    );
    println!(
        "(units: datagrams to the station + HMI messages; user %: share of a 1 GHz Cortex-A8 at IPC {}; kernel %: estimated from the system calls at {} µs each; guest MB: the ARM program's resident memory at the end of the reference run)",
        k.ipc, k.syscall_us
    );
    for r in rows {
        let goal = match r.scenario {
            Scenario::Idle => "<= 1 %",
            Scenario::Standard => "<= 3 %",
            _ => "",
        };
        println!(
            "{:<9} {:>10.1} {:>8.2} {:>12.0} {:>10.2} {:>11.2} {:>9.2} {:>10.0} {:>9.2} {:>9.1}  {goal}",
            r.scenario.name(),
            r.units_per_s,
            r.kept_up,
            r.insns_per_unit,
            r.syscalls_per_unit,
            r.insns_per_s / 1e6,
            share_pct(r.insns_per_s, k),
            r.syscalls_per_s,
            kernel_pct(r.syscalls_per_s, k),
            r.guest_mb
        );
    }
}
