//! The login throttle: failed pilot logins per client address, with a
//! growing delay.
//!
//! Owns [`Throttle`] and what it tells the caller to do ([`Admit`]) and to log
//! ([`ThrottleNote`]). Takes `now` as an argument; bounded in memory whatever
//! it is sent, so no client can make it check more than a handful of
//! passwords per second.

use std::collections::HashMap;
use std::net::IpAddr;
use std::time::{Duration, Instant};

use super::bursts::BURST_QUIET;

/// Failed logins from one address that are checked without delay.
const FREE_FAILURES: u32 = 3;
/// The longest wait between checked attempts from one address.
const MAX_DELAY: Duration = Duration::from_secs(30);
/// An address's failures are forgotten after this much quiet.
const FORGET_AFTER: Duration = Duration::from_secs(600);
/// Addresses the throttle remembers (the oldest is evicted).
const THROTTLE_CAPACITY: usize = 1024;

/// The throttle's key for a client: its IPv4 address, or its IPv6 /64 (one
/// host may hold a whole /64, so per-address counting would not slow it).
pub fn throttle_key(ip: IpAddr) -> IpAddr {
    match ip.to_canonical() {
        IpAddr::V6(v6) => {
            let s = v6.segments();
            IpAddr::from([s[0], s[1], s[2], s[3], 0, 0, 0, 0])
        }
        v4 => v4,
    }
}

/// What the throttle says about a login attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admit {
    /// Check the password.
    Check,
    /// Too many failures: answer "wait" without checking.
    Wait(Duration),
}

/// What to log after a login attempt (at most a few lines per burst).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ThrottleNote {
    /// The first failure of a burst from this address.
    FirstFailure,
    /// A burst ended (quiet, or a success): failures checked and attempts
    /// refused unchecked while waiting.
    Summary {
        ip: IpAddr,
        failures: u64,
        waited: u64,
        over: Duration,
    },
}

#[derive(Debug, Clone)]
struct Failures {
    /// Failures since the last success (drives the delay).
    count: u32,
    blocked_until: Option<Instant>,
    last: Instant,
    /// The current burst: its start, failures checked and attempts refused
    /// unchecked; `None` once summarised.
    burst: Option<(Instant, u64, u64)>,
}

/// Failed pilot logins per client address, with a growing delay: the first
/// three (`FREE_FAILURES`) are free, then 1 s, 2 s, 4 s … up to 30 s between
/// checked attempts. Bounded: the oldest address is evicted.
#[derive(Debug, Default)]
pub struct Throttle {
    table: HashMap<IpAddr, Failures>,
}

impl Throttle {
    /// May an attempt from `ip` be checked now?
    pub fn admit(&mut self, ip: IpAddr, now: Instant) -> Admit {
        let Some(f) = self.table.get_mut(&ip) else {
            return Admit::Check;
        };
        f.last = now;
        match f.blocked_until {
            Some(until) if until > now => {
                if let Some(b) = f.burst.as_mut() {
                    b.2 += 1;
                } else {
                    f.burst = Some((now, 0, 1));
                }
                Admit::Wait(until - now)
            }
            _ => Admit::Check,
        }
    }

    /// A checked attempt failed; says whether it starts a burst (log it).
    pub fn failed(&mut self, ip: IpAddr, now: Instant) -> Option<ThrottleNote> {
        if !self.table.contains_key(&ip) && self.table.len() >= THROTTLE_CAPACITY {
            let oldest = self
                .table
                .iter()
                .min_by_key(|(_, f)| f.last)
                .map(|(k, _)| *k);
            if let Some(k) = oldest {
                self.table.remove(&k);
            }
        }
        let f = self.table.entry(ip).or_insert(Failures {
            count: 0,
            blocked_until: None,
            last: now,
            burst: None,
        });
        f.count += 1;
        f.last = now;
        if f.count >= FREE_FAILURES {
            let exp = (f.count - FREE_FAILURES).min(16);
            let delay = Duration::from_secs(1u64 << exp).min(MAX_DELAY);
            f.blocked_until = Some(now + delay);
        }
        match f.burst.as_mut() {
            Some(b) => {
                b.1 += 1;
                None
            }
            None => {
                f.burst = Some((now, 1, 0));
                Some(ThrottleNote::FirstFailure)
            }
        }
    }

