//! `[camera.webrtc]`: whether viewers may watch over WebRTC, where the
//! signalling WebSocket listens, the ICE servers and the media port.
//!
//! Parsing and checks only: a bad value is an error naming the key, the
//! value and the fix, never a panic and never a silent default.

use std::fmt;
use std::net::SocketAddr;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// Where mavlink-camera-manager's signalling WebSocket is looked for
/// (Cockpit's default `ws://VEHICLE:6021/`).
pub const MCM_SIGNALLING_PORT: u16 = 6021;
/// Where mavlink-camera-manager's REST API is looked for (Cockpit's
/// `http://VEHICLE:6020/streams`).
pub const MCM_REST_PORT: u16 = 6020;
/// Viewers at once unless configured.
pub const DEFAULT_MAX_VIEWERS: usize = 8;

/// The signalling WebSocket on a port of its own: an address, or `off`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignallingAddr {
    Off,
    At(SocketAddr),
}

impl SignallingAddr {
    /// Where the signalling listens: the configured address, else port
    /// 6021 on the HMI's address (a HMI kept on loopback keeps the
    /// signalling there too); `None`: nowhere.
    pub fn resolve(
        configured: Option<SignallingAddr>,
        hmi: Option<SocketAddr>,
    ) -> Option<SocketAddr> {
        match configured {
            Some(SignallingAddr::Off) => None,
            Some(SignallingAddr::At(a)) => Some(a),
            None => hmi.map(|h| SocketAddr::new(h.ip(), MCM_SIGNALLING_PORT)),
        }
    }
}

impl SignallingAddr {
    /// Where `/streams` listens: the configured address, else port 6020 on
    /// the signalling's address (it goes where the signalling goes, and is
    /// off with it); `None`: nowhere.
    pub fn resolve_streams(
        configured: Option<SignallingAddr>,
        signalling: Option<SocketAddr>,
    ) -> Option<SocketAddr> {
        match configured {
            Some(SignallingAddr::Off) => None,
            Some(SignallingAddr::At(a)) => Some(a),
            None => signalling.map(|s| SocketAddr::new(s.ip(), MCM_REST_PORT)),
        }
    }
}

impl fmt::Display for SignallingAddr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SignallingAddr::Off => f.write_str("off"),
            SignallingAddr::At(a) => write!(f, "{a}"),
        }
    }
}

/// A `--webrtc-signalling` value that is neither `HOST:PORT` nor `off`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "WebRTC signalling address {0:?} is not valid — use HOST:PORT (e.g. 0.0.0.0:6021, where Cockpit looks) or off"
)]
pub struct SignallingAddrError(pub String);

impl FromStr for SignallingAddr {
    type Err = SignallingAddrError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.trim().eq_ignore_ascii_case("off") {
            return Ok(SignallingAddr::Off);
        }
        s.trim()
            .parse()
            .map(SignallingAddr::At)
            .map_err(|_| SignallingAddrError(s.to_owned()))
    }
}

impl Serialize for SignallingAddr {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for SignallingAddr {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// One ICE server, as a browser's `RTCIceServer` takes it: a `stun:` or
/// `turn:`/`turns:` URL, with the TURN server's user name and credential.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IceServer {
    pub url: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub username: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub credential: Option<String>,
}

/// An ICE server URL that is not `stun:`, `turn:` or `turns:` `HOST[:PORT]`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "ICE server {0:?} is not valid — use stun:HOST[:PORT] or turn:HOST[:PORT] (e.g. stun:stun.l.google.com:19302)"
)]
pub struct IceServerError(pub String);

impl IceServer {
    /// The scheme and the `host:port` of the URL (port 3478 by default,
    /// 5349 for `turns:`), or an error naming it.
    pub fn parts(&self) -> Result<(&str, String, u16), IceServerError> {
        let bad = || IceServerError(self.url.clone());
        let (scheme, rest) = self.url.split_once(':').ok_or_else(bad)?;
        if !matches!(scheme, "stun" | "turn" | "turns") {
            return Err(bad());
        }
        // `turn:host:port?transport=udp` is a browser's URL too.
        let rest = rest.split('?').next().unwrap_or("");
        let default_port = if scheme == "turns" { 5349 } else { 3478 };
        let (host, port) = match rest.strip_prefix('[') {
            Some(v6) => {
                let (host, after) = v6.split_once(']').ok_or_else(bad)?;
                match after.strip_prefix(':') {
                    Some(p) => (host, p.parse::<u16>().map_err(|_| bad())?),
                    None if after.is_empty() => (host, default_port),
                    None => return Err(bad()),
                }
            }
            None => match rest.split_once(':') {
                Some((h, p)) => (h, p.parse::<u16>().map_err(|_| bad())?),
                None => (rest, default_port),
            },
        };
        let valid = |c: char| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | ':' | '_');
        if host.is_empty() || port == 0 || !host.chars().all(valid) {
            return Err(bad());
        }
        Ok((scheme, host.to_owned(), port))
    }

    pub fn is_stun(&self) -> bool {
        self.url.starts_with("stun:")
    }
}

