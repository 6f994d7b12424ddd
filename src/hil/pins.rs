//! The controller board's outputs as a bench instrument would read them:
//! ESC and servo pulse widths from the edges of their pins, and the lights'
//! and lasers' PWM duty from the timer that drives them.
//!
//! Owns where each output is on controller board 2.5 (30.0.2's
//! `controllerboard25.h`: ESCs on Arduino pins 6, 7, 8 = PH3, PH4, PH5, the
//! camera tilt on pin 11 = PB5, lights on pin 44 = PL5 (OC5C), lasers on
//! pin 45 = PL4 (OC5B)) and the pulse arithmetic. Sans-IO: edges and
//! register values come in with their cycle; nothing here touches simavr.
//!
//! The lights and lasers are read from Timer5's registers rather than from
//! edges: Arduino drives them with phase-correct PWM, which simavr models as
//! the compare value without toggling the pin. `analogWrite` of 0 or 255
//! switches the PWM off and drives the pin as a digital output, which the
//! port register shows.

use serde::Serialize;

use super::avr::{F_CPU_HZ, PinId};

/// The pins whose edges are measured, in [`Output`] order.
pub const WATCHED: [PinId; 4] = [
    PinId { port: 'H', bit: 3 },
    PinId { port: 'H', bit: 4 },
    PinId { port: 'H', bit: 5 },
    PinId { port: 'B', bit: 5 },
];

/// Data-space addresses of the registers behind the lights and lasers.
pub(super) mod reg {
    pub const PORTL: u16 = 0x10B;
    pub const TCCR5A: u16 = 0x120;
    pub const OCR5BL: u16 = 0x12A;
    pub const OCR5CL: u16 = 0x12C;
    /// TCCR5A bits that connect OC5B / OC5C to their pins.
    pub const COM5B1: u8 = 5;
    pub const COM5C1: u8 = 3;
    /// PORTL bits of the lasers (PL4) and lights (PL5).
    pub const PL4: u8 = 4;
    pub const PL5: u8 = 5;
}

/// A pulse output of the board.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Output {
    EscPort,
    EscVertical,
    EscStarboard,
    Tilt,
}

impl Output {
    pub const ALL: [Output; 4] = [
        Output::EscPort,
        Output::EscVertical,
        Output::EscStarboard,
        Output::Tilt,
    ];
}

/// Servo frames repeat every 20 ms; three missed frames mean the output
/// stopped pulsing (detached, or the board is in reset).
const STALE_CYCLES: u64 = F_CPU_HZ / 1000 * 60;
/// A measured width must move by more than this to count as a change: the
/// Servo library's interrupt latency moves an edge by a few cycles.
const CHANGE_US: f64 = 2.0;

/// One output's pulses.
#[derive(Debug, Clone, Copy, Default)]
struct PulseMeter {
    rise: Option<u64>,
    width_cycles: Option<u64>,
    last_pulse_end: u64,
    /// The width last reported as a change.
    reported_us: Option<f64>,
}

/// A pulse width changed (or pulses started or stopped).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PulseChange {
    pub output: Output,
    pub from_us: Option<f64>,
    pub to_us: Option<f64>,
    /// The cycle of the falling edge that ended the first pulse at the new width.
    pub cycle: u64,
}

/// The board's outputs at one moment.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct PinsReport {
    /// ESC pulse widths [port, vertical, starboard] (µs); `None` while not pulsing.
    pub esc_us: [Option<f64>; 3],
    /// Camera tilt servo pulse width (µs).
    pub tilt_us: Option<f64>,
    /// Lights PWM duty, 0..=1.
    pub lights_duty: f64,
    /// Calibration lasers PWM duty, 0..=1.
    pub laser_duty: f64,
}

fn cycles_to_us(cycles: u64) -> f64 {
    cycles as f64 * 1e6 / F_CPU_HZ as f64
}

/// Pulse measurement for every watched output.
#[derive(Debug, Clone, Default)]
pub struct Pins {
    meters: [PulseMeter; 4],
    lights_duty: f64,
    laser_duty: f64,
}

impl Pins {
    /// An edge of output `index` (in [`WATCHED`] order) at `cycle`; a
    /// completed pulse whose width differs from the last reported one is
    /// returned as a change.
    pub fn edge(&mut self, index: usize, cycle: u64, high: bool) -> Option<PulseChange> {
        let output = *Output::ALL.get(index)?;
        let m = self.meters.get_mut(index)?;
        if high {
            m.rise = Some(cycle);
            return None;
        }
        let rise = m.rise.take()?;
        let width = cycle.saturating_sub(rise);
        m.width_cycles = Some(width);
        m.last_pulse_end = cycle;
        let us = cycles_to_us(width);
        let changed = m.reported_us.is_none_or(|r| (r - us).abs() > CHANGE_US);
        if !changed {
            return None;
        }
        let from_us = m.reported_us.replace(us);
        Some(PulseChange {
            output,
            from_us,
            to_us: Some(us),
            cycle,
        })
    }

