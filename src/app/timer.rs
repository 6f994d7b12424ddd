//! The vehicle loop's wake-up timer: a kernel timer (timerfd) that fires
//! at its deadline and at no other time.
//!
//! The runtime's own timers sit in a wheel of 64-ms blocks: a deadline in a
//! later block than now wakes the runtime at the start of that block as
//! well, to move it into the fine wheel. The vehicle's next tick is always
//! about a line period ahead and moves with every line of the board, so
//! most such early wake-ups came just before the line that made the tick
//! unnecessary — several a second on an idle vehicle, for nothing. The
//! kernel's timer costs a system call when the deadline moves, and wakes
//! the loop only when it expires.

use std::io;
use std::os::fd::{AsFd, AsRawFd, RawFd};

use nix::sys::time::TimeSpec;
use nix::sys::timerfd::{ClockId, Expiration, TimerFd, TimerFlags, TimerSetTimeFlags};
use tokio::io::unix::AsyncFd;
use tokio::time::Instant;

/// The timerfd, as the runtime's reactor needs it.
struct Fd(TimerFd);

impl AsRawFd for Fd {
    fn as_raw_fd(&self) -> RawFd {
        self.0.as_fd().as_raw_fd()
    }
}

/// A one-shot timer, moved with [`WakeTimer::set`], awaited with
/// [`WakeTimer::expired`].
pub(super) struct WakeTimer {
    fd: AsyncFd<Fd>,
    deadline: Option<Instant>,
}

impl WakeTimer {
    /// A disarmed timer on the monotonic clock (the runtime's `Instant`).
    pub(super) fn new() -> io::Result<Self> {
        let timer = TimerFd::new(
            ClockId::CLOCK_MONOTONIC,
            TimerFlags::TFD_NONBLOCK | TimerFlags::TFD_CLOEXEC,
        )?;
        // `AsyncFd::new` is deprecated because a registered fd could be
        // closed behind the reactor's back; here the reactor owns the timer
        // outright, so nothing else can close it.
        #[allow(deprecated)]
        let fd = AsyncFd::new(Fd(timer))?;
        Ok(Self { fd, deadline: None })
    }

    /// Fires at `at` (at once if it has passed); the kernel hears of it only
    /// when the deadline moves.
    pub(super) fn set(&mut self, at: Instant) -> io::Result<()> {
        if self.deadline == Some(at) {
            return Ok(());
        }
        // A zero value would disarm the timer: a deadline that has passed
        // fires a nanosecond from now.
        let after = at
            .saturating_duration_since(Instant::now())
            .max(std::time::Duration::from_nanos(1));
        self.fd
            .get_ref()
            .0
            .set(
                Expiration::OneShot(TimeSpec::from(after)),
                TimerSetTimeFlags::empty(),
            )
            .map_err(io::Error::from)?;
        self.deadline = Some(at);
        Ok(())
    }

    /// Resolves when the deadline set last has passed; the timer is
    /// disarmed then until the next [`WakeTimer::set`].
    pub(super) async fn expired(&mut self) -> io::Result<()> {
        loop {
            let mut ready = self.fd.readable().await?;
            // Reading the expiry count clears it; nothing to read yet is a
            // stale readiness, and the wait goes on.
            match ready.try_io(|fd| fd.get_ref().0.wait().map_err(io::Error::from)) {
                Ok(result) => {
                    self.deadline = None;
                    return result;
                }
                Err(_would_block) => continue,
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[tokio::test]
    async fn fires_at_its_deadline_and_follows_it_when_moved() {
        let mut t = WakeTimer::new().unwrap();
        let start = Instant::now();
        t.set(start + Duration::from_secs(3600)).unwrap();
        // Moved nearer: the new deadline counts, not the first.
        t.set(start + Duration::from_millis(30)).unwrap();
        tokio::time::timeout(Duration::from_secs(10), t.expired())
            .await
            .expect("the moved deadline fired")
            .unwrap();
        assert!(start.elapsed() >= Duration::from_millis(30));
        // A deadline already past fires at once.
        t.set(start).unwrap();
        tokio::time::timeout(Duration::from_secs(10), t.expired())
            .await
            .expect("a past deadline fired")
            .unwrap();
    }

    #[tokio::test]
    async fn a_disarmed_or_distant_timer_does_not_fire() {
        let mut t = WakeTimer::new().unwrap();
        assert!(
            tokio::time::timeout(Duration::from_millis(50), t.expired())
                .await
                .is_err(),
            "never set"
        );
        t.set(Instant::now() + Duration::from_secs(3600)).unwrap();
        assert!(
            tokio::time::timeout(Duration::from_millis(50), t.expired())
                .await
                .is_err(),
            "an hour away"
        );
    }
}
