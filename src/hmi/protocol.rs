//! The browser HMI's WebSocket protocol (`/ws`): JSON text messages, one
//! object each, tagged by `"type"`.
//!
//! This module owns the message types and their validation. It must never
//! build MAVLink or decide anything about the vehicle: a [`ClientMsg`] that
//! passes [`ClientMsg::validate`] is turned into MAVLink by the session
//! (`session/`), and the vehicle core decides whether it is honoured.
//!
//! # Browser → server ([`ClientMsg`])
//! | type | fields | becomes |
//! |---|---|---|
//! | `alive` | — | nothing; any message shows the tab is alive (HEARTBEAT goes out at 1 Hz only while the browser showed life within 1.5 s) |
//! | `login` | `password` | pilot rights (and a system id) if it is the pilot password (`neptunus hmi set-password`) → `login_result`; throttled per address like `POST /api/login` |
//! | `sticks` | `surge`, `sway`, `heave_up`, `yaw`: −1..1 | MANUAL_CONTROL (x, y, z, r ×1000) |
//! | `thrusters` | `port`, `vertical`, `starboard`: −1..1 (vertical + = down) | NEPTUNUS_THRUSTERS |
//! | `stop` | — | neutral MANUAL_CONTROL and NEPTUNUS_THRUSTERS |
//! | `focus_lost` | — | a stop, then the core's HMI event FocusLost (owner: safety stop, pick-up) |
//! | `input_mode` | `mode`: `keyboard`, `touch`, `gamepad`, `headtracking` | a stop, then InputModeChanged |
//! | `arm` | `arm`: bool | COMMAND_LONG 400 |
//! | `mode` | `mode`: the number of one of the welcome's `modes` ([`HMI_MODES`]) | COMMAND_LONG 176 (p1 1, p2 mode) |
//! | `run_mode` | `mode`: `normal`, `simulator` | COMMAND_LONG 44200 |
//! | `autopilot_target` | `depth_m` (0..1000) and/or `heading_deg` (0..360), null = unchanged | COMMAND_LONG 44201 (NaN for null) |
//! | `gain` | `value`: 0..1 | PARAM_SET JS_GAIN_DEFAULT |
//! | `lights` | `level`: 0..255 | COMMAND_LONG 32 (ILLUMINATOR_CONFIGURE, percent) |
//! | `laser` | `on`: bool | COMMAND_LONG 183 (DO_SET_SERVO 6, 1900/1100 µs) |
//! | `tilt` | `deg`: −90..90 | COMMAND_LONG 205 (DO_MOUNT_CONTROL, centidegrees) |
//! | `record` | `on`: bool | COMMAND_LONG 2500 / 2501 (VIDEO_START_CAPTURE / _STOP_CAPTURE) to the camera, component 100: recording on the vehicle |
//! | `request_control` | `takeover_allowed` (optional bool) | COMMAND_LONG 32100 p1 1, p3 10 s |
//! | `release_control` | — | COMMAND_LONG 32100 p1 0 |
//! | `answer_request` | `accept`: bool | accept: 32100 p1 0 (release to the requester); refuse: COMMAND_ACK 32100 DENIED |
//!
//! # Server → browser ([`ServerMsg`])
//! | type | when | fields |
//! |---|---|---|
//! | `welcome` | on connect | `session`, `sysid` (null: none held yet), `watch_only_reason` (null: may pilot), `password_required` (log in to pilot), `password_set`, `pilot` (may pilot), `logged_in`, `vehicle_sysid`, `camera_rotation_deg`, `version`, `modes` (the modes to offer: `mode`, `name`, `label`, `thrusters`, `button`), `boot_mode` |
//! | `identity` | the session's rights changed (logged in, took a system id) | `sysid`, `pilot`, `logged_in`, `watch_only_reason` |
//! | `telemetry` | as the vehicle sends (one per pass of its loop), at least every 0.5 s | see [`Telemetry`]; among its fields `ages_ms` {`heartbeat`, `attitude`, `depth`, `battery`, `estimate`}: ms since the vehicle last sent that data (null: never), so the page can grey out stale values, `failsafes`: the plain-word reason of every active failsafe (empty: none), and `recording` (null: the camera has not said): the camera's CAMERA_INFORMATION and CAMERA_CAPTURE_STATUS (each session asks for them at start) — `can` (it records), `on`, `time_ms`, `available_mib` |
//! | `statustext` | at once | `severity` (0 emergency .. 7 debug), `text`, `category` (what it is about, chosen where the text is written: `stop`, `control`, `gain`, `ap_depth`, `ap_heading`, `failsafe`, `board_link` — the developer logger's categories — or `general`) |
//! | `ack` | this session's command answered | `command`, `command_name`, `result`, `result_name`, `text` (plain words: "Arm/disarm: refused", "Lights: done") |
//! | `request_pending` | this session's control request was passed to the owner (instead of its `ack`: MAVLink answers a forwarded request with FAILED, which is no failure) | `owner` (sysid asked), `timeout_s` (how long the owner has to answer) |
//! | `control` | on change | `owner` (sysid or null), `you`, `takeover_allowed` |
//! | `control_request` | the owner is asked | `requester`, `timeout_s` |
//! | `login_result` | after `login` | `ok`, `message` |
//! | `error` | a bad message | `message` (what was wrong and the fix); the message was dropped |
//!
//! A session gets only what concerns it: texts and acks the vehicle aims
//! at one station (a refusal, a reply) reach that station's session alone;
//! what every ground station gets on MAVLink (failsafes, arming, handover
//! news) reaches every session.

