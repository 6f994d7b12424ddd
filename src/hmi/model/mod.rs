//! A session's view of the vehicle, built only from the MAVLink messages the
//! vehicle sent to it (as any ground station builds its view).
//!
//! Owns the translation of telemetry into [`Telemetry`] (with how old each
//! kind of data is, and why the vehicle is in failsafe: `failsafes`) and of
//! event-like messages (STATUSTEXT, COMMAND_ACK in plain words: `acks`,
//! CONTROL_STATUS changes, forwarded control requests) into [`ServerMsg`]s.
//! It must never send anything: it only reads.

mod acks;
mod failsafes;

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use super::Delivery;
use super::protocol::{
    AgesView, AutopilotView, ControlView, EstimateView, HealthView, RecordingView, ServerMsg,
    SimView, Telemetry, ThrustersUs,
};
use crate::dialect::neptunus::*;
use crate::vehicle::machine::Topic;
use crate::vehicle::mode::Mode;

/// No vehicle HEARTBEAT for this long: the vehicle is "not seen".
const VEHICLE_SEEN: Duration = Duration::from_secs(3);
/// Control asks remembered until their acks come back (a session sends
/// them one click at a time; more are a page gone wrong).
const MAX_ASKS: usize = 8;

/// What a session asked with MAV_CMD_REQUEST_OPERATOR_CONTROL: the ack
/// alone does not say whether it answers a request or a release.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum ControlAsk {
    /// p1 1, waiting up to `timeout_s` for the owner's answer.
    Request { timeout_s: f32 },
    /// p1 0: letting go (the owner's yes to a request, too).
    Release,
}

/// When each kind of data last arrived.
#[derive(Debug, Clone, Copy, Default)]
struct Arrivals {
    heartbeat: Option<Instant>,
    attitude: Option<Instant>,
    depth: Option<Instant>,
    battery: Option<Instant>,
    estimate: Option<Instant>,
}

impl Arrivals {
    fn ages(&self, now: Instant) -> AgesView {
        let age = |t: Option<Instant>| {
            t.map(|t| {
                now.saturating_duration_since(t)
                    .as_millis()
                    .min(u128::from(u64::MAX)) as u64
            })
        };
        AgesView {
            heartbeat: age(self.heartbeat),
            attitude: age(self.attitude),
            depth: age(self.depth),
            battery: age(self.battery),
            estimate: age(self.estimate),
        }
    }
}

/// What one session knows about the vehicle.
#[derive(Debug)]
pub struct Model {
    started: Instant,
    arrivals: Arrivals,
    hil: bool,
    tel: Telemetry,
    /// The last SYS_STATUS health bits (failsafe reasons).
    health: Option<MavSysStatusSensor>,
    /// Failsafe texts seen raised and not cleared.
    failsafe_texts: failsafes::FailsafeTexts,
    /// This session's control requests and releases awaiting their acks.
    asks: VecDeque<ControlAsk>,
    /// This session's system id (None: watch only).
    me: Option<u8>,
    /// A long STATUSTEXT being put together from its chunks.
    statustext: Option<Pending>,
    /// What the text being delivered is about (see [`Model::on_delivery`]).
    topic: Topic,
}

/// A long text arriving in chunks.
#[derive(Debug)]
struct Pending {
    id: u16,
    text: String,
    severity: u8,
    topic: Topic,
}

fn deg(rad: f32) -> f64 {
    f64::from(rad).to_degrees()
}

fn nan_none(v: f32) -> Option<f32> {
    (!v.is_nan()).then_some(v)
}

fn text_of(t: &[u8]) -> String {
    let end = t.iter().position(|&b| b == 0).unwrap_or(t.len());
    String::from_utf8_lossy(&t[..end]).into_owned()
}

impl Model {
    pub fn new(me: Option<u8>, started: Instant) -> Self {
        Self {
            started,
            arrivals: Arrivals::default(),
            hil: false,
            tel: Telemetry::default(),
            health: None,
            failsafe_texts: failsafes::FailsafeTexts::default(),
            asks: VecDeque::new(),
            me,
            statustext: None,
            topic: Topic::General,
        }
    }

