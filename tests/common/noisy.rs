//! Stick steps through a damaged serial line: the genuine 30.0.2 firmware
//! in simavr, the project's damaging relay (`neptunus::hil::NoisyRelay`)
//! between it and the vehicle, and a ground station alternating the
//! forward stick between pushed and released. Shared by
//! `tests/genuine_noisy_line.rs` (the behaviour, with deadlines) and
//! `benches/noisy_line.rs` (the figures).
//!
//! Every step is timed twice: on the wall clock (the ground station's
//! send to the ESC pin's change, mapped by the runner) and on the board's
//! own clock (the simulated time when the station sent to the pin's
//! change in simulated cycles). A step counts as *judged* only when the
//! board kept pace through it: no slip of the runner (a fall more than
//! 250 ms behind the wall clock, let go) and at least `MIN_REALTIME` of
//! real time at its end — on a machine so busy that simavr cannot keep
//! real time, the board's loop and UART run slow and no deadline of the
//! vehicle's can be judged by them.

use std::path::Path;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use neptunus::dialect::neptunus::*;
use neptunus::hil::{
    Damage, DamageCount, F_CPU_HZ, GenuineBoard, GenuineControl, NoisyRelay, Output, SerialChunk,
    TimedChange, Wiring, prepare,
};

use crate::common::{self, Gcs, Traffic, Vehicle};

/// The station's forward stick when pushed.
pub const PUSH_X: i16 = 700;
/// Within this of 1500 µs an ESC is at neutral (the simulated servo's
/// jitter; the firmware's deadzone puts any command 50 µs past it).
pub const NEUTRAL_TOL_US: f64 = 25.0;
/// Off neutral enough to be a command.
pub const MOVED_US: f64 = 40.0;
/// Below this share of real time a step is not judged.
pub const MIN_REALTIME: f64 = 0.85;

/// One step: the stick pushed or released.
#[derive(Debug, Clone, Copy)]
pub struct Step {
    pub push: bool,
    /// Station's send → ESC pins as asked, wall clock (None: not within the step).
    pub wall: Option<Duration>,
    /// The same on the board's simulated clock.
    pub board: Option<Duration>,
    /// The board kept pace through the step.
    pub judged: bool,
}

/// What a run saw.
#[derive(Debug, Default)]
pub struct Run {
    pub steps: Vec<Step>,
    /// Times the vehicle said the board link went down.
    pub link_downs: usize,
    /// HEARTBEATs saying disarmed while the run went on (after the arm).
    pub disarmed_heartbeats: usize,
    /// The board's own `icmd:stop()` reports: its dead-man tripped.
    pub dead_man_trips: usize,
    /// The board's `crc:fail` reports (what it printed, before the line).
    pub board_crc_fails: usize,
    pub to_board: DamageCount,
    pub from_board: DamageCount,
    /// STATUSTEXTs of the run, for a failure's message.
    pub texts: Vec<String>,
    pub realtime_min: f64,
    pub slips: u64,
    /// The newest SYS_STATUS's link figures (drop_rate_comm, errors_comm).
    pub comm: Option<(u16, u16)>,
}

/// The genuine board, the relay and the vehicle, armed.
pub struct NoisyRig {
    pub vehicle: Vehicle,
    pub gcs: Gcs,
    pub control: GenuineControl,
    pub relay: NoisyRelay,
    serial: Receiver<SerialChunk>,
    changes: Receiver<TimedChange>,
    from_board: Vec<u8>,
    _board: GenuineBoard,
    _dir: tempfile::TempDir,
}

fn neutral(us: Option<f64>) -> bool {
    us.is_some_and(|u| (u - 1500.0).abs() <= NEUTRAL_TOL_US)
}

/// The ESCs as a push asks (port is wired reversed: forward is below 1500).
fn pushed(w: &[Option<f64>; 3]) -> bool {
    w[0].is_some_and(|u| 1500.0 - u > MOVED_US)
        && w[2].is_some_and(|u| u - 1500.0 > MOVED_US)
        && neutral(w[1])
}

fn released(w: &[Option<f64>; 3]) -> bool {
    w.iter().all(|u| neutral(*u))
}

impl NoisyRig {
    /// Powers the genuine 30.0.2 board, puts the relay with `damage` (each
    /// way, dice seeded with `seed`) in front of it, starts `bin` on the
    /// relay's device and arms.
    pub fn start(
        bin: &Path,
        firmware_dir: &Path,
        cache: &Path,
        damage: Damage,
        seed: u64,
    ) -> anyhow::Result<Self> {
        let firmware = prepare(firmware_dir, cache)?;
        let framing = firmware.framing.to_string();
        let board = GenuineBoard::spawn(firmware, Wiring::default(), None)?;
        let control = board.control();
        let serial = control.serial();
        let changes = control.changes();
        let relay = NoisyRelay::spawn(board.path(), damage, damage, seed)?;
        let dir = tempfile::tempdir()?;
        let (mut gcs, port) = Gcs::bind()?;
        let device = relay.path().to_string_lossy().into_owned();
        let endpoint = format!("udpout:127.0.0.1:{port}");
        let mut vehicle = Vehicle::spawn_env(
            bin,
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
            &[("RUST_LOG", "warn,neptunus::app::vehicle_task=info")],
        )?;
        gcs.await_vehicle(&mut vehicle, Duration::from_secs(30))?;
        gcs.wait_ready(&mut vehicle)?;
        gcs.arm(&mut vehicle)?;
        Ok(Self {
            vehicle,
            gcs,
            control,
            relay,
            serial,
            changes,
            from_board: Vec::new(),
            _board: board,
            _dir: dir,
        })
    }

