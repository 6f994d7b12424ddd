//! The board emulator, sans-IO: byte-level behaviour of the 2015 board.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use neptunus::firmware::codec::{Command, Event, Framing, LineDecoder, crc8, encoded};
use neptunus::firmware::emulator::{Board, BoardRecord, EmulatorOptions, FaultOptions};

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

fn booted(opts: EmulatorOptions) -> (Board, Vec<u8>) {
    let mut b = Board::new(opts);
    b.record(true);
    let mut out = Vec::new();
    b.start(Duration::ZERO, &mut out);
    (b, out)
}

fn lines(bytes: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(bytes)
        .split("\r\n")
        .filter(|l| !l.is_empty())
        .map(str::to_owned)
        .collect()
}

fn executed(b: &mut Board) -> Vec<String> {
    b.take_records()
        .into_iter()
        .filter_map(|r| match r {
            BoardRecord::Executed(s) => Some(s),
            BoardRecord::Frame(_) => None,
        })
        .collect()
}

fn send(b: &mut Board, cmd: Command, at: Duration) -> Vec<String> {
    let mut out = Vec::new();
    b.receive(&encoded(&cmd, Framing::Crc8), at, &mut out);
    b.tick(at + ms(1), &mut out);
    lines(&out)
}

#[test]
fn boots_with_boot_line() {
    let (_, out) = booted(EmulatorOptions::default());
    assert_eq!(out, b"boot:1;\r\n");
}

#[test]
fn valid_frame_is_echoed_checked_and_executed() {
    let (mut b, _) = booted(EmulatorOptions::default());
    let out = send(
        &mut b,
        Command::Go {
            port_us: 1600,
            vertical_us: 1500,
            starboard_us: 1400,
        },
        ms(10),
    );
    let frame = encoded(
        &Command::Go {
            port_us: 1600,
            vertical_us: 1500,
            starboard_us: 1400,
        },
        Framing::Crc8,
    );
    let hex: String = frame.iter().map(|x| format!("{x:x},")).collect();
    assert_eq!(out[0], format!("rawcmd:{hex};"));
    assert_eq!(out[1], "crc:pass;");
    assert_eq!(out[2], "cmd:go(1600,1500,1400);");
    assert_eq!(b.snapshot().target_us, [1600, 1500, 1400]);
    assert_eq!(executed(&mut b), vec!["go(1600,1500,1400)".to_owned()]);
}

#[test]
fn bad_crc_is_echoed_and_dropped() {
    let (mut b, _) = booted(EmulatorOptions::default());
    let mut frame = encoded(&Command::Lights(200), Framing::Crc8);
    frame[0] ^= 0x55;
    let mut out = Vec::new();
    b.receive(&frame, ms(5), &mut out);
    b.tick(ms(6), &mut out);
    let calc = crc8(&frame[1..]);
    let l = lines(&out);
    assert!(
        l.contains(&format!("crc:fail,{calc}/{};", frame[0])),
        "{l:?}"
    );
    assert_eq!(b.snapshot().lights, 0);
    assert_eq!(b.snapshot().crc_failures, 1);
    assert!(executed(&mut b).is_empty());
}

/// A command whose plain CRC is `;` would be cut by the board; the codec's
/// re-encoding keeps it intact and the board executes it.
#[test]
fn crc_equal_to_semicolon_is_reencoded_and_still_executed() {
    let cmd = (0..=255u8)
        .map(Command::Lights)
        .chain((1000..=2000u16).map(Command::Tilt))
        .find(|c| {
            let mut t = Vec::new();
            c.write_text(&mut t);
            crc8(&t) == b';'
        })
        .expect("some command has CRC 0x3B");
    // Unguarded, the board loses the frame.
    let mut text = Vec::new();
    cmd.write_text(&mut text);
    let mut raw = vec![b';'];
    raw.extend_from_slice(&text);
    let (mut b, _) = booted(EmulatorOptions::default());
    let mut out = Vec::new();
    b.receive(&raw, ms(5), &mut out);
    b.tick(ms(6), &mut out);
    assert!(
        executed(&mut b).is_empty(),
        "an unguarded 0x3B frame must be lost"
    );
    // Guarded, it runs.
    let frame = encoded(&cmd, Framing::Crc8);
    assert_ne!(frame[0], b';');
    let mut out = Vec::new();
    b.receive(&frame, ms(10), &mut out);
    b.tick(ms(11), &mut out);
    let ran = executed(&mut b);
    assert_eq!(ran.len(), 1, "{ran:?} {:?}", lines(&out));
    let snap = b.snapshot();
    match cmd {
        Command::Lights(n) => assert_eq!(snap.lights, n),
        Command::Tilt(us) => assert_eq!(snap.tilt_target_us, us),
        _ => unreachable!(),
    }
}

#[test]
fn plain_framing_has_no_crc() {
    let (mut b, _) = booted(EmulatorOptions {
        framing: Framing::Plain,
        ..Default::default()
    });
    let mut out = Vec::new();
    b.receive(
        &encoded(&Command::Laser(255), Framing::Plain),
        ms(5),
        &mut out,
    );
    b.tick(ms(6), &mut out);
    let l = lines(&out);
    assert!(l.contains(&"claser:255;".to_owned()), "{l:?}");
    assert!(!l.iter().any(|x| x.starts_with("crc:")));
}

