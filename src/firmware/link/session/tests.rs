//! The session driven with synthetic time and no device: what the I/O
//! loop would write and report, decision by decision.

use super::*;
use crate::firmware::codec::encoded;
use crate::vehicle::mixer::NEUTRAL_US;

/// What a handshake writes, in order: never `rcap()`, which blinds the
/// genuine board for five seconds.
pub(super) const HANDSHAKE: [Command; 2] = [Command::DeadMan(true), Command::Start];

pub(super) const NAV: &[u8] = b"hdgd:10.00;deep:1.00;pitc:0.00;roll:0.00;yaw:10.00;fthr:0.00;\r\n";

pub(super) fn go(us: u16) -> Command {
    Command::Go {
        port_us: us,
        vertical_us: NEUTRAL_US,
        starboard_us: NEUTRAL_US,
    }
}

pub(super) fn opened(t0: Instant) -> Session {
    let mut s = Session::new(LinkConfig::new("/dev/null"));
    s.opened(t0);
    s
}

/// A session whose board was handshaken at the boot wait and has talked:
/// the link is up at the returned time.
pub(super) fn up(t0: Instant) -> (Session, Instant) {
    let mut s = opened(t0);
    let t = t0 + s.cfg.boot_wait;
    assert_eq!(drain_writes(&mut s, t), HANDSHAKE);
    s.received(NAV, t);
    s.poll_timers(t);
    assert_eq!(s.stats().state, LinkState::Up);
    (s, t)
}

/// Everything written at `now` (pacing permitting), as commands; the
/// board echoes each frame at once, as the genuine 2015 firmware does.
pub(super) fn drain_writes(s: &mut Session, now: Instant) -> Vec<Command> {
    drain(s, now, true)
}

pub(super) fn drain(s: &mut Session, now: Instant, echo: bool) -> Vec<Command> {
    let mut frame = Vec::new();
    let mut written = Vec::new();
    while let Some(cmd) = s.poll_transmit(now, &mut frame) {
        s.transmitted(&cmd, frame.len(), now);
        written.push(cmd);
        if echo {
            s.received(&rawcmd(&frame), now);
        }
    }
    written
}

/// The genuine board's echo of `frame`: `rawcmd:9E,70,…,3B,;`.
pub(super) fn rawcmd(frame: &[u8]) -> Vec<u8> {
    let mut line = b"rawcmd:".to_vec();
    for b in frame {
        line.extend_from_slice(format!("{b:X},").as_bytes());
    }
    line.extend_from_slice(b";\r\n");
    line
}

fn states(s: &mut Session) -> Vec<LinkState> {
    std::iter::from_fn(|| s.poll_output())
        .filter_map(|o| match o {
            Output::Event(LinkEvent::State { state, .. }) => Some(state),
            _ => None,
        })
        .collect()
}

#[test]
fn handshakes_after_boot_wait_and_pings_only_while_healthy() {
    let t0 = Instant::now();
    let mut s = opened(t0);
    assert_eq!(states(&mut s), [LinkState::Down, LinkState::Handshaking]);
    assert!(
        drain_writes(&mut s, t0).is_empty(),
        "nothing before boot_wait"
    );
    let t = t0 + s.cfg.boot_wait;
    assert_eq!(drain_writes(&mut s, t + Duration::from_secs(1)), HANDSHAKE);
    let t = t + Duration::from_secs(1);
    s.healthy(t);
    assert_eq!(drain_writes(&mut s, t), [Command::Ping(0)]);
    s.poll_timers(t);
    assert!(s.next_wake(t) > t);
    // Unhealthy for longer than the window: no ping, so the board's
    // dead-man stops the vehicle.
    assert!(drain_writes(&mut s, t + Duration::from_secs(3)).is_empty());
    // … and the withheld ping is no reason to wake: the loop must not spin.
    s.poll_timers(t + Duration::from_secs(3));
    assert!(
        s.next_wake(t + Duration::from_secs(3)) > t + Duration::from_secs(3),
        "an unhealthy vehicle keeps the link's loop awake"
    );
    // Healthy again after longer than the board's dead-man: the ping that
    // restarts the board goes behind a neutral.
    s.healthy(t + Duration::from_secs(3));
    assert_eq!(
        drain_writes(&mut s, t + Duration::from_secs(3)),
        [go(NEUTRAL_US), Command::Ping(0)]
    );
    assert_eq!(s.stats().handshakes, 1);
    assert_eq!(s.stats().pings_written, 2);
}

