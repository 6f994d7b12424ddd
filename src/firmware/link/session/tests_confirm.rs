//! The board's outputs confirmed, not assumed: what the session writes
//! again when the board rejected a frame, lost it without a word, or
//! reports holding something else — driven with synthetic time.

use super::tests::{drain, drain_writes, go, rawcmd, up};

use super::*;
use crate::firmware::codec::encoded;

const MS: Duration = Duration::from_millis(1);

/// A frame the board read damaged: its echo (not ours) and its rejection.
const REJECTED: &[u8] =
    b"rawcmd:9F,67,6F,28,31,35,30,30,2C,31,35,30,30,2C,31,35,30,30,29,3B,;\r\ncrc:fail,9E/9F;";

fn crc8_frame(cmd: &Command) -> Vec<u8> {
    encoded(cmd, Framing::Crc8)
}

/// A link up, its handshake's frames long taken (the pacing has room).
fn settled() -> (Session, Instant) {
    let (s, t) = up(Instant::now());
    (s, t + Duration::from_millis(50))
}

/// `go(port,1500,1500)`, written and echoed: the board holds it; the
/// returned time is when the line has room again.
fn holding(port_us: u16) -> (Session, Instant) {
    let (mut s, t) = settled();
    s.command(go(port_us));
    assert_eq!(drain_writes(&mut s, t), [go(port_us)]);
    (s, t + Duration::from_millis(20))
}

#[test]
fn a_stop_the_board_rejected_is_written_again_at_once() {
    let (mut s, t) = holding(1600);
    s.command(go(1500));
    assert_eq!(drain(&mut s, t + MS, false), [go(1500)]);
    // The board read it damaged: its CRC rejects it.
    s.received(REJECTED, t + 3 * MS);
    s.received(b"\r\n", t + 3 * MS);
    assert_eq!(drain_writes(&mut s, t + 4 * MS), [go(1500)]);
    assert_eq!(s.stats().thrust_resent, 1);
    assert_eq!(s.stats().crc_failures_echoed, 1);
    // Echoed now: nothing more, however long.
    assert!(drain_writes(&mut s, t + Duration::from_secs(2)).is_empty());
    assert_eq!(s.stats().thrust_resent, 1);
}

#[test]
fn a_stop_lost_without_a_word_is_written_again_after_the_confirm_timeout() {
    let (mut s, t) = holding(1600);
    s.command(go(1500));
    assert_eq!(drain(&mut s, t + MS, false), [go(1500)]);
    // Its `;` was lost: the board waits for the rest and says nothing.
    let before = t + confirm::CONFIRM_TIMEOUT;
    assert!(drain(&mut s, before, false).is_empty());
    let due = s.next_wake(before);
    assert!(due <= t + MS + confirm::CONFIRM_TIMEOUT + 2 * MS, "{due:?}");
    assert_eq!(
        drain_writes(&mut s, t + MS + confirm::CONFIRM_TIMEOUT + 2 * MS),
        [go(1500)]
    );
    assert!(drain_writes(&mut s, t + Duration::from_secs(2)).is_empty());
}

#[test]
fn a_push_whose_echo_was_damaged_is_confirmed_by_the_boards_outputs() {
    let (mut s, t) = settled();
    s.command(go(1600));
    assert_eq!(drain(&mut s, t, false), [go(1600)]);
    // The echo came back damaged, then the board applied it: `motors:`
    // carries ESC pulses, go(1600) through its mapping (deadzone skipped).
    s.received(
        b"rawcmd:9E,67,6F,28,31,36,30,30,2C,31,35,30,30,2C,31,35,30,30,29,3B,;\r\n",
        t + 3 * MS,
    );
    s.received(b"motors:1640,1500,1500;\r\n", t + 40 * MS);
    assert!(drain(&mut s, t + Duration::from_millis(400), false).is_empty());
    assert_eq!(s.stats().thrust_resent, 0);
}

#[test]
fn the_plain_cmd_echo_after_crc_pass_confirms_when_rawcmd_was_damaged() {
    let (mut s, t) = settled();
    s.command(go(1600));
    assert_eq!(drain(&mut s, t, false), [go(1600)]);
    s.received(
        b"rawcmd:9E,67,6F,28,31,,;\r\ncrc:pass;cmd:go(1600,1500,1500);\r\n",
        t + 3 * MS,
    );
    assert!(drain(&mut s, t + Duration::from_millis(400), false).is_empty());
    assert_eq!(s.stats().thrust_echoed, 1);
}

#[test]
fn a_report_that_disagrees_is_answered_with_what_the_vehicle_wants() {
    let (mut s, t) = holding(1600);
    // The board says it holds neutral (a `go` it lost, a stop of its own);
    // the vehicle is alive (a push is written again only then).
    s.healthy(t + 500 * MS);
    let thrust = |s: &mut Session, now| -> Vec<Command> {
        drain_writes(s, now)
            .into_iter()
            .filter(Command::is_thrust)
            .collect()
    };
    s.received(b"mtarg:1500,1500,1500;\r\n", t + 500 * MS);
    assert_eq!(thrust(&mut s, t + 501 * MS), [go(1600)]);
    s.received(b"mtarg:1600,1500,1500;\r\n", t + 550 * MS);
    assert!(thrust(&mut s, t + 600 * MS).is_empty());
    assert_eq!(s.stats().thrust_resent, 1);
    // Its ESCs say otherwise too: again.
    s.received(b"motors:1500,1500,1500;\r\n", t + 700 * MS);
    assert_eq!(thrust(&mut s, t + 701 * MS), [go(1600)]);
}

