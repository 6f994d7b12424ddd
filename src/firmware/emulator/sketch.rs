//! The OpenROV controller-board sketch, re-told in Rust: `setup()`, then
//! `loop()` — one command per pass (a complete serial frame first, else one
//! from the internal queue), every device's `device_loop` in registration
//! order, the status cycle every second and the navigation line every
//! 100 ms — for firmware 30.0.2 and 2014-12.
//!
//! Owns the firmware's state (frame buffer, internal command queue, the
//! devices' variables and `Timer`s) and its clock: every pass advances it
//! by the pass's modelled cost, `delay()`s and the time prints wait for the
//! transmit buffer ([`Uart`]), so the sketch can be suspended between two
//! steps of a pass and resumed when real time catches up (the 5 s `rcap()`
//! pause). Passes in which nothing can happen are skipped in bulk. The
//! simulated vehicle is reached only through [`Hardware`]: what the
//! sensors and ADC read, and the ESC pulses the sketch writes. It never
//! reads a clock or touches a file descriptor.
//!
//! Not imitated (see the emulator's module docs for why): the BNO055 found
//! (it is always absent, as on a 2.5 controller board), `ccal()`'s `dia:`
//! lines, arguments beyond the ninth overwriting memory, the watchdog, and
//! the EEPROM.

use std::time::Duration;

use super::arduino::{self, Timer, atoi, constrain, float, map, mapf, trunc};
use super::uart::Uart;
use super::{BoardRecord, FirmwareVersion, FittedSensors};
use crate::firmware::codec::crc8;
use crate::sim::Readings;

/// Bytes of the sketch's frame buffer (`DATABUFFERSIZE`).
pub const FRAME_BUFFER_BYTES: usize = 80;
/// Slots of the internal command ring (`MAX_COMMANDS`); one stays empty,
/// so four commands wait at most.
pub const COMMAND_QUEUE_SLOTS: usize = 5;
/// `int args[MAX_ARGS]`: the count in `args[0]`, nine arguments after it.
pub const MAX_ARGS: usize = 10;
const MIDPOINT: i32 = 1500;
const DELAY_TO_ARM_MS: u64 = 180_000;
/// How far past `now` a pass in progress runs on to its end: more than a
/// status cycle's prints wait for the transmit buffer.
const PASS_SLACK: Duration = Duration::from_millis(40);
/// One `analogRead` (13 ADC clocks at 125 kHz, plus the call).
const ADC_READ: Duration = Duration::from_micros(112);
/// One I2C address or command byte at 100 kHz, start and stop included.
const I2C_BYTE: Duration = Duration::from_micros(100);
/// Reading the MPU-9150's DMP FIFO and compass over I2C (about 45 bytes).
const MPU_READ: Duration = Duration::from_micros(4_500);
/// `MPU9150Lib::init`: the chip's 100 ms reset, then the DMP's program
/// written and read back in 16-byte chunks at 100 kHz. Nothing in the
/// simulator measured this; it is what that I2C traffic takes.
const MPU_RESET: Duration = Duration::from_millis(110);
const MPU_DMP_LOAD: Duration = Duration::from_millis(540);
/// The MS5803's PROM (eight 2-byte reads) over I2C.
const MS5803_PROM: Duration = Duration::from_micros(3_200);
/// Calibration words the emulated MS5803-14BA reports (its PROM; the
/// readings come from the simulator, so only the chatter shows them).
const MS5803_PROM_WORDS: [u16; 8] = [4112, 46372, 43981, 29059, 27842, 31553, 28165, 3];
/// The I2C addresses the fitted sensors answer at.
const MPU9150_ADDRESS: u8 = 0x68;
const MS5803_ADDRESS: u8 = 0x76;

/// What the sketch reaches outside the microcontroller: the sensors, the
/// ADC inputs and the ESCs. Each call says when (board time) it happens.
pub(super) trait Hardware {
    /// The IMU and pressure sensor read at `at` (noise, sample-and-hold).
    fn read_sensors(&mut self, at: Duration) -> Readings;
    /// The supply voltage and currents at `at` (no noise is drawn).
    fn read_power(&mut self, at: Duration) -> Readings;
    /// The ESC pulses (µs, `[port, vertical, starboard]`) from `at` on.
    fn write_escs(&mut self, at: Duration, us: [u16; 3]);
    /// The ESCs' power switch from `at` on.
    fn esc_power(&mut self, at: Duration, on: bool);
    /// A frame received or a command executed.
    fn record(&mut self, r: BoardRecord);
    /// A periodic telemetry line (no line end) as it goes out, with
    /// whatever faults are injected, `\r\n` included.
    fn telemetry(&mut self, line: String) -> Vec<u8>;
}

/// The sketch's devices, in the order `OpenROV.ino` defines (and so
/// registers) them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Device {
    Settings,
    Controller25,
    Lights,
    Laser,
    Thrusters,
    Pilot,
    CameraMount,
    AltServo,
    Mpu9150,
    Ms5803,
    DeadMan,
    Bno055,
}

/// What differs between the two firmware builds, besides the code paths.
#[derive(Debug)]
struct Build {
    devices: &'static [Device],
    /// Each device's `device_loop` cost per pass when it has nothing to do
    /// (µs), from the genuine board's `dlms` and `alps` in simavr.
    device_cost_us: &'static [u64],
    /// `cmd.get()`, the timer checks and the loop's own overhead (µs).
    main_cost_us: u64,
    /// `freeMemory()` where the status cycle calls it (bytes).
    free_memory: f32,
    /// `cmpd:` — `__DATE__, __TIME__, __VERSION__` of a build of this
    /// release with the Arduino IDE of its day.
    compiled: &'static str,
}

const BUILD_30_0_2: Build = Build {
    devices: &[
        Device::Settings,
        Device::Controller25,
        Device::Lights,
        Device::Laser,
        Device::Thrusters,
        Device::Pilot,
        Device::CameraMount,
        Device::AltServo,
        Device::Mpu9150,
        Device::Ms5803,
        Device::DeadMan,
        Device::Bno055,
    ],
    device_cost_us: &[10, 23, 9, 8, 90, 21, 11, 9, 14, 17, 17, 15],
    main_cost_us: 62,
    free_memory: 3572.0,
    compiled: "Aug 31 2015, 10:21:44, 4.8.1",
};

const BUILD_2014_12: Build = Build {
    devices: &[
        Device::Settings,
        Device::Controller25,
        Device::Lights,
        Device::Laser,
        Device::Thrusters,
        Device::Pilot,
        Device::CameraMount,
        Device::Mpu9150,
        Device::Ms5803,
        Device::DeadMan,
    ],
    device_cost_us: &[12, 23, 5, 6, 88, 20, 8, 11, 17, 17],
    main_cost_us: 60,
    free_memory: 4130.0,
    compiled: "Dec  9 2014, 14:05:12, 4.3.2",
};

/// How the sketch is built and wired (from the emulator's options).
#[derive(Debug, Clone)]
pub(super) struct SketchConfig {
    pub firmware: FirmwareVersion,
    pub sensors: FittedSensors,
    pub deadzone_us: u16,
    pub reverse_multiplier: f64,
    pub nav_period_ms: u64,
    pub status_period_ms: u64,
    pub version: String,
}

/// One entry of the internal command ring (`InternalCommand`).
#[derive(Debug, Clone, Default)]
struct Queued {
    text: String,
    /// `cmdargs`: the count first.
    args: Vec<i32>,
}