#[test]
fn boot_line_handshakes_at_once_and_again_after_a_reboot() {
    let t0 = Instant::now();
    let mut s = opened(t0);
    let t = t0 + Duration::from_millis(10);
    s.received(b"boot:1;\r\n", t);
    assert_eq!(
        drain_writes(&mut s, t + Duration::from_millis(20)),
        HANDSHAKE
    );
    s.received(NAV, t + Duration::from_millis(30));
    s.poll_timers(t + Duration::from_millis(30));
    assert_eq!(s.stats().state, LinkState::Up);
    while s.poll_output().is_some() {}
    // The board restarts: not up until it has been handshaken again and talks.
    let t = t + Duration::from_secs(1);
    s.received(b"boot:1;\r\n", t);
    assert_eq!(s.stats().state, LinkState::Handshaking);
    assert_eq!(s.stats().board_reboots, 1);
    assert_eq!(states(&mut s), [LinkState::Handshaking]);
    assert_eq!(
        drain_writes(&mut s, t + Duration::from_millis(20)),
        HANDSHAKE
    );
    s.received(NAV, t + Duration::from_millis(30));
    s.poll_timers(t + Duration::from_millis(30));
    assert_eq!(s.stats().state, LinkState::Up);
}

#[test]
fn a_board_setting_up_its_imu_after_the_boot_wait_is_not_down() {
    // The 30.0.2 firmware with a BNO055 prints its first telemetry line
    // about 2.5 s after power-up; the handshake is forced at boot_wait.
    let t0 = Instant::now();
    let mut s = opened(t0);
    assert_eq!(states(&mut s), [LinkState::Down, LinkState::Handshaking]);
    let t = t0 + s.cfg.boot_wait;
    assert_eq!(drain_writes(&mut s, t), HANDSHAKE);
    let first_line = t0 + Duration::from_millis(2500);
    assert!(first_line > t0 + s.cfg.boot_wait.max(s.cfg.stale_after));
    let mut at = t;
    while at < first_line {
        s.poll_timers(at);
        at += Duration::from_millis(100);
    }
    assert!(
        !states(&mut s).contains(&LinkState::Down),
        "reported down while the board was still setting up"
    );
    s.received(b"boot:1;\r\n", first_line);
    s.received(NAV, first_line);
    s.poll_timers(first_line);
    drain_writes(&mut s, first_line);
    s.received(NAV, first_line + Duration::from_millis(100));
    s.poll_timers(first_line + Duration::from_millis(100));
    assert_eq!(s.stats().state, LinkState::Up);
    // Once it has talked, silence is judged at once.
    let silent = first_line + Duration::from_millis(100) + s.cfg.stale_after;
    s.poll_timers(silent + Duration::from_millis(10));
    assert_eq!(s.stats().state, LinkState::Down);
}

#[test]
fn never_more_unechoed_than_the_boards_receive_buffer() {
    let t0 = Instant::now();
    let mut s = opened(t0);
    s.received(b"boot:1;\r\n", t0);
    drain_writes(&mut s, t0);
    let t = t0 + Duration::from_millis(100);
    for n in 0..20 {
        s.command(Command::EscPower(n % 2 == 0));
    }
    // A busy board echoes nothing: the writes stop within its 64 bytes.
    let mut written = 0;
    let mut now = t;
    let mut frame = Vec::new();
    for _ in 0..40 {
        now += Duration::from_millis(5);
        while let Some(cmd) = s.poll_transmit(now, &mut frame) {
            s.transmitted(&cmd, frame.len(), now);
            written += frame.len();
        }
    }
    assert!(written > 0 && written <= 64, "{written} bytes unechoed");
    // An echo frees its frame's room (and the older ones': echoes come in order).
    let sent = written;
    let first = encoded(&Command::EscPower(true), Framing::Crc8);
    s.received(&rawcmd(&first), now);
    assert!(!drain(&mut s, now, false).is_empty());
    // A frame never echoed stops holding the budget after the timeout.
    let later = now + s.cfg.echo_timeout + Duration::from_millis(1);
    assert!(!drain(&mut s, later, false).is_empty());
    assert!(s.stats().echoes_missed > 0);
    assert!(sent > 0);
}

