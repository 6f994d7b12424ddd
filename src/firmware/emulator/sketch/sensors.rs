//! The I2C sensors as the firmware drives them, found or not: the MPU-9150
//! (set-up chatter, a read every 50 ms, `ccal()`'s countdown), the
//! MS5803-14BA (its PROM, a sample a second or the failure line, `dzer`,
//! `dtwa`) and the BNO055 probe that never finds one.

use std::time::Duration;

use super::{
    FirmwareVersion, Hardware, I2C_BYTE, MPU_DMP_LOAD, MPU_READ, MPU_RESET, MS5803_PROM,
    MS5803_PROM_WORDS, Sketch,
};
use crate::firmware::emulator::arduino::float;
use crate::firmware::emulator::uart::Uart;

impl Sketch {
    pub(super) fn mpu_setup(&mut self, uart: &mut Uart) {
        let ms = self.millis();
        let found = self.cfg.sensors.mpu9150;
        match self.cfg.firmware {
            FirmwareVersion::V30_0_2 => {
                self.mpu_reinit_timer.reset(ms);
                self.mpu_update_timer.reset(ms);
                // Probed at 0x68, then 0x69.
                self.delay(I2C_BYTE * 2);
                if !found {
                    self.println(uart, "MPU9150.status:Not found;");
                    return;
                }
                self.mpu_init_chip(uart);
                self.capabilities |= (1 << 4) | (1 << 5);
            }
            FirmwareVersion::V2014_12 => {
                if found {
                    self.mpu_init_chip(uart);
                } else {
                    self.delay(I2C_BYTE);
                    self.println(uart, "mpu_init failed with code: -1");
                    self.println(uart, "log:Trying other MPU9150 address to init;");
                    self.mpu_device_id = !self.mpu_device_id;
                    let line = format!(
                        "log:IMU Address was :1 but is now:{};",
                        u8::from(self.mpu_device_id)
                    );
                    self.println(uart, &line);
                    self.delay(I2C_BYTE);
                    self.println(uart, "mpu_init failed with code: -1");
                    self.println(uart, "log:Failed to init on both addresses;");
                }
                self.capabilities |= (1 << 4) | (1 << 5);
                let ms = self.millis();
                self.mpu_reinit_timer.reset(ms);
                self.mpu_update_timer.reset(ms);
            }
        }
    }

    /// `MPU9150Lib::init` on a chip that answers at its primary address.
    pub(super) fn mpu_init_chip(&mut self, uart: &mut Uart) {
        self.delay(MPU_RESET);
        self.println(uart, "Loading firmware");
        self.delay(MPU_DMP_LOAD);
        self.mpu_init = true;
        self.println(uart, "log:init on primary addresses;");
    }

    pub(super) fn mpu_loop(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        let ms = self.millis();
        if !self.mpu_init {
            if self.mpu_reinit_timer.elapsed(ms, 30_000) {
                self.mpu_setup(uart);
            }
            return;
        }
        if self.cmd.is("ccal") {
            self.cal_counter = 359;
            self.calibrating = true;
            self.cal_timer.reset(ms);
            self.println(
                uart,
                "!!!:While the compass counts down from 360 to 0, rotate the ROV slowly in all three axis;",
            );
        }
        if self.calibrating {
            if self.cal_counter > 0 && self.cal_timer.elapsed(self.millis(), 1000) {
                self.cal_counter -= 1;
                self.hdgd = self.cal_counter as f32;
                let text = format!("hdgd:{};", float(self.hdgd));
                self.print(uart, text.as_bytes());
            }
            if self.cal_counter <= 0 {
                self.println(uart, "log:Accel cal data saved for device;");
                self.calibrating = false;
            }
            return;
        }
        if self.mpu_update_timer.elapsed(ms, 50) {
            self.delay(MPU_READ);
            let r = hw.read_sensors(self.clock);
            // The fused yaw, moved into 0..360 (the simulator's heading).
            self.hdgd = r.heading_deg as f32;
            self.pitc = r.pitch_deg as f32;
            self.roll = r.roll_deg as f32;
            self.yaw = r.yaw_deg as f32;
        }
    }

