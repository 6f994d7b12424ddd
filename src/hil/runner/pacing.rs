//! The simulator thread of [`super`]: simavr paced to the wall clock in
//! 1 ms slices, the UART bridged to the pty at its baud rate, the controls
//! applied between slices, the pin edges measured, and the figures kept.
//! Nothing here leaves this thread but what goes through the shared
//! snapshot and the subscribers' channels.

use std::cell::RefCell;
use std::os::fd::{AsFd, OwnedFd};
use std::rc::Rc;
use std::sync::mpsc::{Receiver, Sender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::super::avr::{AvrError, Edge, F_CPU_HZ, Mcu};
use super::super::bno055::{Attitude, Bno055};
use super::super::ms5803::{Ms5803, Water};
use super::super::pins::{Pins, PulseChange, reg};
use super::{
    Analog, Ctl, GenuineSnapshot, MAX_DEBT_CYCLES, SLICE_CYCLES, SPEED_WINDOW, SerialChunk,
    TimedChange,
};

/// The devices on the I2C bus, each if wired; the runner keeps its own
/// handle to change their surroundings between slices.
pub(super) struct Sensors {
    pub(super) depth: Option<Rc<RefCell<Ms5803>>>,
    pub(super) imu: Option<Rc<RefCell<Bno055>>>,
}

/// The simulator thread's state.
pub(super) struct Runner {
    mcu: Mcu,
    master: OwnedFd,
    analog: Analog,
    sensors: Sensors,
    water: Water,
    attitude: Attitude,
    shared: Arc<Mutex<GenuineSnapshot>>,
    pins: Pins,
    /// Host bytes not yet on the UART line.
    from_host: std::collections::VecDeque<u8>,
    /// Whether the last host byte put on the line ended a frame.
    host_at_boundary: bool,
    inject: std::collections::VecDeque<Vec<u8>>,
    serial_subs: Vec<Sender<SerialChunk>>,
    change_subs: Vec<Sender<TimedChange>>,
    anchor_cycle: u64,
    anchor_wall: Instant,
    stats: GenuineSnapshot,
    window_start: (Instant, u64, Duration),
    busy: Duration,
}

impl Runner {
    pub(super) fn new(
        mut mcu: Mcu,
        sensors: Sensors,
        master: OwnedFd,
        analog: Analog,
        shared: Arc<Mutex<GenuineSnapshot>>,
    ) -> Self {
        for (channel, mv) in analog.inputs() {
            mcu.set_adc_mv(channel, mv);
        }
        let stats = shared
            .lock()
            .map(|s| s.clone())
            .unwrap_or_else(|p| p.into_inner().clone());
        let now = Instant::now();
        let cycle = mcu.cycle();
        Self {
            mcu,
            master,
            analog,
            sensors,
            water: Water::default(),
            attitude: Attitude::default(),
            shared,
            pins: Pins::default(),
            from_host: Default::default(),
            host_at_boundary: true,
            inject: Default::default(),
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
        let mut edges: Vec<Edge> = Vec::with_capacity(256);
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
            let cycle = self.mcu.cycle();
            if cycle >= target {
                self.publish(now);
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
            self.feed_uart();
            let started = Instant::now();
            if let Err(e) = self.mcu.run_until(end) {
                self.stop_with(e);
                // A crashed board stays silent until stopped (or reset).
                if !self.wait_for_reset(rx) {
                    return;
                }
                continue;
            }
            self.busy += started.elapsed();
            self.mcu.take_output(&mut out);
            if !out.is_empty() {
                self.send_to_host(&out);
                out.clear();
            }
            self.mcu.take_edges(&mut edges);
            for e in edges.drain(..) {
                if let Some(c) = self.pins.edge(e.pin, e.cycle, e.high) {
                    self.emit_change(c);
                }
            }
            let cycle = self.mcu.cycle();
            for c in self.pins.expire(cycle) {
                self.emit_change(c);
            }
            self.pins.timer5(
                self.mcu.data(reg::TCCR5A),
                self.mcu.data(reg::OCR5BL),
                self.mcu.data(reg::OCR5CL),
                self.mcu.data(reg::PORTL),
            );
        }
    }

    fn control(&mut self, c: Ctl) {
        match c {
            Ctl::Analog(a) => {
                self.analog = a;
                for (channel, mv) in a.inputs() {
                    self.mcu.set_adc_mv(channel, mv);
                }
            }
            Ctl::Water(w) => {
                self.water = w;
                if let Some(sensor) = &self.sensors.depth {
                    sensor.borrow_mut().set_water(&w);
                }
            }
            Ctl::Attitude(a) => {
                self.attitude = a;
                if let Some(sensor) = &self.sensors.imu {
                    sensor.borrow_mut().set_attitude(&a);
                }
            }
            Ctl::Reset => {
                self.mcu.reset();
                self.stats.resets += 1;
                self.stats.error = None;
                let cycle = self.mcu.cycle();
                for c in self.pins.clear(cycle) {
                    self.emit_change(c);
                }
            }
            Ctl::Inject(bytes) => self.inject.push_back(bytes),
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
                    self.from_host.extend(chunk);
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

    /// Puts waiting bytes on the UART line while its receiver has room;
    /// injected frames go in between two of the host's.
    fn feed_uart(&mut self) {
        while self.mcu.uart_ready() {
            if self.host_at_boundary
                && let Some(frame) = self.inject.pop_front()
            {
                for b in frame {
                    self.mcu.uart_send(b);
                }
                continue;
            }
            let Some(b) = self.from_host.pop_front() else {
                break;
            };
            self.mcu.uart_send(b);
            self.host_at_boundary = b == b';';
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
        let cycle = self.mcu.cycle();
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
        self.stats.pins = self.pins.report(cycle);
        self.stats.analog = self.analog;
        self.stats.water = self.water;
        self.stats.attitude = self.attitude;
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
                    self.anchor_cycle = self.mcu.cycle();
                    self.anchor_wall = Instant::now();
                    return true;
                }
                Ok(c) => self.control(c),
            }
        }
    }
}
