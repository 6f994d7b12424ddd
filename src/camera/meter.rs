//! Frame rate over a sliding window, as a pure function of frame times and
//! `now`.

use std::collections::VecDeque;
use std::time::Duration;

use tokio::time::Instant;

/// How far back the measured frame rate looks.
pub const FPS_WINDOW: Duration = Duration::from_secs(3);
/// A source gone wild (ffmpeg without `-re` on a file) must not grow the
/// window without bound: the rate is then measured over the last frames.
const MAX_STAMPS: usize = 512;

#[derive(Debug, Default)]
pub(crate) struct FpsMeter {
    stamps: VecDeque<Instant>,
}

impl FpsMeter {
    pub fn record(&mut self, at: Instant) {
        while let Some(&first) = self.stamps.front() {
            if at.saturating_duration_since(first) > FPS_WINDOW || self.stamps.len() >= MAX_STAMPS {
                self.stamps.pop_front();
            } else {
                break;
            }
        }
        self.stamps.push_back(at);
    }

    /// Frames per second over the window ending at `now`: the n frames in
    /// the window make n − 1 intervals over the time from the first to the
    /// last. Once the source is late by more than its mean interval, the
    /// time since then counts too, so a source that stops decays to 0
    /// instead of showing its last rate forever.
    pub fn fps(&self, now: Instant) -> f64 {
        let mut in_window = self
            .stamps
            .iter()
            .filter(|t| now.saturating_duration_since(**t) <= FPS_WINDOW);
        let Some(first) = in_window.next() else {
            return 0.0;
        };
        let (n, last) = in_window.fold((1usize, first), |(n, _), t| (n + 1, t));
        if n < 2 {
            return 0.0;
        }
        let intervals = (n - 1) as f64;
        let frames_span = last.saturating_duration_since(*first).as_secs_f64();
        let mean_gap = frames_span / intervals;
        let since_first = now.saturating_duration_since(*first).as_secs_f64();
        let span = frames_span.max(since_first - mean_gap);
        if span <= 0.0 { 0.0 } else { intervals / span }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ten_frames_a_second_measure_ten() {
        let t0 = Instant::now();
        let mut m = FpsMeter::default();
        for i in 0..100 {
            m.record(t0 + Duration::from_millis(100 * i));
        }
        // At a frame, and between two frames.
        for now in [9900, 9950, 9999].map(|ms| t0 + Duration::from_millis(ms)) {
            assert!((m.fps(now) - 10.0).abs() < 1e-9, "{}", m.fps(now));
        }
        assert!(m.stamps.len() <= 31);
    }

    #[test]
    fn a_stopped_source_decays_to_zero() {
        let t0 = Instant::now();
        let mut m = FpsMeter::default();
        assert_eq!(m.fps(t0), 0.0);
        for i in 0..30 {
            m.record(t0 + Duration::from_millis(100 * i));
        }
        let last = t0 + Duration::from_millis(2900);
        let later = m.fps(last + Duration::from_secs(1));
        assert!(later < 10.0 && later > 0.0, "{later}");
        assert_eq!(m.fps(last + Duration::from_secs(4)), 0.0);
    }

    #[test]
    fn a_flood_keeps_a_bounded_window() {
        let t0 = Instant::now();
        let mut m = FpsMeter::default();
        for i in 0..10_000 {
            m.record(t0 + Duration::from_micros(100 * i));
        }
        assert!(m.stamps.len() <= MAX_STAMPS);
        let fps = m.fps(t0 + Duration::from_micros(100 * 9_999));
        assert!((fps - 10_000.0).abs() < 1.0, "{fps}");
    }
}