/// The command of this pass (`Command`'s statics).
#[derive(Debug, Clone, Default)]
struct Current {
    ready: bool,
    name: Vec<u8>,
    args: [i32; MAX_ARGS],
}

impl Current {
    /// `Command::cmp`: the command's name starts with `prefix`.
    fn is(&self, prefix: &str) -> bool {
        self.ready && self.name.starts_with(prefix.as_bytes())
    }
    fn arg(&self, i: usize) -> i32 {
        self.args.get(i).copied().unwrap_or(0)
    }
}

/// A thruster channel (`Motor`).
#[derive(Debug, Clone, Copy)]
struct Motor {
    positive_modifier: f32,
    negative_modifier: f32,
    deadzone_negative: i32,
    deadzone_positive: i32,
}

impl Motor {
    /// `Motor::goms`: the ESC pulse for a target, with the modifier
    /// truncated to an `int`, the result constrained, then mapped around
    /// the deadzone (skipped over, not zeroed inside).
    fn goms(&self, ms: i32) -> u16 {
        let modifier = if ms > MIDPOINT {
            trunc(self.positive_modifier)
        } else if ms < MIDPOINT {
            trunc(self.negative_modifier)
        } else {
            1
        };
        // 16-bit `int` arithmetic, as on the board.
        let delta = (ms - MIDPOINT) as i16;
        let scaled = delta
            .wrapping_mul(modifier as i16)
            .wrapping_add(MIDPOINT as i16);
        let pre = constrain(i32::from(scaled), 1000, 2000);
        let fin = if pre < MIDPOINT {
            map(pre, 1000, MIDPOINT, 1000, MIDPOINT - self.deadzone_negative)
        } else if pre > MIDPOINT {
            map(pre, MIDPOINT, 2000, MIDPOINT + self.deadzone_positive, 2000)
        } else {
            MIDPOINT
        };
        // The servo library keeps 544..2400 µs and reads back what it wrote.
        constrain(constrain(fin, 1000, 2000), 544, 2400) as u16
    }
}

/// Where the sketch is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Off,
    /// `setup()`: 0 before the first device, `i + 1` after device `i`.
    Setup(usize),
    /// `loop()`: 0 at the start of a pass (`cmd.get()` next), `i + 1`
    /// before device `i`, `devices + 1` for the outputs at the end.
    Loop(usize),
}

/// The firmware's state. See the module docs.
#[derive(Debug)]
pub(super) struct Sketch {
    cfg: SketchConfig,
    build: &'static Build,
    phase: Phase,
    /// The board's time (`micros()`); `millis()` is its whole milliseconds.
    clock: Duration,
    pass_cost: Duration,
    // Command.cpp
    data: Vec<u8>,
    storing: bool,
    queue: Vec<Queued>,
    head: usize,
    tail: usize,
    cmd: Current,
    // OpenROV.ino
    out1000: Timer,
    out100: Timer,
    loops_per_sec: u32,
    /// Per device, time spent in its `device_loop` (µs; `dlms` in ms).
    device_time_us: Vec<u64>,
    // Shared data (Device.cpp)
    hdgd: f32,
    deap: f32,
    pitc: f32,
    roll: f32,
    yaw: f32,
    fthr: f32,
    pres: f32,
    temp: f32,
    fmem: f32,
    vout: f32,
    iout: f32,
    utim: f32,
    matc: bool,
    cmnt: i32,
    cmtg: i32,
    // Settings
    capabilities: i32,
    smoothing: i32,
    deadzone_min: i32,
    deadzone_max: i32,
    water_salt: bool,
    // Controller25
    adc_timer: Timer,
    brdt_timer: Timer,
    status_timer: Timer,
    // Lights, laser
    lights: i32,
    laser: i32,
    // Thrusters
    motors: [Motor; 3],
    target: [i32; 3],
    applied: [i32; 3],
    esc_us: [u16; 3],
    trg_throttle: f32,
    trg_yaw: f32,
    escs_powered: bool,
    control_timer: Timer,
    output_timer: Timer,
    // Pilot
    heading_hold: bool,
    tgt_hdg: i32,
    hdg_integral: i64,
    depth_hold: bool,
    target_depth: i32,
    pilot_timer: Timer,
    // AltServo
    alts_target: i32,
    alts: i32,
    // MPU9150
    mpu_init: bool,
    mpu_device_id: bool,
    mpu_reinit_timer: Timer,
    mpu_update_timer: Timer,
    calibrating: bool,
    cal_counter: i32,
    cal_timer: Timer,
    // MS5803
    depth_timer: Timer,
    depth: f32,
    depth_offset: f32,
    // DeadManSwitch
    dms_armed: bool,
    dms_tripped: bool,
    blink_state: bool,
    dms_timer: Timer,
    blink_timer: Timer,
    // BNO055
    bno_sample_timer: Timer,
    bno_report_timer: Timer,
    // Figures
    frames_ok: u64,
    crc_failures: u64,
    overruns: u64,
    executed: u64,
}

impl Sketch {
    pub(super) fn new(cfg: SketchConfig) -> Self {
        let build = match cfg.firmware {
            FirmwareVersion::V30_0_2 => &BUILD_30_0_2,
            FirmwareVersion::V2014_12 => &BUILD_2014_12,
        };
        let pass_cost =
            Duration::from_micros(build.main_cost_us + build.device_cost_us.iter().sum::<u64>());
        let deadzone = i32::from(cfg.deadzone_us);
        let motor = Motor {
            positive_modifier: 1.0,
            negative_modifier: cfg.reverse_multiplier as f32,
            deadzone_negative: deadzone,
            deadzone_positive: deadzone,
        };
        Self {
            build,
            phase: Phase::Off,
            clock: Duration::ZERO,
            pass_cost,
            data: Vec::with_capacity(FRAME_BUFFER_BYTES + 1),
            storing: false,
            queue: vec![Queued::default(); COMMAND_QUEUE_SLOTS],
            head: 0,
            tail: 0,
            cmd: Current::default(),
            out1000: Timer::default(),
            out100: Timer::default(),
            loops_per_sec: 0,
            device_time_us: vec![0; build.devices.len()],
            hdgd: 0.0,
            deap: 0.0,
            pitc: 0.0,
            roll: 0.0,
            yaw: 0.0,
            fthr: 0.0,
            pres: 0.0,
            temp: 0.0,
            fmem: 0.0,
            vout: 0.0,
            iout: 0.0,
            utim: 0.0,
            matc: true,
            cmnt: MIDPOINT,
            cmtg: MIDPOINT,
            capabilities: 0,
            smoothing: 40,
            deadzone_min: deadzone,
            deadzone_max: deadzone,
            water_salt: false,
            adc_timer: Timer::default(),
            brdt_timer: Timer::default(),
            status_timer: Timer::default(),
            lights: 0,
            laser: 0,
            motors: [motor; 3],
            target: [MIDPOINT; 3],
            applied: [MIDPOINT; 3],
            esc_us: [MIDPOINT as u16; 3],
            trg_throttle: 0.0,
            trg_yaw: 0.0,
            escs_powered: false,
            control_timer: Timer::default(),
            output_timer: Timer::default(),
            heading_hold: false,
            tgt_hdg: 0,
            hdg_integral: 0,
            depth_hold: false,
            target_depth: 0,
            pilot_timer: Timer::default(),
            alts_target: MIDPOINT,
            alts: MIDPOINT,
            mpu_init: false,
            mpu_device_id: true,
            mpu_reinit_timer: Timer::default(),
            mpu_update_timer: Timer::default(),
            calibrating: false,
            cal_counter: 0,
            cal_timer: Timer::default(),
            depth_timer: Timer::default(),
            depth: 0.0,
            depth_offset: 0.0,
            dms_armed: false,
            dms_tripped: false,
            blink_state: false,
            dms_timer: Timer::default(),
            blink_timer: Timer::default(),
            bno_sample_timer: Timer::default(),
            bno_report_timer: Timer::default(),
            frames_ok: 0,
            crc_failures: 0,
            overruns: 0,
            executed: 0,
            cfg,
        }
    }

