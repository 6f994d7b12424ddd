//! The Bosch BNO055 absolute-orientation sensor on the board's I2C bus, at
//! 0x28 as `BNO055.cpp` addresses it: register reads and writes, the chip
//! and sub-sensor ids, self-test, reset, operation mode, unit selection,
//! axis remapping, calibration status, and the fused Euler angles worked
//! out from the vehicle's true attitude.
//!
//! # Why this IMU
//! Firmware 30.0.2 builds two IMU drivers (`AConfig.h`: `HAS_MPU9150 (1)`
//! and `HAS_BNO055 (1)`; `compile.rs` adds no define that changes them, and
//! `BoardConfig.h` is empty). Both probe at start-up; each leaves
//! `navdata` alone while its chip is missing. The MPU9150 path needs the
//! InvenSense DMP: the driver uploads a 3 KB motion-processor image through
//! the chip's memory-bank registers, reads it back to verify, then pulls
//! quaternion packets out of the FIFO, talks to the AK8975 magnetometer
//! behind the chip's I2C pass-through and keeps calibration in EEPROM. The
//! BNO055 does its fusion on-chip: the driver reads the chip id, triggers a
//! reset and a self-test, writes five configuration registers and then
//! reads heading, roll and pitch as three little-endian `i16` from
//! 0x1A..0x1F. So the BNO055 gives the firmware an attitude with the least
//! machinery, and it is the one simulated here.
//!
//! # How the firmware uses it (`BNO055.cpp`, 30.0.2)
//! Set-up: read CHIP_ID (must be 0xA0, else `BNO055.status:failed;` and a
//! retry every 30 s), SYS_TRIGGER = 0x20 (reset), SW_REV, BL_REV and
//! ST_RESULT read and printed, SYS_TRIGGER = 0x01 (self-test), ST_RESULT
//! again; then CONFIG mode, PAGE_ID = 0, AXIS_MAP_CONFIG = 0x24 and
//! AXIS_MAP_SIGN = 0x03 (placement P4, "wires forward, sensors down"),
//! UNIT_SEL = 0x01 (Euler angles in degrees, Windows orientation), PWR_MODE
//! = normal, OPR_MODE = NDOF (0x0C), read back until it reads NDOF. Then
//! every 1000/21 ms it reads the Euler block, and once a second CALIB_STAT
//! and OPR_MODE (printed as `BNO055.CALIB_*` and `BNO055.MODE`; a mode that
//! is not NDOF starts the set-up over).
//!
//! Every single-register read is `Wire.requestFrom` twice, and every block
//! read too, keeping the second transfer's bytes: each read transfer here
//! starts again at the register address the master last wrote and counts
//! up within the transfer, so both transfers see the same registers (as
//! they must have on the ROV, where the driver worked).
//!
//! # The firmware's convention (what Neptunus must convert)
//! With `h`, `r`, `p` the EUL_Heading, EUL_Roll and EUL_Pitch registers:
//! `hdgd = yaw = h / 16`, `roll = −r / 16`, `pitc = p / 16` (degrees, 1/16°
//! steps, printed with two decimals). In the chip's Windows convention, for
//! the frame the remap makes (X starboard, Y forward, Z up, as P4 does for
//! the mounting its comment names), the angles are a heading–roll–pitch
//! sequence (intrinsic Z, then Y, then X: `R = Rz(−h)·Ry(r)·Rx(p)` from
//! that frame to east-north-up). So the board prints:
//! - `hdgd`, `yaw`: 0 ≤ x < 360, clockwise from magnetic north (the fusion
//!   output has no declination); both the same value.
//! - `pitc`: −180..180, rotation about the starboard axis, nose up positive
//!   (applied after the roll).
//! - `roll`: −90..90, rotation about the forward axis, **port side down
//!   positive** (the chip's roll is starboard-down positive; the firmware
//!   negates it).
//!
//! For a pure pitch, or a pure roll, these are the aviation angles (roll
//! negated); with both at once they differ from the aviation ZYX angles
//! because the chip rolls before it pitches: the true attitude heading 200°,
//! pitch 15°, roll 20° prints `hdgd:194.62`, `pitc:15.92`, `roll:-19.29`.
//! To get MAVLink's angles, build `R` above from (`hdgd`, `−roll`, `pitc`)
//! and decompose it as yaw-pitch-roll in (forward, starboard, down) / NED.
//! [`firmware_reading`] is that forward map.
//!
//! The chip's signs are an assumption the datasheet leaves unclear (Table
//! 3-13 gives the ranges: Windows pitch ±180°, roll ±90°, heading 0..360°
//! clockwise; Bosch support answers "right-hand rule" for the Windows
//! format). Hardware-tested drivers agree: INAV's `accgyro_bno055.c` takes
//! the roll register as its roll (right side down positive) and negates the
//! pitch register into its nose-down-positive pitch. Android orientation
//! (UNIT_SEL bit 7) turns the pitch sign round.
//!
//! # What is not modelled
//! Raw accelerometer, magnetometer and gyro data, quaternion, linear
//! acceleration and gravity registers (zeros: the firmware reads none of
//! them), mode switching times, the 650 ms the real chip is deaf after a
//! reset (the firmware waits a second), interrupts, and the relative heading
//! of the non-magnetic fusion mode (IMU mode reads the same absolute heading
//! here). Writes to read-only or reserved registers are counted and dropped.
//!
//! Sans-IO: bytes in, bytes out; it never reads a clock or touches simavr.
//! The `TwiSlave` impl at the bottom is the one seam to the simulated bus.

