//! TCP endpoints: `tcpin`, a listener with any number of clients (up to
//! [`MAX_PEERS`]), and `tcpout`, how to connect (the connection is kept up by
//! [`run_connector`](super::stream::run_connector)).
//!
//! Owns accepting clients, the table of connections, evicting the least
//! recently heard client that may not control when the table is full, and
//! pausing accepts when they fail (out of descriptors) while connected
//! clients are still served. It must never let one client hold up another:
//! each has its own task and its own bounded queue.

use std::collections::HashMap;
use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use super::context::{EndpointCtx, MAX_PEERS, Queued, Target, stopped};
use super::stream::{BACKOFF_MIN, PEER_QUEUE, dispatch, run_stream};
use super::types::{PeerId, PeerStanding};

/// One TCP client of a `tcpin` endpoint.
struct Conn {
    tx: mpsc::Sender<Arc<[u8]>>,
    abort: tokio::task::AbortHandle,
    standing: PeerStanding,
}

pub(super) async fn run_tcp_in(
    ctx: Arc<EndpointCtx>,
    listener: TcpListener,
    idle_timeout: Duration,
    mut queue: mpsc::Receiver<Queued>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut conns: HashMap<PeerId, Conn> = HashMap::new();
    let mut task_peer: HashMap<tokio::task::Id, PeerId> = HashMap::new();
    // Dropping the set at the end aborts every connection.
    let mut tasks = tokio::task::JoinSet::new();
    // After a failed accept (out of descriptors, mostly) accepting pauses
    // while everything else goes on: the queue keeps being served, so the
    // clients already connected keep their telemetry, fresh.
    let accept_pause = tokio::time::sleep(Duration::ZERO);
    tokio::pin!(accept_pause);
    let mut paused = false;
    let mut accept_failures = 0u64;

    loop {
        tokio::select! {
            () = stopped(&mut shutdown) => break,
            () = &mut accept_pause, if paused => paused = false,
            accepted = listener.accept(), if !paused => match accepted {
                Ok((stream, from)) => {
                    if accept_failures > 0 {
                        tracing::info!(endpoint = %ctx.url, failures = accept_failures, "accepting TCP clients again");
                        accept_failures = 0;
                    }
                    if conns.len() >= MAX_PEERS {
                        // Each client costs a queue and a task: bound them,
                        // at the expense of those that may not control.
                        let victim = conns
                            .iter()
                            .filter(|(_, c)| !c.standing.may_control())
                            // Ties (same millisecond): the oldest connection.
                            .min_by_key(|(id, c)| (c.standing.last_heard_ms(), **id))
                            .map(|(id, _)| *id);
                        match victim.and_then(|id| conns.remove(&id).map(|c| (id, c))) {
                            Some((id, conn)) => {
                                conn.abort.abort();
                                ctx.evicted(&format!("TCP peer {id}"), &from.to_string());
                            }
                            None => {
                                drop(stream);
                                ctx.refuse_peer(&from.to_string(), 0);
                                continue;
                            }
                        }
                    }
                    let peer = ctx.new_peer();
                    if let Err(e) = stream.set_nodelay(true) {
                        tracing::debug!(error = %e, "cannot set TCP_NODELAY");
                    }
                    tracing::info!(endpoint = %ctx.url, %from, peer, "TCP client connected");
                    let (tx, rx) = mpsc::channel(PEER_QUEUE);
                    let standing = PeerStanding::default();
                    standing.heard(ctx.epoch);
                    let handle = tasks.spawn(run_stream(
                        Arc::clone(&ctx),
                        peer,
                        standing.clone(),
                        stream,
                        rx,
                        Some(idle_timeout),
                    ));
                    task_peer.insert(handle.id(), peer);
                    conns.insert(peer, Conn { tx, abort: handle, standing });
                    ctx.set_peers(conns.len());
                }
                Err(e) => {
                    // EMFILE/ENFILE mostly: back off instead of spinning.
                    if accept_failures == 0 {
                        tracing::warn!(
                            endpoint = %ctx.url, error = %e,
                            "cannot accept TCP clients (out of file descriptors?); retrying every \
                             {} ms, connected clients are still served", BACKOFF_MIN.as_millis()
                        );
                    }
                    accept_failures += 1;
                    accept_pause.as_mut().reset(Instant::now() + BACKOFF_MIN);
                    paused = true;
                }
            },
            Some(done) = tasks.join_next_with_id() => {
                let id = match done {
                    Ok((id, ())) => id,
                    Err(e) => e.id(),
                };
                if let Some(peer) = task_peer.remove(&id) {
                    conns.remove(&peer);
                    tracing::info!(endpoint = %ctx.url, peer, "TCP client disconnected");
                }
                ctx.set_peers(conns.len());
            }
            queued = queue.recv() => {
                let Some(queued) = queued else { break };
                if let Target::Peer(id) = queued.target
                    && let Some(conn) = conns.get(&id)
                {
                    ctx.log_reply(&conn.standing, &queued);
                }
                dispatch(&ctx, conns.iter().map(|(id, c)| (*id, &c.tx)), &queued);
            }
        }
    }
    ctx.set_peers(0);
}

/// Connects a `tcpout` endpoint once; `run_connector` retries.
pub(super) async fn connect_tcp(addr: SocketAddr) -> io::Result<(TcpStream, Option<SocketAddr>)> {
    let stream = TcpStream::connect(addr).await?;
    // MAVLink frames are small and latency matters more than packing.
    stream.set_nodelay(true)?;
    let local = stream.local_addr().ok();
    Ok((stream, local))
}
