//! The controller board as a bench holds it, without a clock: the firmware
//! in simavr, the sensors on its I2C bus, its analog inputs, its UART's
//! receive line and its pulse outputs measured — run to a given cycle.
//!
//! Owns what is wired to the simulated ATmega2560 ([`Wiring`]: the analog
//! inputs in volts and amperes converted to what the board's dividers put
//! on its ADC pins, and which sensors are on its I2C bus) and one slice of running
//! it: the host's bytes go onto the UART line as its receiver takes them
//! (injected frames between two of the host's), the firmware's prints come
//! back, and pin edges become pulse widths ([`super::pins`]). Both ways of
//! running the board use it: [`super::runner`] paces it to the wall clock
//! behind a pty, [`super::lockstep`] steps it by simulated time beside a
//! scenario. It never reads a clock and never decides what the board does.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::path::Path;
use std::rc::Rc;

use serde::Serialize;

use super::avr::{AvrError, Edge, Mcu};
use super::bno055::{Attitude, Bno055};
use super::ms5803::{Ms5803, Prom, Water};
use super::pins::{Pins, PinsReport, PulseChange, WATCHED, reg};

/// The analog inputs of controller board 2.5, in the units the board reports.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Analog {
    /// Battery voltage on A4 (`vout`, `BRDV`: ADC × 20 / 1023).
    pub battery_v: f64,
    /// Board current on A0 (`iout`, `BRDI`: ADC × 2 / 1023).
    pub board_current_a: f64,
    /// Battery tube currents on A6 and A5 (`BT1I`, `BT2I`: ADC × 10 / 1023).
    pub battery_current_a: [f64; 2],
    /// Board temperature sensor on A8 (`BRDT`: (ADC × 5 / 1024 − 0.4) × 51.28).
    pub board_temp_c: f64,
}

/// What is wired to the simulated board besides its serial line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wiring {
    /// The analog inputs at power-up.
    pub analog: Analog,
    /// The MS5803-14BA depth sensor on the I2C bus (the kit's depth add-on).
    /// Without it the firmware reads zeros and says so, as a basic kit does.
    pub depth_sensor: bool,
    /// The BNO055 IMU on the I2C bus (the kit's IMU add-on). Without it the
    /// firmware finds no IMU and prints a level attitude heading north.
    pub imu: bool,
}

impl Default for Wiring {
    fn default() -> Self {
        Self {
            analog: Analog::default(),
            depth_sensor: true,
            imu: true,
        }
    }
}

impl Default for Analog {
    fn default() -> Self {
        Self {
            battery_v: 12.0,
            board_current_a: 0.2,
            battery_current_a: [0.0; 2],
            board_temp_c: 25.0,
        }
    }
}

impl Analog {
    /// `(ADC channel, millivolts)` for each input: the smallest voltage whose
    /// 10-bit conversion (against 5 V) is the code nearest the wanted reading.
    pub(super) fn inputs(&self) -> [(u8, u32); 5] {
        let mv_for_code = |code: f64| {
            let code = code.round().clamp(0.0, 1023.0);
            (code * 5000.0 / 1023.0).ceil() as u32
        };
        let temp_code = (self.board_temp_c / 51.28 + 0.4) * 1024.0 / 5.0;
        [
            (4, mv_for_code(self.battery_v / 20.0 * 1023.0)),
            (0, mv_for_code(self.board_current_a / 2.0 * 1023.0)),
            (6, mv_for_code(self.battery_current_a[0] / 10.0 * 1023.0)),
            (5, mv_for_code(self.battery_current_a[1] / 10.0 * 1023.0)),
            (8, mv_for_code(temp_code * 1023.0 / 1024.0)),
        ]
    }
}

/// The firmware on its board, with what is wired to it.
pub(super) struct Bench {
    mcu: Mcu,
    /// The devices on the I2C bus, each if wired; the bench keeps its own
    /// handle to change their surroundings between slices.
    depth: Option<Rc<RefCell<Ms5803>>>,
    imu: Option<Rc<RefCell<Bno055>>>,
    analog: Analog,
    water: Water,
    attitude: Attitude,
    pins: Pins,
    edges: Vec<Edge>,
    /// Host bytes not yet on the UART line.
    from_host: VecDeque<u8>,
    /// Whether the last host byte put on the line ended a frame.
    host_at_boundary: bool,
    inject: VecDeque<Vec<u8>>,
}

impl std::fmt::Debug for Bench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bench").field("mcu", &self.mcu).finish()
    }
}

