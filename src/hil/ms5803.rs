//! The MS5803-14BA depth sensor on the board's I2C bus, as its datasheet
//! describes it: a slave at 0x76 (CSB high, as `AConfig.h` wires it) that
//! takes reset, PROM-read, D1/D2-conversion and ADC-read commands and
//! answers with calibration words and 24-bit raw readings.
//!
//! Owns the sensor's protocol (sans-IO: bytes in, bytes out, time as an
//! argument), its calibration PROM with the datasheet's CRC-4, and the
//! arithmetic that turns a water depth and temperature into the raw D1/D2
//! the firmware must read to print them back: the inverse of the
//! compensation the firmware really applies (`MS5803_14BALib.cpp`,
//! `TemperatureCorrectedPressure_2`: first order plus the datasheet's
//! second-order terms, in integers) and of its depth formula
//! (`MS5803_14BA.cpp`). It never reads a clock or touches simavr; the
//! `TwiSlave` impl at the bottom is the one seam to the simulated bus.

use serde::Serialize;

use super::avr::{F_CPU_HZ, TwiSlave};

/// 7-bit address with the CSB pin high (`MS5803___BA_I2C_ADDRESS`).
pub const ADDRESS: u8 = 0x76;

/// The firmware's surface pressure (`AtmosPressure`, mbar): depth is
/// measured from it.
pub const FIRMWARE_ATMOSPHERE_MBAR: f64 = 1015.0;
/// The firmware's metres per decibar in fresh water (`WaterDensity`).
const FRESH_M_PER_DBAR: f64 = 1.019716;
/// Its salt-water figure (Seabird app note 69, in `MS5803_14BA.cpp`).
const SALT_M_PER_DBAR: f64 = 0.9945;

/// Datasheet-typical calibration of a 14BA. Word 0 (factory data) is 0: the
/// firmware takes a non-zero word 0 for a newer MS5803 and divides by 2^13
/// instead of the 14BA's 2^15. Word 7's low nibble is the CRC, filled in by
/// [`Prom::typical`].
const TYPICAL_WORDS: [u16; 8] = [0, 46372, 43981, 29059, 27842, 31553, 28165, 0];

/// Slowest conversion time per oversampling ratio (OSR 256 … 4096), µs.
const CONVERSION_US: [u64; 5] = [600, 1170, 2280, 4540, 9040];

/// The water the sensor is in, as the runner is told it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Water {
    /// Depth below the surface the firmware zeroes on (m).
    pub depth_m: f64,
    /// Water temperature at the sensor (°C).
    pub temp_c: f64,
    /// Whether the firmware was switched to salt water (`dtwa`): it then
    /// turns pressure into depth with its salt-water factor.
    pub salt_water: bool,
}

impl Default for Water {
    fn default() -> Self {
        Self {
            depth_m: 0.0,
            temp_c: 20.0,
            salt_water: false,
        }
    }
}

impl Water {
    /// Absolute pressure (mbar) that the firmware's own formula turns back
    /// into `depth_m`: `Depth = (P − AtmosPressure) × factor / 100`.
    pub fn pressure_mbar(&self) -> f64 {
        let m_per_dbar = if self.salt_water {
            SALT_M_PER_DBAR
        } else {
            FRESH_M_PER_DBAR
        };
        FIRMWARE_ATMOSPHERE_MBAR + self.depth_m * 100.0 / m_per_dbar
    }
}

/// The sensor's eight 16-bit PROM words: factory data, C1..C6, CRC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Prom(pub [u16; 8]);

impl Prom {
    /// The datasheet's typical coefficients with a valid CRC.
    pub fn typical() -> Self {
        Self::with_crc(TYPICAL_WORDS)
    }

    /// `words` with the CRC-4 of the others in word 7's low nibble.
    pub fn with_crc(mut words: [u16; 8]) -> Self {
        words[7] = (words[7] & 0xFFF0) | u16::from(crc4(&words));
        Self(words)
    }

    /// The datasheet's CRC-4 (polynomial x⁴ + x + 1) over the 16 PROM bytes,
    /// high byte first, with word 7's low byte (where the CRC sits) as zero.
    pub fn crc_ok(&self) -> bool {
        crc4(&self.0) == (self.0[7] & 0x000F) as u8
    }

    fn c(&self, i: usize) -> i64 {
        i64::from(self.0[i])
    }
}

