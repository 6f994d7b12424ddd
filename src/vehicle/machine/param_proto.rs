//! The parameter protocol: PARAM_REQUEST_LIST (streamed a few per tick),
//! PARAM_REQUEST_READ, and PARAM_SET — who may set, which `param_type` is
//! accepted, the values no parameter may take here (a system id the
//! running vehicle or the browser HMI uses), and how it is answered
//! (accepted: PARAM_VALUE to everyone; refused: the old value and a
//! rate-limited reason to the sender alone). The rules a value must keep
//! wherever it comes from live in [`ParamStore::set`](crate::vehicle::params::ParamStore::set).

use super::texts::ReplyKind;
use super::{Identity, Now, Output, Sender, To, Vehicle, authority, char_str, chars};
use crate::dialect::neptunus::*;
use crate::vehicle::params::{self, ParamDef, ParamType};

/// Parameters sent per tick while a list is being streamed (a burst of
/// hundreds of datagrams can overflow a ground station's socket buffer).
const PARAMS_PER_TICK: usize = 20;

/// Whether a PARAM_SET's `param_type` may set a parameter of type `ty`
/// holding `value`: its own type; REAL32 (pymavlink's `param_set_send`
/// default, and what `--identity generic` advertises for every parameter);
/// for integer parameters any integer type whose range holds the value
/// (MAVSDK may send INT32 for a parameter it has not read). Values travel
/// C-cast, so the type only says how the station means the number.
fn type_accepts(ty: ParamType, sent: MavParamType, value: f64) -> bool {
    use MavParamType as T;
    if sent == ty.mav_type() || sent == T::MAV_PARAM_TYPE_REAL32 {
        return true;
    }
    if !ty.is_integer() {
        return false;
    }
    let (lo, hi): (f64, f64) = match sent {
        T::MAV_PARAM_TYPE_INT8 => (i8::MIN.into(), i8::MAX.into()),
        T::MAV_PARAM_TYPE_UINT8 => (0.0, u8::MAX.into()),
        T::MAV_PARAM_TYPE_INT16 => (i16::MIN.into(), i16::MAX.into()),
        T::MAV_PARAM_TYPE_UINT16 => (0.0, u16::MAX.into()),
        // As floats the 32-bit limits round up by one; C-cast values near
        // them are the limits.
        T::MAV_PARAM_TYPE_INT32 => (i32::MIN.into(), f64::from(i32::MAX as f32)),
        T::MAV_PARAM_TYPE_UINT32 => (0.0, f64::from(u32::MAX as f32)),
        _ => return false,
    };
    (lo..=hi).contains(&value.trunc())
}

fn type_name(t: MavParamType) -> String {
    format!("{t:?}")
        .trim_start_matches("MAV_PARAM_TYPE_")
        .to_owned()
}

impl Vehicle {
    /// PARAM_REQUEST_LIST: the whole list to the asker, a few per tick; a
    /// repeated request restarts the list for that peer.
    pub(super) fn param_request_list(&mut self, from: Sender) {
        let to = from.reply();
        self.streams.param_queue.retain(|(t, _)| *t != to);
        self.streams
            .param_queue
            .extend((0..self.params.len()).map(|i| (to, i)));
    }

    /// PARAM_REQUEST_READ by index, or by name when the index is negative.
    pub(super) fn param_request_read(
        &mut self,
        from: Sender,
        p: &PARAM_REQUEST_READ_DATA,
        out: &mut Vec<Output>,
    ) {
        let index = if p.param_index >= 0 {
            Some(p.param_index as usize)
        } else {
            params::index_of(&char_str(&p.param_id))
        };
        if let Some(i) = index {
            self.send_param(i, from.reply(), out);
        }
    }

    /// The next few parameters of the lists being streamed.
    pub(super) fn param_stream_tick(&mut self, out: &mut Vec<Output>) {
        let n = self.streams.param_queue.len().min(PARAMS_PER_TICK);
        let batch: Vec<(To, usize)> = self.streams.param_queue.drain(..n).collect();
        for (to, idx) in batch {
            self.send_param(idx, to, out);
        }
    }

