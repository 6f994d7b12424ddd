//! The 2015 board's behaviour, sans-IO: bytes in from the host and the
//! current time, bytes out that the board would print.
//!
//! Owns the frame buffer (80 bytes, frames end at the first `;`, CRC-8
//! check and the `rawcmd:`/`crc:`/`cmd:` echo), the 5-slot command queue
//! worked at one command per 1 ms loop, `atoi` argument parsing, `go()`
//! validation, the deadzone and reverse multiplier on the ESC outputs, the
//! tilt servo's slew, the dead-man switch, the simulator's steps and the
//! 10 Hz / 1 Hz telemetry schedule. Fault injection on the telemetry lines
//! is [`super::faults`]'.
//!
//! It must never read a clock, sleep or touch a file descriptor: time comes
//! in as an argument (a `Duration` since power-up), so the pty wrapper, the
//! in-process loopback and the tests drive the same board.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::time::Duration;

use super::faults::FaultInjector;
use super::{BoardRecord, BoardSnapshot, EmulatorOptions, SimSnapshot, print};
use crate::firmware::codec::{Framing, crc8};
use crate::sim::{Plant, Readings, SimError, SimState};

/// Bytes the board buffers for one frame before giving up on it.
pub const FRAME_BUFFER_BYTES: usize = 80;
/// Slots in the board's command queue.
pub const COMMAND_QUEUE_SLOTS: usize = 5;
/// Arguments the board parses per command.
pub const MAX_ARGS: usize = 10;
/// `rcap()` answer: lights, lasers, camera mount, compass, orientation, depth (bits 1..=6).
pub const CAPABILITIES: u32 = 0b111_1110;
/// The board firmware's neutral pulse width: the emulator plays the board,
/// so it keeps its own constant apart from the vehicle's
/// `mixer::NEUTRAL_US` on purpose (an independent check).
const NEUTRAL_US: i32 = 1500;
const SIM_STEP: Duration = Duration::from_millis(10);
/// The board works through one queued command per loop iteration.
const LOOP_PERIOD: Duration = Duration::from_millis(1);
/// One byte at 115200 baud, 8N1.
const BYTE_TIME: Duration = Duration::from_nanos(86_806);
const DEAD_MAN_TIMEOUT: Duration = Duration::from_secs(2);
const DEAD_MAN_AUTO_ARM: Duration = Duration::from_secs(180);

/// The emulated board (sans-IO).
#[derive(Debug)]
pub struct Board {
    opts: EmulatorOptions,
    faults: FaultInjector,
    plant: Plant,
    sim_time: Duration,
    frame: Vec<u8>,
    frame_overflow: bool,
    wire_credit: Duration,
    queue: VecDeque<String>,
    last_loop: Duration,
    next_nav: Duration,
    next_status: Duration,
    booted: bool,
    target_us: [i32; 3],
    motors_us: [i32; 3],
    reported_motors_us: Option<[i32; 3]>,
    motors_attached: bool,
    dms_armed: bool,
    dms_tripped: bool,
    last_ping: Duration,
    lights: u8,
    laser: u8,
    tilt_us: i32,
    tilt_target_us: i32,
    depth_offset_m: f64,
    esc_power: bool,
    stalled: bool,
    frames_ok: u64,
    crc_failures: u64,
    overruns: u64,
    executed_total: u64,
    executed_log: Vec<BoardRecord>,
    log_executed: bool,
    now: Duration,
}

impl Board {
    /// A board at power-up; nothing is printed until [`Board::start`].
    ///
    /// # Panics
    /// If `opts.sim` is invalid (see [`SimOptions::validate`](crate::sim::SimOptions::validate)); the defaults
    /// and [`EmulatorOptions::ideal_thesis`] never are. Use
    /// [`Board::try_new`] for options that come from a user.
    pub fn new(opts: EmulatorOptions) -> Self {
        match Self::try_new(opts) {
            Ok(board) => board,
            Err(e) => panic!("{e}"),
        }
    }

