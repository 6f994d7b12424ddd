//! Control authority: which ground station may change the vehicle's state,
//! how it gets that role (claim, MAV_CMD_REQUEST_OPERATOR_CONTROL, primary
//! takeover), how it loses it, the pick-up rule and CONTROL_STATUS.
//!
//! One owner at most, identified by MAVLink system id. Every path that
//! changes the vehicle's state asks [`Vehicle::check_control`] first; every
//! change of owner goes through [`Vehicle::grant`] or
//! [`Vehicle::drop_owner`], which stop the thrusters.

use std::time::Duration;

use super::texts::ReplyKind;
use super::texts::Topic;
use super::{Now, Output, Sender, To, Vehicle};
use crate::dialect::neptunus::*;
use crate::eventlog::LogEvent;
use crate::vehicle::params::ControlClaim;

/// How long a control request waits for the owner when p3 does not say.
pub(super) const DEFAULT_REQUEST_TIMEOUT_S: f32 = 10.0;
/// The board's dead-man is fed only while the owner showed life this recently
/// (heartbeats come at 1 Hz; half a period of slack).
pub(super) const LIFE_FEEDS_DEADMAN: Duration = Duration::from_millis(1500);
/// Refusals of commands are reported at most this often.
const COMMAND_REFUSAL_REPORT: Duration = Duration::from_secs(1);
/// Refused stick input and pending pick-up are reported at most this often.
const INPUT_REPORT: Duration = Duration::from_secs(5);

/// A ground station, and the way back to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Station {
    pub sysid: u8,
    pub compid: u8,
    pub reply: To,
}

impl Station {
    pub fn of(s: Sender) -> Self {
        Self {
            sysid: s.sysid,
            compid: s.compid,
            reply: s.reply(),
        }
    }
}

/// A request for control waiting for the owner's answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Pending {
    pub from: Station,
    pub deadline: Duration,
    /// The requester's last sign of life: a request dies with its
    /// requester (no heartbeat for FS_GCS_TIMEOUT, or its HMI session
    /// closed), so control never passes to a station that is gone.
    pub last_life: Duration,
}

/// Counts events and says whether one is due for a report.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct RateLimit {
    last: Option<Duration>,
    pub count: u64,
}

impl RateLimit {
    /// Counts one event; true when it should be reported now.
    pub fn hit(&mut self, now: Duration, every: Duration) -> bool {
        self.count += 1;
        let due = self.last.is_none_or(|t| now.saturating_sub(t) >= every);
        if due {
            self.last = Some(now);
        }
        due
    }
}

/// Who controls the vehicle.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Authority {
    pub owner: Option<Station>,
    /// The owner lets requests through without asking (GCS_CONTROL_STATUS_FLAGS_TAKEOVER_ALLOWED).
    pub takeover_allowed: bool,
    pub pending: Option<Pending>,
    /// The owner's stick input is ignored until it has been neutral once.
    pub pickup: bool,
    /// The owner's last sign of life: its own HEARTBEAT or stick input.
    pub last_life: Option<Duration>,
    pub command_refusals: RateLimit,
    pub input_refusals: RateLimit,
    pub pickup_notes: RateLimit,
    /// The last station that owned the vehicle (for failsafe texts).
    pub last_owner: Option<u8>,
}

/// What kind of state-changing traffic is being checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Control {
    /// Stick input, per-thruster commands, motor test: may claim an unowned vehicle.
    Drive,
    /// Arming: may claim an unowned vehicle.
    Arm,
    /// Other state changes (mode, lights, tilt, parameters): allowed stations
    /// may make them while nobody owns the vehicle, without claiming it.
    Command,
}

/// Why control traffic was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Refusal {
    /// Signing is on and the frame was not (validly) signed.
    Unsigned,
    /// Not SYSID_MYGCS nor one of NEPT_GCS_ALLOWn.
    NotAllowed,
    /// Another station owns the vehicle.
    NotOwner(u8),
    /// Nobody owns the vehicle and NEPT_CTRL_CLAIM asks for an explicit request.
    NeedsRequest,
}

