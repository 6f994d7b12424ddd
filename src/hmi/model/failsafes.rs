//! Why the vehicle is in failsafe, in plain words, for a pilot who may have
//! joined after the failsafe's STATUSTEXT went out.
//!
//! The reasons are read from what every session has: the HEARTBEAT's
//! CRITICAL state (the core reports it while any failsafe is active or the
//! board link is down) and SYS_STATUS health bits as the core sets them
//! (`vehicle/machine/telemetry.rs::sensors`: RC_RECEIVER unhealthy while the
//! GCS or pilot-input failsafe is active or the board link is down,
//! MOTOR_OUTPUTS while the board link is down, BATTERY while the battery is
//! low or its reading stale). The failsafe texts this session saw (topic
//! `failsafe`: "Failsafe: battery low 10.2 V" … "Failsafe cleared: …")
//! refine a bit into the core's own words when they agree with it.
//!
//! This file only reads: it never sends anything.

use crate::dialect::neptunus::MavSysStatusSensor as S;

/// When CRITICAL and nothing says why.
pub(super) const UNEXPLAINED: &str = "vehicle critical (reason not reported)";

/// The failsafes the core raises, told apart by the words of their texts
/// (`vehicle/machine/failsafe.rs`, `RULES[..].text`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// "GCS 255 heartbeat lost" or "no GCS in control".
    Gcs,
    /// "lost manual control".
    PilotInput,
    /// "board link lost (…)".
    BoardLink,
    /// "battery low 10.2 V".
    BatteryLow,
    /// "battery critical 9.8 V".
    BatteryCritical,
}

impl Kind {
    fn of(text: &str) -> Option<Self> {
        if text == "no GCS in control"
            || (text.starts_with("GCS ") && text.contains("heartbeat lost"))
        {
            Some(Self::Gcs)
        } else if text.starts_with("lost manual control") {
            Some(Self::PilotInput)
        } else if text.starts_with("board link lost") {
            Some(Self::BoardLink)
        } else if text.starts_with("battery low") {
            Some(Self::BatteryLow)
        } else if text.starts_with("battery critical") {
            Some(Self::BatteryCritical)
        } else {
            None
        }
    }
}

/// One failsafe raise this session saw and has not seen cleared.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Raised {
    /// `None`: a text this code does not know (a failsafe added to the
    /// core later); shown as it is while the vehicle is critical.
    kind: Option<Kind>,
    /// The core's words after "Failsafe: ".
    text: String,
}

/// Texts of a kind the session keeps at most (a flood of unknown
/// failsafe texts must not grow the model).
const MAX_RAISED: usize = 16;

/// The failsafe texts a session saw raised and not yet cleared.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct FailsafeTexts {
    raised: Vec<Raised>,
}

impl FailsafeTexts {
    /// A complete STATUSTEXT the core filed under `failsafe`.
    pub fn on_text(&mut self, text: &str) {
        let (raise, words) = if let Some(w) = text.strip_prefix("Failsafe cleared: ") {
            (false, w)
        } else if let Some(w) = text.strip_prefix("Failsafe: ") {
            (true, w)
        } else {
            // "Failsafe gcs: ALT_HOLD is refused, disarming instead": what a
            // failsafe did, not a failsafe.
            return;
        };
        let words = words.trim();
        let kind = Kind::of(words);
        self.raised.retain(|r| match kind {
            Some(_) => r.kind != kind,
            None => r.kind.is_some() || r.text != words,
        });
        if raise && self.raised.len() < MAX_RAISED {
            self.raised.push(Raised {
                kind,
                text: words.to_owned(),
            });
        }
    }

    /// The vehicle says it is not critical: no failsafe is active.
    pub fn clear(&mut self) {
        self.raised.clear();
    }

    fn texts(&self, kind: Kind) -> impl Iterator<Item = &str> {
        self.raised
            .iter()
            .filter(move |r| r.kind == Some(kind))
            .map(|r| r.text.as_str())
    }

