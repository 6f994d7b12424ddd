//! When the sketch has something to do: the idle passes it skips in bulk
//! (nothing to read, no queued command, no timer due) and the deadline a
//! caller may sleep to (the next thing it prints or moves).

use std::time::Duration;

use super::{DELAY_TO_ARM_MS, Device, Phase, Sketch};
use crate::firmware::emulator::uart::Uart;

impl Sketch {
    /// Skips whole passes in which nothing can happen (no byte to read, no
    /// queued command, no timer due, no servo slewing a step that prints)
    /// up to `now`. Whether it skipped any.
    pub(super) fn skip_idle_passes(&mut self, now: Duration, uart: &Uart) -> bool {
        if uart.pending() {
            return false;
        }
        let Some(event) = self.next_event() else {
            return false;
        };
        let cost = self.pass_cost.as_nanos().max(1);
        let span = |until: Duration| until.saturating_sub(self.clock).as_nanos();
        // Pass j starts at clock + j·cost. It is idle if it ends before the
        // next timer is due and starts before a frame has arrived (or the
        // ring would fill); only the passes that start by `now` are run now.
        let mut passes = span(event) / cost;
        if let Some(at) = uart.next_read_due() {
            passes = passes.min(span(at).div_ceil(cost));
        }
        passes = passes.min(span(now) / cost + 1);
        if passes == 0 {
            return false;
        }
        let passes = passes as u64;
        self.clock += Duration::from_nanos((cost as u64).saturating_mul(passes));
        self.loops_per_sec = self.loops_per_sec.saturating_add(passes as u32);
        for (t, cost) in self
            .device_time_us
            .iter_mut()
            .zip(self.build.device_cost_us)
        {
            *t += cost * passes;
        }
        // The camera servo slews a microsecond a pass, seen only in `servo:`.
        let step = (passes as i64).min(i64::from((self.cmtg - self.cmnt).abs())) as i32;
        self.cmnt += step * (self.cmtg - self.cmnt).signum();
        true
    }

    /// The earliest time a timer can fire; `None` if the next pass has
    /// work at once (a queued command, a slewing servo that prints).
    pub(super) fn next_event(&self) -> Option<Duration> {
        if self.head != self.tail || self.alts != self.alts_target {
            return None;
        }
        let ms = |m: u64| Duration::from_millis(m);
        let mut t = ms(self.out1000.due_ms(self.cfg.status_period_ms))
            .min(ms(self.out100.due_ms(self.cfg.nav_period_ms)))
            .min(ms(self.adc_timer.due_ms(100)))
            .min(ms(self.brdt_timer.due_ms(1000)))
            .min(ms(self.status_timer.due_ms(100)))
            .min(ms(self.control_timer.due_ms(50)))
            .min(ms(self.output_timer.due_ms(1000)))
            .min(ms(self.pilot_timer.due_ms(50)))
            .min(ms(self.depth_timer.due_ms(1000)))
            .min(ms(self.dms_timer.due_ms(2000)));
        if self.mpu_init {
            t = t.min(if self.calibrating {
                ms(self.cal_timer.due_ms(1000))
            } else {
                ms(self.mpu_update_timer.due_ms(50))
            });
        } else {
            t = t.min(ms(self.mpu_reinit_timer.due_ms(30_000)));
        }
        if !self.dms_armed {
            t = t.min(ms(DELAY_TO_ARM_MS + 1));
        }
        if self.dms_tripped {
            t = t.min(ms(self.blink_timer.due_ms(500)));
        }
        if self.build.devices.contains(&Device::Bno055) {
            t = t.min(ms(self.bno_sample_timer.due_ms(47)));
        }
        Some(t)
    }

    /// When the sketch next prints, moves a thruster or needs input read,
    /// for a caller that wants to sleep until then: a pass in progress,
    /// queued work, or the next timer whose firing shows.
    pub(in crate::firmware::emulator) fn next_deadline(&self, uart: &Uart) -> Duration {
        // A pass cut short by a `delay` or a long print resumes with the
        // time it needs; what it may still print is due on a timer below.
        if !matches!(self.phase, Phase::Loop(_)) {
            return self.clock;
        }
        if self.head != self.tail || self.alts != self.alts_target || uart.pending() {
            return self.clock;
        }
        let ms = |m: u64| Duration::from_millis(m);
        let mut t = ms(self.out1000.due_ms(self.cfg.status_period_ms))
            .min(ms(self.out100.due_ms(self.cfg.nav_period_ms)))
            .min(ms(self.brdt_timer.due_ms(1000)))
            .min(ms(self.output_timer.due_ms(1000)))
            .min(ms(self.depth_timer.due_ms(1000)));
        if self.target != self.applied {
            t = t.min(ms(self.control_timer.due_ms(50)));
        }
        if self.heading_hold || self.depth_hold {
            t = t.min(ms(self.pilot_timer.due_ms(50)));
        }
        if self.dms_armed && !self.dms_tripped {
            t = t.min(ms(self.dms_timer.due_ms(2000)));
        }
        if !self.dms_armed {
            t = t.min(ms(DELAY_TO_ARM_MS + 1));
        }
        if self.dms_tripped {
            t = t.min(ms(self.blink_timer.due_ms(500)));
        }
        if self.calibrating {
            t = t.min(ms(self.cal_timer.due_ms(1000)));
        }
        if !self.mpu_init {
            t = t.min(ms(self.mpu_reinit_timer.due_ms(30_000)));
        }
        if self.build.devices.contains(&Device::Bno055) {
            t = t.min(ms(self.bno_report_timer.due_ms(30_000)));
        }
        if let Some(at) = uart.next_read_due() {
            t = t.min(at);
        }
        t.max(self.clock)
    }
}