use std::f64::consts::{PI, TAU};

use nalgebra::{Matrix3, Rotation3};
use serde::Serialize;

use super::avr::TwiSlave;

/// 7-bit address with the COM3 pin low (`BNO055_ADDRESS`).
pub const ADDRESS: u8 = 0x28;

/// Register addresses (page 0 unless said).
pub mod reg {
    pub const CHIP_ID: u8 = 0x00;
    pub const ACC_ID: u8 = 0x01;
    pub const MAG_ID: u8 = 0x02;
    pub const GYR_ID: u8 = 0x03;
    pub const SW_REV_ID_LSB: u8 = 0x04;
    pub const SW_REV_ID_MSB: u8 = 0x05;
    pub const BL_REV_ID: u8 = 0x06;
    /// On both pages.
    pub const PAGE_ID: u8 = 0x07;
    pub const EUL_HEADING_LSB: u8 = 0x1A;
    pub const EUL_ROLL_LSB: u8 = 0x1C;
    pub const EUL_PITCH_LSB: u8 = 0x1E;
    pub const TEMP: u8 = 0x34;
    pub const CALIB_STAT: u8 = 0x35;
    pub const ST_RESULT: u8 = 0x36;
    pub const SYS_STATUS: u8 = 0x39;
    pub const UNIT_SEL: u8 = 0x3B;
    pub const OPR_MODE: u8 = 0x3D;
    pub const PWR_MODE: u8 = 0x3E;
    pub const SYS_TRIGGER: u8 = 0x3F;
    pub const TEMP_SOURCE: u8 = 0x40;
    pub const AXIS_MAP_CONFIG: u8 = 0x41;
    pub const AXIS_MAP_SIGN: u8 = 0x42;
    /// Sensor offsets and radii, 0x55..=0x6A.
    pub const FIRST_OFFSET: u8 = 0x55;
    pub const LAST_OFFSET: u8 = 0x6A;
}

/// Operation modes (OPR_MODE).
pub mod mode {
    pub const CONFIG: u8 = 0x00;
    /// First of the fusion modes (IMU, COMPASS, M4G, NDOF_FMC_OFF, NDOF).
    pub const FIRST_FUSION: u8 = 0x08;
    pub const NDOF: u8 = 0x0C;
}

/// What 30.0.2's `initBNO055` writes: placement P4 and degrees, Windows.
pub const FIRMWARE_AXIS_MAP_CONFIG: u8 = 0x24;
pub const FIRMWARE_AXIS_MAP_SIGN: u8 = 0x03;
pub const FIRMWARE_UNIT_SEL: u8 = 0x01;

/// Software 3.11 and bootloader 21: what 2015 parts report.
const SW_REV: u16 = 0x0311;
const BL_REV: u8 = 0x15;
/// Accelerometer, magnetometer, gyro and MCU self-tests all passed.
const SELF_TEST_PASSED: u8 = 0x0F;
/// System, gyro, accelerometer and magnetometer each fully calibrated (3).
const FULLY_CALIBRATED: u8 = 0xFF;
/// SYS_STATUS: system idle; sensor fusion algorithm running.
const SYS_IDLE: u8 = 0x00;
const SYS_FUSION_RUNNING: u8 = 0x05;
const UNIT_EULER_RADIANS: u8 = 1 << 2;
const UNIT_ANDROID: u8 = 1 << 7;
const TRIGGER_SELF_TEST: u8 = 1 << 0;
const TRIGGER_RESET: u8 = 1 << 5;
/// Euler angles: 16 LSB per degree, or 900 per radian.
const LSB_PER_DEG: f64 = 16.0;
const LSB_PER_RAD: f64 = 900.0;

