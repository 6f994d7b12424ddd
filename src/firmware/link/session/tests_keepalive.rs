//! A lost ping never ends a dive, and a stopped vehicle still stops the
//! board: the keep-alive against a model of the firmware's dead-man
//! (`DeadManSwitch.cpp`: a `ping` resets its timer; more than 2,000 ms
//! without one — its `Timer::elapsed` is strict — and it stops the
//! thrusters), with synthetic time.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use super::tests::{NAV, go, rawcmd, up};

use super::*;

const MS: Duration = Duration::from_millis(1);
const DEAD_MAN: Duration = Duration::from_millis(2000);

/// The board's dead-man, fed by the pings it reads.
struct DeadMan {
    last_ping: Instant,
    trips: Vec<Instant>,
    /// How many of the pings read it has taken.
    fed: usize,
}

impl DeadMan {
    fn new(now: Instant) -> Self {
        Self {
            last_ping: now,
            trips: Vec::new(),
            fed: 0,
        }
    }
    fn ping(&mut self, at: Instant) {
        self.last_ping = at;
    }
    /// Checked as often as the board's loop runs.
    fn check(&mut self, now: Instant) {
        if now.duration_since(self.last_ping) > DEAD_MAN
            && self.trips.last() < Some(&self.last_ping)
        {
            self.trips.push(now);
        }
    }
}

/// What one run of the link against a board model did.
struct Run {
    /// When each ping was written, and when the board read one whole.
    pings_written: Vec<Instant>,
    pings_read: Vec<Instant>,
    trips: Vec<Instant>,
    stats: LinkStats,
}

/// Whether one of `len` bytes is hit, each with a chance of one in
/// `one_in` (0: never).
fn hit(rng: &mut SmallRng, len: usize, one_in: u32) -> bool {
    one_in > 0 && (0..len).any(|_| rng.random_ratio(1, one_in))
}

/// `secs` of a pilot driving (a new `go()` every 40 ms, the vehicle task
/// healthy every 50 ms, lights now and then) through a line that flips a
/// bit in one byte in `flip_in` and loses one in `lose_in` (0: never),
/// each way: a frame with a flipped byte is rejected (`crc:fail`), one with
/// a lost byte is never read; an echo with a damaged byte is not
/// recognised. The board reads and echoes a frame 2 ms after it is written.
fn drive(secs: u64, flip_in: u32, lose_in: u32, seed: u64) -> Run {
    let mut rng = SmallRng::seed_from_u64(seed);
    let (mut s, t0) = up(Instant::now());
    let mut board = DeadMan::new(t0);
    let mut pending: VecDeque<(Instant, Vec<u8>)> = VecDeque::new();
    let mut pings_written = Vec::new();
    let mut pings_read = Vec::new();
    let end = t0 + Duration::from_secs(secs);
    let mut now = t0;
    let mut frame = Vec::new();
    let mut step = 0u64;
    while now < end {
        now += 5 * MS;
        step += 1;
        if step.is_multiple_of(10) {
            s.healthy(now);
        }
        if step.is_multiple_of(8) {
            s.command(go(1500 + 10 * (step / 8 % 30) as u16));
        }
        if step.is_multiple_of(997) {
            s.command(Command::Lights((step % 200) as u8));
        }
        if step.is_multiple_of(20) {
            s.received(NAV, now);
        }
        while let Some((_, line)) = pending
            .front()
            .is_some_and(|(at, _)| *at <= now)
            .then(|| pending.pop_front())
            .flatten()
        {
            s.received(&line, now);
        }
        board.check(now);
        s.poll_timers(now);
        while let Some(cmd) = s.poll_transmit(now, &mut frame) {
            s.transmitted(&cmd, frame.len(), now);
            let ping = cmd == Command::Ping(0);
            if ping {
                pings_written.push(now);
            }
            if hit(&mut rng, frame.len(), lose_in) {
                continue;
            }
            let read_at = now + 2 * MS;
            if hit(&mut rng, frame.len(), flip_in) {
                pending.push_back((read_at, b"crc:fail,9E/9F;\r\n".to_vec()));
                continue;
            }
            if ping {
                pings_read.push(read_at);
            }
            let mut echo = rawcmd(&frame);
            if hit(&mut rng, echo.len(), flip_in) {
                let i = rng.random_range(0..echo.len() - 2);
                echo[i] ^= 1 << rng.random_range(0..8);
            }
            pending.push_back((read_at, echo));
        }
        // The board reads what reached it by now.
        while let Some(&p) = pings_read.get(board.fed) {
            if p > now {
                break;
            }
            board.ping(p);
            board.fed += 1;
        }
    }
    Run {
        pings_written,
        pings_read,
        trips: board.trips,
        stats: s.stats().clone(),
    }
}

