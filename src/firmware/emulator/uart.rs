//! The board's serial port at 115200 baud, 8N1, as the Arduino core drives
//! it: bytes from the host cross the wire one per 86.8 µs into a 64-byte
//! receive ring (63 usable: a byte arriving while it is full is lost), and
//! the sketch's prints go through a 64-byte transmit buffer that blocks the
//! loop while it is full.
//!
//! Owns both directions' timing and the printed bytes waiting for their
//! time: each print is stamped with the moment it returned (its bytes in
//! the transmit buffer; the wire takes at most 5.6 ms more), and
//! [`Uart::release`] hands the host what was printed by `now`. It never
//! interprets the bytes; the sketch does.

use std::collections::VecDeque;
use std::time::Duration;

/// One byte at 115200 baud, 8N1 (ten bit times).
pub(super) const BYTE_TIME: Duration = Duration::from_nanos(86_806);
/// The Arduino core's receive ring: 64 slots, one always free.
pub(super) const RX_RING_BYTES: usize = 63;
/// Bytes the sketch can print before a print waits: the core's 64-byte
/// ring (63 usable) plus the transmit data register.
const TX_BUFFER_BYTES: u32 = 64;

#[derive(Debug, Default)]
pub(super) struct Uart {
    /// Host bytes on the wire, with the time each has fully arrived.
    wire: VecDeque<(Duration, u8)>,
    /// When the host's line is free for its next byte.
    wire_free_at: Duration,
    /// The receive ring the sketch reads.
    ring: VecDeque<u8>,
    /// Bytes lost to a full receive ring.
    rx_lost: u64,
    /// When the transmitter will have sent everything printed so far.
    tx_done_at: Duration,
    /// Printed bytes not yet handed to the host, with the time each
    /// print returned (when its last byte was in the transmit buffer).
    out: VecDeque<(Duration, Vec<u8>)>,
}

impl Uart {
    /// The host wrote `bytes` at `now`: they arrive one byte time apart,
    /// after whatever the host wrote before.
    pub(super) fn host_wrote(&mut self, bytes: &[u8], now: Duration) {
        let mut t = self.wire_free_at.max(now);
        for &b in bytes {
            t += BYTE_TIME;
            self.wire.push_back((t, b));
        }
        self.wire_free_at = t;
    }

    /// Moves what has arrived by `t` into the ring; bytes arriving while
    /// it is full are lost. Called when the sketch reads, which is the only
    /// time the ring empties, so the order of losses is exact.
    fn arrive(&mut self, t: Duration) {
        while let Some(&(at, b)) = self.wire.front() {
            if at > t {
                break;
            }
            self.wire.pop_front();
            if self.ring.len() < RX_RING_BYTES {
                self.ring.push_back(b);
            } else {
                self.rx_lost += 1;
            }
        }
    }

    /// `Serial.available() > 0` at `t`.
    #[cfg(test)]
    pub(super) fn available(&mut self, t: Duration) -> bool {
        self.arrive(t);
        !self.ring.is_empty()
    }

    /// `Serial.read()` at `t`.
    pub(super) fn read(&mut self, t: Duration) -> Option<u8> {
        self.arrive(t);
        self.ring.pop_front()
    }

    /// When the sketch next has to read: when the next frame's `;` has
    /// arrived, or a few bytes before the ring would fill (the first pass
    /// after that time must find room for what arrives meanwhile). Bytes
    /// of a frame still arriving can wait in the ring: the sketch reads
    /// them all at once, in the same order.
    pub(super) fn next_read_due(&self) -> Option<Duration> {
        // More than an idle pass's worth of bytes (0.3 ms, 4 bytes).
        const SLACK: usize = 8;
        let room = RX_RING_BYTES.saturating_sub(self.ring.len() + SLACK).max(1);
        self.wire
            .iter()
            .enumerate()
            .find(|(i, (_, b))| *b == b';' || i + 1 >= room)
            .map(|(_, &(at, _))| at)
    }

