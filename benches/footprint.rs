//! The vehicle's footprint on the ROV's computer, side by side with
//! MAVProxy under the same load.
//!
//! The release binary (`$NEPTUNUS_BIN`, else `target/release/neptunus`)
//! runs as `neptunus --serial <pty>` against `neptunus emulate-board` in
//! its own process, so only the vehicle's process is measured, in fixed
//! scenarios:
//!
//! - **idle**: board link up, HMI on, the vehicle's default telemetry to one
//!   UDP station that listens (as QGroundControl does on 14550: the vehicle
//!   sends to it, `udpout:`) and reads everything, nobody driving;
//! - **standard**: that station sends HEARTBEAT at 1 Hz and MANUAL_CONTROL at
//!   25 Hz (neutral sticks, disarmed) and receives ArduSub's default stream
//!   rates; one browser HMI session (the page's protocol: reads everything,
//!   `alive` every 0.5 s);
//! - **heavy**: three stations (255 as above; 254 and 253 send heartbeats to
//!   a `udpin:` endpoint), five HMI sessions, one Cockpit-like mavlink2rest
//!   client (Cockpit's message intervals, a heartbeat, reads everything), and
//!   one `/video.mjpg` viewer. The video is relayed from an MJPEG camera the
//!   bench serves on loopback (640×480 at 10 fps, `[camera] source = "url"`),
//!   as the ROV relays mjpg-streamer; the `synthetic` source also works with
//!   `--serial` (in a config file) but draws and encodes the pictures in the
//!   vehicle, which the ROV never does;
//! - **sim**: `neptunus --sim` (board emulator and simulator in-process)
//!   with the idle load, so the simulator's own cost shows apart.
//!
//! RTP video is off (`--video-rtp off`) everywhere: `auto` would start an
//! ffmpeg encoder for the first station heard.
//!
//! Each scenario settles, then over the window: CPU as % of one core
//! (utime + stime from `/proc/PID/stat`), context switches per second
//! (voluntary + nonvoluntary over `/proc/PID/task/*/status`; threads that
//! ended in the window lose theirs and are shown as `-N`), peak RSS
//! (`VmHWM`) and the number of threads; then what the vehicle holds at the
//! end of the window taken apart (its own memory, `RssAnon`, and the pages
//! mapped from files, `RssFile`), and its threads by name with their
//! switches per second.
//!
//! **Baseline, same run**: MAVProxy (the pins of
//! `tests/interop/requirements.txt`, installed into `target/interop-venv`
//! as `tests/run_all.sh` does, when missing) as a plain forwarding hop
//! between station 1 and the vehicle (`--master=udpin:` ← vehicle,
//! `--out=udpout:` → station; no modules but its core link, no stream-rate
//! requests, no heartbeat or logs of its own), measured in the same window;
//! the ratio is neptunus CPU / MAVProxy CPU. If MAVProxy cannot be
//! installed or started, the bench says why and measures without it.
//!
//! Figures are printed, never asserted. `cargo bench --bench footprint`
//! measures; under `cargo test` (no `--bench`) each scenario runs ~2 s
//! without MAVProxy, to show the bench still works.
//!
//! Environment:
//! - `FOOTPRINT_WINDOW_S`: the measuring window, s (default 30; 2 under
//!   `cargo test`);
//! - `FOOTPRINT_SCENARIOS`: a comma list of scenarios to run (default
//!   `idle,standard,heavy,sim`);
//! - `FOOTPRINT_RUNS`: runs of the whole set (default 1); with more, each
//!   run's table and then the median of each cell;
//! - `NEPTUNUS_BIN`: the binary to measure.

#![allow(
    clippy::print_stdout,
    reason = "a bench binary's output is its figures"
)]

#[path = "../tests/common/mod.rs"]
mod common;

#[path = "footprint/children.rs"]
mod children;
#[path = "footprint/load.rs"]
mod load;
#[path = "footprint/measure.rs"]
mod measure;
#[path = "footprint/scenario.rs"]
mod scenario;

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context as _;
use measure::Figures;
use scenario::Scenario;

