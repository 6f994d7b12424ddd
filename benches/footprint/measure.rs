//! What a process costs over a window, read from `/proc`: CPU (utime +
//! stime of the whole process, exited threads included), context switches
//! (summed over `/proc/PID/task/*/status`, per thread name too), peak RSS
//! (`VmHWM`), what is resident at the end taken apart (`RssAnon`,
//! `RssFile`) and its threads. Reads only; never signals a process.

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

use anyhow::{Context as _, bail};

/// One reading of a process.
pub struct Snapshot {
    at: Instant,
    cpu_ticks: u64,
    /// Thread id → (name, voluntary + nonvoluntary context switches).
    tasks: HashMap<u32, (String, u64)>,
}

/// A process over a window.
#[derive(Debug, Clone, Default)]
pub struct Figures {
    /// % of one core.
    pub cpu_pct: f64,
    /// Context switches per second, all threads.
    pub cs_per_s: f64,
    /// Peak resident set (VmHWM), MB.
    pub peak_rss_mb: f64,
    /// Resident at the end of the window, MB: the process's own memory
    /// (`RssAnon`: heap, stacks, relocated tables).
    pub anon_mb: f64,
    /// Resident at the end of the window, MB: pages mapped from files
    /// (`RssFile`: code and constants of the program and its libraries —
    /// clean, given back under memory pressure, and as many as the kernel's
    /// page cache maps around each page touched).
    pub file_mb: f64,
    /// Threads at the end of the window.
    pub threads: usize,
    /// Threads that ended within the window: their switches since the first
    /// reading are lost, so `cs_per_s` undercounts when this is not 0.
    pub exited: usize,
    /// Threads that started within the window (all their switches counted).
    pub started: usize,
    /// Thread name → (how many threads, context switches per second),
    /// busiest first.
    pub per_thread: Vec<(String, usize, f64)>,
}

pub fn snapshot(pid: u32) -> anyhow::Result<Snapshot> {
    let at = Instant::now();
    let cpu_ticks = crate::common::proc_cpu_ticks(pid)?;
    let mut tasks = HashMap::new();
    let dir = format!("/proc/{pid}/task");
    for entry in std::fs::read_dir(&dir).with_context(|| format!("cannot list {dir}"))? {
        let Ok(entry) = entry else { continue };
        let Some(tid) = entry.file_name().to_str().and_then(|s| s.parse().ok()) else {
            continue;
        };
        // A thread may end between the listing and the read: skip it.
        let Ok(status) = std::fs::read_to_string(entry.path().join("status")) else {
            continue;
        };
        let name = field(&status, "Name:").unwrap_or("?").to_owned();
        let cs = ["voluntary_ctxt_switches:", "nonvoluntary_ctxt_switches:"]
            .iter()
            .filter_map(|k| field(&status, k)?.parse::<u64>().ok())
            .sum();
        tasks.insert(tid, (name, cs));
    }
    if tasks.is_empty() {
        bail!("process {pid} has no threads (it has exited)");
    }
    Ok(Snapshot {
        at,
        cpu_ticks,
        tasks,
    })
}

/// The window between two snapshots of `pid`; peak RSS is read now.
pub fn figures(pid: u32, a: &Snapshot, b: &Snapshot) -> anyhow::Result<Figures> {
    let secs = b.at.duration_since(a.at).as_secs_f64().max(1e-3);
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let mb = |key: &str| {
        field(&status, key)
            .and_then(|v| v.trim_end_matches("kB").trim().parse::<f64>().ok())
            .map(|kb| kb / 1024.0)
    };
    let peak_rss_mb = mb("VmHWM:").context("no VmHWM in /proc/PID/status")?;
    let mut by_name: BTreeMap<&str, (usize, u64)> = BTreeMap::new();
    let mut total = 0;
    for (tid, (name, cs)) in &b.tasks {
        let before = a.tasks.get(tid).map_or(0, |(_, c)| *c);
        let d = cs.saturating_sub(before);
        total += d;
        let e = by_name.entry(name).or_default();
        e.0 += 1;
        e.1 += d;
    }
    let mut per_thread: Vec<_> = by_name
        .into_iter()
        .map(|(name, (n, cs))| (name.to_owned(), n, cs as f64 / secs))
        .collect();
    per_thread.sort_by(|x, y| y.2.total_cmp(&x.2));
    Ok(Figures {
        cpu_pct: b.cpu_ticks.saturating_sub(a.cpu_ticks) as f64
            / crate::common::clock_ticks_per_s()
            / secs
            * 100.0,
        cs_per_s: total as f64 / secs,
        peak_rss_mb,
        anon_mb: mb("RssAnon:").unwrap_or(f64::NAN),
        file_mb: mb("RssFile:").unwrap_or(f64::NAN),
        threads: b.tasks.len(),
        exited: a.tasks.keys().filter(|t| !b.tasks.contains_key(t)).count(),
        started: b.tasks.keys().filter(|t| !a.tasks.contains_key(t)).count(),
        per_thread,
    })
}

/// The value after `key` on its line of a `/proc/.../status` text.
fn field<'a>(status: &'a str, key: &str) -> Option<&'a str> {
    status
        .lines()
        .find_map(|l| l.strip_prefix(key))
        .map(str::trim)
}
