//! `neptunus doctor`'s serial checks: the device exists and this user may
//! use it, and a board answers on it in the configured framing.
//!
//! The probe listens, then sends `ping(n)` in the configured framing and, if
//! nothing answers, in the other one; [`judge`] (pure) reads what came back.
//! A crc8 board echoes `crc:pass;` and answers `pong`; it answers a plain
//! frame with `crc:fail`. A plain (December 2014) board answers a plain
//! `ping` with `pong` and cannot parse a crc8 frame. `rcap()` is not sent:
//! the mid-2015 firmware blocks for 5 s on it.
//!
//! A board that answers then gets [`LINE_PINGS`] more pings, and the line's
//! quality is judged ([`judge_line`]): pings unanswered, frames its CRC
//! rejected, lines from it that arrived damaged. A damaged line is a
//! warning with its fix (the vehicle writes again what the board did not
//! take, but a cable that damages bytes wants looking at).

use std::io::{Read as _, Write as _};
use std::path::Path;
use std::time::{Duration, Instant};

use super::Check;
use crate::firmware::codec::{Command, Event, Framing, LineDecoder, encoded};
use crate::firmware::link::LinkConfig;

/// How long the probe listens before pinging (a board prints telemetry at 10 Hz).
const LISTEN: Duration = Duration::from_millis(800);
/// How long it waits for the answer to one ping.
const ANSWER: Duration = Duration::from_millis(1500);
/// The number in the probe's `ping(n)`.
const PING_ARG: u32 = 4242;
/// Pings of the line-quality probe, one every [`LINE_PING_GAP`].
const LINE_PINGS: u32 = 20;
const LINE_PING_GAP: Duration = Duration::from_millis(50);

/// What the line-quality probe saw.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct LineHeard {
    pub pings: u32,
    pub pongs: u32,
    /// `crc:fail` answers: frames the board read damaged.
    pub crc_fails: u32,
    /// Lines from the board, and those that arrived damaged.
    pub lines: u64,
    pub bad_lines: u64,
}

/// The board check of a board that answered, with the line's quality.
pub fn judge_line(answered: Check, line: &LineHeard) -> Check {
    let lost = line.pings.saturating_sub(line.pongs);
    if lost == 0 && line.crc_fails == 0 && line.bad_lines == 0 {
        return Check::pass(
            answered.name,
            format!(
                "{}; the line is clean ({} of {} pings answered, no damaged frame or line)",
                answered.detail, line.pongs, line.pings
            ),
        );
    }
    Check::warn(
        answered.name,
        format!(
            "{}; but the line damages bytes: {lost} of {} pings unanswered, {} frames rejected by the board's CRC, {} of {} lines from the board damaged",
            answered.detail, line.pings, line.crc_fails, line.bad_lines, line.lines
        ),
        "check the cable and connectors between the BeagleBone and the board (a long, wet or loose one damages bytes), their ground, and the baud rate; the vehicle writes again what the board did not take, and the line's quality shows as SYS_STATUS drop_rate_comm and on the page's board pill".to_owned(),
    )
}

/// What the board said in each phase of the probe.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Heard {
    /// Before any ping.
    pub listening: Vec<Event>,
    /// After the ping in the configured framing.
    pub configured: Vec<Event>,
    /// After the ping in the other framing (None: not sent).
    pub other: Option<Vec<Event>>,
}

fn answered(events: &[Event]) -> bool {
    events
        .iter()
        .any(|e| matches!(e, Event::Pong(_) | Event::CrcPass))
}

fn crc_failed(events: &[Event]) -> bool {
    events.iter().any(|e| matches!(e, Event::CrcFail { .. }))
}

fn other(f: Framing) -> Framing {
    match f {
        Framing::Crc8 => Framing::Plain,
        Framing::Plain => Framing::Crc8,
    }
}

