//! A damaging serial line: a pseudo-terminal relay that sits between the
//! vehicle and a board's pty and spoils bytes the way a long or wet cable
//! to the board does — a bit flipped in one byte of N, one byte of M lost,
//! each way, from a seeded random generator so that a run can be repeated.
//!
//! Owns the damage ([`Damager`], sans-IO: bytes in, bytes out, counted) and
//! the relay thread ([`NoisyRelay`]): its own raw pty, whose slave is the
//! device the vehicle opens (`--serial`), and the board's device, opened
//! like a serial port. It never decides anything about the bytes beyond
//! the dice: no parsing, no delay of its own (the board's runner puts what
//! it gets on the UART at the baud rate). Tests and benches use it
//! (`tests/genuine_noisy_line.rs`, `benches/noisy_line.rs`).

use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use nix::fcntl::{OFlag, open};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::stat::Mode;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use rand::rngs::SmallRng;
use rand::{Rng as _, SeedableRng as _};

use crate::firmware::pty::{PtyError, open_raw};

/// How one direction of the line is damaged: each byte independently has
/// a one-in-`flip_one_in` chance of one of its bits (chosen at random)
/// flipped, and a one-in-`drop_one_in` chance of being lost. `0` turns a
/// kind of damage off.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Damage {
    pub flip_one_in: u32,
    pub drop_one_in: u32,
}

impl Damage {
    /// A clean line.
    pub const NONE: Self = Self {
        flip_one_in: 0,
        drop_one_in: 0,
    };

    /// One byte in `flip_one_in` with a flipped bit, one in `drop_one_in` lost.
    pub fn new(flip_one_in: u32, drop_one_in: u32) -> Self {
        Self {
            flip_one_in,
            drop_one_in,
        }
    }

    /// The same damage `factor` times rarer.
    pub fn rarer(self, factor: u32) -> Self {
        Self {
            flip_one_in: self.flip_one_in.saturating_mul(factor),
            drop_one_in: self.drop_one_in.saturating_mul(factor),
        }
    }
}

/// What the relay did to the bytes of one direction so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DamageCount {
    pub bytes: u64,
    pub flipped: u64,
    pub dropped: u64,
}

/// The dice of one direction (sans-IO).
#[derive(Debug)]
pub struct Damager {
    damage: Damage,
    rng: SmallRng,
    count: DamageCount,
}

impl Damager {
    pub fn new(damage: Damage, seed: u64) -> Self {
        Self {
            damage,
            rng: SmallRng::seed_from_u64(seed),
            count: DamageCount::default(),
        }
    }

    /// Appends `bytes` to `out` as the line delivers them.
    pub fn pass(&mut self, bytes: &[u8], out: &mut Vec<u8>) {
        for &b in bytes {
            self.count.bytes += 1;
            if self.damage.drop_one_in > 0 && self.rng.random_ratio(1, self.damage.drop_one_in) {
                self.count.dropped += 1;
                continue;
            }
            let mut b = b;
            if self.damage.flip_one_in > 0 && self.rng.random_ratio(1, self.damage.flip_one_in) {
                b ^= 1 << self.rng.random_range(0..8u8);
                self.count.flipped += 1;
            }
            out.push(b);
        }
    }

    pub fn count(&self) -> DamageCount {
        self.count
    }
}

/// Errors starting the relay.
#[derive(Debug, thiserror::Error)]
pub enum RelayError {
    #[error(transparent)]
    Pty(#[from] PtyError),
    #[error("cannot open the board's device {path}: {source}")]
    Open { path: PathBuf, source: nix::Error },
    #[error("cannot start the relay thread: {0}")]
    Thread(std::io::Error),
}

#[derive(Debug, Default)]
struct Counters {
    to_board: Mutex<DamageCount>,
    from_board: Mutex<DamageCount>,
    /// Bytes the far side had no room for (a pty's buffer full).
    overflowed: AtomicU64,
}

/// The relay, running until dropped.
#[derive(Debug)]
pub struct NoisyRelay {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
    thread: Option<JoinHandle<()>>,
}

impl NoisyRelay {
    /// Opens `board` (the board's serial device, such as a
    /// [`super::GenuineBoard`]'s pty) and relays between it and a fresh pty,
    /// damaging `to_board` and `from_board` as given; the dice of each
    /// direction are seeded from `seed`.
    pub fn spawn(
        board: &Path,
        to_board: Damage,
        from_board: Damage,
        seed: u64,
    ) -> Result<Self, RelayError> {
        let far = open(
            board,
            OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_NONBLOCK,
            Mode::empty(),
        )
        .map_err(|source| RelayError::Open {
            path: board.to_path_buf(),
            source,
        })?;
        if let Ok(mut tio) = tcgetattr(far.as_fd()) {
            cfmakeraw(&mut tio);
            let _ = tcsetattr(far.as_fd(), SetArg::TCSANOW, &tio);
        }
        let near = open_raw()?;
        let path = near.slave_path.clone();
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(Counters::default());
        let (stop2, counters2) = (Arc::clone(&stop), Arc::clone(&counters));
        let thread = std::thread::Builder::new()
            .name("noisy-relay".into())
            .spawn(move || {
                let mut down = Damager::new(to_board, seed);
                let mut up = Damager::new(from_board, seed ^ 0x9E37_79B9_7F4A_7C15);
                relay(&near.master, &far, &mut down, &mut up, &stop2, &counters2);
                // The slave stays open until here, so the master never sees
                // a hang-up while the vehicle reopens the device.
                drop(near.slave);
            })
            .map_err(RelayError::Thread)?;
        Ok(Self {
            path,
            stop,
            counters,
            thread: Some(thread),
        })
    }

