//! Driving: pilot input (MANUAL_CONTROL, RC_CHANNELS_OVERRIDE, the
//! per-thruster message, motor test, buttons) turned into one `go()`.
//!
//! Every path that can move a thruster ends in [`Vehicle::update_thrusters`],
//! which is the single place that decides the three pulse widths: neutral
//! unless armed, the board link up, and the input fresh. Input reaches the
//! pilot state only from the station in control ([`Vehicle::check_control`])
//! and, after a transfer, only once it has been neutral (pick-up).

use std::time::Duration;

use super::texts::Topic;
use super::{Mode, Now, Output, Sender, Vehicle};
use crate::dialect::neptunus::*;
use crate::firmware::codec::Command;
use crate::firmware::link::LinkState;
use crate::vehicle::input::{self, RcAxis, Sticks};
use crate::vehicle::mixer::{self, Demand, MixerConfig, NEUTRAL_US};
use crate::vehicle::params::{BTN_DEFAULTS, ButtonFunction};

/// A thruster command that has not changed is re-sent this often, so a board
/// that lost it (dead-man trip, reset) gets it back.
const RESEND: Duration = Duration::from_secs(1);
/// No thrust demanded.
pub(super) const NO_DEMAND: Demand = Demand {
    surge: 0.0,
    heave: 0.0,
    yaw: 0.0,
};
/// Motor test stops this long after its last command (ArduSub: ≥ 2 Hz).
const MOTOR_TEST_HOLD: Duration = Duration::from_millis(500);

/// One motor under MAV_CMD_DO_MOTOR_TEST.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct MotorTest {
    /// Index into [port, vertical, starboard].
    slot: usize,
    pwm_us: u16,
    until: Duration,
}

/// Pilot input state.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Pilot {
    /// Latest normalised sticks (before gain).
    pub sticks: Demand,
    /// Latched trims of input hold.
    pub hold: Option<Demand>,
    /// Per-thruster commands [port, vertical, starboard] in MANUAL_THRUSTERS.
    pub thrusters: [f64; 3],
    pub last_input: Option<Duration>,
    pub buttons: u32,
    /// `buttons` belongs to a previous owner: the next mask is a baseline, not edges.
    pub buttons_stale: bool,
    pub last_motor_test: Option<Duration>,
    pub shift: bool,
    pub motor_test: Option<MotorTest>,
    /// Camera tilt rate from an RC override, −1..1.
    pub tilt_rate: f64,
    pub last_go: Option<Duration>,
    /// The pilot gain (JS_GAIN_DEFAULT at start, then the gain buttons).
    pub gain: f64,
}

impl Vehicle {
    pub(super) fn on_manual_control(
        &mut self,
        from: Sender,
        m: &MANUAL_CONTROL_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        // A cheap handle: no profile is copied per message on the 25 Hz path.
        let profiles = std::sync::Arc::clone(&self.profiles);
        let profile = profiles.for_sysid(from.sysid);
        let s: Sticks = input::sticks_from_manual_control(m.x, m.y, m.z, m.r, profile);
        let mut d = self.pilot.sticks;
        if let Some(v) = s.forward {
            d.surge = v;
        }
        if let Some(v) = s.heave_down {
            d.heave = v;
        }
        if let Some(v) = s.yaw {
            d.yaw = v;
        }
        // In MANUAL_THRUSTERS the sticks do not drive (buttons still work).
        if self.mode != Mode::ManualThrusters {
            self.pilot.last_input = Some(now.mono);
            if self.picked_up(is_neutral(&d), now, out) {
                self.pilot.sticks = d;
            }
        }
        let buttons = u32::from(m.buttons) | (u32::from(m.buttons2) << 16);
        self.on_buttons(from, buttons, profile, now, out);
        self.update_thrusters(now, out);
    }

