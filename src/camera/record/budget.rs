//! The storage budget of logs and recordings: a free-space floor and a
//! total cap (`[storage]`), so that recordings never fill the ROV's SD card.
//!
//! [`judge`] is sans-IO (numbers in, a [`StorageReport`] out); [`measure`]
//! reads the file system (statvfs of the data directory, the sizes of the
//! logs and recordings). Only recording is stopped or refused by the
//! budget: the logs keep their own rotation (tlogs by `tlog_total_mb`,
//! the event log and `neptunus.log` by size), and what the vehicle needs
//! to run — parameters, keys, the password — is never refused a write
//! (the floor is the room left for them).

use std::io;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::vehicle::machine::StorageReport;

const MIB: u64 = 1024 * 1024;

/// `[storage]` in the configuration file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StorageConfig {
    /// A recording stops (and none starts) while the data directory's file
    /// system has less free space than this (MiB).
    pub min_free_mb: u64,
    /// Logs and recordings together stay under this (MiB): a recording
    /// stops when they reach it.
    pub total_mb: u64,
}

impl Default for StorageConfig {
    fn default() -> Self {
        Self {
            min_free_mb: 256,
            total_mb: 8192,
        }
    }
}

impl StorageConfig {
    /// The checks serde cannot make.
    pub fn validate(&self) -> Result<(), String> {
        if self.total_mb == 0 {
            return Err(
                "storage.total_mb = 0 leaves no room for logs or recordings — use at least 1 (default 8192)"
                    .into(),
            );
        }
        if self.min_free_mb > 1 << 30 || self.total_mb > 1 << 30 {
            return Err(
                "storage.min_free_mb and storage.total_mb are in MiB: use a value below 2^30"
                    .into(),
            );
        }
        Ok(())
    }
}

/// What [`measure`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Measured {
    /// The file system's size.
    pub fs_total_bytes: u64,
    /// What an unprivileged writer may still take (statvfs `f_bavail`).
    pub fs_free_bytes: u64,
    /// Logs and recordings.
    pub used_bytes: u64,
}

/// The budget's verdict on what was measured.
pub fn judge(cfg: &StorageConfig, m: &Measured) -> StorageReport {
    let floor = cfg.min_free_mb * MIB;
    let cap = cfg.total_mb * MIB;
    let free_above_floor = m.fs_free_bytes.saturating_sub(floor);
    let under_cap = cap.saturating_sub(m.used_bytes);
    let blocked = if m.fs_free_bytes <= floor {
        Some(format!(
            "free space {} MiB is at the floor of {} MiB ([storage] min_free_mb)",
            m.fs_free_bytes / MIB,
            cfg.min_free_mb
        ))
    } else if m.used_bytes >= cap {
        Some(format!(
            "logs and recordings take {} MiB, the cap is {} MiB ([storage] total_mb)",
            m.used_bytes / MIB,
            cfg.total_mb
        ))
    } else {
        None
    };
    StorageReport {
        total_bytes: cap.min(m.used_bytes + free_above_floor),
        used_bytes: m.used_bytes,
        available_bytes: free_above_floor.min(under_cap),
        blocked,
    }
}

/// Whether two reports differ enough to tell the vehicle again: the
/// verdict changed, or a figure moved by a MiB.
pub fn changed(a: &StorageReport, b: &StorageReport) -> bool {
    let far = |x: u64, y: u64| x.abs_diff(y) >= MIB;
    a.blocked != b.blocked
        || far(a.total_bytes, b.total_bytes)
        || far(a.used_bytes, b.used_bytes)
        || far(a.available_bytes, b.available_bytes)
}

/// The data directory's file system and what logs and recordings take in
/// it: `recordings/`, `tlogs/`, `events/` and `neptunus.log*`.
pub fn measure(data_dir: &Path) -> io::Result<Measured> {
    let st = nix::sys::statvfs::statvfs(data_dir).map_err(io::Error::from)?;
    let frsize = st.fragment_size() as u64;
    let mut used = 0;
    for sub in [super::RECORDINGS_DIR, "tlogs", "events"] {
        used += dir_bytes(&data_dir.join(sub));
    }
    if let Ok(entries) = std::fs::read_dir(data_dir) {
        for e in entries.flatten() {
            if e.file_name().to_string_lossy().starts_with("neptunus.log") {
                used += e
                    .metadata()
                    .map_or(0, |m| if m.is_file() { m.len() } else { 0 });
            }
        }
    }
    Ok(Measured {
        fs_total_bytes: (st.blocks() as u64).saturating_mul(frsize),
        fs_free_bytes: (st.blocks_available() as u64).saturating_mul(frsize),
        used_bytes: used,
    })
}

/// The regular files directly in `dir` (0 when it does not exist).
fn dir_bytes(dir: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .filter_map(|e| e.metadata().ok())
        .filter(|m| m.is_file())
        .map(|m| m.len())
        .sum()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const CFG: StorageConfig = StorageConfig {
        min_free_mb: 100,
        total_mb: 1000,
    };

    fn m(free_mb: u64, used_mb: u64) -> Measured {
        Measured {
            fs_total_bytes: 16_000 * MIB,
            fs_free_bytes: free_mb * MIB,
            used_bytes: used_mb * MIB,
        }
    }

    #[test]
    fn room_is_the_smaller_of_floor_and_cap() {
        let r = judge(&CFG, &m(5000, 200));
        assert_eq!(r.blocked, None);
        assert_eq!(r.available_bytes, 800 * MIB, "the cap is nearer");
        assert_eq!(r.total_bytes, 1000 * MIB);
        let r = judge(&CFG, &m(300, 200));
        assert_eq!(r.available_bytes, 200 * MIB, "the floor is nearer");
        assert_eq!(r.total_bytes, 400 * MIB, "what the disk allows");
    }

    #[test]
    fn the_floor_and_the_cap_block_recording_and_say_which() {
        let r = judge(&CFG, &m(100, 10));
        assert_eq!(r.available_bytes, 0);
        assert!(r.blocked.unwrap().contains("min_free_mb"));
        let r = judge(&CFG, &m(5000, 1000));
        assert!(r.blocked.unwrap().contains("total_mb"));
    }

    #[test]
    fn small_moves_are_not_news() {
        let a = judge(&CFG, &m(5000, 200));
        let mut b = a.clone();
        b.used_bytes += MIB / 2;
        assert!(!changed(&a, &b));
        b.used_bytes += MIB;
        assert!(changed(&a, &b));
        assert!(changed(&a, &judge(&CFG, &m(50, 200))));
    }

    #[test]
    fn measures_only_logs_and_recordings() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for (path, n) in [
            ("recordings/rec-a-001.ts", 1000),
            ("tlogs/a.tlog", 200),
            ("events/events.jsonl", 30),
            ("neptunus.log", 4),
            ("neptunus.log.1", 5),
            ("params.toml", 70_000),
            ("openrov-firmware/cache.hex", 90_000),
        ] {
            let p = d.join(path);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, vec![0u8; n]).unwrap();
        }
        let got = measure(d).unwrap();
        assert_eq!(got.used_bytes, 1239);
        assert!(got.fs_total_bytes >= got.fs_free_bytes && got.fs_free_bytes > 0);
    }
}