impl Refusal {
    pub fn reason(self) -> String {
        match self {
            Self::Unsigned => "unsigned, and signing is on".into(),
            Self::NotAllowed => "not an allowed GCS (SYSID_MYGCS, NEPT_GCS_ALLOWn)".into(),
            Self::NotOwner(o) => format!("GCS {o} is in control"),
            Self::NeedsRequest => {
                "nobody is in control: request control first (NEPT_CTRL_CLAIM 1)".into()
            }
        }
    }

    pub fn result(self) -> MavResult {
        match self {
            Self::Unsigned => MavResult::MAV_RESULT_DENIED,
            _ => MavResult::MAV_RESULT_NOT_IN_CONTROL,
        }
    }
}

/// How a station became the owner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Grant {
    /// First allowed station to drive or arm an unowned vehicle.
    Claim,
    /// MAV_CMD_REQUEST_OPERATOR_CONTROL granted at once.
    Request,
    /// The owner released or allowed takeover while a request was pending.
    Handover,
    /// The primary station took control without asking.
    PrimaryTakeover,
}

impl Vehicle {
    /// The current owner's system id.
    pub fn owner(&self) -> Option<u8> {
        self.auth.owner.map(|o| o.sysid)
    }

    /// Whether the owner's stick input is still waiting for neutral.
    pub fn pickup_pending(&self) -> bool {
        self.auth.pickup
    }

    pub(super) fn log(
        &self,
        kind: &'static str,
        sysid: Option<u8>,
        detail: String,
        out: &mut Vec<Output>,
    ) {
        out.push(Output::Log(LogEvent::new(kind, sysid, detail)));
    }

    /// May `from` control the vehicle at all: SYSID_MYGCS, a NEPT_GCS_ALLOWn
    /// station, or an HMI pilot session.
    pub(super) fn allowed(&self, from: Sender) -> bool {
        from.pilot || self.params.gcs_allowed(from.sysid)
    }

    /// May `from` ever control the vehicle: an allowed station whose frames
    /// are signed when signing is on. The others only watch, and nothing
    /// they send may change what other stations see (telemetry rates, peer
    /// slots, broadcast texts).
    pub fn may_control(&self, from: Sender) -> bool {
        (!self.signing_active || from.signed) && self.allowed(from)
    }

    /// May `from` change the vehicle's state in this way? Claims an unowned
    /// vehicle for the first allowed station that drives or arms (NEPT_CTRL_CLAIM 0).
    pub(super) fn check_control(
        &mut self,
        from: Sender,
        kind: Control,
        now: Now,
        out: &mut Vec<Output>,
    ) -> Result<(), Refusal> {
        if self.signing_active && !from.signed {
            return Err(Refusal::Unsigned);
        }
        if !self.allowed(from) {
            return Err(Refusal::NotAllowed);
        }
        match self.auth.owner {
            Some(o) if o.sysid == from.sysid => {
                // The owner may have moved (a new UDP port): answer where it is now.
                if let Some(owner) = self.auth.owner.as_mut() {
                    owner.reply = from.reply();
                    owner.compid = from.compid;
                }
                Ok(())
            }
            Some(o) => Err(Refusal::NotOwner(o.sysid)),
            None => match kind {
                Control::Command => Ok(()),
                Control::Drive | Control::Arm => match self.params.ctrl_claim() {
                    ControlClaim::FirstToDrive => {
                        self.grant(Station::of(from), Grant::Claim, false, now, out);
                        Ok(())
                    }
                    ControlClaim::ExplicitOnly => Err(Refusal::NeedsRequest),
                },
            },
        }
    }

    /// A refused command: the ACK result, and a report to the sender alone,
    /// rate-limited per sender (the refused must not make the vehicle talk
    /// to the other stations).
    pub(super) fn refuse_command(
        &mut self,
        from: Sender,
        what: &str,
        why: Refusal,
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        // The log is bounded for all senders together (many spoofed ids
        // must not flood it); the replies per sender.
        let log_due = self
            .auth
            .command_refusals
            .hit(now.mono, COMMAND_REFUSAL_REPORT);
        let text = format!("Refused {what} from sysid {}: {}", from.sysid, why.reason());
        let replied = self.reply_text_every(
            from,
            ReplyKind::Refused,
            COMMAND_REFUSAL_REPORT,
            MavSeverity::MAV_SEVERITY_WARNING,
            &text,
            now,
            out,
        );
        if replied && log_due {
            self.log("command_rejected", Some(from.sysid), text, out);
        }
        why.result()
    }