    fn millis(&self) -> u64 {
        self.clock.as_millis() as u64
    }

    /// The clock, if the sketch is between two passes of its loop.
    pub(super) fn between_passes(&self) -> Option<Duration> {
        (self.phase == Phase::Loop(0)).then_some(self.clock)
    }

    pub(super) fn powered(&self) -> bool {
        self.phase != Phase::Off
    }

    /// Power-up at `now`.
    pub(super) fn power_on(&mut self, now: Duration) {
        self.clock = now;
        self.phase = Phase::Setup(0);
    }

    /// A hung board's time passes without a pass of its loop.
    pub(super) fn hang_until(&mut self, now: Duration) {
        self.clock = self.clock.max(now);
    }

    // ------------------------------------------------------------------
    // Figures for the snapshot
    // ------------------------------------------------------------------

    pub(super) fn targets(&self) -> [i32; 3] {
        self.target
    }
    pub(super) fn escs(&self) -> [u16; 3] {
        self.esc_us
    }
    pub(super) fn escs_powered(&self) -> bool {
        self.escs_powered
    }
    pub(super) fn motors_attached(&self) -> bool {
        self.matc
    }
    pub(super) fn dead_man(&self) -> (bool, bool) {
        (self.dms_armed, self.dms_tripped)
    }
    pub(super) fn lights(&self) -> i32 {
        self.lights
    }
    pub(super) fn laser(&self) -> i32 {
        self.laser
    }
    pub(super) fn tilt(&self) -> (i32, i32) {
        (self.cmnt, self.cmtg)
    }
    pub(super) fn counters(&self) -> (u64, u64, u64, u64) {
        (
            self.frames_ok,
            self.crc_failures,
            self.overruns,
            self.executed,
        )
    }

    // ------------------------------------------------------------------
    // Running
    // ------------------------------------------------------------------

    /// Runs the sketch while its clock is not past `now`: setup, then
    /// passes of the loop. Stops between two steps of a pass only when a
    /// step took the clock well past `now` (a long `delay`).
    pub(super) fn run_until(&mut self, now: Duration, uart: &mut Uart, hw: &mut dyn Hardware) {
        let devices = self.build.devices.len();
        // A pass in progress is finished unless a `delay` took it well past
        // `now` (the scan's 5 s): waking once per step would only cost.
        let in_pass = |p: Phase| matches!(p, Phase::Loop(i) if i > 0);
        while self.clock <= now || (in_pass(self.phase) && self.clock <= now + PASS_SLACK) {
            match self.phase {
                Phase::Off => return,
                Phase::Setup(0) => {
                    // Serial.begin, Wire.begin, the EEPROM check; then the
                    // output timers start before the devices' set-up.
                    let ms = self.millis();
                    self.out1000.reset(ms);
                    self.out100.reset(ms);
                    self.phase = Phase::Setup(1);
                }
                Phase::Setup(i) if i <= devices => {
                    if self.cfg.firmware == FirmwareVersion::V30_0_2 {
                        self.print(uart, format!("log:setting dev #{};", i - 1).as_bytes());
                    }
                    self.device_setup(self.build.devices[i - 1], uart, hw);
                    self.phase = Phase::Setup(i + 1);
                }
                Phase::Setup(_) => {
                    self.println(uart, "boot:1;");
                    self.phase = Phase::Loop(0);
                }
                Phase::Loop(0) => {
                    if self.skip_idle_passes(now, uart) {
                        continue;
                    }
                    self.get(uart, hw);
                    self.phase = Phase::Loop(1);
                }
                Phase::Loop(i) if i <= devices => {
                    let start = self.clock;
                    let device = self.build.devices[i - 1];
                    self.device_loop(device, uart, hw);
                    self.clock += Duration::from_micros(self.build.device_cost_us[i - 1]);
                    self.device_time_us[i - 1] += (self.clock - start).as_micros() as u64;
                    self.phase = Phase::Loop(i + 1);
                }
                Phase::Loop(_) => {
                    self.end_of_pass(uart, hw);
                    self.clock += Duration::from_micros(self.build.main_cost_us);
                    self.phase = Phase::Loop(0);
                }
            }
        }
    }

    /// Skips whole passes in which nothing can happen (no byte to read, no
    /// queued command, no timer due, no servo slewing a step that prints)
    /// up to `now`. Whether it skipped any.
    fn skip_idle_passes(&mut self, now: Duration, uart: &Uart) -> bool {
        if uart.pending() {
            return false;
        }
        let Some(event) = self.next_event() else {
            return false;
        };
        let cost = self.pass_cost.as_nanos().max(1);
        let span = |until: Duration| until.saturating_sub(self.clock).as_nanos();
        // Pass j starts at clock + j·cost. It is idle if it ends before the
        // next timer is due and starts before the next byte arrives; only
        // the passes that start by `now` are run now.
        let mut passes = span(event) / cost;
        if let Some(at) = uart.next_arrival() {
            passes = passes.min(span(at).div_ceil(cost));
        }
        passes = passes.min(span(now) / cost + 1);
        if passes == 0 {
            return false;
        }
        let passes = passes as u64;
        self.clock += Duration::from_nanos((cost as u64).saturating_mul(passes));
        self.loops_per_sec = self.loops_per_sec.saturating_add(passes as u32);
        for (t, cost) in self
            .device_time_us
            .iter_mut()
            .zip(self.build.device_cost_us)
        {
            *t += cost * passes;
        }
        // The camera servo slews a microsecond a pass, seen only in `servo:`.
        let step = (passes as i64).min(i64::from((self.cmtg - self.cmnt).abs())) as i32;
        self.cmnt += step * (self.cmtg - self.cmnt).signum();
        true
    }

    /// The earliest time a timer can fire; `None` if the next pass has
    /// work at once (a queued command, a slewing servo that prints).
    fn next_event(&self) -> Option<Duration> {
        if self.head != self.tail || self.alts != self.alts_target {
            return None;
        }
        let ms = |m: u64| Duration::from_millis(m);
        let mut t = ms(self.out1000.due_ms(self.cfg.status_period_ms))
            .min(ms(self.out100.due_ms(self.cfg.nav_period_ms)))
            .min(ms(self.adc_timer.due_ms(100)))
            .min(ms(self.brdt_timer.due_ms(1000)))
            .min(ms(self.status_timer.due_ms(100)))
            .min(ms(self.control_timer.due_ms(50)))
            .min(ms(self.output_timer.due_ms(1000)))
            .min(ms(self.pilot_timer.due_ms(50)))
            .min(ms(self.depth_timer.due_ms(1000)))
            .min(ms(self.dms_timer.due_ms(2000)));
        if self.mpu_init {
            t = t.min(if self.calibrating {
                ms(self.cal_timer.due_ms(1000))
            } else {
                ms(self.mpu_update_timer.due_ms(50))
            });
        } else {
            t = t.min(ms(self.mpu_reinit_timer.due_ms(30_000)));
        }
        if !self.dms_armed {
            t = t.min(ms(DELAY_TO_ARM_MS + 1));
        }
        if self.dms_tripped {
            t = t.min(ms(self.blink_timer.due_ms(500)));
        }
        if self.build.devices.contains(&Device::Bno055) {
            t = t.min(ms(self.bno_sample_timer.due_ms(47)));
        }
        Some(t)
    }