/// One scenario's figures.
#[derive(Clone)]
struct Row {
    scenario: Scenario,
    vehicle: Figures,
    mavproxy: Option<Figures>,
    /// neptunus CPU / MAVProxy CPU in the same window.
    ratio: Option<f64>,
    /// What the load received, per second: station 1's datagrams, the
    /// other stations', HMI messages, mavlink2rest frames, video kB.
    load: [f64; 5],
    /// Failures of the load, and why MAVProxy is missing.
    notes: Vec<String>,
}

struct Knobs {
    full: bool,
    window: Duration,
    settle: Duration,
    scenarios: Vec<Scenario>,
    runs: usize,
}

fn knobs() -> anyhow::Result<Knobs> {
    let full = std::env::args().any(|a| a == "--bench");
    let var = |name: &str| std::env::var(name).ok().filter(|v| !v.trim().is_empty());
    let window_s: f64 = match var("FOOTPRINT_WINDOW_S") {
        Some(v) => v
            .trim()
            .parse()
            .ok()
            .filter(|s: &f64| s.is_finite() && *s > 0.0)
            .with_context(|| format!("FOOTPRINT_WINDOW_S={v} — use seconds > 0, e.g. 30"))?,
        None if full => 30.0,
        None => 2.0,
    };
    let scenarios = match var("FOOTPRINT_SCENARIOS") {
        Some(v) => v
            .split(',')
            .map(|s| {
                Scenario::parse(s).with_context(|| {
                    format!("FOOTPRINT_SCENARIOS: unknown scenario {s:?} — use a comma list of idle, standard, heavy, sim")
                })
            })
            .collect::<anyhow::Result<Vec<_>>>()?,
        None => Scenario::ALL.to_vec(),
    };
    let runs = match var("FOOTPRINT_RUNS") {
        Some(v) => v
            .trim()
            .parse::<usize>()
            .ok()
            .filter(|n| *n >= 1)
            .with_context(|| format!("FOOTPRINT_RUNS={v} — use a whole number >= 1"))?,
        None => 1,
    };
    Ok(Knobs {
        full,
        window: Duration::from_secs_f64(window_s),
        settle: Duration::from_secs(if full { 5 } else { 1 }),
        scenarios,
        runs,
    })
}

fn main() -> anyhow::Result<()> {
    let k = knobs()?;
    let bin = common::neptunus_bin()?;
    header(&bin, &k);
    let mut mavproxy = if k.full { baseline() } else { None };
    let mut runs: Vec<Vec<Row>> = Vec::new();
    for run in 1..=k.runs {
        let mut rows = Vec::new();
        for &s in &k.scenarios {
            rows.push(measure_scenario(s, &bin, &mut mavproxy, &k)?);
        }
        if k.runs > 1 {
            println!("\n== run {run} of {}", k.runs);
        }
        print_table(&rows, true);
        runs.push(rows);
    }
    if k.runs > 1 {
        println!("\n== median of {} runs, per cell", k.runs);
        let medians: Vec<Row> = (0..k.scenarios.len())
            .map(|i| median_row(&runs.iter().map(|r| &r[i]).collect::<Vec<_>>()))
            .collect();
        print_table(&medians, false);
    }
    Ok(())
}

fn header(bin: &Path, k: &Knobs) {
    let out = |cmd: &str, args: &[&str]| {
        std::process::Command::new(cmd)
            .args(args)
            .output()
            .ok()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
            .unwrap_or_else(|| "?".into())
    };
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|c| {
            c.lines()
                .find_map(|l| l.strip_prefix("model name"))
                .map(|v| v.trim_start_matches([' ', '\t', ':']).to_owned())
        })
        .unwrap_or_else(|| "?".into());
    let nproc = std::thread::available_parallelism().map_or(0, |n| n.get());
    println!("neptunus footprint");
    println!(
        "date:     {}",
        out("date", &["-u", "+%Y-%m-%d %H:%M:%S UTC"])
    );
    println!("machine:  {}, {cpu}, nproc {nproc}", out("uname", &["-m"]));
    let loadavg = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!("load avg: {}", loadavg.trim());
    println!("binary:   {}", bin.display());
    println!(
        "window:   {:.0} s per scenario after {} s of settling, {} run(s){}",
        k.window.as_secs_f64(),
        k.settle.as_secs(),
        k.runs,
        if k.full {
            ""
        } else {
            " — smoke run (no --bench): no MAVProxy"
        }
    );
    for s in &k.scenarios {
        println!("  {:<9} {}", s.name(), s.describe());
    }
}

