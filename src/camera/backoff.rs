//! The restart schedule of supervised sources: a pure policy, so the
//! schedule is tested without a clock.

use std::time::Duration;

use super::config::BackoffConfig;

/// Exponential backoff: `initial`, doubling up to `max`; a run that lasted
/// at least `healthy` starts the schedule over, so a camera that fails once
/// a day restarts quickly while one that fails at once is retried slowly.
#[derive(Debug, Clone)]
pub struct Backoff {
    initial: Duration,
    max: Duration,
    healthy: Duration,
    next: Duration,
}

impl Backoff {
    pub fn new(initial: Duration, max: Duration, healthy: Duration) -> Self {
        let max = max.max(initial);
        Backoff {
            initial,
            max,
            healthy,
            next: initial,
        }
    }

    pub fn from_config(cfg: &BackoffConfig) -> Self {
        Backoff::new(
            Duration::from_secs_f64(cfg.initial_s),
            Duration::from_secs_f64(cfg.max_s),
            Duration::from_secs_f64(cfg.healthy_s),
        )
    }

    /// The wait before the next start, given how long the run that just
    /// ended lasted.
    pub fn after_run(&mut self, ran_for: Duration) -> Duration {
        if ran_for >= self.healthy {
            self.next = self.initial;
        }
        let wait = self.next;
        self.next = (self.next * 2).min(self.max);
        wait
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn default() -> Backoff {
        Backoff::from_config(&BackoffConfig::default())
    }

    #[test]
    fn doubles_from_half_a_second_to_ten() {
        let mut b = default();
        let waits: Vec<f64> = (0..8)
            .map(|_| b.after_run(Duration::ZERO).as_secs_f64())
            .collect();
        assert_eq!(waits, [0.5, 1.0, 2.0, 4.0, 8.0, 10.0, 10.0, 10.0]);
    }

    #[test]
    fn a_healthy_minute_resets_the_schedule() {
        let mut b = default();
        for _ in 0..6 {
            b.after_run(Duration::from_secs(1));
        }
        assert_eq!(
            b.after_run(Duration::from_secs(59)),
            Duration::from_secs(10)
        );
        assert_eq!(
            b.after_run(Duration::from_secs(60)),
            Duration::from_millis(500)
        );
        assert_eq!(b.after_run(Duration::ZERO), Duration::from_secs(1));
    }

    /// A program that fails at once is started at most this often: over an
    /// hour, 5 starts in the first 15.5 s and then one per 10 s — no busy loop.
    #[test]
    fn attempts_in_a_window_are_bounded_by_the_schedule() {
        let mut b = default();
        let window = Duration::from_secs(3600);
        let (mut t, mut starts) = (Duration::ZERO, 1u32);
        loop {
            t += b.after_run(Duration::ZERO);
            if t > window {
                break;
            }
            starts += 1;
        }
        // 0, 0.5, 1.5, 3.5, 7.5, 15.5, then every 10 s up to 3595.5.
        assert_eq!(starts, 6 + 358);
    }

    #[test]
    fn max_below_initial_is_clamped() {
        let mut b = Backoff::new(
            Duration::from_secs(2),
            Duration::from_secs(1),
            Duration::MAX,
        );
        assert_eq!(b.after_run(Duration::ZERO), Duration::from_secs(2));
        assert_eq!(b.after_run(Duration::ZERO), Duration::from_secs(2));
    }
}
