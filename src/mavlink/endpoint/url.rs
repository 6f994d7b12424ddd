//! Endpoint URLs in the style users know from mavlink-router and MAVProxy
//! (`udpin:0.0.0.0:14550`, `udpout:192.168.2.1:14550`, `tcpin:0.0.0.0:5760`,
//! `tcpout:HOST:PORT`, `serial:/dev/ttyUSB0:57600`, each optionally ending in
//! `?trusted`): parsing them and writing them back.
//!
//! Owns the syntax, the defaults (the endpoints used when none is named, the
//! serial baud rate) and resolving host names, once, at parse time. It must
//! never open a socket or a port: parsing a configuration binds nothing.

use std::fmt;
use std::net::{SocketAddr, ToSocketAddrs};
use std::path::PathBuf;
use std::str::FromStr;

use super::error::EndpointError;

/// Where a ground station can reach us.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EndpointSpec {
    /// Listen on a UDP address; whoever sends to it becomes a peer.
    UdpIn(SocketAddr),
    /// Send to a UDP address (a ground station listening there), and to
    /// whoever sends to our socket.
    UdpOut(SocketAddr),
    /// Accept any number of TCP clients.
    TcpIn(SocketAddr),
    /// Connect to a TCP server, reconnecting as needed.
    TcpOut(SocketAddr),
    /// A serial port (telemetry radio, USB adapter), reopened as needed.
    Serial { path: PathBuf, baud: u32 },
}

/// Endpoints used when the user names none: QGroundControl's default UDP
/// port on this machine, and a TCP port for MAVProxy/pymavlink scripts.
pub const DEFAULT_ENDPOINTS: [&str; 2] = ["udpout:127.0.0.1:14550", "tcpin:0.0.0.0:5760"];

/// Baud rate used when a `serial:` URL names none (SiK radios' default).
pub const DEFAULT_SERIAL_BAUD: u32 = 57_600;

impl FromStr for EndpointSpec {
    type Err = EndpointError;

    fn from_str(url: &str) -> Result<Self, Self::Err> {
        let err = |reason: String| EndpointError::Spec {
            url: url.to_owned(),
            reason,
        };
        let Some((scheme, rest)) = url.trim().split_once(':') else {
            return Err(err("no scheme".into()));
        };
        let addr = |rest: &str| resolve(rest).map_err(err);
        match scheme.to_ascii_lowercase().as_str() {
            "udpin" => Ok(Self::UdpIn(addr(rest)?)),
            "udpout" => Ok(Self::UdpOut(addr(rest)?)),
            "tcpin" => Ok(Self::TcpIn(addr(rest)?)),
            "tcpout" => Ok(Self::TcpOut(addr(rest)?)),
            "serial" => {
                let (path, baud) = match rest.rsplit_once(':') {
                    Some((path, baud)) if !baud.is_empty() => {
                        let baud =
                            baud.parse::<u32>().ok().filter(|&b| b > 0).ok_or_else(|| {
                                err(format!("baud rate {baud:?} is not a number"))
                            })?;
                        (path, baud)
                    }
                    _ => (rest, DEFAULT_SERIAL_BAUD),
                };
                if path.is_empty() {
                    return Err(err("no serial device path".into()));
                }
                Ok(Self::Serial {
                    path: PathBuf::from(path),
                    baud,
                })
            }
            other => Err(err(format!("unknown scheme {other:?}"))),
        }
    }
}

/// `host:port` or `ip:port` (`[v6]:port`) to one address; hostnames are
/// resolved now, once, so a typo fails at start-up rather than at send time.
fn resolve(text: &str) -> Result<SocketAddr, String> {
    if let Ok(addr) = text.parse::<SocketAddr>() {
        return Ok(addr);
    }
    if text
        .rsplit_once(':')
        .is_none_or(|(host, _)| host.is_empty())
    {
        return Err(format!("{text:?} is not HOST:PORT"));
    }
    let addrs: Vec<SocketAddr> = text
        .to_socket_addrs()
        .map_err(|e| format!("cannot resolve {text:?}: {e}"))?
        .collect();
    // Prefer IPv4: ground stations on robot networks rarely listen on v6.
    addrs
        .iter()
        .find(|a| a.is_ipv4())
        .or_else(|| addrs.first())
        .copied()
        .ok_or_else(|| format!("{text:?} resolves to no address"))
}

impl fmt::Display for EndpointSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UdpIn(a) => write!(f, "udpin:{a}"),
            Self::UdpOut(a) => write!(f, "udpout:{a}"),
            Self::TcpIn(a) => write!(f, "tcpin:{a}"),
            Self::TcpOut(a) => write!(f, "tcpout:{a}"),
            Self::Serial { path, baud } => write!(f, "serial:{}:{baud}", path.display()),
        }
    }
}

/// An endpoint as the user writes it: a URL, optionally ending in
/// `?trusted` (SETUP_SIGNING, which sets the signing key, is accepted only
/// on trusted endpoints — a cable or a VPN, never an open radio link).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EndpointUrl {
    pub spec: EndpointSpec,
    pub trusted: bool,
}

const TRUSTED_SUFFIX: &str = "?trusted";

impl FromStr for EndpointUrl {
    type Err = EndpointError;

    fn from_str(url: &str) -> Result<Self, Self::Err> {
        let url = url.trim();
        let (base, trusted) = match url.strip_suffix(TRUSTED_SUFFIX) {
            Some(base) => (base, true),
            None => (url, false),
        };
        if let Some((_, option)) = base.split_once('?') {
            return Err(EndpointError::Spec {
                url: url.to_owned(),
                reason: format!("unknown option {option:?} (the only option is ?trusted)"),
            });
        }
        Ok(Self {
            spec: base.parse()?,
            trusted,
        })
    }
}

impl fmt::Display for EndpointUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.spec)?;
        if self.trusted {
            f.write_str(TRUSTED_SUFFIX)?;
        }
        Ok(())
    }
}