    /// Steps of `half` each (pushed, released, …) for `duration`, armed.
    pub fn run(&mut self, duration: Duration, half: Duration) -> anyhow::Result<Run> {
        let mut run = Run {
            realtime_min: f64::INFINITY,
            ..Run::default()
        };
        for c in self.serial.try_iter() {
            if !c.to_board {
                self.from_board.extend(c.bytes);
            }
        }
        let reports_at_start = self.board_reports();
        let slips_at_start = self.control.snapshot().slips;
        let mut widths = self.control.snapshot().pins.esc_us;
        for _ in self.changes.try_iter() {}
        let end = Instant::now() + duration;
        let mut push = true;
        let mut was_down = false;
        while Instant::now() < end {
            let x = if push { PUSH_X } else { 0 };
            let traffic = Traffic::Sticks { x, z: 500, r: 0 };
            let before = self.control.snapshot();
            let sent = self.gcs.send(&common::sticks(x, 500, 0))?;
            let sent_board_s = before.sim_time_s;
            let reached = |w: &[Option<f64>; 3]| if push { pushed(w) } else { released(w) };
            let mut step = Step {
                push,
                wall: None,
                board: None,
                judged: false,
            };
            if reached(&widths) {
                step.wall = Some(Duration::ZERO);
                step.board = Some(Duration::ZERO);
            }
            let step_end = sent + half;
            while Instant::now() < step_end {
                self.vehicle.check_running()?;
                self.gcs.pump(traffic)?;
                for m in self.gcs.recv() {
                    match m {
                        MavMessage::HEARTBEAT(h) if !common::armed(&h) => {
                            run.disarmed_heartbeats += 1;
                        }
                        MavMessage::STATUSTEXT(s) => {
                            let t = common::statustext(&s);
                            let down = t.contains("link down") || t.contains("link lost");
                            if down && !was_down {
                                run.link_downs += 1;
                            }
                            was_down = down || (was_down && !t.contains("link up"));
                            run.texts.push(t);
                        }
                        MavMessage::SYS_STATUS(s) => {
                            run.comm = Some((s.drop_rate_comm, s.errors_comm));
                        }
                        _ => {}
                    }
                }
                for c in self.changes.try_iter() {
                    let slot = match c.change.output {
                        Output::EscPort => 0,
                        Output::EscVertical => 1,
                        Output::EscStarboard => 2,
                        Output::Tilt => continue,
                    };
                    widths[slot] = c.change.to_us;
                    if step.wall.is_none() && reached(&widths) {
                        step.wall = Some(c.at.saturating_duration_since(sent));
                        let board_s = c.change.cycle as f64 / F_CPU_HZ as f64 - sent_board_s;
                        step.board = Some(Duration::from_secs_f64(board_s.max(0.0)));
                    }
                }
            }
            let after = self.control.snapshot();
            step.judged = after.slips == before.slips && after.realtime_ratio >= MIN_REALTIME;
            run.realtime_min = run.realtime_min.min(after.realtime_ratio);
            run.steps.push(step);
            push = !push;
        }
        // Back to neutral before the figures are read.
        self.gcs.send(&common::sticks(0, 500, 0))?;
        for c in self.serial.try_iter() {
            if !c.to_board {
                self.from_board.extend(c.bytes);
            }
        }
        let (trips, crc) = self.board_reports();
        run.dead_man_trips = trips - reports_at_start.0;
        run.board_crc_fails = crc - reports_at_start.1;
        let (down, up, _) = self.relay.counts();
        run.to_board = down;
        run.from_board = up;
        run.slips = self.control.snapshot().slips - slips_at_start;
        Ok(run)
    }

    /// (dead-man trips, CRC failures) the board printed so far.
    fn board_reports(&self) -> (usize, usize) {
        let text = String::from_utf8_lossy(&self.from_board);
        (
            text.matches("icmd:stop(").count(),
            text.matches("crc:fail,").count(),
        )
    }
}

/// p-quantile of `v` in ms (nearest rank).
pub fn quantile_ms(v: &[Duration], q: f64) -> Option<f64> {
    let mut v = v.to_vec();
    v.sort();
    if v.is_empty() {
        return None;
    }
    let i = ((v.len() as f64 * q).ceil() as usize).clamp(1, v.len()) - 1;
    Some(v[i].as_secs_f64() * 1000.0)
}