    /// When the sketch next prints, moves a thruster or needs input read,
    /// for a caller that wants to sleep until then: a pass in progress,
    /// queued work, or the next timer whose firing shows.
    pub(super) fn next_deadline(&self, uart: &Uart) -> Duration {
        // A pass cut short by a `delay` or a long print resumes with the
        // time it needs; what it may still print is due on a timer below.
        if !matches!(self.phase, Phase::Loop(_)) {
            return self.clock;
        }
        if self.head != self.tail || self.alts != self.alts_target || uart.pending() {
            return self.clock;
        }
        let ms = |m: u64| Duration::from_millis(m);
        let mut t = ms(self.out1000.due_ms(self.cfg.status_period_ms))
            .min(ms(self.out100.due_ms(self.cfg.nav_period_ms)))
            .min(ms(self.brdt_timer.due_ms(1000)))
            .min(ms(self.output_timer.due_ms(1000)))
            .min(ms(self.depth_timer.due_ms(1000)));
        if self.target != self.applied {
            t = t.min(ms(self.control_timer.due_ms(50)));
        }
        if self.heading_hold || self.depth_hold {
            t = t.min(ms(self.pilot_timer.due_ms(50)));
        }
        if self.dms_armed && !self.dms_tripped {
            t = t.min(ms(self.dms_timer.due_ms(2000)));
        }
        if !self.dms_armed {
            t = t.min(ms(DELAY_TO_ARM_MS + 1));
        }
        if self.dms_tripped {
            t = t.min(ms(self.blink_timer.due_ms(500)));
        }
        if self.calibrating {
            t = t.min(ms(self.cal_timer.due_ms(1000)));
        }
        if !self.mpu_init {
            t = t.min(ms(self.mpu_reinit_timer.due_ms(30_000)));
        }
        if self.build.devices.contains(&Device::Bno055) {
            t = t.min(ms(self.bno_report_timer.due_ms(30_000)));
        }
        if let Some(at) = uart.next_frame_end() {
            t = t.min(at);
        }
        t.max(self.clock)
    }

    // ------------------------------------------------------------------
    // Serial output
    // ------------------------------------------------------------------

    fn print(&mut self, uart: &mut Uart, bytes: &[u8]) {
        uart.print(bytes, &mut self.clock);
    }

    fn println(&mut self, uart: &mut Uart, text: &str) {
        let mut line = Vec::with_capacity(text.len() + 2);
        line.extend_from_slice(text.as_bytes());
        line.extend_from_slice(b"\r\n");
        uart.print(&line, &mut self.clock);
    }

    /// A periodic line, through the fault injector.
    fn telemetry(&mut self, uart: &mut Uart, hw: &mut dyn Hardware, line: String) {
        // The board printed the clean line; the faults are on the wire.
        let printed = line.len() + 2;
        let bytes = hw.telemetry(line);
        uart.print_as(&bytes, printed, &mut self.clock);
    }

    fn delay(&mut self, d: Duration) {
        self.clock += d;
    }

    // ------------------------------------------------------------------
    // Command.cpp
    // ------------------------------------------------------------------

    /// `Command::get`: a complete serial frame, else one queued command.
    fn get(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        self.cmd = Current::default();
        if let Some(frame) = self.get_serial_string(uart) {
            self.parse(&frame, uart, hw);
            self.cmd.ready = true;
            return;
        }
        if self.head != self.tail {
            self.tail = (self.tail + 1) % COMMAND_QUEUE_SLOTS;
            let c = self.queue[self.tail].clone();
            let count = c.args.first().copied().unwrap_or(0).max(0) as usize;
            let mut line = format!("icmd:{}(", c.text);
            for i in 1..=count.min(MAX_ARGS - 1) {
                let v = c.args.get(i).copied().unwrap_or(0);
                self.cmd.args[i] = v;
                if i > 1 {
                    line.push(',');
                }
                line.push_str(&v.to_string());
            }
            line.push_str(");");
            self.cmd.args[0] = c.args.first().copied().unwrap_or(0);
            self.cmd.name = c.text.into_bytes();
            self.cmd.ready = true;
            self.println(uart, &line);
        }
    }

    /// `getSerialString`: reads what has arrived up to the first `;`. A
    /// frame that outgrows the buffer is cut: the byte that found it full
    /// is lost and storing starts again at the buffer's start.
    fn get_serial_string(&mut self, uart: &mut Uart) -> Option<Vec<u8>> {
        let keeps_end = self.cfg.firmware == FirmwareVersion::V30_0_2;
        while let Some(b) = uart.read(self.clock) {
            if !self.storing {
                self.storing = true;
                self.data.clear();
            }
            if self.data.len() == FRAME_BUFFER_BYTES {
                self.data.clear();
                break;
            }
            if b == b';' {
                if keeps_end {
                    self.data.push(b);
                }
                self.storing = false;
                return Some(self.data.clone());
            }
            self.data.push(b);
        }
        None
    }

    /// `Command::parse`: the echo, the CRC check (30.0.2) and the split
    /// into a name and `atoi`'d arguments; the echo prints each argument
    /// as it came.
    fn parse(&mut self, frame: &[u8], uart: &mut Uart, hw: &mut dyn Hardware) {
        let text = match self.cfg.firmware {
            FirmwareVersion::V30_0_2 => {
                let mut line = String::from("rawcmd:");
                for &b in frame {
                    line.push_str(&arduino::hex(b));
                    line.push(',');
                }
                line.push(';');
                self.println(uart, &line);
                hw.record(BoardRecord::Frame(frame.to_vec()));
                let got = frame.first().copied().unwrap_or(0);
                let calc = crc8(frame.get(1..).unwrap_or(&[]));
                if calc != got {
                    self.crc_failures += 1;
                    let fail = format!("crc:fail,{}/{};", arduino::hex(calc), arduino::hex(got));
                    self.print(uart, fail.as_bytes());
                    return;
                }
                self.print(uart, b"crc:pass;");
                frame.get(1..).unwrap_or(&[])
            }
            FirmwareVersion::V2014_12 => {
                let mut received = frame.to_vec();
                received.push(b';');
                hw.record(BoardRecord::Frame(received));
                frame
            }
        };
        self.frames_ok += 1;
        // strtok works on the C string: up to the first NUL.
        let text = match text.iter().position(|&b| b == 0) {
            Some(end) => &text[..end],
            None => text,
        };
        let tokens: Vec<&[u8]> = text
            .split(|b| b" ,();".contains(b))
            .filter(|t| !t.is_empty())
            .collect();
        let mut line = Vec::with_capacity(text.len() + 8);
        if let Some((name, args)) = tokens.split_first() {
            line.extend_from_slice(b"cmd:");
            line.extend_from_slice(name);
            line.push(b'(');
            self.cmd.name = name.to_vec();
            for (i, arg) in args.iter().enumerate() {
                if i > 0 {
                    line.push(b',');
                }
                line.extend_from_slice(arg);
                if let Some(slot) = self.cmd.args.get_mut(i + 1) {
                    *slot = atoi(arg);
                }
            }
            let parsed: Vec<String> = (1..=args.len().min(MAX_ARGS - 1))
                .map(|i| self.cmd.args[i].to_string())
                .collect();
            self.executed += 1;
            hw.record(BoardRecord::Executed(format!(
                "{}({})",
                String::from_utf8_lossy(name),
                parsed.join(",")
            )));
        }
        line.extend_from_slice(b");\r\n");
        self.print(uart, &line);
        // `byte i` counted the tokens; none leaves -1.
        self.cmd.args[0] = tokens.len() as i32 - 1;
    }