#[test]
fn a_report_heard_while_the_frame_is_on_its_way_is_not_judged() {
    let (mut s, t) = holding(1500);
    s.command(go(1600));
    assert_eq!(drain(&mut s, t + MS, false), [go(1600)]);
    // Printed before the board read the frame.
    s.received(b"mtarg:1500,1500,1500;\r\n", t + 2 * MS);
    assert!(drain(&mut s, t + 3 * MS, false).is_empty());
    s.received(&rawcmd(&crc8_frame(&go(1600))), t + 4 * MS);
    assert!(drain(&mut s, t + Duration::from_secs(1), false).is_empty());
    assert_eq!(s.stats().thrust_resent, 0);
}

#[test]
fn writes_again_at_most_ten_a_second_to_a_board_that_keeps_disagreeing() {
    let (mut s, t) = holding(1600);
    let mut writes = 0;
    for ms in 1..=1000u64 {
        let now = t + Duration::from_millis(ms);
        s.healthy(now);
        s.received(b"mtarg:1500,1500,1500;\r\n", now);
        writes += drain_writes(&mut s, now)
            .iter()
            .filter(|c| c.is_thrust())
            .count();
    }
    assert!((9..=10).contains(&writes), "{writes} writes in a second");
}

#[test]
fn a_stop_goes_ahead_of_the_keep_alive_and_the_lights() {
    let (mut s, t) = settled();
    s.healthy(t);
    s.command(Command::Lights(200));
    s.command(go(1500));
    let written = drain_writes(&mut s, t);
    assert_eq!(written[0], go(1500), "{written:?}");
    assert!(written.contains(&Command::Ping(0)));
    // A push waits its turn behind them.
    s.healthy(t + Duration::from_secs(1));
    s.command(Command::Lights(100));
    s.command(go(1600));
    let written = drain_writes(&mut s, t + Duration::from_secs(1));
    assert_eq!(written.last(), Some(&go(1600)), "{written:?}");
}

#[test]
fn five_pings_fall_in_the_boards_dead_man_window() {
    let (mut s, t) = settled();
    let mut pings = 0;
    for ms in (0..2000u64).step_by(10) {
        let now = t + Duration::from_millis(ms);
        s.healthy(now);
        pings += drain_writes(&mut s, now)
            .iter()
            .filter(|c| **c == Command::Ping(0))
            .count();
    }
    assert_eq!(pings, 5);
}

#[test]
fn the_drop_rate_counts_rejected_frames_and_damaged_lines_over_ten_seconds() {
    let (mut s, t) = holding(1600);
    s.poll_timers(t);
    assert_eq!(s.stats().drop_rate_cpct, 0);
    // Ten lines and one frame in: one rejected frame, one torn line.
    for i in 0..9 {
        s.received(super::tests::NAV, t + Duration::from_millis(100 * i));
    }
    s.received(b"hdgd:1x.0;\r\n", t + 950 * MS);
    s.command(go(1500));
    drain(&mut s, t + 960 * MS, false);
    s.received(REJECTED, t + 970 * MS);
    s.received(b"\r\n", t + 970 * MS);
    drain_writes(&mut s, t + 980 * MS);
    s.poll_timers(t + Duration::from_secs(1));
    let rate = s.stats().drop_rate_cpct;
    assert!(rate > 0, "{:?}", s.stats());
    assert_eq!(s.stats().errors(), 2);
    // Ten seconds of a clean line later, the window has forgotten them.
    for i in 1..=120u64 {
        let now = t + Duration::from_secs(1) + Duration::from_millis(100 * i);
        s.received(super::tests::NAV, now);
        s.poll_timers(now);
    }
    assert_eq!(s.stats().drop_rate_cpct, 0);
    assert_eq!(s.stats().errors(), 2, "the count stays");
}

#[test]
fn the_cmd_echo_after_a_recognised_rawcmd_leaves_an_identical_frame_behind_it_in_flight() {
    let (mut s, t) = settled();
    // The same push twice in flight (a re-send): the board has both in
    // its buffer, and echoes the first with `rawcmd:`, `crc:pass`, `cmd:`.
    s.command(go(1600));
    assert_eq!(drain(&mut s, t, false), [go(1600)]);
    s.command(go(1600));
    assert_eq!(drain(&mut s, t + MS, false), [go(1600)]);
    let mut echo = rawcmd(&crc8_frame(&go(1600)));
    echo.extend_from_slice(b"crc:pass;cmd:go(1600,1500,1500);\r\n");
    s.received(&echo, t + 5 * MS);
    assert_eq!(s.stats().thrust_echoed, 1);
    // The second still holds its 20 bytes of the board's 64: two more
    // frames fit beside it, a third would overrun the board's buffer.
    s.command(go(1601));
    assert_eq!(drain(&mut s, t + 20 * MS, false), [go(1601)]);
    s.command(go(1602));
    assert_eq!(drain(&mut s, t + 30 * MS, false), [go(1602)]);
    s.command(go(1603));
    assert!(drain(&mut s, t + 40 * MS, false).is_empty());
    // Its own echo frees its room.
    s.received(&echo, t + 45 * MS);
    assert_eq!(s.stats().thrust_echoed, 2);
    assert_eq!(s.stats().echoes_missed, 0);
    assert_eq!(drain(&mut s, t + 50 * MS, false), [go(1603)]);
}
