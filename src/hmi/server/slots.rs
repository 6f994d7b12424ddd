//! The connection caps, in total and per client address, and the
//! rate-limited report of what they refuse.
//!
//! Owns [`Slots`] (a [`Slot`] is given back when dropped), what counts as one
//! client ([`address_key`]) and [`Refusals`]. Never logs per refused
//! connection.

use std::collections::HashMap;
use std::net::{IpAddr, Ipv6Addr};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::Limits;

/// Refused connections are summed up in the log at most this often.
const REFUSAL_LOG_PERIOD: Duration = Duration::from_secs(10);

/// Why a connection was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Full {
    Total,
    PerAddress,
}

/// Open connections, in all and per client address.
#[derive(Clone)]
pub(super) struct Slots {
    inner: Arc<Mutex<Counts>>,
    limits: Limits,
}

#[derive(Default)]
struct Counts {
    total: usize,
    per_address: HashMap<IpAddr, usize>,
}

/// One taken slot; given back when the connection's task ends (or is cut).
pub(super) struct Slot {
    slots: Slots,
    key: IpAddr,
}

impl Slots {
    pub(super) fn new(limits: Limits) -> Self {
        Self {
            inner: Arc::default(),
            limits,
        }
    }

    pub(super) fn take(&self, ip: IpAddr) -> Result<Slot, Full> {
        let key = address_key(ip);
        let mut c = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        if c.total >= self.limits.max_connections {
            return Err(Full::Total);
        }
        let mine = c.per_address.entry(key).or_insert(0);
        if *mine >= self.limits.max_connections_per_address {
            return Err(Full::PerAddress);
        }
        *mine += 1;
        c.total += 1;
        Ok(Slot {
            slots: self.clone(),
            key,
        })
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut c = self.slots.inner.lock().unwrap_or_else(|p| p.into_inner());
        c.total = c.total.saturating_sub(1);
        if let Some(n) = c.per_address.get_mut(&self.key) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                c.per_address.remove(&self.key);
            }
        }
    }
}

/// What counts as one client: an IPv4 address (IPv4-mapped IPv6 included),
/// or an IPv6 /64 (one host is routinely given a whole /64).
fn address_key(ip: IpAddr) -> IpAddr {
    match ip.to_canonical() {
        IpAddr::V4(v4) => IpAddr::V4(v4),
        IpAddr::V6(v6) => {
            let s = v6.segments();
            IpAddr::V6(Ipv6Addr::new(s[0], s[1], s[2], s[3], 0, 0, 0, 0))
        }
    }
}

/// Rate-limited reporting of a repeated condition: the first occurrence is
/// reported at once, then at most one line (with the count since the last)
/// per [`REFUSAL_LOG_PERIOD`]. Under attack, slots free up and are taken
/// again all the time, so there is no reliable "end of burst" to report.
#[derive(Default)]
pub(super) struct Refusals {
    /// Occurrences since the last report.
    unreported: u64,
    last_report: Option<Instant>,
}

impl Refusals {
    pub(super) fn note(&mut self, report: impl FnOnce(u64)) {
        self.unreported += 1;
        if self
            .last_report
            .is_none_or(|t| t.elapsed() >= REFUSAL_LOG_PERIOD)
        {
            report(self.unreported);
            self.unreported = 0;
            self.last_report = Some(Instant::now());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_hold_both_caps_and_come_back() {
        let slots = Slots::new(Limits {
            max_connections: 3,
            max_connections_per_address: 2,
            header_timeout: Duration::from_secs(1),
        });
        let a: IpAddr = "10.0.0.1".parse().expect("ip");
        let b: IpAddr = "10.0.0.2".parse().expect("ip");
        let c: IpAddr = "10.0.0.3".parse().expect("ip");
        let a1 = slots.take(a).expect("first");
        let _a2 = slots.take(a).expect("second");
        assert_eq!(slots.take(a).err(), Some(Full::PerAddress));
        let _b1 = slots.take(b).expect("b");
        assert_eq!(slots.take(c).err(), Some(Full::Total));
        drop(a1);
        let _c1 = slots.take(c).expect("a slot came back");
        assert_eq!(slots.take(a).err(), Some(Full::Total));
    }

    #[test]
    fn ipv4_mapped_and_ipv6_64_count_as_one_client() {
        let mapped: IpAddr = "::ffff:10.0.0.1".parse().expect("ip");
        assert_eq!(
            address_key(mapped),
            "10.0.0.1".parse::<IpAddr>().expect("ip")
        );
        let x: IpAddr = "2001:db8:1:2::1".parse().expect("ip");
        let y: IpAddr = "2001:db8:1:2:ffff::9".parse().expect("ip");
        let z: IpAddr = "2001:db8:1:3::1".parse().expect("ip");
        assert_eq!(address_key(x), address_key(y));
        assert_ne!(address_key(x), address_key(z));
    }

    #[test]
    fn refusals_report_once_per_period() {
        let mut r = Refusals::default();
        let mut reports = Vec::new();
        for _ in 0..100 {
            r.note(|n| reports.push(n));
        }
        assert_eq!(
            reports,
            vec![1],
            "one line for a burst, not one per connection"
        );
        assert_eq!(r.unreported, 99, "the rest are counted for the next line");
    }
}