    /// Whether unread bytes wait in the ring.
    pub(super) fn pending(&self) -> bool {
        !self.ring.is_empty()
    }

    pub(super) fn rx_lost(&self) -> u64 {
        self.rx_lost
    }

    /// The sketch prints `bytes` at `*clock`; the clock moves on while the
    /// transmit buffer is full, as `Serial.print` blocks.
    pub(super) fn print(&mut self, bytes: &[u8], clock: &mut Duration) {
        self.print_as(bytes, bytes.len(), clock);
    }

    /// As [`Uart::print`], timed as if `sent_len` bytes were printed: line
    /// noise injected on the wire changes the bytes, not the board's time.
    pub(super) fn print_as(&mut self, bytes: &[u8], sent_len: usize, clock: &mut Duration) {
        if sent_len == 0 {
            return;
        }
        let n = sent_len as u32;
        let done = self.tx_done_at.max(*clock) + BYTE_TIME * n;
        self.tx_done_at = done;
        // The last byte goes into the buffer once at most 63 others are
        // still ahead of it, which is 64 byte times before it is sent.
        if let Some(enters) = done.checked_sub(BYTE_TIME * TX_BUFFER_BYTES) {
            *clock = (*clock).max(enters);
        }
        if bytes.is_empty() {
            return;
        }
        // Handed over once printed (the wire's last few milliseconds are not
        // worth a wake-up each); prints of the same moment go together.
        match self.out.back_mut() {
            Some((at, chunk)) if *at == *clock => chunk.extend_from_slice(bytes),
            _ => self.out.push_back((*clock, bytes.to_vec())),
        }
    }

    /// Appends to `out` every printed byte that has left the wire by `now`.
    pub(super) fn release(&mut self, now: Duration, out: &mut Vec<u8>) {
        while let Some((at, _)) = self.out.front() {
            if *at > now {
                break;
            }
            if let Some((_, chunk)) = self.out.pop_front() {
                out.extend_from_slice(&chunk);
            }
        }
    }

    /// When the next printed chunk is handed over.
    pub(super) fn next_release(&self) -> Option<Duration> {
        self.out.front().map(|(at, _)| *at)
    }

    /// A hung board: whatever was printed still goes out, but nothing more
    /// is read; bytes on the wire and in the ring are lost.
    pub(super) fn drop_input(&mut self) {
        self.rx_lost += (self.wire.len() + self.ring.len()) as u64;
        self.wire.clear();
        self.ring.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn host_bytes_arrive_one_byte_time_apart_and_a_full_ring_loses_them() {
        let mut u = Uart::default();
        let burst = vec![b'x'; 100];
        u.host_wrote(&burst, Duration::ZERO);
        assert!(!u.available(Duration::ZERO));
        assert!(u.available(BYTE_TIME));
        // Nobody reads for a second: 63 kept, 37 lost.
        let mut n = 0;
        while u.read(Duration::from_secs(1)).is_some() {
            n += 1;
        }
        assert_eq!((n, u.rx_lost()), (63, 37));
    }

    #[test]
    fn a_long_print_blocks_until_the_buffer_has_room() {
        let mut u = Uart::default();
        let mut clock = Duration::ZERO;
        u.print(&[b'a'; 64], &mut clock);
        assert_eq!(clock, Duration::ZERO, "64 bytes fit");
        u.print(&[b'b'; 36], &mut clock);
        // 100 bytes queued; the last enters when 64 are left to send.
        assert_eq!(clock, BYTE_TIME * 36);
        let mut out = Vec::new();
        u.release(Duration::ZERO, &mut out);
        assert_eq!(out.len(), 64, "the first print is handed over at once");
        u.release(BYTE_TIME * 36, &mut out);
        assert_eq!(out.len(), 100, "the second once it returned");
    }
}
