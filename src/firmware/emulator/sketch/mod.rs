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
//! One file per part of the sketch: `command` (`Command.cpp` and the
//! loop's own outputs), `devices` (set-up and the per-pass dispatch, the
//! settings, the controller board's ADC, lights, the dead-man switch),
//! `motion` (thrusters, the pilot's holds, the servos), `sensors` (IMU,
//! depth sensor, BNO055 probe), `schedule` (when a pass has work; the idle
//! skip).
//!
//! Not imitated (see the emulator's module docs for why): the BNO055 found
//! (it is always absent, as on a 2.5 controller board), `ccal()`'s `dia:`
//! lines, arguments beyond the ninth overwriting memory, the watchdog, and
//! the EEPROM.

use std::time::Duration;

use super::arduino::Timer;
use super::uart::Uart;
use super::{BoardRecord, FirmwareVersion, FittedSensors};
use crate::sim::Readings;

mod command;
mod devices;
mod motion;
mod schedule;
mod sensors;

use motion::Motor;

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
/// `MPU9150Lib::init`: the chip's 100 ms reset and its registers, then
/// the DMP's 3062-byte program written and read back in 16-byte chunks
/// (about 45 bytes of I2C at 100 kHz each, 192 chunks) and the FIFO reset.
/// simavr has no MPU-9150 to measure; this is what that traffic takes.
const MPU_RESET: Duration = Duration::from_millis(110);
const MPU_DMP_LOAD: Duration = Duration::from_millis(900);
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

    pub(super) fn targets(&self) -> [i32; 3] {
        self.target
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
}
