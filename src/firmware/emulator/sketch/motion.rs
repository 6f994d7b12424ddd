//! What moves: `Thrusters2X1` (targets, the board's `thro`/`yaw`/`lift`
//! mixing, the 50 ms motor timer and `Motor::goms`), the pilot's depth and
//! heading holds (`Pilot.cpp`), the alternative servo.

use super::{FirmwareVersion, Hardware, MIDPOINT, Sketch};
use crate::firmware::emulator::arduino::{constrain, float, map, trunc};
use crate::firmware::emulator::uart::Uart;

/// A thruster channel (`Motor`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Motor {
    pub(super) positive_modifier: f32,
    pub(super) negative_modifier: f32,
    pub(super) deadzone_negative: i32,
    pub(super) deadzone_positive: i32,
}

impl Motor {
    /// `Motor::goms`: the ESC pulse for a target, with the modifier
    /// truncated to an `int`, the result constrained, then mapped around
    /// the deadzone (skipped over, not zeroed inside).
    pub(super) fn goms(&self, ms: i32) -> u16 {
        let modifier = if ms > MIDPOINT {
            trunc(self.positive_modifier)
        } else if ms < MIDPOINT {
            trunc(self.negative_modifier)
        } else {
            1
        };
        // 16-bit `int` arithmetic, as on the board.
        let delta = (ms - MIDPOINT) as i16;
        let scaled = delta
            .wrapping_mul(modifier as i16)
            .wrapping_add(MIDPOINT as i16);
        let pre = constrain(i32::from(scaled), 1000, 2000);
        let fin = if pre < MIDPOINT {
            map(pre, 1000, MIDPOINT, 1000, MIDPOINT - self.deadzone_negative)
        } else if pre > MIDPOINT {
            map(pre, MIDPOINT, 2000, MIDPOINT + self.deadzone_positive, 2000)
        } else {
            MIDPOINT
        };
        // The servo library keeps 544..2400 µs and reads back what it wrote.
        constrain(constrain(fin, 1000, 2000), 544, 2400) as u16
    }
}

impl Sketch {
    pub(super) fn mtrmod_line(&self) -> String {
        let [p, v, s] = self.motors;
        format!(
            "mtrmod:{},{},{},{},{},{};",
            float(p.positive_modifier),
            float(v.positive_modifier),
            float(s.positive_modifier),
            float(p.negative_modifier),
            float(v.negative_modifier),
            float(s.negative_modifier)
        )
    }