    pub(super) fn on_rc_override(
        &mut self,
        from: Sender,
        r: &RC_CHANNELS_OVERRIDE_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        // A cheap handle: no profile is copied per message on the 25 Hz path.
        let profiles = std::sync::Arc::clone(&self.profiles);
        let profile = profiles.for_sysid(from.sysid);
        let ch = [
            r.chan1_raw,
            r.chan2_raw,
            r.chan3_raw,
            r.chan4_raw,
            r.chan5_raw,
            r.chan6_raw,
            r.chan7_raw,
            r.chan8_raw,
            r.chan9_raw,
            r.chan10_raw,
            r.chan11_raw,
            r.chan12_raw,
            r.chan13_raw,
            r.chan14_raw,
            r.chan15_raw,
            r.chan16_raw,
            r.chan17_raw,
            r.chan18_raw,
        ];
        let u = input::rc_override(&ch, profile);
        let apply = |slot: &mut f64, a: Option<RcAxis>| match a {
            Some(RcAxis::Set(v)) => *slot = v,
            Some(RcAxis::Release) => *slot = 0.0,
            None => {}
        };
        let mut d = self.pilot.sticks;
        apply(&mut d.surge, u.forward);
        apply(&mut d.heave, u.heave_down);
        apply(&mut d.yaw, u.yaw);
        let sticks_drive = self.mode != Mode::ManualThrusters;
        if sticks_drive && self.picked_up(is_neutral(&d), now, out) {
            self.pilot.sticks = d;
        }
        apply(&mut self.pilot.tilt_rate, u.tilt_rate);
        if let Some(RcAxis::Set(level)) = u.lights {
            let max = f64::from(self.params.lights_max());
            let level = (level * max).round().clamp(0.0, 255.0) as u8;
            if level != self.payload.lights {
                self.set_lights(level, out);
            }
        }
        if sticks_drive {
            self.pilot.last_input = Some(now.mono);
        }
        self.update_thrusters(now, out);
    }

    pub(super) fn on_thrusters_message(
        &mut self,
        t: &NEPTUNUS_THRUSTERS_DATA,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if self.mode != Mode::ManualThrusters {
            // Not this mode's input: it neither drives nor keeps other input fresh.
            return;
        }
        let mut thrusters = self.pilot.thrusters;
        for (slot, v) in thrusters.iter_mut().zip([t.port, t.vertical, t.starboard]) {
            if !v.is_nan() {
                *slot = f64::from(v).clamp(-1.0, 1.0);
            }
        }
        self.pilot.last_input = Some(now.mono);
        if self.picked_up(thrusters.iter().all(|v| v.abs() < 1e-9), now, out) {
            self.pilot.thrusters = thrusters;
        }
        self.update_thrusters(now, out);
    }