    /// This session's system id (it may lease one after it started).
    pub fn set_me(&mut self, me: Option<u8>) {
        self.me = me;
    }

    pub fn control(&self) -> ControlView {
        self.tel.control
    }

    /// Whether this session is in control.
    pub fn in_control(&self) -> bool {
        self.tel.control.you
    }

    /// This session sent MAV_CMD_REQUEST_OPERATOR_CONTROL: its ack will
    /// say how that went.
    pub(crate) fn asked_control(&mut self, ask: ControlAsk) {
        if self.asks.len() >= MAX_ASKS {
            self.asks.pop_front();
        }
        self.asks.push_back(ask);
    }

    /// The telemetry as of `now`.
    pub fn snapshot(&self, now: Instant) -> Telemetry {
        let mut t = self.tel.clone();
        t.t_ms = now.saturating_duration_since(self.started).as_millis() as u64;
        t.vehicle_seen = self
            .arrivals
            .heartbeat
            .is_some_and(|h| now.saturating_duration_since(h) <= VEHICLE_SEEN);
        t.ages_ms = self.arrivals.ages(now);
        t.failsafes = self.failsafe_texts.reasons(t.critical, self.health);
        t
    }

    /// Takes in one delivery from the vehicle (a message, and for a text
    /// what it is about); events for the browser go to `events`.
    pub fn on_delivery(&mut self, d: &Delivery, now: Instant, events: &mut Vec<ServerMsg>) {
        self.topic = d.topic.unwrap_or(Topic::General);
        self.on_message(&d.msg, now, events);
        self.topic = Topic::General;
    }