    /// A board at power-up, or why its simulator options are unusable.
    pub fn try_new(opts: EmulatorOptions) -> Result<Self, SimError> {
        let plant = Plant::new(&opts.sim, opts.wiring_directions)?;
        let faults = FaultInjector::new(opts.faults.clone());
        Ok(Self {
            opts,
            faults,
            plant,
            sim_time: Duration::ZERO,
            frame: Vec::with_capacity(FRAME_BUFFER_BYTES),
            frame_overflow: false,
            wire_credit: Duration::ZERO,
            queue: VecDeque::with_capacity(COMMAND_QUEUE_SLOTS),
            last_loop: Duration::ZERO,
            next_nav: Duration::ZERO,
            next_status: Duration::ZERO,
            booted: false,
            target_us: [NEUTRAL_US; 3],
            motors_us: [NEUTRAL_US; 3],
            reported_motors_us: None,
            motors_attached: true,
            dms_armed: false,
            dms_tripped: false,
            last_ping: Duration::ZERO,
            lights: 0,
            laser: 0,
            tilt_us: NEUTRAL_US,
            tilt_target_us: NEUTRAL_US,
            depth_offset_m: 0.0,
            esc_power: true,
            stalled: false,
            frames_ok: 0,
            crc_failures: 0,
            overruns: 0,
            executed_total: 0,
            executed_log: Vec::new(),
            log_executed: false,
            now: Duration::ZERO,
        })
    }

    /// Keep every received frame and executed command (read back with
    /// [`Board::take_records`]).
    pub fn record(&mut self, on: bool) {
        self.log_executed = on;
    }

    /// Frames received and commands executed since the last call.
    pub fn take_records(&mut self) -> Vec<BoardRecord> {
        std::mem::take(&mut self.executed_log)
    }

    /// Sets the simulated vehicle's pose and 4-DOF velocities (tests,
    /// scenario start): [`Plant::set_pose`] then [`Plant::set_velocities`].
    /// With the 6-DOF model the vehicle starts level with no roll or pitch
    /// rate, and the thrusters restart from rest.
    pub fn set_sim_state(&mut self, s: SimState) {
        self.plant.set_pose(s.eta[0], s.eta[1], s.eta[2], s.eta[3]);
        self.plant
            .set_velocities(s.nu[0], s.nu[1], s.nu[2], s.nu[3]);
    }

    /// The simulated vehicle.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// The simulated vehicle, to set a scenario up.
    pub fn plant_mut(&mut self) -> &mut Plant {
        &mut self.plant
    }

    /// Stalls the board: it neither reads nor prints, as a hung firmware.
    pub fn set_stalled(&mut self, stalled: bool) {
        self.stalled = stalled;
    }

    /// Power-up at `now`: prints `boot:1;`.
    pub fn start(&mut self, now: Duration, out: &mut Vec<u8>) {
        self.now = now;
        self.booted = true;
        self.last_loop = now;
        self.sim_time = now;
        self.last_ping = now;
        self.next_nav = now + Duration::from_millis(self.opts.nav_period_ms);
        self.next_status = now + Duration::from_millis(self.opts.status_period_ms);
        out.extend_from_slice(b"boot:1;\r\n");
    }

    /// Bytes from the host at `now`. Complete frames are checked and queued;
    /// the queue is worked through by [`Board::tick`].
    pub fn receive(&mut self, bytes: &[u8], now: Duration, out: &mut Vec<u8>) {
        if self.stalled || !self.booted {
            return;
        }
        self.tick(now, out);
        for &b in bytes {
            // A UART delivers a byte per 10 bit times; the board's loop runs
            // meanwhile. Bytes that reach us in one burst (the emulator task
            // was scheduled late) still took that long on a real wire.
            self.wire_credit += BYTE_TIME;
            while self.wire_credit >= LOOP_PERIOD {
                self.wire_credit -= LOOP_PERIOD;
                match self.queue.pop_front() {
                    Some(cmd) => self.execute(&cmd, out),
                    None => {
                        self.wire_credit = Duration::ZERO;
                        break;
                    }
                }
            }
            if b == b';' {
                if self.frame_overflow {
                    self.frame.clear();
                    self.frame_overflow = false;
                } else {
                    self.frame.push(b);
                    let frame = std::mem::take(&mut self.frame);
                    self.accept_frame(&frame, out);
                    self.frame = frame;
                    self.frame.clear();
                }
            } else if self.frame.len() < FRAME_BUFFER_BYTES {
                self.frame.push(b);
            } else {
                self.frame_overflow = true;
            }
        }
    }

