//! Where `auto` sends the video: [`GroundStations`] remembers the address
//! each ground station that may control the vehicle was last heard from on
//! a UDP endpoint, and picks the one in control, else the first heard of
//! those that still may control — never a station that may only watch.
//!
//! Who may control is not decided here: the app records a station only
//! when the vehicle core says it may control (an allowed system id, its
//! frame signed when signing is on), and asks the core again, through the
//! `may_control` it passes to [`GroundStations::target`], whenever it
//! picks (signing may have been turned on, the allowed ids changed). So an
//! unsigned stranger using the pilot's system id from another address
//! cannot move the video while signing is on, and a station outside the
//! allowed ids never gets it.
//!
//! Pure: time is an argument, nothing here touches a socket or a clock. It
//! only knows stations the vehicle already sends telemetry to, so `auto`
//! never sends video to an address that could not see the vehicle anyway.

use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

/// A station not heard for this long is forgotten (a peer's timeout on a
/// UDP endpoint is 10 s by default).
pub const STATION_TIMEOUT: Duration = Duration::from_secs(10);

#[derive(Debug, Clone)]
struct Station<S> {
    sysid: u8,
    addr: SocketAddr,
    last_heard: Duration,
    /// How its last recorded frame came (the core's `Sender`): what
    /// `may_control` is asked about.
    sender: S,
}

/// Ground stations that may control, heard on UDP endpoints, in the order
/// first heard. `S` is how a frame came, as the vehicle core judges it.
#[derive(Debug, Clone)]
pub struct GroundStations<S> {
    /// At most one entry per system id (256).
    heard: Vec<Station<S>>,
}

impl<S> Default for GroundStations<S> {
    fn default() -> Self {
        Self { heard: Vec::new() }
    }
}

impl<S> GroundStations<S> {
    /// A HEARTBEAT from ground station `sysid` at `addr` at `now` (time
    /// since any fixed start), which the core said may control: the caller
    /// records no other. A station that moved keeps its place in the order.
    pub fn heard(&mut self, sysid: u8, sender: S, addr: SocketAddr, now: Duration) {
        match self.heard.iter_mut().find(|s| s.sysid == sysid) {
            Some(s) => {
                s.addr = addr;
                s.last_heard = now;
                s.sender = sender;
            }
            None => self.heard.push(Station {
                sysid,
                addr,
                last_heard: now,
                sender,
            }),
        }
    }

    /// The address video goes to: the station in control (`owner`) if it
    /// is heard on UDP, else the first heard; only stations `may_control`
    /// still admits count, and stations silent for [`STATION_TIMEOUT`] are
    /// forgotten first.
    pub fn target(
        &mut self,
        owner: Option<u8>,
        now: Duration,
        may_control: impl Fn(&S) -> bool,
    ) -> Option<IpAddr> {
        self.heard
            .retain(|s| now.saturating_sub(s.last_heard) < STATION_TIMEOUT);
        let mut admitted = self.heard.iter().filter(|s| may_control(&s.sender));
        owner
            .and_then(|o| admitted.clone().find(|s| s.sysid == o))
            .or_else(|| admitted.next())
            .map(|s| s.addr.ip())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    fn ip(s: &str) -> IpAddr {
        s.parse().expect("ip")
    }

    fn addr(s: &str) -> SocketAddr {
        s.parse().expect("addr")
    }

    fn anyone(_: &bool) -> bool {
        true
    }

    #[test]
    fn owner_first_then_first_heard_then_nobody() {
        let mut g = GroundStations::default();
        assert_eq!(g.target(None, at(0), anyone), None);
        g.heard(255, true, addr("10.0.0.2:14550"), at(0));
        g.heard(200, true, addr("10.0.0.3:14550"), at(10));
        assert_eq!(g.target(None, at(20), anyone), Some(ip("10.0.0.2")));
        assert_eq!(g.target(Some(200), at(20), anyone), Some(ip("10.0.0.3")));
        // An owner heard only elsewhere (TCP): the first UDP station.
        assert_eq!(g.target(Some(7), at(20), anyone), Some(ip("10.0.0.2")));
        // The first one moves: video follows it.
        g.heard(255, true, addr("10.0.0.9:40000"), at(5_000));
        assert_eq!(g.target(None, at(5_000), anyone), Some(ip("10.0.0.9")));
        // 200 goes silent and is forgotten; then 255 too.
        assert_eq!(
            g.target(Some(200), at(10_010), anyone),
            Some(ip("10.0.0.9"))
        );
        assert_eq!(g.target(None, at(15_000), anyone), None);
    }

    /// The verdict is asked again at every pick: a station the vehicle no
    /// longer lets control (signing turned on, its id no longer allowed)
    /// loses the video at once, to the owner or the next that may.
    #[test]
    fn only_stations_that_may_still_control_count() {
        // The sender: whether its frames were signed.
        let signing_on = |signed: &bool| *signed;
        let mut g = GroundStations::default();
        g.heard(7, false, addr("10.0.0.7:14550"), at(0));
        g.heard(255, true, addr("10.0.0.2:14550"), at(10));
        assert_eq!(g.target(None, at(20), anyone), Some(ip("10.0.0.7")));
        assert_eq!(g.target(None, at(20), signing_on), Some(ip("10.0.0.2")));
        // The owner itself, once its frames no longer count: the next one.
        g.heard(255, false, addr("10.0.0.2:14550"), at(30));
        g.heard(7, true, addr("10.0.0.7:14550"), at(30));
        assert_eq!(
            g.target(Some(255), at(40), signing_on),
            Some(ip("10.0.0.7"))
        );
        assert_eq!(g.target(Some(255), at(40), |_: &bool| false), None);
    }
}
