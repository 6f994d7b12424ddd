//! MAVLink endpoints: the sockets and serial ports ground stations talk to,
//! and the router that fans frames in and out of them.
//!
//! Owns: parsing endpoint URLs (`udpin:`, `udpout:`, `tcpin:`, `tcpout:`,
//! `serial:`), binding/connecting and reconnecting, the per-endpoint peer
//! tables (UDP addresses, TCP connections, the serial port), per-endpoint
//! counters, and feeding the telemetry log. Every decoded frame goes to one
//! inbound channel tagged with where it came from; outbound bytes are routed
//! to all endpoints, one endpoint, or one peer.
//!
//! Under attack: each peer carries a [`PeerStanding`] the vehicle side sets
//! once a station that may control the vehicle speaks through it. A full
//! peer table ([`MAX_PEERS`]) makes room by evicting the least recently heard
//! peer that may not control (closing its TCP connection), so strangers can
//! never shut out a station that may control; idle TCP clients are closed
//! after the peer timeout like UDP peers; frames from peers that may not
//! control reach the telemetry log through a per-endpoint rate limit and may
//! use only part of the inbound channel.
//!
//! It never interprets a message (no authority, no signing, no replies):
//! that is the vehicle core's job. It never blocks the caller of
//! [`RouterHandle::send`]: queues are bounded, and a slow client loses frames
//! (counted in `send_errors`) rather than stalling the vehicle or the other
//! clients. A full inbound channel drops frames (counted) rather than
//! buffering without bound.
//!
//! One file per concern: `url` (endpoint URLs), `error` (the boundary's
//! error), `types` (what goes in and out, peer standing, counters), `router`
//! (start-up, routing, shutdown), `context` (what an endpoint's tasks share:
//! delivery, counters, limits), `udp`, `tcp`, `stream` (byte-stream peers and
//! reconnecting) and `serial`. The telemetry log's writer thread lives with
//! the writer, in [`super::tlog`].

mod context;
mod error;
mod router;
mod serial;
mod stream;
mod tcp;
mod types;
mod udp;
mod url;

pub use context::{MAX_PEERS, TLOG_STRANGER_RATE_HZ};
pub use error::EndpointError;
pub use router::{Router, RouterConfig, RouterHandle};
pub use types::{EndpointId, EndpointStats, Inbound, Outbound, PeerId, PeerStanding, Route};
pub use url::{DEFAULT_ENDPOINTS, DEFAULT_SERIAL_BAUD, EndpointSpec, EndpointUrl};
