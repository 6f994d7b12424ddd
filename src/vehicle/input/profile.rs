//! One ground station's conventions: the [`Profile`] type and the checks
//! serde cannot express.
//!
//! Owns [`Profile`], [`ZConvention`] and [`RcMap`], and the validation that
//! names the offending place in the file. Loading files is
//! [`Profiles`](super::Profiles)' job; converting input is in `convert`.

use serde::{Deserialize, Serialize};

use super::locate::{Invalid, Seg};
use super::{DEFAULT_PROFILE_NAME, MAX_DEADBAND, RC_CHANNELS};
use crate::vehicle::params::{BTN_DEFAULTS, BUTTONS, is_button_function};

/// Which way MANUAL_CONTROL's z runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ZConvention {
    /// 0..1000, 500 neutral, above 500 = rise (ArduSub, QGC, Cockpit, MAVSDK).
    ZeroToThousand,
    /// −1000..1000, 0 neutral, positive = rise (the MAVLink spec).
    Centered,
}

/// RC_CHANNELS_OVERRIDE channel numbers (1-based) of each function.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RcMap {
    pub heave: u8,
    pub yaw: u8,
    pub forward: u8,
    pub lateral: u8,
    pub tilt: u8,
    pub lights: u8,
}

impl Default for RcMap {
    /// ArduSub's map.
    fn default() -> Self {
        Self {
            heave: 3,
            yaw: 4,
            forward: 5,
            lateral: 6,
            tilt: 8,
            lights: 9,
        }
    }
}

impl RcMap {
    fn named(&self) -> [(&'static str, u8); 6] {
        [
            ("heave", self.heave),
            ("yaw", self.yaw),
            ("forward", self.forward),
            ("lateral", self.lateral),
            ("tilt", self.tilt),
            ("lights", self.lights),
        ]
    }
}

/// The conventions of one ground station.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    pub name: String,
    /// Senders it applies to; empty = none (a reference convention).
    pub sysids: Vec<u8>,
    #[serde(default)]
    pub description: String,
    pub z_convention: ZConvention,
    /// 0..0.5 of full scale, on x, y, z and r.
    #[serde(default)]
    pub deadband: f64,
    /// 0..1: `out = (1−e)·in + e·in³`.
    #[serde(default)]
    pub expo: f64,
    /// Default function (ArduSub code) of button i, up to 32; missing = 0.
    #[serde(default = "default_buttons")]
    pub buttons: Vec<u8>,
    /// Default function of button i while shift is held.
    #[serde(default = "default_shift_buttons")]
    pub shift_buttons: Vec<u8>,
    #[serde(default)]
    pub rc: RcMap,
}

fn default_buttons() -> Vec<u8> {
    BTN_DEFAULTS.iter().map(|b| b.0).collect()
}

fn default_shift_buttons() -> Vec<u8> {
    BTN_DEFAULTS.iter().map(|b| b.1).collect()
}

impl Profile {
    /// ArduSub's own convention: the profile for senders no file claims.
    pub fn ardusub_default() -> Self {
        Self {
            name: DEFAULT_PROFILE_NAME.into(),
            sysids: Vec::new(),
            description: "ArduSub's convention, for senders no profile claims".into(),
            z_convention: ZConvention::ZeroToThousand,
            deadband: 0.0,
            expo: 0.0,
            buttons: default_buttons(),
            shift_buttons: default_shift_buttons(),
            rc: RcMap::default(),
        }
    }

    /// Default function of button `i`, regular or shifted; 0 (none) past the list.
    pub fn button_function(&self, i: usize, shifted: bool) -> u8 {
        let list = if shifted {
            &self.shift_buttons
        } else {
            &self.buttons
        };
        list.get(i).copied().unwrap_or(0)
    }

    /// Checks the ranges serde cannot express; the error names the place.
    pub(super) fn validate(&self) -> Result<(), Invalid> {
        if self.name.trim().is_empty() {
            return Err(Invalid::at(
                &[Seg::Key("name")],
                "name is empty — give the profile a name".into(),
            ));
        }
        if self.name == DEFAULT_PROFILE_NAME {
            return Err(Invalid::at(
                &[Seg::Key("name")],
                format!(
                    "name \"{DEFAULT_PROFILE_NAME}\" is reserved for the built-in fallback — choose another name"
                ),
            ));
        }
        for (i, &s) in self.sysids.iter().enumerate() {
            if s == 0 {
                return Err(Invalid::at(
                    &[Seg::Key("sysids"), Seg::Index(i)],
                    "sysid 0 is the broadcast address, never a sender — use 1..=255".into(),
                ));
            }
            if self.sysids[..i].contains(&s) {
                return Err(Invalid::at(
                    &[Seg::Key("sysids"), Seg::Index(i)],
                    format!("sysid {s} is listed twice — list it once"),
                ));
            }
        }
        if !(self.deadband.is_finite() && (0.0..=MAX_DEADBAND).contains(&self.deadband)) {
            return Err(Invalid::at(
                &[Seg::Key("deadband")],
                format!(
                    "deadband = {} is out of range — use 0..=0.5 (a fraction of full scale)",
                    self.deadband
                ),
            ));
        }
        if !(self.expo.is_finite() && (0.0..=1.0).contains(&self.expo)) {
            return Err(Invalid::at(
                &[Seg::Key("expo")],
                format!("expo = {} is out of range — use 0..=1", self.expo),
            ));
        }
        for (key, list) in [
            ("buttons", &self.buttons),
            ("shift_buttons", &self.shift_buttons),
        ] {
            if list.len() > BUTTONS {
                return Err(Invalid::at(
                    &[Seg::Key(key), Seg::Index(BUTTONS)],
                    format!(
                        "{key} has {} entries — MANUAL_CONTROL has {BUTTONS} buttons",
                        list.len()
                    ),
                ));
            }
            if let Some(i) = list.iter().position(|&c| !is_button_function(c)) {
                return Err(Invalid::at(
                    &[Seg::Key(key), Seg::Index(i)],
                    format!(
                        "{key}[{i}] = {} is not a button function — use an ArduSub code \
                         (0 none, 1 shift, 2-13 arm/modes, 21-27 mount, 31-36 lights, 41-49, \
                         51-59 relays, 61-87 actuators, 91-96 custom) or 101 laser_toggle",
                        list[i]
                    ),
                ));
            }
        }
        let named = self.rc.named();
        for (i, (key, ch)) in named.iter().enumerate() {
            let path = [Seg::Key("rc"), Seg::Key(key)];
            if !(1..=RC_CHANNELS as u8).contains(ch) {
                return Err(Invalid::at(
                    &path,
                    format!("rc.{key} = {ch} — use a channel 1..=18"),
                ));
            }
            if let Some((other, _)) = named[..i].iter().find(|(_, c)| c == ch) {
                // Point at whichever of the two the file sets (one may be a default).
                let mut inv = Invalid::at(
                    &path,
                    format!(
                        "rc.{key} = {ch} is also rc.{other} — give each function its own channel"
                    ),
                );
                inv.alternative = Some(vec![Seg::Key("rc"), Seg::Key(other)]);
                return Err(inv);
            }
        }
        Ok(())
    }
}