#[test]
fn go_needs_all_three_in_range() {
    let (mut b, _) = booted(EmulatorOptions::default());
    send(
        &mut b,
        Command::Go {
            port_us: 1700,
            vertical_us: 1700,
            starboard_us: 1700,
        },
        ms(5),
    );
    send(
        &mut b,
        Command::Go {
            port_us: 1800,
            vertical_us: 2001,
            starboard_us: 1800,
        },
        ms(10),
    );
    assert_eq!(b.snapshot().target_us, [1700, 1700, 1700]);
    send(
        &mut b,
        Command::Go {
            port_us: 999,
            vertical_us: 1500,
            starboard_us: 1500,
        },
        ms(15),
    );
    assert_eq!(b.snapshot().target_us, [1700, 1700, 1700]);
}

#[test]
fn deadzone_and_reverse_multiplier_shape_the_esc_outputs() {
    let (mut b, _) = booted(EmulatorOptions::default());
    send(
        &mut b,
        Command::Go {
            port_us: 1540,
            vertical_us: 1400,
            starboard_us: 1700,
        },
        ms(5),
    );
    // 1540 is inside the 50 µs deadzone; 1400 is reverse: 1500 - 2·100.
    assert_eq!(b.snapshot().motors_us, [1500, 1300, 1700]);
    send(
        &mut b,
        Command::Go {
            port_us: 1000,
            vertical_us: 1460,
            starboard_us: 1551,
        },
        ms(10),
    );
    assert_eq!(b.snapshot().motors_us, [1000, 1500, 1551]);
}

#[test]
fn lights_laser_tilt_and_capabilities_answer() {
    let (mut b, _) = booted(EmulatorOptions::default());
    assert!(send(&mut b, Command::Lights(51), ms(5)).contains(&"LIGT:51;LIGP:0.20;".to_owned()));
    assert!(send(&mut b, Command::Laser(255), ms(10)).contains(&"claser:255;".to_owned()));
    assert!(
        send(&mut b, Command::Capabilities, ms(15))
            .iter()
            .any(|l| l.starts_with("CAPA:"))
    );
    assert!(send(&mut b, Command::Ping(0), ms(20)).contains(&"pong:0;".to_owned()));
    send(&mut b, Command::Tilt(1600), ms(25));
    let mut out = Vec::new();
    b.tick(ms(75), &mut out);
    let s = b.snapshot();
    assert_eq!(s.tilt_target_us, 1600);
    assert!(
        s.tilt_us > 1500 && s.tilt_us < 1600,
        "tilt slews: {}",
        s.tilt_us
    );
    b.tick(ms(200), &mut out);
    assert_eq!(b.snapshot().tilt_us, 1600);
}

#[test]
fn dead_man_stops_motors_after_two_seconds_without_ping() {
    let (mut b, _) = booted(EmulatorOptions::default());
    send(&mut b, Command::DeadMan(true), ms(5));
    send(&mut b, Command::Ping(0), ms(10));
    send(
        &mut b,
        Command::Go {
            port_us: 1700,
            vertical_us: 1500,
            starboard_us: 1700,
        },
        ms(15),
    );
    let mut out = Vec::new();
    b.tick(ms(1900), &mut out);
    assert_eq!(b.snapshot().target_us, [1700, 1500, 1700]);
    b.tick(ms(2100), &mut out);
    let s = b.snapshot();
    assert!(s.dead_man_tripped);
    assert_eq!(s.motors_us, [1500, 1500, 1500]);
    // go() is ignored while tripped; the next ping restarts.
    send(
        &mut b,
        Command::Go {
            port_us: 1700,
            vertical_us: 1500,
            starboard_us: 1700,
        },
        ms(2200),
    );
    assert_eq!(b.snapshot().motors_us, [1500, 1500, 1500]);
    send(&mut b, Command::Ping(0), ms(2300));
    assert!(!b.snapshot().dead_man_tripped);
    send(
        &mut b,
        Command::Go {
            port_us: 1700,
            vertical_us: 1500,
            starboard_us: 1700,
        },
        ms(2400),
    );
    assert_eq!(b.snapshot().motors_us, [1700, 1500, 1700]);
}

#[test]
fn dead_man_inactive_without_dms_before_180_s() {
    let (mut b, _) = booted(EmulatorOptions::default());
    send(
        &mut b,
        Command::Go {
            port_us: 1700,
            vertical_us: 1500,
            starboard_us: 1700,
        },
        ms(5),
    );
    let mut out = Vec::new();
    b.tick(ms(10_000), &mut out);
    assert!(!b.snapshot().dead_man_tripped);
    b.tick(ms(181_000), &mut out);
    assert!(
        b.snapshot().dead_man_tripped,
        "auto-armed after 180 s of uptime"
    );
}

