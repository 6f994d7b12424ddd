//! PARAM_SET: who may set, which `param_type` is accepted, the values no
//! parameter may take (a ground station's system id for the vehicle), and
//! how it is answered (accepted: PARAM_VALUE to everyone; refused: the old
//! value and a rate-limited reason to the sender alone).

use super::texts::ReplyKind;
use super::{Now, Output, Sender, To, Vehicle, authority, char_str};
use crate::dialect::neptunus::*;
use crate::vehicle::params::{self, ParamDef, ParamType};

/// The id QGroundControl, MAVProxy and pymavlink use by default.
const DEFAULT_GCS_SYSID: u8 = 255;

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
            self.bad_param_types += 1;
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
        self.bad_param_types += 1;
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

    /// Values that would make the vehicle share a ground station's system
    /// id (or a ground station the vehicle's): refused whatever the range.
    fn id_conflict(&self, name: &str, value: f64) -> Option<String> {
        if !value.is_finite() || !(0.0..=255.0).contains(&value) {
            return None; // the range check says why
        }
        let id = value.trunc() as u8;
        if name == "SYSID_THISMAV" {
            let (lo, hi) = self.hmi_sysids;
            if id == DEFAULT_GCS_SYSID {
                Some("255 is the ground stations' id (QGroundControl, MAVProxy, pymavlink)".into())
            } else if id == self.params.sysid_mygcs() {
                Some("that is SYSID_MYGCS, the primary ground station".into())
            } else if self.params.gcs_allowed_extra().contains(&id) {
                Some("that is an allowed ground station (NEPT_GCS_ALLOWn)".into())
            } else if (lo..=hi).contains(&id) {
                Some(format!(
                    "{lo}..{hi} are lent to browser HMI sessions (ground stations)"
                ))
            } else {
                None
            }
        } else if (name == "SYSID_MYGCS" || name.starts_with("NEPT_GCS_ALLOW"))
            && id != 0
            && (id == self.sysid || id == self.params.sysid_thismav())
        {
            Some("that is this vehicle's own system id (SYSID_THISMAV)".into())
        } else {
            None
        }
    }

    /// A telemetry-rate request from a station that may not control:
    /// nothing changes for the others on its endpoint.
    pub(super) fn refuse_rates(&mut self, from: Sender, now: Now, out: &mut Vec<Output>) {
        self.refused_rate_requests += 1;
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
