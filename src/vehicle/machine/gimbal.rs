//! The camera tilt as a MAVLink gimbal (gimbal protocol v2): this
//! component (the autopilot) is the gimbal manager of one non-MAVLink
//! gimbal device, id [`GIMBAL_DEVICE_ID`] — the tilt servo on the board.
//!
//! GIMBAL_MANAGER_INFORMATION (on request) gives the pitch range from
//! NEPT_TILT_MIN/MAX_US; GIMBAL_MANAGER_STATUS (the station in control as
//! primary control) and GIMBAL_DEVICE_ATTITUDE_STATUS are streamed. The
//! attitude's pitch is the servo position the board reports (its `servo`
//! status value, so a ground station sees the tilt the board really took),
//! or the commanded tilt while the board reports none.
//! MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, GIMBAL_MANAGER_SET_ATTITUDE and
//! GIMBAL_MANAGER_SET_PITCHYAW move the tilt through the same path as
//! MAV_CMD_DO_MOUNT_CONTROL (`set_tilt_us`, the board's `tilt()`), and only
//! after the authority check: a non-owner's command is refused with its
//! reason, its messages are counted and ignored.
//!
//! A pitch rate (angle NaN, rate given: what QGC's gimbal buttons send)
//! slews the tilt each tick while it is repeated, and stops 1 s after the
//! last request.
//!
//! The tilt servo turns with the vehicle (it is not stabilised), so the
//! gimbal "follows" in pitch; yaw and roll do not exist. Angles map to the
//! servo as DO_MOUNT_CONTROL maps them: ±90° over ±500 µs around neutral.

use std::time::Duration;

use super::authority::Control;
use super::{NEUTRAL_US, Now, Output, Sender, Vehicle, given};
use crate::dialect::neptunus::*;

/// The gimbal device's id: 1–6 name a gimbal without a MAVLink component of
/// its own, handled by the manager (QGroundControl ignores 0).
pub const GIMBAL_DEVICE_ID: u8 = 1;
/// Pulse width per degree of tilt (±90° over ±500 µs).
const US_PER_DEG: f64 = 500.0 / 90.0;
/// A pitch rate holds this long after its last request (QGC repeats a held
/// button's rate every 0.5 s), so a lost "stop" cannot slew the tilt away.
const RATE_HOLD: Duration = Duration::from_secs(1);
/// The fastest pitch rate accepted (deg/s).
const MAX_RATE_DPS: f64 = 90.0;

/// A pitch rate being applied.
#[derive(Debug, Default)]
pub(super) struct Gimbal {
    rate_dps: f64,
    until: Duration,
    /// Fractional microseconds not yet applied.
    accum_us: f64,
}

/// Tilt angle (degrees, up positive) of a servo pulse width.
pub(super) fn tilt_deg(us: u16) -> f64 {
    (f64::from(us) - f64::from(NEUTRAL_US)) / US_PER_DEG
}

/// Servo pulse width of a tilt angle (degrees, up positive).
pub(super) fn tilt_us_of(deg: f64) -> f64 {
    f64::from(NEUTRAL_US) + deg * US_PER_DEG
}

impl Vehicle {
    /// MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW: p1 pitch (deg, NaN: unchanged),
    /// p2 yaw (ignored: no yaw axis), p3 pitch rate (deg/s, used when p1
    /// is NaN), p4 yaw rate (ignored), p5 flags, p7 gimbal device id (0 all,
    /// or ours). After the authority check.
    pub(super) fn gimbal_pitchyaw_command(
        &mut self,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        let device = given(p[6]).unwrap_or(0.0);
        if device != 0.0 && device != f32::from(GIMBAL_DEVICE_ID) {
            return MavResult::MAV_RESULT_DENIED;
        }
        let flags = given(p[4]).map_or(0, |f| f.max(0.0) as u32);
        self.gimbal_pitch(given(p[0]), given(p[2]), flags, now, out)
    }

    /// Pitch in degrees (or the neutral/retract flags) to the tilt servo;
    /// with no angle, a pitch rate in deg/s (applied by [`Vehicle::gimbal_tick`]).
    fn gimbal_pitch(
        &mut self,
        pitch_deg: Option<f32>,
        rate_dps: Option<f32>,
        flags: u32,
        now: Now,
        out: &mut Vec<Output>,
    ) -> MavResult {
        let neutral = GimbalManagerFlags::GIMBAL_MANAGER_FLAGS_NEUTRAL.bits()
            | GimbalManagerFlags::GIMBAL_MANAGER_FLAGS_RETRACT.bits();
        let deg = if flags & neutral != 0 {
            Some(0.0)
        } else {
            pitch_deg.filter(|d| d.is_finite()).map(f64::from)
        };
        let rate = rate_dps.filter(|r| r.is_finite()).map(f64::from);
        match (deg, rate) {
            (Some(d), _) => {
                self.gimbal.rate_dps = 0.0;
                self.set_tilt_us(tilt_us_of(d.clamp(-180.0, 180.0)).round(), out);
                MavResult::MAV_RESULT_ACCEPTED
            }
            (None, Some(r)) => {
                self.gimbal.rate_dps = r.clamp(-MAX_RATE_DPS, MAX_RATE_DPS);
                self.gimbal.until = now.mono + RATE_HOLD;
                MavResult::MAV_RESULT_ACCEPTED
            }
            (None, None) => MavResult::MAV_RESULT_DENIED,
        }
    }

    /// A pitch rate is moving the tilt (the core ticks while it does).
    pub(super) fn gimbal_moving(&self) -> bool {
        self.gimbal.rate_dps != 0.0
    }