    pub(super) fn thrusters_loop(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        let a = self.cmd.args;
        if self.cmd.is("mtrmod1") {
            for (m, v) in self.motors.iter_mut().zip(&a[1..4]) {
                // Integer division before the float: 150 is 1.
                m.positive_modifier = (v / 100) as f32;
            }
        }
        if self.cmd.is("mtrmod2") {
            for (m, v) in self.motors.iter_mut().zip(&a[1..4]) {
                m.negative_modifier = (v / 100) as f32;
            }
        }
        if self.cmd.is("rmtrmod") {
            let line = self.mtrmod_line();
            self.println(uart, &line);
        }
        let valid = |v: i32| v > 999 && v < 2001;
        if self.cmd.is("go") && valid(a[1]) && valid(a[2]) && valid(a[3]) {
            self.target = [a[1], a[2], a[3]];
        }
        if self.cmd.is("port") && valid(a[1]) {
            self.target[0] = a[1];
        }
        if self.cmd.is("vertical") && valid(a[1]) {
            self.target[1] = a[1];
        }
        if self.cmd.is("starboard") && valid(a[1]) {
            self.target[2] = a[1];
        }
        if self.cmd.is("thro") || self.cmd.is("yaw") {
            self.mix_throttle_and_yaw();
        }
        if self.cmd.is("lift") {
            if (-100..=100).contains(&a[1]) {
                let lift = a[1] as f32 / 100.0;
                self.target[1] = trunc(1500.0 + 500.0 * lift);
            }
        } else if self.cmd.is("escp") {
            self.escs_powered = a[1] != 0;
            hw.esc_power(self.clock, self.escs_powered);
            let line = format!("log:escpower={};", a[1]);
            self.println(uart, &line);
        } else if self.cmd.is("start") {
            // Re-attaches the ESC outputs, which never detach.
        } else if self.cmd.is("stop") {
            self.target = [MIDPOINT; 3];
        } else if self.cmd.is("mcal") {
            self.println(uart, "log:Motor Callibration Staring;");
            self.println(uart, "log:Motor Callibration Complete;");
        }
        let ms = self.millis();
        if self.control_timer.elapsed(ms, 50) && self.target != self.applied {
            self.applied = self.target;
            let m = self.motors;
            self.esc_us = [
                m[0].goms(self.applied[0]),
                m[1].goms(self.applied[1]),
                m[2].goms(self.applied[2]),
            ];
            hw.write_escs(self.clock, self.esc_us);
            let [p, v, s] = self.esc_us;
            let line = format!("motors:{p},{v},{s};");
            self.println(uart, &line);
        }
        self.fthr = map(
            (self.applied[0] + self.applied[2]) / 2,
            1000,
            2000,
            -100,
            100,
        ) as f32;
        let ms = self.millis();
        if self.output_timer.elapsed(ms, 1000) {
            let [p, v, s] = self.target;
            self.telemetry(uart, hw, format!("mtarg:{p},{v},{s};"));
            if self.cfg.firmware == FirmwareVersion::V30_0_2 {
                let line = self.mtrmod_line();
                self.telemetry(uart, hw, line);
            }
        }
    }

    /// `thro`/`yaw` on the board: the throttle spread over the port
    /// motor's range (the reverse half divided by its modifier), then the
    /// turn added and the pair shifted back inside 1000..2000.
    pub(super) fn mix_throttle_and_yaw(&mut self) {
        let v = self.cmd.arg(1);
        if self.cmd.is("thro") && (-100..=100).contains(&v) {
            self.trg_throttle = v as f32 / 100.0;
        }
        if self.cmd.is("yaw") && (-100..=100).contains(&v) {
            self.trg_yaw = v as f32 / 100.0;
        }
        let port = self.motors[0];
        let modifier = if self.trg_throttle >= 0.0 {
            port.positive_modifier
        } else {
            port.negative_modifier
        };
        let power = trunc(1500.0 + (500.0 / modifier.abs()) * self.trg_throttle);
        let turn = trunc(self.trg_yaw * 250.0);
        let (p, s) = if self.trg_throttle >= 0.0 {
            let offset = ((turn.abs() + power) - 2000).max(0);
            (power + turn - offset, power - turn - offset)
        } else {
            let offset = (1000 - (power - turn.abs())).max(0);
            (power + turn + offset, power - turn + offset)
        };
        self.target[0] = p;
        self.target[2] = s;
    }

