//! The router's vocabulary, shared by the router, the endpoint tasks and the
//! vehicle side: what comes in from a ground station ([`Inbound`]), what goes
//! out and to whom ([`Outbound`], [`Route`]), the ids of endpoints and peers,
//! a peer's [`PeerStanding`], and an endpoint's counters ([`EndpointStats`]).
//!
//! Plain data: it must never do I/O or take a lock (a standing is checked
//! on every frame, with one atomic load).

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use serde::Serialize;
use tokio::time::Instant;

use crate::mavlink::frame::{Frame, FrameStats};

/// Index of an endpoint in the list given to [`Router::start`](super::Router::start).
pub type EndpointId = usize;
/// One remote (UDP address, TCP connection, serial port session); never
/// reused while the router runs.
pub type PeerId = u64;

/// A frame from a ground station.
#[derive(Debug, Clone)]
pub struct Inbound {
    pub endpoint: EndpointId,
    pub peer: PeerId,
    /// The sender's address, on UDP endpoints (where video can be sent
    /// back to it); `None` on TCP and serial.
    pub udp_from: Option<SocketAddr>,
    pub frame: Frame,
    /// The peer's standing with the router; the vehicle side marks it once a
    /// station that may control speaks through this peer.
    pub standing: PeerStanding,
}

/// What the router knows of one peer that the vehicle side tells it: whether
/// a station that may control the vehicle speaks through it. Shared by the
/// peer's table entry and every [`Inbound`] from it; cheap to clone and to
/// check on every frame (one atomic load).
#[derive(Debug, Clone, Default)]
pub struct PeerStanding(Arc<PeerShared>);

#[derive(Debug, Default)]
struct PeerShared {
    may_control: AtomicBool,
    /// Milliseconds since the router's epoch when it was last heard (TCP).
    last_heard_ms: AtomicU64,
}

impl PeerStanding {
    /// Whether a station that may control has been heard through this peer.
    pub fn may_control(&self) -> bool {
        self.0.may_control.load(Ordering::Relaxed)
    }

    /// Records whether a station that may control speaks through this peer;
    /// true when that changed it. A peer that may control is never evicted to
    /// make room for a newcomer and all its frames are logged.
    pub fn set_may_control(&self, may: bool) -> bool {
        self.may_control() != may && self.0.may_control.swap(may, Ordering::Relaxed) != may
    }

    pub(super) fn heard(&self, epoch: Instant) {
        let ms = u64::try_from(epoch.elapsed().as_millis()).unwrap_or(u64::MAX);
        self.0.last_heard_ms.store(ms, Ordering::Relaxed);
    }

    pub(super) fn last_heard_ms(&self) -> u64 {
        self.0.last_heard_ms.load(Ordering::Relaxed)
    }
}

/// Who gets an outbound frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    All,
    Endpoint(EndpointId),
    Peer(EndpointId, PeerId),
}

/// Encoded bytes (MAVLink 2) and where they go.
#[derive(Debug, Clone)]
pub struct Outbound {
    pub route: Route,
    pub bytes: Arc<[u8]>,
}

/// Counters of one endpoint. `frames_out`/`bytes_out` count each delivery to
/// each peer; `send_errors` counts frames a peer did not get (its queue was
/// full, or the OS refused them).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EndpointStats {
    pub spec: String,
    pub local_addr: Option<SocketAddr>,
    pub peers: usize,
    pub frames_in: u64,
    pub frames_out: u64,
    pub bytes_in: u64,
    pub bytes_out: u64,
    pub decode: FrameStats,
    pub send_errors: u64,
    /// Frames decoded but dropped because the inbound channel was full (or
    /// their sender was refused: the peer table was full of peers that may
    /// control).
    pub inbound_dropped: u64,
    /// Peers that may not control evicted to make room for a newcomer.
    pub peers_evicted: u64,
    /// Frames from (and replies to) peers that may not control left out of
    /// the telemetry log by its rate limit.
    pub tlog_dropped: u64,
}
