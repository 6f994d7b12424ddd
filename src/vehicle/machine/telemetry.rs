//! Outgoing telemetry: the streams each endpoint asked for (REQUEST_DATA_STREAM,
//! SET/GET_MESSAGE_INTERVAL), and what each message says now — built only
//! from fresh readings, so a ground station never shows stale data as live.

use std::time::Duration;

use mavlink_core::MessageData;

use super::texts::ReplyKind;
use super::{
    Identity, NEUTRAL_US, Now, Output, RunMode, Sender, To, Vehicle, chars, failsafe, given,
};
use crate::dialect::neptunus::*;
use crate::firmware::link::LinkState;
use crate::vehicle::telemetry::{self as schedule, Schedule};

/// Every endpoint's schedule, and the parameter lists being streamed.
#[derive(Debug)]
pub(super) struct Streams {
    schedules: Vec<Schedule>,
    /// Per schedule: nobody listens there now (an in-process endpoint with
    /// no browser session, mavlink2rest client or recent REST reader), so
    /// its streams are not built. Its schedule stands still meanwhile, so
    /// when someone comes every stream message is due at once.
    quiet: Vec<bool>,
    /// (to whom, parameter index) still to send.
    pub param_queue: Vec<(To, usize)>,
}

impl Streams {
    pub fn new(endpoints: usize) -> Self {
        Self {
            schedules: vec![Schedule::default(); endpoints.max(1)],
            quiet: vec![false; endpoints.max(1)],
            param_queue: Vec::new(),
        }
    }

    /// ArduSub's default rates from `now` on.
    pub fn start(&mut self, now: Duration) {
        for s in &mut self.schedules {
            *s = Schedule::with_defaults(now);
        }
    }

    /// When a message is next due on any endpoint someone listens on,
    /// without new input.
    pub fn next_deadline(&self) -> Option<Duration> {
        self.schedules
            .iter()
            .zip(&self.quiet)
            .filter(|(_, quiet)| !**quiet)
            .filter_map(|(s, _)| s.next_deadline())
            .min()
    }

    /// Whether anyone listens on `endpoint` (see [`Input::Listeners`](super::Input::Listeners)).
    pub fn set_listened(&mut self, endpoint: usize, listened: bool) {
        let last = self.quiet.len() - 1;
        self.quiet[endpoint.min(last)] = !listened;
    }

    /// The schedule of an endpoint (endpoint ids beyond the table share the last one).
    fn schedule_mut(&mut self, endpoint: usize) -> &mut Schedule {
        let last = self.schedules.len() - 1;
        &mut self.schedules[endpoint.min(last)]
    }
}

impl Vehicle {
    /// The messages due now, to each endpoint.
    pub(super) fn stream_tick(&mut self, now: Now, out: &mut Vec<Output>) {
        self.stream_send(now, out, Schedule::due);
    }

    /// A navigation line has just updated the readings: the messages made
    /// from it go out now where their interval allows.
    pub(super) fn stream_nav_line(&mut self, now: Now, out: &mut Vec<Output>) {
        self.stream_send(now, out, Schedule::line_arrived);
    }

    /// Builds and sends, endpoint by endpoint, what `pick` says is due.
    fn stream_send(
        &mut self,
        now: Now,
        out: &mut Vec<Output>,
        pick: fn(&mut Schedule, Duration, &mut Vec<u32>),
    ) {
        let mut due = Vec::new();
        for ep in 0..self.streams.schedules.len() {
            if self.streams.quiet[ep] {
                continue;
            }
            due.clear();
            pick(&mut self.streams.schedules[ep], now.mono, &mut due);
            for id in &due {
                for msg in self.build(*id, now) {
                    out.push(Output::Send {
                        to: To::Endpoint(ep),
                        msg,
                    });
                }
            }
        }
    }

    /// REQUEST_DATA_STREAM: ArduPilot's stream groups at one rate. Only
    /// from a station that may control: the schedule is shared by every
    /// station on the endpoint.
    pub(super) fn request_data_stream(
        &mut self,
        from: Sender,
        r: &REQUEST_DATA_STREAM_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if !self.may_control(from) {
            // No ack exists for this message: ignored, counted, and
            // the asker told (rate-limited) why its rates stay.
            self.refuse_rates(from, now, out);
            return;
        }
        let id = r.req_stream_id as u8;
        let groups: Vec<u8> = if id == 0 {
            schedule::ALL_GROUPS.to_vec()
        } else {
            vec![id]
        };
        let interval = (r.start_stop != 0 && r.req_message_rate > 0)
            .then(|| Duration::from_secs_f64(1.0 / f64::from(r.req_message_rate)));
        for g in groups {
            for msg_id in schedule::stream_group(g) {
                self.streams
                    .schedule_mut(from.endpoint)
                    .set(*msg_id, interval, now.mono);
            }
        }
    }