/// The longest time between two successive instants of `v`.
fn widest(v: &[Instant]) -> Duration {
    v.windows(2)
        .map(|w| w[1].duration_since(w[0]))
        .max()
        .unwrap_or_default()
}

#[test]
fn the_dead_man_window_holds_five_pings_and_three_lost_in_a_row_leave_it_fed() {
    let run = drive(60, 0, 0, 1);
    let pings = &run.pings_written;
    assert!(pings.len() >= 149, "{} pings in 60 s", pings.len());
    // Every 400 ms, whatever else the pilot's driving writes.
    let widest = widest(pings);
    assert!(
        widest <= Duration::from_millis(410),
        "pings {widest:?} apart"
    );
    // So any 2-s window holds at least four, and with any three lost in a
    // row the board still reads one within its 2 s.
    for (i, w) in pings.windows(5).enumerate() {
        let fed_after_three_lost = w[4].duration_since(w[0]);
        assert!(
            fed_after_three_lost < DEAD_MAN - Duration::from_millis(300),
            "pings {i}..{}: {fed_after_three_lost:?} with three lost",
            i + 4
        );
    }
    let last = *pings.last().expect("pings");
    for (i, &start) in pings.iter().enumerate() {
        let window_end = start + DEAD_MAN;
        if window_end > last {
            break;
        }
        let held = pings[i..].iter().take_while(|&&p| p < window_end).count();
        assert!(held >= 5, "the 2 s from ping {i} hold {held} pings");
    }
    assert!(run.trips.is_empty());
}

#[test]
fn on_the_noisy_line_the_dead_man_never_trips_in_ten_minutes() {
    // One byte in 400 with a bit flipped and one in 2,000 lost, each way.
    let run = drive(600, 400, 2000, 37);
    let stats = &run.stats;
    assert!(
        stats.crc_failures_echoed > 0 && stats.echoes_missed > 0,
        "the line damaged nothing: {stats:?}"
    );
    let lost = run.pings_written.len() - run.pings_read.len();
    assert!(lost > 0, "no ping was lost");
    assert!(
        run.trips.is_empty(),
        "the board's dead-man tripped at {:?} ({lost} of {} pings lost)",
        run.trips,
        run.pings_written.len()
    );
    // A ping waits behind frames whose echoes were lost only until the
    // oldest is overdue (it then has room of its own), not for their echo
    // timeout.
    let written = widest(&run.pings_written);
    assert!(
        written <= Duration::from_millis(410) + super::outbox::ECHO_OVERDUE,
        "the pings were held back: {written:?} apart"
    );
    let read = widest(&run.pings_read);
    assert!(read < DEAD_MAN, "{read:?} between two pings the board read");
}

#[test]
fn a_vehicle_that_stops_stops_the_pings_and_the_dead_man_trips_within_its_window() {
    let (mut s, t) = up(Instant::now());
    let mut board = DeadMan::new(t);
    let mut frame = Vec::new();
    let mut last_ping = None;
    let stops_at = t + Duration::from_secs(5);
    let mut now = t;
    while now < t + Duration::from_secs(10) {
        now += 5 * MS;
        // The vehicle task's signs of life stop at `stops_at`.
        if now <= stops_at {
            s.healthy(now);
        }
        s.received(NAV, now);
        s.poll_timers(now);
        while let Some(cmd) = s.poll_transmit(now, &mut frame) {
            s.transmitted(&cmd, frame.len(), now);
            if cmd == Command::Ping(0) {
                last_ping = Some(now);
                board.ping(now);
            }
            s.received(&rawcmd(&frame), now);
        }
        board.check(now);
    }
    let last_ping = last_ping.expect("pings while the vehicle lived");
    assert!(
        last_ping <= stops_at + s.cfg.healthy_window,
        "a ping {:?} after the vehicle stopped",
        last_ping.duration_since(stops_at)
    );
    let [trip] = board.trips[..] else {
        panic!("the dead-man tripped {} times", board.trips.len());
    };
    let after_last = trip.duration_since(last_ping);
    assert!(
        after_last > DEAD_MAN && after_last <= DEAD_MAN + 10 * MS,
        "tripped {after_last:?} after the last ping"
    );
    assert!(trip.duration_since(stops_at) <= s.cfg.healthy_window + DEAD_MAN + 10 * MS);
}
