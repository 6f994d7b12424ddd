//! Pilot input from ground stations: MANUAL_CONTROL and RC_CHANNELS_OVERRIDE
//! turned into normalised sticks, per ground-station convention ("profile").
//!
//! This module owns the conventions of each ground station (which way z
//! runs, deadband and expo, default buttons, RC channel map), the loader of
//! `gcs_profiles/*.toml` and the pure conversions. It must never decide who
//! is in control, apply the pilot gain or talk to the board: the vehicle
//! core does that with the [`Sticks`] and [`RcUpdate`] returned here, and
//! [`super::mixer`] applies the gain.
//!
//! # Conventions
//! - x forward, y lateral (right +), r yaw (turn right +): −1000..1000 → −1..1.
//! - z, the heave stick, comes in two conventions ([`ZConvention`]):
//!   ArduSub's 0..1000 with 500 neutral (QGroundControl, Cockpit, MAVSDK,
//!   pymavlink scripts), and the MAVLink spec's ±1000 (the Neptunus web
//!   HMI). In both, stick up means rise; [`Sticks::heave_down`] is positive
//!   **down** so it feeds the mixer's heave directly (z = 250 → +0.5, descend).
//! - `INT16_MAX` (32767) on an axis means "not given": that axis is `None`.
//! - Shaping, in this order: clamp to ±1, deadband (rescaled so full
//!   deflection still gives ±1), expo `out = (1−e)·in + e·in³`.
//!
//! # The pilot gain, a worked example (ArduSub's)
//! At gain 0.5, ArduSub turns x = 500 into channel value
//! `1500 + 500 · 0.4 · 0.5 = 1600`, i.e. +0.25 of full forward thrust.
//! Here x = 500 gives `forward = 0.5`; the mixer multiplies by the gain:
//! `mix(Demand { surge: 0.5, .. })` at gain 0.5 gives each horizontal
//! thruster 0.25 of its half range — 1600 µs starboard and, with the port
//! thruster wired reversed, 1400 µs port (MOT_PWM 1100..1900).
//! Likewise z = 250 (ArduSub: 1400, descend at 0.25) gives
//! `heave_down = 0.5`, and 0.25 after the gain. ArduSub's JS_THR_GAIN
//! multiplies heave on top of that; the caller applies it.
//!
//! # RC_CHANNELS_OVERRIDE
//! ArduSub's map (1-based): 3 heave (1500 neutral, > 1500 = up), 4 yaw,
//! 5 forward, 6 lateral, 8 camera tilt rate, 9 lights. 1100..1900 µs ↔ −1..1
//! (lights: 1100..1900 ↔ off..full). Channels 1–8: 65535 = ignore (keep the
//! last value), 0 = release (back to neutral). Channels 9–18 are MAVLink 2
//! extensions, zero-filled when a MAVLink 1 sender leaves them out, so there
//! 0 and 65535 both mean ignore and 65534 means release (the MAVLink spec
//! and ArduPilot agree).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::params::{BTN_DEFAULTS, BUTTONS, is_button_function};

/// MANUAL_CONTROL's "this axis is not given".
pub const INVALID_AXIS: i16 = i16::MAX;
/// Name of the built-in fallback profile.
pub const DEFAULT_PROFILE_NAME: &str = "ardusub-default";
/// Largest deadband a profile may ask for (fraction of full scale).
pub const MAX_DEADBAND: f64 = 0.5;
/// RC_CHANNELS_OVERRIDE carries 18 channels.
pub const RC_CHANNELS: usize = 18;

const RC_NEUTRAL_US: f64 = 1500.0;
const RC_HALF_RANGE_US: f64 = 400.0;
const RC_MIN_US: f64 = 1100.0;
const RC_FULL_RANGE_US: f64 = 800.0;

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
    fn validate(&self) -> Result<(), Invalid> {
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

/// One step of a path into the TOML document, to find where an error is.
#[derive(Debug, Clone, Copy)]
enum Seg {
    Key(&'static str),
    Index(usize),
}

/// A validation failure and where it is.
#[derive(Debug)]
struct Invalid {
    path: Vec<Seg>,
    /// Where to point instead if the document does not contain `path`.
    alternative: Option<Vec<Seg>>,
    message: String,
}

impl Invalid {
    fn at(path: &[Seg], message: String) -> Self {
        Self {
            path: path.to_vec(),
            alternative: None,
            message,
        }
    }

    /// Byte offset of the failure in `text`.
    fn offset(&self, text: &str) -> usize {
        match (locate(text, &self.path), &self.alternative) {
            ((offset, true), _) | ((offset, false), None) => offset,
            ((offset, false), Some(alt)) => match locate(text, alt) {
                (alt_offset, true) => alt_offset,
                _ => offset,
            },
        }
    }
}

/// Errors of the profile loader; each names the file, the place and the fix.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    #[error(
        "cannot read ground-station profile directory {}: {source} — pass a directory of *.toml profiles",
        dir.display()
    )]
    ReadDir {
        dir: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot read ground-station profile {}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("no ground-station profiles (*.toml) in {} — pass the directory holding them", dir.display())]
    Empty { dir: PathBuf },
    #[error("{file}:{line}:{column}: {message}")]
    Invalid {
        file: String,
        line: usize,
        column: usize,
        message: String,
    },
}