/// What the board's answers mean, as a check line.
pub fn judge(dev: &Path, baud: u32, configured: Framing, heard: &Heard) -> Check {
    let name = "board";
    let dev = dev.display();
    let boot = heard
        .listening
        .iter()
        .chain(&heard.configured)
        .any(|e| matches!(e, Event::Boot));
    if answered(&heard.configured) {
        let how = match configured {
            Framing::Crc8 => "crc8 (crc:pass echoed)",
            Framing::Plain => "plain",
        };
        let boot = if boot { ", boot seen" } else { "" };
        return Check::pass(
            name,
            format!("a board answers on {dev}: pong in framing {how}{boot}"),
        );
    }
    let speaks = if configured == Framing::Plain && crc_failed(&heard.configured) {
        Some(Framing::Crc8)
    } else if heard.other.as_deref().is_some_and(answered) {
        Some(other(configured))
    } else {
        None
    };
    if let Some(speaks) = speaks {
        return Check::fail(
            name,
            format!(
                "the board on {dev} speaks {speaks} framing, the configuration says {configured}"
            ),
            format!(
                "set framing = \"{speaks}\" in [board] of the configuration file (or pass --framing {speaks})"
            ),
        );
    }
    let anything = !heard.listening.is_empty()
        || !heard.configured.is_empty()
        || heard.other.as_ref().is_some_and(|o| !o.is_empty());
    if anything {
        Check::fail(
            name,
            format!("something on {dev} sends lines but answers ping in neither framing"),
            format!(
                "check that {dev} is the OpenROV board (not a console or another device) and that it runs the OpenROV 2.x firmware at {baud} baud"
            ),
        )
    } else {
        Check::fail(
            name,
            format!("no answer from a board on {dev} at {baud} baud"),
            "check the board's power and its TX/RX wires (BeagleBone UART1: P9.24 TX, P9.26 RX), that the UART1 overlay is enabled in /boot/uEnv.txt, and the baud rate ([board] baud, 115200)".to_owned(),
        )
    }
}

/// The device check: it exists and this user may read and write it.
pub fn device(cfg: &LinkConfig) -> Check {
    let dev = &cfg.device;
    let name = "serial";
    if !dev.exists() {
        return Check::fail(
            name,
            format!("serial port {} does not exist", dev.display()),
            format!(
                "enable UART1 (BB-UART1 overlay in /boot/uEnv.txt; newer kernels call it /dev/ttyS1) or set [board] serial to the board's device; `ls -l /dev/ttyO* /dev/ttyS*` lists them{}",
                if dev.as_os_str() == "/dev/ttyO1" {
                    " (try /dev/ttyS1)"
                } else {
                    ""
                }
            ),
        );
    }
    use nix::unistd::{AccessFlags, access};
    if let Err(e) = access(dev.as_path(), AccessFlags::R_OK | AccessFlags::W_OK) {
        let user = nix::unistd::User::from_uid(nix::unistd::geteuid())
            .ok()
            .flatten()
            .map_or_else(|| "this user".to_owned(), |u| u.name);
        return Check::fail(
            name,
            format!(
                "serial port {} is not readable and writable by {user}: {e}",
                dev.display()
            ),
            format!(
                "add {user} to the device's group (`sudo adduser {user} dialout`, then log in again), or run as the neptunus service user"
            ),
        );
    }
    Check::pass(
        name,
        format!("{} exists and is readable and writable", dev.display()),
    )
}

/// The board check: open the device and probe it (see the module docs).
pub fn probe(cfg: &LinkConfig) -> Check {
    let mut port = match tokio_serial::new(cfg.device.to_string_lossy(), cfg.baud)
        .timeout(Duration::from_millis(50))
        .open()
    {
        Ok(p) => p,
        Err(e) => {
            return Check::fail(
                "board",
                format!("cannot open {}: {e}", cfg.device.display()),
                "if it is busy, another program holds it — stop the service first (`sudo systemctl stop neptunus`)".to_owned(),
            );
        }
    };
    let mut decoder = LineDecoder::new();
    let mut heard = Heard::default();
    let ping = |port: &mut Box<dyn tokio_serial::SerialPort>, framing: Framing| {
        let _ = port.write_all(&encoded(&Command::Ping(PING_ARG), framing));
        let _ = port.flush();
    };
    heard.listening = read_for(&mut port, &mut decoder, LISTEN, false);
    ping(&mut port, cfg.framing);
    heard.configured = read_for(&mut port, &mut decoder, ANSWER, true);
    if !answered(&heard.configured) && !crc_failed(&heard.configured) {
        ping(&mut port, other(cfg.framing));
        heard.other = Some(read_for(&mut port, &mut decoder, ANSWER, true));
    }
    let check = judge(&cfg.device, cfg.baud, cfg.framing, &heard);
    if !check.ok {
        return check;
    }
    // The line's quality: more pings, what came back.
    let before = decoder.stats().clone();
    let mut line = LineHeard::default();
    for n in 0..LINE_PINGS {
        let _ = port.write_all(&encoded(&Command::Ping(n), cfg.framing));
        let _ = port.flush();
        line.pings += 1;
        let events = read_for(&mut port, &mut decoder, LINE_PING_GAP, false);
        count_line(&events, &mut line);
    }
    count_line(
        &read_for(&mut port, &mut decoder, ANSWER / 2, false),
        &mut line,
    );
    let after = decoder.stats();
    line.bad_lines = after.rejected_total() - before.rejected_total();
    line.lines = after.lines_accepted - before.lines_accepted + line.bad_lines;
    judge_line(check, &line)
}

