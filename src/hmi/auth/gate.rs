//! Who may reach the HMI at all, and who may pilot without a password.
//!
//! Owns [`OpenControl`] (`[hmi] open_control`), and the Host and Origin
//! checks against foreign web pages and DNS rebinding ([`Gate`]). Decides
//! from plain strings and addresses; reads nothing but the machine's host
//! name ([`machine_hostname`]).

use std::net::IpAddr;

use serde::{Deserialize, Serialize};

/// `[hmi] open_control`: which client addresses may pilot without the
/// pilot password. Never applies with MAVLink signing on. The default is
/// `None` on the vehicle and `Loopback` with `--sim` (see `config::resolve`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OpenControl {
    /// Every session must log in.
    #[default]
    None,
    /// A browser on the vehicle itself (127.0.0.0/8, ::1).
    Loopback,
    /// Also private networks: RFC 1918, IPv6 ULA (fc00::/7) and link-local.
    Private,
}

impl std::fmt::Display for OpenControl {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::None => "none",
            Self::Loopback => "loopback",
            Self::Private => "private",
        })
    }
}

impl OpenControl {
    /// Whether a client at `ip` may pilot without logging in.
    pub fn admits(self, ip: IpAddr) -> bool {
        let ip = ip.to_canonical();
        match self {
            Self::None => false,
            Self::Loopback => ip.is_loopback(),
            Self::Private => {
                ip.is_loopback()
                    || match ip {
                        IpAddr::V4(v4) => v4.is_private() || v4.is_link_local(),
                        IpAddr::V6(v6) => {
                            let first = v6.segments()[0];
                            (first & 0xfe00) == 0xfc00 || (first & 0xffc0) == 0xfe80
                        }
                    }
            }
        }
    }
}

/// An origin as browsers send it: `scheme://host[:port]`, lower case.
/// Errors say what is wrong and the fix.
pub fn parse_origin(s: &str) -> Result<String, String> {
    let bad = |why: &str| {
        format!(
            "\"{s}\" is not an origin ({why}) — use scheme://host[:port], e.g. http://topside.local:8080"
        )
    };
    let lower = s.trim().trim_end_matches('/').to_ascii_lowercase();
    let Some((scheme, rest)) = lower.split_once("://") else {
        return Err(bad("no scheme"));
    };
    if scheme != "http" && scheme != "https" {
        return Err(bad("the scheme must be http or https"));
    }
    if rest.is_empty() || rest.contains(['/', '?', '#', '@']) {
        return Err(bad("only a host and a port, no path"));
    }
    if rest.contains(|c: char| c.is_whitespace() || c.is_control()) {
        return Err(bad("a space or a control character"));
    }
    match split_host(rest) {
        None => return Err(bad("the port is not a number")),
        Some("") => return Err(bad("no host")),
        Some(_) => {}
    }
    Ok(lower)
}

/// The host part of `host[:port]` (IPv6 literals keep their brackets off),
/// or `None` when the port is not a number.
/// A TCP port as a Host header writes it: 1–5 digits, at most 65535.
fn port_ok(port: &str) -> bool {
    (1..=5).contains(&port.len())
        && port.bytes().all(|b| b.is_ascii_digit())
        && port.parse::<u16>().is_ok()
}

fn split_host(hostport: &str) -> Option<&str> {
    if let Some(rest) = hostport.strip_prefix('[') {
        let (host, after) = rest.split_once(']')?;
        return match after {
            "" => Some(host),
            p => p.strip_prefix(':').filter(|p| port_ok(p)).map(|_| host),
        };
    }
    match hostport.rsplit_once(':') {
        Some((host, port)) if port_ok(port) => Some(host),
        Some(_) => None,
        None => Some(hostport),
    }
}

/// `host[:port]` with its port replaced by `port` (left out when it is
/// the scheme's default, as browsers write origins); `None` when `host` has
/// a port that is not a number.
pub fn with_port(host: &str, port: u16, tls: bool) -> Option<String> {
    let host = host.trim();
    let name = split_host(host)?;
    let name = if name.contains(':') {
        format!("[{name}]")
    } else {
        name.to_owned()
    };
    let default = if tls { 443 } else { 80 };
    Some(if port == default {
        name
    } else {
        format!("{name}:{port}")
    })
}

/// The Host and Origin rules (see [`Gate::host_ok`], [`Gate::origin_ok`]).
#[derive(Debug, Clone, Default)]
pub struct Gate {
    /// `[hmi] allowed_origins`, parsed.
    allowed_origins: Vec<String>,
    /// Host names this server answers to besides IP literals and localhost.
    names: Vec<String>,
}

impl Gate {
    /// `hostname`: the machine's name (it and `NAME.local` are accepted).
    pub fn new(allowed_origins: &[String], hostname: Option<&str>) -> Self {
        let mut names = Vec::new();
        if let Some(h) = hostname
            .map(str::to_ascii_lowercase)
            .filter(|h| !h.is_empty())
        {
            names.push(format!("{h}.local"));
            names.push(h);
        }
        for o in allowed_origins {
            if let Some(host) = o
                .split_once("://")
                .and_then(|(_, r)| split_host(r))
                .filter(|h| !h.is_empty())
            {
                names.push(host.to_owned());
            }
        }
        Self {
            allowed_origins: allowed_origins.to_vec(),
            names,
        }
    }