#[test]
fn queue_overrun_drops_oldest() {
    let (mut b, _) = booted(EmulatorOptions::default());
    // Short frames back to back arrive faster (≈ 0.8 ms each on the wire)
    // than the board's loop takes them (1 ms): the queue fills up.
    let mut burst = Vec::new();
    for n in 1..=60u8 {
        burst.extend(encoded(&Command::Lights(n), Framing::Crc8));
    }
    let mut out = Vec::new();
    b.receive(&burst, ms(5), &mut out);
    b.tick(ms(50), &mut out);
    let l = lines(&out);
    assert!(l.iter().any(|x| x == "log:CommandBufferOverrun;"), "{l:?}");
    assert!(b.snapshot().overruns >= 1);
}

#[test]
fn telemetry_is_10_hz_nav_and_1_hz_status() {
    let (mut b, _) = booted(EmulatorOptions::default());
    let mut out = Vec::new();
    let mut t = Duration::ZERO;
    while t < Duration::from_secs(10) {
        t += ms(7);
        b.tick(t, &mut out);
    }
    let mut dec = LineDecoder::new();
    let mut ev = Vec::new();
    dec.push(&out, &mut ev);
    let nav = ev.iter().filter(|e| matches!(e, Event::Nav(_))).count();
    let status = ev
        .iter()
        .filter(|e| matches!(e, Event::Status(s) if s.vout_v.is_some()))
        .count();
    assert!((99..=100).contains(&nav), "nav {nav}");
    assert!((9..=10).contains(&status), "status {status}");
    assert_eq!(dec.stats().rejected_total(), 0);
}

/// The thesis' exact physics (`tests/sim_models.rs` covers the realistic
/// model, where the reversed port ESC at full reverse gives half thrust).
#[test]
fn forward_thrust_moves_the_simulated_vehicle() {
    let (mut b, _) = booted(EmulatorOptions::ideal_thesis());
    // Port wired reversed: full forward is port 1000, starboard 2000.
    send(
        &mut b,
        Command::Go {
            port_us: 1000,
            vertical_us: 1500,
            starboard_us: 2000,
        },
        ms(5),
    );
    let mut out = Vec::new();
    b.tick(Duration::from_secs(30), &mut out);
    let s = b.snapshot().sim;
    assert!(s.surge_mps > 1.4, "surge {}", s.surge_mps);
    assert!(s.north_m > 30.0, "north {}", s.north_m);
}

/// With faults injected, every line the decoder accepts carries either the
/// clean value or an in-range wild point the emulator recorded, and the
/// rejection counters equal what the emulator injected.
#[test]
fn fault_injection_is_accounted_for_exactly() {
    let faults = FaultOptions {
        garbage: 0.05,
        torn: 0.05,
        wild: 0.05,
        dropped: 0.0,
        seed: 7,
    };
    let (mut faulty, _) = booted(EmulatorOptions {
        faults,
        ..Default::default()
    });
    let (mut clean, _) = booted(EmulatorOptions::default());
    let cmd = encoded(
        &Command::Go {
            port_us: 1300,
            vertical_us: 1600,
            starboard_us: 1800,
        },
        Framing::Crc8,
    );
    let (mut fo, mut co) = (Vec::new(), Vec::new());
    faulty.receive(&cmd, ms(1), &mut fo);
    clean.receive(&cmd, ms(1), &mut co);
    fo.clear();
    co.clear();
    let mut t = Duration::ZERO;
    while t < Duration::from_secs(300) {
        t += ms(10);
        faulty.tick(t, &mut fo);
        clean.tick(t, &mut co);
    }
    let f_lines: Vec<&[u8]> = fo
        .split(|&b| b == b'\n')
        .filter(|l| !l.is_empty())
        .collect();
    let c_lines: Vec<&[u8]> = co
        .split(|&b| b == b'\n')
        .filter(|l| !l.is_empty())
        .collect();
    assert_eq!(f_lines.len(), c_lines.len());
    let mut whole = LineDecoder::new();
    let mut all = Vec::new();
    let mut differing_accepted = 0;
    for (f, c) in f_lines.iter().zip(&c_lines) {
        let mut fd = LineDecoder::new();
        let mut cd = LineDecoder::new();
        let (mut fe, mut ce) = (Vec::new(), Vec::new());
        let mut f = f.to_vec();
        f.push(b'\n');
        let mut c = c.to_vec();
        c.push(b'\n');
        fd.push(&f, &mut fe);
        cd.push(&c, &mut ce);
        whole.push(&f, &mut all);
        if fd.stats().rejected_total() == 0 && fe != ce {
            differing_accepted += 1;
        }
    }
    let injected = faulty.snapshot().faults;
    assert!(
        injected.torn_lines > 50 && injected.wild_out_of_range > 20 && injected.garbage_bursts > 50,
        "{injected:?}"
    );
    assert_eq!(
        whole.stats().rejected_total(),
        injected.expected_rejections(),
        "{:?} vs {injected:?}",
        whole.stats()
    );
    // Accepted lines that differ from the clean ones are exactly the in-range wild points.
    assert_eq!(differing_accepted, injected.wild_in_range);
    assert_eq!(whole.stats().garbage_bytes, injected.garbage_bytes);
}
