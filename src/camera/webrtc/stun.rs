//! The vehicle's public address, asked of the configured STUN servers
//! (`[camera.webrtc] ice_servers`, the `stun:` ones) from each media
//! socket: a server-reflexive candidate lets a viewer beyond a NAT reach
//! the vehicle. On a tether none is configured and nothing is sent.
//!
//! A binding request (RFC 8489, built and parsed by str0m's STUN code)
//! goes out every 30 s until a server answers, then every 5 minutes (NAT
//! mappings expire). Names are looked up off the runtime's thread
//! (`tokio::net::lookup_host`) and looked up again at each round.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use str0m::Candidate;
use str0m::ice::{StunMessage, StunMessageBuilder, TransId};

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
    pending: BTreeMap<TransId, SocketAddr>,
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
                let id = TransId::new();
                let mut buf = [0u8; 64];
                let msg = StunMessageBuilder::new().binding().request().build(id);
                // No integrity: a STUN server answers anyone.
                let Ok(n) = msg.to_bytes(None, &mut buf, |_, _| [0; 20]) else {
                    continue;
                };
                if sockets.send(local, *server, &buf[..n]) {
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
        let msg = StunMessage::parse(&d.data).ok()?;
        if !msg.is_successful_binding_response() {
            return None;
        }
        let local = self.pending.remove(&msg.trans_id())?;
        let public = msg.mapped_address()?;
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