impl FromStr for IceServer {
    type Err = IceServerError;

    /// `--ice-server URL`: a STUN server, or a TURN server without
    /// credentials (give those in the file).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let server = IceServer {
            url: s.trim().to_owned(),
            username: None,
            credential: None,
        };
        server.parts()?;
        Ok(server)
    }
}

/// `[camera.webrtc]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WebRtcConfig {
    /// Viewers may watch over WebRTC (`--webrtc on|off`): the signalling
    /// WebSocket on the HMI's port at `/webrtc` and on `signalling`.
    pub enabled: bool,
    /// The signalling WebSocket on a port of its own, where Cockpit looks
    /// (`--webrtc-signalling`), or `off`; unset: port 6021 on the HMI's
    /// address.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub signalling: Option<SignallingAddr>,
    /// mavlink-camera-manager's REST port with `/streams` (what Cockpit
    /// shows of the stream), or `off`; unset: port 6020 on the
    /// signalling's address.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub streams: Option<SignallingAddr>,
    /// ICE servers for viewers away from the tether (`--ice-server`): the
    /// vehicle asks the STUN ones for its public address, and the page
    /// hands them all to its browser. None on a tether.
    pub ice_servers: Vec<IceServer>,
    /// The UDP port of the media on each of the vehicle's addresses; 0: a
    /// free one.
    pub udp_port: u16,
    /// Viewers at once; more are refused with the reason.
    pub max_viewers: usize,
}

impl Default for WebRtcConfig {
    fn default() -> Self {
        WebRtcConfig {
            enabled: true,
            signalling: None,
            streams: None,
            ice_servers: Vec::new(),
            udp_port: 0,
            max_viewers: DEFAULT_MAX_VIEWERS,
        }
    }
}

/// A `[camera.webrtc]` value out of range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WebRtcConfigError {
    #[error("camera.webrtc.ice_servers: {0}")]
    IceServer(#[from] IceServerError),
    #[error(
        "camera.webrtc.max_viewers = {0} is out of range — use 1 to 64 (each viewer costs the tether the whole stream), or enabled = false"
    )]
    MaxViewers(usize),
}

impl WebRtcConfig {
    pub fn validate(&self) -> Result<(), WebRtcConfigError> {
        for s in &self.ice_servers {
            s.parts()?;
        }
        if !(1..=64).contains(&self.max_viewers) {
            return Err(WebRtcConfigError::MaxViewers(self.max_viewers));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signalling_addresses_parse_and_bad_ones_are_named() {
        assert_eq!("off".parse(), Ok(SignallingAddr::Off));
        let hmi = "0.0.0.0:8080".parse().ok();
        assert_eq!(
            SignallingAddr::resolve(None, hmi),
            "0.0.0.0:6021".parse().ok(),
            "Cockpit's default, on the HMI's address"
        );
        assert_eq!(
            SignallingAddr::resolve(Some(SignallingAddr::Off), hmi),
            None
        );
        assert_eq!(SignallingAddr::resolve(None, None), None);
        let sig = "127.0.0.5:6021".parse().ok();
        assert_eq!(
            SignallingAddr::resolve_streams(None, sig),
            "127.0.0.5:6020".parse().ok(),
            "Cockpit's /streams, beside the signalling"
        );
        assert_eq!(SignallingAddr::resolve_streams(None, None), None);
        assert_eq!(
            SignallingAddr::resolve_streams(Some(SignallingAddr::Off), sig),
            None
        );
        let a: SignallingAddr = "127.0.0.1:0".parse().expect("address");
        assert_eq!(a.to_string(), "127.0.0.1:0");
        for bad in ["", "6021", "localhost:6021", "on"] {
            let e = bad.parse::<SignallingAddr>().expect_err(bad).to_string();
            assert!(e.contains("HOST:PORT"), "{e}");
        }
    }

    #[test]
    fn ice_servers_are_checked() {
        let s: IceServer = "stun:stun.l.google.com:19302".parse().expect("stun");
        assert_eq!(
            s.parts().expect("parts"),
            ("stun", "stun.l.google.com".into(), 19302)
        );
        assert!(s.is_stun());
        let t: IceServer = "turn:10.0.0.1?transport=udp".parse().expect("turn");
        assert_eq!(t.parts().expect("parts"), ("turn", "10.0.0.1".into(), 3478));
        let v6: IceServer = "stun:[2001:db8::1]:3478".parse().expect("v6");
        assert_eq!(v6.parts().expect("parts").1, "2001:db8::1");
        for bad in ["", "stun:", "http://x", "stun:h:0", "stun:h:x", "stun:a b"] {
            let e = bad.parse::<IceServer>().expect_err(bad).to_string();
            assert!(e.contains("stun:HOST"), "{e}");
        }
        let c = WebRtcConfig {
            max_viewers: 0,
            ..WebRtcConfig::default()
        };
        assert!(c.validate().expect_err("0").to_string().contains("1 to 64"));
        assert!(WebRtcConfig::default().validate().is_ok());
    }
}