    fn accept_frame(&mut self, frame: &[u8], out: &mut Vec<u8>) {
        if self.log_executed {
            self.executed_log.push(BoardRecord::Frame(frame.to_vec()));
        }
        let mut line = String::from("rawcmd:");
        for b in frame {
            let _ = write!(line, "{b:x},");
        }
        line.push(';');
        print(&line, out);
        let text = match self.opts.framing {
            Framing::Crc8 => {
                let (got, text) = match frame.split_first() {
                    Some((&got, text)) => (got, text),
                    None => return,
                };
                let calc = crc8(text);
                if calc != got || text.is_empty() {
                    self.crc_failures += 1;
                    print(&format!("crc:fail,{calc}/{got};"), out);
                    return;
                }
                print("crc:pass;", out);
                text
            }
            Framing::Plain => frame,
        };
        self.frames_ok += 1;
        // Printable by construction of the queue: the board stores the raw text.
        let text = String::from_utf8_lossy(text).into_owned();
        if self.queue.len() == COMMAND_QUEUE_SLOTS {
            self.queue.pop_front();
            self.overruns += 1;
            print("log:CommandBufferOverrun;", out);
        }
        self.queue.push_back(text);
    }

    /// Advances the board to `now`: works the command queue, slews the tilt
    /// servo, runs the dead-man switch, steps the simulator and prints the
    /// telemetry that is due.
    pub fn tick(&mut self, now: Duration, out: &mut Vec<u8>) {
        if !self.booted || now < self.now {
            return;
        }
        let elapsed = now - self.now;
        self.now = now;
        if self.stalled {
            // A hung board does nothing, but physics goes on.
            self.last_loop = now;
            self.step_sim(now);
            self.next_nav = now + Duration::from_millis(self.opts.nav_period_ms);
            self.next_status = now + Duration::from_millis(self.opts.status_period_ms);
            return;
        }
        let loops = ((now - self.last_loop).as_micros() / LOOP_PERIOD.as_micros()) as usize;
        let mut worked = 0;
        while worked < loops.max(1) {
            let Some(cmd) = self.queue.pop_front() else {
                break;
            };
            self.execute(&cmd, out);
            worked += 1;
        }
        if loops > 0 {
            self.last_loop = now;
        }
        let slew = elapsed.as_millis().min(i32::MAX as u128) as i32;
        let diff = self.tilt_target_us - self.tilt_us;
        self.tilt_us += diff.clamp(-slew, slew);

        let dms_active = self.dms_armed || now >= DEAD_MAN_AUTO_ARM;
        if dms_active && !self.dms_tripped && now.saturating_sub(self.last_ping) > DEAD_MAN_TIMEOUT
        {
            self.dms_tripped = true;
            self.target_us = [NEUTRAL_US; 3];
            self.update_motors();
            print("log:DeadManSwitchTripped;", out);
        }
        self.step_sim(now);
        while now >= self.next_nav {
            let due = self.next_nav;
            self.next_nav += Duration::from_millis(self.opts.nav_period_ms);
            let line = self.nav_line(due);
            self.faults.emit(line, out);
        }
        while now >= self.next_status {
            let due = self.next_status;
            self.next_status += Duration::from_millis(self.opts.status_period_ms);
            let line = self.status_line(due);
            self.faults.emit(line, out);
            if self.reported_motors_us != Some(self.motors_us) {
                self.reported_motors_us = Some(self.motors_us);
                let m = self.motors_us;
                let line = format!("motors:{},{},{};", m[0], m[1], m[2]);
                self.faults.emit(line, out);
            }
        }
    }

