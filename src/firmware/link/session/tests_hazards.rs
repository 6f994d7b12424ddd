//! What the board's outputs being confirmed must never do, driven with
//! synthetic time: write again a push the vehicle no longer wants (after
//! a stop or a disarm, a closed and reopened device, a board that
//! rebooted, a vehicle that stalled), write faster than ten a second
//! whatever the board prints, or fail with the December 2014 firmware's
//! plain framing and `cmd:` echoes.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use super::tests::{NAV, drain, drain_writes, go, rawcmd, up};

use super::*;
use crate::firmware::codec::encoded;

const MS: Duration = Duration::from_millis(1);

/// Thrust commands that are not neutral among `written`.
fn pushes(written: &[Command]) -> Vec<Command> {
    written
        .iter()
        .copied()
        .filter(|c| c.is_thrust() && *c != NEUTRAL_GO)
        .collect()
}

/// A link up and healthy whose board took `go(port_us,1500,1500)`; the
/// returned time is when the line has room again.
fn holding(port_us: u16) -> (Session, Instant) {
    let (mut s, t) = up(Instant::now());
    let t = t + 50 * MS;
    s.healthy(t);
    s.command(go(port_us));
    let written = drain_writes(&mut s, t);
    assert!(written.contains(&go(port_us)), "{written:?}");
    (s, t + 20 * MS)
}

/// One line the board (or the noise on its line) might print, drawn by
/// `rng`: echoes of what was written (whole, of an older frame, damaged),
/// rejections, reports that agree or not, its dead-man's stop, garbage.
fn board_says(rng: &mut SmallRng, push: &Command, written: &[Vec<u8>]) -> Vec<u8> {
    let push_frame = encoded(push, Framing::Crc8);
    match rng.random_range(0..12) {
        0 => rawcmd(&push_frame),
        1 => written
            .get(rng.random_range(0..written.len().max(1)))
            .map_or_else(Vec::new, |f| rawcmd(f)),
        2 => b"crc:fail,9E/9F;\r\n".to_vec(),
        3 => b"mtarg:1600,1500,1500;\r\n".to_vec(),
        4 => b"mtarg:1500,1500,1500;\r\n".to_vec(),
        5 => b"motors:1640,1500,1500;\r\n".to_vec(),
        6 => b"motors:1500,1500,1500;\r\n".to_vec(),
        7 => b"icmd:stop();\r\n".to_vec(),
        8 => b"crc:pass;cmd:go(1600,1500,1500);\r\n".to_vec(),
        9 => {
            // A damaged echo: one byte of it flipped.
            let mut line = rawcmd(written.last().unwrap_or(&push_frame));
            let i = rng.random_range(0..line.len());
            line[i] ^= 1 << rng.random_range(0..8);
            line
        }
        10 => (0..rng.random_range(1..40)).map(|_| rng.random()).collect(),
        _ => NAV.to_vec(),
    }
}

#[test]
fn after_a_stop_or_a_disarm_nothing_but_neutral_is_written_whatever_the_board_says() {
    for seed in 0..64 {
        let mut rng = SmallRng::seed_from_u64(seed);
        let (mut s, t) = holding(1600);
        // The vehicle disarmed (or the pilot let go): its decision is
        // neutral from now on.
        s.command(NEUTRAL_GO);
        let mut written_frames = vec![encoded(&go(1600), Framing::Crc8)];
        let mut after_stop = Vec::new();
        let mut now = t;
        let end = t + Duration::from_secs(20);
        while now < end {
            now += Duration::from_millis(rng.random_range(1..60));
            if rng.random_bool(0.8) {
                s.healthy(now);
            }
            for _ in 0..rng.random_range(0..4) {
                let line = board_says(&mut rng, &go(1600), &written_frames);
                s.received(&line, now);
            }
            s.poll_timers(now);
            let mut frame = Vec::new();
            while let Some(cmd) = s.poll_transmit(now, &mut frame) {
                s.transmitted(&cmd, frame.len(), now);
                written_frames.push(frame.clone());
                after_stop.push(cmd);
                // The board echoes some of them, sometimes much later.
                if rng.random_bool(0.5) {
                    s.received(&rawcmd(&frame), now);
                }
            }
        }
        assert!(
            pushes(&after_stop).is_empty(),
            "seed {seed}: a push written after the stop: {after_stop:?}"
        );
        assert!(
            after_stop.contains(&NEUTRAL_GO),
            "seed {seed}: the stop itself was never written"
        );
    }
}

