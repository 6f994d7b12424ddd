//! The genuine OpenROV firmware 30.0.2 reading the sensors on its I2C bus:
//! the MS5803-14BA depth sensor (`src/hil/ms5803.rs`) with a depth and
//! water temperature the runner is given, the firmware's own code working
//! `deap`, `pres` and `temp` out of the raw readings; and the BNO055 IMU
//! (`src/hil/bno055.rs`) with an attitude, the firmware printing `hdgd`,
//! `pitc`, `roll` and `yaw` from its Euler registers. No Neptunus here: the
//! test reads the board's UART as the BeagleBone would.
//!
//! Waiting is counted in the firmware's own output (its `pres:` line comes
//! once a second of simulated time, its sensor read once a second too; its
//! navigation line ten times a second, its IMU read 21 times), so a slow
//! machine that runs the simulator below real time does not change what is
//! asserted.
#![cfg(feature = "hil")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::Path;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use neptunus::hil::bno055::firmware_reading;
use neptunus::hil::ms5803::Prom;
use neptunus::hil::{
    Attitude, Firmware, GenuineBoard, GenuineControl, SerialChunk, Water, Wiring, prepare,
};

/// Only a guard against a hung simulator: nothing is judged by wall time.
const WAIT: Duration = Duration::from_secs(60);
const DEPTH_TOL_M: f64 = 0.05;
const PRES_TOL_MBAR: f64 = 2.0;
const TEMP_TOL_C: f64 = 0.1;
const I2C_FAILURE: &str = "log:Failed to read Depth from I2C";
/// Printed with two decimals from 1/16° steps: 0.04° at most, when right.
const ATTITUDE_TOL_DEG: f64 = 0.5;

/// One simulated board at a time: simavr paced to real time takes a good
/// share of a core.
static ONE_BOARD: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_board() -> std::sync::MutexGuard<'static, ()> {
    ONE_BOARD
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn firmware_30_0_2() -> Firmware {
    let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("openrov-firmware");
    prepare(&common::firmware_dir("30.0.2"), &cache)
        .unwrap_or_else(|e| panic!("building the 30.0.2 firmware: {e}"))
}

/// The board's output as `name:value` fields (each ended by `;`), and
/// everything it printed, for the failure check.
struct Uart {
    rx: Receiver<SerialChunk>,
    partial: String,
    fields: std::collections::VecDeque<String>,
    all: String,
}

impl Uart {
    fn new(rx: Receiver<SerialChunk>) -> Self {
        Self {
            rx,
            partial: String::new(),
            fields: Default::default(),
            all: String::new(),
        }
    }

    fn take(&mut self, chunk: SerialChunk) {
        if chunk.to_board {
            return;
        }
        let text = String::from_utf8_lossy(&chunk.bytes);
        self.all.push_str(&text);
        for c in text.chars() {
            match c {
                ';' => self
                    .fields
                    .push_back(std::mem::take(&mut self.partial).trim().to_owned()),
                '\r' | '\n' => self.partial.clear(),
                c => self.partial.push(c),
            }
        }
    }

    /// The next field, waiting for the board to print it.
    fn field(&mut self) -> String {
        let deadline = Instant::now() + WAIT;
        loop {
            if let Some(f) = self.fields.pop_front() {
                return f;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(chunk) => self.take(chunk),
                Err(RecvTimeoutError::Timeout) => panic!("the board printed nothing for {WAIT:?}"),
                Err(RecvTimeoutError::Disconnected) => panic!("the board stopped"),
            }
        }
    }

    /// The value of the next `name:` field.
    fn next(&mut self, name: &str) -> String {
        loop {
            let f = self.field();
            if let Some(v) = f.strip_prefix(name).and_then(|r| r.strip_prefix(':')) {
                return v.to_owned();
            }
        }
    }

    fn next_f64(&mut self, name: &str) -> f64 {
        let v = self.next(name);
        v.parse()
            .unwrap_or_else(|_| panic!("{name}:{v} is not a number"))
    }

    /// Forgets what the board printed so far (still kept in `all`).
    fn drain(&mut self) {
        while let Ok(chunk) = self.rx.try_recv() {
            self.take(chunk);
        }
        self.fields.clear();
        self.partial.clear();
    }
}

/// What the firmware printed once it had read the sensor in `water`.
#[derive(Debug)]
struct Reading {
    deap_m: Vec<f64>,
    pres_mbar: f64,
    temp_c: f64,
}