    /// DNS rebinding: a page from evil.example.com whose name now points at
    /// the vehicle still sends `Host: evil.example.com`. Only names that are
    /// the vehicle's own are answered: IP literals, `localhost`, the
    /// machine's host name (and `.local`), hosts of `allowed_origins`.
    pub fn host_ok(&self, host: &str) -> bool {
        let host = host.trim().to_ascii_lowercase();
        let Some(name) = split_host(&host) else {
            return false;
        };
        let name = name.trim_end_matches('.');
        if name.is_empty() {
            return false;
        }
        name.parse::<IpAddr>().is_ok()
            || name == "localhost"
            || self.names.iter().any(|n| n == name)
    }

    /// A page may use the WebSocket and change state only from its own
    /// origin (`scheme://` + the request's Host) or an allowed one.
    pub fn origin_ok(&self, origin: &str, host: Option<&str>, tls: bool) -> bool {
        let origin = origin.trim().to_ascii_lowercase();
        let scheme = if tls { "https" } else { "http" };
        host.is_some_and(|h| origin == format!("{scheme}://{}", h.trim().to_ascii_lowercase()))
            || self.allowed_origins.contains(&origin)
    }
}

/// The machine's host name, for [`Gate::new`].
pub fn machine_hostname() -> Option<String> {
    nix::unistd::gethostname()
        .ok()
        .and_then(|h| h.into_string().ok())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn open_control_admits() {
        let ip = |s: &str| s.parse::<IpAddr>().unwrap();
        assert!(OpenControl::Loopback.admits(ip("127.0.0.1")));
        assert!(OpenControl::Loopback.admits(ip("::1")));
        assert!(OpenControl::Loopback.admits(ip("::ffff:127.0.0.1")));
        assert!(!OpenControl::Loopback.admits(ip("192.168.2.2")));
        assert!(!OpenControl::None.admits(ip("127.0.0.1")));
        for p in [
            "10.1.2.3",
            "172.16.0.9",
            "192.168.2.1",
            "169.254.1.1",
            "fd00::1",
            "fe80::1",
            "127.0.0.1",
        ] {
            assert!(OpenControl::Private.admits(ip(p)), "{p}");
        }
        for p in ["8.8.8.8", "172.32.0.1", "2001:db8::1"] {
            assert!(!OpenControl::Private.admits(ip(p)), "{p}");
        }
    }

    #[test]
    fn host_rule_stops_rebinding() {
        let g = Gate::new(
            &[parse_origin("https://Topside.example:8443").unwrap()],
            Some("rov"),
        );
        for h in [
            "127.0.0.1:8080",
            "192.168.2.2",
            "[::1]:8080",
            "localhost:8080",
            "rov",
            "ROV.local:8080",
            "topside.example:8443",
            "localhost.",
        ] {
            assert!(g.host_ok(h), "{h}");
        }
        for h in [
            "evil.example.com",
            "evil.example.com:8080",
            "rov.evil.com",
            "127.0.0.1:x",
            "",
            // A port no TCP port can be (found by the http_gate fuzz target).
            "localhost:65536",
            "localhost:000000080",
            "[::1]:99999",
        ] {
            assert!(!g.host_ok(h), "{h}");
        }
    }

    #[test]
    fn a_port_beside_knows_the_page_on_the_hmis_port() {
        assert_eq!(
            with_port("192.168.2.2:6021", 8080, false).as_deref(),
            Some("192.168.2.2:8080")
        );
        assert_eq!(
            with_port("[::1]:6021", 8080, false).as_deref(),
            Some("[::1]:8080")
        );
        assert_eq!(with_port("rov", 80, false).as_deref(), Some("rov"));
        assert_eq!(with_port("rov:6021", 443, true).as_deref(), Some("rov"));
        assert_eq!(with_port("rov:x", 8080, false), None);
    }

    #[test]
    fn origin_rule() {
        let g = Gate::new(&[parse_origin("http://topside.local:8080/").unwrap()], None);
        assert!(g.origin_ok("http://127.0.0.1:8080", Some("127.0.0.1:8080"), false));
        assert!(g.origin_ok("http://ROV.local", Some("rov.local"), false));
        assert!(!g.origin_ok("http://127.0.0.1:8080", Some("127.0.0.1:8080"), true));
        assert!(!g.origin_ok("http://evil.example.com", Some("127.0.0.1:8080"), false));
        assert!(!g.origin_ok("null", Some("127.0.0.1:8080"), false));
        assert!(!g.origin_ok("http://127.0.0.1:9999", Some("127.0.0.1:8080"), false));
        assert!(g.origin_ok("http://topside.local:8080", Some("127.0.0.1:8080"), false));
        assert!(parse_origin("ftp://x").is_err());
        assert!(parse_origin("http://x/path").is_err());
        assert!(parse_origin("topside").is_err());
        assert!(parse_origin("http://x:port").is_err());
        assert!(parse_origin("http://top side").is_err());
        assert!(parse_origin("https://x\u{b}/").is_err());
        // No host at all (found by the http_gate fuzz target): such an
        // origin made the empty Host one of the vehicle's own names.
        assert!(parse_origin("http://:2").is_err());
        assert!(parse_origin("http://[]:8080").is_err());
        let g = Gate::new(&["http://:2".to_owned()], Some("rov"));
        assert!(!g.host_ok(""));
        assert!(!g.host_ok(":2"));
    }
}