    /// Takes in one message from the vehicle; events for the browser go to `events`.
    pub fn on_message(&mut self, msg: &MavMessage, now: Instant, events: &mut Vec<ServerMsg>) {
        let t = &mut self.tel;
        match msg {
            MavMessage::HEARTBEAT(h) => {
                self.arrivals.heartbeat = Some(now);
                t.armed = h
                    .base_mode
                    .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
                self.hil = h.base_mode.contains(MavModeFlag::MAV_MODE_FLAG_HIL_ENABLED);
                t.simulated = self.hil || t.estimate.is_some_and(|e| e.simulated);
                t.mode = Some(h.custom_mode);
                t.mode_name = Some(Mode::name_of(h.custom_mode).to_owned());
                t.critical = matches!(
                    h.system_status,
                    MavState::MAV_STATE_CRITICAL | MavState::MAV_STATE_EMERGENCY
                );
                if !t.critical {
                    // The core is critical while any failsafe is active.
                    self.failsafe_texts.clear();
                }
            }
            MavMessage::ATTITUDE(a) => {
                self.arrivals.attitude = Some(now);
                t.heading_deg = Some(deg(a.yaw).rem_euclid(360.0));
                t.roll_deg = Some(deg(a.roll));
                t.pitch_deg = Some(deg(a.pitch));
                t.yaw_rate_dps = Some(deg(a.yawspeed));
            }
            MavMessage::VFR_HUD(v) => {
                self.arrivals.depth = Some(now);
                t.depth_m = Some(-f64::from(v.alt));
            }
            MavMessage::SYS_STATUS(s) => {
                use MavSysStatusSensor as S;
                let h = s.onboard_control_sensors_health;
                self.health = Some(h);
                t.health = Some(HealthView {
                    board_link: h.contains(S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS),
                    depth: h.contains(S::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE),
                    attitude: h.contains(S::MAV_SYS_STATUS_SENSOR_3D_GYRO),
                    pilot_input: h.contains(S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER),
                    battery: h.contains(S::MAV_SYS_STATUS_SENSOR_BATTERY),
                    prearm: h.contains(S::MAV_SYS_STATUS_PREARM_CHECK),
                    board_line_drop_pct: f64::from(s.drop_rate_comm) / 100.0,
                    board_line_errors: s.errors_comm,
                });
                // A value the message lacks keeps its last reading (its age
                // says how old). The core repeats the last voltage while the
                // board is silent, so only a voltage over a live board link
                // counts as a new reading.
                if s.voltage_battery != u16::MAX {
                    t.voltage_v = Some(f64::from(s.voltage_battery) / 1000.0);
                    if h.contains(S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS) {
                        self.arrivals.battery = Some(now);
                    }
                }
                if s.current_battery >= 0 {
                    t.current_a = Some(f64::from(s.current_battery) / 100.0);
                }
                if s.battery_remaining >= 0 {
                    t.battery_pct = Some(s.battery_remaining);
                }
            }
            MavMessage::SERVO_OUTPUT_RAW(s) => {
                t.thrusters_us = Some(ThrustersUs {
                    starboard: s.servo1_raw,
                    port: s.servo2_raw,
                    vertical: s.servo3_raw,
                });
                t.laser = Some(s.servo6_raw > 1500);
            }
            MavMessage::NAMED_VALUE_FLOAT(n) => {
                let v = f64::from(n.value);
                match text_of(n.name.as_ref()).as_str() {
                    "Lights1" => t.lights = Some((v * 255.0).round().clamp(0.0, 255.0) as u8),
                    "PilotGain" => t.gain = Some(v),
                    "CamTilt" => t.tilt = Some(v),
                    "Laser" => t.laser = Some(v > 0.0),
                    _ => {}
                }
            }
            MavMessage::NEPTUNUS_SIM_STATE(s) => {
                t.sim = Some(SimView {
                    north_m: s.x,
                    east_m: s.y,
                    depth_m: s.z,
                    heading_deg: s.psi.to_degrees().rem_euclid(360.0),
                    surge_mps: s.u,
                    sway_mps: s.v,
                    heave_mps: s.w,
                    yaw_rate_dps: s.r.to_degrees(),
                    roll_deg: s.phi.to_degrees(),
                    pitch_deg: s.theta.to_degrees(),
                });
            }
            MavMessage::NEPTUNUS_ESTIMATE(e) => {
                self.arrivals.estimate = Some(now);
                use NeptunusEstimateFlags as F;
                let simulated = e.flags.contains(F::NEPTUNUS_ESTIMATE_FLAGS_SIMULATED);
                t.estimate = Some(EstimateView {
                    depth_m: e.depth,
                    depth_measured_m: e.depth_measured,
                    climb_rate_mps: e.climb_rate,
                    heading_deg: e.heading,
                    heading_measured_deg: e.heading_measured,
                    yaw_rate_dps: e.yaw_rate,
                    depth_valid: e.flags.contains(F::NEPTUNUS_ESTIMATE_FLAGS_DEPTH_VALID),
                    heading_valid: e.flags.contains(F::NEPTUNUS_ESTIMATE_FLAGS_HEADING_VALID),
                    simulated,
                });
                t.simulated = self.hil || simulated;
            }
            MavMessage::NEPTUNUS_AUTOPILOT(a) => {
                use NeptunusAutopilotFlags as F;
                t.autopilot = Some(AutopilotView {
                    depth_target_m: nan_none(a.depth_target),
                    heading_target_deg: nan_none(a.heading_target),
                    climb_target_mps: a.climb_target,
                    yaw_rate_target_dps: a.yaw_rate_target,
                    heave_output: a.heave_output,
                    yaw_output: a.yaw_output,
                    depth_hold: a.flags.contains(F::NEPTUNUS_AUTOPILOT_FLAGS_DEPTH_HOLD),
                    heading_hold: a.flags.contains(F::NEPTUNUS_AUTOPILOT_FLAGS_HEADING_HOLD),
                    surfacing: a.flags.contains(F::NEPTUNUS_AUTOPILOT_FLAGS_SURFACING),
                });
            }
            MavMessage::CONTROL_STATUS(c) => {
                let view = ControlView {
                    owner: (c.gcs_main != 0).then_some(c.gcs_main),
                    you: self.me.is_some_and(|me| me == c.gcs_main),
                    takeover_allowed: c
                        .flags
                        .contains(GcsControlStatusFlags::GCS_CONTROL_STATUS_FLAGS_TAKEOVER_ALLOWED),
                };
                if view != t.control {
                    t.control = view;
                    events.push(ServerMsg::Control(view));
                }
            }
            MavMessage::CAMERA_INFORMATION(c) => {
                let r = t.recording.get_or_insert_with(RecordingView::default);
                r.can = c
                    .flags
                    .contains(CameraCapFlags::CAMERA_CAP_FLAGS_CAPTURE_VIDEO);
            }
            MavMessage::CAMERA_CAPTURE_STATUS(c) => {
                let r = t.recording.get_or_insert_with(RecordingView::default);
                r.on = c.video_status == 1;
                r.time_ms = c.recording_time_ms;
                r.available_mib = c.available_capacity;
            }
            MavMessage::STATUSTEXT(s) => self.on_statustext(s, events),
            // Our own telemetry-rate and message requests are plumbing, not news.
            MavMessage::COMMAND_ACK(a)
                if !matches!(
                    a.command,
                    MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL | MavCmd::MAV_CMD_REQUEST_MESSAGE
                ) && self
                    .me
                    .is_none_or(|me| a.target_system == me || a.target_system == 0) =>
            {
                events.push(self.on_ack(a));
            }
            MavMessage::COMMAND_LONG(c)
                if c.command == MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL
                    && self.me.is_some_and(|me| me == c.target_system)
                    && c.param1 >= 0.5 =>
            {
                events.push(ServerMsg::ControlRequest {
                    requester: c.param4.clamp(0.0, 255.0) as u8,
                    timeout_s: c.param3,
                });
            }
            _ => {}
        }
    }