    /// The reasons of the active failsafes: `critical` from the last
    /// HEARTBEAT, `health` the last SYS_STATUS health bits (None: none seen).
    pub fn reasons(&self, critical: bool, health: Option<S>) -> Vec<String> {
        let mut out = Vec::new();
        if !critical {
            return out;
        }
        // A bit the vehicle reported unhealthy; with no SYS_STATUS yet the
        // texts stand on their own.
        let unhealthy = |bit: S| health.is_none_or(|h| !h.contains(bit));
        let known_unhealthy = |bit: S| health.is_some_and(|h| !h.contains(bit));
        // With the board link down, the RC and battery bits are unhealthy
        // because of it (no fresh readings): only a text says more.
        let link_down = known_unhealthy(S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS);

        if unhealthy(S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS) {
            let before = out.len();
            out.extend(self.texts(Kind::BoardLink).map(str::to_owned));
            if out.len() == before && link_down {
                out.push("board link down".to_owned());
            }
        }
        if unhealthy(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER) {
            let before = out.len();
            for kind in [Kind::Gcs, Kind::PilotInput] {
                out.extend(self.texts(kind).map(|t| format!("no pilot input: {t}")));
            }
            if out.len() == before
                && !link_down
                && known_unhealthy(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER)
            {
                out.push("no pilot input".to_owned());
            }
        }
        if unhealthy(S::MAV_SYS_STATUS_SENSOR_BATTERY) {
            let before = out.len();
            for kind in [Kind::BatteryCritical, Kind::BatteryLow] {
                out.extend(self.texts(kind).map(str::to_owned));
            }
            if out.len() == before
                && !link_down
                && known_unhealthy(S::MAV_SYS_STATUS_SENSOR_BATTERY)
            {
                out.push("battery low".to_owned());
            }
        }
        out.extend(
            self.raised
                .iter()
                .filter(|r| r.kind.is_none())
                .map(|r| r.text.clone()),
        );
        if out.is_empty() {
            out.push(UNEXPLAINED.to_owned());
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use super::super::Model;
    use super::super::tests::{heartbeat, sys_status, text};
    use super::*;
    use crate::dialect::neptunus::{MavState, MavSysStatusSensor};
    use crate::hmi::protocol::ServerMsg;
    use crate::vehicle::machine::Topic;

    /// Every bit the core sets when all is well.
    fn healthy() -> S {
        S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
            | S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER
            | S::MAV_SYS_STATUS_SENSOR_BATTERY
            | S::MAV_SYS_STATUS_SENSOR_3D_GYRO
            | S::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    }

    fn without(bits: S) -> Option<S> {
        Some(healthy() & !bits)
    }

    #[test]
    fn nothing_when_not_critical_whatever_the_bits_and_texts() {
        let mut t = FailsafeTexts::default();
        t.on_text("Failsafe: battery low 10.2 V");
        // Below the threshold but not yet for BATTERY_DEBOUNCE: no failsafe.
        assert!(
            t.reasons(false, without(S::MAV_SYS_STATUS_SENSOR_BATTERY))
                .is_empty()
        );
    }

    #[test]
    fn each_bit_gives_its_reason_without_texts() {
        let t = FailsafeTexts::default();
        assert_eq!(
            t.reasons(true, without(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER)),
            ["no pilot input"]
        );
        assert_eq!(
            t.reasons(true, without(S::MAV_SYS_STATUS_SENSOR_BATTERY)),
            ["battery low"]
        );
        // The link down explains the RC and battery bits too.
        assert_eq!(
            t.reasons(
                true,
                without(
                    S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
                        | S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER
                        | S::MAV_SYS_STATUS_SENSOR_BATTERY
                )
            ),
            ["board link down"]
        );
        assert_eq!(t.reasons(true, Some(healthy())), [UNEXPLAINED]);
        assert_eq!(t.reasons(true, None), [UNEXPLAINED]);
    }

    #[test]
    fn texts_refine_the_bits_they_agree_with() {
        let mut t = FailsafeTexts::default();
        t.on_text("Failsafe: lost manual control");
        t.on_text("Failsafe: battery low 10.2 V");
        assert_eq!(
            t.reasons(
                true,
                without(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER | S::MAV_SYS_STATUS_SENSOR_BATTERY)
            ),
            ["no pilot input: lost manual control", "battery low 10.2 V"]
        );
        // The bits say the pilot input is back: its text no longer applies.
        assert_eq!(
            t.reasons(true, without(S::MAV_SYS_STATUS_SENSOR_BATTERY)),
            ["battery low 10.2 V"]
        );
        // Cleared in the core's words.
        t.on_text("Failsafe cleared: battery low 11.9 V");
        assert_eq!(
            t.reasons(true, without(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER)),
            ["no pilot input: lost manual control"]
        );
    }

    #[test]
    fn gcs_and_board_link_texts() {
        let mut t = FailsafeTexts::default();
        t.on_text("Failsafe: GCS 255 heartbeat lost");
        assert_eq!(
            t.reasons(true, without(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER)),
            ["no pilot input: GCS 255 heartbeat lost"]
        );
        t.on_text("Failsafe: board link lost (no telemetry for 1.0 s)");
        t.on_text("Failsafe: battery critical 9.8 V");
        let down = without(
            S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
                | S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER
                | S::MAV_SYS_STATUS_SENSOR_BATTERY,
        );
        assert_eq!(
            t.reasons(true, down),
            [
                "board link lost (no telemetry for 1.0 s)",
                "no pilot input: GCS 255 heartbeat lost",
                "battery critical 9.8 V"
            ]
        );
        // Before any SYS_STATUS the texts stand on their own.
        t.on_text("Failsafe cleared: board link lost (no telemetry)");
        assert_eq!(
            t.reasons(true, None),
            [
                "no pilot input: GCS 255 heartbeat lost",
                "battery critical 9.8 V"
            ]
        );
        t.clear();
        assert_eq!(t.reasons(true, None), [UNEXPLAINED]);
    }

    #[test]
    fn other_failsafe_texts_and_actions() {
        let mut t = FailsafeTexts::default();
        // What a failsafe did is not a failsafe.
        t.on_text("Failsafe gcs: ALT_HOLD is refused, disarming instead");
        t.on_text("Failsafe: leak detected");
        assert_eq!(t.reasons(true, Some(healthy())), ["leak detected"]);
        t.on_text("Failsafe cleared: leak detected");
        assert_eq!(t.reasons(true, Some(healthy())), [UNEXPLAINED]);
        // A flood of texts stays bounded.
        for i in 0..1000 {
            t.on_text(&format!("Failsafe: thing {i}"));
        }
        assert_eq!(t.reasons(true, Some(healthy())).len(), MAX_RAISED);
    }

    #[test]
    fn a_late_joiner_reads_the_failsafe_reasons_from_the_bits() {
        use MavSysStatusSensor as S;
        let now = Instant::now();
        let mut m = Model::new(None, now);
        let mut ev = Vec::new();
        // Link up, RC and battery unhealthy, CRITICAL: the GCS or pilot-input
        // failsafe and the battery one, but no text was seen.
        m.on_message(
            &sys_status(S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS, 10_200),
            now,
            &mut ev,
        );
        assert!(m.snapshot(now).failsafes.is_empty());
        m.on_message(&heartbeat(MavState::MAV_STATE_CRITICAL), now, &mut ev);
        assert_eq!(m.snapshot(now).failsafes, ["no pilot input", "battery low"]);
        // All healthy yet CRITICAL: said so, not hidden.
        let all = S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
            | S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER
            | S::MAV_SYS_STATUS_SENSOR_BATTERY;
        m.on_message(&sys_status(all, 12_000), now, &mut ev);
        assert_eq!(
            m.snapshot(now).failsafes,
            ["vehicle critical (reason not reported)"]
        );
        m.on_message(&heartbeat(MavState::MAV_STATE_ACTIVE), now, &mut ev);
        assert!(m.snapshot(now).failsafes.is_empty());
    }

    #[test]
    fn failsafe_texts_seen_refine_the_reasons_until_cleared() {
        use MavSysStatusSensor as S;
        let now = Instant::now();
        let mut m = Model::new(Some(200), now);
        let mut ev = Vec::new();
        m.on_message(&heartbeat(MavState::MAV_STATE_ACTIVE), now, &mut ev);
        let ev = text(
            &mut m,
            Topic::Failsafe,
            "Failsafe: lost manual control",
            now,
        );
        assert!(matches!(
            &ev[..],
            [ServerMsg::Statustext {
                category: Topic::Failsafe,
                ..
            }]
        ));
        text(&mut m, Topic::Failsafe, "Failsafe: battery low 10.2 V", now);
        // Words alone are not a failsafe: only the failsafe topic counts.
        text(&mut m, Topic::General, "Failsafe: made up", now);
        let mut ev = Vec::new();
        m.on_message(
            &sys_status(S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS, 10_200),
            now,
            &mut ev,
        );
        m.on_message(&heartbeat(MavState::MAV_STATE_CRITICAL), now, &mut ev);
        assert_eq!(
            m.snapshot(now).failsafes,
            ["no pilot input: lost manual control", "battery low 10.2 V"]
        );
        text(
            &mut m,
            Topic::Failsafe,
            "Failsafe cleared: lost manual control",
            now,
        );
        m.on_message(
            &sys_status(
                S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER,
                10_200,
            ),
            now,
            &mut ev,
        );
        assert_eq!(m.snapshot(now).failsafes, ["battery low 10.2 V"]);
        // No longer critical: nothing is active, whatever was seen.
        m.on_message(&heartbeat(MavState::MAV_STATE_ACTIVE), now, &mut ev);
        m.on_message(&heartbeat(MavState::MAV_STATE_CRITICAL), now, &mut ev);
        assert_eq!(m.snapshot(now).failsafes, ["battery low"]);
    }
}
