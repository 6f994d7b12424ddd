//! Stopping end to end: the built `neptunus` binary on a board emulator's
//! pty, a bare UDP ground station, and the two ways the thrusters must stop
//! when something dies.
//!
//! - Neptunus itself freezes (`kill -STOP`): nothing feeds the board's
//!   dead-man any more, and the *board* stops the thrusters on its own.
//! - The owner ground station goes silent while Neptunus runs on: the GCS
//!   failsafe disarms the vehicle, which commands neutral thrust.
//!
//! And one thing that must never stop it: a log nobody reads.
//!
//! Time is real (a child process, a real tty), so every wait polls a
//! condition against a generous deadline; how fast the vehicle reacts is
//! measured by `benches/failsafe.rs`, not asserted here.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::Path;
use std::time::{Duration, Instant};

use common::{NEUTRAL_GO, NEUTRAL_US, Rig, Traffic};
use neptunus::dialect::neptunus::*;
use nix::sys::signal::Signal;

/// Full forward: the board's motors leave neutral.
const FORWARD: i16 = 1000;
const GENEROUS: Duration = Duration::from_secs(15);

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

#[test]
fn a_stopped_neptunus_is_caught_by_the_boards_dead_man() {
    let mut rig = Rig::start(bin(), "").unwrap();
    rig.arm_and_drive(FORWARD).unwrap();
    let before = rig.snapshot();
    assert!(
        before.dead_man_armed,
        "the handshake arms the dead-man: {before:?}"
    );

    // Running normally, with the owner alive, Neptunus keeps the dead-man
    // fed: drive on through three pings (more than the board's 2 s timeout)
    // and watch that it never trips.
    let Rig {
        vehicle,
        gcs,
        board,
        executed,
        ..
    } = &mut rig;
    let control = board.control();
    let mut pings = 0;
    let mut tripped_while_running = None;
    let fed = gcs
        .run_until(vehicle, Traffic::Drive(FORWARD), GENEROUS, |_| {
            pings += executed.try_iter().filter(|(_, c)| c == "ping(0)").count();
            let s = control.snapshot();
            if s.dead_man_tripped || s.motors_us == NEUTRAL_US {
                tripped_while_running.get_or_insert(s);
            }
            pings >= 3
        })
        .unwrap();
    assert!(fed, "only {pings} ping() in {GENEROUS:?} while driving");
    assert_eq!(
        tripped_while_running, None,
        "the dead-man tripped (or the motors stopped) while neptunus ran and the GCS drove"
    );

    vehicle.signal(Signal::SIGSTOP).unwrap();
    let stopped_at = Instant::now();
    let pid = vehicle.pid();
    let frozen = gcs
        .run_until(vehicle, Traffic::Drive(FORWARD), GENEROUS, |_| {
            common::proc_state(pid) == Some('T')
        })
        .unwrap();
    assert!(frozen, "neptunus never showed state T after SIGSTOP");

    // The ground station is fine and keeps driving; only neptunus is frozen.
    let mut last = control.snapshot();
    let stopped = gcs
        .run_until(vehicle, Traffic::Drive(FORWARD), GENEROUS, |_| {
            last = control.snapshot();
            last.dead_man_tripped && last.motors_us == NEUTRAL_US
        })
        .unwrap();
    assert!(
        stopped,
        "{GENEROUS:?} after SIGSTOP the board still drives: {last:?}"
    );
    assert_eq!(
        last.target_us, NEUTRAL_US,
        "the dead-man zeroes the targets"
    );
    eprintln!(
        "dead-man tripped {:.2} s after SIGSTOP",
        stopped_at.elapsed().as_secs_f64()
    );
    // Dropping the rig continues and then ends the stopped child.
}

