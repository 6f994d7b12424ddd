//! Neptunus against the genuine OpenROV controller-board firmware: the
//! 2015 release 30.0.2 (CRC-8 framing) and the December 2014 snapshot
//! (plain framing), built from source with avr-gcc and run in the simavr
//! AVR simulator at real time behind a pty (`src/hil/`). The vehicle is the
//! real binary, driven by a MAVLink ground station; what the board does is
//! read where an instrument would read it: the ESC and servo pulses on the
//! firmware's pins, the lights' PWM, and the bytes on the serial line.
//!
//! The firmware comes from `$OPENROV_FIRMWARE_DIR`, else from
//! `../shared/openrov-firmware` beside the repository (the user guide's
//! "Hardware in the loop", docs/guide/src/hil.md, says how to get it). Times the firmware decides (its dead-man)
//! are judged in the board's own simulated time, so a busy machine that
//! slows the simulator does not fail them.
#![cfg(feature = "hil")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::Path;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use common::{Gcs, Traffic, Vehicle};
use neptunus::dialect::neptunus::*;
use neptunus::hil::{
    Analog, Attitude, F_CPU_HZ, GenuineBoard, GenuineControl, Output, PinsReport, SerialChunk,
    TimedChange, Wiring, prepare,
};
use nix::sys::signal::Signal;

/// The simulated board's servo neutral is a few microseconds above 1500, and
/// a pulse now and then ends 10–16 µs late while the UART's interrupts hold
/// the Servo library's off (seen when the line is busy): "neutral" is within
/// this. A real command is never that close: the firmware's motor mapping
/// skips a 50 µs deadzone each side.
const NEUTRAL_TOL_US: f64 = 25.0;
/// Off neutral enough to be a command, not jitter.
const MOVED_US: f64 = 40.0;
const WAIT: Duration = Duration::from_secs(15);

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

fn neutral(us: Option<f64>) -> bool {
    us.is_some_and(|u| (u - 1500.0).abs() <= NEUTRAL_TOL_US)
}

/// The board's figures as Neptunus logs them every 5 s: (rejected lines,
/// CRC failures echoed), from the newest summary line.
fn link_figures(vehicle: &Vehicle) -> Option<(u64, u64)> {
    let text = strip_ansi(&vehicle.stderr_text());
    let line = text.lines().rev().find(|l| l.contains("crc_fail="))?;
    let field = |name: &str| -> Option<u64> {
        let at = line.find(name)? + name.len();
        let digits: String = line[at..]
            .chars()
            .skip_while(|c| !c.is_ascii_digit())
            .take_while(char::is_ascii_digit)
            .collect();
        digits.parse().ok()
    };
    Some((field("rejected=")?, field("crc_fail=")?))
}