use serde::{Deserialize, Serialize};

use crate::vehicle::machine::Topic;
use crate::vehicle::mode::Mode;

/// Largest WebSocket message the server reads (bytes).
pub const MAX_MESSAGE_BYTES: usize = 4096;

/// Modes the HMI offers, in the page's order, with the page's label for each.
/// The page gets them in the welcome ([`ModeView`]) and spells no mode number.
pub const HMI_MODES: [(Mode, &str); 5] = [
    (Mode::ManualThrusters, "Manual thrusters"),
    (Mode::Manual, "Manual"),
    (Mode::Stabilize, "Heading hold"),
    (Mode::AltHold, "Depth + heading hold"),
    (Mode::Surface, "SURFACE"),
];

/// A mode the HMI offers, as the welcome tells the page.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct ModeView {
    /// The number to send in `mode` and that telemetry's `mode` reports.
    pub mode: u32,
    /// The vehicle's name for it (telemetry's `mode_name`).
    pub name: &'static str,
    /// What the page shows.
    pub label: &'static str,
    /// The page drives each thruster (`thrusters`) rather than the sticks.
    pub thrusters: bool,
    /// A button of its own (SURFACE: one press from any mode), not a radio button.
    pub button: bool,
}

impl ModeView {
    /// The modes the HMI offers, for the welcome.
    pub fn offered() -> Vec<ModeView> {
        HMI_MODES
            .iter()
            .map(|&(m, label)| ModeView {
                mode: m.number(),
                name: m.name(),
                label,
                thrusters: m == Mode::ManualThrusters,
                button: m == Mode::Surface,
            })
            .collect()
    }
}

/// "100 (MANUAL_THRUSTERS), 19 (MANUAL) … or 9 (SURFACE)", for error messages.
fn offered_modes_text() -> String {
    let each: Vec<String> = HMI_MODES
        .iter()
        .map(|(m, _)| format!("{} ({m})", m.number()))
        .collect();
    match each.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => each.concat(),
    }
}

/// Input devices of the operator interface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InputMode {
    Keyboard,
    Touch,
    Gamepad,
    Headtracking,
}

/// The thesis' run modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RunMode {
    Normal,
    Simulator,
}

