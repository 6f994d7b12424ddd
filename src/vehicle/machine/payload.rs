//! Payload: lights, laser and camera tilt — from commands (DO_SET_SERVO,
//! DO_MOUNT_CONTROL, the illuminator commands), buttons and RC override —
//! and what the board is told when its link comes up.

use super::texts::Topic;
use super::{Output, Vehicle, given};
use crate::dialect::neptunus::*;
use crate::firmware::codec::Command;
use crate::vehicle::mixer::NEUTRAL_US;
use crate::vehicle::params::ServoFunction;

/// Lights, laser and tilt as last commanded (or reported by the board).
#[derive(Debug, Clone)]
pub(super) struct Payload {
    /// Lamp level 0..=255.
    pub lights: u8,
    /// The level the lamp had when last on (ILLUMINATOR_ON_OFF turns it back on there).
    pub last_lights_on: u8,
    /// Laser 0 (off) or 255.
    pub laser: u8,
    /// Camera tilt servo pulse width (µs).
    pub tilt_us: u16,
    /// Fractional microseconds of a tilt rate not yet applied.
    pub tilt_accum: f64,
}

impl Default for Payload {
    fn default() -> Self {
        Self {
            lights: 0,
            last_lights_on: 255,
            laser: 0,
            tilt_us: NEUTRAL_US,
            tilt_accum: 0.0,
        }
    }
}

/// Pulse widths DO_SET_SERVO accepts at all (µs).
const SERVO_PWM_RANGE: std::ops::RangeInclusive<f64> = 800.0..=2200.0;
/// Pulse widths a servo output maps to 0..1 (µs).
const SERVO_PWM_OFF: f64 = 1100.0;
const SERVO_PWM_SPAN: f64 = 800.0;

impl Vehicle {
    /// Camera tilt servo pulse width (µs).
    pub fn tilt_us(&self) -> u16 {
        self.payload.tilt_us
    }

    /// What the board gets when its link comes up: our lights, tilt, laser.
    pub(super) fn payload_to_board(&self, out: &mut Vec<Output>) {
        let p = &self.payload;
        out.push(Output::Board(Command::Lights(p.lights)));
        out.push(Output::Board(Command::Tilt(p.tilt_us)));
        if p.laser > 0 {
            out.push(Output::Board(Command::Laser(p.laser)));
        }
    }

    /// The payload commands, after the authority check.
    pub(super) fn payload_command(
        &mut self,
        cmd: MavCmd,
        p: [f32; 7],
        out: &mut Vec<Output>,
    ) -> MavResult {
        use MavCmd as C;
        use MavResult as R;
        match cmd {
            C::MAV_CMD_DO_SET_SERVO => self.set_servo(
                given(p[0]).unwrap_or(0.0) as u32,
                given(p[1]).unwrap_or(0.0),
                out,
            ),
            // p1 tilt in centidegrees, ±90° over the tilt servo's ±500 µs.
            C::MAV_CMD_DO_MOUNT_CONTROL => match given(p[0]) {
                Some(tilt_cdeg) => {
                    let deg = f64::from(tilt_cdeg) / 100.0;
                    self.set_tilt_us((f64::from(NEUTRAL_US) + deg / 90.0 * 500.0).round(), out);
                    R::MAV_RESULT_ACCEPTED
                }
                None => R::MAV_RESULT_DENIED,
            },
            C::MAV_CMD_ILLUMINATOR_ON_OFF => {
                let on = given(p[0]).unwrap_or(0.0) >= 0.5;
                let level = if on {
                    self.payload.last_lights_on.max(1)
                } else {
                    0
                };
                self.set_lights(level, out);
                R::MAV_RESULT_ACCEPTED
            }
            // p2 brightness in percent of NEPT_LIGHTS_MAX.
            C::MAV_CMD_DO_ILLUMINATOR_CONFIGURE => match given(p[1]) {
                Some(pct) if (0.0..=100.0).contains(&pct) => {
                    let level = (f64::from(pct) / 100.0 * f64::from(self.params.lights_max()))
                        .round()
                        .clamp(0.0, 255.0) as u8;
                    self.set_lights(level, out);
                    R::MAV_RESULT_ACCEPTED
                }
                _ => R::MAV_RESULT_DENIED,
            },
            _ => R::MAV_RESULT_UNSUPPORTED,
        }
    }

    pub(super) fn set_lights(&mut self, level: u8, out: &mut Vec<Output>) {
        self.payload.lights = level;
        if level > 0 {
            self.payload.last_lights_on = level;
        }
        out.push(Output::Board(Command::Lights(level)));
    }

    pub(super) fn set_laser(&mut self, on: bool, out: &mut Vec<Output>) {
        self.payload.laser = if on { 255 } else { 0 };
        out.push(Output::Board(Command::Laser(self.payload.laser)));
    }

    /// The tilt servo to `us`, inside NEPT_TILT_MIN_US..NEPT_TILT_MAX_US.
    pub(super) fn set_tilt_us(&mut self, us: f64, out: &mut Vec<Output>) {
        let lo = f64::from(self.params.tilt_min_us());
        let hi = f64::from(self.params.tilt_max_us());
        let us = us.clamp(lo.min(hi), hi.max(lo)).round() as u16;
        self.payload.tilt_us = us;
        out.push(Output::Board(Command::Tilt(us)));
    }

    /// DO_SET_SERVO: the output's SERVOn_FUNCTION says what it drives.
    fn set_servo(&mut self, servo: u32, pwm: f32, out: &mut Vec<Output>) -> MavResult {
        let function = self.params.servo_function(servo);
        let pwm = f64::from(pwm);
        if !SERVO_PWM_RANGE.contains(&pwm) {
            self.statustext(
                Topic::General,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Servo {servo}: {pwm} µs out of range"),
                out,
            );
            return MavResult::MAV_RESULT_DENIED;
        }
        let frac = ((pwm - SERVO_PWM_OFF) / SERVO_PWM_SPAN).clamp(0.0, 1.0);
        match function {
            Some(ServoFunction::Lights1) => {
                let level = (frac * f64::from(self.params.lights_max()))
                    .round()
                    .clamp(0.0, 255.0) as u8;
                self.set_lights(level, out);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(ServoFunction::Lights2) => {
                self.set_laser(pwm > f64::from(NEUTRAL_US), out);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(ServoFunction::MountTilt) => {
                self.set_tilt_us(pwm, out);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(ServoFunction::Motor(_)) => {
                self.statustext(
                    Topic::General,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("Servo {servo} is a thruster: use MAV_CMD_DO_MOTOR_TEST"),
                    out,
                );
                MavResult::MAV_RESULT_DENIED
            }
            _ => MavResult::MAV_RESULT_UNSUPPORTED,
        }
    }
}