impl ProfileError {
    fn at(file: &str, text: &str, offset: usize, message: String) -> Self {
        let (line, column) = line_column(text, offset);
        Self::Invalid {
            file: file.into(),
            line,
            column,
            message,
        }
    }
}

/// 1-based line and column (in characters) of a byte offset.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// Byte offset of the value at `path`, as deep as the document goes
/// (a key left to its default points at its table), and whether the whole
/// path was found.
fn locate(text: &str, path: &[Seg]) -> (usize, bool) {
    use toml::de::{DeTable, DeValue};
    let Ok(root) = DeTable::parse(text) else {
        return (0, false);
    };
    let mut offset = 0;
    let mut table = Some(root.get_ref());
    let mut array = None;
    for seg in path {
        let found = match (*seg, table, array) {
            (Seg::Key(k), Some(t), _) => t
                .iter()
                .find(|(key, _)| &**key.get_ref() == k)
                .map(|(key, v)| (key.span(), v)),
            (Seg::Index(i), _, Some(a)) => {
                let a: &toml::de::DeArray<'_> = a;
                // Past the end (too many entries): point at the last one.
                a.get(i).or(a.last()).map(|v| (v.span(), v))
            }
            _ => None,
        };
        let Some((key_span, v)) = found else {
            return (offset, false);
        };
        offset = match seg {
            Seg::Key(_) if !matches!(v.get_ref(), DeValue::Array(_) | DeValue::Table(_)) => {
                v.span().start
            }
            Seg::Key(_) => key_span.start,
            Seg::Index(_) => v.span().start,
        };
        table = v.get_ref().as_table();
        array = v.get_ref().as_array();
    }
    (offset, true)
}

/// The profiles in use: one per convention, and the fallback.
#[derive(Debug, Clone, PartialEq)]
pub struct Profiles {
    profiles: Vec<Profile>,
    fallback: Profile,
}

/// The shipped profiles, embedded so the binary needs no files at run time.
const BUILTIN: [(&str, &str); 6] = [
    (
        "qgroundcontrol.toml",
        include_str!("../../gcs_profiles/qgroundcontrol.toml"),
    ),
    (
        "cockpit.toml",
        include_str!("../../gcs_profiles/cockpit.toml"),
    ),
    (
        "mavproxy.toml",
        include_str!("../../gcs_profiles/mavproxy.toml"),
    ),
    (
        "mavsdk.toml",
        include_str!("../../gcs_profiles/mavsdk.toml"),
    ),
    (
        "pymavlink.toml",
        include_str!("../../gcs_profiles/pymavlink.toml"),
    ),
    (
        "neptunus-web.toml",
        include_str!("../../gcs_profiles/neptunus-web.toml"),
    ),
];

impl Profiles {
    /// Loads every `*.toml` in `dir` (in file-name order).
    pub fn load_dir(dir: &Path) -> Result<Self, ProfileError> {
        let entries = std::fs::read_dir(dir).map_err(|source| ProfileError::ReadDir {
            dir: dir.into(),
            source,
        })?;
        let mut paths = Vec::new();
        for entry in entries {
            let path = entry
                .map_err(|source| ProfileError::ReadDir {
                    dir: dir.into(),
                    source,
                })?
                .path();
            if path.extension().is_some_and(|e| e == "toml") && path.is_file() {
                paths.push(path);
            }
        }
        if paths.is_empty() {
            return Err(ProfileError::Empty { dir: dir.into() });
        }
        paths.sort();
        let mut sources = Vec::with_capacity(paths.len());
        for path in paths {
            let text = std::fs::read_to_string(&path).map_err(|source| ProfileError::Read {
                path: path.clone(),
                source,
            })?;
            sources.push((path.display().to_string(), text));
        }
        let refs: Vec<(&str, &str)> = sources
            .iter()
            .map(|(f, t)| (f.as_str(), t.as_str()))
            .collect();
        Self::from_sources(&refs)
    }