#[test]
fn after_a_gap_in_the_pings_neutral_goes_ahead_of_the_ping() {
    let t0 = Instant::now();
    let mut s = opened(t0);
    s.received(b"boot:1;\r\n", t0);
    s.healthy(t0);
    assert!(drain_writes(&mut s, t0).contains(&Command::Ping(0)));
    // The process stood still for three seconds with a thrust pending: the
    // board's dead-man stopped it, and the next ping restarts it on its
    // last target — which must be neutral by then.
    s.command(go(1700));
    let t = t0 + Duration::from_secs(3);
    s.healthy(t);
    let written = drain_writes(&mut s, t);
    assert_eq!(
        written,
        [go(NEUTRAL_US), Command::Ping(0)],
        "neutral before the ping, no stale go() after the gap"
    );
    // A neutral the vehicle decided after the gap (it disarmed) is written
    // too: it is never dropped.
    let t = t + Duration::from_secs(3);
    s.command(go(NEUTRAL_US));
    s.healthy(t);
    let written = drain_writes(&mut s, t);
    assert_eq!(
        written.iter().filter(|c| **c == Command::Ping(0)).count(),
        1
    );
    assert!(
        written
            .iter()
            .all(|c| !c.is_thrust() || *c == go(NEUTRAL_US))
    );
    assert_eq!(written.first(), Some(&go(NEUTRAL_US)), "{written:?}");
    // After the ping, new thrust goes as usual.
    s.command(go(1600));
    assert_eq!(
        drain_writes(&mut s, t + Duration::from_millis(20)),
        [go(1600)]
    );
}

#[test]
fn newest_thrust_wins_and_a_burst_is_paced() {
    let t0 = Instant::now();
    let mut s = opened(t0);
    let t = t0 + s.cfg.boot_wait;
    drain_writes(&mut s, t + Duration::from_secs(1));
    let t = t + Duration::from_secs(2);
    s.healthy(t);
    s.command(go(1600));
    s.command(go(1700));
    for c in [
        Command::Lights(1),
        Command::Laser(2),
        Command::Tilt(1600),
        Command::Lights(3),
        Command::EscPower(true),
        Command::DeadMan(true),
    ] {
        s.command(c);
    }
    // About `max_ahead` worth of frames (the ping among them) go out at
    // once; the rest wait until the board has taken them.
    let first = drain_writes(&mut s, t);
    assert!(
        (1..5).contains(&first.len()),
        "a burst is held back: {first:?}"
    );
    s.poll_timers(t);
    let wake = s.next_wake(t);
    assert!(
        wake > t && wake <= t + Duration::from_millis(10),
        "{wake:?}"
    );
    let mut all = first;
    let mut now = t;
    while all.len() < 7 {
        now += Duration::from_millis(5);
        all.extend(drain_writes(&mut s, now));
    }
    assert_eq!(all.last(), Some(&go(1700)), "thrust after control: {all:?}");
    assert!(
        !all.contains(&go(1600)),
        "the stale thrust is never written"
    );
    assert_eq!(s.stats().thrust_coalesced, 1);
    assert_eq!(s.stats().thrust_written, 1);
    assert!(
        all.contains(&Command::Lights(3)) && !all.contains(&Command::Lights(1)),
        "the newest lights level replaced the pending one in its place: {all:?}"
    );
    assert_eq!(s.stats().settings_coalesced, 1);
}

#[test]
fn the_ping_goes_ahead_of_a_queue_of_levels() {
    let t0 = Instant::now();
    let mut s = opened(t0);
    let t = t0 + s.cfg.boot_wait;
    drain(&mut s, t + Duration::from_secs(1), true);
    let t = t + Duration::from_secs(2);
    s.command(Command::Lights(9));
    s.command(Command::Laser(1));
    s.command(Command::Tilt(1700));
    s.healthy(t);
    let written = drain(&mut s, t, true);
    assert_eq!(written.first(), Some(&Command::Ping(0)), "{written:?}");
}