/// A message from the browser.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMsg {
    // Empty braces, not unit variants: serde then refuses unknown fields on them too.
    Alive {},
    Login {
        password: String,
    },
    Sticks {
        surge: f64,
        #[serde(default)]
        sway: f64,
        heave_up: f64,
        yaw: f64,
    },
    Thrusters {
        port: f64,
        vertical: f64,
        starboard: f64,
    },
    Stop {},
    FocusLost {},
    InputMode {
        mode: InputMode,
    },
    Arm {
        arm: bool,
    },
    Mode {
        mode: u32,
    },
    RunMode {
        mode: RunMode,
    },
    AutopilotTarget {
        #[serde(default)]
        depth_m: Option<f64>,
        #[serde(default)]
        heading_deg: Option<f64>,
    },
    Gain {
        value: f64,
    },
    Lights {
        level: f64,
    },
    Laser {
        on: bool,
    },
    /// Recording on the vehicle: start (`true`) or stop.
    Record {
        on: bool,
    },
    Tilt {
        deg: f64,
    },
    RequestControl {
        #[serde(default)]
        takeover_allowed: bool,
    },
    ReleaseControl {},
    AnswerRequest {
        accept: bool,
    },
}

fn in_range(name: &str, v: f64, lo: f64, hi: f64) -> Result<(), String> {
    if !v.is_finite() {
        return Err(format!(
            "{name} is not a finite number — send a number in {lo}..{hi}"
        ));
    }
    if v < lo || v > hi {
        return Err(format!(
            "{name} = {v} is out of range — send a number in {lo}..{hi}"
        ));
    }
    Ok(())
}

impl ClientMsg {
    /// Parses one text message; the error says what was wrong and the fix.
    pub fn parse(text: &str) -> Result<Self, String> {
        let msg: Self = serde_json::from_str(text).map_err(|e| {
            let e = e.to_string();
            if e.contains("unknown variant") {
                format!("unknown message type: {e}")
            } else {
                format!("not a valid message: {e}")
            }
        })?;
        msg.validate()?;
        Ok(msg)
    }

    /// Range checks serde cannot express.
    pub fn validate(&self) -> Result<(), String> {
        match self {
            Self::Sticks {
                surge,
                sway,
                heave_up,
                yaw,
            } => {
                in_range("surge", *surge, -1.0, 1.0)?;
                in_range("sway", *sway, -1.0, 1.0)?;
                in_range("heave_up", *heave_up, -1.0, 1.0)?;
                in_range("yaw", *yaw, -1.0, 1.0)
            }
            Self::Thrusters {
                port,
                vertical,
                starboard,
            } => {
                in_range("port", *port, -1.0, 1.0)?;
                in_range("vertical", *vertical, -1.0, 1.0)?;
                in_range("starboard", *starboard, -1.0, 1.0)
            }
            Self::Mode { mode } => {
                if HMI_MODES.iter().any(|(m, _)| m.number() == *mode) {
                    Ok(())
                } else {
                    Err(format!(
                        "mode {mode} is not offered by the HMI — use {}",
                        offered_modes_text()
                    ))
                }
            }
            Self::AutopilotTarget {
                depth_m,
                heading_deg,
            } => {
                if depth_m.is_none() && heading_deg.is_none() {
                    return Err("autopilot_target needs depth_m or heading_deg".into());
                }
                if let Some(d) = depth_m {
                    in_range("depth_m", *d, 0.0, 1000.0)?;
                }
                if let Some(h) = heading_deg {
                    in_range("heading_deg", *h, 0.0, 360.0)?;
                }
                Ok(())
            }
            Self::Gain { value } => in_range("gain", *value, 0.0, 1.0),
            Self::Lights { level } => in_range("lights level", *level, 0.0, 255.0),
            Self::Tilt { deg } => in_range("tilt deg", *deg, -90.0, 90.0),
            Self::Login { password } if password.len() > super::auth::MAX_PASSWORD_BYTES => {
                Err(format!(
                    "password longer than {} bytes",
                    super::auth::MAX_PASSWORD_BYTES
                ))
            }
            _ => Ok(()),
        }
    }
}

/// Who controls the vehicle, as one session sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
pub struct ControlView {
    /// System id of the ground station in control (CONTROL_STATUS gcs_main).
    pub owner: Option<u8>,
    /// This session is in control.
    pub you: bool,
    pub takeover_allowed: bool,
}