    /// `Command::pushCommand`: onto the internal ring, the oldest waiting
    /// command lost when it is full.
    fn push(&mut self, uart: &mut Uart, text: &str, args: &[i32]) {
        self.head = (self.head + 1) % COMMAND_QUEUE_SLOTS;
        if self.head == self.tail {
            self.println(uart, "log: CommandBufferOverrun;");
            self.overruns += 1;
            self.tail = (self.tail + 1) % COMMAND_QUEUE_SLOTS;
        }
        self.queue[self.head] = Queued {
            text: text.to_owned(),
            args: args.to_vec(),
        };
    }

    // ------------------------------------------------------------------
    // The main loop's outputs
    // ------------------------------------------------------------------

    fn end_of_pass(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        self.loops_per_sec = self.loops_per_sec.saturating_add(1);
        let ms = self.millis();
        if self.out1000.elapsed(ms, self.cfg.status_period_ms) {
            self.shared_data(uart, hw);
            let alps = format!("alps:{};", self.loops_per_sec);
            self.telemetry(uart, hw, alps);
            self.loops_per_sec = 0;
        }
        let ms = self.millis();
        if self.out100.elapsed(ms, self.cfg.nav_period_ms) {
            let line = format!(
                "hdgd:{};deap:{};pitc:{};roll:{};yaw:{};fthr:{};",
                float(self.hdgd),
                float(self.deap),
                float(self.pitc),
                float(self.roll),
                float(self.yaw),
                float(self.fthr)
            );
            self.telemetry(uart, hw, line);
        }
    }

    /// `OutputSharedData`: six lines, one of them (`cmpd`) broken before
    /// its `;`, which starts the `time` line.
    fn shared_data(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        self.telemetry(uart, hw, format!("motorAttached:{};", u8::from(self.matc)));
        self.telemetry(
            uart,
            hw,
            format!("servo:{};starg:{};", self.cmnt, self.cmtg),
        );
        let status = format!(
            "fmem:{};vout:{};iout:{};atmp:{};ver:{};cmpd:{}",
            float(self.fmem),
            float(self.vout),
            float(self.iout),
            float(0.0),
            self.cfg.version,
            self.build.compiled
        );
        self.println(uart, &status);
        let time = format!(";time:{};", float(self.utim));
        self.println(uart, &time);
        self.telemetry(
            uart,
            hw,
            format!("pres:{};temp:{};", float(self.pres), float(self.temp)),
        );
        let mut dlms = String::from("dlms:");
        for (i, us) in self.device_time_us.iter().enumerate() {
            dlms.push_str(&format!("{i}|{}", us / 1000));
        }
        dlms.push(';');
        self.telemetry(uart, hw, dlms);
    }

    // ------------------------------------------------------------------
    // The devices
    // ------------------------------------------------------------------

    fn device_setup(&mut self, device: Device, uart: &mut Uart, hw: &mut dyn Hardware) {
        let ms = self.millis();
        match device {
            Device::Settings => {}
            Device::Controller25 => {
                self.adc_timer.reset(ms);
                self.status_timer.reset(ms);
                self.brdt_timer.reset(ms);
                if self.cfg.firmware == FirmwareVersion::V30_0_2 {
                    // The I2C bus's power cycled.
                    self.delay(Duration::from_millis(10));
                }
            }
            Device::Lights => self.capabilities |= 1 << 1,
            Device::Laser => self.capabilities |= 1 << 2,
            Device::Thrusters => {
                for m in &mut self.motors {
                    m.deadzone_negative = self.deadzone_min;
                    m.deadzone_positive = self.deadzone_max;
                }
                self.output_timer.reset(ms);
                self.control_timer.reset(ms);
                self.escs_powered = true;
                hw.esc_power(self.clock, true);
                hw.write_escs(self.clock, self.esc_us);
            }
            Device::Pilot => {
                self.pilot_timer.reset(ms);
                self.println(uart, "log:pilot setup complete;");
            }
            Device::CameraMount => self.capabilities |= 1 << 3,
            Device::AltServo => self.capabilities |= 1 << 7,
            Device::Mpu9150 => self.mpu_setup(uart),
            Device::Ms5803 => self.ms5803_setup(uart),
            Device::DeadMan => {
                self.capabilities |= 1 << 1;
                self.dms_timer.reset(ms);
                self.blink_timer.reset(ms);
            }
            Device::Bno055 => self.bno055_setup(uart),
        }
    }

    fn device_loop(&mut self, device: Device, uart: &mut Uart, hw: &mut dyn Hardware) {
        match device {
            Device::Settings => self.settings_loop(uart),
            Device::Controller25 => self.controller_loop(uart, hw),
            Device::Lights => self.lights_loop(uart),
            Device::Laser => {
                if self.cmd.is("claser") {
                    self.laser = self.cmd.arg(1);
                    let text = format!("claser:{};", self.laser);
                    self.print(uart, text.as_bytes());
                }
            }
            Device::Thrusters => self.thrusters_loop(uart, hw),
            Device::Pilot => self.pilot_loop(uart),
            Device::CameraMount => {
                if self.cmd.is("tilt") {
                    let v = self.cmd.arg(1);
                    if v > 999 && v < 2001 {
                        self.cmtg = v;
                    }
                }
                if self.cmtg != self.cmnt {
                    self.cmnt += (self.cmtg - self.cmnt).signum();
                }
            }
            Device::AltServo => self.alt_servo_loop(uart),
            Device::Mpu9150 => self.mpu_loop(uart, hw),
            Device::Ms5803 => self.ms5803_loop(uart, hw),
            Device::DeadMan => self.dead_man_loop(uart),
            Device::Bno055 => {
                let ms = self.millis();
                // Never found: set-up is retried every 30 s.
                if self.bno_sample_timer.elapsed(ms, 1000 / 21)
                    && self.bno_report_timer.elapsed(ms, 30_000)
                {
                    self.bno055_setup(uart);
                }
            }
        }
    }

    fn settings_loop(&mut self, uart: &mut Uart) {
        if self.cmd.is("reportSetting") {
            let line = format!(
                "*settings:smoothingIncriment|{},deadZone_min|{},deadZone_max|{};water_type{};",
                self.smoothing,
                self.deadzone_min,
                self.deadzone_max,
                u8::from(self.water_salt)
            );
            self.println(uart, &line);
        } else if self.cmd.is("rcap") {
            let capa = format!("CAPA:{};", self.capabilities);
            self.print(uart, capa.as_bytes());
            self.scan_i2c(uart);
        } else if self.cmd.is("updateSetting") {
            self.smoothing = self.cmd.arg(1);
            self.deadzone_min = self.cmd.arg(2);
            self.deadzone_max = self.cmd.arg(3);
            self.water_salt = self.cmd.arg(4) != 0;
        }
    }