    pub(super) fn ms5803_setup(&mut self, uart: &mut Uart) {
        self.capabilities |= 1 << 6;
        let words = if self.cfg.sensors.ms5803 {
            MS5803_PROM_WORDS
        } else {
            // Nothing answers: the bytes read stay 0.
            [0; 8]
        };
        match self.cfg.firmware {
            FirmwareVersion::V30_0_2 => {
                self.println(uart, "log:Depth Sensor setup;");
                self.println(uart, "MS5803.status: initialized I2C;");
                self.delay(Duration::from_millis(10) + I2C_BYTE);
                self.delay(Duration::from_millis(10));
                self.println(uart, "MS5803.status: reset;");
                self.delay(MS5803_PROM);
                self.println(uart, "Depth: Calibration constants are:");
                for (i, w) in words.iter().enumerate() {
                    let line = format!("Depth.C{i}:{w};");
                    self.println(uart, &line);
                }
            }
            FirmwareVersion::V2014_12 => {
                self.println(uart, "Depth Sensor setup.");
                self.println(uart, "Depth Sensor: initialized I2C");
                self.delay(Duration::from_millis(10) + I2C_BYTE);
                self.delay(Duration::from_millis(10));
                self.println(uart, "Depth Sensor is reset");
                self.delay(MS5803_PROM);
                self.println(uart, "Depth: Calibration constants are:");
            }
        }
        let ms = self.millis();
        self.depth_timer.reset(ms);
    }

    pub(super) fn ms5803_loop(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        if self.cmd.is("dzer") {
            self.depth_offset = self.depth;
        } else if self.cmd.is("dtwa") {
            self.water_salt = !self.water_salt;
            let line = if self.water_salt {
                "dtwa:1;"
            } else {
                "dtwa:0;"
            };
            self.println(uart, line);
        }
        let ms = self.millis();
        if !self.depth_timer.elapsed(ms, 1000) {
            return;
        }
        // D1: convert, wait 10 ms, read.
        self.delay(I2C_BYTE + Duration::from_millis(10) + I2C_BYTE);
        if !self.cfg.sensors.ms5803 {
            // Nothing answers: 20 ms of waiting for three bytes, then this
            // line, printed without its `;`.
            self.delay(Duration::from_millis(21));
            self.println(uart, "log:Failed to read Depth from I2C");
            return;
        }
        self.delay(I2C_BYTE * 4);
        // D2, the same.
        self.delay(I2C_BYTE + Duration::from_millis(10) + I2C_BYTE * 5);
        let r = hw.read_sensors(self.clock);
        if self.cfg.firmware == FirmwareVersion::V2014_12 {
            let line = format!(
                "First-Order Temperature in Degrees C is {}\r\nSecond-Order Temperature in Degrees C is {}",
                float(r.temp_c as f32),
                float(r.temp_c as f32)
            );
            self.println(uart, &line);
        }
        self.temp = r.temp_c as f32;
        self.pres = r.pressure_mbar as f32;
        // The simulator's water is fresh, as the board's is by default:
        // its reading (with any wild point) is the board's depth. Set for
        // salt water, the board's own conversion applies.
        self.depth = if self.water_salt {
            (self.pres - 1015.0) * 0.9945 / 100.0
        } else {
            r.depth_m as f32
        };
        self.deap = self.depth - self.depth_offset;
    }

    pub(super) fn bno055_setup(&mut self, uart: &mut Uart) {
        self.delay(I2C_BYTE * 4);
        self.println(
            uart,
            "BNO055.Address:40;\r\nBNO055.WHO_AM_I:0;\r\nBNO055.IAM_160:255;\r\nBNO055.status:failed;",
        );
        let ms = self.millis();
        self.bno_sample_timer.reset(ms);
        self.bno_report_timer.reset(ms);
    }
}