/// CRC-4 of the PROM as the datasheet computes it: a 16-bit remainder takes
/// each byte in its low half, then eight steps of shifting left and, when a
/// one leaves the top, folding in the polynomial aligned to the top nibble.
pub fn crc4(words: &[u16; 8]) -> u8 {
    const POLY_TOP: u16 = 0x3000; // x^4 + x + 1 without its x^4, at bits 15..12
    let mut rem: u16 = 0;
    for (i, &word) in words.iter().enumerate() {
        let word = if i == 7 { word & 0xFF00 } else { word };
        for byte in word.to_be_bytes() {
            rem ^= u16::from(byte);
            for _ in 0..8 {
                let top = rem & 0x8000 != 0;
                rem <<= 1;
                if top {
                    rem ^= POLY_TOP;
                }
            }
        }
    }
    ((rem >> 12) & 0x000F) as u8
}

/// What the firmware prints from D1 and D2, computed as it computes them.
impl Prom {
    /// `pres` in tenths of a mbar: `TemperatureCorrectedPressure_2`'s integer
    /// arithmetic (first order, second-order OFF2/SENS2, its divisor).
    pub fn firmware_pressure_dmbar(&self, d1: u32, d2: u32) -> i64 {
        let dt = i64::from(d2 as i32 - (self.0[5] as i32) * 256);
        let temp = 2000 + dt * self.c(6) / (1 << 23);
        let t = temp - 2000;
        let (mut off2, mut sens2) = if temp < 2000 {
            (3 * (t * t) / 2, 5 * (t * t) / 8)
        } else {
            (t * t / 16, 0)
        };
        if temp < -1500 {
            let u = temp + 1500;
            off2 += 7 * u * u;
            sens2 += 4 * u * u;
        }
        let off = self.c(2) * 65536 + self.c(4) * dt / 128 - off2;
        let sens = self.c(1) * 32768 + self.c(3) * dt / 256 - sens2;
        let divisor = if self.0[0] != 0 { 8192 } else { 32768 };
        i64::from(((i64::from(d1) * sens / 2_097_152 - off) / divisor) as i32)
    }

    /// `temp` in °C: `CorrectedTemperature` (first order minus the
    /// second-order T2, in floating point).
    pub fn firmware_temperature_c(&self, d2: u32) -> f64 {
        let dt = f64::from(d2) - f64::from(self.0[5]) * 256.0;
        let temp = 2000.0 + dt * f64::from(self.0[6]) / 2f64.powi(23);
        let t2 = if temp < 2000.0 {
            3.0 * dt * dt / 2f64.powi(33)
        } else {
            7.0 * dt * dt / 2f64.powi(37)
        };
        temp / 100.0 - t2 / 100.0
    }

    /// Raw `(D1, D2)` that the firmware turns into `pressure_mbar` and
    /// `temp_c` (nearest it can print), clamped to the 24-bit ADC range.
    pub fn raw_for(&self, pressure_mbar: f64, temp_c: f64) -> (u32, u32) {
        // Both are monotonic in their raw value over the whole 24-bit range
        // (the second-order terms are too small to turn them round).
        let d2 = nearest(temp_c, |d2| self.firmware_temperature_c(d2));
        let target = (pressure_mbar * 10.0).round();
        let d1 = nearest(target, |d1| self.firmware_pressure_dmbar(d1, d2) as f64);
        (d1, d2)
    }
}

const ADC_MAX: u32 = (1 << 24) - 1;

