//! The devices' set-up and the per-pass dispatch in registration order,
//! and the small ones: `Settings` (`rcap`'s scan and delay, the settings
//! report), `Controller25` (its ADC lines), `Lights`, the laser, the
//! camera servo, `DeadManSwitch`.

use std::time::Duration;

use super::{
    ADC_READ, DELAY_TO_ARM_MS, Device, FirmwareVersion, Hardware, I2C_BYTE, MPU9150_ADDRESS,
    MS5803_ADDRESS, Sketch,
};
use crate::firmware::emulator::arduino::{float, mapf, trunc};
use crate::firmware::emulator::uart::Uart;
use crate::sim::Readings;

impl Sketch {
    pub(super) fn device_setup(&mut self, device: Device, uart: &mut Uart, hw: &mut dyn Hardware) {
        let ms = self.millis();
        match device {
            Device::Settings => {}
            Device::Controller25 => {
                self.adc_timer.reset(ms);
                self.status_timer.reset(ms);
                self.brdt_timer.reset(ms);
                if self.cfg.firmware == FirmwareVersion::V30_0_2 {
                    // The I2C bus's power cycled.
                    self.delay(Duration::from_millis(10));
                }
            }
            Device::Lights => self.capabilities |= 1 << 1,
            Device::Laser => self.capabilities |= 1 << 2,
            Device::Thrusters => {
                for m in &mut self.motors {
                    m.deadzone_negative = self.deadzone_min;
                    m.deadzone_positive = self.deadzone_max;
                }
                self.output_timer.reset(ms);
                self.control_timer.reset(ms);
                self.escs_powered = true;
                hw.esc_power(self.clock, true);
                hw.write_escs(self.clock, self.esc_us);
            }
            Device::Pilot => {
                self.pilot_timer.reset(ms);
                self.println(uart, "log:pilot setup complete;");
            }
            Device::CameraMount => self.capabilities |= 1 << 3,
            Device::AltServo => self.capabilities |= 1 << 7,
            Device::Mpu9150 => self.mpu_setup(uart),
            Device::Ms5803 => self.ms5803_setup(uart),
            Device::DeadMan => {
                self.capabilities |= 1 << 1;
                self.dms_timer.reset(ms);
                self.blink_timer.reset(ms);
            }
            Device::Bno055 => self.bno055_setup(uart),
        }
    }

    pub(super) fn device_loop(&mut self, device: Device, uart: &mut Uart, hw: &mut dyn Hardware) {
        match device {
            Device::Settings => self.settings_loop(uart),
            Device::Controller25 => self.controller_loop(uart, hw),
            Device::Lights => self.lights_loop(uart),
            Device::Laser => {
                if self.cmd.is("claser") {
                    self.laser = self.cmd.arg(1);
                    let text = format!("claser:{};", self.laser);
                    self.print(uart, text.as_bytes());
                }
            }
            Device::Thrusters => self.thrusters_loop(uart, hw),
            Device::Pilot => self.pilot_loop(uart),
            Device::CameraMount => {
                if self.cmd.is("tilt") {
                    let v = self.cmd.arg(1);
                    if v > 999 && v < 2001 {
                        self.cmtg = v;
                    }
                }
                if self.cmtg != self.cmnt {
                    self.cmnt += (self.cmtg - self.cmnt).signum();
                }
            }
            Device::AltServo => self.alt_servo_loop(uart),
            Device::Mpu9150 => self.mpu_loop(uart, hw),
            Device::Ms5803 => self.ms5803_loop(uart, hw),
            Device::DeadMan => self.dead_man_loop(uart),
            Device::Bno055 => {
                let ms = self.millis();
                // Never found: set-up is retried every 30 s.
                if self.bno_sample_timer.elapsed(ms, 1000 / 21)
                    && self.bno_report_timer.elapsed(ms, 30_000)
                {
                    self.bno055_setup(uart);
                }
            }
        }
    }

    pub(super) fn settings_loop(&mut self, uart: &mut Uart) {
        if self.cmd.is("reportSetting") {
            let line = format!(
                "*settings:smoothingIncriment|{},deadZone_min|{},deadZone_max|{};water_type{};",
                self.smoothing,
                self.deadzone_min,
                self.deadzone_max,
                u8::from(self.water_salt)
            );
            self.println(uart, &line);
        } else if self.cmd.is("rcap") {
            let capa = format!("CAPA:{};", self.capabilities);
            self.print(uart, capa.as_bytes());
            self.scan_i2c(uart);
        } else if self.cmd.is("updateSetting") {
            self.smoothing = self.cmd.arg(1);
            self.deadzone_min = self.cmd.arg(2);
            self.deadzone_max = self.cmd.arg(3);
            self.water_salt = self.cmd.arg(4) != 0;
        }
    }

    /// `Settings::scan_i2c`: every address probed, the ones that answer
    /// listed, then five seconds of `delay` in which the board reads
    /// nothing (its receive ring fills, then loses bytes).
    pub(super) fn scan_i2c(&mut self, uart: &mut Uart) {
        self.println(uart, "log:Scanning...;");
        let mut found = 0;
        for address in 1u8..127 {
            self.delay(I2C_BYTE);
            let answers = (address == MPU9150_ADDRESS && self.cfg.sensors.mpu9150)
                || (address == MS5803_ADDRESS && self.cfg.sensors.ms5803);
            if answers {
                let line = format!("log:I2C device found at address 0x{address:02X}  !;");
                self.println(uart, &line);
                found += 1;
            }
        }
        if found == 0 {
            self.println(uart, "log:No I2C devices found\n;");
        } else {
            self.println(uart, "log:done\n;");
        }
        self.delay(Duration::from_secs(5));
    }

