//! STATUSTEXT: what every station sees (vehicle events) and what only the
//! asker sees (replies to its bad or refused requests, rate-limited per
//! sender), and the one place that makes every text ASCII.
//!
//! A station that is refused must never be able to make the vehicle talk to
//! the other stations: replies go to its own peer, at most one per second
//! per kind, the rest only counted.

use std::collections::HashMap;
use std::time::Duration;

use mavlink_core::types::CharArray;

use super::{Now, Output, Sender, To, Vehicle};
use crate::dialect::neptunus::*;

/// A reply of one kind reaches one sender at most this often.
pub(super) const REPLY_EVERY: Duration = Duration::from_secs(1);
/// Senders remembered for rate limiting; beyond this (spoofed ids on many
/// ports) the least useful entries are forgotten and, while still full,
/// replies are only counted.
const MAX_SENDERS: usize = 512;

/// What a reply is about: each kind has its own rate limit per sender.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) enum ReplyKind {
    /// PARAM_SET/READ of a name that does not exist.
    UnknownParam,
    /// PARAM_SET refused (range, type, meaning).
    ParamRefused,
    /// A command or message refused for lack of control.
    Refused,
    /// Stick input from a station not in control.
    Input,
    /// A telemetry rate request from a station that may not control.
    Rates,
    /// Control requests that cannot be honoured.
    Control,
    /// SETUP_SIGNING refused.
    Signing,
    /// Information for the asker (SYSID_THISMAV at the next start …).
    Note,
    /// Log download and file access refused or done.
    Files,
}

impl ReplyKind {
    /// What a reply of this kind is about.
    fn topic(self) -> Topic {
        match self {
            Self::Refused | Self::Input | Self::Control => Topic::Control,
            Self::UnknownParam
            | Self::ParamRefused
            | Self::Rates
            | Self::Signing
            | Self::Note
            | Self::Files => Topic::General,
        }
    }
}

/// What a text is about, chosen where it is written: the browser HMI files
/// it under the developer logger's category of the same name (thesis 7.2);
/// `general` texts appear only in the message list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topic {
    /// Safety-mode stops: arming, disarming, mode and run-mode changes.
    Stop,
    /// Who controls the vehicle: transfers, requests, refusals.
    Control,
    /// The pilot gain and input hold.
    Gain,
    /// The depth autopilot and its setpoints.
    ApDepth,
    /// The heading autopilot and its setpoints.
    ApHeading,
    /// A failsafe raised (`true`) or cleared (`false`): which one, typed, so
    /// a reader never has to tell them apart by their words.
    FailsafeChange(FailsafeKind, bool),
    /// What a failsafe did ("Failsafe gcs: ALT_HOLD is refused, disarming
    /// instead").
    Failsafe,
    /// The board link.
    BoardLink,
    /// Anything else (parameters, signing, payload, telemetry rates).
    General,
}

/// Which failsafe: carried with each raise and clear text
/// ([`Topic::FailsafeChange`]), so the browser HMI knows the reason by its
/// kind and keeps the words only to show them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailsafeKind {
    /// The station in control went silent or left while armed.
    Gcs,
    /// No stick input in a mode the pilot drives.
    PilotInput,
    /// The board link is down.
    BoardLink,
    BatteryLow,
    BatteryCritical,
}

impl FailsafeKind {
    /// Short name for logs.
    pub fn name(self) -> &'static str {
        match self {
            Self::Gcs => "gcs",
            Self::PilotInput => "pilot_input",
            Self::BoardLink => "board_link",
            Self::BatteryLow => "battery_low",
            Self::BatteryCritical => "battery_critical",
        }
    }
}

impl Topic {
    /// The developer logger's category (a failsafe's change and its
    /// action are both `failsafe`).
    pub fn category(self) -> &'static str {
        match self {
            Self::Stop => "stop",
            Self::Control => "control",
            Self::Gain => "gain",
            Self::ApDepth => "ap_depth",
            Self::ApHeading => "ap_heading",
            Self::FailsafeChange(..) | Self::Failsafe => "failsafe",
            Self::BoardLink => "board_link",
            Self::General => "general",
        }
    }
}

impl serde::Serialize for Topic {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.category())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Key {
    endpoint: usize,
    peer: u64,
    sysid: u8,
    kind: ReplyKind,
}