    /// A whole text: to the browser, and into the failsafe reasons.
    fn text_done(&mut self, p: Pending, events: &mut Vec<ServerMsg>) {
        if let Topic::FailsafeChange(kind, raised) = p.topic {
            self.failsafe_texts.on_change(kind, raised, &p.text);
        }
        events.push(ServerMsg::Statustext {
            severity: p.severity,
            text: p.text,
            category: p.topic,
        });
    }

    /// STATUSTEXT, with MAVLink 2 chunks (same id) joined.
    fn on_statustext(&mut self, s: &STATUSTEXT_DATA, events: &mut Vec<ServerMsg>) {
        let bytes: &[u8] = s.text.as_ref();
        let chunk = text_of(bytes);
        let severity = s.severity as u8;
        let topic = self.topic;
        let full = !bytes.contains(&0);
        if s.id == 0 {
            let p = Pending {
                id: 0,
                text: chunk,
                severity,
                topic,
            };
            self.text_done(p, events);
            return;
        }
        let text = match self.statustext.take() {
            Some(mut p) if p.id == s.id => {
                p.text.push_str(&chunk);
                p.text
            }
            Some(other) => {
                self.text_done(other, events);
                chunk
            }
            None => chunk,
        };
        let p = Pending {
            id: s.id,
            text,
            severity,
            topic,
        };
        if full {
            self.statustext = Some(p);
        } else {
            self.text_done(p, events);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_status_and_chunks() {
        let now = Instant::now();
        let mut m = Model::new(Some(200), now);
        let mut ev = Vec::new();
        m.on_message(
            &MavMessage::CONTROL_STATUS(CONTROL_STATUS_DATA {
                flags: GcsControlStatusFlags::GCS_CONTROL_STATUS_FLAGS_SYSTEM_MANAGER,
                gcs_main: 200,
                gcs_secondary: [0; 10],
            }),
            now,
            &mut ev,
        );
        assert!(m.in_control());
        assert_eq!(ev.len(), 1);
        ev.clear();
        let long = "x".repeat(60);
        let mut first = [0u8; 50];
        first.copy_from_slice(&long.as_bytes()[..50]);
        let mut second = [0u8; 50];
        second[..10].copy_from_slice(&long.as_bytes()[50..]);
        for (i, arr) in [first, second].into_iter().enumerate() {
            m.on_message(
                &MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                    severity: MavSeverity::MAV_SEVERITY_INFO,
                    text: arr.into(),
                    id: 7,
                    chunk_seq: i as u8,
                }),
                now,
                &mut ev,
            );
        }
        assert_eq!(
            ev,
            vec![ServerMsg::Statustext {
                severity: 6,
                text: long,
                category: Topic::General,
            }]
        );
    }

