//! The serial line's quality as the pilot sees it (SYS_STATUS
//! `drop_rate_comm` and `errors_comm`, the browser's board pill, `doctor`):
//! frames that did not make the round trip to the board and back, and
//! lines from the board that arrived damaged, over a sliding window.
//!
//! A *damaged or lost frame* is one of ours the board rejected (its
//! `crc:fail`), or one whose echo never came (lost on the way there or
//! its echo lost on the way back: either way the vehicle could not know
//! the board took it). A *damaged line* is a board line the decoder
//! rejected (torn, non-numeric, out of range, overlong). The drop rate is
//! the share of both among everything sent and received in the window.
//! Sans-IO: it reads the link's cumulative figures with the time given.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use super::super::LinkStats;

/// The window the drop rate is taken over.
pub(super) const WINDOW: Duration = Duration::from_secs(10);
/// How often a mark is kept (the window's resolution).
const MARK_EVERY: Duration = Duration::from_secs(1);

/// (frames, bad frames, lines, bad lines), cumulative.
type Counts = (u64, u64, u64, u64);

fn counts(s: &LinkStats) -> Counts {
    let bad_lines = s.decode.rejected_total();
    (
        s.commands_written,
        s.crc_failures_echoed + s.echoes_missed,
        s.decode.lines_accepted + bad_lines,
        bad_lines,
    )
}

/// Damaged or lost frames and lines since the link started (both ways),
/// as SYS_STATUS `errors_comm` carries them (saturating at 65,535).
pub(crate) fn errors(s: &LinkStats) -> u16 {
    let (_, bad_frames, _, bad_lines) = counts(s);
    u16::try_from(bad_frames + bad_lines).unwrap_or(u16::MAX)
}

#[derive(Debug, Default)]
pub(super) struct Quality {
    marks: VecDeque<(Instant, Counts)>,
}

impl Quality {
    /// The drop rate (hundredths of a percent, 0..=10,000) over the last
    /// [`WINDOW`] at `now`, keeping a mark of `s` at most every second.
    pub(super) fn drop_rate_cpct(&mut self, s: &LinkStats, now: Instant) -> u16 {
        let current = counts(s);
        if self
            .marks
            .back()
            .is_none_or(|(t, _)| now.duration_since(*t) >= MARK_EVERY)
        {
            self.marks.push_back((now, current));
        }
        while self.marks.len() > 1
            && self
                .marks
                .get(1)
                .is_some_and(|(t, _)| now.duration_since(*t) >= WINDOW)
        {
            self.marks.pop_front();
        }
        let Some(&(_, old)) = self.marks.front() else {
            return 0;
        };
        let total = (current.0 - old.0) + (current.2 - old.2);
        let bad = (current.1 - old.1) + (current.3 - old.3);
        if total == 0 {
            return 0;
        }
        u16::try_from((bad.min(total) * 10_000).div_ceil(total)).unwrap_or(10_000)
    }
}
