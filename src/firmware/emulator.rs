//! Emulator of the 2015 OpenROV controller board, driving the simulator.
//!
//! [`Board`] is sans-IO: it takes the bytes the host wrote and the current
//! time, and produces the bytes the board would print. [`PtyBoard`] puts it
//! behind a real pseudo-terminal, which is what `neptunus --sim`,
//! `neptunus emulate-board` and the tests use, so the serial link runs the
//! same code as on the ROV.
//!
//! Behaviour modelled on the board (see `reference/openrov-serial.md`):
//! - frames end at the first `;`; in `crc8` framing the first byte of a
//!   frame is the CRC-8 of the rest. Every frame is echoed as
//!   `rawcmd:<hex>,...,;`, then `crc:pass;` or `crc:fail,<calc>/<got>;`
//!   (failed frames are dropped), then `cmd:<text>;`;
//! - an 80-byte frame buffer (longer frames are dropped), at most 10
//!   integer arguments parsed with `atoi` semantics, a 5-slot command queue
//!   that drops the oldest with `log:CommandBufferOverrun;`;
//! - `go()` applied only when all three values are in 1000..=2000, a 50 µs
//!   deadzone around 1500 and a ×2 reverse multiplier on the ESC outputs;
//! - lights (`LIGT`/`LIGP`), laser (`claser`), camera tilt slewing 1 µs per
//!   millisecond, `boot:1;` at start, `CAPA:` for `rcap()`, `pong:` for
//!   `ping()`, and the dead-man switch: after `dms(1)` (or 180 s of uptime)
//!   two seconds without `ping` stop the motors until the next ping;
//! - navigation lines at 10 Hz and status lines at 1 Hz from the simulator.
//!
//! The simulator ([`crate::sim::Plant`]) is driven with the ESC outputs, as
//! on the vehicle: after the board's deadzone and its reverse multiplier
//! (which compensates for propellers that push less in reverse — the plant
//! models that), and neutral while the motors are detached, the ESCs are
//! powered off or the dead-man switch has tripped. The navigation line
//! reports the plant's readings: heading, 1 Hz depth, pitch and roll, with
//! the noise the options ask for.
//!
//! Fault injection (all off by default) reproduces what the thesis saw on
//! the real link: garbage bytes, torn lines, wild points, dropped lines and
//! a stalled board. The emulator counts what it injected so tests can check
//! the decoder's rejection counters against it.
//!
//! The emulator never decides anything on the host's behalf; it only
//! behaves like the hardware.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Duration;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use tokio::sync::{broadcast, oneshot, watch};

use super::codec::{Framing, crc8, physical_range};
use super::pty::{PtyError, PtyPair};
use crate::sim::{Plant, Readings, SimError, SimOptions, SimState, Truth, thesis::wrap_deg_360};

/// Bytes the board buffers for one frame before giving up on it.
pub const FRAME_BUFFER_BYTES: usize = 80;
/// Slots in the board's command queue.
pub const COMMAND_QUEUE_SLOTS: usize = 5;
/// Arguments the board parses per command.
pub const MAX_ARGS: usize = 10;
/// `rcap()` answer: lights, lasers, camera mount, compass, orientation, depth (bits 1..=6).
pub const CAPABILITIES: u32 = 0b111_1110;
const NEUTRAL_US: i32 = 1500;
const SIM_STEP: Duration = Duration::from_millis(10);
/// The board works through one queued command per loop iteration.
const LOOP_PERIOD: Duration = Duration::from_millis(1);
/// One byte at 115200 baud, 8N1.
const BYTE_TIME: Duration = Duration::from_nanos(86_806);
const DEAD_MAN_TIMEOUT: Duration = Duration::from_secs(2);
const DEAD_MAN_AUTO_ARM: Duration = Duration::from_secs(180);

/// Fault injection rates, each a probability per emitted telemetry line.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaultOptions {
    /// Random non-printable bytes in front of a line (line noise).
    pub garbage: f64,
    /// A line cut inside a value, or a value replaced by the next key's
    /// name (the thesis' heading reading `pitc`).
    pub torn: f64,
    /// One value multiplied by 0.1, 10 or 100.
    pub wild: f64,
    /// A line never sent.
    pub dropped: f64,
    /// Seed of the fault generator (the faults are reproducible).
    pub seed: u64,
}

