//! Where `auto` sends the video: [`GroundStations`] remembers the address
//! each ground station was last heard from on a UDP endpoint, and picks the
//! one in control, else the first one heard that is still there.
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
struct Station {
    sysid: u8,
    addr: SocketAddr,
    last_heard: Duration,
}

/// Ground stations heard on UDP endpoints, in the order first heard.
#[derive(Debug, Clone, Default)]
pub struct GroundStations {
    /// At most one entry per system id (256).
    heard: Vec<Station>,
}

impl GroundStations {
    /// A ground station's HEARTBEAT from `addr` at `now` (time since any
    /// fixed start). A station that moved keeps its place in the order.
    pub fn heard(&mut self, sysid: u8, addr: SocketAddr, now: Duration) {
        match self.heard.iter_mut().find(|s| s.sysid == sysid) {
            Some(s) => {
                s.addr = addr;
                s.last_heard = now;
            }
            None => self.heard.push(Station {
                sysid,
                addr,
                last_heard: now,
            }),
        }
    }

    /// The address video goes to: the station in control (`owner`), else
    /// the first heard; stations silent for [`STATION_TIMEOUT`] are
    /// forgotten first.
    pub fn target(&mut self, owner: Option<u8>, now: Duration) -> Option<IpAddr> {
        self.heard
            .retain(|s| now.saturating_sub(s.last_heard) < STATION_TIMEOUT);
        owner
            .and_then(|o| self.heard.iter().find(|s| s.sysid == o))
            .or_else(|| self.heard.first())
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

    #[test]
    fn owner_first_then_first_heard_then_nobody() {
        let mut g = GroundStations::default();
        assert_eq!(g.target(None, at(0)), None);
        g.heard(255, addr("10.0.0.2:14550"), at(0));
        g.heard(200, addr("10.0.0.3:14550"), at(10));
        assert_eq!(g.target(None, at(20)), Some(ip("10.0.0.2")));
        assert_eq!(g.target(Some(200), at(20)), Some(ip("10.0.0.3")));
        // An owner heard only elsewhere (TCP): the first UDP station.
        assert_eq!(g.target(Some(7), at(20)), Some(ip("10.0.0.2")));
        // The first one moves: video follows it.
        g.heard(255, addr("10.0.0.9:40000"), at(5_000));
        assert_eq!(g.target(None, at(5_000)), Some(ip("10.0.0.9")));
        // 200 goes silent and is forgotten; then 255 too.
        assert_eq!(g.target(Some(200), at(10_010)), Some(ip("10.0.0.9")));
        assert_eq!(g.target(None, at(15_000)), None);
    }
}