/// The vehicle's true attitude, in the aviation and MAVLink convention.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct Attitude {
    /// Where the bow points, clockwise from (magnetic) north, 0..360.
    pub heading_deg: f64,
    /// Nose up positive.
    pub pitch_deg: f64,
    /// Starboard side down positive.
    pub roll_deg: f64,
}

impl Attitude {
    /// From (forward, starboard, down) body axes to north-east-down: yaw,
    /// then pitch, then roll (intrinsic Z-Y-X).
    fn body_to_ned(&self) -> Rotation3<f64> {
        Rotation3::from_euler_angles(
            self.roll_deg.to_radians(),
            self.pitch_deg.to_radians(),
            self.heading_deg.to_radians(),
        )
    }
}

/// What the 30.0.2 firmware prints for an attitude, in its own convention
/// (module docs): the values of `hdgd`, `pitc`, `roll` and `yaw`, before
/// the two-decimal printing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirmwareReading {
    pub hdgd_deg: f64,
    pub pitc_deg: f64,
    pub roll_deg: f64,
    pub yaw_deg: f64,
}

/// What firmware 30.0.2 prints with the vehicle at `attitude`: this chip
/// configured as its `initBNO055` configures it, read through its
/// `device_loop` arithmetic.
pub fn firmware_reading(attitude: &Attitude) -> FirmwareReading {
    let mut chip = Bno055::new(attitude);
    chip.write_register(reg::AXIS_MAP_CONFIG, FIRMWARE_AXIS_MAP_CONFIG);
    chip.write_register(reg::AXIS_MAP_SIGN, FIRMWARE_AXIS_MAP_SIGN);
    chip.write_register(reg::UNIT_SEL, FIRMWARE_UNIT_SEL);
    chip.write_register(reg::OPR_MODE, mode::NDOF);
    let [heading, roll, pitch] = chip.euler_registers();
    let deg = |lsb: i16| f64::from(lsb) / 16.0;
    FirmwareReading {
        hdgd_deg: deg(heading),
        pitc_deg: deg(pitch),
        roll_deg: -deg(roll),
        yaw_deg: deg(heading),
    }
}

/// North-east-down to east-north-up, and (forward, starboard, down) to
/// (starboard, forward, up): the same swap of the first two axes and
/// turn of the third.
fn swap_xy_flip_z() -> Matrix3<f64> {
    Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0)
}

/// The chip's own axes in the vehicle's (starboard, forward, up) frame, as
/// placement P4 describes the mounting: x to starboard, y aft, z down.
fn mounting() -> Matrix3<f64> {
    Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, -1.0, -1.0))
}

/// The signed permutation AXIS_MAP_CONFIG/SIGN describe (remapped = P ·
/// chip), or `None` if two remapped axes take the same chip axis.
fn remap_matrix(config: u8, sign: u8) -> Option<Matrix3<f64>> {
    let axes = [config & 3, (config >> 2) & 3, (config >> 4) & 3];
    let mut seen = [false; 3];
    let mut p = Matrix3::zeros();
    for (i, &axis) in axes.iter().enumerate() {
        let a = usize::from(axis);
        if a > 2 || seen[a] {
            return None;
        }
        seen[a] = true;
        // SIGN: bit 2 is remapped X, bit 1 Y, bit 0 Z.
        let negative = sign & (1 << (2 - i)) != 0;
        p[(i, a)] = if negative { -1.0 } else { 1.0 };
    }
    Some(p)
}

