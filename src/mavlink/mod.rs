//! MAVLink transport: how frames get between ground stations and the
//! vehicle core.
//!
//! - [`frame`]: sans-IO framing (stream and datagram decoders, MAVLink 2
//!   encoding) with per-kind counters for bad input.
//! - [`endpoint`]: endpoint URLs, sockets and serial ports, peer tables, and
//!   the router that fans frames in and out.
//! - [`signing`]: MAVLink 2 signing (sans-IO signer and verifier) and the
//!   key and timestamp files.
//! - [`tlog`]: telemetry log files (pymavlink `.tlog` format).
//! - [`ftp`]: MAVLink FTP payloads (requests, replies, directory entries,
//!   the CRC-32), pure.
//!
//! Nothing here interprets a message or decides anything about the vehicle;
//! the external `mavlink` crate is used only for CRCs, payload codecs and
//! the generated dialect, never for its connection types (its `udpin`
//! answers only the last sender and its `tcpin` takes one client).

pub mod endpoint;
pub mod frame;
pub mod ftp;
pub mod signing;
pub mod tlog;

pub use endpoint::{
    DEFAULT_ENDPOINTS, EndpointError, EndpointId, EndpointSpec, EndpointStats, Inbound, MAX_PEERS,
    Outbound, PeerId, PeerStanding, Route, Router, RouterConfig, RouterHandle,
};
pub use frame::{Frame, FrameDecoder, FrameStats, MavMessage, decode_datagram, encode_v2};
pub use tlog::{TlogConfig, TlogWriter};
