//! systemd's notify protocol (`sd_notify`, through the `sd-notify` crate):
//! `READY=1` once the vehicle task runs, `WATCHDOG=1` from the vehicle
//! task's own loop, `STOPPING=1` at shutdown once the thrusters are neutral.
//!
//! Owns the watchdog's schedule and nothing else. `WATCHDOG=1` is sent only
//! from [`Notify::alive`], which the vehicle task's loop calls after each
//! input it handled: a loop that hangs (a stuck core, a blocked worker)
//! stops feeding systemd, which then restarts the service — while the
//! board's own dead-man switch, no longer pinged, has already stopped the
//! thrusters. It must never be called from another task or a timer of its
//! own: that would keep a hung vehicle "alive".
//!
//! Without `NOTIFY_SOCKET` (not started by systemd) every call does nothing.

use std::time::{Duration, Instant};

use sd_notify::NotifyState;

/// `WATCHDOG=1` goes out this many times per `WatchdogSec=` (systemd
/// advises at least twice; four leaves room for a slow wake-up).
const PER_WATCHDOG_PERIOD: u32 = 4;

pub(super) struct Notify {
    /// How often `WATCHDOG=1` is due; None when systemd asked for none.
    period: Option<Duration>,
    next: Option<Instant>,
    /// A failed send is logged once, not at every period.
    failed: bool,
}

impl Notify {
    /// From the environment systemd sets (`NOTIFY_SOCKET`, `WATCHDOG_USEC`,
    /// `WATCHDOG_PID`).
    pub(super) fn from_env() -> Self {
        let watchdog = sd_notify::watchdog_enabled();
        if let Some(wd) = watchdog {
            tracing::info!(
                watchdog_s = wd.as_secs_f64(),
                "systemd watchdog on: fed from the vehicle task's loop"
            );
        }
        Self {
            period: watchdog.map(|wd| wd / PER_WATCHDOG_PERIOD),
            next: None,
            failed: false,
        }
    }

    /// `READY=1`: the vehicle task is about to run its loop.
    pub(super) fn ready(&mut self) {
        self.send(&[
            NotifyState::Ready,
            NotifyState::Status("vehicle task running"),
        ]);
        self.next = self.period.map(|p| Instant::now() + p);
    }

    /// The vehicle task's loop went round: `WATCHDOG=1` when it is due.
    pub(super) fn alive(&mut self) {
        let (Some(period), Some(next)) = (self.period, self.next) else {
            return;
        };
        let now = Instant::now();
        if now >= next {
            self.next = Some(now + period);
            self.send(&[NotifyState::Watchdog]);
        }
    }

    /// `STOPPING=1`: shutting down (the thrusters are neutral already).
    pub(super) fn stopping(&mut self) {
        self.next = None;
        self.send(&[
            NotifyState::Stopping,
            NotifyState::Status("stopping: thrusters neutral"),
        ]);
    }

    fn send(&mut self, state: &[NotifyState]) {
        if let Err(e) = sd_notify::notify(state)
            && !std::mem::replace(&mut self.failed, true)
        {
            tracing::warn!(error = %e, "cannot notify systemd (NOTIFY_SOCKET) — logged once");
        }
    }
}

/// A test hook, in debug builds only: `NEPTUNUS_TEST_STALL_AFTER_S=N` makes
/// the vehicle task's loop hang N seconds after it started — a stuck core —
/// while every other task (sockets, the serial link, the HMI) runs on.
/// `tests/notify.rs` shows that the watchdog then starves and the board's
/// dead-man switch stops the thrusters. Release builds read no such variable.
pub(super) struct StallHook {
    at: Option<Instant>,
}

impl StallHook {
    pub(super) fn from_env() -> Self {
        #[cfg(debug_assertions)]
        let at = std::env::var("NEPTUNUS_TEST_STALL_AFTER_S")
            .ok()
            .and_then(|s| s.parse::<f64>().ok())
            .filter(|s| s.is_finite() && (0.0..=3600.0).contains(s))
            .map(|s| Instant::now() + Duration::from_secs_f64(s));
        #[cfg(not(debug_assertions))]
        let at = None;
        Self { at }
    }

    /// Hangs the calling loop for good once the time has come.
    pub(super) fn check(&self) {
        if self.at.is_some_and(|t| Instant::now() >= t) {
            tracing::error!("NEPTUNUS_TEST_STALL_AFTER_S: the vehicle task hangs now (test hook)");
            loop {
                std::thread::park();
            }
        }
    }
}