    pub(super) fn controller_loop(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        let ms = self.millis();
        if self.adc_timer.elapsed(ms, 100) {
            self.delay(ADC_READ);
        }
        let ms = self.millis();
        if self.brdt_timer.elapsed(ms, 1000) {
            // Ten conversions and readVcc's 2 ms for its reference.
            self.delay(ADC_READ * 9 + Duration::from_millis(2));
            let p = Power::of(&hw.read_power(self.clock));
            let line = format!(
                "BRDT:{};SC1I:{};SC2I:{};SC3I:{};BRDI:{};BT1I:{};BT2I:{};BRDV:{};AVCC:{};",
                float(p.board_temp_c()),
                float(0.0),
                float(0.0),
                float(0.0),
                float(p.board_current_a()),
                float(p.tube_current_a(0)),
                float(p.tube_current_a(1)),
                float(p.battery_v()),
                Power::AVCC_MV
            );
            self.telemetry(uart, hw, line);
        }
        let ms = self.millis();
        if self.status_timer.elapsed(ms, 100) {
            self.delay(ADC_READ * 2);
            let p = Power::of(&hw.read_power(self.clock));
            self.vout = p.battery_v();
            self.iout = p.board_current_a();
            self.fmem = self.build.free_memory;
            self.utim = self.millis() as f32;
        }
    }

    pub(super) fn lights_loop(&mut self, uart: &mut Uart) {
        if self.cmd.is("ligt") {
            let value = self.cmd.arg(1);
            self.lights = value;
            let line = format!("LIGT:{value};LIGP:{};", float(value as f32 / 255.0));
            self.println(uart, &line);
        }
        if self.cfg.firmware == FirmwareVersion::V30_0_2 && self.cmd.is("eligt") {
            let percent = self.cmd.arg(1) as f32 / 100.0;
            let value = trunc(255.0 * percent);
            let line = format!("LIGTE:{value};LIGPE:{};", float(percent));
            self.println(uart, &line);
        }
    }

    pub(super) fn dead_man_loop(&mut self, uart: &mut Uart) {
        let ms = self.millis();
        if !self.dms_armed && ms > DELAY_TO_ARM_MS {
            self.dms_armed = true;
        }
        if self.cmd.is("ping") {
            self.dms_timer.reset(ms);
            if self.dms_tripped {
                self.push(uart, "start", &[0]);
                self.dms_tripped = false;
            }
            let pong = format!("pong:{},{};", self.cmd.arg(0), self.millis());
            self.print(uart, pong.as_bytes());
        }
        let ms = self.millis();
        // The timer restarts every 2 s whether or not the switch is armed.
        if self.dms_timer.elapsed(ms, 2000) && self.dms_armed && !self.dms_tripped {
            self.push(uart, "deptloff", &[0]);
            self.push(uart, "headloff", &[0]);
            self.push(uart, "stop", &[0]);
            self.dms_tripped = true;
        }
        let ms = self.millis();
        if self.dms_tripped && self.blink_timer.elapsed(ms, 500) {
            let level = if self.blink_state { 0 } else { 50 };
            self.push(uart, "ligt", &[1, level]);
            self.blink_state = !self.blink_state;
        }
        if self.cmd.is("dms") {
            self.dms_armed = self.cmd.arg(0) != 0;
        }
    }
}

/// The controller board's analog inputs as its ADC converts them (10 bits
/// against 5 V) and the sketch scales them back.
struct Power {
    battery_code: i32,
    board_code: i32,
    tube_codes: [i32; 2],
    temp_code: i32,
}

impl Power {
    /// `readVcc()` of a 5.0 V supply: 1125300 / 225.
    const AVCC_MV: i32 = 5001;
    /// The board's own temperature sensor (the simulator has none).
    const BOARD_TEMP_C: f64 = 25.0;

    pub(super) fn code(value: f64, full_scale: f64) -> i32 {
        if value.is_finite() {
            (value / full_scale * 1023.0).round().clamp(0.0, 1023.0) as i32
        } else {
            0
        }
    }

    pub(super) fn of(r: &Readings) -> Self {
        let temp_v = Self::BOARD_TEMP_C / 51.28 + 0.4;
        Self {
            battery_code: Self::code(r.vout_v, 20.0),
            board_code: Self::code(r.iout_a, 2.0),
            // Two battery tubes share the vehicle's current.
            tube_codes: [Self::code(r.btti_a / 2.0, 10.0); 2],
            temp_code: (temp_v / 5.0 * 1024.0).round() as i32,
        }
    }
    pub(super) fn battery_v(&self) -> f32 {
        mapf(self.battery_code, 0, 1023, 0, 20)
    }
    pub(super) fn board_current_a(&self) -> f32 {
        mapf(self.board_code, 0, 1023, 0, 2)
    }
    pub(super) fn tube_current_a(&self, i: usize) -> f32 {
        mapf(self.tube_codes[i], 0, 1023, 0, 10)
    }
    pub(super) fn board_temp_c(&self) -> f32 {
        let volt = mapf(self.temp_code, 0, 1024, 0, 5);
        (volt - 0.4) * 51.28
    }
}