    /// The device the vehicle opens (`--serial`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What was done so far to the bytes towards the board and from it,
    /// and how many bytes a full pty refused.
    pub fn counts(&self) -> (DamageCount, DamageCount, u64) {
        let get = |m: &Mutex<DamageCount>| match m.lock() {
            Ok(c) => *c,
            Err(p) => *p.into_inner(),
        };
        (
            get(&self.counters.to_board),
            get(&self.counters.from_board),
            self.counters.overflowed.load(Ordering::Relaxed),
        )
    }
}

impl Drop for NoisyRelay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Bytes waiting for the far side to have room, at most this many (then
/// dropped and counted: a UART with nobody reading loses them too).
const MAX_PENDING: usize = 64 * 1024;

fn relay(
    near: &OwnedFd,
    far: &OwnedFd,
    down: &mut Damager,
    up: &mut Damager,
    stop: &AtomicBool,
    counters: &Counters,
) {
    let mut buf = [0u8; 1024];
    let (mut to_far, mut to_near) = (Vec::new(), Vec::new());
    while !stop.load(Ordering::Relaxed) {
        let flags = |pending: &[u8]| {
            if pending.is_empty() {
                PollFlags::POLLIN
            } else {
                PollFlags::POLLIN | PollFlags::POLLOUT
            }
        };
        let mut fds = [
            PollFd::new(near.as_fd(), flags(&to_near)),
            PollFd::new(far.as_fd(), flags(&to_far)),
        ];
        if poll(&mut fds, PollTimeout::from(20u16)).is_err() {
            continue;
        }
        let ready = |fd: &PollFd, f: PollFlags| fd.revents().is_some_and(|r| r.intersects(f));
        let (near_in, far_in) = (
            ready(&fds[0], PollFlags::POLLIN),
            ready(&fds[1], PollFlags::POLLIN),
        );
        if near_in {
            move_bytes(near.as_fd(), &mut buf, down, &mut to_far, counters, true);
        }
        if far_in {
            move_bytes(far.as_fd(), &mut buf, up, &mut to_near, counters, false);
        }
        flush(far.as_fd(), &mut to_far);
        flush(near.as_fd(), &mut to_near);
        for pending in [&mut to_far, &mut to_near] {
            if pending.len() > MAX_PENDING {
                let extra = pending.len() - MAX_PENDING;
                pending.drain(..extra);
                counters
                    .overflowed
                    .fetch_add(extra as u64, Ordering::Relaxed);
            }
        }
        if !near_in && !far_in && fds.iter().any(|f| ready(f, PollFlags::POLLHUP)) {
            // Nobody on a side (the board's runner gone): do not spin.
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
}

fn move_bytes(
    from: BorrowedFd<'_>,
    buf: &mut [u8],
    dice: &mut Damager,
    pending: &mut Vec<u8>,
    counters: &Counters,
    to_board: bool,
) {
    if let Ok(n) = nix::unistd::read(from, buf)
        && n > 0
    {
        dice.pass(&buf[..n], pending);
        let slot = if to_board {
            &counters.to_board
        } else {
            &counters.from_board
        };
        match slot.lock() {
            Ok(mut c) => *c = dice.count(),
            Err(p) => *p.into_inner() = dice.count(),
        }
    }
}

fn flush(to: BorrowedFd<'_>, pending: &mut Vec<u8>) {
    if pending.is_empty() {
        return;
    }
    if let Ok(n) = nix::unistd::write(to, pending) {
        pending.drain(..n);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dice_damage_at_the_rates_asked_and_repeat_with_the_seed() {
        let bytes = vec![0x55u8; 400_000];
        let run = |seed| {
            let mut d = Damager::new(Damage::new(400, 2000), seed);
            let mut out = Vec::new();
            d.pass(&bytes, &mut out);
            (out, d.count())
        };
        let (out, count) = run(7);
        assert_eq!(count.bytes, 400_000);
        assert!((800..1200).contains(&count.flipped), "{count:?}");
        assert!((140..260).contains(&count.dropped), "{count:?}");
        assert_eq!(out.len() as u64, count.bytes - count.dropped);
        let changed = out.iter().filter(|&&b| b != 0x55).count() as u64;
        assert_eq!(changed, count.flipped, "each flip changes one byte");
        assert!(
            out.iter()
                .all(|&b| b == 0x55 || (b ^ 0x55).count_ones() == 1)
        );
        assert_eq!(run(7).0, out, "the same seed, the same damage");
        assert_ne!(run(8).0, out);
        let mut clean = Damager::new(Damage::NONE, 1);
        let mut out = Vec::new();
        clean.pass(&bytes, &mut out);
        assert_eq!(out, bytes);
    }
}