impl FaultOptions {
    /// Whether any fault is enabled.
    pub fn any(&self) -> bool {
        self.garbage > 0.0 || self.torn > 0.0 || self.wild > 0.0 || self.dropped > 0.0
    }
}

/// How the emulated board is set up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmulatorOptions {
    pub framing: Framing,
    /// Deadzone around 1500 µs in which the ESCs get neutral.
    pub deadzone_us: u16,
    /// Multiplier on reverse thrust applied to the ESC outputs.
    pub reverse_multiplier: f64,
    /// Thruster directions [port, vertical, starboard] as wired on the
    /// vehicle (Neptunus' port thruster is wired reversed).
    pub wiring_directions: [i8; 3],
    pub nav_period_ms: u64,
    pub status_period_ms: u64,
    /// Firmware version printed in status lines.
    pub version: String,
    pub faults: FaultOptions,
    /// The simulated vehicle (`[emulator.sim]`).
    pub sim: SimOptions,
}

impl EmulatorOptions {
    /// The board with the thesis' ideal simulator, reproducing the emulator
    /// from before the plant existed: [`SimOptions::ideal_thesis`], and a
    /// reverse multiplier of 1 so the ESC outputs are the accepted `go()`
    /// values (the old emulator fed those to the physics, never the
    /// multiplied ones). For tests that check exact physics.
    pub fn ideal_thesis() -> Self {
        Self {
            reverse_multiplier: 1.0,
            sim: SimOptions::ideal_thesis(),
            ..Self::default()
        }
    }
}

impl Default for EmulatorOptions {
    fn default() -> Self {
        Self {
            framing: Framing::Crc8,
            deadzone_us: 50,
            reverse_multiplier: 2.0,
            wiring_directions: [-1, 1, 1],
            nav_period_ms: 100,
            status_period_ms: 1000,
            version: "30.0.3-neptunus-emu".into(),
            faults: FaultOptions::default(),
            sim: SimOptions::default(),
        }
    }
}

/// What the emulator injected, for checking the decoder's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FaultStats {
    pub lines_emitted: u64,
    pub garbage_bursts: u64,
    pub garbage_bytes: u64,
    pub torn_lines: u64,
    /// Wild points whose value left the physical range: the decoder must reject them.
    pub wild_out_of_range: u64,
    /// Wild points still inside the physical range: only an estimator can catch them.
    pub wild_in_range: u64,
    pub dropped_lines: u64,
}

impl FaultStats {
    /// Lines the host's decoder must reject.
    pub fn expected_rejections(&self) -> u64 {
        self.torn_lines + self.wild_out_of_range
    }
}

/// What the board received and did, for tests.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BoardRecord {
    /// A complete frame as received, CRC byte included, up to its `;`.
    Frame(Vec<u8>),
    /// A command executed, as the board tokenised it: `go(1500,1500,1500)`.
    Executed(String),
}

/// A [`BoardRecord`] with the moment the emulator task woke to handle the
/// bytes (or timer) that produced it. For a `Frame`, that is when the read
/// that completed the frame returned: as close to the pty as the emulator
/// gets, for latency measurements that must not include the delay of a
/// broadcast receiver being scheduled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TimedRecord {
    pub at: std::time::Instant,
    pub record: BoardRecord,
}

/// A snapshot of the board and the simulated vehicle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoardSnapshot {
    pub uptime_ms: u64,
    /// Last accepted `go()` values [port, vertical, starboard].
    pub target_us: [u16; 3],
    /// ESC outputs after deadzone and reverse multiplier.
    pub motors_us: [u16; 3],
    pub motors_attached: bool,
    pub dead_man_armed: bool,
    pub dead_man_tripped: bool,
    pub lights: u8,
    pub laser: u8,
    pub tilt_us: u16,
    pub tilt_target_us: u16,
    pub frames_ok: u64,
    pub crc_failures: u64,
    pub overruns: u64,
    pub stalled: bool,
    /// Every command executed, in order, as text (`go(1500,1500,1500)`).
    pub executed_total: u64,
    pub sim: SimSnapshot,
    pub faults: FaultStats,
}

