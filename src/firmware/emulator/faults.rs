//! Fault injection on the board's telemetry lines: what the thesis saw on
//! the real link (line noise, torn lines, wild points, dropped lines).
//!
//! Owns the seeded generator, so a run's faults are reproducible, and the
//! count of what was injected, so tests can hold the host decoder's
//! rejection counters against it. It never touches commands or the board's
//! state, and with every rate at 0 it prints each line unchanged without
//! drawing a single random number.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use super::{FaultOptions, FaultStats, print};
use crate::firmware::codec::physical_range;

/// Injects the faults [`FaultOptions`] asks for into telemetry lines.
#[derive(Debug)]
pub(super) struct FaultInjector {
    opts: FaultOptions,
    rng: SmallRng,
    stats: FaultStats,
}

impl FaultInjector {
    pub(super) fn new(opts: FaultOptions) -> Self {
        Self {
            rng: SmallRng::seed_from_u64(opts.seed),
            opts,
            stats: FaultStats::default(),
        }
    }

    /// What was injected so far.
    pub(super) fn stats(&self) -> FaultStats {
        self.stats
    }

    /// Prints a telemetry line, with faults injected if enabled.
    pub(super) fn emit(&mut self, line: String, out: &mut Vec<u8>) {
        let f = self.opts.clone();
        if !f.any() {
            self.stats.lines_emitted += 1;
            print(&line, out);
            return;
        }
        if self.rng.random_bool(f.dropped.clamp(0.0, 1.0)) {
            self.stats.dropped_lines += 1;
            return;
        }
        if self.rng.random_bool(f.garbage.clamp(0.0, 1.0)) {
            let n = self.rng.random_range(1..=16);
            for _ in 0..n {
                out.push(self.garbage_byte());
            }
            self.stats.garbage_bursts += 1;
            self.stats.garbage_bytes += n;
        }
        let line = if self.rng.random_bool(f.torn.clamp(0.0, 1.0)) {
            match self.tear(&line) {
                Some(torn) => {
                    self.stats.torn_lines += 1;
                    torn
                }
                None => line,
            }
        } else if self.rng.random_bool(f.wild.clamp(0.0, 1.0)) {
            self.wild(&line)
        } else {
            line
        };
        self.stats.lines_emitted += 1;
        print(&line, out);
    }

    fn garbage_byte(&mut self) -> u8 {
        // Line noise: bytes no telemetry line contains.
        loop {
            let b: u8 = self.rng.random();
            if !(0x20..=0x7e).contains(&b) && b != b'\r' && b != b'\n' {
                return b;
            }
        }
    }

    /// Either cuts the line inside a value, or replaces a value by the name
    /// of the following key, as a torn read buffer does.
    fn tear(&mut self, line: &str) -> Option<String> {
        let pairs: Vec<&str> = line.split_terminator(';').collect();
        let numeric: Vec<usize> = (0..pairs.len().saturating_sub(1))
            .filter(|&i| {
                pairs[i]
                    .split(':')
                    .next()
                    .is_some_and(|k| physical_range(k).is_some())
            })
            .collect();
        if !numeric.is_empty() && self.rng.random_bool(0.5) {
            let i = numeric[self.rng.random_range(0..numeric.len())];
            let next_key = pairs[i + 1].split(':').next().unwrap_or("pitc");
            let key = pairs[i].split(':').next().unwrap_or("hdgd");
            let mut v: Vec<String> = pairs.iter().map(|p| (*p).to_owned()).collect();
            v[i] = format!("{key}:{next_key}");
            return Some(v.iter().map(|p| format!("{p};")).collect());
        }
        // Cut anywhere but right after a `;` (which would leave a shorter
        // but valid line): the result never ends in `;`, so it is torn.
        let bytes = line.as_bytes();
        let cut_points: Vec<usize> = (1..bytes.len()).filter(|&i| bytes[i - 1] != b';').collect();
        if cut_points.is_empty() {
            return None;
        }
        let at = cut_points[self.rng.random_range(0..cut_points.len())];
        Some(line[..at].to_owned())
    }

    /// Multiplies one numeric value by 0.1, 10 or 100 and records whether
    /// the result left its key's physical range.
    fn wild(&mut self, line: &str) -> String {
        let pairs: Vec<&str> = line.split_terminator(';').collect();
        let numeric: Vec<usize> = pairs
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let (k, v) = p.split_once(':')?;
                (physical_range(k).is_some() && v.parse::<f64>().is_ok() && !v.contains(','))
                    .then_some(i)
            })
            .collect();
        if numeric.is_empty() {
            return line.to_owned();
        }
        let i = numeric[self.rng.random_range(0..numeric.len())];
        let Some((k, v)) = pairs[i].split_once(':') else {
            return line.to_owned();
        };
        let value: f64 = v.parse().unwrap_or(0.0);
        let factor = [0.1, 10.0, 100.0][self.rng.random_range(0..3)];
        let integer = !v.contains('.');
        let wild_value = value * factor;
        let text = if integer {
            format!("{}", wild_value.round() as i64)
        } else {
            format!("{wild_value:.2}")
        };
        if text == v {
            // 0 × 10 is still 0: nothing was injected.
            return line.to_owned();
        }
        let shown: f64 = text.parse().unwrap_or(wild_value);
        let in_range = physical_range(k).is_some_and(|(lo, hi)| shown >= lo && shown <= hi);
        if in_range {
            self.stats.wild_in_range += 1;
        } else {
            self.stats.wild_out_of_range += 1;
        }
        let mut v: Vec<String> = pairs.iter().map(|p| (*p).to_owned()).collect();
        v[i] = format!("{k}:{text}");
        v.iter().map(|p| format!("{p};")).collect()
    }
}