/// The log without its terminal colour codes (`ESC [ … m`).
fn strip_ansi(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for c in chars.by_ref() {
                if c.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

struct GenuineRig {
    vehicle: Vehicle,
    gcs: Gcs,
    control: GenuineControl,
    /// Every byte on the serial line since the board was powered.
    serial: Receiver<SerialChunk>,
    from_board: Vec<u8>,
    changes: Receiver<TimedChange>,
    texts: Vec<String>,
    powered_at: Instant,
    board: GenuineBoard,
    _dir: tempfile::TempDir,
}

impl GenuineRig {
    /// Powers the genuine board `version` with 12.0 V on its battery input
    /// (and, if `add_ons`, the depth sensor and the IMU on its I2C bus, the
    /// vehicle heading south-west, a little bow-up and port side down, so
    /// that every attitude field has a sign and `yaw` is past 180), then
    /// starts `neptunus --serial <its pty>`.
    fn start(version: &str, add_ons: bool) -> Self {
        Self::start_on(bin(), version, add_ons)
    }

    /// As [`Self::start`], with `vehicle` as the program that runs
    /// Neptunus (the armhf build's qemu-arm launcher).
    fn start_on(vehicle: &Path, version: &str, add_ons: bool) -> Self {
        let cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("openrov-firmware");
        let firmware = prepare(&common::firmware_dir(version), &cache)
            .unwrap_or_else(|e| panic!("building the {version} firmware: {e}"));
        let framing = firmware.framing.to_string();
        let analog = Analog {
            battery_v: 12.0,
            battery_current_a: [0.4, 0.3],
            ..Analog::default()
        };
        let wiring = Wiring {
            analog,
            depth_sensor: add_ons,
            imu: add_ons,
        };
        let board = GenuineBoard::spawn(firmware, wiring, None).expect("simavr runs the firmware");
        board.control().set_attitude(Attitude {
            heading_deg: 225.0,
            pitch_deg: 4.0,
            roll_deg: -3.0,
        });
        let powered_at = Instant::now();
        let control = board.control();
        let serial = control.serial();
        let changes = control.changes();
        let dir = tempfile::tempdir().unwrap();
        let (mut gcs, port) = Gcs::bind().unwrap();
        let device = board.path().to_string_lossy().into_owned();
        let endpoint = format!("udpout:127.0.0.1:{port}");
        let mut vehicle = Vehicle::spawn_env(
            vehicle,
            &[
                "--serial",
                &device,
                "--framing",
                &framing,
                "--mavlink",
                &endpoint,
            ],
            dir.path(),
            "",
            &[(
                "RUST_LOG",
                "warn,neptunus::app::vehicle_task=info,neptunus::firmware::codec=debug",
            )],
        )
        .unwrap();
        gcs.await_vehicle(&mut vehicle, Duration::from_secs(30))
            .unwrap();
        Self {
            vehicle,
            gcs,
            control,
            serial,
            from_board: Vec::new(),
            changes,
            texts: Vec::new(),
            powered_at,
            board,
            _dir: dir,
        }
    }

    fn pins(&self) -> PinsReport {
        self.control.snapshot().pins
    }

    /// Sends `traffic` until `done(pins)` holds (collecting STATUSTEXTs), or panics.
    fn until(&mut self, traffic: Traffic, what: &str, done: impl Fn(&PinsReport) -> bool) {
        let control = self.control.clone();
        let texts = &mut self.texts;
        let ok = self
            .gcs
            .run_until(&mut self.vehicle, traffic, WAIT, |msgs| {
                collect_texts(msgs, texts);
                done(&control.snapshot().pins)
            })
            .unwrap();
        assert!(
            ok,
            "{what}: not within {WAIT:?}; pins {:?}\n{}",
            self.pins(),
            self.vehicle.stderr_tail()
        );
    }

    /// Sends `traffic` until a message satisfies `pick`, or panics.
    fn until_msg<T>(
        &mut self,
        traffic: Traffic,
        what: &str,
        mut pick: impl FnMut(&MavMessage) -> Option<T>,
    ) -> T {
        let mut found = None;
        let texts = &mut self.texts;
        self.gcs
            .run_until(&mut self.vehicle, traffic, WAIT, |msgs| {
                collect_texts(msgs, texts);
                found = msgs.iter().find_map(&mut pick);
                found.is_some()
            })
            .unwrap();
        found.unwrap_or_else(|| {
            panic!(
                "{what}: not within {WAIT:?}\n{}",
                self.vehicle.stderr_tail()
            )
        })
    }

    fn armed(&mut self, traffic: Traffic) -> bool {
        self.until_msg(traffic, "a HEARTBEAT", |m| match m {
            MavMessage::HEARTBEAT(h) => Some(common::armed(h)),
            _ => None,
        })
    }

    /// Bytes Neptunus wrote to the board before the board printed its
    /// `boot:1;` (the end of its set-up), waiting for that line up to
    /// `WAIT`. Reads the serial tap from the start: call it first.
    fn written_before_boot(&mut self) -> usize {
        let end = Instant::now() + WAIT;
        let mut written = 0;
        while Instant::now() < end {
            for chunk in self.serial.try_iter() {
                if chunk.to_board {
                    if !self.from_board.windows(7).any(|w| w == b"boot:1;") {
                        written += chunk.bytes.len();
                    }
                } else {
                    self.from_board.extend(chunk.bytes);
                }
            }
            if self.from_board.windows(7).any(|w| w == b"boot:1;") {
                return written;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        panic!(
            "the board printed no boot:1; within {WAIT:?}:\n{}",
            String::from_utf8_lossy(&self.from_board)
        );
    }

    /// The serial traffic not read yet, one chunk a line, stamped in
    /// seconds from `t0` (for a failure's message).
    fn serial_since(&self, t0: Instant) -> String {
        self.serial
            .try_iter()
            .map(|c| {
                format!(
                    "{:>6.3} s {} {}\n",
                    c.at.saturating_duration_since(t0).as_secs_f64(),
                    if c.to_board { "→" } else { "←" },
                    String::from_utf8_lossy(&c.bytes).escape_debug()
                )
            })
            .collect()
    }

    fn board_output(&mut self) -> String {
        for chunk in self.serial.try_iter() {
            if !chunk.to_board {
                self.from_board.extend(chunk.bytes);
            }
        }
        String::from_utf8_lossy(&self.from_board).into_owned()
    }

    fn set_servo(&mut self, servo: f32, pwm: f32) {
        let r = self
            .gcs
            .command_with(
                &mut self.vehicle,
                MavCmd::MAV_CMD_DO_SET_SERVO,
                [servo, pwm, 0.0, 0.0, 0.0, 0.0, 0.0],
            )
            .unwrap();
        assert_eq!(
            r,
            MavResult::MAV_RESULT_ACCEPTED,
            "DO_SET_SERVO {servo} {pwm}"
        );
    }

    /// Waits for a newer 5-s summary line and returns its figures.
    fn next_figures(&mut self) -> (u64, u64) {
        let lines = |v: &Vehicle| strip_ansi(&v.stderr_text()).matches("crc_fail=").count();
        let before = lines(&self.vehicle);
        let end = Instant::now() + Duration::from_secs(12);
        while lines(&self.vehicle) == before && Instant::now() < end {
            let texts = &mut self.texts;
            self.gcs
                .run_until(
                    &mut self.vehicle,
                    Traffic::Heartbeats,
                    Duration::from_millis(500),
                    |m| {
                        collect_texts(m, texts);
                        false
                    },
                )
                .unwrap();
        }
        assert!(
            lines(&self.vehicle) > before,
            "no summary line in 12 s:\n{}",
            self.vehicle.stderr_tail()
        );
        link_figures(&self.vehicle).expect("a summary line with the link's figures")
    }
}

fn collect_texts(msgs: &[MavMessage], texts: &mut Vec<String>) {
    for m in msgs {
        if let MavMessage::STATUSTEXT(s) = m {
            texts.push(common::statustext(s));
        }
    }
}

/// Port thrust is forward when its pulse is below neutral: the port
/// thruster is wired reversed (MOT_2_DIRECTION −1), as on Neptunus.
fn port_forward(p: &PinsReport) -> f64 {
    1500.0 - p.esc_us[0].unwrap_or(1500.0)
}
fn starboard_forward(p: &PinsReport) -> f64 {
    p.esc_us[2].unwrap_or(1500.0) - 1500.0
}

/// Link up, battery, arming, the three thrusters, lights and tilt through
/// the genuine firmware's own pins.
fn drives_the_board(rig: &mut GenuineRig, version: &str) {
    // The link comes up once, soon after the board's reset.
    let up = rig.until_msg(Traffic::Heartbeats, "the board link up", |m| match m {
        MavMessage::SYS_STATUS(s)
            if s.onboard_control_sensors_health
                .contains(MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS) =>
        {
            Some(Instant::now())
        }
        _ => None,
    });
    let after = up.duration_since(rig.powered_at);
    eprintln!(
        "{version}: board link up {:.1} s after the board's reset",
        after.as_secs_f64()
    );
    assert!(
        after < Duration::from_secs(20),
        "link up only after {after:?}"
    );
    // The battery voltage from the board's own divider arithmetic.
    let mv = rig.until_msg(
        Traffic::Heartbeats,
        "a voltage in SYS_STATUS",
        |m| match m {
            MavMessage::SYS_STATUS(s) if s.voltage_battery != u16::MAX => Some(s.voltage_battery),
            _ => None,
        },
    );
    assert!(
        (f64::from(mv) / 1000.0 - 12.0).abs() <= 0.2,
        "SYS_STATUS says {mv} mV for 12.0 V on the board"
    );
    // A normal arm: the pre-arm checks pass on the genuine board's lines.
    rig.gcs.arm(&mut rig.vehicle).unwrap();
    assert!(rig.armed(Traffic::Heartbeats));

    rig.until(
        Traffic::Sticks {
            x: 700,
            z: 500,
            r: 0,
        },
        "forward",
        |p| port_forward(p) > MOVED_US && starboard_forward(p) > MOVED_US && neutral(p.esc_us[1]),
    );
    rig.until(Traffic::Sticks { x: 0, z: 150, r: 0 }, "dive", |p| {
        // Heave down is a vertical pulse above neutral (MOT_3_DIRECTION 1).
        p.esc_us[1].is_some_and(|v| v - 1500.0 > MOVED_US)
            && neutral(p.esc_us[0])
            && neutral(p.esc_us[2])
    });
    rig.until(
        Traffic::Sticks {
            x: 0,
            z: 500,
            r: 700,
        },
        "yaw",
        |p| port_forward(p) > MOVED_US && starboard_forward(p) < -MOVED_US && neutral(p.esc_us[1]),
    );
    rig.until(
        Traffic::Sticks { x: 0, z: 500, r: 0 },
        "sticks released",
        |p| p.esc_us.iter().all(|u| neutral(*u)),
    );
    // Lights (SERVO7, lights1) and the camera tilt (SERVO8) on their pins.
    let lights_before = rig.pins().lights_duty;
    rig.set_servo(7.0, 1900.0);
    rig.until(Traffic::Heartbeats, "lights on", |p| p.lights_duty > 0.9);
    rig.set_servo(7.0, 1500.0);
    rig.until(Traffic::Heartbeats, "lights dimmed", |p| {
        (0.3..0.7).contains(&p.lights_duty)
    });
    assert!(
        lights_before < 0.1,
        "lights were on at start: {lights_before}"
    );
    rig.set_servo(8.0, 1800.0);
    rig.until(Traffic::Heartbeats, "tilt", |p| {
        p.tilt_us.is_some_and(|t| (t - 1800.0).abs() < 10.0)
    });
    assert!(
        !rig.texts
            .iter()
            .any(|t| t.contains("link down") || t.contains("link lost")),
        "a board-link failsafe while the board ran: {:?}",
        rig.texts
    );
}

/// Neptunus frozen while driving: the firmware's own dead-man stops the
/// ESCs (judged in board time), and Neptunus, back, does not drive on.
fn dead_man_stops_a_frozen_vehicle(rig: &mut GenuineRig) {
    rig.gcs.arm(&mut rig.vehicle).unwrap();
    rig.until(
        Traffic::Sticks {
            x: 700,
            z: 500,
            r: 0,
        },
        "forward before the stop",
        |p| port_forward(p) > MOVED_US,
    );
    for _ in rig.changes.try_iter() {}
    let _ = rig.board_output();
    rig.vehicle.signal(Signal::SIGSTOP).unwrap();
    let stopped_board_s = rig.control.snapshot().sim_time_s;
    let stopped_wall = Instant::now();
    let mut neutral_at = None;
    // Each ESC's width as its own pin changes say (the snapshot of the
    // others may not have measured their next pulse yet at one's change).
    let mut widths = rig.pins().esc_us;
    while neutral_at.is_none() && stopped_wall.elapsed() < WAIT {
        rig.gcs
            .pump(Traffic::Sticks {
                x: 700,
                z: 500,
                r: 0,
            })
            .unwrap();
        let _ = rig.gcs.recv();
        for c in rig.changes.try_iter() {
            let slot = match c.change.output {
                Output::EscPort => 0,
                Output::EscVertical => 1,
                Output::EscStarboard => 2,
                Output::Tilt => continue,
            };
            widths[slot] = c.change.to_us;
            if neutral_at.is_none() && widths.iter().all(|u| neutral(*u)) {
                neutral_at = Some(c.change.cycle);
            }
        }
    }
    // The serial traffic from the stop on, for a failure's message.
    let traffic = rig.serial_since(stopped_wall);
    let cycle = neutral_at.unwrap_or_else(|| {
        panic!("the board's dead-man never brought the ESCs to neutral:\n{traffic}")
    });
    let board_s = cycle as f64 / F_CPU_HZ as f64 - stopped_board_s;
    eprintln!(
        "dead-man: ESCs neutral {board_s:.2} s (board time) after neptunus stopped ({:.2} s wall)",
        stopped_wall.elapsed().as_secs_f64()
    );
    assert!(
        board_s < 3.0,
        "ESCs neutral only {board_s:.2} s after the stop; the serial line since:\n{traffic}"
    );
    rig.vehicle.signal(Signal::SIGCONT).unwrap();
    let resumed_wall = Instant::now();
    // Back, the vehicle is disarmed and the board stays neutral although
    // the station still sends forward stick.
    let armed = rig.until_msg(
        Traffic::Sticks {
            x: 700,
            z: 500,
            r: 0,
        },
        "disarmed",
        |m| match m {
            MavMessage::HEARTBEAT(h) if !common::armed(h) => Some(false),
            _ => None,
        },
    );
    assert!(!armed);
    let end = Instant::now() + Duration::from_secs(3);
    while Instant::now() < end {
        rig.gcs
            .pump(Traffic::Sticks {
                x: 700,
                z: 500,
                r: 0,
            })
            .unwrap();
        let _ = rig.gcs.recv();
        let p = rig.pins();
        if !p.esc_us.iter().all(|u| neutral(*u) || u.is_none()) {
            std::thread::sleep(Duration::from_millis(300));
            // From the stop on: what the board read and said while the
            // vehicle stood still tells a stale command from a new one.
            let traffic = rig.serial_since(stopped_wall);
            let resumed_s = resumed_wall.duration_since(stopped_wall).as_secs_f64();
            panic!(
                "the board drove again after the stall without a new arm: {p:?}\nthe serial line since the vehicle was stopped (resumed at {resumed_s:.3} s):\n{traffic}\n{}",
                strip_ansi(&rig.vehicle.stderr_tail())
            );
        }
    }
    // Arming again is the way back.
    rig.gcs.arm(&mut rig.vehicle).unwrap();
    rig.until(
        Traffic::Sticks {
            x: 700,
            z: 500,
            r: 0,
        },
        "forward after re-arming",
        |p| port_forward(p) > MOVED_US,
    );
    rig.until(Traffic::Sticks { x: 0, z: 500, r: 0 }, "released", |p| {
        p.esc_us.iter().all(|u| neutral(*u))
    });
}

/// The board resets while armed and driving: disarmed, neutral, and a
/// normal arm works once the link is back.
fn board_reset_disarms(rig: &mut GenuineRig) {
    rig.gcs.arm(&mut rig.vehicle).unwrap();
    rig.until(
        Traffic::Sticks {
            x: 700,
            z: 500,
            r: 0,
        },
        "forward before the reset",
        |p| port_forward(p) > MOVED_US,
    );
    rig.control.reset();
    let armed = rig.until_msg(
        Traffic::Sticks {
            x: 700,
            z: 500,
            r: 0,
        },
        "disarmed",
        |m| match m {
            MavMessage::HEARTBEAT(h) if !common::armed(h) => Some(false),
            _ => None,
        },
    );
    assert!(!armed);
    rig.until(
        Traffic::Sticks {
            x: 700,
            z: 500,
            r: 0,
        },
        "neutral after the reset",
        |p| p.esc_us.iter().all(|u| neutral(*u)),
    );
    assert!(
        rig.texts
            .iter()
            .any(|t| t.contains("rebooted") || t.contains("link")),
        "no STATUSTEXT said why: {:?}",
        rig.texts
    );
    rig.gcs.arm(&mut rig.vehicle).unwrap();
    rig.until(
        Traffic::Sticks {
            x: 700,
            z: 500,
            r: 0,
        },
        "forward after the reset",
        |p| port_forward(p) > MOVED_US,
    );
    rig.until(Traffic::Sticks { x: 0, z: 500, r: 0 }, "released", |p| {
        p.esc_us.iter().all(|u| neutral(*u))
    });
}

/// A minute of normal running adds no rejected line.
fn steady_running_rejects_nothing(rig: &mut GenuineRig) {
    let (rejected_before, _) = rig.next_figures();
    let end = Instant::now() + Duration::from_secs(60);
    let texts = &mut rig.texts;
    while Instant::now() < end {
        rig.gcs
            .run_until(
                &mut rig.vehicle,
                Traffic::Heartbeats,
                Duration::from_secs(1),
                |m| {
                    collect_texts(m, texts);
                    false
                },
            )
            .unwrap();
    }
    let (rejected_after, _) = rig.next_figures();
    let snap = rig.control.snapshot();
    eprintln!(
        "steady running: {} rejected lines in 60 s; simulator at {:.2}× real time, {:.1}× headroom, {} slips",
        rejected_after - rejected_before,
        snap.realtime_ratio,
        snap.speed_ratio,
        snap.slips
    );
    assert_eq!(
        rejected_after,
        rejected_before,
        "rejected lines in a minute of normal running:\n{}",
        strip_ansi(&rig.vehicle.stderr_text())
            .lines()
            .filter(|l| l.contains("rejected"))
            .collect::<Vec<_>>()
            .join("\n")
    );
}

/// One genuine board at a time: simavr paced to real time takes a good
/// share of a core, and two at once on a small machine slip behind it.
static ONE_BOARD: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_board() -> std::sync::MutexGuard<'static, ()> {
    ONE_BOARD
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

#[test]
fn the_genuine_2015_firmware_arms_drives_and_stops() {
    let _one = one_board();
    // A ROV with the depth and IMU add-ons.
    let mut rig = GenuineRig::start("30.0.2", true);
    // Its sensors' set-up takes longer than the link's boot wait, and it
    // chatters meanwhile: nothing is written to it until it has booted (a
    // frame then would wait unread in its receive buffer).
    let early = rig.written_before_boot();
    assert_eq!(
        early,
        0,
        "{early} bytes written to the board during its set-up; it printed:\n{}",
        rig.board_output()
    );
    drives_the_board(&mut rig, "30.0.2");

    // Corrupted frames on the line: the board reports each, and Neptunus
    // counts exactly the board's reports.
    const BAD: usize = 5;
    for n in 0..BAD {
        let text = format!("ping({n});");
        let mut frame = vec![neptunus::firmware::codec::crc8(text.as_bytes()) ^ 0x5A];
        frame.extend_from_slice(text.as_bytes());
        rig.control.inject(frame);
    }
    let board_reports = |rig: &mut GenuineRig| rig.board_output().matches("crc:fail,").count();
    let mut figures = rig.next_figures();
    for _ in 0..3 {
        if board_reports(&mut rig) >= BAD && figures.1 as usize == board_reports(&mut rig) {
            break;
        }
        figures = rig.next_figures();
    }
    let reported = board_reports(&mut rig);
    assert!(
        reported >= BAD,
        "the board reported {reported} CRC failures for {BAD} bad frames"
    );
    assert_eq!(
        figures.1 as usize, reported,
        "Neptunus counted {} CRC failures, the board reported {reported}",
        figures.1
    );

    steady_running_rejects_nothing(&mut rig);
    dead_man_stops_a_frozen_vehicle(&mut rig);
    board_reset_disarms(&mut rig);
    assert_eq!(rig.control.snapshot().error, None);
    drop(rig.board);
}

#[test]
fn the_genuine_2014_firmware_with_plain_framing() {
    let _one = one_board();
    // A basic kit: no depth sensor, the firmware says so once a second.
    let mut rig = GenuineRig::start("2014-12", false);
    assert_eq!(rig.board.firmware().framing.to_string(), "plain");
    drives_the_board(&mut rig, "2014-12");
    steady_running_rejects_nothing(&mut rig);
    dead_man_stops_a_frozen_vehicle(&mut rig);
    board_reset_disarms(&mut rig);
}

/// The BeagleBone's build (armv7-unknown-linux-gnueabihf) as the vehicle,
/// run by Debian 13's `qemu-arm -cpu cortex-a8`: the checks of the 2015
/// firmware's test that a vehicle on the ROV's computer must pass — link
/// up, the battery, a normal arm, the thrusters forward and back to
/// neutral, the firmware's dead-man stop. `tests/armhf.sh` builds the
/// binary and runs this with `NEPTUNUS_ARMHF_BIN` (the binary) and
/// `NEPTUNUS_ARMHF_VEHICLE` (a launcher that execs qemu-arm on it); without
/// them it fails.
#[test]
#[ignore = "needs the armhf build and qemu-arm: tests/armhf.sh runs it"]
fn the_armhf_vehicle_under_qemu_drives_the_genuine_2015_firmware() {
    let var = |name: &str| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .unwrap_or_else(|| panic!("{name} is not set: tests/armhf.sh runs this test"))
    };
    let arm_bin = var("NEPTUNUS_ARMHF_BIN");
    let launcher = var("NEPTUNUS_ARMHF_VEHICLE");
    // The ELF header: 32-bit, ARM (EM_ARM 40), EABI 5, hard-float.
    let header = std::fs::read(&arm_bin).unwrap_or_else(|e| panic!("{arm_bin:?}: {e}"));
    assert!(
        header.len() > 52 && &header[..4] == b"\x7fELF",
        "{arm_bin:?} is no ELF file"
    );
    let e_machine = u16::from_le_bytes([header[18], header[19]]);
    let e_flags = u32::from_le_bytes([header[36], header[37], header[38], header[39]]);
    assert_eq!(header[4], 1, "{arm_bin:?} is not a 32-bit ELF");
    assert_eq!(e_machine, 40, "{arm_bin:?} is not an ARM program");
    assert_eq!(
        e_flags & 0xff00_0000,
        0x0500_0000,
        "not EABI 5: {e_flags:#x}"
    );
    assert_ne!(
        e_flags & 0x400,
        0,
        "not hard-float (EF_ARM_ABI_FLOAT_HARD): {e_flags:#x}"
    );

    let _one = one_board();
    let mut rig = GenuineRig::start_on(Path::new(&launcher), "30.0.2", true);
    // What runs is the emulator with the ARM program, not a host build.
    let exe = std::fs::read_link(format!("/proc/{}/exe", rig.vehicle.pid())).unwrap();
    assert!(
        exe.file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with("qemu-arm")),
        "the vehicle runs as {exe:?}, not under qemu-arm"
    );
    drives_the_board(&mut rig, "30.0.2, the armhf vehicle under qemu-arm");
    dead_man_stops_a_frozen_vehicle(&mut rig);
    assert_eq!(rig.control.snapshot().error, None);
    drop(rig.board);
}