    /// Outputs that stopped pulsing by `cycle` (reported once each).
    pub fn expire(&mut self, cycle: u64) -> Vec<PulseChange> {
        let mut out = Vec::new();
        for (m, output) in self.meters.iter_mut().zip(Output::ALL) {
            if m.reported_us.is_some() && cycle.saturating_sub(m.last_pulse_end) > STALE_CYCLES {
                let from_us = m.reported_us.take();
                m.width_cycles = None;
                out.push(PulseChange {
                    output,
                    from_us,
                    to_us: None,
                    cycle,
                });
            }
        }
        out
    }

    /// The PWM registers of Timer5 and port L, as read at one moment.
    pub fn timer5(&mut self, tccr5a: u8, ocr5b: u8, ocr5c: u8, portl: u8) {
        let duty = |com: u8, ocr: u8, port_bit: u8| {
            if tccr5a & (1 << com) != 0 {
                f64::from(ocr) / 255.0
            } else if portl & (1 << port_bit) != 0 {
                1.0
            } else {
                0.0
            }
        };
        self.lights_duty = duty(reg::COM5C1, ocr5c, reg::PL5);
        self.laser_duty = duty(reg::COM5B1, ocr5b, reg::PL4);
    }

    /// Forgets every pulse (after a reset the board starts from nothing).
    pub fn clear(&mut self, cycle: u64) -> Vec<PulseChange> {
        let mut out = Vec::new();
        for (m, output) in self.meters.iter_mut().zip(Output::ALL) {
            if let Some(from_us) = m.reported_us {
                out.push(PulseChange {
                    output,
                    from_us: Some(from_us),
                    to_us: None,
                    cycle,
                });
            }
            *m = PulseMeter::default();
        }
        self.lights_duty = 0.0;
        self.laser_duty = 0.0;
        out
    }

    /// What the outputs show at `cycle`.
    pub fn report(&self, cycle: u64) -> PinsReport {
        let width = |m: &PulseMeter| {
            m.width_cycles
                .filter(|_| cycle.saturating_sub(m.last_pulse_end) <= STALE_CYCLES)
                .map(cycles_to_us)
        };
        PinsReport {
            esc_us: [
                width(&self.meters[0]),
                width(&self.meters[1]),
                width(&self.meters[2]),
            ],
            tilt_us: width(&self.meters[3]),
            lights_duty: self.lights_duty,
            laser_duty: self.laser_duty,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const US: u64 = F_CPU_HZ / 1_000_000;

    #[test]
    fn widths_changes_and_staleness() {
        let mut p = Pins::default();
        assert_eq!(p.edge(0, 1000, true), None);
        let c = p.edge(0, 1000 + 1500 * US, false).expect("first pulse");
        assert_eq!(c.to_us, Some(1500.0));
        assert_eq!(c.from_us, None);
        // Jitter of a few cycles is no change.
        p.edge(0, 400_000, true);
        assert_eq!(p.edge(0, 400_000 + 1500 * US + 8, false), None);
        p.edge(0, 800_000, true);
        let c = p.edge(0, 800_000 + 1640 * US, false).expect("new width");
        assert_eq!((c.from_us, c.to_us), (Some(1500.0), Some(1640.0)));
        assert_eq!(p.report(900_000).esc_us[0], Some(1640.0));
        assert_eq!(p.report(900_000).esc_us[1], None);
        let later = 800_000 + 1640 * US + STALE_CYCLES + 1;
        assert_eq!(p.report(later).esc_us[0], None);
        let gone = p.expire(later);
        assert_eq!(gone.len(), 1);
        assert_eq!(gone[0].to_us, None);
        // A falling edge with no rise before it (the first edge seen) is no pulse.
        assert_eq!(p.edge(1, 5, false), None);
    }

    #[test]
    fn duty_from_timer_or_port() {
        let mut p = Pins::default();
        p.timer5(1 << reg::COM5C1, 0, 128, 0);
        assert!((p.report(0).lights_duty - 128.0 / 255.0).abs() < 1e-9);
        assert_eq!(p.report(0).laser_duty, 0.0);
        // analogWrite(255): PWM off, pin high.
        p.timer5(0, 0, 0, 1 << reg::PL5 | 1 << reg::PL4);
        assert_eq!(p.report(0).lights_duty, 1.0);
        assert_eq!(p.report(0).laser_duty, 1.0);
    }
}