#[test]
fn a_silent_owner_gcs_disarms_the_vehicle_and_the_board_goes_neutral() {
    // The pilot-input failsafe off, so only the GCS failsafe can act.
    let mut rig = Rig::start(bin(), "FS_GCS_TIMEOUT = 2.0\nFS_PILOT_INPUT = 0\n").unwrap();
    let Rig { vehicle, gcs, .. } = &mut rig;
    assert_eq!(gcs.param(vehicle, "FS_GCS_TIMEOUT").unwrap(), 2.0);
    assert_eq!(gcs.param(vehicle, "FS_PILOT_INPUT").unwrap(), 0.0);
    rig.arm_and_drive(FORWARD).unwrap();

    let Rig {
        vehicle,
        gcs,
        board,
        executed,
        ..
    } = &mut rig;
    let control = board.control();
    // Driving with a live GCS: armed, and no failsafe.
    let mut texts = Vec::new();
    let armed = gcs
        .run_until(vehicle, Traffic::Drive(FORWARD), GENEROUS, |msgs| {
            for m in msgs {
                if let MavMessage::STATUSTEXT(s) = m {
                    texts.push(common::statustext(s));
                }
            }
            msgs.iter()
                .any(|m| matches!(m, MavMessage::HEARTBEAT(h) if common::armed(h)))
        })
        .unwrap();
    assert!(armed, "no armed HEARTBEAT while driving");
    assert!(
        !texts.iter().any(|t| t.starts_with("Failsafe")),
        "a failsafe while the GCS was alive: {texts:?}"
    );

    // The owner goes silent.
    let last_life = gcs.last_life.expect("we sent heartbeats and sticks");
    let _ = executed.try_iter().count();
    let mut failsafe_text_at = None;
    let mut disarmed_heartbeat = None;
    let mut neutral_go_at = None;
    let mut texts = Vec::new();
    let done = gcs
        .run_until(vehicle, Traffic::Silent, GENEROUS, |msgs| {
            for m in msgs {
                match m {
                    MavMessage::STATUSTEXT(s) => {
                        let t = common::statustext(s);
                        if t.starts_with("Failsafe: GCS 255 heartbeat lost") {
                            failsafe_text_at.get_or_insert_with(Instant::now);
                        }
                        texts.push(t);
                    }
                    MavMessage::HEARTBEAT(h) if !common::armed(h) => {
                        disarmed_heartbeat.get_or_insert_with(|| h.clone());
                    }
                    _ => {}
                }
            }
            for (at, cmd) in executed.try_iter() {
                if cmd == NEUTRAL_GO && at > last_life {
                    neutral_go_at.get_or_insert(at);
                }
            }
            failsafe_text_at.is_some()
                && disarmed_heartbeat.is_some()
                && neutral_go_at.is_some()
                && control.snapshot().motors_us == NEUTRAL_US
        })
        .unwrap();
    assert!(
        done,
        "{GENEROUS:?} after the GCS went silent: failsafe STATUSTEXT {failsafe_text_at:?}, \
         disarmed HEARTBEAT {disarmed_heartbeat:?}, neutral go() {neutral_go_at:?}, \
         board {:?}; texts {texts:?}",
        control.snapshot()
    );
    let failsafe_after = failsafe_text_at.unwrap() - last_life;
    // A lower bound cannot flake: the vehicle heard our last message after
    // we sent it, and must then wait FS_GCS_TIMEOUT.
    assert!(
        failsafe_after >= Duration::from_secs(2),
        "the failsafe fired {failsafe_after:?} after our last message, before FS_GCS_TIMEOUT 2 s"
    );
    // The active failsafe shows in the heartbeat. Today the GCS failsafe
    // stays raised after its disarm until a station owns the vehicle again;
    // the spec's table also lists "disarmed" as clearing it, and a core that
    // cleared it on the tick after the disarm would make this heartbeat
    // STANDBY: then this check needs the spec settled first.
    let hb = disarmed_heartbeat.unwrap();
    assert_eq!(
        hb.system_status,
        MavState::MAV_STATE_CRITICAL,
        "after the GCS failsafe: {hb:?}"
    );
    eprintln!(
        "failsafe STATUSTEXT {:.3} s, neutral go() at the board {:.3} s after our last message",
        failsafe_after.as_secs_f64(),
        (neutral_go_at.unwrap() - last_life).as_secs_f64()
    );
}

/// A pipe whose buffer is already full: whoever writes to its write end
/// blocks until someone reads — a stderr that a stalled journal, or a
/// terminal nobody scrolls, has stopped taking.
fn full_pipe() -> (std::os::fd::OwnedFd, std::os::fd::OwnedFd) {
    use nix::fcntl::{FcntlArg, OFlag, fcntl};
    let (read, write) = nix::unistd::pipe().unwrap();
    let flags = OFlag::from_bits_truncate(fcntl(&write, FcntlArg::F_GETFL).unwrap());
    fcntl(&write, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK)).unwrap();
    let chunk = [b'#'; 4096];
    let mut filled = 0;
    loop {
        match nix::unistd::write(&write, &chunk) {
            Ok(n) => filled += n,
            Err(nix::errno::Errno::EAGAIN) => break,
            Err(e) => panic!("filling the pipe: {e}"),
        }
    }
    assert!(filled > 0, "the pipe took nothing");
    // The child must block on it, not be told EAGAIN: the flag belongs to
    // the open pipe, which the child shares.
    fcntl(&write, FcntlArg::F_SETFL(flags)).unwrap();
    (read, write)
}

#[test]
fn a_log_nobody_reads_never_stops_the_vehicle() {
    // Its stderr full from the first line, and logging at info: every line
    // the vehicle logs would block a writer that writes in place.
    let (read, write) = full_pipe();
    let mut rig = Rig::start_with(
        bin(),
        "",
        &[("RUST_LOG", "info")],
        Some(std::process::Stdio::from(write)),
    )
    .unwrap();
    // Up, armed (logged) and driving: the board's motors leave neutral.
    rig.arm_and_drive(FORWARD).unwrap();
    let Rig {
        vehicle,
        gcs,
        board,
        ..
    } = &mut rig;
    let control = board.control();
    // Disarmed (logged again) by command, the board goes neutral.
    let disarm = gcs
        .command(vehicle, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0.0)
        .unwrap();
    assert_eq!(disarm, MavResult::MAV_RESULT_ACCEPTED);
    let neutral = gcs
        .run_until(vehicle, Traffic::Drive(FORWARD), GENEROUS, |_| {
            control.snapshot().motors_us == NEUTRAL_US
        })
        .unwrap();
    assert!(
        neutral,
        "disarmed, the board still drives: {:?}",
        control.snapshot()
    );
    vehicle.check_running().unwrap();
    // Reading the pipe now lets the lines through: they were held, not lost.
    let mut text = Vec::new();
    let mut pipe = std::fs::File::from(read);
    vehicle.signal(Signal::SIGTERM).unwrap();
    std::io::Read::read_to_end(&mut pipe, &mut text).unwrap();
    let text = String::from_utf8_lossy(&text);
    assert!(
        text.contains("starting") && text.contains("armed"),
        "the held log lines did not come out: {}",
        &text[text.len().saturating_sub(2000)..]
    );
}