    /// A checked attempt succeeded: the address starts afresh; the summary
    /// of its burst, if one was under way.
    pub fn succeeded(&mut self, ip: IpAddr) -> Option<ThrottleNote> {
        let f = self.table.remove(&ip)?;
        summary(ip, &f)
    }

    /// Summaries of bursts that went quiet; forgets long-quiet addresses.
    pub fn sweep(&mut self, now: Instant) -> Vec<ThrottleNote> {
        let mut notes = Vec::new();
        for (ip, f) in &mut self.table {
            if now.saturating_duration_since(f.last) >= BURST_QUIET
                && let Some(n) = summary(*ip, f)
            {
                notes.push(n);
                f.burst = None;
            }
        }
        self.table
            .retain(|_, f| now.saturating_duration_since(f.last) < FORGET_AFTER);
        notes
    }

    pub fn len(&self) -> usize {
        self.table.len()
    }

    pub fn is_empty(&self) -> bool {
        self.table.is_empty()
    }
}

fn summary(ip: IpAddr, f: &Failures) -> Option<ThrottleNote> {
    let (start, failures, waited) = f.burst?;
    Some(ThrottleNote::Summary {
        ip,
        failures,
        waited,
        over: f.last.saturating_duration_since(start),
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn throttle_grows_caps_and_resets() {
        let ip: IpAddr = "192.168.2.9".parse().unwrap();
        let t0 = Instant::now();
        let mut t = Throttle::default();
        // Three free failures, the first one logged.
        assert_eq!(t.admit(ip, t0), Admit::Check);
        assert_eq!(t.failed(ip, t0), Some(ThrottleNote::FirstFailure));
        assert_eq!(t.admit(ip, t0), Admit::Check);
        assert_eq!(t.failed(ip, t0), None);
        assert_eq!(t.admit(ip, t0), Admit::Check);
        t.failed(ip, t0);
        // Then 1 s, 2 s, 4 s … capped at 30 s.
        assert_eq!(t.admit(ip, t0), Admit::Wait(Duration::from_secs(1)));
        let mut now = t0 + Duration::from_secs(1);
        for expect in [2, 4, 8, 16, 30, 30] {
            assert_eq!(t.admit(ip, now), Admit::Check);
            assert_eq!(t.failed(ip, now), None);
            assert_eq!(t.admit(ip, now), Admit::Wait(Duration::from_secs(expect)));
            now += Duration::from_secs(expect);
        }
        // Another address is not affected.
        assert_eq!(t.admit("10.0.0.1".parse().unwrap(), now), Admit::Check);
        // Quiet: one summary, once.
        let later = now + BURST_QUIET;
        let notes = t.sweep(later);
        assert!(
            matches!(
                notes.as_slice(),
                [ThrottleNote::Summary {
                    failures: 9,
                    waited: 7,
                    ..
                }]
            ),
            "{notes:?}"
        );
        assert!(t.sweep(later).is_empty());
        // A success resets.
        assert_eq!(t.admit(ip, later + MAX_DELAY), Admit::Check);
        t.succeeded(ip);
        assert!(t.is_empty());
    }

    #[test]
    fn ipv6_hosts_are_throttled_per_64() {
        let a = throttle_key("2001:db8:1:2::5".parse().unwrap());
        let b = throttle_key("2001:db8:1:2:ffff::9".parse().unwrap());
        assert_eq!(a, b);
        assert_ne!(a, throttle_key("2001:db8:1:3::5".parse().unwrap()));
        let v4: IpAddr = "192.168.2.9".parse().unwrap();
        assert_eq!(throttle_key(v4), v4);
        assert_eq!(throttle_key("::ffff:192.168.2.9".parse().unwrap()), v4);
    }

    #[test]
    fn throttle_is_bounded() {
        let t0 = Instant::now();
        let mut t = Throttle::default();
        for i in 0..(THROTTLE_CAPACITY as u32 + 10) {
            t.failed(
                IpAddr::from(i.to_be_bytes()),
                t0 + Duration::from_millis(u64::from(i)),
            );
        }
        assert_eq!(t.len(), THROTTLE_CAPACITY);
    }
}