    /// `Settings::scan_i2c`: every address probed, the ones that answer
    /// listed, then five seconds of `delay` in which the board reads
    /// nothing (its receive ring fills, then loses bytes).
    fn scan_i2c(&mut self, uart: &mut Uart) {
        self.println(uart, "log:Scanning...;");
        let mut found = 0;
        for address in 1u8..127 {
            self.delay(I2C_BYTE);
            let answers = (address == MPU9150_ADDRESS && self.cfg.sensors.mpu9150)
                || (address == MS5803_ADDRESS && self.cfg.sensors.ms5803);
            if answers {
                let line = format!("log:I2C device found at address 0x{address:02X}  !;");
                self.println(uart, &line);
                found += 1;
            }
        }
        if found == 0 {
            self.println(uart, "log:No I2C devices found\n;");
        } else {
            self.println(uart, "log:done\n;");
        }
        self.delay(Duration::from_secs(5));
    }

    fn controller_loop(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        let ms = self.millis();
        if self.adc_timer.elapsed(ms, 100) {
            self.delay(ADC_READ);
        }
        let ms = self.millis();
        if self.brdt_timer.elapsed(ms, 1000) {
            // Ten conversions and readVcc's 2 ms for its reference.
            self.delay(ADC_READ * 9 + Duration::from_millis(2));
            let p = Power::of(&hw.read_power(self.clock));
            let line = format!(
                "BRDT:{};SC1I:{};SC2I:{};SC3I:{};BRDI:{};BT1I:{};BT2I:{};BRDV:{};AVCC:{};",
                float(p.board_temp_c()),
                float(0.0),
                float(0.0),
                float(0.0),
                float(p.board_current_a()),
                float(p.tube_current_a(0)),
                float(p.tube_current_a(1)),
                float(p.battery_v()),
                Power::AVCC_MV
            );
            self.telemetry(uart, hw, line);
        }
        let ms = self.millis();
        if self.status_timer.elapsed(ms, 100) {
            self.delay(ADC_READ * 2);
            let p = Power::of(&hw.read_power(self.clock));
            self.vout = p.battery_v();
            self.iout = p.board_current_a();
            self.fmem = self.build.free_memory;
            self.utim = self.millis() as f32;
        }
    }

    fn lights_loop(&mut self, uart: &mut Uart) {
        if self.cmd.is("ligt") {
            let value = self.cmd.arg(1);
            self.lights = value;
            let line = format!("LIGT:{value};LIGP:{};", float(value as f32 / 255.0));
            self.println(uart, &line);
        }
        if self.cfg.firmware == FirmwareVersion::V30_0_2 && self.cmd.is("eligt") {
            let percent = self.cmd.arg(1) as f32 / 100.0;
            let value = trunc(255.0 * percent);
            let line = format!("LIGTE:{value};LIGPE:{};", float(percent));
            self.println(uart, &line);
        }
    }

    fn mtrmod_line(&self) -> String {
        let [p, v, s] = self.motors;
        format!(
            "mtrmod:{},{},{},{},{},{};",
            float(p.positive_modifier),
            float(v.positive_modifier),
            float(s.positive_modifier),
            float(p.negative_modifier),
            float(v.negative_modifier),
            float(s.negative_modifier)
        )
    }

    fn thrusters_loop(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        let a = self.cmd.args;
        if self.cmd.is("mtrmod1") {
            for (m, v) in self.motors.iter_mut().zip(&a[1..4]) {
                // Integer division before the float: 150 is 1.
                m.positive_modifier = (v / 100) as f32;
            }
        }
        if self.cmd.is("mtrmod2") {
            for (m, v) in self.motors.iter_mut().zip(&a[1..4]) {
                m.negative_modifier = (v / 100) as f32;
            }
        }
        if self.cmd.is("rmtrmod") {
            let line = self.mtrmod_line();
            self.println(uart, &line);
        }
        let valid = |v: i32| v > 999 && v < 2001;
        if self.cmd.is("go") && valid(a[1]) && valid(a[2]) && valid(a[3]) {
            self.target = [a[1], a[2], a[3]];
        }
        if self.cmd.is("port") && valid(a[1]) {
            self.target[0] = a[1];
        }
        if self.cmd.is("vertical") && valid(a[1]) {
            self.target[1] = a[1];
        }
        if self.cmd.is("starboard") && valid(a[1]) {
            self.target[2] = a[1];
        }
        if self.cmd.is("thro") || self.cmd.is("yaw") {
            self.mix_throttle_and_yaw();
        }
        if self.cmd.is("lift") {
            if (-100..=100).contains(&a[1]) {
                let lift = a[1] as f32 / 100.0;
                self.target[1] = trunc(1500.0 + 500.0 * lift);
            }
        } else if self.cmd.is("escp") {
            self.escs_powered = a[1] != 0;
            hw.esc_power(self.clock, self.escs_powered);
            let line = format!("log:escpower={};", a[1]);
            self.println(uart, &line);
        } else if self.cmd.is("start") {
            // Re-attaches the ESC outputs, which never detach.
        } else if self.cmd.is("stop") {
            self.target = [MIDPOINT; 3];
        } else if self.cmd.is("mcal") {
            self.println(uart, "log:Motor Callibration Staring;");
            self.println(uart, "log:Motor Callibration Complete;");
        }
        let ms = self.millis();
        if self.control_timer.elapsed(ms, 50) && self.target != self.applied {
            self.applied = self.target;
            let m = self.motors;
            self.esc_us = [
                m[0].goms(self.applied[0]),
                m[1].goms(self.applied[1]),
                m[2].goms(self.applied[2]),
            ];
            hw.write_escs(self.clock, self.esc_us);
            let [p, v, s] = self.esc_us;
            let line = format!("motors:{p},{v},{s};");
            self.println(uart, &line);
        }
        self.fthr = map(
            (self.applied[0] + self.applied[2]) / 2,
            1000,
            2000,
            -100,
            100,
        ) as f32;
        let ms = self.millis();
        if self.output_timer.elapsed(ms, 1000) {
            let [p, v, s] = self.target;
            self.telemetry(uart, hw, format!("mtarg:{p},{v},{s};"));
            if self.cfg.firmware == FirmwareVersion::V30_0_2 {
                let line = self.mtrmod_line();
                self.telemetry(uart, hw, line);
            }
        }
    }

    /// `thro`/`yaw` on the board: the throttle spread over the port
    /// motor's range (the reverse half divided by its modifier), then the
    /// turn added and the pair shifted back inside 1000..2000.
    fn mix_throttle_and_yaw(&mut self) {
        let v = self.cmd.arg(1);
        if self.cmd.is("thro") && (-100..=100).contains(&v) {
            self.trg_throttle = v as f32 / 100.0;
        }
        if self.cmd.is("yaw") && (-100..=100).contains(&v) {
            self.trg_yaw = v as f32 / 100.0;
        }
        let port = self.motors[0];
        let modifier = if self.trg_throttle >= 0.0 {
            port.positive_modifier
        } else {
            port.negative_modifier
        };
        let power = trunc(1500.0 + (500.0 / modifier.abs()) * self.trg_throttle);
        let turn = trunc(self.trg_yaw * 250.0);
        let (p, s) = if self.trg_throttle >= 0.0 {
            let offset = ((turn.abs() + power) - 2000).max(0);
            (power + turn - offset, power - turn - offset)
        } else {
            let offset = (1000 - (power - turn.abs())).max(0);
            (power + turn + offset, power - turn + offset)
        };
        self.target[0] = p;
        self.target[2] = s;
    }