    /// Refused stick input: counted, reported at most every 5 s.
    pub(super) fn refuse_input(
        &mut self,
        from: Sender,
        what: &str,
        why: Refusal,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let log_due = self.auth.input_refusals.hit(now.mono, INPUT_REPORT);
        let n = self.auth.input_refusals.count;
        let text = format!(
            "Ignoring {what} from sysid {}: {} ({n} refused)",
            from.sysid,
            why.reason()
        );
        let replied = self.reply_text_every(
            from,
            ReplyKind::Input,
            INPUT_REPORT,
            MavSeverity::MAV_SEVERITY_WARNING,
            &text,
            now,
            out,
        );
        if replied && log_due {
            self.log("input_rejected", Some(from.sysid), text, out);
        }
    }

    /// The owner or the pending requester showed life (its own HEARTBEAT or
    /// stick input; with signing on, only signed counts).
    pub(super) fn note_life(&mut self, from: Sender, now: Now) {
        if !from.signed && self.signing_active {
            return;
        }
        if self.owner() == Some(from.sysid) {
            self.auth.last_life = Some(now.mono);
        }
        if let Some(p) = self.auth.pending.as_mut()
            && p.from.sysid == from.sysid
        {
            p.last_life = now.mono;
        }
    }

    /// A pending request is withdrawn because its requester is gone.
    pub(super) fn withdraw_request(&mut self, why: &str, out: &mut Vec<Output>) {
        let Some(p) = self.auth.pending.take() else {
            return;
        };
        let text = format!("Control request from GCS {} withdrawn: {why}", p.from.sysid);
        self.statustext(
            Topic::Control,
            MavSeverity::MAV_SEVERITY_WARNING,
            &text,
            out,
        );
        self.log("control_request_withdrawn", Some(p.from.sysid), text, out);
    }

    /// The pending requester, if it still shows life.
    fn live_request(&self, now: Now) -> Option<Pending> {
        self.auth
            .pending
            .filter(|p| now.mono.saturating_sub(p.last_life) <= self.gcs_timeout())
    }

    /// Whether the owner showed life within `window`.
    pub(super) fn owner_alive(&self, now: Now, window: Duration) -> bool {
        self.auth.owner.is_some()
            && self
                .auth
                .last_life
                .is_some_and(|t| now.mono.saturating_sub(t) <= window)
    }

    /// Pick-up: true when the owner's input may drive. `neutral` says whether
    /// this input has every axis centred.
    pub(super) fn picked_up(&mut self, neutral: bool, now: Now, out: &mut Vec<Output>) -> bool {
        if !self.auth.pickup {
            return true;
        }
        if neutral {
            self.auth.pickup = false;
            if let Some(o) = self.owner() {
                self.statustext(
                    Topic::Control,
                    MavSeverity::MAV_SEVERITY_INFO,
                    &format!("GCS {o}: sticks centred, driving"),
                    out,
                );
            }
            return true;
        }
        if self.auth.pickup_notes.hit(now.mono, INPUT_REPORT) {
            self.statustext(
                Topic::Control,
                MavSeverity::MAV_SEVERITY_WARNING,
                "Centre the sticks to take control",
                out,
            );
        }
        false
    }