/// Gives the sensor `water`, waits until the firmware has read it, and
/// returns what it printed.
fn read_at(control: &GenuineControl, uart: &mut Uart, water: Water) -> Reading {
    control.set_water(water);
    // The runner shows the water once it has applied it.
    while control.snapshot().water != water {
        let _ = uart.field();
    }
    uart.drain();
    // From here on every sensor read is in the new water. The next read is
    // at most a second (and two 10 ms conversions) away, the `pres:` line
    // comes once a second: the third one is surely from the new read.
    for _ in 0..2 {
        uart.next("pres");
    }
    let pres_mbar = uart.next_f64("pres");
    let temp_c = uart.next_f64("temp");
    let deap_m = (0..3).map(|_| uart.next_f64("deap")).collect();
    Reading {
        deap_m,
        pres_mbar,
        temp_c,
    }
}

#[test]
fn genuine_firmware_reads_depth_pressure_and_temperature() {
    let _one = one_board();
    // The IMU is on the bus too, as on a ROV with both add-ons.
    let board = GenuineBoard::spawn(firmware_30_0_2(), Wiring::default(), None)
        .expect("simavr runs the firmware");
    let control = board.control();
    let mut uart = Uart::new(control.serial());

    // At set-up the firmware reads the PROM and prints C0..C7.
    let prom = Prom::typical();
    for (i, word) in prom.0.iter().enumerate() {
        let got = uart.next(&format!("Depth.C{i}"));
        assert_eq!(got, word.to_string(), "PROM word {i}");
    }

    let steps = [(0.0, 15.0), (2.0, 11.5), (5.5, 8.0)];
    let mut deaps = Vec::new();
    for (depth_m, temp_c) in steps {
        let water = Water {
            depth_m,
            temp_c,
            salt_water: false,
        };
        let r = read_at(&control, &mut uart, water);
        let want_mbar = water.pressure_mbar();
        eprintln!(
            "depth {depth_m:.2} m, {temp_c:.1} °C: deap {:?} m, pres {:.2} mbar (want {want_mbar:.2}), temp {:.2} °C",
            r.deap_m, r.pres_mbar, r.temp_c
        );
        for d in &r.deap_m {
            assert!(
                (d - depth_m).abs() <= DEPTH_TOL_M,
                "deap:{d} at {depth_m} m"
            );
        }
        assert!(
            (r.pres_mbar - want_mbar).abs() <= PRES_TOL_MBAR,
            "pres:{} where {want_mbar:.2} mbar was wanted",
            r.pres_mbar
        );
        assert!(
            (r.temp_c - temp_c).abs() <= TEMP_TOL_C,
            "temp:{} in {temp_c} °C water",
            r.temp_c
        );
        deaps.push(r.deap_m[0]);
    }
    assert!(
        deaps.windows(2).all(|w| w[1] > w[0]),
        "deeper must read deeper: {deaps:?}"
    );
    uart.drain();
    assert!(
        !uart.all.contains(I2C_FAILURE),
        "the firmware could not read its depth sensor:\n{}",
        uart.all
    );
    let snap = control.snapshot();
    eprintln!(
        "simulated {:.1} s, real-time ratio {:.2}, slips {}",
        snap.sim_time_s, snap.realtime_ratio, snap.slips
    );
    assert!(snap.error.is_none(), "{:?}", snap.error);
}

/// `hdgd`, `pitc`, `roll` and `yaw` as the firmware printed them.
#[derive(Debug, Clone, Copy)]
struct Printed {
    hdgd: f64,
    pitc: f64,
    roll: f64,
    yaw: f64,
}

/// The next navigation line's attitude fields (printed in this order).
fn next_attitude(uart: &mut Uart) -> Printed {
    let hdgd = uart.next_f64("hdgd");
    let pitc = uart.next_f64("pitc");
    let roll = uart.next_f64("roll");
    let yaw = uart.next_f64("yaw");
    Printed {
        hdgd,
        pitc,
        roll,
        yaw,
    }
}

/// Gives the IMU `attitude`, waits until the firmware has read it, and
/// returns the next navigation lines.
fn attitude_at(control: &GenuineControl, uart: &mut Uart, attitude: Attitude) -> Vec<Printed> {
    control.set_attitude(attitude);
    while control.snapshot().attitude != attitude {
        let _ = uart.field();
    }
    uart.drain();
    // The first line may have gone out before the next IMU read (every
    // 48 ms); the one after it, 100 ms later, cannot have.
    next_attitude(uart);
    (0..3).map(|_| next_attitude(uart)).collect()
}