    fn pilot_loop(&mut self, uart: &mut Uart) {
        if self.cmd.is("headloff") {
            self.heading_hold = false;
            self.hdg_integral = 0;
            self.tgt_hdg = -500;
            self.push(uart, "yaw", &[1, 0]);
            self.println(uart, "log:heading_hold_disabled;");
            self.println(uart, "targetHeading:DISABLED;");
        }
        if self.cmd.is("headlon") {
            self.heading_hold = true;
            self.tgt_hdg = if self.cmd.arg(0) == 0 {
                trunc(self.hdgd)
            } else {
                self.cmd.arg(1)
            };
            let line = format!(
                "log:heading_hold_enabled on={};\r\ntargetHeading:{};",
                self.tgt_hdg, self.tgt_hdg
            );
            self.println(uart, &line);
        }
        if self.cmd.is("holdHeading_toggle") {
            if self.heading_hold {
                self.push(uart, "headloff", &[0]);
            } else if self.cmd.arg(0) == 0 {
                self.push(uart, "headlon", &[0]);
            } else {
                let a = self.cmd.arg(1);
                self.push(uart, "headlon", &[1, a]);
            }
        }
        if self.cmd.is("deptloff") {
            self.depth_hold = false;
            self.target_depth = 0;
            self.push(uart, "lift", &[1, 0]);
            self.println(uart, "log:depth_hold_disabled;");
            self.println(uart, "targetDepth:DISABLED;");
        }
        if self.cmd.is("deptlon") {
            self.depth_hold = true;
            self.target_depth = if self.cmd.arg(0) == 0 {
                trunc(self.deap * 100.0)
            } else {
                self.cmd.arg(1)
            };
            let line = format!(
                "log:depth_hold_enabled on={};\r\ntargetDepth:{};",
                self.target_depth, self.target_depth
            );
            self.println(uart, &line);
        }
        if self.cmd.is("holdDepth_toggle") {
            if self.depth_hold {
                self.push(uart, "deptloff", &[0]);
            } else if self.cmd.arg(0) == 0 {
                self.push(uart, "deptlon", &[0]);
            } else {
                let a = self.cmd.arg(1);
                self.push(uart, "deptlon", &[1, a]);
            }
        }
        let ms = self.millis();
        if self.pilot_timer.elapsed(ms, 50) {
            if self.depth_hold {
                let depth = trunc(self.deap * 100.0);
                let error = self.target_depth - depth;
                let lift = constrain(trunc(error as f32 * 0.6), -100, 100);
                let line = format!("log:dhold pushing command;\r\ndp_er:{error};");
                self.println(uart, &line);
                let lift = if error.abs() > 4 { lift } else { 0 };
                self.push(uart, "lift", &[1, lift]);
            }
            if self.heading_hold {
                let mut error = trunc(self.hdgd) - self.tgt_hdg;
                if error > 180 {
                    error -= 360;
                }
                if error < -179 {
                    error += 360;
                }
                self.hdg_integral += i64::from(error);
                let yaw = constrain(trunc((-error) as f32), -50, 50);
                let line = format!("log:hold pushing command;\r\np_er:{error};");
                self.println(uart, &line);
                let yaw = if error.abs() > 4 { yaw } else { 0 };
                self.push(uart, "yaw", &[1, yaw]);
            }
        }
    }

    fn alt_servo_loop(&mut self, uart: &mut Uart) {
        if self.cmd.is("asrt") {
            let ms = map(self.cmd.arg(1), -100, 100, 1000, 2000);
            if (1000..=2000).contains(&ms) {
                self.alts_target = ms;
                let line = format!("asr.t:{ms};");
                self.println(uart, &line);
            }
        }
        if self.alts_target != self.alts {
            self.alts += (self.alts_target - self.alts).signum();
            let line = format!("asr.v:{};", self.alts);
            self.println(uart, &line);
        }
    }

    fn mpu_setup(&mut self, uart: &mut Uart) {
        let ms = self.millis();
        let found = self.cfg.sensors.mpu9150;
        match self.cfg.firmware {
            FirmwareVersion::V30_0_2 => {
                self.mpu_reinit_timer.reset(ms);
                self.mpu_update_timer.reset(ms);
                // Probed at 0x68, then 0x69.
                self.delay(I2C_BYTE * 2);
                if !found {
                    self.println(uart, "MPU9150.status:Not found;");
                    return;
                }
                self.mpu_init_chip(uart);
                self.capabilities |= (1 << 4) | (1 << 5);
            }
            FirmwareVersion::V2014_12 => {
                if found {
                    self.mpu_init_chip(uart);
                } else {
                    self.delay(I2C_BYTE);
                    self.println(uart, "mpu_init failed with code: -1");
                    self.println(uart, "log:Trying other MPU9150 address to init;");
                    self.mpu_device_id = !self.mpu_device_id;
                    let line = format!(
                        "log:IMU Address was :1 but is now:{};",
                        u8::from(self.mpu_device_id)
                    );
                    self.println(uart, &line);
                    self.delay(I2C_BYTE);
                    self.println(uart, "mpu_init failed with code: -1");
                    self.println(uart, "log:Failed to init on both addresses;");
                }
                self.capabilities |= (1 << 4) | (1 << 5);
                let ms = self.millis();
                self.mpu_reinit_timer.reset(ms);
                self.mpu_update_timer.reset(ms);
            }
        }
    }

    /// `MPU9150Lib::init` on a chip that answers at its primary address.
    fn mpu_init_chip(&mut self, uart: &mut Uart) {
        self.delay(MPU_RESET);
        self.println(uart, "Loading firmware");
        self.delay(MPU_DMP_LOAD);
        self.mpu_init = true;
        self.println(uart, "log:init on primary addresses;");
    }

    fn mpu_loop(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        let ms = self.millis();
        if !self.mpu_init {
            if self.mpu_reinit_timer.elapsed(ms, 30_000) {
                self.mpu_setup(uart);
            }
            return;
        }
        if self.cmd.is("ccal") {
            self.cal_counter = 359;
            self.calibrating = true;
            self.cal_timer.reset(ms);
            self.println(
                uart,
                "!!!:While the compass counts down from 360 to 0, rotate the ROV slowly in all three axis;",
            );
        }
        if self.calibrating {
            if self.cal_counter > 0 && self.cal_timer.elapsed(self.millis(), 1000) {
                self.cal_counter -= 1;
                self.hdgd = self.cal_counter as f32;
                let text = format!("hdgd:{};", float(self.hdgd));
                self.print(uart, text.as_bytes());
            }
            if self.cal_counter <= 0 {
                self.println(uart, "log:Accel cal data saved for device;");
                self.calibrating = false;
            }
            return;
        }
        if self.mpu_update_timer.elapsed(ms, 50) {
            self.delay(MPU_READ);
            let r = hw.read_sensors(self.clock);
            // The fused yaw, moved into 0..360 (the simulator's heading).
            self.hdgd = r.heading_deg as f32;
            self.pitc = r.pitch_deg as f32;
            self.roll = r.roll_deg as f32;
            self.yaw = r.yaw_deg as f32;
        }
    }