    /// MAV_CMD_SET_MESSAGE_INTERVAL (p1 message id, p2 interval µs: 0
    /// default, -1 off).
    pub(super) fn set_message_interval(
        &mut self,
        from: Sender,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        let id = given(p[0]).map_or(u32::MAX, |v| v as u32);
        let interval_us = given(p[1]).unwrap_or(0.0);
        if !schedule::is_streamable(id) && !schedule::nothing_to_send(id) {
            MavResult::MAV_RESULT_UNSUPPORTED
        } else if !self.may_control(from) {
            // The schedule is shared by every station on the endpoint.
            self.refuse_rates(from, now, out);
            MavResult::MAV_RESULT_DENIED
        } else if !schedule::is_streamable(id) {
            // ArduSub's answer for a message it has no sensor for.
            MavResult::MAV_RESULT_ACCEPTED
        } else if interval_us < 0.0 && !schedule::may_disable(id) {
            self.reply_text(
                from,
                ReplyKind::Rates,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!(
                    "Message {id} cannot be turned off: ground stations detect link loss by it"
                ),
                now,
                out,
            );
            MavResult::MAV_RESULT_DENIED
        } else {
            let iv = if interval_us < 0.0 {
                None
            } else if interval_us == 0.0 {
                schedule::default_interval(id)
            } else {
                Some(Duration::from_micros(interval_us as u64))
            };
            self.streams
                .schedule_mut(from.endpoint)
                .set(id, iv, now.mono);
            MavResult::MAV_RESULT_ACCEPTED
        }
    }

    /// MAV_CMD_GET_MESSAGE_INTERVAL: MESSAGE_INTERVAL for this endpoint
    /// (0 µs, "not available", for one we have nothing to send for), or
    /// None for a message we do not know.
    pub(super) fn message_interval(&mut self, from: Sender, p: [f32; 7]) -> Option<MavMessage> {
        let id = given(p[0]).map_or(u32::MAX, |v| v as u32);
        if schedule::nothing_to_send(id) {
            return Some(MavMessage::MESSAGE_INTERVAL(MESSAGE_INTERVAL_DATA {
                interval_us: 0,
                message_id: id as u16,
            }));
        }
        if !schedule::is_streamable(id) {
            return None;
        }
        let iv = self.streams.schedule_mut(from.endpoint).interval(id);
        Some(MavMessage::MESSAGE_INTERVAL(MESSAGE_INTERVAL_DATA {
            interval_us: iv.map_or(-1, |d| d.as_micros().min(i32::MAX as u128) as i32),
            message_id: id as u16,
        }))
    }

    fn sensors(&self, now: Now) -> (MavSysStatusSensor, MavSysStatusSensor, MavSysStatusSensor) {
        use MavSysStatusSensor as S;
        let imu = S::MAV_SYS_STATUS_SENSOR_3D_GYRO
            | S::MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | S::MAV_SYS_STATUS_SENSOR_3D_MAG;
        let depth = S::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE;
        let motors = S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS;
        let battery = S::MAV_SYS_STATUS_SENSOR_BATTERY;
        let rc = S::MAV_SYS_STATUS_SENSOR_RC_RECEIVER;
        let prearm = S::MAV_SYS_STATUS_PREARM_CHECK;
        // Storage (parameters, logs): unhealthy while the data directory is
        // unusable or parameters fail to save.
        let logging = S::MAV_SYS_STATUS_LOGGING;
        let present = imu | depth | motors | battery | rc | prearm | logging;
        let enabled = present;
        // GEOFENCE is healthy though absent, as ArduPilot reports it: MAVProxy's
        // fence module announces "fence breach" when this bit is clear.
        let mut health = S::MAV_SYS_STATUS_GEOFENCE;
        if self.fresh(&self.board.heading_deg, now) {
            health |= imu;
        }
        if self.fresh(&self.board.depth_m, now) {
            health |= depth;
        }
        if self.board.link == LinkState::Up {
            health |= motors;
        }
        if self.board.link == LinkState::Up
            && !self.failsafes.active[failsafe::GCS]
            && !self.failsafes.active[failsafe::PILOT]
        {
            health |= rc;
        }
        if self.battery_ok(now) {
            health |= battery;
        }
        if self.prearm_failure(now).is_none() {
            health |= prearm;
        }
        if self.storage_healthy() {
            health |= logging;
        }
        (present, enabled, health)
    }

