//! SETUP_SIGNING: who may set or clear the link key (a trusted endpoint;
//! once signing is on, only a signed request). The app persists the key.

use super::texts::ReplyKind;
use super::texts::Topic;
use super::{Now, Output, Sender, Vehicle};
use crate::dialect::neptunus::*;

impl Vehicle {
    /// SETUP_SIGNING: only over a trusted endpoint, and once signing is on
    /// only signed with the current key. The key itself is never logged.
    pub(super) fn setup_signing(
        &mut self,
        from: Sender,
        k: &SETUP_SIGNING_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let refusal = if !from.trusted {
            Some(format!("endpoint {} is not trusted", from.endpoint))
        } else if self.signing_active && !from.signed {
            Some("unsigned, and a key is already set".to_owned())
        } else {
            None
        };
        if let Some(why) = refusal {
            let text = format!("SETUP_SIGNING from sysid {} ignored: {why}", from.sysid);
            if self.reply_text(
                from,
                ReplyKind::Signing,
                MavSeverity::MAV_SEVERITY_WARNING,
                &text,
                now,
                out,
            ) {
                self.log("signing_refused", Some(from.sysid), text, out);
            }
            return;
        }
        let off = k.secret_key.iter().all(|b| *b == 0);
        self.signing_active = !off;
        out.push(Output::SetSigningKey {
            key: k.secret_key,
            initial_timestamp: k.initial_timestamp,
        });
        let (kind, text) = if off {
            ("signing_key_cleared", "Signing off: key cleared")
        } else {
            ("signing_key_set", "Signing on: key set")
        };
        self.statustext(Topic::General, MavSeverity::MAV_SEVERITY_INFO, text, out);
        self.log(
            kind,
            Some(from.sysid),
            format!("over endpoint {}", from.endpoint),
            out,
        );
    }
}