    /// Makes `to` the owner. From another owner this is a transfer: thrusters
    /// to neutral, input hold cleared, pick-up required. Claiming an armed
    /// vehicle also needs pick-up; claiming a disarmed one does not.
    /// `takeover_allowed` is the new owner's own choice (p2 of its request).
    pub(super) fn grant(
        &mut self,
        to: Station,
        how: Grant,
        takeover_allowed: bool,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let previous = self.auth.owner.map(|o| o.sysid);
        if previous == Some(to.sysid) {
            return;
        }
        // A handover passes control from one station to another even when the
        // old owner let go first.
        let transfer =
            previous.is_some() || matches!(how, Grant::Handover | Grant::PrimaryTakeover);
        self.safety_stop(transfer || self.armed, out);
        self.auth.owner = Some(to);
        self.auth.last_owner = Some(to.sysid);
        self.auth.takeover_allowed = takeover_allowed;
        self.auth.last_life = Some(now.mono);
        if self.auth.pending.is_some_and(|p| p.from.sysid == to.sysid) {
            self.auth.pending = None;
        }
        let was = previous.map_or_else(|| "nobody".to_owned(), |p| format!("GCS {p}"));
        let (kind, how_text) = match how {
            Grant::Claim => ("control_claimed", "first to drive or arm"),
            Grant::Request => ("control_granted", "on request"),
            Grant::Handover => ("control_granted", "handed over"),
            Grant::PrimaryTakeover => ("control_takeover", "primary takeover"),
        };
        self.statustext(
            Topic::Control,
            MavSeverity::MAV_SEVERITY_INFO,
            &format!("GCS {} in control (was {was})", to.sysid),
            out,
        );
        let detail = format!(
            "{} -> {} ({how_text}{})",
            previous.map_or_else(|| "none".to_owned(), |p| p.to_string()),
            to.sysid,
            if self.auth.pickup {
                ", pick-up required"
            } else {
                ""
            }
        );
        self.log(kind, Some(to.sysid), detail, out);
        self.send_control_status(out);
    }

    /// Nobody owns the vehicle any more; a pending request gets control.
    pub(super) fn drop_owner(
        &mut self,
        kind: &'static str,
        why: &str,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let Some(old) = self.auth.owner.take() else {
            return;
        };
        self.auth.takeover_allowed = false;
        self.auth.pickup = false;
        self.safety_stop(false, out);
        self.statustext(
            Topic::Control,
            MavSeverity::MAV_SEVERITY_WARNING,
            &format!("GCS {} no longer in control: {why}", old.sysid),
            out,
        );
        self.log(kind, Some(old.sysid), why.to_owned(), out);
        if let Some(p) = self.live_request(now) {
            self.auth.pending = None;
            self.grant(p.from, Grant::Handover, false, now, out);
        } else {
            self.withdraw_request("no heartbeat from it for FS_GCS_TIMEOUT", out);
            self.send_control_status(out);
        }
    }

    /// Request timeouts and the owner's disappearance.
    pub(super) fn authority_tick(&mut self, now: Now, out: &mut Vec<Output>) {
        if self.auth.pending.is_some() && self.live_request(now).is_none() {
            self.withdraw_request("no heartbeat from it for FS_GCS_TIMEOUT", out);
        }
        if let Some(p) = self.auth.pending
            && now.mono >= p.deadline
        {
            self.auth.pending = None;
            let keeper = self
                .owner()
                .map_or_else(|| "nobody".into(), |o| format!("GCS {o}"));
            let text = format!(
                "Control request from GCS {} timed out: {keeper} keeps control",
                p.from.sysid
            );
            self.statustext(
                Topic::Control,
                MavSeverity::MAV_SEVERITY_WARNING,
                &text,
                out,
            );
            self.log("control_refused", Some(p.from.sysid), text, out);
        }
        if self.auth.owner.is_some() && !self.owner_alive(now, self.gcs_timeout()) {
            self.drop_owner("control_lost", "no heartbeat for FS_GCS_TIMEOUT", now, out);
        }
    }

    pub(super) fn gcs_timeout(&self) -> Duration {
        Duration::from_secs_f32(self.params.fs_gcs_timeout_s().clamp(0.1, 600.0))
    }

    pub(super) fn control_status(&self) -> MavMessage {
        let mut flags = GcsControlStatusFlags::GCS_CONTROL_STATUS_FLAGS_SYSTEM_MANAGER;
        if self.auth.takeover_allowed {
            flags |= GcsControlStatusFlags::GCS_CONTROL_STATUS_FLAGS_TAKEOVER_ALLOWED;
        }
        MavMessage::CONTROL_STATUS(CONTROL_STATUS_DATA {
            flags,
            gcs_main: self.owner().unwrap_or(0),
            gcs_secondary: [0; 10],
        })
    }

    pub(super) fn send_control_status(&self, out: &mut Vec<Output>) {
        out.push(Output::Send {
            to: To::All,
            msg: self.control_status(),
        });
    }
}