fn page0_defaults() -> [u8; 128] {
    let mut r = [0u8; 128];
    r[usize::from(reg::CHIP_ID)] = 0xA0;
    r[usize::from(reg::ACC_ID)] = 0xFB;
    r[usize::from(reg::MAG_ID)] = 0x32;
    r[usize::from(reg::GYR_ID)] = 0x0F;
    let [sw_msb, sw_lsb] = SW_REV.to_be_bytes();
    r[usize::from(reg::SW_REV_ID_LSB)] = sw_lsb;
    r[usize::from(reg::SW_REV_ID_MSB)] = sw_msb;
    r[usize::from(reg::BL_REV_ID)] = BL_REV;
    r[usize::from(reg::TEMP)] = 25;
    r[usize::from(reg::CALIB_STAT)] = FULLY_CALIBRATED;
    // The power-on self-test's result.
    r[usize::from(reg::ST_RESULT)] = SELF_TEST_PASSED;
    // Windows orientation: Bosch's answer to the register map's 0x80, which
    // its own text contradicts.
    r[usize::from(reg::UNIT_SEL)] = 0x00;
    r[usize::from(reg::OPR_MODE)] = mode::CONFIG;
    r[usize::from(reg::AXIS_MAP_CONFIG)] = 0x24;
    r[usize::from(reg::AXIS_MAP_SIGN)] = 0x00;
    r
}

fn page1_defaults() -> [u8; 128] {
    let mut r = [0u8; 128];
    r[usize::from(reg::PAGE_ID)] = 1;
    r
}

/// The chip's state between bytes.
#[derive(Debug, Clone)]
pub struct Bno055 {
    page0: [u8; 128],
    page1: [u8; 128],
    attitude: Attitude,
    /// The register address the master wrote last: where a read starts.
    pointer: u8,
    /// The register the next data byte goes to or comes from.
    cursor: u8,
    /// The next byte written is a register address.
    awaiting_address: bool,
    /// The Euler block as it was when the read transfer started, so that a
    /// new attitude mid-transfer cannot tear a value.
    euler_latch: [u8; 6],
    /// Writes to read-only or reserved registers, and invalid values,
    /// counted and dropped.
    pub ignored_writes: u64,
}

impl Bno055 {
    /// A chip just powered, in a vehicle at `attitude`.
    pub fn new(attitude: &Attitude) -> Self {
        Self {
            page0: page0_defaults(),
            page1: page1_defaults(),
            attitude: *attitude,
            pointer: 0,
            cursor: 0,
            awaiting_address: false,
            euler_latch: [0; 6],
            ignored_writes: 0,
        }
    }

    pub fn attitude(&self) -> Attitude {
        self.attitude
    }

    /// The vehicle's new attitude, in the fusion output from the next read.
    pub fn set_attitude(&mut self, attitude: &Attitude) {
        self.attitude = *attitude;
    }

    /// The operation mode (OPR_MODE).
    pub fn mode(&self) -> u8 {
        self.page0[usize::from(reg::OPR_MODE)]
    }

    fn fusion(&self) -> bool {
        (mode::FIRST_FUSION..=mode::NDOF).contains(&self.mode())
    }

    fn on_page1(&self) -> bool {
        self.page0[usize::from(reg::PAGE_ID)] == 1
    }

    /// EUL_Heading, EUL_Roll, EUL_Pitch as the registers hold them: zeros
    /// outside the fusion modes.
    pub fn euler_registers(&self) -> [i16; 3] {
        if !self.fusion() {
            return [0; 3];
        }
        let unit_sel = self.page0[usize::from(reg::UNIT_SEL)];
        let Some(remap) = remap_matrix(
            self.page0[usize::from(reg::AXIS_MAP_CONFIG)],
            self.page0[usize::from(reg::AXIS_MAP_SIGN)],
        ) else {
            return [0; 3];
        };
        let m = swap_xy_flip_z();
        // Remapped axes → east-north-up: through the chip's own axes, the
        // vehicle's (starboard, forward, up) and its (forward, starboard, down).
        let r = m * self.attitude.body_to_ned().matrix() * m * mounting() * remap.transpose();
        let roll = (-r[(2, 0)]).clamp(-1.0, 1.0).asin();
        let mut pitch = r[(2, 1)].atan2(r[(2, 2)]);
        let heading = (-r[(1, 0)].atan2(r[(0, 0)])).rem_euclid(TAU);
        if unit_sel & UNIT_ANDROID != 0 {
            pitch = -pitch;
        }
        let lsb_per_rad = if unit_sel & UNIT_EULER_RADIANS != 0 {
            LSB_PER_RAD
        } else {
            LSB_PER_DEG * 180.0 / PI
        };
        let lsb = |rad: f64| (rad * lsb_per_rad).round();
        let full_turn = lsb(TAU);
        let mut h = lsb(heading);
        if h >= full_turn {
            h -= full_turn;
        }
        // All within ±2π × 900 < 2^15.
        [h as i16, lsb(roll) as i16, lsb(pitch) as i16]
    }

