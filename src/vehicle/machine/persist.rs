//! When parameters are saved, and what the stations are told when saving
//! fails.
//!
//! The core only decides: a change marks the store dirty; a save is asked for
//! ([`Output::SaveParams`]) 0.5 s after the last change (at most 2 s after
//! the first), never while one is in flight; the app writes off the vehicle
//! task and answers with [`Input::ParamsSaved`](super::Input::ParamsSaved).
//! A failure is announced to every station (it is the vehicle's state: the
//! value acknowledged will not survive a restart), shown in SYS_STATUS
//! (MAV_SYS_STATUS_LOGGING unhealthy) and retried with backoff until it works.

use std::collections::BTreeSet;
use std::time::Duration;

use super::texts::Topic;
use super::{Now, Output, Vehicle};
use crate::dialect::neptunus::*;

/// Quiet time after the last change before saving: a slider dragged in a
/// ground station or the HMI gives one write, not fifty.
pub const SAVE_DEBOUNCE: Duration = Duration::from_millis(500);
/// A stream of changes still saves this long after its first one.
pub const SAVE_MAX_DELAY: Duration = Duration::from_secs(2);
/// Retry delays after a failed save: 1 s doubling up to 30 s.
const RETRY_FIRST: Duration = Duration::from_secs(1);
const RETRY_MAX: Duration = Duration::from_secs(30);
/// Names listed in a failure text before "and N more".
const NAMES_SHOWN: usize = 3;

#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Persist {
    /// Changes not yet handed to a save: (first, last) change time.
    dirty: Option<(Duration, Duration)>,
    in_flight: bool,
    /// Parameters changed since the last successful save.
    unsaved: BTreeSet<&'static str>,
    /// Consecutive failed saves, and the last reason.
    failures: u32,
    last_error: Option<String>,
    retry_at: Option<Duration>,
    /// Saves asked for, for tests and statistics.
    pub requested: u64,
    /// When each parameter's change was last logged.
    logged: std::collections::HashMap<&'static str, Duration>,
    /// Why the data directory is unusable, if it is (from the app at start).
    pub storage_problem: Option<String>,
}

impl Persist {
    /// Whether a change of `name` goes to the event log now (one per second
    /// per parameter; there are only so many parameters).
    pub fn log_change_due(&mut self, name: &'static str, now: Duration) -> bool {
        match self.logged.get(name) {
            Some(t) if now.saturating_sub(*t) < Duration::from_secs(1) => false,
            _ => {
                self.logged.insert(name, now);
                true
            }
        }
    }

    fn backoff(failures: u32) -> Duration {
        let shift = failures.saturating_sub(1).min(5);
        (RETRY_FIRST * (1 << shift)).min(RETRY_MAX)
    }
}

impl Vehicle {
    /// A parameter value really changed: it must reach the disk.
    pub(super) fn param_changed(&mut self, name: &'static str, now: Now) {
        let p = &mut self.persist;
        p.unsaved.insert(name);
        p.dirty = Some(match p.dirty {
            Some((first, _)) => (first, now.mono),
            None => (now.mono, now.mono),
        });
    }

    /// From the tick: asks for a save when one is due.
    pub(super) fn persist_tick(&mut self, now: Now, out: &mut Vec<Output>) {
        let p = &mut self.persist;
        let Some((first, last)) = p.dirty else {
            return;
        };
        if p.in_flight || p.retry_at.is_some_and(|t| now.mono < t) {
            return;
        }
        let due = (last + SAVE_DEBOUNCE).min(first + SAVE_MAX_DELAY);
        if now.mono < due {
            return;
        }
        p.dirty = None;
        p.in_flight = true;
        p.requested += 1;
        out.push(Output::SaveParams);
    }

    /// The app's answer to [`Output::SaveParams`].
    pub(super) fn on_params_saved(
        &mut self,
        result: Result<(), String>,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let p = &mut self.persist;
        p.in_flight = false;
        match result {
            Ok(()) => {
                if p.dirty.is_none() {
                    p.unsaved.clear();
                }
                p.retry_at = None;
                let failures = std::mem::take(&mut p.failures);
                p.last_error = None;
                // A save went through: the data directory works (again).
                if let Some(was) = self.persist.storage_problem.take() {
                    self.log(
                        "storage_ok",
                        None,
                        format!("writable again (was: {was})"),
                        out,
                    );
                }
                if failures > 0 {
                    self.statustext(
                        Topic::General,
                        MavSeverity::MAV_SEVERITY_INFO,
                        &format!("Parameters saved (after {failures} failed attempts)"),
                        out,
                    );
                    self.log(
                        "params_saved",
                        None,
                        format!("after {failures} failed attempts"),
                        out,
                    );
                }
            }
            Err(why) => {
                p.failures = p.failures.saturating_add(1);
                let delay = Persist::backoff(p.failures);
                p.retry_at = Some(now.mono + delay);
                // Still to be written: keep it dirty, due at the retry.
                p.dirty = Some(match p.dirty {
                    Some(d) => d,
                    None => (now.mono, now.mono),
                });
                let mut names: Vec<&str> = p.unsaved.iter().copied().take(NAMES_SHOWN).collect();
                let more = p.unsaved.len().saturating_sub(NAMES_SHOWN);
                if names.is_empty() {
                    names.push("parameters");
                }
                let mut list = names.join(", ");
                if more > 0 {
                    list.push_str(&format!(" and {more} more"));
                }
                let attempt = p.failures;
                let new_reason = p.last_error.as_deref() != Some(why.as_str());
                p.last_error = Some(why.clone());
                let text = format!(
                    "NOT SAVED: {list} (in use until restart): {why}; retry in {} s",
                    delay.as_secs()
                );
                self.statustext(
                    Topic::General,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &text,
                    out,
                );
                if new_reason || attempt.is_power_of_two() {
                    self.log(
                        "params_not_saved",
                        None,
                        format!("attempt {attempt}: {list}: {why}"),
                        out,
                    );
                }
            }
        }
    }

    /// Parameter changes that are not on disk yet (pending, in flight or failed).
    pub fn params_unsaved(&self) -> bool {
        !self.persist.unsaved.is_empty()
    }

    /// The last save failure, while saving keeps failing.
    pub fn params_save_error(&self) -> Option<&str> {
        self.persist.last_error.as_deref()
    }

    /// How many saves the core has asked for.
    pub fn params_saves_requested(&self) -> u64 {
        self.persist.requested
    }

    /// Storage is healthy: parameters save, and nothing at start said the
    /// data directory is unusable.
    pub(super) fn storage_healthy(&self) -> bool {
        self.persist.last_error.is_none() && self.persist.storage_problem.is_none()
    }

    /// At start: the data directory is unusable (read-only, missing, full),
    /// so parameters live in memory and logs may be lost. Shown in
    /// SYS_STATUS until a parameter save succeeds.
    pub fn set_storage_problem(&mut self, problem: Option<String>) {
        self.persist.storage_problem = problem;
    }

    pub fn storage_problem(&self) -> Option<&str> {
        self.persist.storage_problem.as_deref()
    }
}