/// Per-sender, per-kind rate limits of replies, and the id of the last
/// text sent in chunks.
#[derive(Debug, Clone, Default)]
pub(super) struct Texts {
    last: HashMap<Key, Duration>,
    /// MAVLink 2 STATUSTEXT id of the last long text (its chunks share it).
    pub chunk_id: u16,
    /// Replies sent.
    pub sent: u64,
    /// Replies suppressed by the rate limit (counted, not sent).
    pub suppressed: u64,
}

impl Texts {
    /// Whether a reply of `kind` to `from` may go out now; counts it either way.
    fn allow(&mut self, from: Sender, kind: ReplyKind, every: Duration, now: Duration) -> bool {
        let key = Key {
            endpoint: from.endpoint,
            peer: from.peer,
            sysid: from.sysid,
            kind,
        };
        if let Some(t) = self.last.get(&key)
            && now.saturating_sub(*t) < every
        {
            self.suppressed += 1;
            return false;
        }
        if !self.last.contains_key(&key) && self.last.len() >= MAX_SENDERS {
            // Forget the ones whose limit has run out; they would be allowed anyway.
            self.last
                .retain(|_, t| now.saturating_sub(*t) < REPLY_EVERY.max(every));
            if self.last.len() >= MAX_SENDERS {
                self.suppressed += 1;
                return false;
            }
        }
        self.last.insert(key, now);
        self.sent += 1;
        true
    }
}

/// The text as ground stations can show it: ASCII only. µ → u, ° → deg,
/// × → x, ± → +/-, typographic dashes and quotes to their ASCII forms, and
/// control characters to spaces; anything else becomes '?'.
pub fn ascii_text(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            ' '..='~' => s.push(c),
            'µ' | 'μ' => s.push('u'),
            '°' => s.push_str("deg"),
            '×' => s.push('x'),
            '±' => s.push_str("+/-"),
            '−' | '–' | '—' => s.push('-'),
            '‘' | '’' => s.push('\''),
            '“' | '”' => s.push('"'),
            '…' => s.push_str("..."),
            c if c.is_control() || c.is_whitespace() => s.push(' '),
            _ => s.push('?'),
        }
    }
    s
}

impl Vehicle {
    /// A vehicle event every station must see (failsafes, arming, modes,
    /// saving trouble).
    pub(super) fn statustext(
        &mut self,
        topic: Topic,
        severity: MavSeverity,
        text: &str,
        out: &mut Vec<Output>,
    ) {
        self.statustext_to(To::All, topic, severity, text, out);
    }

    /// A reply to `from` alone, at most one per [`REPLY_EVERY`] of its kind;
    /// true when it was sent (callers log only what they report).
    pub(super) fn reply_text(
        &mut self,
        from: Sender,
        kind: ReplyKind,
        severity: MavSeverity,
        text: &str,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        self.reply_text_every(from, kind, REPLY_EVERY, severity, text, now, out)
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn reply_text_every(
        &mut self,
        from: Sender,
        kind: ReplyKind,
        every: Duration,
        severity: MavSeverity,
        text: &str,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        if !self.texts.allow(from, kind, every, now.mono) {
            return false;
        }
        self.statustext_to(from.reply(), kind.topic(), severity, text, out);
        true
    }

    fn statustext_to(
        &mut self,
        to: To,
        topic: Topic,
        severity: MavSeverity,
        text: &str,
        out: &mut Vec<Output>,
    ) {
        let text = ascii_text(text);
        tracing::info!(severity = ?severity, to = ?to, "{text}");
        // Long texts go in 50-byte chunks sharing an id, as MAVLink 2 allows.
        let bytes = text.as_bytes();
        if bytes.len() <= 50 {
            out.push(Output::Text {
                to,
                topic,
                msg: MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                    severity,
                    text: CharArray::from(text.as_str()),
                    id: 0,
                    chunk_seq: 0,
                }),
            });
            return;
        }
        self.texts.chunk_id = self.texts.chunk_id.wrapping_add(1).max(1);
        for (i, chunk) in bytes.chunks(50).enumerate() {
            let mut arr = [0u8; 50];
            arr[..chunk.len()].copy_from_slice(chunk);
            out.push(Output::Text {
                to,
                topic,
                msg: MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                    severity,
                    text: CharArray::from(arr),
                    id: self.texts.chunk_id,
                    chunk_seq: i as u8,
                }),
            });
        }
    }

    /// Replies sent to single stations, and those suppressed by the rate limit.
    pub fn reply_counts(&self) -> (u64, u64) {
        (self.texts.sent, self.texts.suppressed)
    }
}