    /// The supply voltage if it is current (a board that stopped reporting
    /// it has an unknown voltage, not its last one).
    fn fresh_vout(&self, now: Now) -> Option<f64> {
        self.fresh(&self.board.vout_v, now)
            .then_some(self.board.vout_v.value)
    }

    /// The battery current in cA if it is current, else MAVLink's unknown (−1).
    fn fresh_current_ca(&self, now: Now) -> i16 {
        if self.fresh(&self.board.current_a, now) {
            (self.board.current_a.value * 100.0)
                .round()
                .clamp(0.0, 32767.0) as i16
        } else {
            -1
        }
    }

    fn battery_remaining(&self, now: Now) -> i8 {
        let Some(v) = self.fresh_vout(now) else {
            return -1;
        };
        let empty = f64::from(self.params.batt_low_volt());
        let full = 12.6_f64.max(empty + 0.1);
        // A voltage-based estimate: the board has no coulomb counter.
        (((v - empty) / (full - empty)) * 100.0).clamp(0.0, 100.0) as i8
    }

    fn heartbeat(&self) -> MavMessage {
        use MavModeFlag as F;
        let mut base = F::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | F::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
            | F::MAV_MODE_FLAG_STABILIZE_ENABLED;
        if self.armed {
            base |= F::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        if self.run_mode == RunMode::Simulator {
            // Telemetry is simulated: MAVLink's flag for hardware in the loop.
            base |= F::MAV_MODE_FLAG_HIL_ENABLED;
        }
        let system_status = if self.board.link != LinkState::Up || self.failsafe_active() {
            MavState::MAV_STATE_CRITICAL
        } else if self.armed {
            MavState::MAV_STATE_ACTIVE
        } else {
            MavState::MAV_STATE_STANDBY
        };
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: self.mode.number(),
            mavtype: MavType::MAV_TYPE_SUBMARINE,
            autopilot: match self.identity {
                Identity::Ardupilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                Identity::Generic => MavAutopilot::MAV_AUTOPILOT_GENERIC,
            },
            base_mode: base,
            system_status,
            mavlink_version: 3,
        })
    }

    /// The message(s) for `id` now; empty when there is nothing honest to send.
    pub fn build(&self, id: u32, now: Now) -> Vec<MavMessage> {
        let boot_ms = self.boot_ms(now);
        // Estimates where the filters have started, raw readings before.
        let e = self.holds.est.estimate(now.mono);
        let (heading, yaw_rate_rps) = if self.holds.est.heading_filter().initialised() {
            (e.heading_deg, e.yaw_rate_dps.to_radians())
        } else {
            (self.board.heading_deg.value, self.board.yaw_rate_rps)
        };
        let (depth, heave_mps) = if self.holds.est.depth_filter().initialised() {
            (e.depth_m, e.heave_mps)
        } else {
            (self.board.depth_m.value, 0.0)
        };
        match id {
            HEARTBEAT_DATA::ID => vec![self.heartbeat()],
            SYS_STATUS_DATA::ID => vec![self.sys_status(now)],
            SYSTEM_TIME_DATA::ID => vec![MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
                time_unix_usec: now.unix_us,
                time_boot_ms: boot_ms,
            })],
            ATTITUDE_DATA::ID if self.fresh(&self.board.heading_deg, now) => {
                let yaw = (heading + 180.0).rem_euclid(360.0) - 180.0;
                vec![MavMessage::ATTITUDE(ATTITUDE_DATA {
                    time_boot_ms: boot_ms,
                    roll: self.board.roll_deg.value.to_radians() as f32,
                    pitch: self.board.pitch_deg.value.to_radians() as f32,
                    yaw: yaw.to_radians() as f32,
                    rollspeed: 0.0,
                    pitchspeed: 0.0,
                    yawspeed: yaw_rate_rps as f32,
                })]
            }
            GLOBAL_POSITION_INT_DATA::ID if self.fresh(&self.board.depth_m, now) => {
                vec![MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                    time_boot_ms: boot_ms,
                    lat: 0,
                    lon: 0,
                    alt: (-depth * 1000.0).round() as i32,
                    relative_alt: (-depth * 1000.0).round() as i32,
                    vx: 0,
                    vy: 0,
                    vz: (heave_mps * 100.0).round().clamp(-32767.0, 32767.0) as i16,
                    hdg: if self.fresh(&self.board.heading_deg, now) {
                        (heading * 100.0).round().rem_euclid(36000.0) as u16
                    } else {
                        u16::MAX
                    },
                })]
            }
            SERVO_OUTPUT_RAW_DATA::ID => vec![self.servo_output_raw(now)],
            VFR_HUD_DATA::ID
                if self.fresh(&self.board.heading_deg, now)
                    || self.fresh(&self.board.depth_m, now) =>
            {
                let throttle =
                    ((i32::from(self.motors_us[1]) - i32::from(NEUTRAL_US)).unsigned_abs() / 5)
                        .min(100) as u16;
                vec![MavMessage::VFR_HUD(VFR_HUD_DATA {
                    airspeed: 0.0,
                    groundspeed: 0.0,
                    alt: -depth as f32,
                    climb: -heave_mps as f32,
                    heading: heading.round().rem_euclid(360.0) as i16,
                    throttle,
                })]
            }
            SCALED_PRESSURE2_DATA::ID if self.fresh(&self.board.water, now) => {
                let (pres, temp) = self.board.water.value;
                vec![MavMessage::SCALED_PRESSURE2(SCALED_PRESSURE2_DATA {
                    time_boot_ms: boot_ms,
                    press_abs: pres as f32,
                    press_diff: 0.0,
                    temperature: temp.map_or(0, |t| (t * 100.0).round() as i16),
                    temperature_press_diff: 0,
                })]
            }
            BATTERY_STATUS_DATA::ID => vec![self.battery_status(now)],
            // The board's free RAM, as ArduPilot reports its own.
            MEMINFO_DATA::ID if self.fresh(&self.board.fmem_bytes, now) => {
                let free = self.board.fmem_bytes.value;
                vec![MavMessage::MEMINFO(MEMINFO_DATA {
                    brkval: 0,
                    freemem: free.min(u32::from(u16::MAX)) as u16,
                    freemem32: free,
                })]
            }
            NAMED_VALUE_FLOAT_DATA::ID => self.named_values(boot_ms),
            AUTOPILOT_VERSION_DATA::ID => vec![self.autopilot_version()],
            CONTROL_STATUS_DATA::ID => vec![self.control_status()],
            NEPTUNUS_SIM_STATE_DATA::ID if self.board.sim_truth.recent(now) => {
                let t = self.board.sim_truth.value;
                vec![MavMessage::NEPTUNUS_SIM_STATE(NEPTUNUS_SIM_STATE_DATA {
                    time_boot_ms: boot_ms,
                    x: t.north_m as f32,
                    y: t.east_m as f32,
                    z: t.depth_m as f32,
                    psi: t.heading_rad as f32,
                    u: t.surge_mps as f32,
                    v: t.sway_mps as f32,
                    w: t.heave_mps as f32,
                    r: t.yaw_rate_rps as f32,
                    phi: t.roll_rad as f32,
                    theta: t.pitch_rad as f32,
                })]
            }
            _ => self
                .build_gimbal(id, now)
                .or_else(|| self.build_instruments(id, now))
                .or_else(|| self.build_holds(id, now))
                .into_iter()
                .collect(),
        }
    }

    fn sys_status(&self, now: Now) -> MavMessage {
        let (present, enabled, health) = self.sensors(now);
        MavMessage::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_present: present,
            onboard_control_sensors_enabled: enabled,
            onboard_control_sensors_health: health,
            load: 0,
            voltage_battery: self.fresh_vout(now).map_or(u16::MAX, |v| {
                (v * 1000.0).round().clamp(0.0, 65534.0) as u16
            }),
            current_battery: self.fresh_current_ca(now),
            battery_remaining: self.battery_remaining(now),
            // The serial line to the board (frames and lines damaged or
            // lost, both ways: `firmware/link/session/quality.rs`).
            drop_rate_comm: self.board.link_quality.drop_rate_cpct,
            errors_comm: self.board.link_quality.errors,
            ..Default::default()
        })
    }

    fn servo_output_raw(&self, now: Now) -> MavMessage {
        let [port, vert, star] = self.motors_us;
        let laser_pwm = if self.payload.laser > 0 { 1900 } else { 1100 };
        let lights_pwm = (1100 + (u32::from(self.payload.lights) * 800) / 255) as u16;
        MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
            time_usec: (now.mono.saturating_sub(self.clock.booted).as_micros() & 0xffff_ffff)
                as u32,
            // MOT_1 starboard, MOT_2 port, MOT_3 vertical (ArduSub SimpleROV-3 numbering).
            servo1_raw: star,
            servo2_raw: port,
            servo3_raw: vert,
            servo6_raw: laser_pwm,
            servo7_raw: lights_pwm,
            servo8_raw: self.payload.tilt_us,
            ..Default::default()
        })
    }

    fn battery_status(&self, now: Now) -> MavMessage {
        let mut voltages = [u16::MAX; 10];
        voltages[0] = self.fresh_vout(now).map_or(u16::MAX, |v| {
            (v * 1000.0).round().clamp(0.0, 65534.0) as u16
        });
        MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
            current_consumed: self.board.consumed_mah.round() as i32,
            energy_consumed: -1,
            temperature: i16::MAX,
            voltages,
            current_battery: self.fresh_current_ca(now),
            id: 0,
            battery_function: MavBatteryFunction::MAV_BATTERY_FUNCTION_ALL,
            mavtype: MavBatteryType::MAV_BATTERY_TYPE_UNKNOWN,
            battery_remaining: self.battery_remaining(now),
            ..Default::default()
        })
    }

    /// ArduSub's NAMED_VALUE_FLOATs: lights, gain, tilt, laser, input hold.
    fn named_values(&self, boot_ms: u32) -> Vec<MavMessage> {
        let tilt_min = f64::from(self.params.tilt_min_us());
        let tilt_max = f64::from(self.params.tilt_max_us());
        let tilt = if tilt_max > tilt_min {
            (f64::from(self.payload.tilt_us) - tilt_min) / (tilt_max - tilt_min)
        } else {
            0.5
        };
        [
            ("Lights1", f64::from(self.payload.lights) / 255.0),
            ("PilotGain", self.pilot.gain),
            ("CamTilt", tilt),
            ("Laser", f64::from(self.payload.laser) / 255.0),
            (
                "InputHold",
                if self.pilot.hold.is_some() { 1.0 } else { 0.0 },
            ),
        ]
        .iter()
        .map(|(name, v)| {
            MavMessage::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
                time_boot_ms: boot_ms,
                value: *v as f32,
                name: chars(name),
            })
        })
        .collect()
    }

    pub(super) fn autopilot_version(&self) -> MavMessage {
        use MavProtocolCapability as C;
        let mut caps = C::MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | C::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | C::MAV_PROTOCOL_CAPABILITY_MISSION_INT;
        // Values travel as their numeric value (C cast) under both
        // identities; the generic one also sends every type as REAL32.
        #[allow(deprecated)]
        let param_float = C::MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT;
        caps |= param_float
            | C::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
            | C::MAV_PROTOCOL_CAPABILITY_COMPONENT_ACCEPTS_GCS_CONTROL
            // MAVLink FTP (read side): the logs and the component metadata.
            | C::MAV_PROTOCOL_CAPABILITY_FTP;
        let mut custom = [0u8; 8];
        let v = env!("CARGO_PKG_VERSION").as_bytes();
        let tag = b"nept";
        custom[..4].copy_from_slice(tag);
        for (i, b) in v.iter().filter(|b| b.is_ascii_digit()).take(4).enumerate() {
            custom[4 + i] = *b;
        }
        MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
            capabilities: caps,
            uid: 0x4e45_5054_0000_0000 | u64::from(self.sysid()),
            // Claim ArduSub 4.5.0, BETA type: QGC then uses its Sub 4.5 metadata and does not nag.
            flight_sw_version: (4 << 24) | (5 << 16) | 128,
            middleware_sw_version: 0,
            os_sw_version: 0,
            board_version: 0,
            vendor_id: 0,
            product_id: 0,
            flight_custom_version: custom,
            ..Default::default()
        })
    }
}
