//! Keeping refused requests and client text out of the log in bulk.
//!
//! Owns [`Bursts`] (log the first of a burst, summarise the rest) and
//! [`loggable`] (client text made short and safe for one log line).

use std::time::{Duration, Instant};

/// A burst of failures (or of refused requests) is over, and summarised,
/// after this much quiet.
pub const BURST_QUIET: Duration = Duration::from_secs(30);

/// Refused requests of one kind (foreign Origin, foreign Host, watcher cap):
/// the first of a burst is logged, the rest counted and summarised when the
/// burst ends.
#[derive(Debug, Default)]
pub struct Bursts {
    /// Total refused since start.
    pub total: u64,
    current: Option<(Instant, Instant, u64)>,
}

impl Bursts {
    /// Counts one; true when it is the first of a burst (log it).
    pub fn hit(&mut self, now: Instant) -> bool {
        self.total += 1;
        match self.current.as_mut() {
            Some((_, last, n)) => {
                *last = now;
                *n += 1;
                false
            }
            None => {
                self.current = Some((now, now, 1));
                true
            }
        }
    }

    /// `(count, over)` of a burst that went quiet, once.
    pub fn sweep(&mut self, now: Instant) -> Option<(u64, Duration)> {
        let (start, last, n) = self.current?;
        if now.saturating_duration_since(last) < BURST_QUIET {
            return None;
        }
        self.current = None;
        (n > 1).then(|| (n, last.saturating_duration_since(start)))
    }
}

/// Text from a client, made safe and short for a log line.
pub fn loggable(s: &str) -> String {
    let mut out: String = s.chars().take(80).collect();
    if s.chars().count() > 80 {
        out.push('…');
    }
    format!("{out:?}")
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn bursts_log_once() {
        let t0 = Instant::now();
        let mut b = Bursts::default();
        assert!(b.hit(t0));
        for i in 1..1000 {
            assert!(!b.hit(t0 + Duration::from_millis(i)));
        }
        assert_eq!(b.sweep(t0 + Duration::from_secs(1)), None);
        assert_eq!(
            b.sweep(t0 + Duration::from_secs(40)).map(|(n, _)| n),
            Some(1000)
        );
        assert!(b.hit(t0 + Duration::from_secs(41)));
        assert_eq!(b.total, 1001);
    }
}
