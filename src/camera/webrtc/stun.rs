//! The vehicle's public address, asked of the configured STUN servers
//! (`[camera.webrtc] ice_servers`, the `stun:` ones) from each media
//! socket: a server-reflexive candidate lets a viewer beyond a NAT reach
//! the vehicle. On a tether none is configured and nothing is sent.
//!
//! A binding request (RFC 8489: a bare 20-byte header) goes out every 30 s
//! until a server answers, then every 5 minutes (NAT mappings expire).
//! Names are looked up off the runtime's thread (`tokio::net::lookup_host`)
//! and looked up again at each round. The answer is read here: str0m's own
//! STUN parser is for ICE and refuses a binding answer without
//! MESSAGE-INTEGRITY, which a STUN server's answer to anyone has not. Only
//! an answer to a request of ours counts; anything else is not ours.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use str0m::Candidate;

use super::net::{Inbound, Sockets};

const RETRY: Duration = Duration::from_secs(30);
const REFRESH: Duration = Duration::from_secs(300);
const LOOKUP: Duration = Duration::from_secs(2);

/// The STUN side of the media sockets.
pub(super) struct Reflexive {
    servers: Vec<(String, u16)>,
    /// The servers' addresses, as the last lookup gave them.
    resolved: Arc<Mutex<Vec<SocketAddr>>>,
    /// Requests in flight: transaction → the local socket it left from.
    pending: BTreeMap<[u8; 12], SocketAddr>,
    /// Public address per local socket.
    mapped: BTreeMap<SocketAddr, SocketAddr>,
    next: Option<Instant>,
}

impl Reflexive {
    /// `servers`: the `stun:` servers' hosts and ports.
    pub(super) fn new(servers: Vec<(String, u16)>, now: Instant) -> Self {
        let next = (!servers.is_empty()).then_some(now);
        Reflexive {
            servers,
            resolved: Arc::new(Mutex::new(Vec::new())),
            pending: BTreeMap::new(),
            mapped: BTreeMap::new(),
            next,
        }
    }

    pub(super) fn next_timeout(&self) -> Option<Instant> {
        self.next
    }

    /// Sends a round of binding requests when one is due, and looks the
    /// servers up again for the next round.
    pub(super) fn timeout(&mut self, now: Instant, sockets: &Sockets) {
        if self.next.is_none_or(|d| d > now) {
            return;
        }
        self.pending.clear();
        let servers = self.resolved.lock().map(|r| r.clone()).unwrap_or_default();
        for local in sockets.locals() {
            for server in servers.iter().filter(|s| s.is_ipv4() == local.is_ipv4()) {
                let id: [u8; 12] = rand::random();
                if sockets.send(local, *server, &binding_request(id)) {
                    self.pending.insert(id, local);
                }
            }
        }
        self.next = Some(
            now + if servers.is_empty() {
                // The first lookup is still on its way.
                LOOKUP
            } else if self.mapped.is_empty() {
                RETRY
            } else {
                REFRESH
            },
        );
        let (servers, resolved) = (self.servers.clone(), Arc::clone(&self.resolved));
        tokio::spawn(async move {
            let mut found = Vec::new();
            for (host, port) in servers {
                match tokio::net::lookup_host((host.as_str(), port)).await {
                    Ok(addrs) => found.extend(addrs),
                    Err(e) => tracing::debug!("WebRTC: STUN server {host}:{port}: {e}"),
                }
            }
            if let Ok(mut r) = resolved.lock() {
                *r = found;
            }
        });
    }

    /// Takes a STUN server's answer to one of our requests: `None` when
    /// the datagram is not one, else whether it told a new address.
    pub(super) fn take(&mut self, d: &Inbound) -> Option<bool> {
        if self.pending.is_empty() {
            return None;
        }
        let (id, public) = parse_binding_success(&d.data)?;
        let local = self.pending.remove(&id)?;
        let new = self.mapped.insert(local, public) != Some(public);
        if new {
            tracing::info!(%local, %public, "WebRTC: public address from STUN");
        }
        Some(new)
    }

    /// A server-reflexive candidate for each socket whose public address
    /// is not its own.
    pub(super) fn candidates(&self) -> Vec<Candidate> {
        self.mapped
            .iter()
            .filter(|(local, public)| local != public)
            .filter_map(|(local, public)| Candidate::server_reflexive(*public, *local, "udp").ok())
            .collect()
    }
}

const MAGIC: [u8; 4] = [0x21, 0x12, 0xa4, 0x42];
const BINDING_REQUEST: u16 = 0x0001;
const BINDING_SUCCESS: u16 = 0x0101;
const XOR_MAPPED_ADDRESS: u16 = 0x0020;

/// A binding request without attributes.
pub(crate) fn binding_request(id: [u8; 12]) -> [u8; 20] {
    let mut m = [0u8; 20];
    m[..2].copy_from_slice(&BINDING_REQUEST.to_be_bytes());
    m[4..8].copy_from_slice(&MAGIC);
    m[8..].copy_from_slice(&id);
    m
}