    fn ms5803_setup(&mut self, uart: &mut Uart) {
        self.capabilities |= 1 << 6;
        let words = if self.cfg.sensors.ms5803 {
            MS5803_PROM_WORDS
        } else {
            // Nothing answers: the bytes read stay 0.
            [0; 8]
        };
        match self.cfg.firmware {
            FirmwareVersion::V30_0_2 => {
                self.println(uart, "log:Depth Sensor setup;");
                self.println(uart, "MS5803.status: initialized I2C;");
                self.delay(Duration::from_millis(10) + I2C_BYTE);
                self.delay(Duration::from_millis(10));
                self.println(uart, "MS5803.status: reset;");
                self.delay(MS5803_PROM);
                self.println(uart, "Depth: Calibration constants are:");
                for (i, w) in words.iter().enumerate() {
                    let line = format!("Depth.C{i}:{w};");
                    self.println(uart, &line);
                }
            }
            FirmwareVersion::V2014_12 => {
                self.println(uart, "Depth Sensor setup.");
                self.println(uart, "Depth Sensor: initialized I2C");
                self.delay(Duration::from_millis(10) + I2C_BYTE);
                self.delay(Duration::from_millis(10));
                self.println(uart, "Depth Sensor is reset");
                self.delay(MS5803_PROM);
                self.println(uart, "Depth: Calibration constants are:");
            }
        }
        let ms = self.millis();
        self.depth_timer.reset(ms);
    }

    fn ms5803_loop(&mut self, uart: &mut Uart, hw: &mut dyn Hardware) {
        if self.cmd.is("dzer") {
            self.depth_offset = self.depth;
        } else if self.cmd.is("dtwa") {
            self.water_salt = !self.water_salt;
            let line = if self.water_salt {
                "dtwa:1;"
            } else {
                "dtwa:0;"
            };
            self.println(uart, line);
        }
        let ms = self.millis();
        if !self.depth_timer.elapsed(ms, 1000) {
            return;
        }
        // D1: convert, wait 10 ms, read.
        self.delay(I2C_BYTE + Duration::from_millis(10) + I2C_BYTE);
        if !self.cfg.sensors.ms5803 {
            // Nothing answers: 20 ms of waiting for three bytes, then this
            // line, printed without its `;`.
            self.delay(Duration::from_millis(21));
            self.println(uart, "log:Failed to read Depth from I2C");
            return;
        }
        self.delay(I2C_BYTE * 4);
        // D2, the same.
        self.delay(I2C_BYTE + Duration::from_millis(10) + I2C_BYTE * 5);
        let r = hw.read_sensors(self.clock);
        if self.cfg.firmware == FirmwareVersion::V2014_12 {
            let line = format!(
                "First-Order Temperature in Degrees C is {}\r\nSecond-Order Temperature in Degrees C is {}",
                float(r.temp_c as f32),
                float(r.temp_c as f32)
            );
            self.println(uart, &line);
        }
        self.temp = r.temp_c as f32;
        self.pres = r.pressure_mbar as f32;
        // The simulator's water is fresh, as the board's is by default:
        // its reading (with any wild point) is the board's depth. Set for
        // salt water, the board's own conversion applies.
        self.depth = if self.water_salt {
            (self.pres - 1015.0) * 0.9945 / 100.0
        } else {
            r.depth_m as f32
        };
        self.deap = self.depth - self.depth_offset;
    }

    fn dead_man_loop(&mut self, uart: &mut Uart) {
        let ms = self.millis();
        if !self.dms_armed && ms > DELAY_TO_ARM_MS {
            self.dms_armed = true;
        }
        if self.cmd.is("ping") {
            self.dms_timer.reset(ms);
            if self.dms_tripped {
                self.push(uart, "start", &[0]);
                self.dms_tripped = false;
            }
            let pong = format!("pong:{},{};", self.cmd.arg(0), self.millis());
            self.print(uart, pong.as_bytes());
        }
        let ms = self.millis();
        // The timer restarts every 2 s whether or not the switch is armed.
        if self.dms_timer.elapsed(ms, 2000) && self.dms_armed && !self.dms_tripped {
            self.push(uart, "deptloff", &[0]);
            self.push(uart, "headloff", &[0]);
            self.push(uart, "stop", &[0]);
            self.dms_tripped = true;
        }
        let ms = self.millis();
        if self.dms_tripped && self.blink_timer.elapsed(ms, 500) {
            let level = if self.blink_state { 0 } else { 50 };
            self.push(uart, "ligt", &[1, level]);
            self.blink_state = !self.blink_state;
        }
        if self.cmd.is("dms") {
            self.dms_armed = self.cmd.arg(0) != 0;
        }
    }

    fn bno055_setup(&mut self, uart: &mut Uart) {
        self.delay(I2C_BYTE * 4);
        self.println(
            uart,
            "BNO055.Address:40;\r\nBNO055.WHO_AM_I:0;\r\nBNO055.IAM_160:255;\r\nBNO055.status:failed;",
        );
        let ms = self.millis();
        self.bno_sample_timer.reset(ms);
        self.bno_report_timer.reset(ms);
    }
}

/// The controller board's analog inputs as its ADC converts them (10 bits
/// against 5 V) and the sketch scales them back.
struct Power {
    battery_code: i32,
    board_code: i32,
    tube_codes: [i32; 2],
    temp_code: i32,
}

impl Power {
    /// `readVcc()` of a 5.0 V supply: 1125300 / 225.
    const AVCC_MV: i32 = 5001;
    /// The board's own temperature sensor (the simulator has none).
    const BOARD_TEMP_C: f64 = 25.0;

    fn code(value: f64, full_scale: f64) -> i32 {
        if value.is_finite() {
            (value / full_scale * 1023.0).round().clamp(0.0, 1023.0) as i32
        } else {
            0
        }
    }

    fn of(r: &Readings) -> Self {
        let temp_v = Self::BOARD_TEMP_C / 51.28 + 0.4;
        Self {
            battery_code: Self::code(r.vout_v, 20.0),
            board_code: Self::code(r.iout_a, 2.0),
            // Two battery tubes share the vehicle's current.
            tube_codes: [Self::code(r.btti_a / 2.0, 10.0); 2],
            temp_code: (temp_v / 5.0 * 1024.0).round() as i32,
        }
    }
    fn battery_v(&self) -> f32 {
        mapf(self.battery_code, 0, 1023, 0, 20)
    }
    fn board_current_a(&self) -> f32 {
        mapf(self.board_code, 0, 1023, 0, 2)
    }
    fn tube_current_a(&self, i: usize) -> f32 {
        mapf(self.tube_codes[i], 0, 1023, 0, 10)
    }
    fn board_temp_c(&self) -> f32 {
        let volt = mapf(self.temp_code, 0, 1024, 0, 5);
        (volt - 0.4) * 51.28
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motor(dz: i32, neg: f32) -> Motor {
        Motor {
            positive_modifier: 1.0,
            negative_modifier: neg,
            deadzone_negative: dz,
            deadzone_positive: dz,
        }
    }

    #[test]
    fn goms_is_the_firmware_mapping() {
        let m = motor(50, 2.0);
        assert_eq!(m.goms(1600), 1640);
        assert_eq!(m.goms(1400), 1270);
        assert_eq!(m.goms(1500), 1500);
        assert_eq!(m.goms(1501), 1550);
        assert_eq!(m.goms(1499), 1448);
        assert_eq!(m.goms(2000), 2000);
        assert_eq!(m.goms(1000), 1000);
        assert_eq!(m.goms(1250), 1000);
        // A 2.5 reverse multiplier is an `int` 2 on the board.
        assert_eq!(motor(50, 2.5).goms(1400), 1270);
        // No deadzone and no multiplier: the target itself.
        for us in [1000, 1234, 1500, 1777, 2000] {
            assert_eq!(i32::from(motor(0, 1.0).goms(us)), us);
        }
    }
}