    pub(super) fn pilot_loop(&mut self, uart: &mut Uart) {
        if self.cmd.is("headloff") {
            self.heading_hold = false;
            self.hdg_integral = 0;
            self.tgt_hdg = -500;
            self.push(uart, "yaw", &[1, 0]);
            self.println(uart, "log:heading_hold_disabled;");
            self.println(uart, "targetHeading:DISABLED;");
        }
        if self.cmd.is("headlon") {
            self.heading_hold = true;
            self.tgt_hdg = if self.cmd.arg(0) == 0 {
                trunc(self.hdgd)
            } else {
                self.cmd.arg(1)
            };
            let line = format!(
                "log:heading_hold_enabled on={};\r\ntargetHeading:{};",
                self.tgt_hdg, self.tgt_hdg
            );
            self.println(uart, &line);
        }
        if self.cmd.is("holdHeading_toggle") {
            if self.heading_hold {
                self.push(uart, "headloff", &[0]);
            } else if self.cmd.arg(0) == 0 {
                self.push(uart, "headlon", &[0]);
            } else {
                let a = self.cmd.arg(1);
                self.push(uart, "headlon", &[1, a]);
            }
        }
        if self.cmd.is("deptloff") {
            self.depth_hold = false;
            self.target_depth = 0;
            self.push(uart, "lift", &[1, 0]);
            self.println(uart, "log:depth_hold_disabled;");
            self.println(uart, "targetDepth:DISABLED;");
        }
        if self.cmd.is("deptlon") {
            self.depth_hold = true;
            self.target_depth = if self.cmd.arg(0) == 0 {
                trunc(self.deap * 100.0)
            } else {
                self.cmd.arg(1)
            };
            let line = format!(
                "log:depth_hold_enabled on={};\r\ntargetDepth:{};",
                self.target_depth, self.target_depth
            );
            self.println(uart, &line);
        }
        if self.cmd.is("holdDepth_toggle") {
            if self.depth_hold {
                self.push(uart, "deptloff", &[0]);
            } else if self.cmd.arg(0) == 0 {
                self.push(uart, "deptlon", &[0]);
            } else {
                let a = self.cmd.arg(1);
                self.push(uart, "deptlon", &[1, a]);
            }
        }
        let ms = self.millis();
        if self.pilot_timer.elapsed(ms, 50) {
            if self.depth_hold {
                let depth = trunc(self.deap * 100.0);
                let error = self.target_depth - depth;
                let lift = constrain(trunc(error as f32 * 0.6), -100, 100);
                let line = format!("log:dhold pushing command;\r\ndp_er:{error};");
                self.println(uart, &line);
                let lift = if error.abs() > 4 { lift } else { 0 };
                self.push(uart, "lift", &[1, lift]);
            }
            if self.heading_hold {
                let mut error = trunc(self.hdgd) - self.tgt_hdg;
                if error > 180 {
                    error -= 360;
                }
                if error < -179 {
                    error += 360;
                }
                self.hdg_integral += i64::from(error);
                let yaw = constrain(trunc((-error) as f32), -50, 50);
                let line = format!("log:hold pushing command;\r\np_er:{error};");
                self.println(uart, &line);
                let yaw = if error.abs() > 4 { yaw } else { 0 };
                self.push(uart, "yaw", &[1, yaw]);
            }
        }
    }

    pub(super) fn alt_servo_loop(&mut self, uart: &mut Uart) {
        if self.cmd.is("asrt") {
            let ms = map(self.cmd.arg(1), -100, 100, 1000, 2000);
            if (1000..=2000).contains(&ms) {
                self.alts_target = ms;
                let line = format!("asr.t:{ms};");
                self.println(uart, &line);
            }
        }
        if self.alts_target != self.alts {
            self.alts += (self.alts_target - self.alts).signum();
            let line = format!("asr.v:{};", self.alts);
            self.println(uart, &line);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motor(dz: i32, neg: f32) -> Motor {
        Motor {
            positive_modifier: 1.0,
            negative_modifier: neg,
            deadzone_negative: dz,
            deadzone_positive: dz,
        }
    }

    #[test]
    fn goms_is_the_firmware_mapping() {
        let m = motor(50, 2.0);
        assert_eq!(m.goms(1600), 1640);
        assert_eq!(m.goms(1400), 1270);
        assert_eq!(m.goms(1500), 1500);
        assert_eq!(m.goms(1501), 1550);
        assert_eq!(m.goms(1499), 1448);
        assert_eq!(m.goms(2000), 2000);
        assert_eq!(m.goms(1000), 1000);
        assert_eq!(m.goms(1250), 1000);
        // A 2.5 reverse multiplier is an `int` 2 on the board.
        assert_eq!(motor(50, 2.5).goms(1400), 1270);
        // No deadzone and no multiplier: the target itself.
        for us in [1000, 1234, 1500, 1777, 2000] {
            assert_eq!(i32::from(motor(0, 1.0).goms(us)), us);
        }
    }
}