/// What `port` says for `d` (until an answer to a ping, if asked).
fn read_for(
    port: &mut Box<dyn tokio_serial::SerialPort>,
    decoder: &mut LineDecoder,
    d: Duration,
    stop_on_answer: bool,
) -> Vec<Event> {
    let mut events = Vec::new();
    let end = Instant::now() + d;
    let mut buf = [0u8; 512];
    while Instant::now() < end {
        match port.read(&mut buf) {
            Ok(n) => decoder.push(&buf[..n], &mut events),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(_) => break,
        }
        if stop_on_answer && answered(&events) {
            break;
        }
    }
    events
}

fn count_line(events: &[Event], line: &mut LineHeard) {
    for e in events {
        match e {
            Event::Pong(_) => line.pongs += 1,
            Event::CrcFail { .. } => line.crc_fails += 1,
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(framing: Framing, heard: &Heard) -> Check {
        judge(Path::new("/dev/ttyO1"), 115_200, framing, heard)
    }

    #[test]
    fn a_crc8_board_passes_and_says_so() {
        let heard = Heard {
            configured: vec![Event::CrcPass, Event::Pong("4242".into())],
            ..Heard::default()
        };
        let c = check(Framing::Crc8, &heard);
        assert!(c.ok && c.detail.contains("crc8"), "{c:?}");
    }

    #[test]
    fn the_other_framing_is_named_in_the_fix() {
        // Plain configured, the crc8 board says crc:fail.
        let heard = Heard {
            configured: vec![Event::CrcFail { calc: 1, got: 2 }],
            ..Heard::default()
        };
        let c = check(Framing::Plain, &heard);
        assert!(
            !c.ok
                && c.fix
                    .as_deref()
                    .unwrap_or("")
                    .contains("framing = \"crc8\"")
        );
        // Crc8 configured, a plain board answers only the plain ping.
        let heard = Heard {
            listening: vec![Event::Boot],
            configured: vec![Event::CmdEcho("?".into())],
            other: Some(vec![Event::Pong("4242".into())]),
        };
        let c = check(Framing::Crc8, &heard);
        assert!(
            !c.ok
                && c.fix
                    .as_deref()
                    .unwrap_or("")
                    .contains("framing = \"plain\"")
        );
    }

    #[test]
    fn a_damaging_line_is_a_warning_with_its_fix_and_a_clean_one_says_so() {
        let answered = || Check::pass("board", "a board answers on /dev/ttyO1");
        let clean = LineHeard {
            pings: 20,
            pongs: 20,
            lines: 40,
            ..LineHeard::default()
        };
        let c = judge_line(answered(), &clean);
        assert!(c.ok && !c.warning && c.detail.contains("clean"), "{c:?}");
        let noisy = LineHeard {
            pings: 20,
            pongs: 18,
            crc_fails: 1,
            lines: 40,
            bad_lines: 3,
        };
        let c = judge_line(answered(), &noisy);
        assert!(c.ok && c.warning, "{c:?}");
        assert!(
            c.detail.contains("2 of 20 pings unanswered")
                && c.detail.contains("1 frames rejected")
                && c.detail.contains("3 of 40 lines"),
            "{c:?}"
        );
        assert!(c.fix.as_deref().unwrap_or("").contains("cable"), "{c:?}");
    }

    #[test]
    fn silence_and_strangers_fail_with_their_fix() {
        let c = check(Framing::Crc8, &Heard::default());
        assert!(
            !c.ok && c.fix.as_deref().unwrap_or("").contains("P9.24"),
            "{c:?}"
        );
        let heard = Heard {
            listening: vec![Event::Log("login:".into())],
            other: Some(Vec::new()),
            ..Heard::default()
        };
        let c = check(Framing::Crc8, &heard);
        assert!(!c.ok && c.detail.contains("neither framing"), "{c:?}");
    }
}
