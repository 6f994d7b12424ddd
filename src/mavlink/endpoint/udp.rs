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
                let Some(queued) = queued else { break };
                let mut dests: Vec<SocketAddr> = Vec::new();
                match queued.target {
                    Target::All => {
                        dests.extend(target.map(|(addr, _)| addr));
                        dests.extend(peers.keys().copied());
                    }
                    Target::Peer(id) => {
                        if let Some((addr, _)) = target.filter(|&(_, t)| t == id) {
                            ctx.log_reply(&target_standing, &queued.bytes);
                            dests.push(addr);
                        } else if let Some((addr, p)) = peers.iter().find(|(_, p)| p.id == id) {
                            ctx.log_reply(&p.standing, &queued.bytes);
                            dests.push(*addr);
                        }
                    }
                }
                for dest in dests {
                    match socket.send_to(&queued.bytes, dest).await {
                        Ok(_) => ctx.sent(queued.bytes.len()),
                        Err(e) => ctx.send_error(&format!("UDP send to {dest} failed: {e}")),
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
