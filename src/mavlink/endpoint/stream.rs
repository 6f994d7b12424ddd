//! Byte-stream peers (a TCP connection, a serial port): [`run_stream`] runs
//! one peer, decoding what it sends and writing what is queued for it, and
//! [`run_connector`] keeps a link we open ourselves (`tcpout`, `serial`) up,
//! reconnecting with backoff.
//!
//! It must never stall on a peer: a peer that does not read loses frames (its
//! queue is bounded), a peer that does not read still has its input decoded,
//! and frames queued while a link is down are thrown away, not kept.

use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, BufWriter};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use super::context::{EndpointCtx, Queued, Target, stopped};
use super::types::{PeerId, PeerStanding};
use crate::mavlink::frame::FrameDecoder;

/// Frames queued for one TCP/serial peer before its frames are dropped.
pub(super) const PEER_QUEUE: usize = 256;
pub(super) const BACKOFF_MIN: Duration = Duration::from_millis(200);
const BACKOFF_MAX: Duration = Duration::from_secs(5);

/// Hands a frame to stream peers' queues without waiting.
pub(super) fn dispatch<'a>(
    ctx: &EndpointCtx,
    conns: impl Iterator<Item = (PeerId, &'a mpsc::Sender<Arc<[u8]>>)>,
    q: &Queued,
) {
    for (id, tx) in conns {
        if matches!(q.target, Target::Peer(p) if p != id) {
            continue;
        }
        if let Err(mpsc::error::TrySendError::Full(_)) = tx.try_send(Arc::clone(&q.bytes)) {
            ctx.send_error(1, "a client is not reading: dropping its frames");
        }
    }
}

/// Runs one byte-stream peer (TCP connection or serial port) until it
/// closes or fails: decodes what it sends, writes what is queued for it.
/// Reading and writing are polled together so a peer that does not read
/// still has its input decoded. With `idle_timeout`, a peer that sends no
/// frame for that long is closed (a connection that only holds a slot).
pub(super) async fn run_stream<S>(
    ctx: Arc<EndpointCtx>,
    peer: PeerId,
    standing: PeerStanding,
    stream: S,
    mut rx: mpsc::Receiver<Arc<[u8]>>,
    idle_timeout: Option<Duration>,
) where
    S: AsyncRead + AsyncWrite + Send + 'static,
{
    let (mut rd, wr) = tokio::io::split(stream);
    let reader = async {
        let mut decoder = FrameDecoder::new();
        let mut buf = vec![0u8; 4096];
        let mut frames = Vec::new();
        let mut last_frame = Instant::now();
        loop {
            let read = match idle_timeout {
                Some(idle) => {
                    match tokio::time::timeout_at(last_frame + idle, rd.read(&mut buf)).await {
                        Ok(read) => read,
                        Err(_) => {
                            return Err(io::Error::new(
                                io::ErrorKind::TimedOut,
                                format!(
                                    "no MAVLink frame for {:.1} s (peer_timeout_s): closed",
                                    idle.as_secs_f64()
                                ),
                            ));
                        }
                    }
                }
                None => rd.read(&mut buf).await,
            };
            match read {
                Ok(0) => return Ok(()),
                Ok(n) => {
                    decoder.push(&buf[..n], &mut frames);
                    let delta = decoder.take_stats();
                    // Garbage does not keep a connection alive; frames do.
                    if !frames.is_empty() {
                        last_frame = Instant::now();
                    }
                    ctx.deliver(peer, None, &standing, n, &mut frames, &delta);
                }
                Err(e) => return Err(e),
            }
        }
    };
    let writer = async {
        let mut wr = BufWriter::new(wr);
        while let Some(bytes) = rx.recv().await {
            wr.write_all(&bytes).await?;
            ctx.sent(1, bytes.len());
            // Batch whatever else is already queued into the same write.
            while let Ok(bytes) = rx.try_recv() {
                wr.write_all(&bytes).await?;
                ctx.sent(1, bytes.len());
            }
            wr.flush().await?;
        }
        Ok::<(), io::Error>(())
    };
    let result = tokio::select! {
        r = reader => r,
        w = writer => w,
    };
    if let Err(e) = result {
        tracing::info!(endpoint = %ctx.url, peer, error = %e, "peer connection ended");
    }
}

pub(super) async fn run_connector<S, F, Fut>(
    ctx: Arc<EndpointCtx>,
    mut queue: mpsc::Receiver<Queued>,
    mut shutdown: watch::Receiver<bool>,
    mut connect: F,
) where
    S: AsyncRead + AsyncWrite + Send + 'static,
    F: FnMut() -> Fut,
    Fut: Future<Output = io::Result<(S, Option<SocketAddr>)>>,
{
    let mut backoff = BACKOFF_MIN;
    let mut failures = 0u32;
    loop {
        let attempt = while_discarding(&mut queue, &mut shutdown, connect()).await;
        let (stream, local) = match attempt {
            None => break,
            Some(Ok(opened)) => opened,
            Some(Err(e)) => {
                if failures == 0 {
                    tracing::warn!(endpoint = %ctx.url, error = %e, "cannot connect; retrying with backoff");
                } else {
                    tracing::debug!(endpoint = %ctx.url, error = %e, "still cannot connect");
                }
                failures = failures.saturating_add(1);
                let wait = tokio::time::sleep(backoff);
                backoff = (backoff * 2).min(BACKOFF_MAX);
                if while_discarding(&mut queue, &mut shutdown, wait)
                    .await
                    .is_none()
                {
                    break;
                }
                continue;
            }
        };
        backoff = BACKOFF_MIN;
        failures = 0;
        let peer = ctx.new_peer();
        tracing::info!(endpoint = %ctx.url, peer, "connected");
        ctx.counters.set_local_addr(local);
        ctx.set_peers(1);
        let (tx, rx) = mpsc::channel(PEER_QUEUE);
        let standing = PeerStanding::default();
        // tcpout and serial links are ours to keep: no idle timeout.
        let session = run_stream(Arc::clone(&ctx), peer, standing.clone(), stream, rx, None);
        tokio::pin!(session);
        let stop = loop {
            tokio::select! {
                () = stopped(&mut shutdown) => break true,
                () = &mut session => break false,
                queued = queue.recv() => match queued {
                    Some(queued) => {
                        if matches!(queued.target, Target::Peer(p) if p == peer) {
                            ctx.log_reply(&standing, &queued);
                        }
                        dispatch(&ctx, std::iter::once((peer, &tx)), &queued);
                    }
                    None => break true,
                },
            }
        };
        ctx.set_peers(0);
        if stop {
            break;
        }
        tracing::warn!(endpoint = %ctx.url, peer, "disconnected; reconnecting");
        // A peer that drops us at once must not make us hammer it.
        if while_discarding(&mut queue, &mut shutdown, tokio::time::sleep(BACKOFF_MIN))
            .await
            .is_none()
        {
            break;
        }
    }
    ctx.set_peers(0);
}

/// Runs `fut` while throwing away frames queued for a peer that is not
/// there (as UDP does with no peers), so `send` never sees a full queue
/// because of a disconnected link. `None` on shutdown.
async fn while_discarding<T>(
    queue: &mut mpsc::Receiver<Queued>,
    shutdown: &mut watch::Receiver<bool>,
    fut: impl Future<Output = T>,
) -> Option<T> {
    tokio::pin!(fut);
    loop {
        tokio::select! {
            () = stopped(shutdown) => return None,
            out = &mut fut => return Some(out),
            // A closed queue means the router is gone.
            queued = queue.recv() => { queued.as_ref()?; }
        }
    }
}