    /// MAV_CMD_DO_MOTOR_TEST: p1 motor (1-based, ArduSub numbering: 1 starboard,
    /// 2 port, 3 vertical), p2 throttle type (0 percent, 1 PWM), p3 value,
    /// p4 timeout s. Needs arming; stops 0.5 s after the last command.
    pub(super) fn motor_test(&mut self, p: [f32; 7], now: Now, out: &mut Vec<Output>) -> MavResult {
        if !self.armed {
            self.statustext(
                Topic::General,
                MavSeverity::MAV_SEVERITY_WARNING,
                "Motor test: arm first",
                out,
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        let motor = p[0];
        let slot = match motor.round() as i64 {
            1 => 2,
            2 => 0,
            3 => 1,
            _ => {
                self.statustext(
                    Topic::General,
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("Motor test: no motor {motor}"),
                    out,
                );
                return MavResult::MAV_RESULT_DENIED;
            }
        };
        let (lo, hi) = (self.params.mot_pwm_min(), self.params.mot_pwm_max());
        let value = f64::from(p[2]);
        let pwm = match p[1].round() as i64 {
            0 if value.is_finite() => {
                f64::from(lo) + (f64::from(hi) - f64::from(lo)) * value.clamp(0.0, 100.0) / 100.0
            }
            1 if value.is_finite() => value,
            _ => return MavResult::MAV_RESULT_DENIED,
        };
        // Compare before converting: a huge p4 would overflow a Duration.
        let hold = if p[3] > 0.0 && p[3] < MOTOR_TEST_HOLD.as_secs_f32() {
            Duration::from_secs_f32(p[3])
        } else {
            MOTOR_TEST_HOLD
        };
        let pwm_us = pwm.round().clamp(f64::from(lo), f64::from(hi)) as u16;
        self.pilot.last_motor_test = Some(now.mono);
        self.pilot.motor_test = Some(MotorTest {
            slot,
            pwm_us,
            until: now.mono + hold,
        });
        self.update_thrusters(now, out);
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// The pilot's sticks with input hold applied; centred when the input is stale.
    pub(super) fn pilot_sticks(&self, now: Now) -> Demand {
        if !self.input_fresh(now) {
            return NO_DEMAND;
        }
        let mut d = self.pilot.sticks;
        if let Some(h) = self.pilot.hold {
            d.surge = (d.surge + h.surge).clamp(-1.0, 1.0);
            d.heave = (d.heave + h.heave).clamp(-1.0, 1.0);
            d.yaw = (d.yaw + h.yaw).clamp(-1.0, 1.0);
        }
        d
    }

    fn input_fresh(&self, now: Now) -> bool {
        let timeout = Duration::from_secs_f32(self.params.fs_pilot_timeout_s().clamp(0.1, 3.0));
        self.pilot
            .last_input
            .is_some_and(|t| now.mono.saturating_sub(t) <= timeout)
    }

    pub(super) fn mixer(&self) -> MixerConfig {
        self.params.mixer_config(self.pilot.gain)
    }

    /// The one place that decides what the thrusters get: the `go()`
    /// values (`motors_us`, what SERVO_OUTPUT_RAW reports), linear in
    /// thrust through the firmware's motor mapping.
    pub(super) fn update_thrusters(&mut self, now: Now, out: &mut Vec<Output>) {
        if let Some(t) = self.pilot.motor_test
            && (now.mono >= t.until || !self.armed)
        {
            self.pilot.motor_test = None;
        }
        let target = if !self.armed || self.board.link != LinkState::Up {
            [NEUTRAL_US; 3]
        } else if let Some(t) = self.pilot.motor_test {
            let mut us = [NEUTRAL_US; 3];
            us[t.slot] = t.pwm_us;
            us
        } else if self.mode.holds_depth() || self.mode.holds_heading() {
            // The autopilots act only while a live owner (or a failsafe
            // action) is behind them: the same rule that feeds the dead-man.
            if self.owner_alive(now, super::authority::LIFE_FEEDS_DEADMAN)
                || self.failsafe_needs_thrust()
            {
                let d = self.hold_demand(self.pilot_sticks(now));
                mixer::mix(
                    &d,
                    &MixerConfig {
                        gain: 1.0,
                        ..self.mixer()
                    },
                )
            } else {
                [NEUTRAL_US; 3]
            }
        } else if !self.input_fresh(now) {
            // Pilot input lost: neutral first (the failsafe action comes on top).
            [NEUTRAL_US; 3]
        } else if self.mode == Mode::Manual {
            let mut d = self.pilot.sticks;
            if let Some(h) = self.pilot.hold {
                d.surge = (d.surge + h.surge).clamp(-1.0, 1.0);
                d.heave = (d.heave + h.heave).clamp(-1.0, 1.0);
                d.yaw = (d.yaw + h.yaw).clamp(-1.0, 1.0);
            }
            d.heave *= f64::from(self.params.js_thr_gain());
            mixer::mix(&d, &self.mixer())
        } else if self.mode == Mode::ManualThrusters {
            let cfg = self.mixer();
            let dirs = cfg.directions;
            let [p, v, s] = self.pilot.thrusters;
            [
                mixer::thruster_us(p, dirs[0], &cfg),
                mixer::thruster_us(v, dirs[1], &cfg),
                mixer::thruster_us(s, dirs[2], &cfg),
            ]
        } else {
            [NEUTRAL_US; 3]
        };
        let resend = target != [NEUTRAL_US; 3]
            && self
                .pilot
                .last_go
                .is_none_or(|t| now.mono.saturating_sub(t) >= RESEND);
        // What the thrusters really push, for the estimator's model.
        self.holds.applied = self.effective_demand(target);
        if target != self.motors_us || resend {
            self.motors_us = target;
            self.pilot.last_go = Some(now.mono);
            let [port_us, vertical_us, starboard_us] = target;
            self.send_go(
                Command::Go {
                    port_us,
                    vertical_us,
                    starboard_us,
                },
                out,
            );
        }
    }

    /// Called every tick: timeouts and rates.
    pub(super) fn drive_tick(&mut self, now: Now, dt: Duration, out: &mut Vec<Output>) {
        if self.pilot.tilt_rate != 0.0 && self.input_fresh(now) {
            // Full stick slews the camera over its whole range in about 2 s.
            let span = f64::from(self.params.tilt_max_us()) - f64::from(self.params.tilt_min_us());
            let step = self.pilot.tilt_rate * span / 2.0 * dt.as_secs_f64();
            self.payload.tilt_accum += step;
            if self.payload.tilt_accum.abs() >= 1.0 {
                let delta = self.payload.tilt_accum.trunc();
                self.payload.tilt_accum -= delta;
                self.set_tilt_us(f64::from(self.payload.tilt_us) + delta, out);
            }
        }
        self.holds_step(now, dt, out);
        self.update_thrusters(now, out);
    }

    /// Thrusters to neutral and pilot state cleared (the thesis' safety-mode
    /// stop). With `pickup`, the owner's sticks are ignored until centred.
    pub(super) fn safety_stop(&mut self, pickup: bool, out: &mut Vec<Output>) {
        self.stop_pilot();
        self.pilot.hold = None;
        // An autopilot mode stops where it is: the held depth and heading are
        // taken again from the vehicle's state.
        self.holds_reset();
        // After a transfer the next button mask is a baseline: buttons the new
        // owner holds were not pressed now. Otherwise buttons start released.
        self.pilot.buttons_stale = pickup;
        if pickup {
            self.auth.pickup = true;
        } else {
            self.pilot.buttons = 0;
        }
        self.send_neutral(out);
    }

    /// Clears pilot state at a safety-mode stop (mode change, disarm, transfer).
    pub(super) fn stop_pilot(&mut self) {
        self.pilot.sticks = Demand::default();
        self.pilot.thrusters = [0.0; 3];
        self.pilot.motor_test = None;
        self.pilot.tilt_rate = 0.0;
        // A gimbal pitch rate is the pilot's input too.
        self.gimbal_stop();
    }

    fn on_buttons(
        &mut self,
        from: Sender,
        now_mask: u32,
        profile: &input::Profile,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if std::mem::take(&mut self.pilot.buttons_stale) {
            // The first mask after a transfer: buttons held now were not pressed now.
            self.pilot.buttons = now_mask;
            return;
        }
        let (pressed, released) = input::edges(self.pilot.buttons, now_mask);
        self.pilot.buttons = now_mask;
        for i in 0..32usize {
            let bit = 1u32 << i;
            if pressed & bit != 0 {
                let f = self.button_function(i, self.pilot.shift, profile);
                self.button_press(from, f, now, out);
            } else if released & bit != 0 {
                let f = self.button_function(i, false, profile);
                if ButtonFunction::from_code(f) == Some(ButtonFunction::Shift) {
                    self.pilot.shift = false;
                }
            }
        }
    }

    /// BTNn_FUNCTION / BTNn_SFUNCTION where set away from ArduSub's default,
    /// otherwise the sender's profile default.
    fn button_function(&self, i: usize, shifted: bool, profile: &input::Profile) -> u8 {
        let param = self.params.btn_function(i, shifted);
        let ardusub = BTN_DEFAULTS
            .get(i)
            .map_or(0, |&(regular, shift)| if shifted { shift } else { regular });
        if param != ardusub {
            param
        } else {
            profile.button_function(i, shifted)
        }
    }

    fn button_press(&mut self, from: Sender, code: u8, now: Now, out: &mut Vec<Output>) {
        use ButtonFunction as B;
        let sev = MavSeverity::MAV_SEVERITY_INFO;
        let Some(function) = ButtonFunction::from_code(code) else {
            return;
        };
        match function {
            B::None => {}
            B::Shift => self.pilot.shift = true,
            B::ArmToggle => {
                if self.armed {
                    self.disarm("button", Some(from.sysid), out);
                } else {
                    self.arm(false, Some(from.sysid), now, out);
                }
            }
            B::Arm => {
                self.arm(false, Some(from.sysid), now, out);
            }
            B::Disarm => {
                self.disarm("button", Some(from.sysid), out);
            }
            B::Mode(mode) => {
                self.set_mode(mode.number(), Some(from.sysid), now, out);
            }
            B::MountCenter => self.set_tilt_us(f64::from(NEUTRAL_US), out),
            B::MountTiltUp | B::MountTiltDown => {
                let step = (f64::from(self.params.tilt_max_us())
                    - f64::from(self.params.tilt_min_us()))
                    / 10.0;
                let sign = if function == B::MountTiltUp {
                    1.0
                } else {
                    -1.0
                };
                self.set_tilt_us(f64::from(self.payload.tilt_us) + sign * step, out);
            }
            B::LightsCycle | B::LightsBrighter | B::LightsDimmer => {
                let max = u16::from(self.params.lights_max());
                let steps = self.params.js_lights_steps().max(1);
                let step = (max / steps).max(1);
                let level = u16::from(self.payload.lights);
                let level = match function {
                    B::LightsCycle if level >= max => 0,
                    B::LightsCycle | B::LightsBrighter => (level + step).min(max),
                    _ => level.saturating_sub(step),
                };
                self.set_lights(level.min(255) as u8, out);
            }
            B::GainToggle | B::GainInc | B::GainDec => {
                let (lo, hi) = (
                    f64::from(self.params.js_gain_min()),
                    f64::from(self.params.js_gain_max()),
                );
                let steps = f64::from(self.params.js_gain_steps().max(2) - 1);
                let step = (hi - lo) / steps;
                let gain = self.pilot.gain;
                self.pilot.gain = match function {
                    B::GainToggle if (gain - hi).abs() < 1e-6 => lo,
                    B::GainToggle => hi,
                    B::GainInc => (gain + step).min(hi),
                    _ => (gain - step).max(lo),
                };
                let pct = (self.pilot.gain * 100.0).round();
                self.statustext(Topic::Gain, sev, &format!("#Gain is {pct:.0}%"), out);
            }
            B::InputHoldSet => {
                if self.pilot.hold.take().is_some() {
                    self.statustext(Topic::Gain, sev, "#Input Hold Disabled", out);
                } else {
                    self.pilot.hold = Some(self.pilot.sticks);
                    self.statustext(Topic::Gain, sev, "#Input Hold Set", out);
                }
            }
            B::LaserToggle => self.set_laser(self.payload.laser == 0, out),
            B::Unsupported(code) => {
                tracing::debug!(
                    function = code,
                    sysid = from.sysid,
                    "button function not implemented on this vehicle"
                );
            }
        }
    }
}

/// Every axis centred (after the profile's deadband).
fn is_neutral(d: &Demand) -> bool {
    d.surge.abs() < 1e-9 && d.heave.abs() < 1e-9 && d.yaw.abs() < 1e-9
}