/// The venv's python with MAVProxy, or None with the reason printed.
fn baseline() -> Option<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .map(|t| if t.is_relative() { root.join(t) } else { t })
        .unwrap_or_else(|| root.join("target"));
    match children::mavproxy_python(&root, &target) {
        Ok(p) => {
            let pin = std::fs::read_to_string(root.join("tests/interop/requirements.txt"))
                .ok()
                .and_then(|r| {
                    r.lines()
                        .find(|l| l.starts_with("mavproxy=="))
                        .map(str::to_owned)
                })
                .unwrap_or_else(|| "mavproxy".into());
            println!(
                "baseline: {pin} from {}, {}",
                p.display(),
                children::MAVPROXY_FLAGS.join(" ")
            );
            Some(p)
        }
        Err(e) => {
            println!("baseline: MAVProxy unavailable, rows without it — {e:#}");
            None
        }
    }
}

/// Runs and measures one scenario. A MAVProxy that fails is dropped from
/// this scenario and the rest of the run, with the reason printed.
fn measure_scenario(
    s: Scenario,
    bin: &Path,
    mavproxy: &mut Option<PathBuf>,
    k: &Knobs,
) -> anyhow::Result<Row> {
    let mut notes = Vec::new();
    let mut running = match scenario::start(s, bin, mavproxy.as_deref()) {
        Ok(r) => r,
        Err(e) if mavproxy.is_some() => {
            let why = format!("MAVProxy failed, measuring without it from here on: {e:#}");
            println!("{}: {why}", s.name());
            notes.push("MAVProxy failed: measured without it (the reason is printed above)".into());
            *mavproxy = None;
            scenario::start(s, bin, None)?
        }
        Err(e) => return Err(e),
    };
    std::thread::sleep(k.settle);
    running.check()?;
    let vpid = running.vehicle.pid();
    let mpid = running.mavproxy.as_ref().map(|m| m.pid());
    let v0 = measure::snapshot(vpid)?;
    let m0 = mpid.map(measure::snapshot).transpose()?;
    let c0 = running.tally.counts();
    std::thread::sleep(k.window);
    let v1 = measure::snapshot(vpid)?;
    let m1 = mpid.map(measure::snapshot).transpose()?;
    let c1 = running.tally.counts();
    running.check()?;
    let vehicle = measure::figures(vpid, &v0, &v1)?;
    let baseline = match (mpid, &m0, &m1) {
        (Some(pid), Some(a), Some(b)) => Some(measure::figures(pid, a, b)?),
        _ => None,
    };
    let secs = k.window.as_secs_f64();
    let mut load = [0.0; 5];
    for (i, l) in load.iter_mut().enumerate() {
        *l = c1[i].saturating_sub(c0[i]) as f64 / secs;
    }
    load[4] /= 1000.0;
    if let Ok(errors) = running.tally.errors.lock() {
        notes.extend(errors.iter().map(|e| format!("load: {e}")));
    }
    let ratio = baseline
        .as_ref()
        .filter(|m| m.cpu_pct > 0.0)
        .map(|m| vehicle.cpu_pct / m.cpu_pct);
    Ok(Row {
        scenario: s,
        vehicle,
        mavproxy: baseline,
        ratio,
        load,
        notes,
    })
}

