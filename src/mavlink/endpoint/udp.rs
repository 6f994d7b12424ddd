//! UDP endpoints (`udpin`, `udpout`): one socket, and a table of peers keyed
//! by source address.
//!
//! Owns the peer table: admitting a sender of valid MAVLink, evicting the
//! least recently heard peer that may not control when the table is full,
//! expiring peers after the peer timeout, and sending each queued frame to
//! the peers it is for. It must never make a peer of a datagram that is not
//! MAVLink: a port scan or a stray packet must not start a telemetry stream.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::UdpSocket;
use tokio::sync::{mpsc, watch};
use tokio::time::{Instant, MissedTickBehavior};

use super::context::{EndpointCtx, MAX_PEERS, Queued, Target, stopped};
use super::types::{PeerId, PeerStanding};
use crate::mavlink::frame::{FrameStats, decode_datagram};

/// The most bytes of MAVLink in one datagram: whole frames only, and inside
/// the smallest MTU IPv6 guarantees (1280 bytes less the IPv6 and UDP
/// headers), so no datagram is fragmented on the way to a station.
const DATAGRAM_MAX: usize = 1232;

/// The most queued frames gathered into one round of sends: one tick's
/// worth is a few dozen; a parameter list or a burst is sent in rounds, so
/// the socket's receive side is served in between.
const GATHER_MAX: usize = 64;

/// One datagram to send: whole frames for one destination.
#[derive(Debug)]
struct Datagram {
    dest: SocketAddr,
    bytes: Vec<u8>,
    frames: usize,
}

impl Datagram {
    fn empty(dest: SocketAddr) -> Datagram {
        Datagram {
            dest,
            bytes: Vec::with_capacity(DATAGRAM_MAX),
            frames: 0,
        }
    }
}

/// Packs frames into datagrams per destination, in order: each
/// destination's frames arrive in the order they were queued, and a frame
/// never straddles two datagrams.
#[derive(Debug, Default)]
struct Packer {
    /// Filled datagrams, in the order they filled.
    full: Vec<Datagram>,
    /// The datagram being filled for each destination.
    open: Vec<Datagram>,
}

impl Packer {
    fn add(&mut self, dest: SocketAddr, frame: &[u8]) {
        let i = match self.open.iter().position(|d| d.dest == dest) {
            Some(i) => i,
            None => {
                self.open.push(Datagram::empty(dest));
                self.open.len() - 1
            }
        };
        let d = &mut self.open[i];
        if d.frames > 0 && d.bytes.len() + frame.len() > DATAGRAM_MAX {
            self.full.push(std::mem::replace(d, Datagram::empty(dest)));
        }
        let d = &mut self.open[i];
        d.bytes.extend_from_slice(frame);
        d.frames += 1;
    }

    /// Every datagram, filled ones first (a destination's filled datagrams
    /// hold its earlier frames); the packer is empty after.
    fn drain(&mut self) -> impl Iterator<Item = Datagram> + '_ {
        self.full.drain(..).chain(self.open.drain(..))
    }
}

struct UdpPeer {
    id: PeerId,
    last_seen: Instant,
    standing: PeerStanding,
}

/// The peer for a datagram of valid MAVLink from `from`: known, admitted
/// (evicting the least recently heard peer that may not control when the
/// table is full), or `None` when every slot holds a peer that may control.
fn admit_udp(
    ctx: &EndpointCtx,
    peers: &mut HashMap<SocketAddr, UdpPeer>,
    from: SocketAddr,
    now: Instant,
) -> Option<(PeerId, PeerStanding)> {
    if let Some(known) = peers.get_mut(&from) {
        known.last_seen = now;
        return Some((known.id, known.standing.clone()));
    }
    let full = peers.len() >= MAX_PEERS;
    if full {
        let victim = peers
            .iter()
            .filter(|(_, p)| !p.standing.may_control())
            .min_by_key(|(_, p)| (p.last_seen, p.id))
            .map(|(addr, _)| *addr)?;
        if let Some(old) = peers.remove(&victim) {
            tracing::debug!(endpoint = %ctx.url, %victim, peer = old.id, "UDP peer evicted");
        }
        ctx.evicted(&victim.to_string(), &from.to_string());
    }
    let id = ctx.new_peer();
    if full {
        // A churning flood of source ports: the eviction report sums it up.
        tracing::debug!(endpoint = %ctx.url, %from, peer = id, "new UDP peer");
    } else {
        tracing::info!(endpoint = %ctx.url, %from, peer = id, "new UDP peer");
    }
    let standing = PeerStanding::default();
    peers.insert(
        from,
        UdpPeer {
            id,
            last_seen: now,
            standing: standing.clone(),
        },
    );
    Some((id, standing))
}