/// The three thrusters' pulse widths (SERVO_OUTPUT_RAW).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
pub struct ThrustersUs {
    pub port: u16,
    pub vertical: u16,
    pub starboard: u16,
}

/// Simulated states (NEPTUNUS_SIM_STATE).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct SimView {
    pub north_m: f32,
    pub east_m: f32,
    pub depth_m: f32,
    pub heading_deg: f32,
    pub surge_mps: f32,
    pub sway_mps: f32,
    pub heave_mps: f32,
    pub yaw_rate_dps: f32,
    pub roll_deg: f32,
    pub pitch_deg: f32,
}

/// Estimated states (NEPTUNUS_ESTIMATE).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct EstimateView {
    pub depth_m: f32,
    pub depth_measured_m: f32,
    pub climb_rate_mps: f32,
    pub heading_deg: f32,
    pub heading_measured_deg: f32,
    pub yaw_rate_dps: f32,
    pub depth_valid: bool,
    pub heading_valid: bool,
    pub simulated: bool,
}

/// Autopilot setpoints and outputs (NEPTUNUS_AUTOPILOT); NaN targets are null.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct AutopilotView {
    pub depth_target_m: Option<f32>,
    pub heading_target_deg: Option<f32>,
    pub climb_target_mps: f32,
    pub yaw_rate_target_dps: f32,
    pub heave_output: f32,
    pub yaw_output: f32,
    pub depth_hold: bool,
    pub heading_hold: bool,
    pub surfacing: bool,
}

/// Health bits of SYS_STATUS that the operator needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct HealthView {
    /// Motor outputs healthy: the board link is up.
    pub board_link: bool,
    /// Depth sensor fresh.
    pub depth: bool,
    /// Attitude sensors fresh.
    pub attitude: bool,
    /// RC receiver healthy: no GCS or pilot-input failsafe.
    pub pilot_input: bool,
    pub battery: bool,
    /// Pre-arm checks pass.
    pub prearm: bool,
    /// The board's serial line: frames and lines damaged or lost (both
    /// ways) over the last 10 s, percent (SYS_STATUS `drop_rate_comm`).
    pub board_line_drop_pct: f64,
    /// The same since the vehicle started, a count (`errors_comm`).
    pub board_line_errors: u16,
}

/// How old each kind of data is: milliseconds between the arrival of the
/// message that carried it and the snapshot (null: never received). The
/// vehicle sends attitude and depth only from fresh board readings, so an
/// old age means the data is old, not just the message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
pub struct AgesView {
    /// The vehicle's HEARTBEAT (armed, mode, critical).
    pub heartbeat: Option<u64>,
    /// ATTITUDE: heading, roll, pitch, yaw rate.
    pub attitude: Option<u64>,
    /// VFR_HUD: depth.
    pub depth: Option<u64>,
    /// SYS_STATUS with a battery voltage while the board link was up:
    /// voltage, current, remaining.
    pub battery: Option<u64>,
    /// NEPTUNUS_ESTIMATE.
    pub estimate: Option<u64>,
}