/// The raw value in 0..2^24 whose `f` is nearest `target`, for a
/// non-decreasing `f`.
fn nearest(target: f64, f: impl Fn(u32) -> f64) -> u32 {
    let (mut lo, mut hi) = (0u32, ADC_MAX);
    // Smallest raw value with f >= target.
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if f(mid) >= target {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    if lo > 0 && (target - f(lo - 1)).abs() <= (f(lo) - target).abs() {
        lo - 1
    } else {
        lo
    }
}

/// Which raw value a conversion measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Channel {
    Pressure,
    Temperature,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Conversion {
    channel: Channel,
    done_us: u64,
}

/// The sensor's state between bytes.
#[derive(Debug, Clone)]
pub struct Ms5803 {
    prom: Prom,
    d1: u32,
    d2: u32,
    conversion: Option<Conversion>,
    /// The last finished conversion, for the next ADC read.
    adc: u32,
    /// Bytes the master reads next, MSB first.
    reply: [u8; 3],
    reply_len: usize,
    reply_pos: usize,
    /// Commands the datasheet does not list, counted and ignored.
    pub unknown_commands: u64,
}

impl Ms5803 {
    /// A sensor with `prom` in `water`.
    pub fn new(prom: Prom, water: &Water) -> Self {
        let mut s = Self {
            prom,
            d1: 0,
            d2: 0,
            conversion: None,
            adc: 0,
            reply: [0; 3],
            reply_len: 0,
            reply_pos: 0,
            unknown_commands: 0,
        };
        s.set_water(water);
        s
    }

    pub fn prom(&self) -> Prom {
        self.prom
    }

    /// The raw `(D1, D2)` a conversion started now would measure.
    pub fn raw(&self) -> (u32, u32) {
        (self.d1, self.d2)
    }

    /// New surroundings from the next conversion on.
    pub fn set_water(&mut self, water: &Water) {
        (self.d1, self.d2) = self.prom.raw_for(water.pressure_mbar(), water.temp_c);
    }

    /// One command byte written to the sensor at `now_us`.
    pub fn command(&mut self, byte: u8, now_us: u64) {
        self.reply_len = 0;
        self.reply_pos = 0;
        match byte {
            0x1E => {
                // Reset reloads the PROM; a conversion in flight is lost.
                self.conversion = None;
                self.adc = 0;
            }
            0x00 => {
                let value = match self.conversion {
                    // A read during a conversion returns 0 (datasheet).
                    Some(c) if now_us < c.done_us => 0,
                    Some(c) => {
                        self.conversion = None;
                        self.adc = match c.channel {
                            Channel::Pressure => self.d1,
                            Channel::Temperature => self.d2,
                        };
                        self.adc
                    }
                    None => self.adc,
                };
                let [_, a, b, c] = value.to_be_bytes();
                self.set_reply(&[a, b, c]);
            }
            0x40..=0x48 | 0x50..=0x58 if byte & 1 == 0 => {
                let channel = if byte < 0x50 {
                    Channel::Pressure
                } else {
                    Channel::Temperature
                };
                let osr = usize::from((byte & 0x0F) >> 1);
                self.conversion = Some(Conversion {
                    channel,
                    done_us: now_us + CONVERSION_US[osr],
                });
            }
            0xA0..=0xAE if byte & 1 == 0 => {
                let word = self.prom.0[usize::from((byte - 0xA0) >> 1)];
                self.set_reply(&word.to_be_bytes());
            }
            _ => self.unknown_commands += 1,
        }
    }

    fn set_reply(&mut self, bytes: &[u8]) {
        self.reply[..bytes.len()].copy_from_slice(bytes);
        self.reply_len = bytes.len();
        self.reply_pos = 0;
    }

    /// The next byte the master clocks out. Past the prepared reply the
    /// datasheet says nothing; this sensor sends zeros.
    pub fn read(&mut self) -> u8 {
        if self.reply_pos < self.reply_len {
            self.reply_pos += 1;
            self.reply[self.reply_pos - 1]
        } else {
            0
        }
    }

    /// A read transfer starts over from the reply's first byte, as the
    /// sensor's output register does on a new addressing.
    pub fn restart_reply(&mut self) {
        self.reply_pos = 0;
    }
}

fn cycles_to_us(cycle: u64) -> u64 {
    cycle / (F_CPU_HZ / 1_000_000)
}

impl TwiSlave for Ms5803 {
    fn address(&self) -> u8 {
        ADDRESS
    }
    fn start(&mut self, read: bool, _cycle: u64) {
        if read {
            self.restart_reply();
        }
    }
    fn write(&mut self, byte: u8, cycle: u64) {
        self.command(byte, cycles_to_us(cycle));
    }
    fn read(&mut self, _cycle: u64) -> u8 {
        Ms5803::read(self)
    }
    fn stop(&mut self, _cycle: u64) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_n(s: &mut Ms5803, n: usize) -> Vec<u8> {
        (0..n).map(|_| s.read()).collect()
    }

    #[test]
    fn crc_matches_an_independent_computation_and_catches_flips() {
        let prom = Prom::typical();
        assert!(prom.crc_ok());
        // The datasheet's algorithm, run in C on the same words.
        assert_eq!(crc4(&prom.0), 0x8);
        assert_eq!(crc4(&[0x1234, 1, 2, 3, 4, 5, 6, 0xAB00]), 0x5);
        // Word 7's low byte is outside the sum.
        assert_eq!(crc4(&[0x1234, 1, 2, 3, 4, 5, 6, 0xAB0F]), 0x5);
        for word in 0..7 {
            for bit in 0..16 {
                let mut w = prom.0;
                w[word] ^= 1 << bit;
                assert!(!Prom(w).crc_ok(), "flip of word {word} bit {bit}");
            }
        }
    }

    #[test]
    fn prom_is_read_high_byte_first() {
        let mut s = Ms5803::new(Prom::typical(), &Water::default());
        s.command(0x1E, 0);
        let mut words = [0u16; 8];
        for (i, w) in words.iter_mut().enumerate() {
            s.command(0xA0 + 2 * i as u8, 10);
            let b = read_n(&mut s, 2);
            *w = u16::from_be_bytes([b[0], b[1]]);
        }
        assert_eq!(Prom(words), Prom::typical());
        assert_eq!(words[1], 46372);
    }

    #[test]
    fn adc_read_waits_for_the_conversion() {
        let mut s = Ms5803::new(Prom::typical(), &Water::default());
        let (d1, d2) = s.raw();
        s.command(0x42, 1_000); // D1, OSR 512
        s.command(0x00, 1_500); // too early: zero, conversion goes on
        assert_eq!(read_n(&mut s, 3), [0, 0, 0]);
        s.command(0x00, 3_000);
        let b = read_n(&mut s, 3);
        assert_eq!(u32::from_be_bytes([0, b[0], b[1], b[2]]), d1);
        s.command(0x58, 4_000); // D2, OSR 4096
        s.command(0x00, 4_000 + 9_040);
        let b = read_n(&mut s, 3);
        assert_eq!(u32::from_be_bytes([0, b[0], b[1], b[2]]), d2);
        // Past the reply, and after an unknown command: zeros, counted.
        assert_eq!(s.read(), 0);
        s.command(0x41, 5);
        assert_eq!(s.unknown_commands, 1);
    }

    #[test]
    fn arithmetic_matches_the_firmware_library() {
        // (D1, D2) → (pres mbar, temp °C) as the firmware's own
        // MS5803_14BALib.cpp computes them, built for the host with this
        // PROM: warm and cold second-order branches, and below −15 °C.
        let cases = [
            (4_311_550, 8_387_300, 752.60, 30.3505),
            (4_311_550, 7_900_000, 729.00, 13.9280),
            (6_000_000, 8_100_000, 4478.20, 20.7529),
            (9_000_000, 7_000_000, 10170.20, -20.2349),
            (4_500_000, 8_600_000, 1196.20, 37.4018),
        ];
        let p = Prom::typical();
        for (d1, d2, mbar, temp_c) in cases {
            let got = p.firmware_pressure_dmbar(d1, d2) as f64 / 10.0;
            assert!((got - mbar).abs() < 0.05, "{d1} {d2}: {got} mbar");
            let t = p.firmware_temperature_c(d2);
            assert!((t - temp_c).abs() < 0.001, "{d2}: {t} °C");
        }
    }

    #[test]
    fn raw_values_round_trip_through_the_firmware_arithmetic() {
        let p = Prom::typical();
        for temp_c in [-20.0, 0.5, 4.0, 12.3, 19.99, 20.0, 28.7, 40.0] {
            for mbar in [800.0, 1015.0, 1211.13, 1554.37, 5000.0, 14_000.0] {
                let (d1, d2) = p.raw_for(mbar, temp_c);
                let got_t = p.firmware_temperature_c(d2);
                let got_p = p.firmware_pressure_dmbar(d1, d2) as f64 / 10.0;
                assert!((got_t - temp_c).abs() < 0.01, "{temp_c} °C: {got_t}");
                assert!((got_p - mbar).abs() <= 0.05, "{mbar} mbar: {got_p}");
            }
        }
    }

    #[test]
    fn depth_round_trips_through_the_firmware_formula() {
        for salt_water in [false, true] {
            for depth_m in [0.0, 2.0, 5.5, 100.0] {
                let w = Water {
                    depth_m,
                    temp_c: 10.0,
                    salt_water,
                };
                let factor = if salt_water { 0.9945 } else { 1.019716 };
                let back = (w.pressure_mbar() - 1015.0) * factor / 100.0;
                assert!((back - depth_m).abs() < 1e-9);
            }
        }
        assert!((Water::default().pressure_mbar() - 1015.0).abs() < 1e-9);
    }

    #[test]
    fn deeper_water_reads_higher() {
        let mut s = Ms5803::new(Prom::typical(), &Water::default());
        let (surface, _) = s.raw();
        s.set_water(&Water {
            depth_m: 5.0,
            ..Water::default()
        });
        assert!(s.raw().0 > surface);
    }
}