    /// Ends a pitch rate (a safety stop: mode change, disarm, transfer).
    pub(super) fn gimbal_stop(&mut self) {
        self.gimbal.rate_dps = 0.0;
    }

    /// Every tick: a pitch rate requested within [`RATE_HOLD`] moves the tilt.
    pub(super) fn gimbal_tick(&mut self, now: Now, dt: Duration, out: &mut Vec<Output>) {
        if self.gimbal.rate_dps == 0.0 {
            return;
        }
        if now.mono >= self.gimbal.until {
            self.gimbal.rate_dps = 0.0;
            self.gimbal.accum_us = 0.0;
            return;
        }
        self.gimbal.accum_us += self.gimbal.rate_dps * US_PER_DEG * dt.as_secs_f64();
        if self.gimbal.accum_us.abs() >= 1.0 {
            let delta = self.gimbal.accum_us.trunc();
            self.gimbal.accum_us -= delta;
            self.set_tilt_us(f64::from(self.payload.tilt_us) + delta, out);
        }
    }

    /// GIMBAL_MANAGER_SET_ATTITUDE / GIMBAL_MANAGER_SET_PITCHYAW: from the
    /// station in control only; anyone else's is counted and ignored (with a
    /// rate-limited reply), as other control input.
    pub(super) fn on_gimbal_message(
        &mut self,
        from: Sender,
        msg: &MavMessage,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        let (what, device, flags, pitch, rate) = match msg {
            MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(m) => {
                let [w, x, y, z] = m.q;
                // Pitch of the quaternion (aerospace order), NaN if it has none.
                let s = 2.0 * (w * y - z * x);
                let pitch = s.clamp(-1.0, 1.0).asin().to_degrees();
                (
                    "GIMBAL_MANAGER_SET_ATTITUDE",
                    m.gimbal_device_id,
                    m.flags.bits(),
                    pitch,
                    m.angular_velocity_y.to_degrees(),
                )
            }
            MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(m) => (
                "GIMBAL_MANAGER_SET_PITCHYAW",
                m.gimbal_device_id,
                m.flags.bits(),
                m.pitch.to_degrees(),
                m.pitch_rate.to_degrees(),
            ),
            _ => return,
        };
        if device != 0 && device != GIMBAL_DEVICE_ID {
            return;
        }
        if let Err(why) = self.check_control(from, Control::Command, now, out) {
            self.refuse_input(from, what, why, now, out);
            return;
        }
        self.gimbal_pitch(Some(pitch), Some(rate), flags, now, out);
    }

    /// The gimbal messages `build` makes (None for any other id).
    pub(super) fn build_gimbal(&self, id: u32, now: Now) -> Option<MavMessage> {
        use mavlink_core::MessageData;
        let time_boot_ms = self.boot_ms(now);
        match id {
            GIMBAL_MANAGER_INFORMATION_DATA::ID => {
                let lo = tilt_deg(self.params.tilt_min_us()).to_radians() as f32;
                let hi = tilt_deg(self.params.tilt_max_us()).to_radians() as f32;
                Some(MavMessage::GIMBAL_MANAGER_INFORMATION(
                    GIMBAL_MANAGER_INFORMATION_DATA {
                        time_boot_ms,
                        cap_flags: GimbalManagerCapFlags::GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_AXIS
                            | GimbalManagerCapFlags::GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_FOLLOW
                            | GimbalManagerCapFlags::GIMBAL_MANAGER_CAP_FLAGS_HAS_NEUTRAL,
                        gimbal_device_id: GIMBAL_DEVICE_ID,
                        roll_min: 0.0,
                        roll_max: 0.0,
                        pitch_min: lo.min(hi),
                        pitch_max: hi.max(lo),
                        yaw_min: 0.0,
                        yaw_max: 0.0,
                    },
                ))
            }
            GIMBAL_MANAGER_STATUS_DATA::ID => {
                // The station in control of the vehicle controls its gimbal.
                let (sysid, compid) = self.auth.owner.map_or((0, 0), |o| (o.sysid, o.compid));
                Some(MavMessage::GIMBAL_MANAGER_STATUS(
                    GIMBAL_MANAGER_STATUS_DATA {
                        time_boot_ms,
                        flags: GimbalManagerFlags::GIMBAL_MANAGER_FLAGS_YAW_IN_VEHICLE_FRAME,
                        gimbal_device_id: GIMBAL_DEVICE_ID,
                        primary_control_sysid: sysid,
                        primary_control_compid: compid,
                        secondary_control_sysid: 0,
                        secondary_control_compid: 0,
                    },
                ))
            }
            GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID => {
                // The device's attitude: where the board says the servo is
                // (its status line, 1 Hz), else where it was told to go.
                let reported = self
                    .fresh(&self.board.servo_us, now)
                    .then_some(self.board.servo_us.value);
                let us = reported.unwrap_or(self.payload.tilt_us);
                let half = tilt_deg(us).to_radians() / 2.0;
                Some(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(
                    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
                        target_system: 0,
                        target_component: 0,
                        time_boot_ms,
                        flags: GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME,
                        q: [half.cos() as f32, 0.0, half.sin() as f32, 0.0],
                        angular_velocity_x: f32::NAN,
                        angular_velocity_y: f32::NAN,
                        angular_velocity_z: f32::NAN,
                        failure_flags: GimbalDeviceErrorFlags::empty(),
                        delta_yaw: f32::NAN,
                        delta_yaw_velocity: f32::NAN,
                        gimbal_device_id: GIMBAL_DEVICE_ID,
                    },
                ))
            }
            _ => None,
        }
    }
}