/// The vehicle as a session's browser sees it, pushed as the vehicle sends. Fields the
/// vehicle has not sent (yet) are null.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Telemetry {
    /// Milliseconds since the session started (browser plots' time axis).
    pub t_ms: u64,
    /// A HEARTBEAT from the vehicle arrived within 3 s.
    pub vehicle_seen: bool,
    pub armed: bool,
    pub mode: Option<u32>,
    pub mode_name: Option<String>,
    /// HEARTBEAT MAV_MODE_FLAG_HIL_ENABLED or NEPTUNUS_ESTIMATE's simulated flag.
    pub simulated: bool,
    /// HEARTBEAT system_status is CRITICAL or EMERGENCY (failsafe or link down).
    pub critical: bool,
    /// Measured heading (ATTITUDE yaw), 0..360.
    pub heading_deg: Option<f64>,
    /// Measured depth (VFR_HUD alt, down positive).
    pub depth_m: Option<f64>,
    pub roll_deg: Option<f64>,
    pub pitch_deg: Option<f64>,
    pub yaw_rate_dps: Option<f64>,
    /// Battery values keep their last reading; `ages_ms.battery` says how old it is.
    pub voltage_v: Option<f64>,
    pub current_a: Option<f64>,
    pub battery_pct: Option<i8>,
    pub thrusters_us: Option<ThrustersUs>,
    /// Lights 0..255.
    pub lights: Option<u8>,
    pub laser: Option<bool>,
    /// Camera tilt 0..1 of its travel (0.5 centre).
    pub tilt: Option<f64>,
    pub gain: Option<f64>,
    pub control: ControlView,
    pub health: Option<HealthView>,
    pub sim: Option<SimView>,
    pub estimate: Option<EstimateView>,
    pub autopilot: Option<AutopilotView>,
    /// How old each kind of data is.
    pub ages_ms: AgesView,
    /// Why the vehicle is in failsafe, one plain-word reason per active
    /// failsafe ("battery low 10.2 V"); empty when none is.
    pub failsafes: Vec<String>,
    /// Recording on the vehicle, as its camera last said (None: it has not).
    pub recording: Option<RecordingView>,
}

/// Recording on the vehicle: what its camera said (CAMERA_INFORMATION,
/// CAMERA_CAPTURE_STATUS).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct RecordingView {
    /// The camera can record (CAMERA_CAP_FLAGS_CAPTURE_VIDEO).
    pub can: bool,
    /// A recording runs (or is starting).
    pub on: bool,
    /// How long it has recorded.
    pub time_ms: u32,
    /// What the storage still takes for recordings.
    pub available_mib: f32,
}

/// A message to the browser.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMsg {
    Welcome {
        session: u64,
        sysid: Option<u8>,
        watch_only_reason: Option<String>,
        password_required: bool,
        password_set: bool,
        pilot: bool,
        logged_in: bool,
        vehicle_sysid: u8,
        camera_rotation_deg: i32,
        version: &'static str,
        /// The modes the page offers.
        modes: Vec<ModeView>,
        /// The mode the vehicle starts in (shown until telemetry says otherwise).
        boot_mode: u32,
    },
    Identity {
        sysid: Option<u8>,
        pilot: bool,
        logged_in: bool,
        watch_only_reason: Option<String>,
    },
    Telemetry(Box<Telemetry>),
    Statustext {
        severity: u8,
        text: String,
        /// What it is about, as the vehicle core chose it.
        category: Topic,
    },
    Ack {
        command: u32,
        command_name: String,
        result: u32,
        result_name: String,
        /// What was asked and how it went, in plain words.
        text: String,
    },
    /// This session's control request waits for the owner's answer.
    RequestPending {
        /// System id of the station in control, which was asked.
        owner: u8,
        /// How long it has to answer.
        timeout_s: f32,
    },
    Control(ControlView),
    ControlRequest {
        requester: u8,
        timeout_s: f32,
    },
    LoginResult {
        ok: bool,
        message: String,
    },
    Error {
        message: String,
    },
}