    /// One register as the master reads it.
    pub fn read_register(&self, addr: u8) -> u8 {
        let a = usize::from(addr);
        if a >= 128 {
            return 0;
        }
        if self.on_page1() {
            return self.page1[a];
        }
        match addr {
            reg::EUL_HEADING_LSB..=0x1F => self.euler_latch[a - usize::from(reg::EUL_HEADING_LSB)],
            reg::SYS_STATUS if self.fusion() => SYS_FUSION_RUNNING,
            reg::SYS_STATUS => SYS_IDLE,
            _ => self.page0[a],
        }
    }

    /// One register as the master writes it.
    pub fn write_register(&mut self, addr: u8, value: u8) {
        let a = usize::from(addr);
        if addr == reg::PAGE_ID {
            match value {
                0 | 1 => {
                    self.page0[a] = value;
                    self.page1[a] = 1;
                }
                _ => self.ignored_writes += 1,
            }
            return;
        }
        if self.on_page1() {
            // Page 1: sensor configuration, kept and read back, not acted on.
            if (0x08..=0x1F).contains(&addr) {
                self.page1[a] = value;
            } else {
                self.ignored_writes += 1;
            }
            return;
        }
        match addr {
            reg::UNIT_SEL | reg::PWR_MODE | reg::TEMP_SOURCE => self.page0[a] = value,
            reg::OPR_MODE => self.page0[a] = value & 0x0F,
            reg::SYS_TRIGGER => {
                if value & TRIGGER_RESET != 0 {
                    // A reset is a power-up: it also reruns the self-test.
                    self.page0 = page0_defaults();
                    self.page1 = page1_defaults();
                } else if value & TRIGGER_SELF_TEST != 0 {
                    self.page0[usize::from(reg::ST_RESULT)] = SELF_TEST_PASSED;
                }
            }
            reg::AXIS_MAP_CONFIG => {
                let sign = self.page0[usize::from(reg::AXIS_MAP_SIGN)];
                if remap_matrix(value, sign).is_some() {
                    self.page0[a] = value;
                } else {
                    self.ignored_writes += 1;
                }
            }
            reg::AXIS_MAP_SIGN => self.page0[a] = value & 0x07,
            reg::FIRST_OFFSET..=reg::LAST_OFFSET => self.page0[a] = value,
            _ => self.ignored_writes += 1,
        }
    }

    fn latch_euler(&mut self) {
        let [h, r, p] = self.euler_registers();
        let (h, r, p) = (h.to_le_bytes(), r.to_le_bytes(), p.to_le_bytes());
        self.euler_latch = [h[0], h[1], r[0], r[1], p[0], p[1]];
    }

    /// The master addressed the chip: a write starts with a register
    /// address; a read starts at the address written last.
    pub fn start(&mut self, read: bool) {
        if read {
            self.cursor = self.pointer;
            self.latch_euler();
        } else {
            self.awaiting_address = true;
        }
    }

    /// A byte the master wrote: the register address, then data for it and
    /// the registers after it.
    pub fn write(&mut self, byte: u8) {
        if self.awaiting_address {
            self.awaiting_address = false;
            self.pointer = byte;
            self.cursor = byte;
        } else {
            self.write_register(self.cursor, byte);
            self.cursor = self.cursor.wrapping_add(1);
        }
    }

    /// The next byte the master clocks out, counting up the registers.
    pub fn read(&mut self) -> u8 {
        let b = self.read_register(self.cursor);
        self.cursor = self.cursor.wrapping_add(1);
        b
    }
}

impl TwiSlave for Bno055 {
    fn address(&self) -> u8 {
        ADDRESS
    }
    fn start(&mut self, read: bool, _cycle: u64) {
        Bno055::start(self, read);
    }
    fn write(&mut self, byte: u8, _cycle: u64) {
        Bno055::write(self, byte);
    }
    fn read(&mut self, _cycle: u64) -> u8 {
        Bno055::read(self)
    }
    fn stop(&mut self, _cycle: u64) {}
}

#[cfg(test)]
mod tests;