pub(super) async fn run_udp(
    ctx: Arc<EndpointCtx>,
    socket: UdpSocket,
    target: Option<SocketAddr>,
    peer_timeout: Duration,
    mut queue: mpsc::Receiver<Queued>,
    mut shutdown: watch::Receiver<bool>,
) {
    // The configured target is a permanent peer; it never expires.
    let target = target.map(|addr| (addr, ctx.new_peer()));
    let target_standing = PeerStanding::default();
    let fixed = usize::from(target.is_some());
    let mut peers: HashMap<SocketAddr, UdpPeer> = HashMap::new();
    ctx.set_peers(fixed);
    let mut buf = vec![0u8; 65_536];
    let mut frames = Vec::new();
    let mut packer = Packer::default();
    let mut sweep = tokio::time::interval((peer_timeout / 4).max(Duration::from_millis(10)));
    sweep.set_missed_tick_behavior(MissedTickBehavior::Delay);

    loop {
        tokio::select! {
            () = stopped(&mut shutdown) => break,
            received = socket.recv_from(&mut buf) => match received {
                Ok((n, from)) => {
                    let mut delta = FrameStats::default();
                    decode_datagram(&buf[..n], &mut delta, &mut frames);
                    // Only a sender of valid MAVLink becomes a peer: a port
                    // scan or a stray packet must not start a telemetry stream.
                    let peer = match target {
                        Some((addr, id)) if addr == from => Some((id, target_standing.clone())),
                        _ if frames.is_empty() => None,
                        _ => {
                            let admitted = admit_udp(&ctx, &mut peers, from, Instant::now());
                            ctx.set_peers(fixed + peers.len());
                            admitted
                        }
                    };
                    match peer {
                        Some((peer, standing)) => ctx.deliver(peer, Some(from), &standing, n, &mut frames, &delta),
                        None => {
                            if !frames.is_empty() {
                                ctx.refuse_peer(&from.to_string(), frames.len());
                                frames.clear();
                            }
                            ctx.deliver(0, None, &PeerStanding::default(), n, &mut frames, &delta);
                        }
                    }
                }
                Err(e) => {
                    // Linux reports ICMP errors from earlier sends here; they
                    // say nothing about the next datagram.
                    tracing::debug!(endpoint = %ctx.url, error = %e, "UDP receive error");
                }
            },
            queued = queue.recv() => {
                let Some(first) = queued else { break };
                // What is already queued goes with it: a tick's messages to
                // one station share datagrams, as ArduPilot's do.
                let mut next = Some(first);
                let mut taken = 0;
                while let Some(queued) = next {
                    let mut add = |dest: SocketAddr| packer.add(dest, &queued.bytes);
                    match queued.target {
                        Target::All => {
                            if let Some((addr, _)) = target {
                                add(addr);
                            }
                            peers.keys().copied().for_each(add);
                        }
                        Target::Peer(id) => {
                            if let Some((addr, _)) = target.filter(|&(_, t)| t == id) {
                                ctx.log_reply(&target_standing, &queued);
                                add(addr);
                            } else if let Some((addr, p)) = peers.iter().find(|(_, p)| p.id == id) {
                                ctx.log_reply(&p.standing, &queued);
                                add(*addr);
                            }
                        }
                    }
                    taken += 1;
                    next = if taken < GATHER_MAX { queue.try_recv().ok() } else { None };
                }
                for d in packer.drain() {
                    match socket.send_to(&d.bytes, d.dest).await {
                        Ok(_) => ctx.sent(d.frames, d.bytes.len()),
                        Err(e) => ctx.send_error(d.frames, &format!("UDP send to {} failed: {e}", d.dest)),
                    }
                }
            }
            _ = sweep.tick() => {
                let now = Instant::now();
                peers.retain(|addr, peer| {
                    let live = now.duration_since(peer.last_seen) < peer_timeout;
                    if !live {
                        tracing::info!(endpoint = %ctx.url, %addr, peer = peer.id, "UDP peer timed out");
                    }
                    live
                });
                ctx.set_peers(fixed + peers.len());
            }
        }
    }
    ctx.set_peers(0);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn addr(port: u16) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], port))
    }

    #[test]
    fn frames_to_one_destination_share_a_datagram_in_order() {
        let mut p = Packer::default();
        p.add(addr(1), &[1; 30]);
        p.add(addr(2), &[9; 40]);
        p.add(addr(1), &[2; 50]);
        let out: Vec<Datagram> = p.drain().collect();
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].dest, addr(1));
        assert_eq!(out[0].frames, 2);
        assert_eq!(out[0].bytes, [vec![1; 30], vec![2; 50]].concat());
        assert_eq!(out[1].dest, addr(2));
        assert_eq!(out[1].bytes, vec![9; 40]);
        assert_eq!(p.drain().count(), 0, "drained");
    }

    #[test]
    fn a_full_datagram_goes_first_and_no_frame_is_split() {
        let mut p = Packer::default();
        // Five 280-byte frames (MAVLink 2's largest): four fit in 1232.
        for i in 0..5u8 {
            p.add(addr(1), &[i; 280]);
        }
        let out: Vec<Datagram> = p.drain().collect();
        assert_eq!(out.len(), 2);
        assert_eq!((out[0].frames, out[0].bytes.len()), (4, 1120));
        assert_eq!(out[0].bytes[..280], [0; 280]);
        assert_eq!((out[1].frames, &out[1].bytes), (1, &vec![4; 280]));
        assert!(out.iter().all(|d| d.bytes.len() <= DATAGRAM_MAX));
    }

    #[test]
    fn a_frame_larger_than_the_limit_still_goes_alone() {
        let mut p = Packer::default();
        p.add(addr(1), &[1; 10]);
        p.add(addr(1), &[2; DATAGRAM_MAX + 1]);
        let out: Vec<Datagram> = p.drain().collect();
        assert_eq!(out.len(), 2);
        assert_eq!(out[1].bytes.len(), DATAGRAM_MAX + 1);
    }
}