impl ServerMsg {
    pub fn to_json(&self) -> String {
        // Serialising these plain types cannot fail; a placeholder keeps the
        // session alive if it ever did.
        serde_json::to_string(self)
            .unwrap_or_else(|_| r#"{"type":"error","message":"internal"}"#.to_owned())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_mode_not_offered_names_the_offered_ones() {
        assert_eq!(
            ClientMsg::parse(r#"{"type":"mode","mode":3}"#),
            Err("mode 3 is not offered by the HMI — use 100 (MANUAL_THRUSTERS), 19 (MANUAL), 0 (STABILIZE), 2 (ALT_HOLD) or 9 (SURFACE)".to_owned())
        );
        for m in ModeView::offered() {
            let msg = format!(r#"{{"type":"mode","mode":{}}}"#, m.mode);
            assert_eq!(ClientMsg::parse(&msg), Ok(ClientMsg::Mode { mode: m.mode }));
        }
    }

    #[test]
    fn the_welcome_offers_the_pages_modes() {
        let modes = serde_json::to_value(ModeView::offered()).unwrap();
        assert_eq!(
            modes,
            serde_json::json!([
                {"mode": 100, "name": "MANUAL_THRUSTERS", "label": "Manual thrusters", "thrusters": true, "button": false},
                {"mode": 19, "name": "MANUAL", "label": "Manual", "thrusters": false, "button": false},
                {"mode": 0, "name": "STABILIZE", "label": "Heading hold", "thrusters": false, "button": false},
                {"mode": 2, "name": "ALT_HOLD", "label": "Depth + heading hold", "thrusters": false, "button": false},
                {"mode": 9, "name": "SURFACE", "label": "SURFACE", "thrusters": false, "button": true},
            ])
        );
    }

    #[test]
    fn parses_and_validates() {
        assert_eq!(
            ClientMsg::parse(r#"{"type":"sticks","surge":0.5,"heave_up":0,"yaw":-1}"#),
            Ok(ClientMsg::Sticks {
                surge: 0.5,
                sway: 0.0,
                heave_up: 0.0,
                yaw: -1.0
            })
        );
        assert!(
            ClientMsg::parse(r#"{"type":"sticks","surge":1.5,"heave_up":0,"yaw":0}"#)
                .unwrap_err()
                .contains("out of range")
        );
        assert!(
            ClientMsg::parse(r#"{"type":"warp"}"#)
                .unwrap_err()
                .contains("unknown message type")
        );
        assert!(ClientMsg::parse(r#"{"type":"sticks","surge":NaN}"#).is_err());
        assert!(ClientMsg::parse("not json").is_err());
        assert!(ClientMsg::parse(r#"{"type":"mode","mode":3}"#).is_err());
        assert!(ClientMsg::parse(r#"{"type":"autopilot_target"}"#).is_err());
        assert!(ClientMsg::parse(r#"{"type":"autopilot_target","depth_m":2.5}"#).is_ok());
        assert!(ClientMsg::parse(r#"{"type":"stop","extra":1}"#).is_err());
        assert_eq!(
            ClientMsg::parse(r#"{"type":"alive"}"#),
            Ok(ClientMsg::Alive {})
        );
        assert_eq!(
            ClientMsg::parse(r#"{"type":"stop"}"#),
            Ok(ClientMsg::Stop {})
        );
        assert!(ClientMsg::parse(r#"{"type":"input_mode","mode":"gamepad"}"#).is_ok());
    }

    #[test]
    fn server_messages_are_tagged() {
        let j = ServerMsg::Statustext {
            severity: 6,
            text: "hi".into(),
            category: Topic::BoardLink,
        }
        .to_json();
        assert_eq!(
            j,
            r#"{"type":"statustext","severity":6,"text":"hi","category":"board_link"}"#
        );
        let t = ServerMsg::Telemetry(Box::default()).to_json();
        assert!(t.starts_with(r#"{"type":"telemetry","t_ms":0"#), "{t}");
        assert!(
            t.ends_with(
                r#""ages_ms":{"heartbeat":null,"attitude":null,"depth":null,"battery":null,"estimate":null},"failsafes":[],"recording":null}"#
            ),
            "{t}"
        );
        let a = ServerMsg::Ack {
            command: 400,
            command_name: "COMPONENT_ARM_DISARM".into(),
            result: 0,
            result_name: "ACCEPTED".into(),
            text: "Arm/disarm: done".into(),
        }
        .to_json();
        assert_eq!(
            a,
            r#"{"type":"ack","command":400,"command_name":"COMPONENT_ARM_DISARM","result":0,"result_name":"ACCEPTED","text":"Arm/disarm: done"}"#
        );
        let p = ServerMsg::RequestPending {
            owner: 200,
            timeout_s: 10.0,
        }
        .to_json();
        assert_eq!(
            p,
            r#"{"type":"request_pending","owner":200,"timeout_s":10.0}"#
        );
    }
}