    /// PARAM_VALUE for the parameter at `index`, typed as the identity says.
    pub(super) fn param_value(&self, index: usize) -> Option<MavMessage> {
        let (def, value) = self.params.get_index(index)?;
        let param_type = match self.identity {
            Identity::Ardupilot => def.ty.mav_type(),
            Identity::Generic => MavParamType::MAV_PARAM_TYPE_REAL32,
        };
        Some(MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: value as f32,
            param_count: self.params.len() as u16,
            param_index: index as u16,
            param_id: chars(def.name),
            param_type,
        }))
    }

    /// State that follows a parameter at once.
    fn on_param_changed(&mut self, name: &str) {
        if name == "JS_GAIN_DEFAULT" {
            self.pilot.gain = f64::from(self.params.js_gain_default());
        }
    }

    pub(super) fn param_set(
        &mut self,
        from: Sender,
        p: &PARAM_SET_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let asked = char_str(&p.param_id);
        let Some(index) = self.known_param(from, &asked, now, out) else {
            return;
        };
        let def: &'static ParamDef = &params::definitions()[index];
        let name = def.name;
        let reply = from.reply();
        if let Err(why) = self.check_control(from, authority::Control::Command, now, out) {
            self.refuse_command(from, &format!("PARAM_SET {name}"), why, now, out);
            self.send_param(index, reply, out);
            return;
        }
        let value = f64::from(p.param_value);
        if !type_accepts(def.ty, p.param_type, value) {
            self.counters.bad_param_types += 1;
            self.reply_text(
                from,
                ReplyKind::ParamRefused,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!(
                    "Param {name} refused: param_type {} cannot carry {value} for this {} parameter",
                    type_name(p.param_type),
                    def.ty.name()
                ),
                now,
                out,
            );
            self.send_param(index, reply, out);
            return;
        }
        if let Some(why) = self.id_conflict(name, value) {
            self.reply_text(
                from,
                ReplyKind::ParamRefused,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Param refused: {name} = {value}: {why}"),
                now,
                out,
            );
            self.send_param(index, reply, out);
            return;
        }
        let before = self.params.get_index(index).map(|(_, v)| v);
        match self.params.set(name, value) {
            Ok(v) => {
                if before != Some(v) {
                    self.on_param_changed(name);
                    self.param_changed(name, now);
                }
                // Logged once per second per parameter: a dragged slider is
                // not fifty lines.
                if before != Some(v) && self.persist.log_change_due(name, now.mono) {
                    self.log(
                        "param_set",
                        Some(from.sysid),
                        format!("{name} = {v} (was {})", before.unwrap_or(f64::NAN)),
                        out,
                    );
                }
                if name == "SYSID_THISMAV" && v != f64::from(self.sysid) {
                    self.reply_text(
                        from,
                        ReplyKind::Note,
                        MavSeverity::MAV_SEVERITY_NOTICE,
                        &format!(
                            "SYSID_THISMAV {v} takes effect at the next start; until then this vehicle stays system {}",
                            self.sysid
                        ),
                        now,
                        out,
                    );
                }
                self.send_param(index, To::All, out);
            }
            Err(e) => {
                self.reply_text(
                    from,
                    ReplyKind::ParamRefused,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("Param refused: {e}"),
                    now,
                    out,
                );
                self.send_param(index, reply, out);
            }
        }
    }

    /// A PARAM_SET whose param_type is no MAV_PARAM_TYPE at all.
    pub(super) fn bad_param_type(
        &mut self,
        from: Sender,
        asked: &str,
        param_type: u8,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let Some(index) = self.known_param(from, asked, now, out) else {
            return;
        };
        self.counters.bad_param_types += 1;
        self.reply_text(
            from,
            ReplyKind::ParamRefused,
            MavSeverity::MAV_SEVERITY_WARNING,
            &format!("Param {asked} refused: param_type {param_type} is not a MAV_PARAM_TYPE"),
            now,
            out,
        );
        self.send_param(index, from.reply(), out);
    }

    /// The index of parameter `asked`, or a (rate-limited) reply to the
    /// sender alone that there is no such parameter.
    fn known_param(
        &mut self,
        from: Sender,
        asked: &str,
        now: Now,
        out: &mut Vec<Output>,
    ) -> Option<usize> {
        let index = params::index_of(asked);
        if index.is_none() {
            self.reply_text(
                from,
                ReplyKind::UnknownParam,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Param {asked}: no such parameter"),
                now,
                out,
            );
        }
        index
    }

    fn send_param(&self, index: usize, to: To, out: &mut Vec<Output>) {
        if let Some(msg) = self.param_value(index) {
            out.push(Output::Send { to, msg });
        }
    }

    /// Values the parameter store cannot judge alone: a system id the
    /// running vehicle or the browser HMI's sessions use. (The store keeps
    /// the rest: SYSID_THISMAV is never 255, SYSID_MYGCS or NEPT_GCS_ALLOWn.)
    fn id_conflict(&self, name: &str, value: f64) -> Option<String> {
        if !value.is_finite() || !(0.0..=255.0).contains(&value) {
            return None; // the range check says why
        }
        let id = value.trunc() as u8;
        let (lo, hi) = self.hmi_sysids;
        if name == "SYSID_THISMAV" && (lo..=hi).contains(&id) {
            Some(format!(
                "{lo}..{hi} are lent to browser HMI sessions (ground stations)"
            ))
        } else if (name == "SYSID_MYGCS" || name.starts_with("NEPT_GCS_ALLOW"))
            && id != 0
            && id == self.sysid
        {
            Some("that is this vehicle's own system id (SYSID_THISMAV)".into())
        } else {
            None
        }
    }

    /// A telemetry-rate request from a station that may not control:
    /// nothing changes for the others on its endpoint.
    pub(super) fn refuse_rates(&mut self, from: Sender, now: Now, out: &mut Vec<Output>) {
        self.counters.refused_rate_requests += 1;
        let why = if self.signing_active && !from.signed {
            "unsigned, and signing is on"
        } else {
            "not an allowed GCS (SYSID_MYGCS, NEPT_GCS_ALLOWn)"
        };
        let text = format!(
            "Telemetry rates unchanged: sysid {} may only watch ({why})",
            from.sysid
        );
        if self.reply_text(
            from,
            ReplyKind::Rates,
            MavSeverity::MAV_SEVERITY_WARNING,
            &text,
            now,
            out,
        ) {
            self.log("rates_refused", Some(from.sysid), text, out);
        }
    }
}
