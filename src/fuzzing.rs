//! Entry points for the fuzz targets (`fuzz/fuzz_targets/`) and the
//! property tests: not an API, hidden from the docs.
//!
//! Most parsers of network input are public where they live and the
//! targets call them there. The few below are private to their module (a
//! helper of a route, of the STUN client, of the accept loop); each has a
//! one-line wrapper here that calls it, so a target exercises the very
//! function the server calls and no module widens its API for the fuzzer
//! (they are only crate-visible there).

use std::net::SocketAddr;

use axum::http::{HeaderMap, HeaderValue};

/// The STUN reader (`camera::webrtc::stun`): the transaction and the
/// XOR-MAPPED-ADDRESS of a binding success answer, `None` for anything else.
pub fn parse_binding_success(m: &[u8]) -> Option<([u8; 12], SocketAddr)> {
    crate::camera::webrtc::stun::parse_binding_success(m)
}

/// The STUN client's binding request (`camera::webrtc::stun`).
pub fn binding_request(id: [u8; 12]) -> [u8; 20] {
    crate::camera::webrtc::stun::binding_request(id)
}

/// Whether `If-None-Match` names the tag (`hmi::assets`).
pub fn if_none_match(request: &HeaderMap, tag: &HeaderValue) -> bool {
    crate::hmi::assets::matches(request, tag)
}

/// The ETag of a file's SHA-256 (`hmi::assets`).
pub fn etag(sha256: &[u8; 32]) -> HeaderValue {
    crate::hmi::assets::etag(sha256)
}

/// Whether a path is one of mavlink2rest's API routes (`hmi::m2r`).
pub fn is_api_path(path: &str) -> bool {
    crate::hmi::m2r::is_api_path(path)
}

/// The message a REST read of `path` waits for (`hmi::m2r`).
pub fn m2r_wanted(path: &str, vehicle_sysid: u8) -> (u8, u8, &str) {
    crate::hmi::m2r::wanted(path, vehicle_sysid)
}

/// The Host a plain-HTTP request on the TLS port is redirected to
/// (`hmi::server::connection`).
pub fn redirect_host(head: &str) -> Option<&str> {
    crate::hmi::server::connection::redirect_host(head)
}

/// Whether a Host is only host-name characters (`hmi::headers`), so it may
/// go into the Content-Security-Policy and a `Location`.
pub fn plain_host(h: &str) -> bool {
    crate::hmi::headers::plain_host(h)
}

/// A binding success answer as a STUN server writes it (RFC 8489): the
/// attributes `before` (type, value; padded to four bytes), then
/// XOR-MAPPED-ADDRESS. The other half of the STUN reader's round trip.
pub fn stun_binding_success(id: [u8; 12], addr: SocketAddr, before: &[(u16, Vec<u8>)]) -> Vec<u8> {
    const MAGIC: [u8; 4] = [0x21, 0x12, 0xa4, 0x42];
    let mut key = [0u8; 16];
    key[..4].copy_from_slice(&MAGIC);
    key[4..].copy_from_slice(&id);
    let mut value = vec![0, if addr.is_ipv4() { 1 } else { 2 }];
    value.extend((addr.port() ^ 0x2112).to_be_bytes());
    let ip = match addr.ip() {
        std::net::IpAddr::V4(a) => a.octets().to_vec(),
        std::net::IpAddr::V6(a) => a.octets().to_vec(),
    };
    value.extend(ip.iter().zip(key).map(|(b, k)| b ^ k));
    let mut attrs = Vec::new();
    for (kind, v) in before.iter().chain([&(0x0020, value)]) {
        attrs.extend(kind.to_be_bytes());
        attrs.extend(u16::try_from(v.len()).unwrap_or(u16::MAX).to_be_bytes());
        attrs.extend(v);
        attrs.resize(attrs.len().next_multiple_of(4), 0);
    }
    let mut m = vec![0x01, 0x01];
    m.extend(u16::try_from(attrs.len()).unwrap_or(u16::MAX).to_be_bytes());
    m.extend(MAGIC);
    m.extend(id);
    m.extend(attrs);
    m
}