#[test]
fn a_push_is_not_written_again_to_a_device_closed_and_reopened() {
    let (mut s, t) = holding(1600);
    let _ = s.closed("the device vanished".into(), t);
    let t = t + Duration::from_secs(3);
    s.opened(t);
    // The board kept running (its dead-man stopped it, or not): it still
    // reports the old push, rejects a frame, stops.
    s.received(
        b"mtarg:1600,1500,1500;\r\nmotors:1640,1500,1500;\r\n",
        t + MS,
    );
    let t = t + s.cfg.boot_wait;
    let mut written = Vec::new();
    for ms in (0..3000u64).step_by(10) {
        let now = t + Duration::from_millis(ms);
        s.healthy(now);
        s.received(NAV, now);
        if ms % 500 == 0 {
            s.received(
                b"mtarg:1500,1500,1500;\r\ncrc:fail,9E/9F;\r\nicmd:stop();\r\n",
                now,
            );
        }
        s.poll_timers(now);
        written.extend(drain_writes(&mut s, now));
    }
    assert!(written.contains(&Command::Ping(0)), "{written:?}");
    assert!(
        written.iter().all(|c| !c.is_thrust()),
        "a thrust the vehicle did not decide after the reopening: {written:?}"
    );
    // The vehicle decides again: that is written, and confirmed.
    let now = t + Duration::from_secs(3);
    s.command(NEUTRAL_GO);
    assert_eq!(drain_writes(&mut s, now), [NEUTRAL_GO]);
}

#[test]
fn a_board_that_rebooted_gets_no_push_decided_for_it_before() {
    let (mut s, t) = holding(1500);
    // A busy board echoes nothing: frames fill its receive buffer, and the
    // push the vehicle decides next waits.
    for n in 0..7 {
        s.command(Command::EscPower(n % 2 == 0));
    }
    let mut now = t;
    for _ in 0..30 {
        now += MS;
        drain(&mut s, now, false);
    }
    s.command(go(1700));
    let held_back = drain(&mut s, now + MS, false);
    assert!(!held_back.contains(&go(1700)), "{held_back:?}");
    // It restarts: what it had not taken is gone, and the push with it.
    let t = now + 2 * MS;
    s.received(b"boot:1;\r\n", t);
    let mut written = Vec::new();
    for ms in (0..2000u64).step_by(10) {
        let now = t + Duration::from_millis(ms);
        s.healthy(now);
        s.received(NAV, now);
        if ms % 300 == 0 {
            s.received(b"mtarg:1500,1500,1500;\r\nmotors:1500,1500,1500;\r\n", now);
        }
        s.poll_timers(now);
        written.extend(drain_writes(&mut s, now));
    }
    assert!(written.starts_with(&tests::HANDSHAKE), "{written:?}");
    assert!(
        pushes(&written).is_empty(),
        "a push decided before the reboot reached the rebooted board: {written:?}"
    );
}

#[test]
fn a_stalled_vehicles_push_is_never_renewed_and_after_the_gap_only_its_next_decision_drives() {
    let (mut s, t) = holding(1600);
    // The vehicle task stalls: no sign of life after `t`. The board's
    // lines say it holds neutral (a lost frame, then its dead-man's stop).
    let last_alive = t - 20 * MS;
    let mut written = Vec::new();
    for ms in (0..4000u64).step_by(10) {
        let now = t + Duration::from_millis(ms);
        s.received(NAV, now);
        if ms % 100 == 0 {
            s.received(b"mtarg:1500,1500,1500;\r\nmotors:1500,1500,1500;\r\n", now);
        }
        if ms == 2100 {
            s.received(b"icmd:stop();\r\n", now);
        }
        s.poll_timers(now);
        for c in drain_writes(&mut s, now) {
            written.push((now, c));
        }
        let wake = s.next_wake(now);
        assert!(wake > now, "the link spins at {ms} ms");
    }
    let late: Vec<_> = written
        .iter()
        .filter(|(at, c)| {
            c.is_thrust() && *c != NEUTRAL_GO && *at > last_alive + s.cfg.healthy_window
        })
        .collect();
    assert!(
        late.is_empty(),
        "a stalled vehicle's push was written again: {late:?}"
    );
    assert!(
        !written
            .iter()
            .any(|(at, c)| *c == Command::Ping(0) && *at > last_alive + s.cfg.healthy_window),
        "a ping from a stalled vehicle: {written:?}"
    );
    // Alive again: neutral ahead of the ping that restarts the board, and
    // no push until the vehicle decides one (its reports say neutral).
    let t = t + Duration::from_secs(4);
    let mut after = Vec::new();
    for ms in (0..900u64).step_by(10) {
        let now = t + Duration::from_millis(ms);
        s.healthy(now);
        s.received(NAV, now);
        if ms % 100 == 50 {
            s.received(b"mtarg:1500,1500,1500;\r\n", now);
        }
        s.poll_timers(now);
        after.extend(drain_writes(&mut s, now));
    }
    assert_eq!(after[..2], [NEUTRAL_GO, Command::Ping(0)], "{after:?}");
    assert!(pushes(&after).is_empty(), "{after:?}");
    // Its next decision drives.
    s.command(go(1650));
    assert_eq!(drain_writes(&mut s, t + Duration::from_secs(1)), [go(1650)]);
}

