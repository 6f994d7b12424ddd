//! Failsafes, table-driven: each row says when it is raised, when it clears,
//! which parameter picks its action and how it reads to the operator.
//!
//! Raising acts once (warn, disarm, or an autopilot mode that needs thrust);
//! any active failsafe shows as MAV_STATE_CRITICAL and in SYS_STATUS health,
//! and each raise and clear is a STATUSTEXT and an event-log line.

use std::time::Duration;

use super::texts::{FailsafeKind, Topic};
use super::{Mode, Now, Output, Vehicle};
use crate::dialect::neptunus::{MavResult, MavSeverity};
use crate::firmware::link::LinkState;
use crate::vehicle::params::{FailsafeAction, ParamStore};

/// A battery voltage must stay beyond its threshold this long to raise or
/// clear a battery failsafe (ArduPilot's BATT_LOW_TIMER default).
pub(super) const BATTERY_DEBOUNCE: Duration = Duration::from_secs(10);

/// One failsafe.
pub(super) struct Rule {
    pub kind: FailsafeKind,
    raise: fn(&Vehicle, Now) -> bool,
    clear: fn(&Vehicle, Now) -> bool,
    action: fn(&ParamStore) -> FailsafeAction,
    /// What the operator reads ("GCS 255 heartbeat lost").
    text: fn(&Vehicle) -> String,
}

/// Index of each rule in [`RULES`].
pub(super) const GCS: usize = 0;
pub(super) const PILOT: usize = 1;

/// How many failsafes there are.
const RULE_COUNT: usize = 5;

pub(super) const RULES: [Rule; RULE_COUNT] = [
    Rule {
        kind: FailsafeKind::Gcs,
        // Armed, and no station in control showed life for FS_GCS_TIMEOUT —
        // or none is in control: the owner left (its HMI session closed, it
        // released control), and nobody took over.
        raise: |v, now| v.armed && !v.owner_alive(now, v.gcs_timeout()),
        clear: |v, now| v.owner_alive(now, v.gcs_timeout()),
        action: ParamStore::fs_gcs_enable,
        text: |v| match (v.auth.owner, v.auth.last_owner, &v.auth.owner_left) {
            (Some(o), ..) => format!("GCS {} heartbeat lost", o.sysid),
            (None, Some(o), Some(why)) => format!("GCS {o} left ({why})"),
            (None, Some(o), None) => format!("GCS {o} heartbeat lost"),
            (None, None, _) => "no GCS in control".into(),
        },
    },
    Rule {
        kind: FailsafeKind::PilotInput,
        raise: |v, now| v.armed && v.pilot_input_stale(now),
        clear: |v, now| !v.pilot_input_stale(now),
        action: ParamStore::fs_pilot_input,
        text: |_| "lost manual control".into(),
    },
    Rule {
        kind: FailsafeKind::BoardLink,
        raise: |v, _| v.board.link_seen_up && v.board.link != LinkState::Up,
        clear: |v, _| v.board.link == LinkState::Up,
        action: |_| FailsafeAction::Disarm,
        text: |v| {
            format!(
                "board link lost ({})",
                v.board.link_reason.as_deref().unwrap_or("no telemetry")
            )
        },
    },
    Rule {
        kind: FailsafeKind::BatteryLow,
        raise: |v, now| v.failsafes.battery[0].held_below(now),
        clear: |v, now| v.failsafes.battery[0].held_above(now),
        action: ParamStore::batt_fs_low_act,
        text: |v| format!("battery low {:.1} V", v.board.vout_v.value),
    },
    Rule {
        kind: FailsafeKind::BatteryCritical,
        raise: |v, now| v.failsafes.battery[1].held_below(now),
        clear: |v, now| v.failsafes.battery[1].held_above(now),
        action: ParamStore::batt_fs_crt_act,
        text: |v| format!("battery critical {:.1} V", v.board.vout_v.value),
    },
];

/// Which failsafes are active, and the mode one of them put the vehicle in.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Failsafes {
    pub active: [bool; RULE_COUNT],
    pub mode: Option<Mode>,
    /// Low and critical battery thresholds.
    pub battery: [BatteryWatch; 2],
}

/// How long a battery voltage has been below / above one threshold.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct BatteryWatch {
    below_since: Option<Duration>,
    above_since: Option<Duration>,
}

