//! What every task of one endpoint shares ([`EndpointCtx`]): its counters,
//! the inbound channel, the telemetry log's sender, peer ids, and the limits
//! that keep peers that may not control from crowding out those that may.
//!
//! Owns delivering decoded frames (counted, each kind of trouble logged once,
//! into the telemetry log through a rate limit for peers that may not
//! control, and only into their share of the inbound channel), counting and
//! reporting evictions, and the counters behind [`EndpointStats`]. It must
//! never wait: every channel is used with `try_send`, so a full one drops the
//! frame and counts it instead of holding up an endpoint task.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use super::types::{EndpointId, EndpointStats, Inbound, PeerId, PeerStanding};
use crate::mavlink::frame::{Frame, FrameStats};
use crate::mavlink::tlog::TlogSender;

/// Peers per endpoint (UDP addresses or TCP clients). When full, the least
/// recently heard peer that may not control makes room for a newcomer;
/// only a table full of peers that may control refuses one. Bounded so that
/// spoofed source addresses or a connection flood cannot grow memory.
pub const MAX_PEERS: usize = 64;
/// Frames per second (per endpoint, for all its peers that may not control
/// together) that reach the telemetry log…
pub const TLOG_STRANGER_RATE_HZ: f64 = 20.0;
/// …with bursts of this many.
const TLOG_STRANGER_BURST: f64 = 40.0;
/// Peers that may not control may fill the inbound channel only to this
/// fraction: the rest is kept for stations that may control.
const INBOUND_STRANGER_SHARE: (usize, usize) = (3, 4);
/// Evictions are logged at most this often (with the count since).
const EVICTION_REPORT: Duration = Duration::from_secs(10);

#[derive(Debug, Clone, Copy)]
pub(super) enum Target {
    All,
    Peer(PeerId),
}

pub(super) struct Queued {
    pub(super) target: Target,
    pub(super) bytes: Arc<[u8]>,
    /// Goes to the telemetry log (a reply to one peer is logged by the
    /// endpoint that knows the peer's standing).
    pub(super) log: bool,
}

/// What every task of one endpoint shares.
pub(super) struct EndpointCtx {
    pub(super) id: EndpointId,
    pub(super) url: String,
    pub(super) counters: Counters,
    pub(super) inbound: mpsc::Sender<Inbound>,
    pub(super) tlog: Option<TlogSender>,
    pub(super) next_peer: Arc<AtomicU64>,
    /// Zero of [`PeerStanding`]'s last-heard times.
    pub(super) epoch: Instant,
    /// The telemetry log's share for peers that may not control.
    pub(super) tlog_bucket: Mutex<TokenBucket>,
    pub(super) evictions_unreported: AtomicU64,
    pub(super) last_eviction_report: Mutex<Option<Instant>>,
}

/// Frames allowed at [`TLOG_STRANGER_RATE_HZ`] with bursts of [`TLOG_STRANGER_BURST`].
pub(super) struct TokenBucket {
    tokens: f64,
    last: Instant,
}

impl TokenBucket {
    pub(super) fn new(now: Instant) -> Self {
        Self {
            tokens: TLOG_STRANGER_BURST,
            last: now,
        }
    }

