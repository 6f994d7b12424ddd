//! Why the vehicle is in failsafe, in plain words, for a pilot who may have
//! joined after the failsafe's STATUSTEXT went out.
//!
//! The reasons are read from what every session has: the HEARTBEAT's
//! CRITICAL state (the core reports it while any failsafe is active or the
//! board link is down) and SYS_STATUS health bits as the core sets them
//! (`vehicle/machine/telemetry.rs::sensors`: RC_RECEIVER unhealthy while the
//! GCS or pilot-input failsafe is active or the board link is down,
//! MOTOR_OUTPUTS while the board link is down, BATTERY while the battery is
//! low or its reading stale). The failsafe raises and clears this session
//! saw — each tagged by the core with its kind ([`Kind`]), never told apart
//! by their words — refine a bit into the core's own words ("battery low
//! 10.2 V") when they agree with it.
//!
//! This file only reads: it never sends anything.

use crate::dialect::neptunus::MavSysStatusSensor as S;
use crate::vehicle::machine::FailsafeKind as Kind;

/// When CRITICAL and nothing says why.
pub(super) const UNEXPLAINED: &str = "vehicle critical (reason not reported)";

/// One failsafe raise this session saw and has not seen cleared.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Raised {
    kind: Kind,
    /// The core's words after "Failsafe: ", shown as they are.
    text: String,
}

/// The failsafes a session saw raised and not yet cleared (one per kind).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct FailsafeTexts {
    raised: Vec<Raised>,
}

impl FailsafeTexts {
    /// A whole STATUSTEXT the core tagged as the raise (`raised`) or clear
    /// of failsafe `kind`.
    pub fn on_change(&mut self, kind: Kind, raised: bool, text: &str) {
        let words = text
            .strip_prefix("Failsafe cleared: ")
            .or_else(|| text.strip_prefix("Failsafe: "))
            .unwrap_or(text)
            .trim();
        self.raised.retain(|r| r.kind != kind);
        if raised {
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
            .filter(move |r| r.kind == kind)
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
        t.on_change(Kind::BatteryLow, true, "Failsafe: battery low 10.2 V");
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
        t.on_change(Kind::PilotInput, true, "Failsafe: lost manual control");
        t.on_change(Kind::BatteryLow, true, "Failsafe: battery low 10.2 V");
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
        t.on_change(
            Kind::BatteryLow,
            false,
            "Failsafe cleared: battery low 11.9 V",
        );
        assert_eq!(
            t.reasons(true, without(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER)),
            ["no pilot input: lost manual control"]
        );
    }

    #[test]
    fn gcs_and_board_link_texts() {
        let mut t = FailsafeTexts::default();
        t.on_change(Kind::Gcs, true, "Failsafe: GCS 255 heartbeat lost");
        assert_eq!(
            t.reasons(true, without(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER)),
            ["no pilot input: GCS 255 heartbeat lost"]
        );
        t.on_change(
            Kind::BoardLink,
            true,
            "Failsafe: board link lost (no telemetry for 1.0 s)",
        );
        t.on_change(
            Kind::BatteryCritical,
            true,
            "Failsafe: battery critical 9.8 V",
        );
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
        t.on_change(
            Kind::BoardLink,
            false,
            "Failsafe cleared: board link lost (no telemetry)",
        );
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
    fn a_kind_raised_again_replaces_its_words() {
        let mut t = FailsafeTexts::default();
        t.on_change(Kind::BatteryLow, true, "Failsafe: battery low 10.2 V");
        t.on_change(Kind::BatteryLow, true, "Failsafe: battery low 10.0 V");
        assert_eq!(
            t.reasons(true, without(S::MAV_SYS_STATUS_SENSOR_BATTERY)),
            ["battery low 10.0 V"]
        );
        // The words are the core's; the kind alone says which failsafe.
        t.on_change(
            Kind::Gcs,
            true,
            "Failsafe: GCS 200 left (HMI session closed)",
        );
        assert_eq!(
            t.reasons(
                true,
                without(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER | S::MAV_SYS_STATUS_SENSOR_BATTERY)
            ),
            [
                "no pilot input: GCS 200 left (HMI session closed)",
                "battery low 10.0 V"
            ]
        );
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
        let raised = Topic::FailsafeChange(Kind::PilotInput, true);
        let ev = text(&mut m, raised, "Failsafe: lost manual control", now);
        assert!(matches!(
            &ev[..],
            [ServerMsg::Statustext { category, .. }] if *category == raised
        ));
        text(
            &mut m,
            Topic::FailsafeChange(Kind::BatteryLow, true),
            "Failsafe: battery low 10.2 V",
            now,
        );
        // Words alone are not a failsafe: only a failsafe change counts.
        text(&mut m, Topic::General, "Failsafe: made up", now);
        text(
            &mut m,
            Topic::Failsafe,
            "Failsafe gcs: ALT_HOLD is refused, disarming instead",
            now,
        );
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
            Topic::FailsafeChange(Kind::PilotInput, false),
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
