//! The vehicle's addresses as ICE host candidates, and a UDP socket on
//! each: one socket per address, shared by every viewer (str0m tells the
//! datagrams apart), so str0m always knows which address a datagram came
//! in on and which it must leave from. A viewer is offered the address its
//! signalling connection reached when the vehicle knows it ([`Sockets::ensure`]).

use std::collections::BTreeMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::time::Instant;

use tokio::net::UdpSocket;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

/// Largest datagram read (WebRTC keeps under the path MTU).
const DATAGRAM_BYTES: usize = 2048;

/// A datagram that arrived on one of the media sockets.
pub(super) struct Inbound {
    pub at: Instant,
    pub local: SocketAddr,
    pub from: SocketAddr,
    pub data: Vec<u8>,
}

/// The addresses of the interfaces that are up, as candidates can use
/// them: IPv4 but link-local (str0m refuses 169.254/16), IPv6 but
/// link-local (it needs a scope id a candidate cannot carry). Loopback
/// last: a browser on the vehicle itself.
pub(super) fn host_addresses() -> Vec<IpAddr> {
    let Ok(addrs) = nix::ifaddrs::getifaddrs() else {
        return vec![IpAddr::from([127, 0, 0, 1])];
    };
    let mut out: Vec<IpAddr> = Vec::new();
    for a in addrs {
        let up = a.flags.contains(nix::net::if_::InterfaceFlags::IFF_UP);
        let ip = a.address.as_ref().and_then(|s| {
            s.as_sockaddr_in()
                .map(|v4| IpAddr::V4(v4.ip()))
                .or_else(|| s.as_sockaddr_in6().map(|v6| IpAddr::V6(v6.ip())))
        });
        let Some(ip) = ip.filter(|_| up) else {
            continue;
        };
        let usable = match ip {
            IpAddr::V4(v4) => !v4.is_link_local() && !v4.is_unspecified(),
            IpAddr::V6(v6) => (v6.segments()[0] & 0xffc0) != 0xfe80 && !v6.is_unspecified(),
        };
        if usable && !out.contains(&ip) {
            out.push(ip);
        }
    }
    out.sort_by_key(IpAddr::is_loopback);
    out
}

/// The media sockets, one per address, each with a reader task.
pub(super) struct Sockets {
    port: u16,
    by_local: BTreeMap<SocketAddr, Arc<UdpSocket>>,
    /// Addresses that could not be bound (logged once each).
    failed: Vec<IpAddr>,
    readers: Vec<JoinHandle<()>>,
    inbound: mpsc::Sender<Inbound>,
}

impl Sockets {
    /// `port`: the media port on every address (0: a free one each).
    pub(super) fn new(port: u16, inbound: mpsc::Sender<Inbound>) -> Self {
        Sockets {
            port,
            by_local: BTreeMap::new(),
            failed: Vec::new(),
            readers: Vec::new(),
            inbound,
        }
    }

    /// Binds a socket on each address that has none yet (a tether that
    /// came up after the start is used from the next viewer on) and gives
    /// the local address of every socket on a current address.
    pub(super) fn refresh(&mut self) -> Vec<SocketAddr> {
        let addrs = host_addresses();
        for ip in &addrs {
            if self.by_local.keys().any(|l| l.ip() == *ip) || self.failed.contains(ip) {
                continue;
            }
            self.bind_on(*ip);
        }
        self.by_local
            .keys()
            .filter(|l| addrs.contains(&l.ip()))
            .copied()
            .collect()
    }

    /// The socket on `ip` (an address of this machine: a viewer reached it),
    /// bound now if there is none yet (a loopback alias is on no
    /// interface's list); `None` when it cannot be bound.
    pub(super) fn ensure(&mut self, ip: IpAddr) -> Option<SocketAddr> {
        let ip = ip.to_canonical();
        if ip.is_unspecified() {
            return None;
        }
        if let Some(local) = self.by_local.keys().find(|l| l.ip() == ip) {
            return Some(*local);
        }
        if self.failed.contains(&ip) {
            return None;
        }
        self.bind_on(ip);
        self.by_local.keys().find(|l| l.ip() == ip).copied()
    }

    /// Binds a socket on `ip` with its reader, or notes that it cannot.
    fn bind_on(&mut self, ip: IpAddr) {
        match bind(SocketAddr::new(ip, self.port)) {
            Ok(sock) => {
                let local = sock.local_addr().unwrap_or(SocketAddr::new(ip, self.port));
                tracing::info!(%local, "WebRTC: media socket");
                let sock = Arc::new(sock);
                self.readers.push(tokio::spawn(read(
                    Arc::clone(&sock),
                    local,
                    self.inbound.clone(),
                )));
                self.by_local.insert(local, sock);
            }
            Err(e) => {
                tracing::warn!(
                    "WebRTC: cannot bind UDP {ip}:{} ({e}) — viewers cannot use this address{}",
                    self.port,
                    if self.port == 0 {
                        ""
                    } else {
                        "; check camera.webrtc.udp_port"
                    }
                );
                self.failed.push(ip);
            }
        }
    }

    /// The local address of every socket.
    pub(super) fn locals(&self) -> Vec<SocketAddr> {
        self.by_local.keys().copied().collect()
    }

    /// Sends without waiting: a datagram that does not fit the socket's
    /// buffer now is dropped (WebRTC recovers; a waiting sender would hold
    /// every viewer up). False when it was not sent.
    pub(super) fn send(&self, from: SocketAddr, to: SocketAddr, data: &[u8]) -> bool {
        self.by_local
            .get(&from)
            .is_some_and(|s| s.try_send_to(data, to).is_ok())
    }
}

impl Drop for Sockets {
    fn drop(&mut self) {
        for r in &self.readers {
            r.abort();
        }
    }
}

fn bind(addr: SocketAddr) -> std::io::Result<UdpSocket> {
    let sock = std::net::UdpSocket::bind(addr)?;
    sock.set_nonblocking(true)?;
    UdpSocket::from_std(sock)
}

async fn read(sock: Arc<UdpSocket>, local: SocketAddr, to: mpsc::Sender<Inbound>) {
    let mut buf = vec![0u8; DATAGRAM_BYTES];
    loop {
        match sock.recv_from(&mut buf).await {
            Ok((n, from)) => {
                let d = Inbound {
                    at: Instant::now(),
                    local,
                    from,
                    data: buf[..n].to_vec(),
                };
                // A full queue drops: the hub is behind, old datagrams help nobody.
                if let Err(mpsc::error::TrySendError::Closed(_)) = to.try_send(d) {
                    return;
                }
            }
            // ICMP port unreachable and the like: the socket goes on.
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
            Err(e) => {
                tracing::warn!(%local, "WebRTC: media socket read failed: {e}");
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        }
    }
}