    /// Parses and validates one profile; `name` (usually the file) labels errors.
    pub fn parse(name: &str, text: &str) -> Result<Profile, ProfileError> {
        let profile: Profile = toml::from_str(text).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            ProfileError::at(name, text, offset, e.message().trim_end().to_owned())
        })?;
        profile
            .validate()
            .map_err(|inv| ProfileError::at(name, text, inv.offset(text), inv.message))?;
        Ok(profile)
    }

    /// Profiles from `(file, text)` pairs: each parsed, then checked against
    /// the others (a sysid and a name may appear in one profile only).
    pub fn from_sources(sources: &[(&str, &str)]) -> Result<Self, ProfileError> {
        let mut profiles: Vec<Profile> = Vec::with_capacity(sources.len());
        let mut files: Vec<&str> = Vec::with_capacity(sources.len());
        for &(file, text) in sources {
            let p = Self::parse(file, text)?;
            if let Some(j) = profiles.iter().position(|q| q.name == p.name) {
                return Err(ProfileError::at(
                    file,
                    text,
                    locate(text, &[Seg::Key("name")]).0,
                    format!(
                        "profile name \"{}\" is already used by {} — give each profile its own name",
                        p.name, files[j]
                    ),
                ));
            }
            for (i, s) in p.sysids.iter().enumerate() {
                if let Some(j) = profiles.iter().position(|q| q.sysids.contains(s)) {
                    return Err(ProfileError::at(
                        file,
                        text,
                        locate(text, &[Seg::Key("sysids"), Seg::Index(i)]).0,
                        format!(
                            "sysid {s} is already claimed by profile \"{}\" ({}) — a sysid may \
                             appear in only one profile; remove it from one of them \
                             (`sysids = []` keeps a profile as a reference convention)",
                            profiles[j].name, files[j]
                        ),
                    ));
                }
            }
            profiles.push(p);
            files.push(file);
        }
        Ok(Self {
            profiles,
            fallback: Profile::ardusub_default(),
        })
    }

    /// The shipped profiles, or the error if one of them is broken (a test
    /// keeps that from ever shipping).
    pub fn try_builtin() -> Result<Self, ProfileError> {
        Self::from_sources(&BUILTIN)
    }

    /// The shipped profiles (`gcs_profiles/*.toml`, embedded at build time).
    pub fn builtin() -> Self {
        Self::try_builtin().unwrap_or_else(|e| {
            tracing::error!("built-in ground-station profiles are broken ({e}); every sender gets {DEFAULT_PROFILE_NAME}");
            Self {
                profiles: Vec::new(),
                fallback: Profile::ardusub_default(),
            }
        })
    }

    /// The profile for a sender, or the ArduSub default when none claims it.
    pub fn for_sysid(&self, sysid: u8) -> &Profile {
        self.profiles
            .iter()
            .find(|p| p.sysids.contains(&sysid))
            .unwrap_or(&self.fallback)
    }

    /// A profile by name (the fallback included).
    pub fn get(&self, name: &str) -> Option<&Profile> {
        self.profiles
            .iter()
            .chain(std::iter::once(&self.fallback))
            .find(|p| p.name == name)
    }

    /// The loaded profiles, in load order (without the fallback).
    pub fn profiles(&self) -> &[Profile] {
        &self.profiles
    }

    /// The profile of senders no profile claims.
    pub fn fallback(&self) -> &Profile {
        &self.fallback
    }
}

/// Normalised sticks from one MANUAL_CONTROL; `None` = axis not given.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sticks {
    /// −1..1, + = forward.
    pub forward: Option<f64>,
    /// −1..1, + = right.
    pub lateral: Option<f64>,
    /// −1..1, + = down (descend).
    pub heave_down: Option<f64>,
    /// −1..1, + = turn to starboard.
    pub yaw: Option<f64>,
}

/// Clamp to ±1 (NaN → 0), deadband, expo. Profile values out of range are
/// clamped here too, since a `Profile` can be built without the loader.
fn shape(v: f64, p: &Profile) -> f64 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(-1.0, 1.0) };
    let db = if p.deadband.is_finite() {
        p.deadband.clamp(0.0, MAX_DEADBAND)
    } else {
        0.0
    };
    let e = if p.expo.is_finite() {
        p.expo.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let a = v.abs();
    let v = if a <= db {
        0.0
    } else {
        ((a - db) / (1.0 - db)).copysign(v)
    };
    (1.0 - e) * v + e * v * v * v
}

/// MANUAL_CONTROL axes to normalised sticks under a profile's conventions.
pub fn sticks_from_manual_control(x: i16, y: i16, z: i16, r: i16, p: &Profile) -> Sticks {
    let axis = |v: i16| (v != INVALID_AXIS).then(|| shape(f64::from(v) / 1000.0, p));
    let heave_down = (z != INVALID_AXIS).then(|| {
        let z = f64::from(z);
        let down = match p.z_convention {
            ZConvention::ZeroToThousand => (500.0 - z) / 500.0,
            ZConvention::Centered => -z / 1000.0,
        };
        shape(down, p)
    });
    Sticks {
        forward: axis(x),
        lateral: axis(y),
        heave_down,
        yaw: axis(r),
    }
}