    fn take(&mut self, now: Instant) -> bool {
        let dt = now.saturating_duration_since(self.last).as_secs_f64();
        self.last = now;
        self.tokens = (self.tokens + dt * TLOG_STRANGER_RATE_HZ).min(TLOG_STRANGER_BURST);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

#[derive(Default)]
pub(super) struct Counters {
    peers: AtomicUsize,
    frames_in: AtomicU64,
    frames_out: AtomicU64,
    bytes_in: AtomicU64,
    bytes_out: AtomicU64,
    send_errors: AtomicU64,
    inbound_dropped: AtomicU64,
    peers_evicted: AtomicU64,
    tlog_dropped: AtomicU64,
    decode: Mutex<FrameStats>,
    local_addr: Mutex<Option<SocketAddr>>,
    /// Kinds of trouble already logged (bit per kind): log once, count always.
    warned: AtomicU32,
}

impl Counters {
    pub(super) fn set_local_addr(&self, addr: Option<SocketAddr>) {
        *self
            .local_addr
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = addr;
    }

    pub(super) fn local_addr(&self) -> Option<SocketAddr> {
        *self
            .local_addr
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
}

const WARN_BAD_CRC: u32 = 1;
const WARN_UNKNOWN: u32 = 2;
const WARN_BAD_PAYLOAD: u32 = 4;
const WARN_GARBAGE: u32 = 8;
const WARN_SEND: u32 = 16;
const WARN_INBOUND: u32 = 32;
const WARN_PEERS: u32 = 64;
const WARN_TLOG_RATE: u32 = 128;
const WARN_INBOUND_SHARE: u32 = 256;

impl EndpointCtx {
    pub(super) fn new_peer(&self) -> PeerId {
        self.next_peer.fetch_add(1, Ordering::Relaxed)
    }

    pub(super) fn set_peers(&self, n: usize) {
        self.counters.peers.store(n, Ordering::Relaxed);
    }

    fn first_time(&self, bit: u32) -> bool {
        self.counters.warned.fetch_or(bit, Ordering::Relaxed) & bit == 0
    }

    pub(super) fn send_error(&self, frames: usize, what: &str) {
        self.counters
            .send_errors
            .fetch_add(frames as u64, Ordering::Relaxed);
        if self.first_time(WARN_SEND) {
            tracing::warn!(endpoint = %self.url, "{what} (logged once; see send_errors)");
        }
    }

    /// A new peer was refused because the table is full of peers that may
    /// control; its `frames` are dropped (counted as inbound drops).
    pub(super) fn refuse_peer(&self, from: &str, frames: usize) {
        self.counters
            .inbound_dropped
            .fetch_add(frames as u64, Ordering::Relaxed);
        if self.first_time(WARN_PEERS) {
            tracing::warn!(endpoint = %self.url, %from, "peer table full ({MAX_PEERS} peers, all stations that may control): refusing new peers (logged once)");
        }
    }

    /// A peer that may not control was evicted for `newcomer`: counted
    /// always, logged once per burst.
    pub(super) fn evicted(&self, victim: &str, newcomer: &str) {
        self.counters.peers_evicted.fetch_add(1, Ordering::Relaxed);
        let unreported = self.evictions_unreported.fetch_add(1, Ordering::Relaxed) + 1;
        let now = Instant::now();
        let mut last = self
            .last_eviction_report
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if last.is_none_or(|t| now.saturating_duration_since(t) >= EVICTION_REPORT) {
            *last = Some(now);
            self.evictions_unreported.store(0, Ordering::Relaxed);
            tracing::warn!(
                endpoint = %self.url, %victim, %newcomer, evicted = unreported,
                "peer table full ({MAX_PEERS}): evicting the least recently heard peers that may \
                 not control to admit new ones (a flood of peers? logged once per {} s; see \
                 peers_evicted)",
                EVICTION_REPORT.as_secs()
            );
        }
    }

    /// Logs a frame addressed to one peer: always for a peer that may
    /// control, through the shared rate limit for the others.
    pub(super) fn log_reply(&self, standing: &PeerStanding, queued: &Queued) {
        let Some(tlog) = &self.tlog else { return };
        if !queued.log {
            return;
        }
        let bytes = &queued.bytes;
        if standing.may_control() || self.tlog_allows_stranger(Instant::now()) {
            tlog.record(Arc::clone(bytes));
        }
    }

    /// One frame of a peer that may not control into the log, if the rate
    /// limit allows; counted (and said once) when it does not.
    fn tlog_allows_stranger(&self, now: Instant) -> bool {
        let allowed = self
            .tlog_bucket
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take(now);
        if !allowed {
            self.counters.tlog_dropped.fetch_add(1, Ordering::Relaxed);
            if self.first_time(WARN_TLOG_RATE) {
                tracing::warn!(endpoint = %self.url, "frames to and from stations that may not control reach the telemetry log at most {TLOG_STRANGER_RATE_HZ}/s per endpoint: dropping the rest from the log (logged once; see tlog_dropped)");
            }
        }
        allowed
    }

    pub(super) fn sent(&self, frames: usize, bytes: usize) {
        self.counters
            .frames_out
            .fetch_add(frames as u64, Ordering::Relaxed);
        self.counters
            .bytes_out
            .fetch_add(bytes as u64, Ordering::Relaxed);
    }

    /// Accounts for `bytes_in` bytes that decoded to `frames` (drained) with
    /// `delta` decoder counters, and passes the frames on.
    pub(super) fn deliver(
        &self,
        peer: PeerId,
        udp_from: Option<SocketAddr>,
        standing: &PeerStanding,
        bytes_in: usize,
        frames: &mut Vec<Frame>,
        delta: &FrameStats,
    ) {
        let c = &self.counters;
        c.bytes_in.fetch_add(bytes_in as u64, Ordering::Relaxed);
        c.frames_in
            .fetch_add(frames.len() as u64, Ordering::Relaxed);
        if delta != &FrameStats::default() {
            c.decode
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .add(delta);
            for (count, bit, what) in [
                (delta.bad_crc, WARN_BAD_CRC, "frames with a bad CRC"),
                (
                    delta.unknown_msg,
                    WARN_UNKNOWN,
                    "frames of unknown message ids",
                ),
                (
                    delta.bad_payload,
                    WARN_BAD_PAYLOAD,
                    "frames with undecodable payloads",
                ),
                (
                    delta.garbage_bytes,
                    WARN_GARBAGE,
                    "bytes that are not MAVLink",
                ),
            ] {
                if count > 0 && self.first_time(bit) {
                    tracing::warn!(endpoint = %self.url, peer, "dropping {what} (logged once; see the endpoint's decode stats)");
                }
            }
        }
        if frames.is_empty() {
            return;
        }
        let may_control = standing.may_control();
        let now = Instant::now();
        standing.heard(self.epoch);
        for frame in frames.drain(..) {
            if let Some(tlog) = &self.tlog
                && (may_control || self.tlog_allows_stranger(now))
            {
                tlog.record(Arc::from(frame.raw.as_slice()));
            }
            // Strangers may not crowd out the stations that may control.
            let (num, den) = INBOUND_STRANGER_SHARE;
            if !may_control
                && self.inbound.capacity() * den < self.inbound.max_capacity() * (den - num)
            {
                c.inbound_dropped.fetch_add(1, Ordering::Relaxed);
                if self.first_time(WARN_INBOUND_SHARE) {
                    tracing::warn!(endpoint = %self.url, peer, "inbound channel filling up: dropping frames from stations that may not control (logged once)");
                }
                continue;
            }
            let inbound = Inbound {
                endpoint: self.id,
                peer,
                udp_from,
                frame,
                standing: standing.clone(),
            };
            if let Err(mpsc::error::TrySendError::Full(_)) = self.inbound.try_send(inbound) {
                c.inbound_dropped.fetch_add(1, Ordering::Relaxed);
                if self.first_time(WARN_INBOUND) {
                    tracing::warn!(endpoint = %self.url, "inbound channel full: dropping frames (logged once)");
                }
            }
        }
    }

    pub(super) fn stats(&self) -> EndpointStats {
        let c = &self.counters;
        EndpointStats {
            spec: self.url.clone(),
            local_addr: c.local_addr(),
            peers: c.peers.load(Ordering::Relaxed),
            frames_in: c.frames_in.load(Ordering::Relaxed),
            frames_out: c.frames_out.load(Ordering::Relaxed),
            bytes_in: c.bytes_in.load(Ordering::Relaxed),
            bytes_out: c.bytes_out.load(Ordering::Relaxed),
            decode: c
                .decode
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone(),
            send_errors: c.send_errors.load(Ordering::Relaxed),
            inbound_dropped: c.inbound_dropped.load(Ordering::Relaxed),
            peers_evicted: c.peers_evicted.load(Ordering::Relaxed),
            tlog_dropped: c.tlog_dropped.load(Ordering::Relaxed),
        }
    }
}

/// Resolves when the router shuts down (or every handle is gone).
pub(super) async fn stopped(shutdown: &mut watch::Receiver<bool>) {
    // An error means the sender is gone: nobody can ever use us again.
    let _ = shutdown.wait_for(|&stop| stop).await;
}