    pub(super) fn heartbeat(status: MavState) -> MavMessage {
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: Mode::Manual.number(),
            mavtype: MavType::MAV_TYPE_SUBMARINE,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: status,
            mavlink_version: 3,
        })
    }

    pub(super) fn sys_status(health: MavSysStatusSensor, voltage_mv: u16) -> MavMessage {
        MavMessage::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_health: health,
            voltage_battery: voltage_mv,
            current_battery: 150,
            battery_remaining: 40,
            ..Default::default()
        })
    }

    pub(super) fn text(m: &mut Model, topic: Topic, words: &str, now: Instant) -> Vec<ServerMsg> {
        let mut ev = Vec::new();
        m.on_delivery(
            &Delivery {
                peer: None,
                compid: crate::vehicle::machine::COMPONENT_ID,
                msg: MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                    severity: MavSeverity::MAV_SEVERITY_CRITICAL,
                    text: words.into(),
                    id: 0,
                    chunk_seq: 0,
                }),
                topic: Some(topic),
            },
            now,
            &mut ev,
        );
        ev
    }

    #[test]
    fn ages_say_how_old_each_kind_of_data_is_and_values_stay() {
        let t0 = Instant::now();
        let mut m = Model::new(None, t0);
        let ms = Duration::from_millis;
        assert_eq!(m.snapshot(t0).ages_ms, AgesView::default());
        let mut ev = Vec::new();
        m.on_message(&heartbeat(MavState::MAV_STATE_STANDBY), t0, &mut ev);
        m.on_message(
            &MavMessage::ATTITUDE(ATTITUDE_DATA {
                yaw: 1.0,
                ..Default::default()
            }),
            t0 + ms(100),
            &mut ev,
        );
        m.on_message(
            &MavMessage::VFR_HUD(VFR_HUD_DATA {
                alt: -2.5,
                ..Default::default()
            }),
            t0 + ms(200),
            &mut ev,
        );
        let link_up = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS;
        m.on_message(&sys_status(link_up, 12_100), t0 + ms(300), &mut ev);
        m.on_message(
            &MavMessage::NEPTUNUS_ESTIMATE(NEPTUNUS_ESTIMATE_DATA::default()),
            t0 + ms(400),
            &mut ev,
        );
        let t = m.snapshot(t0 + ms(1000));
        assert_eq!(
            t.ages_ms,
            AgesView {
                heartbeat: Some(1000),
                attitude: Some(900),
                depth: Some(800),
                battery: Some(700),
                estimate: Some(600),
            }
        );
        // The board link went down: the core repeats its last voltage, which
        // is no new reading; a SYS_STATUS without values keeps the old ones.
        m.on_message(
            &sys_status(MavSysStatusSensor::empty(), 12_100),
            t0 + ms(1500),
            &mut ev,
        );
        m.on_message(
            &MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                voltage_battery: u16::MAX,
                current_battery: -1,
                battery_remaining: -1,
                ..Default::default()
            }),
            t0 + ms(1600),
            &mut ev,
        );
        let t = m.snapshot(t0 + ms(5000));
        assert_eq!(t.ages_ms.battery, Some(4700));
        assert_eq!(t.ages_ms.attitude, Some(4900));
        assert!(!t.vehicle_seen);
        assert_eq!(t.voltage_v, Some(12.1));
        assert_eq!(t.current_a, Some(1.5));
        assert_eq!(t.battery_pct, Some(40));
        assert_eq!(t.depth_m, Some(2.5));
        assert!(t.heading_deg.is_some());
        let json = ServerMsg::Telemetry(Box::new(t)).to_json();
        assert!(
            json.contains(r#""ages_ms":{"heartbeat":5000,"attitude":4900,"depth":4800,"battery":4700,"estimate":4600}"#),
            "{json}"
        );
    }
}