#[test]
fn up_on_telemetry_down_when_silent_and_backoff_doubles_then_resets() {
    let (mut s, t) = up(Instant::now());
    let silent = t + s.cfg.stale_after + Duration::from_millis(1);
    s.poll_timers(silent);
    assert_eq!(s.stats().state, LinkState::Down);
    assert!(
        s.stats()
            .down_reason
            .as_deref()
            .is_some_and(|r| r.starts_with("no telemetry"))
    );
    assert_eq!(
        states(&mut s),
        [
            LinkState::Down,
            LinkState::Handshaking,
            LinkState::Up,
            LinkState::Down
        ]
    );
    // A pending thrust is dropped with the device; reopening backs off.
    s.command(go(1600));
    let min = s.cfg.backoff_min;
    assert_eq!(s.closed("device closed".into(), silent), silent + min);
    assert_eq!(s.stats().thrust_coalesced, 1);
    assert_eq!(s.open_failed("gone".into(), silent), silent + min * 2);
    s.opened(silent);
    // A board that is already running talks before the handshake.
    s.received(NAV, silent + Duration::from_millis(100));
    let t = silent + s.cfg.boot_wait;
    drain_writes(&mut s, t);
    s.received(NAV, t);
    s.poll_timers(t);
    assert_eq!(s.stats().state, LinkState::Up);
    assert_eq!(
        s.closed("device closed".into(), t),
        t + min,
        "reset once up"
    );
}

#[test]
fn a_dropped_state_event_is_counted_and_published() {
    let mut s = Session::new(LinkConfig::new("/dev/null"));
    let event = LinkEvent::State {
        state: LinkState::Down,
        reason: None,
    };
    while s.poll_output().is_some() {}
    s.event_dropped(&event);
    assert_eq!(s.stats().events_dropped, 1);
    assert!(matches!(s.poll_output(), Some(Output::Stats(st)) if st.events_dropped == 1));
}

#[test]
fn a_board_heard_in_its_set_up_is_handshaken_after_its_boot_line() {
    // The 30.0.2 firmware with its sensors fitted prints their set-up
    // chatter, then `boot:1;` about 2.5 s after power-up.
    let t0 = Instant::now();
    let mut s = opened(t0);
    s.received(
        b"BNO055.bootloader:21;\r\nDepth: Calibration constants are:\r\n",
        t0 + Duration::from_millis(300),
    );
    let mut at = t0 + Duration::from_millis(300);
    while at < t0 + Duration::from_millis(2500) {
        assert_eq!(
            drain_writes(&mut s, at),
            [],
            "written to a board still setting up"
        );
        s.poll_timers(at);
        let wake = s.next_wake(at);
        assert!(
            wake > at,
            "a withheld handshake must not make the loop spin"
        );
        at += Duration::from_millis(100);
    }
    let boot = t0 + Duration::from_millis(2500);
    s.received(b"boot:1;\r\n", boot);
    assert!(s.next_wake(boot) <= boot);
    assert_eq!(drain_writes(&mut s, boot), HANDSHAKE);
    assert_eq!(s.stats().handshakes, 1, "one handshake, after the set-up");
    assert_eq!(s.stats().board_reboots, 0);
    s.received(NAV, boot + Duration::from_millis(100));
    s.poll_timers(boot + Duration::from_millis(100));
    assert_eq!(s.stats().state, LinkState::Up);
}

#[test]
fn a_set_up_that_never_ends_in_boot_is_handshaken_after_the_allowance() {
    let t0 = Instant::now();
    let mut s = opened(t0);
    s.received(b"Depth: Calibration constants are:\r\n", t0);
    let allowance = s.cfg.setup_allowance;
    let before = t0 + allowance - Duration::from_millis(1);
    assert_eq!(drain_writes(&mut s, before), []);
    s.poll_timers(before);
    assert_eq!(
        s.next_wake(before),
        (t0 + allowance).min(before + STATS_PERIOD)
    );
    assert_eq!(drain_writes(&mut s, t0 + allowance), HANDSHAKE);
}

#[test]
fn a_running_board_first_heard_mid_line_is_handshaken_at_the_boot_wait() {
    // Opened while the board runs: the first read may be the tail of a line
    // (torn), then telemetry follows; that is no set-up.
    let t0 = Instant::now();
    let mut s = opened(t0);
    s.received(b"00;yaw:10.00;fthr:0.00;\r\n", t0);
    s.received(NAV, t0 + Duration::from_millis(100));
    let boot_wait = s.cfg.boot_wait;
    assert_eq!(drain_writes(&mut s, t0 + boot_wait), HANDSHAKE);
}

