//! When the core next needs a tick: the app sleeps until then instead of
//! ticking at a fixed rate, so an idle vehicle wakes only for what is due.
//!
//! While anything moves or may move — armed (driving, autopilots, the
//! pilot-input and link failsafes), a camera tilt or gimbal rate, a
//! parameter list being sent — the core ticks every [`BUSY_TICK`], as it
//! always did. Otherwise it ticks when a telemetry message or the camera's
//! heartbeat is due, and every [`IDLE_TICK`] for the timers of a disarmed
//! vehicle (authority and request timeouts, failsafe warnings, parameter
//! saving, the board's dead-man feed), which a tenth of a second does not
//! change. Inputs are handled when they arrive, never on a tick.
//!
//! The board's navigation lines wake the vehicle ten times a second anyway:
//! an idle tick due before the next line is run with the line that came
//! ([`Vehicle::tick_with_line`]), and a clocked telemetry message or the
//! camera's heartbeat due before the next line goes with it
//! (`Schedule::line_arrived`, `telemetry::gather`). Their own deadlines
//! give a late line its slack (`LINE_SLACK`), so while the board talks an
//! idle vehicle wakes for nothing but its lines; when it is silent the idle
//! tick comes every `IDLE_TICK + LINE_SLACK`.

use std::time::Duration;

use super::{Now, Output, Vehicle};
use crate::vehicle::telemetry::{LINE_GATHER, LINE_SLACK};

/// The tick period while something moves or may move.
pub const BUSY_TICK: Duration = Duration::from_millis(10);

/// The longest a vehicle with nothing moving goes without a tick. Well
/// inside the board link's dead-man window (500 ms), which the tick feeds.
pub const IDLE_TICK: Duration = Duration::from_millis(100);

impl Vehicle {
    /// When (monotonic time, as `Now::mono`) the core next needs
    /// `Input::Tick`; at once before the first tick.
    pub fn next_tick(&self) -> Duration {
        let Some(last) = self.clock.last_tick else {
            return Duration::ZERO;
        };
        if self.ticks_busy() {
            return last + BUSY_TICK;
        }
        // The idle tick goes with the board's lines (`tick_with_line`): its
        // own deadline gives a line its slack, so a line a little late is not
        // preceded by a tick of its own.
        [
            self.streams.next_deadline(),
            self.camera_next_heartbeat(),
            self.recording_next_tick(),
        ]
        .into_iter()
        .flatten()
        .fold(last + IDLE_TICK + LINE_SLACK, Duration::min)
    }

    /// A navigation line was handled at `now`: the idle tick runs with it
    /// when it would be due before the next line (never while the fine
    /// tick runs: its timing is its own).
    pub(super) fn tick_with_line(&mut self, now: Now, out: &mut Vec<Output>) {
        if self.ticks_busy() {
            return;
        }
        if self
            .clock
            .last_tick
            .is_some_and(|t| now.mono + LINE_GATHER >= t + IDLE_TICK)
        {
            self.tick(now, out);
        }
    }

    /// Whether something moves or may move, and needs the fine tick.
    fn ticks_busy(&self) -> bool {
        self.armed
            || self.pilot.tilt_rate != 0.0
            || self.gimbal_moving()
            || !self.streams.param_queue.is_empty()
    }
}