#[test]
fn a_flood_of_rejections_and_garbage_gets_at_most_ten_thrust_writes_a_second() {
    for wanted in [go(1600), NEUTRAL_GO] {
        let (mut s, t) = holding(1550);
        s.command(wanted);
        let mut thrust = 0;
        let mut pings = 0;
        let mut rng = SmallRng::seed_from_u64(7);
        for ms in 1..=5000u64 {
            let now = t + Duration::from_millis(ms);
            if ms % 50 == 0 {
                s.healthy(now);
            }
            // A line that prints a rejection every millisecond, and noise.
            s.received(b"crc:fail,9E/9F;\r\n", now);
            let noise: Vec<u8> = (0..rng.random_range(0..32)).map(|_| rng.random()).collect();
            s.received(&noise, now);
            s.poll_timers(now);
            for c in drain(&mut s, now, false) {
                match c {
                    Command::Ping(_) => pings += 1,
                    c if c.is_thrust() => {
                        assert_eq!(c, wanted, "only what the vehicle wants");
                        thrust += 1;
                    }
                    _ => {}
                }
            }
        }
        // The first write, then at most one per RESEND_INTERVAL.
        assert!(
            (40..=51).contains(&thrust),
            "{thrust} thrust writes in 5 s for {wanted:?}"
        );
        assert!((12..=13).contains(&pings), "{pings} pings in 5 s");
        assert_eq!(s.stats().thrust_resent, thrust - 1);
    }
}

/// A link up with the December 2014 firmware's plain framing.
fn plain_up() -> (Session, Instant) {
    let t0 = Instant::now();
    let mut s = Session::new(LinkConfig {
        framing: Framing::Plain,
        ..LinkConfig::new("/dev/null")
    });
    s.opened(t0);
    let t = t0 + s.cfg.boot_wait;
    let mut frame = Vec::new();
    while let Some(cmd) = s.poll_transmit(t, &mut frame) {
        s.transmitted(&cmd, frame.len(), t);
        s.received(&plain_echo(&frame), t);
    }
    s.received(NAV, t);
    s.poll_timers(t);
    assert_eq!(s.stats().state, LinkState::Up);
    (s, t + 50 * MS)
}

/// The 2014-12 firmware's echo of a plain frame: `cmd:go(1600,1500,1500);`.
fn plain_echo(frame: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(frame);
    format!("cmd:{};\r\n", text.trim_end_matches(';')).into_bytes()
}

fn plain_drain(s: &mut Session, now: Instant, echo: bool) -> Vec<Command> {
    let mut frame = Vec::new();
    let mut written = Vec::new();
    while let Some(cmd) = s.poll_transmit(now, &mut frame) {
        s.transmitted(&cmd, frame.len(), now);
        written.push(cmd);
        if echo {
            s.received(&plain_echo(&frame), now);
        }
    }
    written
}