/// What one RC_CHANNELS_OVERRIDE field asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RcValue {
    /// Keep whatever the channel had.
    Ignore,
    /// Stop overriding: back to neutral.
    Release,
    /// A pulse width.
    Us(u16),
}

impl RcValue {
    /// The meaning of `raw` on channel `index` (0-based): channels 1–8 use
    /// 65535 = ignore, 0 = release; the MAVLink 2 extension channels 9–18
    /// use 0 or 65535 = ignore, 65534 = release.
    pub fn from_raw(index: usize, raw: u16) -> Self {
        match (index < 8, raw) {
            (_, u16::MAX) => Self::Ignore,
            (true, 0) => Self::Release,
            (false, 0) => Self::Ignore,
            (false, 65534) => Self::Release,
            (_, us) => Self::Us(us),
        }
    }
}

/// A new value for one input axis from an RC override.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RcAxis {
    /// The override stops: sticks and tilt rate go to 0; for lights the
    /// override stops holding the level (the caller keeps the last one).
    Release,
    /// A normalised value: −1..1 for motion and tilt rate, 0..1 for lights.
    Set(f64),
}

/// Per-axis updates from one RC_CHANNELS_OVERRIDE; `None` = leave as is.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RcUpdate {
    /// + = forward.
    pub forward: Option<RcAxis>,
    /// + = right.
    pub lateral: Option<RcAxis>,
    /// + = down (channel 3 above 1500 is up, so it is negated here).
    pub heave_down: Option<RcAxis>,
    /// + = turn to starboard.
    pub yaw: Option<RcAxis>,
    /// Camera tilt rate, + = up.
    pub tilt_rate: Option<RcAxis>,
    /// Lights level 0..1 (1100 µs off, 1900 µs full).
    pub lights: Option<RcAxis>,
}

/// RC_CHANNELS_OVERRIDE to per-axis updates under a profile's channel map.
/// Motion axes get the profile's deadband and expo like MANUAL_CONTROL.
pub fn rc_override(channels: &[u16; RC_CHANNELS], p: &Profile) -> RcUpdate {
    let value = |ch: u8| {
        let i = usize::from(ch).checked_sub(1)?;
        match RcValue::from_raw(i, *channels.get(i)?) {
            RcValue::Ignore => None,
            RcValue::Release => Some(RcAxis::Release),
            RcValue::Us(us) => Some(RcAxis::Set(f64::from(us))),
        }
    };
    let map = |ch: u8, f: &dyn Fn(f64) -> f64| {
        value(ch).map(|a| match a {
            RcAxis::Set(us) => RcAxis::Set(f(us)),
            RcAxis::Release => RcAxis::Release,
        })
    };
    let centred = |us: f64| ((us - RC_NEUTRAL_US) / RC_HALF_RANGE_US).clamp(-1.0, 1.0);
    let stick = |us: f64| shape(centred(us), p);
    RcUpdate {
        forward: map(p.rc.forward, &stick),
        lateral: map(p.rc.lateral, &stick),
        heave_down: map(p.rc.heave, &|us| -stick(us)),
        yaw: map(p.rc.yaw, &stick),
        tilt_rate: map(p.rc.tilt, &centred),
        lights: map(p.rc.lights, &|us| {
            ((us - RC_MIN_US) / RC_FULL_RANGE_US).clamp(0.0, 1.0)
        }),
    }
}

/// Button edges between two 32-bit states (`buttons | buttons2 << 16`):
/// `(pressed, released)`.
pub fn edges(prev: u32, now: u32) -> (u32, u32) {
    (now & !prev, prev & !now)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_column_counts_characters() {
        let t = "a = 1\nµb = 2\n";
        assert_eq!(line_column(t, 0), (1, 1));
        assert_eq!(line_column(t, 6), (2, 1));
        assert_eq!(line_column(t, 8), (2, 2));
        assert_eq!(line_column(t, 7), (2, 1));
        assert_eq!(line_column(t, 999), (3, 1));
    }

    #[test]
    fn locate_finds_array_elements_and_nested_keys() {
        let t = "name = \"x\"\nbuttons = [0, 1, 200]\n[rc]\nheave = 30\n";
        let (l, c) = line_column(t, locate(t, &[Seg::Key("buttons"), Seg::Index(2)]).0);
        assert_eq!((l, c), (2, 18));
        let (l, c) = line_column(t, locate(t, &[Seg::Key("rc"), Seg::Key("heave")]).0);
        assert_eq!((l, c), (4, 9));
    }
}