impl Bench {
    /// Loads `elf` and powers the board up wired as `wiring` says. simavr's
    /// objects are not `Send`: the bench lives on the thread that made it.
    pub(super) fn load(elf: &Path, wiring: &Wiring) -> Result<Self, AvrError> {
        let mut mcu = Mcu::load(elf, &WATCHED)?;
        let water = Water::default();
        let attitude = Attitude::default();
        let depth = wiring
            .depth_sensor
            .then(|| Rc::new(RefCell::new(Ms5803::new(Prom::typical(), &water))));
        let imu = wiring
            .imu
            .then(|| Rc::new(RefCell::new(Bno055::new(&attitude))));
        if let Some(sensor) = &depth {
            mcu.attach_twi(sensor.clone())?;
        }
        if let Some(sensor) = &imu {
            mcu.attach_twi(sensor.clone())?;
        }
        for (channel, mv) in wiring.analog.inputs() {
            mcu.set_adc_mv(channel, mv);
        }
        Ok(Self {
            mcu,
            depth,
            imu,
            analog: wiring.analog,
            water,
            attitude,
            pins: Pins::default(),
            edges: Vec::with_capacity(256),
            from_host: VecDeque::new(),
            host_at_boundary: true,
            inject: VecDeque::new(),
        })
    }

    /// Clock cycles since power-up.
    pub(super) fn cycle(&self) -> u64 {
        self.mcu.cycle()
    }

    pub(super) fn analog(&self) -> Analog {
        self.analog
    }

    pub(super) fn water(&self) -> Water {
        self.water
    }

    pub(super) fn attitude(&self) -> Attitude {
        self.attitude
    }

    /// The outputs as measured now.
    pub(super) fn pins(&self) -> PinsReport {
        self.pins.report(self.mcu.cycle())
    }

    /// New analog inputs from the next slice on.
    pub(super) fn set_analog(&mut self, analog: Analog) {
        if analog == self.analog {
            return;
        }
        self.analog = analog;
        for (channel, mv) in analog.inputs() {
            self.mcu.set_adc_mv(channel, mv);
        }
    }

    /// New surroundings for the depth sensor's next conversion.
    pub(super) fn set_water(&mut self, water: Water) {
        if water == self.water {
            return;
        }
        self.water = water;
        if let Some(sensor) = &self.depth {
            sensor.borrow_mut().set_water(&water);
        }
    }

    /// The vehicle's new attitude, in the IMU's next read.
    pub(super) fn set_attitude(&mut self, attitude: Attitude) {
        if attitude == self.attitude {
            return;
        }
        self.attitude = attitude;
        if let Some(sensor) = &self.imu {
            sensor.borrow_mut().set_attitude(&attitude);
        }
    }

    /// Bytes the host wrote, for the UART line.
    pub(super) fn host_wrote(&mut self, bytes: &[u8]) {
        self.from_host.extend(bytes);
    }

    /// A frame for the UART line between two of the host's (after its next `;`).
    pub(super) fn inject(&mut self, frame: Vec<u8>) {
        self.inject.push_back(frame);
    }

    /// Pulls the reset line; every output stops pulsing (returned as changes).
    pub(super) fn reset(&mut self) -> Vec<PulseChange> {
        self.mcu.reset();
        self.pins.clear(self.mcu.cycle())
    }

    /// Runs the firmware to cycle `end` (a slice: the UART is fed once, at
    /// its start). What it printed is appended to `out`, its outputs'
    /// changes to `changes`.
    pub(super) fn run_until(
        &mut self,
        end: u64,
        out: &mut Vec<u8>,
        changes: &mut Vec<PulseChange>,
    ) -> Result<(), AvrError> {
        self.feed_uart();
        self.mcu.run_until(end)?;
        self.mcu.take_output(out);
        self.mcu.take_edges(&mut self.edges);
        for e in self.edges.drain(..) {
            changes.extend(self.pins.edge(e.pin, e.cycle, e.high));
        }
        changes.extend(self.pins.expire(self.mcu.cycle()));
        self.pins.timer5(
            self.mcu.data(reg::TCCR5A),
            self.mcu.data(reg::OCR5BL),
            self.mcu.data(reg::OCR5CL),
            self.mcu.data(reg::PORTL),
        );
        Ok(())
    }

    /// Puts waiting bytes on the UART line while its receiver has room;
    /// injected frames go in between two of the host's.
    fn feed_uart(&mut self) {
        while self.mcu.uart_ready() {
            if self.host_at_boundary
                && let Some(frame) = self.inject.pop_front()
            {
                for b in frame {
                    self.mcu.uart_send(b);
                }
                continue;
            }
            let Some(b) = self.from_host.pop_front() else {
                break;
            };
            self.mcu.uart_send(b);
            self.host_at_boundary = b == b';';
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analog_inputs_land_on_the_nearest_code() {
        let a = Analog {
            battery_v: 12.0,
            board_current_a: 0.2,
            battery_current_a: [1.5, 0.0],
            board_temp_c: 25.0,
        };
        let code = |mv: u32| (u64::from(mv) * 1023 / 5000) as f64;
        let inputs = a.inputs();
        // The board's own arithmetic on the code simavr converts.
        assert!((code(inputs[0].1) * 20.0 / 1023.0 - 12.0).abs() < 0.02);
        assert!((code(inputs[1].1) * 2.0 / 1023.0 - 0.2).abs() < 0.002);
        assert!((code(inputs[2].1) * 10.0 / 1023.0 - 1.5).abs() < 0.01);
        assert_eq!(inputs[3].1, 0);
        let t = (code(inputs[4].1) * 5.0 / 1024.0 - 0.4) * 51.28;
        assert!((t - 25.0).abs() < 0.3, "{t}");
    }
}