/// Angles on a circle: 359.9 and 0.1 are 0.2 apart.
fn angle_off(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

#[test]
fn genuine_firmware_prints_the_attitude_of_its_bno055() {
    let _one = one_board();
    let board = GenuineBoard::spawn(firmware_30_0_2(), Wiring::default(), None)
        .expect("simavr runs the firmware");
    let control = board.control();
    let mut uart = Uart::new(control.serial());

    // Set-up: the MPU9150 is not there, the BNO055 is found and set up;
    // the depth sensor beside it on the bus still answers.
    assert_eq!(uart.next("MPU9150.status"), "Not found");
    assert_eq!(uart.next("Depth.C1"), Prom::typical().0[1].to_string());
    assert_eq!(uart.next("BNO055.IAM_160"), "160");
    let status = loop {
        let s = uart.next("BNO055.status");
        if s != "online" && s.trim() != "step2" {
            break s;
        }
    };
    assert_eq!(status, "initialized", "{}", uart.all);
    assert_eq!(uart.next("BNO055.MODE"), "12", "NDOF");
    assert_eq!(uart.next("BNO055.CALIB_SYS"), "3");
    for sensor in ["acc", "mag", "gyro"] {
        for test in ["selftest", "selftest2"] {
            let line = format!("BNO055.{test}.{sensor}:passed");
            assert!(uart.all.contains(&line), "no {line}:\n{}", uart.all);
        }
    }

    // Set (heading, pitch, roll) → printed (hdgd, pitc, roll); `yaw` is
    // `hdgd` again. Each sign, each axis and the heading's origin shows on
    // its own, headings on both sides of 180 and near 360; a degree read as
    // a radian would be off by a factor of 57. The firmware negates the
    // chip's roll. Combined, the chip rolls before it pitches: those
    // figures come from its heading–roll–pitch decomposition, worked out by
    // hand (src/hil/bno055.rs), not from the aviation angles.
    let cases = [
        ((30.0, 0.0, 0.0), (30.0, 0.0, 0.0)),
        ((200.0, 0.0, 0.0), (200.0, 0.0, 0.0)),
        ((350.0, 15.0, 0.0), (350.0, 15.0, 0.0)),
        ((30.0, -15.0, 0.0), (30.0, -15.0, 0.0)),
        ((200.0, 0.0, 20.0), (200.0, 0.0, -20.0)),
        ((350.0, 0.0, -20.0), (350.0, 0.0, 20.0)),
        ((200.0, 15.0, 20.0), (194.62, 15.92, -19.29)),
        ((30.0, -15.0, -20.0), (24.62, -15.92, 19.29)),
    ];
    for ((heading_deg, pitch_deg, roll_deg), (hdgd, pitc, roll)) in cases {
        let attitude = Attitude {
            heading_deg,
            pitch_deg,
            roll_deg,
        };
        // The module's forward map agrees with the table.
        let model = firmware_reading(&attitude);
        assert!(
            angle_off(model.hdgd_deg, hdgd) < 0.05
                && (model.pitc_deg - pitc).abs() < 0.05
                && (model.roll_deg - roll).abs() < 0.05,
            "{attitude:?}: the model says {model:?}"
        );
        let lines = attitude_at(&control, &mut uart, attitude);
        let whole = |l: &&str| l.starts_with("hdgd:") && l.contains("fthr:") && l.ends_with(';');
        let line = uart.all.lines().rev().find(whole);
        eprintln!(
            "set heading {heading_deg} pitch {pitch_deg} roll {roll_deg}: printed {}",
            line.unwrap_or_default()
        );
        for p in lines {
            assert!(
                angle_off(p.hdgd, hdgd) <= ATTITUDE_TOL_DEG
                    && (p.pitc - pitc).abs() <= ATTITUDE_TOL_DEG
                    && (p.roll - roll).abs() <= ATTITUDE_TOL_DEG
                    && p.yaw == p.hdgd,
                "{attitude:?}: printed {p:?}, want hdgd {hdgd} pitc {pitc} roll {roll}"
            );
        }
    }
    uart.drain();
    for failure in ["BNO055.status:failed", "DIAG:Timeout reading I2c"] {
        assert!(!uart.all.contains(failure), "{failure}:\n{}", uart.all);
    }
    assert!(control.snapshot().error.is_none());
}