#[test]
fn plain_framing_echoes_confirm_and_nothing_is_written_twice() {
    let (mut s, t) = plain_up();
    s.healthy(t);
    s.command(go(1600));
    let written = plain_drain(&mut s, t, true);
    assert!(written.contains(&go(1600)), "{written:?}");
    s.command(NEUTRAL_GO);
    assert_eq!(plain_drain(&mut s, t + 20 * MS, true), [NEUTRAL_GO]);
    // The board's reports agree: nothing more, however long.
    for ms in (100..3000u64).step_by(100) {
        let now = t + Duration::from_millis(ms);
        s.healthy(now);
        s.received(b"mtarg:1500,1500,1500;\r\n", now);
        let w = plain_drain(&mut s, now, true);
        assert!(w.iter().all(|c| !c.is_thrust()), "{w:?}");
    }
    assert_eq!(s.stats().thrust_resent, 0);
    assert_eq!(s.stats().thrust_echoed, 2);
}

#[test]
fn plain_framing_a_stop_the_board_read_damaged_is_written_again() {
    // No CRC: a digit damaged on the way is a command the board takes. Its
    // echo is not of our frame, and its outputs say what it took.
    let (mut s, t) = plain_up();
    s.healthy(t);
    s.command(go(1600));
    plain_drain(&mut s, t, true);
    s.command(NEUTRAL_GO);
    assert_eq!(plain_drain(&mut s, t + 20 * MS, false), [NEUTRAL_GO]);
    s.received(
        b"cmd:go(1500,1500,1900);\r\nmotors:1500,1500,1940;\r\n",
        t + 23 * MS,
    );
    let again = plain_drain(&mut s, t + 30 * MS, true);
    assert_eq!(again, [NEUTRAL_GO]);
    // And a stop whose echo never comes (its `;` lost) goes again after the
    // confirm timeout.
    s.command(go(1600));
    plain_drain(&mut s, t + 200 * MS, true);
    s.command(NEUTRAL_GO);
    assert_eq!(plain_drain(&mut s, t + 220 * MS, false), [NEUTRAL_GO]);
    let later = t + 221 * MS + confirm::CONFIRM_TIMEOUT;
    assert_eq!(plain_drain(&mut s, later, true), [NEUTRAL_GO]);
    assert_eq!(s.stats().thrust_resent, 2);
}

#[test]
fn a_stop_a_report_seemed_to_confirm_is_written_again_when_its_frame_turns_out_lost() {
    let (mut s, t) = holding(1400);
    s.command(NEUTRAL_GO);
    assert_eq!(drain(&mut s, t + MS, false), [NEUTRAL_GO]);
    // A report that agrees before the frame is heard of: printed before the
    // board read it, or damaged on the way (`1400` with one bit flipped is
    // `1500`).
    s.received(b"mtarg:1500,1500,1500;\r\n", t + 2 * MS);
    assert!(drain(&mut s, t + 3 * MS, false).is_empty());
    // Then the board rejects the frame: the stop is not taken.
    s.received(b"crc:fail,9E/9F;\r\n", t + 4 * MS);
    assert_eq!(drain_writes(&mut s, t + 5 * MS), [NEUTRAL_GO]);
    assert_eq!(s.stats().thrust_resent, 1);
}

#[test]
fn a_stop_and_the_keep_alive_never_wait_behind_frames_whose_echoes_were_lost() {
    let (mut s, t) = holding(1500);
    // Pushes whose echoes a noisy line damaged: the budget is full.
    let mut now = t;
    for us in [1600, 1610, 1620, 1630] {
        s.command(go(us));
        now += 10 * MS;
        s.healthy(now);
        drain(&mut s, now, false);
    }
    s.command(go(1640));
    now += 10 * MS;
    assert!(
        drain(&mut s, now, false).is_empty(),
        "a push waits for the board's room"
    );
    // … asleep until an echo comes or the oldest frame is overdue: waking
    // for the line's room would spin.
    let overdue = t + 10 * MS + outbox::ECHO_OVERDUE + MS;
    assert_eq!(s.next_wake(now), overdue);
    // The pilot lets go. A board merely slow to read would echo within the
    // overdue time: until then the stop waits for room like anything else
    // (its buffer is never overrun) — then it goes, ahead of the push, not
    // half a second later at the echo timeout.
    s.command(NEUTRAL_GO);
    assert!(drain(&mut s, now + MS, false).is_empty());
    assert_eq!(s.next_wake(now + MS), overdue);
    assert_eq!(drain(&mut s, overdue, false), [NEUTRAL_GO]);
    // The keep-alive too, when it is due.
    let ping_at = t + s.cfg.ping_period;
    s.healthy(ping_at);
    assert_eq!(drain(&mut s, ping_at, false), [Command::Ping(0)]);
}
