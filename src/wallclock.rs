//! The vehicle's wall clock: what the telemetry log and the event log name
//! and stamp their records with, and what the core gets as `Now::unix_us`.
//!
//! A BeagleBone has no battery-backed clock and at the pool usually no
//! network: it boots in 2000 (or at the last shutdown, with fake-hwclock).
//! Until the ground station in control sets it (the core decides: SYSTEM_TIME,
//! `vehicle/machine/wallclock.rs`) this is the system clock. Once set, it is
//! the station's time carried forward on the monotonic clock, so a later
//! jump of the system clock (NTP arriving) cannot make it jump.
//!
//! Owns [`WallClock`] (shared, lock-free), the build date the core compares
//! against and reading whether the system clock is synchronised. It never
//! decides whether to take a station's time, and never sets the system
//! clock (that would need CAP_SYS_TIME, which the service does not have).

use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

/// When this binary was built (`SOURCE_DATE_EPOCH` when set, for
/// reproducible builds), in seconds since the Unix epoch: a clock before it
/// is certainly wrong.
pub const BUILD_UNIX_S: u64 = parse_u64(env!("NEPTUNUS_BUILD_UNIX_S"));

const fn parse_u64(s: &str) -> u64 {
    let bytes = s.as_bytes();
    let mut value = 0u64;
    let mut i = 0;
    while i < bytes.len() {
        let digit = bytes[i].wrapping_sub(b'0');
        if digit > 9 {
            return 0;
        }
        value = value.saturating_mul(10).saturating_add(digit as u64);
        i += 1;
    }
    value
}

/// Whether the system clock is known to follow a time source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ClockSync {
    /// systemd-timesyncd says it synchronised the clock.
    Synced,
    /// systemd-timesyncd runs but has not synchronised (no network).
    Unsynced,
    /// No systemd-timesyncd (chrony, ntpd or nothing): not known.
    Unknown,
}

/// What systemd-timesyncd says (`/run/systemd/timesync/synchronized`
/// exists once it synchronised; the folder exists while it runs).
pub fn system_sync() -> ClockSync {
    let dir = std::path::Path::new("/run/systemd/timesync");
    if dir.join("synchronized").exists() {
        ClockSync::Synced
    } else if dir.is_dir() {
        ClockSync::Unsynced
    } else {
        ClockSync::Unknown
    }
}

/// The system clock, µs since the Unix epoch (0 before it).
pub fn system_unix_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

/// No offset set: the system clock is used.
const UNSET: i64 = i64::MIN;

/// The wall clock the vehicle's logs use (see the module docs). Shared by
/// `Arc`; every method takes `&self`.
#[derive(Debug)]
pub struct WallClock {
    base: Instant,
    /// Unix µs at `base` once set, else [`UNSET`].
    offset_us: AtomicI64,
    /// Counts the times it was set: the telemetry log starts a file named
    /// with the new time when it changes.
    generation: AtomicU64,
}

impl WallClock {
    /// Following the system clock until [`set_unix_us`](Self::set_unix_us).
    pub fn system() -> std::sync::Arc<Self> {
        std::sync::Arc::new(Self {
            base: Instant::now(),
            offset_us: AtomicI64::new(UNSET),
            generation: AtomicU64::new(0),
        })
    }

    /// Now, µs since the Unix epoch.
    pub fn unix_us(&self) -> u64 {
        match self.offset_us.load(Ordering::Acquire) {
            UNSET => system_unix_us(),
            offset => {
                let elapsed = i64::try_from(self.base.elapsed().as_micros()).unwrap_or(i64::MAX);
                u64::try_from(offset.saturating_add(elapsed)).unwrap_or(0)
            }
        }
    }

    /// From now on the time is `unix_us`, carried forward on the monotonic clock.
    pub fn set_unix_us(&self, unix_us: u64) {
        let elapsed = i64::try_from(self.base.elapsed().as_micros()).unwrap_or(i64::MAX);
        let at = i64::try_from(unix_us).unwrap_or(i64::MAX);
        self.offset_us
            .store(at.saturating_sub(elapsed).max(UNSET + 1), Ordering::Release);
        self.generation.fetch_add(1, Ordering::AcqRel);
    }

    /// How many times it was set.
    pub fn generation(&self) -> u64 {
        self.generation.load(Ordering::Acquire)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_the_system_clock_until_set() {
        let clock = WallClock::system();
        let sys = system_unix_us();
        assert!(clock.unix_us().abs_diff(sys) < 1_000_000);
        assert_eq!(clock.generation(), 0);
        let set = 1_900_000_000_000_000;
        clock.set_unix_us(set);
        let now = clock.unix_us();
        assert!((set..set + 1_000_000).contains(&now), "{now}");
        assert_eq!(clock.generation(), 1);
    }

    #[test]
    fn the_build_date_is_known() {
        assert_eq!(parse_u64("1767225600"), 1_767_225_600);
        assert_eq!(parse_u64("12x"), 0);
    }
}