/// Simulated vehicle state in plain units (the truth, not the readings).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SimSnapshot {
    pub north_m: f64,
    pub east_m: f64,
    pub depth_m: f64,
    /// Wrapped into `[0, 360)`.
    pub heading_deg: f64,
    pub surge_mps: f64,
    pub sway_mps: f64,
    pub heave_mps: f64,
    pub yaw_rate_dps: f64,
    /// 0 in the 4-DOF model.
    pub roll_deg: f64,
    /// Positive nose up; 0 in the 4-DOF model.
    pub pitch_deg: f64,
    /// `[port, vertical, starboard]` (N), positive forward / down.
    pub thrust_n: [f64; 3],
    /// 0 with the tether off.
    pub tether_length_m: f64,
}

impl From<&SimState> for SimSnapshot {
    /// A 4-DOF state: level, thrust and tether unknown (0).
    fn from(s: &SimState) -> Self {
        Self {
            north_m: s.eta[0],
            east_m: s.eta[1],
            depth_m: s.depth_m(),
            heading_deg: s.heading_deg(),
            surge_mps: s.nu[0],
            sway_mps: s.nu[1],
            heave_mps: s.nu[2],
            yaw_rate_dps: s.nu[3].to_degrees(),
            roll_deg: 0.0,
            pitch_deg: 0.0,
            thrust_n: [0.0; 3],
            tether_length_m: 0.0,
        }
    }
}

impl From<&Truth> for SimSnapshot {
    fn from(t: &Truth) -> Self {
        Self {
            north_m: t.north_m,
            east_m: t.east_m,
            depth_m: t.depth_m,
            heading_deg: wrap_deg_360(t.heading_rad.to_degrees()),
            surge_mps: t.surge_mps,
            sway_mps: t.sway_mps,
            heave_mps: t.heave_mps,
            yaw_rate_dps: t.yaw_rate_rps.to_degrees(),
            roll_deg: t.roll_rad.to_degrees(),
            pitch_deg: t.pitch_rad.to_degrees(),
            thrust_n: t.thrust_n,
            tether_length_m: t.tether_length_m,
        }
    }
}

/// The emulated board (sans-IO).
#[derive(Debug)]
pub struct Board {
    opts: EmulatorOptions,
    rng: SmallRng,
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
    faults: FaultStats,
    now: Duration,
}