fn print_table(rows: &[Row], details: bool) {
    println!(
        "\n{:<9} {:<9} {:>7} {:>9} {:>9} {:>11} {:>9}  target",
        "scenario", "process", "CPU %", "ctx sw/s", "RSS MB", "threads", "CPU vs MP"
    );
    let line = |name: &str, proc_: &str, f: &Figures, ratio: &str, target: &str| {
        let threads = match (f.started, f.exited) {
            (0, 0) => f.threads.to_string(),
            (s, e) => format!("{} +{s}-{e}", f.threads),
        };
        let text = format!(
            "{name:<9} {proc_:<9} {:>7.2} {:>9.0} {:>9.1} {threads:>11} {ratio:>9}  {target}",
            f.cpu_pct, f.cs_per_s, f.peak_rss_mb
        );
        println!("{}", text.trim_end());
    };
    println!(
        "(CPU: % of one core; ctx sw/s: all threads; RSS: peak, VmHWM; threads: at the end, +started -ended in the window; CPU vs MP: neptunus / MAVProxy in the same window, MAVProxy forwarding station 1's traffic)"
    );
    for r in rows {
        let ratio = r.ratio.map_or("-".into(), |x| format!("{x:.2}x"));
        line(
            r.scenario.name(),
            "neptunus",
            &r.vehicle,
            &ratio,
            r.scenario.target(),
        );
        match &r.mavproxy {
            Some(m) => line("", "MAVProxy", m, "", ""),
            None => println!("{:<9} {:<9} {:>7}", "", "MAVProxy", "-"),
        }
    }
    if !details {
        return;
    }
    println!("\nload received per second over the window:");
    for r in rows {
        let [s1, others, hmi, m2r, video] = r.load;
        // With the baseline running, station 1 hears the vehicle through it.
        let via = if r.mavproxy.is_some() {
            " (through MAVProxy)"
        } else {
            ""
        };
        println!(
            "  {:<9} station 1{via} {s1:.0} datagrams, other stations {others:.0}, HMI {hmi:.0} messages, mavlink2rest {m2r:.0} frames, video {video:.0} kB",
            r.scenario.name()
        );
        for n in &r.notes {
            println!("  {:<9} NOTE {n}", "");
        }
    }
    println!(
        "\nneptunus resident at the end of the window: its own memory (heap, stacks, relocated tables) + pages mapped from files (code and constants, clean; how many depends on the kernel's page cache)"
    );
    for r in rows {
        let f = &r.vehicle;
        println!(
            "  {:<9} {:.1} MB own + {:.1} MB from files",
            r.scenario.name(),
            f.anon_mb,
            f.file_mb
        );
    }
    println!("\nneptunus threads by name: count × name, context switches/s over the window");
    for r in rows {
        let threads: Vec<String> = r
            .vehicle
            .per_thread
            .iter()
            .map(|(name, n, cs)| format!("{n}×{name} {cs:.0}"))
            .collect();
        println!("  {:<9} {}", r.scenario.name(), threads.join(", "));
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

fn median_figures(all: &[&Figures]) -> Figures {
    let m = |f: fn(&Figures) -> f64| median(all.iter().map(|x| f(x)).collect());
    Figures {
        cpu_pct: m(|f| f.cpu_pct),
        cs_per_s: m(|f| f.cs_per_s),
        peak_rss_mb: m(|f| f.peak_rss_mb),
        anon_mb: m(|f| f.anon_mb),
        file_mb: m(|f| f.file_mb),
        threads: m(|f| f.threads as f64).round() as usize,
        exited: 0,
        started: 0,
        per_thread: Vec::new(),
    }
}

/// The median of each cell (the ratio: the median of the same-run ratios).
fn median_row(rows: &[&Row]) -> Row {
    let mavproxy: Vec<&Figures> = rows.iter().filter_map(|r| r.mavproxy.as_ref()).collect();
    let ratios: Vec<f64> = rows.iter().filter_map(|r| r.ratio).collect();
    Row {
        ratio: (!ratios.is_empty()).then(|| median(ratios)),
        scenario: rows[0].scenario,
        vehicle: median_figures(&rows.iter().map(|r| &r.vehicle).collect::<Vec<_>>()),
        mavproxy: (!mavproxy.is_empty()).then(|| median_figures(&mavproxy)),
        load: [0.0; 5],
        notes: Vec::new(),
    }
}