    /// When [`Board::tick`] next has something to do.
    pub fn next_deadline(&self) -> Duration {
        let mut next = self.next_nav.min(self.next_status).min(self.now + SIM_STEP);
        if !self.queue.is_empty() || self.tilt_us != self.tilt_target_us {
            next = next.min(self.now + LOOP_PERIOD);
        }
        next
    }

    fn step_sim(&mut self, now: Duration) {
        let esc_us = self.esc_drive_us();
        while self.sim_time + SIM_STEP <= now {
            self.plant.step(esc_us, SIM_STEP.as_secs_f64());
            self.sim_time += SIM_STEP;
        }
    }

    /// What the ESCs are driven with: the motor outputs, or neutral while
    /// the motors are detached, the ESCs unpowered or the dead-man tripped
    /// (no thrust in any of those).
    fn esc_drive_us(&self) -> [u16; 3] {
        if !self.motors_attached || !self.esc_power || self.dms_tripped {
            return [NEUTRAL_US as u16; 3];
        }
        self.motors_us.map(|v| v.clamp(1000, 2000) as u16)
    }

    fn update_motors(&mut self) {
        let dz = i32::from(self.opts.deadzone_us);
        let mult = self.opts.reverse_multiplier;
        self.motors_us = self.target_us.map(|v| {
            let d = v - NEUTRAL_US;
            if d.abs() <= dz {
                NEUTRAL_US
            } else if d < 0 {
                (NEUTRAL_US as f64 + f64::from(d) * mult)
                    .round()
                    .clamp(1000.0, 2000.0) as i32
            } else {
                v
            }
        });
    }

    fn execute(&mut self, text: &str, out: &mut Vec<u8>) {
        let mut tokens = text
            .split([' ', ',', '(', ')', ';'])
            .filter(|t| !t.is_empty());
        let Some(name) = tokens.next() else { return };
        let name = name.to_owned();
        let args: Vec<i32> = tokens.take(MAX_ARGS).map(atoi).collect();
        let canonical = format!(
            "{name}({})",
            args.iter()
                .map(i32::to_string)
                .collect::<Vec<_>>()
                .join(",")
        );
        print(&format!("cmd:{canonical};"), out);
        self.executed_total += 1;
        if self.log_executed {
            self.executed_log.push(BoardRecord::Executed(canonical));
        }
        let arg = |i: usize| args.get(i).copied().unwrap_or(0);
        match name.as_str() {
            "go" => {
                if args.len() >= 3
                    && args[..3].iter().all(|v| (1000..=2000).contains(v))
                    && !self.dms_tripped
                {
                    self.target_us = [args[0], args[1], args[2]];
                    self.update_motors();
                }
            }
            "stop" => {
                self.target_us = [NEUTRAL_US; 3];
                self.update_motors();
            }
            "start" => self.motors_attached = true,
            "ligt" => {
                self.lights = arg(0).clamp(0, 255) as u8;
                let frac = f64::from(self.lights) / 255.0;
                print(&format!("LIGT:{};LIGP:{frac:.2};", self.lights), out);
            }
            "claser" => {
                self.laser = arg(0).clamp(0, 255) as u8;
                print(&format!("claser:{};", self.laser), out);
            }
            "tilt" => self.tilt_target_us = arg(0).clamp(1000, 2000),
            "escp" => self.esc_power = arg(0) != 0,
            "ping" => {
                self.last_ping = self.now;
                if self.dms_tripped {
                    self.dms_tripped = false;
                    self.motors_attached = true;
                }
                print(&format!("pong:{};", arg(0)), out);
            }
            "dms" => {
                self.dms_armed = arg(0) != 0;
                self.last_ping = self.now;
            }
            // The board zeroes on the pressure sensor's last sample, not on
            // a line's (possibly wild) value.
            "dzer" | "depth_zero" => self.depth_offset_m = self.plant.depth_sample_m(),
            "rcap" => print(&format!("CAPA:{CAPABILITIES};"), out),
            "thro" | "yaw" | "lift" => self.board_mix(&name, arg(0)),
            _ => print(&format!("log:UnknownCommand {name};"), out),
        }
    }