impl Board {
    /// A board at power-up; nothing is printed until [`Board::start`].
    ///
    /// # Panics
    /// If `opts.sim` is invalid (see [`SimOptions::validate`]); the defaults
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
        let seed = opts.faults.seed;
        let plant = Plant::new(&opts.sim, opts.wiring_directions)?;
        Ok(Self {
            opts,
            rng: SmallRng::seed_from_u64(seed),
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
            faults: FaultStats::default(),
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
        self.print(&line, out);
        let text = match self.opts.framing {
            Framing::Crc8 => {
                let (got, text) = match frame.split_first() {
                    Some((&got, text)) => (got, text),
                    None => return,
                };
                let calc = crc8(text);
                if calc != got || text.is_empty() {
                    self.crc_failures += 1;
                    self.print(&format!("crc:fail,{calc}/{got};"), out);
                    return;
                }
                self.print("crc:pass;", out);
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
            self.print("log:CommandBufferOverrun;", out);
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
            self.print("log:DeadManSwitchTripped;", out);
        }
        self.step_sim(now);
        while now >= self.next_nav {
            let due = self.next_nav;
            self.next_nav += Duration::from_millis(self.opts.nav_period_ms);
            let line = self.nav_line(due);
            self.emit_telemetry(line, out);
        }
        while now >= self.next_status {
            let due = self.next_status;
            self.next_status += Duration::from_millis(self.opts.status_period_ms);
            let line = self.status_line(due);
            self.emit_telemetry(line, out);
            if self.reported_motors_us != Some(self.motors_us) {
                self.reported_motors_us = Some(self.motors_us);
                let m = self.motors_us;
                let line = format!("motors:{},{},{};", m[0], m[1], m[2]);
                self.emit_telemetry(line, out);
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
        self.print(&format!("cmd:{canonical};"), out);
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
                self.print(&format!("LIGT:{};LIGP:{frac:.2};", self.lights), out);
            }
            "claser" => {
                self.laser = arg(0).clamp(0, 255) as u8;
                self.print(&format!("claser:{};", self.laser), out);
            }
            "tilt" => self.tilt_target_us = arg(0).clamp(1000, 2000),
            "escp" => self.esc_power = arg(0) != 0,
            "ping" => {
                self.last_ping = self.now;
                if self.dms_tripped {
                    self.dms_tripped = false;
                    self.motors_attached = true;
                }
                self.print(&format!("pong:{};", arg(0)), out);
            }
            "dms" => {
                self.dms_armed = arg(0) != 0;
                self.last_ping = self.now;
            }
            // The board zeroes on the pressure sensor's last sample, not on
            // a line's (possibly wild) value.
            "dzer" | "depth_zero" => self.depth_offset_m = self.plant.depth_sample_m(),
            "rcap" => self.print(&format!("CAPA:{CAPABILITIES};"), out),
            "thro" | "yaw" | "lift" => self.board_mix(&name, arg(0)),
            _ => self.print(&format!("log:UnknownCommand {name};"), out),
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
            "vout:{:.2};iout:{:.2};btti:{:.2};pres:{:.2};temp:{:.2};time:{};fmem:{};motorAttached:{};servo:{};starg:{};mtarg:{},{},{};ver:{};",
            r.vout_v,
            r.iout_a,
            r.btti_a,
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

    fn print(&mut self, line: &str, out: &mut Vec<u8>) {
        out.extend_from_slice(line.as_bytes());
        out.extend_from_slice(b"\r\n");
    }

    /// Prints a telemetry line, with faults injected if enabled.
    fn emit_telemetry(&mut self, line: String, out: &mut Vec<u8>) {
        let f = self.opts.faults.clone();
        if !f.any() {
            self.faults.lines_emitted += 1;
            self.print(&line, out);
            return;
        }
        if self.rng.random_bool(f.dropped.clamp(0.0, 1.0)) {
            self.faults.dropped_lines += 1;
            return;
        }
        if self.rng.random_bool(f.garbage.clamp(0.0, 1.0)) {
            let n = self.rng.random_range(1..=16);
            for _ in 0..n {
                out.push(self.garbage_byte());
            }
            self.faults.garbage_bursts += 1;
            self.faults.garbage_bytes += n;
        }
        let line = if self.rng.random_bool(f.torn.clamp(0.0, 1.0)) {
            match self.tear(&line) {
                Some(torn) => {
                    self.faults.torn_lines += 1;
                    torn
                }
                None => line,
            }
        } else if self.rng.random_bool(f.wild.clamp(0.0, 1.0)) {
            self.wild(&line)
        } else {
            line
        };
        self.faults.lines_emitted += 1;
        self.print(&line, out);
    }

    fn garbage_byte(&mut self) -> u8 {
        // Line noise: bytes no telemetry line contains.
        loop {
            let b: u8 = self.rng.random();
            if !(0x20..=0x7e).contains(&b) && b != b'\r' && b != b'\n' {
                return b;
            }
        }
    }

    /// Either cuts the line inside a value, or replaces a value by the name
    /// of the following key, as a torn read buffer does.
    fn tear(&mut self, line: &str) -> Option<String> {
        let pairs: Vec<&str> = line.split_terminator(';').collect();
        let numeric: Vec<usize> = (0..pairs.len().saturating_sub(1))
            .filter(|&i| {
                pairs[i]
                    .split(':')
                    .next()
                    .is_some_and(|k| physical_range(k).is_some())
            })
            .collect();
        if !numeric.is_empty() && self.rng.random_bool(0.5) {
            let i = numeric[self.rng.random_range(0..numeric.len())];
            let next_key = pairs[i + 1].split(':').next().unwrap_or("pitc");
            let key = pairs[i].split(':').next().unwrap_or("hdgd");
            let mut v: Vec<String> = pairs.iter().map(|p| (*p).to_owned()).collect();
            v[i] = format!("{key}:{next_key}");
            return Some(v.iter().map(|p| format!("{p};")).collect());
        }
        // Cut anywhere but right after a `;` (which would leave a shorter
        // but valid line): the result never ends in `;`, so it is torn.
        let bytes = line.as_bytes();
        let cut_points: Vec<usize> = (1..bytes.len()).filter(|&i| bytes[i - 1] != b';').collect();
        if cut_points.is_empty() {
            return None;
        }
        let at = cut_points[self.rng.random_range(0..cut_points.len())];
        Some(line[..at].to_owned())
    }

    /// Multiplies one numeric value by 0.1, 10 or 100 and records whether
    /// the result left its key's physical range.
    fn wild(&mut self, line: &str) -> String {
        let pairs: Vec<&str> = line.split_terminator(';').collect();
        let numeric: Vec<usize> = pairs
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let (k, v) = p.split_once(':')?;
                (physical_range(k).is_some() && v.parse::<f64>().is_ok() && !v.contains(','))
                    .then_some(i)
            })
            .collect();
        if numeric.is_empty() {
            return line.to_owned();
        }
        let i = numeric[self.rng.random_range(0..numeric.len())];
        let Some((k, v)) = pairs[i].split_once(':') else {
            return line.to_owned();
        };
        let value: f64 = v.parse().unwrap_or(0.0);
        let factor = [0.1, 10.0, 100.0][self.rng.random_range(0..3)];
        let integer = !v.contains('.');
        let wild_value = value * factor;
        let text = if integer {
            format!("{}", wild_value.round() as i64)
        } else {
            format!("{wild_value:.2}")
        };
        if text == v {
            // 0 × 10 is still 0: nothing was injected.
            return line.to_owned();
        }
        let shown: f64 = text.parse().unwrap_or(wild_value);
        let in_range = physical_range(k).is_some_and(|(lo, hi)| shown >= lo && shown <= hi);
        if in_range {
            self.faults.wild_in_range += 1;
        } else {
            self.faults.wild_out_of_range += 1;
        }
        let mut v: Vec<String> = pairs.iter().map(|p| (*p).to_owned()).collect();
        v[i] = format!("{k}:{text}");
        v.iter().map(|p| format!("{p};")).collect()
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
            faults: self.faults,
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

/// Controls for a running [`PtyBoard`].
#[derive(Debug, Clone)]
pub struct BoardControl {
    stall: watch::Sender<bool>,
    snapshot: watch::Receiver<BoardSnapshot>,
    records: broadcast::Sender<BoardRecord>,
    timed: broadcast::Sender<TimedRecord>,
}

impl BoardControl {
    /// Stalls (or resumes) the board.
    pub fn set_stalled(&self, stalled: bool) {
        let _ = self.stall.send(stalled);
    }
    /// The latest snapshot (updated at 10 Hz and on every executed command).
    pub fn snapshot(&self) -> BoardSnapshot {
        self.snapshot.borrow().clone()
    }
    /// Frames received and commands executed from now on.
    pub fn records(&self) -> broadcast::Receiver<BoardRecord> {
        self.records.subscribe()
    }
    /// As [`BoardControl::records`], each with the time the emulator woke to
    /// handle it (benchmarks).
    pub fn timed_records(&self) -> broadcast::Receiver<TimedRecord> {
        self.timed.subscribe()
    }
    /// A receiver that changes with every snapshot.
    pub fn subscribe(&self) -> watch::Receiver<BoardSnapshot> {
        self.snapshot.clone()
    }
}

/// The board emulator behind a pseudo-terminal, running on the tokio runtime.
#[derive(Debug)]
pub struct PtyBoard {
    path: PathBuf,
    control: BoardControl,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<()>,
}

impl PtyBoard {
    /// Creates the pty, optionally a stable symlink to it, boots the board
    /// and runs it until [`PtyBoard::shutdown`] or drop.
    pub fn spawn(opts: EmulatorOptions, symlink: Option<PathBuf>) -> Result<Self, PtyError> {
        // Bad simulator options fail before a pty or a symlink exists.
        let mut board = Board::try_new(opts)?;
        board.record(true);
        let mut pty = PtyPair::open()?;
        if let Some(link) = &symlink {
            pty.make_symlink(link)?;
        }
        let path = symlink.unwrap_or_else(|| pty.slave_path().to_path_buf());
        let (stall_tx, stall_rx) = watch::channel(false);
        let (snap_tx, snap_rx) = watch::channel(board.snapshot());
        let (records_tx, _) = broadcast::channel(4096);
        let (timed_tx, _) = broadcast::channel(4096);
        let (stop_tx, stop_rx) = oneshot::channel();
        let task = tokio::spawn(run_board(
            pty,
            board,
            stall_rx,
            snap_tx,
            records_tx.clone(),
            timed_tx.clone(),
            stop_rx,
        ));
        Ok(Self {
            path,
            control: BoardControl {
                stall: stall_tx,
                snapshot: snap_rx,
                records: records_tx,
                timed: timed_tx,
            },
            stop: Some(stop_tx),
            task,
        })
    }

    /// The path a serial program opens (the symlink if one was asked for).
    pub fn path(&self) -> &std::path::Path {
        &self.path
    }

    pub fn control(&self) -> BoardControl {
        self.control.clone()
    }

    /// Stops the board and closes the pty (the host sees the device vanish).
    pub async fn shutdown(mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        let _ = (&mut self.task).await;
    }
}

impl Drop for PtyBoard {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn run_board(
    pty: PtyPair,
    mut board: Board,
    mut stall: watch::Receiver<bool>,
    snapshots: watch::Sender<BoardSnapshot>,
    records: broadcast::Sender<BoardRecord>,
    timed: broadcast::Sender<TimedRecord>,
    mut stop: oneshot::Receiver<()>,
) {
    let origin = tokio::time::Instant::now();
    let now = || tokio::time::Instant::now() - origin;
    let mut out = Vec::with_capacity(4096);
    board.start(now(), &mut out);
    let mut buf = [0u8; 512];
    let mut last_snapshot = Duration::ZERO;
    let mut last_executed = 0;
    loop {
        if !out.is_empty() {
            // Bytes the tty cannot take are lost, as on a UART nobody reads.
            if let Err(e) = pty.try_write(&out) {
                tracing::debug!("emulator pty write failed: {e}");
            }
            out.clear();
        }
        let deadline = origin + board.next_deadline();
        tokio::select! {
            _ = &mut stop => break,
            changed = stall.changed() => {
                if changed.is_err() { break; }
                let stalled = *stall.borrow();
                board.set_stalled(stalled);
            }
            read = pty.read(&mut buf) => match read {
                Ok(0) => {}
                Ok(n) => board.receive(&buf[..n], now(), &mut out),
                Err(e) => {
                    tracing::warn!("emulator pty read failed: {e}");
                    break;
                }
            },
            _ = tokio::time::sleep_until(deadline) => {}
        }
        let woke_at = std::time::Instant::now();
        let t = now();
        board.tick(t, &mut out);
        // The snapshot first: whoever sees a record must find the state it led to.
        if t.saturating_sub(last_snapshot) >= Duration::from_millis(100)
            || board.executed_total != last_executed
        {
            last_snapshot = t;
            last_executed = board.executed_total;
            let _ = snapshots.send(board.snapshot());
        }
        let timed_wanted = timed.receiver_count() > 0;
        for r in board.take_records() {
            if timed_wanted {
                let _ = timed.send(TimedRecord {
                    at: woke_at,
                    record: r.clone(),
                });
            }
            // Nobody listening is fine: records are for tests and tools.
            let _ = records.send(r);
        }
    }
}