#[test]
fn a_long_set_up_that_chatters_is_not_down_and_a_device_printing_only_noise_is() {
    // A set-up stretched to 4.5 s (a loaded simulator): it chatters, so the
    // link stays handshaking, not down, and comes up after its `boot`.
    let t0 = Instant::now();
    let mut s = opened(t0);
    assert_eq!(states(&mut s), [LinkState::Down, LinkState::Handshaking]);
    let mut at = t0;
    while at < t0 + Duration::from_millis(4500) {
        s.received(b"Depth: Calibration constants are:\r\n", at);
        s.poll_timers(at);
        drain_writes(&mut s, at);
        at += Duration::from_millis(500);
    }
    assert!(
        !states(&mut s).contains(&LinkState::Down),
        "down while the board chattered through its set-up"
    );
    s.received(b"boot:1;\r\n", at);
    drain_writes(&mut s, at);
    s.received(NAV, at + Duration::from_millis(100));
    s.poll_timers(at + Duration::from_millis(100));
    assert_eq!(s.stats().state, LinkState::Up);

    // A device that prints only what is not telemetry (a wrong baud rate)
    // is down once a set-up would have ended.
    let mut s = opened(t0);
    let mut at = t0;
    let end = t0 + s.cfg.setup_allowance + s.cfg.stale_after;
    while at <= end {
        s.received(b"\xf0\x0f\x81garbage\r\n", at);
        s.poll_timers(at);
        at += Duration::from_millis(100);
    }
    assert_eq!(s.stats().state, LinkState::Down);
}

#[test]
fn a_gap_just_short_of_the_dead_man_timeout_counts_as_one_that_tripped_it() {
    // The board's clock is not the link's: a gap of 1.8 s by the link's may
    // be 2 s by the board's, which then stopped and restarts on its last
    // target at the next ping.
    let t0 = Instant::now();
    let mut s = opened(t0);
    s.received(b"boot:1;\r\n", t0);
    s.healthy(t0);
    assert!(drain_writes(&mut s, t0).contains(&Command::Ping(0)));
    s.command(go(1700));
    let t = t0 + s.cfg.dead_man_timeout - Duration::from_millis(200);
    s.healthy(t);
    assert_eq!(
        drain_writes(&mut s, t),
        [go(NEUTRAL_US), Command::Ping(0)],
        "neutral before the ping, no stale go() after a gap near the timeout"
    );
    // A regular second between pings is no gap: thrust goes as usual.
    let t = t + Duration::from_secs(1);
    s.command(go(1600));
    s.healthy(t);
    let written = drain_writes(&mut s, t);
    assert!(written.contains(&go(1600)), "{written:?}");
    assert!(!written.contains(&go(NEUTRAL_US)), "{written:?}");
}

#[test]
fn a_talking_board_wakes_the_link_for_its_watchdog_not_for_the_figures() {
    let (mut s, t) = up(Instant::now());
    // No vehicle healthy: no ping is due; only the watchdog wakes the link,
    // just past the board's allowed silence or after a second — not every
    // 100 ms.
    let stale_after = s.cfg.stale_after;
    let watchdog =
        move |at: Instant| (at + stale_after + Duration::from_millis(1)).min(at + WATCHDOG_IDLE);
    assert_eq!(s.next_wake(t), watchdog(t));
    // The figures go out whenever the link runs, at most every 100 ms.
    let figures = |s: &mut Session| -> Vec<Option<u64>> {
        std::iter::from_fn(|| s.poll_output())
            .filter_map(|o| match o {
                Output::Stats(st) => Some(st.telemetry_age_ms),
                _ => None,
            })
            .collect()
    };
    figures(&mut s);
    let later = t + Duration::from_millis(150);
    s.poll_timers(later);
    assert_eq!(figures(&mut s), [Some(150)]);
    s.poll_timers(later + Duration::from_millis(50));
    assert_eq!(figures(&mut s), []);
    // A line moves the watchdog on.
    s.received(NAV, later);
    assert_eq!(s.next_wake(later), watchdog(later));
    // Silent past the allowance: down at the watchdog's wake, and from then
    // on a sleep of at most a second.
    let silent = later + stale_after + Duration::from_millis(1);
    s.poll_timers(silent);
    assert_eq!(s.stats().state, LinkState::Down);
    assert_eq!(s.next_wake(silent), silent + WATCHDOG_IDLE);
}