/// The transaction and the XOR-MAPPED-ADDRESS of a binding success answer;
/// `None` for anything else (other messages, short or damaged ones).
pub(crate) fn parse_binding_success(m: &[u8]) -> Option<([u8; 12], SocketAddr)> {
    let header = m.get(..20)?;
    let len = usize::from(u16::from_be_bytes([header[2], header[3]]));
    if u16::from_be_bytes([header[0], header[1]]) != BINDING_SUCCESS
        || header[4..8] != MAGIC
        || m.len() != 20 + len
    {
        return None;
    }
    let mut id = [0u8; 12];
    id.copy_from_slice(&header[8..20]);
    let mut attrs = &m[20..];
    while attrs.len() >= 4 {
        let kind = u16::from_be_bytes([attrs[0], attrs[1]]);
        let n = usize::from(u16::from_be_bytes([attrs[2], attrs[3]]));
        let value = attrs.get(4..4 + n)?;
        if kind == XOR_MAPPED_ADDRESS {
            return xor_address(value, &id).map(|a| (id, a));
        }
        // Attributes are padded to four bytes.
        attrs = attrs.get(4 + n.div_ceil(4) * 4..)?;
    }
    None
}

fn xor_address(v: &[u8], id: &[u8; 12]) -> Option<SocketAddr> {
    let port = u16::from_be_bytes([*v.get(2)?, *v.get(3)?]) ^ 0x2112;
    let mut key = [0u8; 16];
    key[..4].copy_from_slice(&MAGIC);
    key[4..].copy_from_slice(id);
    let ip = match (v.get(1)?, v.len()) {
        (1, 8) => {
            let a: [u8; 4] = std::array::from_fn(|i| v[4 + i] ^ key[i]);
            std::net::IpAddr::from(a)
        }
        (2, 20) => {
            let a: [u8; 16] = std::array::from_fn(|i| v[4 + i] ^ key[i]);
            std::net::IpAddr::from(a)
        }
        _ => return None,
    };
    Some(SocketAddr::new(ip, port))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        let s: String = s.split_whitespace().collect();
        (0..s.len())
            .step_by(2)
            .filter_map(|i| u8::from_str_radix(&s[i..i + 2], 16).ok())
            .collect()
    }

    /// RFC 5769's sample IPv4 answer (SOFTWARE, XOR-MAPPED-ADDRESS
    /// 192.0.2.1:32853, MESSAGE-INTEGRITY, FINGERPRINT).
    const IPV4: &str = "0101 003c 2112a442 b7e7a701 bc34d686 fa87dfae
        8022 000b 74657374 20766563 746f7220
        0020 0008 0001a147 e112a643
        0008 0014 2b91f599 fd9e90c3 8c7489f9 2af9ba53 f06be7d7
        8028 0004 c07d4c96";

    #[test]
    fn the_mapped_address_is_read_from_a_servers_answer() {
        let (id, addr) = parse_binding_success(&hex(IPV4)).expect("answer");
        assert_eq!(id[..4], [0xb7, 0xe7, 0xa7, 0x01]);
        assert_eq!(addr, "192.0.2.1:32853".parse().expect("addr"));
        // The same with an IPv6 address (RFC 5769's second sample).
        let v6 = hex("0101 0048 2112a442 b7e7a701 bc34d686 fa87dfae
             8022 000b 74657374 20766563 746f7220
             0020 0014 0002a147 0113a9fa a5d3f179 bc25f4b5 bed2b9d9
             0008 0014 00000000 00000000 00000000 00000000 00000000
             8028 0004 00000000");
        let (_, addr) = parse_binding_success(&v6).expect("answer");
        assert_eq!(
            addr,
            "[2001:db8:1234:5678:11:2233:4455:6677]:32853"
                .parse()
                .expect("addr")
        );
    }

    #[test]
    fn anything_else_is_not_an_answer() {
        let good = hex(IPV4);
        assert!(parse_binding_success(&binding_request([7; 12])).is_none());
        for cut in [0, 4, 19, 20, 40, good.len() - 1] {
            assert!(parse_binding_success(&good[..cut]).is_none(), "{cut}");
        }
        let mut bad_magic = good.clone();
        bad_magic[4] = 0;
        assert!(parse_binding_success(&bad_magic).is_none());
        // An attribute longer than the message.
        let mut long = good.clone();
        long[22] = 0xff;
        assert!(parse_binding_success(&long).is_none());
        // Random bytes never panic.
        for seed in 0..2000u32 {
            let bytes: Vec<u8> = (0..(seed % 64))
                .map(|i| (seed.wrapping_mul(2_654_435_761).wrapping_add(i * 40_503) >> 7) as u8)
                .collect();
            let _ = parse_binding_success(&bytes);
        }
    }

    #[test]
    fn a_request_is_a_bare_binding_header() {
        let r = binding_request([9; 12]);
        assert_eq!(r[..8], [0, 1, 0, 0, 0x21, 0x12, 0xa4, 0x42]);
        assert_eq!(r[8..], [9; 12]);
    }
}
