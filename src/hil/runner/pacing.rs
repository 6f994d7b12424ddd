//! The simulator thread of [`super`]: the bench ([`super::super::bench`])
//! paced to the wall clock in 1 ms slices, the UART bridged to the pty at
//! its baud rate, the controls applied between slices, the pulse changes
//! stamped with the wall time, and the figures kept. Nothing here leaves
//! this thread but what goes through the shared snapshot and the
//! subscribers' channels.

use std::os::fd::{AsFd, OwnedFd};
use std::sync::mpsc::{Receiver, Sender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::super::avr::{AvrError, F_CPU_HZ};
use super::super::bench::Bench;
use super::super::pins::PulseChange;
use super::{
    Ctl, GenuineSnapshot, MAX_DEBT_CYCLES, SLICE_CYCLES, SPEED_WINDOW, SerialChunk, TimedChange,
};

/// The simulator thread's state.
pub(super) struct Runner {
    bench: Bench,
    master: OwnedFd,
    shared: Arc<Mutex<GenuineSnapshot>>,
    serial_subs: Vec<Sender<SerialChunk>>,
    change_subs: Vec<Sender<TimedChange>>,
    anchor_cycle: u64,
    anchor_wall: Instant,
    stats: GenuineSnapshot,
    window_start: (Instant, u64, Duration),
    busy: Duration,
}

impl Runner {
    pub(super) fn new(bench: Bench, master: OwnedFd, shared: Arc<Mutex<GenuineSnapshot>>) -> Self {
        let stats = shared
            .lock()
            .map(|s| s.clone())
            .unwrap_or_else(|p| p.into_inner().clone());
        let now = Instant::now();
        let cycle = bench.cycle();
        Self {
            bench,
            master,
            shared,
            serial_subs: Vec::new(),
            change_subs: Vec::new(),
            anchor_cycle: cycle,
            anchor_wall: now,
            stats,
            window_start: (now, cycle, Duration::ZERO),
            busy: Duration::ZERO,
        }
    }

    fn wall_of(&self, cycle: u64) -> Instant {
        let ns = u128::from(cycle.saturating_sub(self.anchor_cycle)) * 1_000_000_000
            / u128::from(F_CPU_HZ);
        self.anchor_wall + Duration::from_nanos(ns.min(u128::from(u64::MAX)) as u64)
    }

    pub(super) fn run(&mut self, rx: &Receiver<Ctl>) {
        let mut out = Vec::with_capacity(4096);
        let mut changes: Vec<PulseChange> = Vec::with_capacity(16);
        let mut buf = [0u8; 1024];
        loop {
            loop {
                match rx.try_recv() {
                    Ok(Ctl::Stop) | Err(TryRecvError::Disconnected) => return,
                    Ok(c) => self.control(c),
                    Err(TryRecvError::Empty) => break,
                }
            }
            self.read_host(&mut buf);
            let now = Instant::now();
            let due = now.saturating_duration_since(self.anchor_wall);
            let target =
                self.anchor_cycle + (due.as_nanos() * u128::from(F_CPU_HZ) / 1_000_000_000) as u64;
            let cycle = self.bench.cycle();
            if cycle >= target {
                // Ahead of the wall clock: wait for host bytes or the next slice.
                let ahead_ns = (cycle - target + SLICE_CYCLES) * 1_000_000_000 / F_CPU_HZ;
                let ms = (ahead_ns / 1_000_000).clamp(1, 5) as u8;
                let mut fds = [nix::poll::PollFd::new(
                    self.master.as_fd(),
                    nix::poll::PollFlags::POLLIN,
                )];
                let _ = nix::poll::poll(&mut fds, nix::poll::PollTimeout::from(ms));
                continue;
            }
            if target - cycle > MAX_DEBT_CYCLES {
                // Cannot keep up: run slow from here instead of in a burst.
                self.stats.slips += 1;
                self.anchor_cycle = cycle;
                self.anchor_wall = now;
            }
            // A whole slice, even if that runs up to a slice ahead of the
            // wall clock: the wait above then sleeps instead of spinning.
            let end = cycle + SLICE_CYCLES;
            let started = Instant::now();
            if let Err(e) = self.bench.run_until(end, &mut out, &mut changes) {
                self.stop_with(e);
                // A crashed board stays silent until stopped (or reset).
                if !self.wait_for_reset(rx) {
                    return;
                }
                continue;
            }
            self.busy += started.elapsed();
            // After every slice, ahead of the wall clock or behind it: a
            // runner that cannot keep up (a loaded machine) must not leave
            // the pins of seconds ago in the snapshot.
            self.publish(Instant::now());
            if !out.is_empty() {
                self.send_to_host(&out);
                out.clear();
            }
            for c in changes.drain(..) {
                self.emit_change(c);
            }
        }
    }

    fn control(&mut self, c: Ctl) {
        match c {
            Ctl::Analog(a) => self.bench.set_analog(a),
            Ctl::Water(w) => self.bench.set_water(w),
            Ctl::Attitude(a) => self.bench.set_attitude(a),
            Ctl::Reset => {
                self.stats.resets += 1;
                self.stats.error = None;
                for c in self.bench.reset() {
                    self.emit_change(c);
                }
            }
            Ctl::Inject(bytes) => self.bench.inject(bytes),
            Ctl::Serial(tx) => self.serial_subs.push(tx),
            Ctl::Changes(tx) => self.change_subs.push(tx),
            Ctl::Stop => {}
        }
    }

    /// Takes what the host wrote to the pty.
    fn read_host(&mut self, buf: &mut [u8]) {
        loop {
            match nix::unistd::read(self.master.as_fd(), buf) {
                Ok(0) | Err(_) => return,
                Ok(n) => {
                    self.stats.bytes_to_board += n as u64;
                    let chunk = &buf[..n];
                    self.bench.host_wrote(chunk);
                    let at = Instant::now();
                    self.serial_subs.retain(|s| {
                        s.send(SerialChunk {
                            at,
                            to_board: true,
                            bytes: chunk.to_vec(),
                        })
                        .is_ok()
                    });
                }
            }
        }
    }

    fn send_to_host(&mut self, bytes: &[u8]) {
        self.stats.bytes_from_board += bytes.len() as u64;
        let mut rest = bytes;
        while !rest.is_empty() {
            match nix::unistd::write(&self.master, rest) {
                Ok(n) if n > 0 => rest = &rest[n..],
                _ => {
                    // Nobody reads the pty and its buffer is full: the bytes
                    // are lost, as on a UART with nobody listening.
                    self.stats.bytes_lost += rest.len() as u64;
                    break;
                }
            }
        }
        let at = Instant::now();
        self.serial_subs.retain(|s| {
            s.send(SerialChunk {
                at,
                to_board: false,
                bytes: bytes.to_vec(),
            })
            .is_ok()
        });
    }

    fn emit_change(&mut self, change: PulseChange) {
        let at = self.wall_of(change.cycle);
        self.change_subs
            .retain(|s| s.send(TimedChange { at, change }).is_ok());
    }

    fn publish(&mut self, now: Instant) {
        let cycle = self.bench.cycle();
        let (w0, c0, b0) = self.window_start;
        let wall = now.saturating_duration_since(w0);
        if wall >= SPEED_WINDOW {
            let sim = cycle.saturating_sub(c0) as f64 / F_CPU_HZ as f64;
            self.stats.realtime_ratio = sim / wall.as_secs_f64();
            let busy = self.busy.saturating_sub(b0).as_secs_f64();
            if busy > 0.0 {
                self.stats.speed_ratio = sim / busy;
            }
            self.window_start = (now, cycle, self.busy);
        }
        self.stats.sim_time_s = cycle as f64 / F_CPU_HZ as f64;
        self.stats.pins = self.bench.pins();
        self.stats.analog = self.bench.analog();
        self.stats.water = self.bench.water();
        self.stats.attitude = self.bench.attitude();
        if let Ok(mut s) = self.shared.lock() {
            *s = self.stats.clone();
        }
    }

    fn stop_with(&mut self, e: AvrError) {
        tracing::error!(error = %e, "the genuine board stopped");
        self.stats.error = Some(e.to_string());
        self.publish(Instant::now());
    }

    /// After a crash: waits for a reset (`true`) or the end (`false`).
    fn wait_for_reset(&mut self, rx: &Receiver<Ctl>) -> bool {
        loop {
            match rx.recv() {
                Ok(Ctl::Stop) | Err(_) => return false,
                Ok(Ctl::Reset) => {
                    self.control(Ctl::Reset);
                    self.anchor_cycle = self.bench.cycle();
                    self.anchor_wall = Instant::now();
                    return true;
                }
                Ok(c) => self.control(c),
            }
        }
    }
}