    /// The OpenROV cockpit's per-axis path, mixed on the board.
    fn board_mix(&mut self, axis: &str, value: i32) {
        let v = value.clamp(-100, 100) * 5;
        let [p, vert, s] = self.target_us;
        let dirs = self.opts.wiring_directions.map(i32::from);
        self.target_us = match axis {
            "thro" => [NEUTRAL_US + dirs[0] * v, vert, NEUTRAL_US + dirs[2] * v],
            "yaw" => [NEUTRAL_US + dirs[0] * v, vert, NEUTRAL_US - dirs[2] * v],
            _ => [p, NEUTRAL_US + dirs[1] * v, s],
        };
        self.update_motors();
    }

    /// The plant's readings at board time `at`, as the board reports them.
    fn readings(&mut self, at: Duration) -> Readings {
        let mut r = self.plant.read(at);
        r.depth_m -= self.depth_offset_m;
        r
    }

    fn nav_line(&mut self, at: Duration) -> String {
        let r = self.readings(at);
        format!(
            "hdgd:{:.2};deep:{:.2};pitc:{:.2};roll:{:.2};yaw:{:.2};fthr:{:.2};",
            r.heading_deg, r.depth_m, r.pitch_deg, r.roll_deg, r.yaw_deg, r.fthr_pct
        )
    }

    fn status_line(&mut self, at: Duration) -> String {
        let r = self.readings(at);
        let t = self.target_us;
        format!(
            "vout:{:.2};iout:{:.2};BT1I:{:.2};BT2I:{:.2};pres:{:.2};temp:{:.2};time:{};fmem:{};motorAttached:{};servo:{};starg:{};mtarg:{},{},{};ver:{};",
            r.vout_v,
            r.iout_a,
            r.btti_a / 2.0,
            r.btti_a / 2.0,
            r.pressure_mbar,
            r.temp_c,
            self.now.as_millis(),
            2048,
            u8::from(self.motors_attached),
            self.tilt_us,
            self.tilt_target_us,
            t[0],
            t[1],
            t[2],
            self.opts.version,
        )
    }

    /// Commands executed since power-up (cheaper than a snapshot, for the
    /// pty wrapper to know when one is due).
    pub(super) fn executed_total(&self) -> u64 {
        self.executed_total
    }

    /// The board and the simulated vehicle right now.
    pub fn snapshot(&self) -> BoardSnapshot {
        let c = |v: i32| v.clamp(0, i32::from(u16::MAX)) as u16;
        BoardSnapshot {
            uptime_ms: self.now.as_millis() as u64,
            target_us: self.target_us.map(c),
            motors_us: self.motors_us.map(c),
            motors_attached: self.motors_attached,
            dead_man_armed: self.dms_armed,
            dead_man_tripped: self.dms_tripped,
            lights: self.lights,
            laser: self.laser,
            tilt_us: c(self.tilt_us),
            tilt_target_us: c(self.tilt_target_us),
            frames_ok: self.frames_ok,
            crc_failures: self.crc_failures,
            overruns: self.overruns,
            stalled: self.stalled,
            executed_total: self.executed_total,
            sim: SimSnapshot::from(&self.plant.truth()),
            faults: self.faults.stats(),
        }
    }
}

/// C `atoi`: optional sign, leading digits, anything after ignored; 0 if none.
fn atoi(s: &str) -> i32 {
    let s = s.trim_start();
    let (neg, digits) = match s.as_bytes().first() {
        Some(b'-') => (true, &s[1..]),
        Some(b'+') => (false, &s[1..]),
        _ => (false, s),
    };
    let mut v: i64 = 0;
    for b in digits.bytes().take_while(u8::is_ascii_digit) {
        v = (v * 10 + i64::from(b - b'0')).min(i64::from(i32::MAX) + 1);
    }
    let v = if neg { -v } else { v };
    v.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}