impl BatteryWatch {
    /// A new voltage sample against `threshold_v` (0 = off).
    pub fn sample(&mut self, volts: f64, threshold_v: f64, now: Duration) {
        if threshold_v <= 0.0 {
            *self = Self::default();
        } else if volts < threshold_v {
            self.above_since = None;
            self.below_since.get_or_insert(now);
        } else {
            self.below_since = None;
            self.above_since.get_or_insert(now);
        }
    }
    fn held_below(&self, now: Now) -> bool {
        self.below_since
            .is_some_and(|t| now.mono.saturating_sub(t) >= BATTERY_DEBOUNCE)
    }
    fn held_above(&self, now: Now) -> bool {
        self.above_since
            .is_some_and(|t| now.mono.saturating_sub(t) >= BATTERY_DEBOUNCE)
            || (self.below_since.is_none() && self.above_since.is_none())
    }
}

impl Vehicle {
    /// Whether any failsafe is active.
    pub fn failsafe_active(&self) -> bool {
        self.failsafes.active.iter().any(|a| *a)
    }

    /// Names of the active failsafes.
    pub fn active_failsafes(&self) -> Vec<&'static str> {
        RULES
            .iter()
            .zip(self.failsafes.active)
            .filter(|(_, a)| *a)
            .map(|(r, _)| r.kind.name())
            .collect()
    }

    /// No stick input from the owner (nor a motor test) for FS_PILOT_TIMEOUT
    /// since the input, the test or arming, in a mode the pilot drives.
    fn pilot_input_stale(&self, now: Now) -> bool {
        let pilot_mode = matches!(self.mode, Mode::Manual | Mode::ManualThrusters);
        let timeout = Duration::from_secs_f32(self.params.fs_pilot_timeout_s().clamp(0.1, 3.0));
        let last = [
            self.pilot.last_input,
            self.armed_at,
            self.pilot.last_motor_test,
        ]
        .into_iter()
        .flatten()
        .max();
        pilot_mode
            && self.pilot.motor_test.is_none()
            && last.is_none_or(|t| now.mono.saturating_sub(t) > timeout)
    }

    /// A failsafe action is holding the vehicle in an autopilot mode: the
    /// board's dead-man must be fed on Neptunus' own authority.
    pub(super) fn failsafe_needs_thrust(&self) -> bool {
        self.armed && self.failsafe_active() && self.failsafes.mode == Some(self.mode)
    }

    /// Raises and clears failsafes; runs every tick and after link changes.
    pub(super) fn failsafe_tick(&mut self, now: Now, out: &mut Vec<Output>) {
        for (i, rule) in RULES.iter().enumerate() {
            let action = (rule.action)(&self.params);
            let active = self.failsafes.active[i];
            if !active && action != FailsafeAction::Off && (rule.raise)(self, now) {
                self.failsafes.active[i] = true;
                let text = (rule.text)(self);
                self.statustext(
                    Topic::FailsafeChange(rule.kind, true),
                    MavSeverity::MAV_SEVERITY_CRITICAL,
                    &format!("Failsafe: {text}"),
                    out,
                );
                self.log(
                    "failsafe_raised",
                    self.auth.last_owner,
                    format!("{}: {text} (action {action:?})", rule.kind.name()),
                    out,
                );
                self.failsafe_act(rule.kind.name(), action, now, out);
            } else if active && (action == FailsafeAction::Off || (rule.clear)(self, now)) {
                self.failsafes.active[i] = false;
                let text = (rule.text)(self);
                self.statustext(
                    Topic::FailsafeChange(rule.kind, false),
                    MavSeverity::MAV_SEVERITY_INFO,
                    &format!("Failsafe cleared: {text}"),
                    out,
                );
                self.log(
                    "failsafe_cleared",
                    self.owner(),
                    format!("{}: {text}", rule.kind.name()),
                    out,
                );
                if !self.failsafe_active() {
                    self.failsafes.mode = None;
                }
            }
        }
    }

    fn failsafe_act(
        &mut self,
        name: &str,
        action: FailsafeAction,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let mode = match action {
            FailsafeAction::Off | FailsafeAction::Warn => return,
            FailsafeAction::Disarm => {
                self.disarm(&format!("failsafe: {name}"), None, out);
                return;
            }
            FailsafeAction::DepthHold => Mode::AltHold,
            FailsafeAction::Surface => Mode::Surface,
        };
        let why = if mode.refused().is_some() {
            Some("not available on this vehicle")
        } else if !self.armed || self.board.link != LinkState::Up {
            Some("not possible without the board link")
        } else {
            self.hold_unavailable(mode, now)
        };
        if why.is_none()
            && self.set_mode(mode.number(), None, now, out) == MavResult::MAV_RESULT_ACCEPTED
        {
            self.failsafes.mode = Some(mode);
        } else {
            self.statustext(
                Topic::Failsafe,
                MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!(
                    "Failsafe {name}: {} is {}, disarming instead",
                    mode,
                    why.unwrap_or("refused")
                ),
                out,
            );
            self.disarm(&format!("failsafe: {name}"), None, out);
        }
    }
}
