//! How fast one transfer sends: a token bucket refilled at the transfer's
//! rate, and the rate itself, which adapts to what the station takes.
//!
//! A transfer starts at [`START_RATE`]; each range it finishes without the
//! station asking again for data already sent raises the rate by a
//! quarter, up to what its endpoint allows; a station asking again for
//! sent data (it lost some: its socket or the link between could not keep
//! up) halves it, down to [`MIN_RATE`]. The bucket holds [`QUANTUM`]'s
//! worth, so one pass of the vehicle's loop sends at most that much (a
//! few kilobytes, tens of messages): the control path between two passes
//! waits for no transfer.

use std::time::Duration;

/// Bytes per second a transfer starts at.
pub const START_RATE: f64 = 1_000_000.0;
/// The slowest a transfer goes after losses.
pub const MIN_RATE: f64 = 16_000.0;
/// The bucket's depth in time: a pass sends at most this long's worth.
pub const QUANTUM: Duration = Duration::from_millis(4);
/// The largest message a transfer sends, in bytes on the wire (an FTP
/// packet with its frame, signed): the bucket always holds one.
pub const LARGEST: f64 = 280.0;

#[derive(Debug, Clone)]
pub struct Pacer {
    /// Bytes per second.
    rate: f64,
    tokens: f64,
    last: Option<Duration>,
}

impl Pacer {
    pub fn new(rate: f64) -> Self {
        Self {
            rate: rate.max(MIN_RATE),
            tokens: 0.0,
            last: None,
        }
    }

    pub fn rate(&self) -> f64 {
        self.rate
    }

    fn depth(&self) -> f64 {
        (self.rate * QUANTUM.as_secs_f64()).max(LARGEST)
    }

    /// Adds what the time since the last refill allows, at most `cap`
    /// bytes per second (the transfer's share of its endpoint). The first
    /// refill fills the bucket.
    pub fn refill(&mut self, now: Duration, cap: f64) {
        self.rate = self.rate.min(cap).max(MIN_RATE.min(cap));
        self.tokens = match self.last {
            None => self.depth(),
            Some(last) => {
                let dt = now.saturating_sub(last).as_secs_f64();
                (self.tokens + dt * self.rate).min(self.depth())
            }
        };
        self.last = Some(now);
    }

    /// Takes `bytes` if the bucket holds them.
    pub fn take(&mut self, bytes: f64) -> bool {
        if self.tokens >= bytes {
            self.tokens -= bytes;
            true
        } else {
            false
        }
    }

    /// When the bucket will hold enough for the next pass: half its depth
    /// (so passes come every half quantum), at least one message.
    pub fn due(&self) -> Duration {
        let Some(last) = self.last else {
            return Duration::ZERO;
        };
        let need = (self.depth() / 2.0).max(LARGEST) - self.tokens;
        if need <= 0.0 {
            last
        } else {
            last + Duration::from_secs_f64(need / self.rate)
        }
    }

    /// The station asked again for data already sent.
    pub fn loss(&mut self) {
        self.rate = (self.rate / 2.0).max(MIN_RATE);
    }

    /// A range was sent without a loss; up to `cap` bytes per second.
    pub fn good(&mut self, cap: f64) {
        self.rate = (self.rate * 1.25).min(cap).max(MIN_RATE.min(cap));
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn sends_at_its_rate_in_passes_of_a_quantum() {
        let mut p = Pacer::new(1_000_000.0);
        p.refill(Duration::ZERO, 4e6);
        // A full bucket: 4 ms at 1 MB/s.
        let mut sent = 0.0;
        while p.take(100.0) {
            sent += 100.0;
        }
        assert_eq!(sent, 4000.0);
        // Half a quantum later it holds enough for a pass again.
        assert_eq!(p.due(), 2 * MS);
        let mut t = Duration::ZERO;
        let mut total = 0.0f64;
        while t < Duration::from_secs(1) {
            t = p.due().max(t + Duration::from_micros(1));
            p.refill(t, 4e6);
            while p.take(100.0) {
                total += 100.0;
            }
        }
        assert!((total - 1e6).abs() < 5e3, "{total}");
    }

    #[test]
    fn loss_halves_and_good_ranges_climb_to_the_cap() {
        let mut p = Pacer::new(START_RATE);
        p.loss();
        assert_eq!(p.rate(), START_RATE / 2.0);
        for _ in 0..100 {
            p.loss();
        }
        assert_eq!(p.rate(), MIN_RATE);
        for _ in 0..100 {
            p.good(3e6);
        }
        assert_eq!(p.rate(), 3e6);
        // A slower endpoint caps it below the floor too.
        p.refill(Duration::ZERO, 5_000.0);
        assert_eq!(p.rate(), 5_000.0);
    }
}
