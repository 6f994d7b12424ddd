//! The error at the endpoint boundary: what a user sees when an endpoint
//! URL is not valid, an address cannot be bound, or the telemetry log cannot
//! be created.
//!
//! Owns the messages only, each naming the thing, the value and the fix. It
//! must never decide what happens next: the router and `main` do.

use std::io;
use std::path::PathBuf;

const EXPECTED_FORMS: &str = "udpin:ADDR:PORT, udpout:HOST:PORT, tcpin:ADDR:PORT, \
     tcpout:HOST:PORT or serial:PATH[:BAUD] (e.g. udpin:0.0.0.0:14550, serial:/dev/ttyUSB0:57600)";

/// Errors at the endpoint boundary.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    #[error("endpoint {url:?} is not valid: {reason}; expected {EXPECTED_FORMS}")]
    Spec { url: String, reason: String },
    #[error(
        "cannot open endpoint {url}: {source}; another program (QGroundControl, MAVProxy, \
         a second neptunus) may be using that address: pick another port or stop it"
    )]
    Bind { url: String, source: io::Error },
    #[error(
        "cannot create the telemetry log in {}: {source}; make the folder writable or turn \
         the telemetry log off",
        dir.display()
    )]
    Tlog { dir: PathBuf, source: io::Error },
}
