//! Who may use the browser HMI: the pilot password (argon2 PHC string in
//! `DATA_DIR/hmi-password`), which client addresses may pilot without it
//! (`[hmi] open_control`), the Host and Origin checks against foreign web
//! pages and DNS rebinding, the login throttle and the login cookies.
//!
//! Everything here decides from plain values and an explicit `now`, so the
//! rules are unit-tested without sockets or clocks. This module must never
//! log a password or a token, and never do more than a handful of password
//! checks per second for one client address, whatever it is sent.

use std::collections::HashMap;
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use argon2::{Argon2, PasswordHash, PasswordHasher as _, PasswordVerifier as _};
use rand::RngCore as _;
use serde::{Deserialize, Serialize};

/// The pilot password's file in the data directory.
pub const PASSWORD_FILE: &str = "hmi-password";
/// Shortest pilot password `set-password` accepts.
pub const MIN_PASSWORD_CHARS: usize = 8;
/// Longest password a login may carry (longer ones are refused unchecked).
pub const MAX_PASSWORD_BYTES: usize = 256;
/// Name of the login cookie.
pub const COOKIE: &str = "neptunus_login";
/// How long a login cookie is good for.
pub const LOGIN_LIFETIME: Duration = Duration::from_secs(12 * 3600);
/// Failed logins from one address that are checked without delay.
const FREE_FAILURES: u32 = 3;
/// The longest wait between checked attempts from one address.
const MAX_DELAY: Duration = Duration::from_secs(30);
/// A burst of failures (or of refused requests) is over, and summarised,
/// after this much quiet.
pub const BURST_QUIET: Duration = Duration::from_secs(30);
/// An address's failures are forgotten after this much quiet.
const FORGET_AFTER: Duration = Duration::from_secs(600);
/// Addresses the throttle remembers (the oldest is evicted).
const THROTTLE_CAPACITY: usize = 1024;
/// Login cookies held at once (the oldest is evicted).
const TOKEN_CAPACITY: usize = 256;

/// Errors of the password file.
#[derive(Debug, thiserror::Error)]
pub enum PasswordError {
    #[error(
        "cannot read the HMI pilot password file {path}: {source} — set the password again with `neptunus hmi set-password`"
    )]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "the HMI pilot password file {path} does not hold an argon2 PHC string ({why}) — set the password again with `neptunus hmi set-password`"
    )]
    Corrupt { path: PathBuf, why: String },
    #[error("cannot write the HMI pilot password file {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "the pilot password has {chars} characters — use at least {MIN_PASSWORD_CHARS} (and at most {MAX_PASSWORD_BYTES} bytes)"
    )]
    Length { chars: usize },
    #[error("cannot hash the pilot password: {0}")]
    Hash(String),
}

/// A verified-to-parse argon2 PHC string. Checking a password against it
/// takes tens of milliseconds on purpose.
#[derive(Clone, PartialEq, Eq)]
pub struct PilotPassword {
    phc: String,
}

impl std::fmt::Debug for PilotPassword {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PilotPassword(argon2 hash)")
    }
}

impl PilotPassword {
    /// Hashes `password` with a fresh random salt (argon2id, the crate's
    /// recommended parameters).
    pub fn hash(password: &str) -> Result<Self, PasswordError> {
        let chars = password.chars().count();
        if chars < MIN_PASSWORD_CHARS || password.len() > MAX_PASSWORD_BYTES {
            return Err(PasswordError::Length { chars });
        }
        let mut salt = [0u8; 16];
        rand::rng().fill_bytes(&mut salt);
        let salt = argon2::password_hash::SaltString::encode_b64(&salt)
            .map_err(|e| PasswordError::Hash(e.to_string()))?;
        let phc = Argon2::default()
            .hash_password(password.as_bytes(), &salt)
            .map_err(|e| PasswordError::Hash(e.to_string()))?
            .to_string();
        Ok(Self { phc })
    }

    /// Takes a PHC string as stored.
    pub fn from_phc(phc: &str) -> Result<Self, String> {
        let parsed = PasswordHash::new(phc.trim()).map_err(|e| e.to_string())?;
        if !parsed.algorithm.as_str().starts_with("argon2") {
            return Err(format!("algorithm {} is not argon2", parsed.algorithm));
        }
        Ok(Self {
            phc: phc.trim().to_owned(),
        })
    }

    pub fn phc(&self) -> &str {
        &self.phc
    }

    /// Whether `password` is the pilot's (the crate compares in constant time).
    pub fn verify(&self, password: &str) -> bool {
        if password.len() > MAX_PASSWORD_BYTES {
            return false;
        }
        PasswordHash::new(&self.phc).is_ok_and(|h| {
            Argon2::default()
                .verify_password(password.as_bytes(), &h)
                .is_ok()
        })
    }
}

/// The pilot password's file: `DATA_DIR/hmi-password`, mode 0600, written
/// whole to a temporary file and renamed (never half a hash).
#[derive(Debug, Clone)]
pub struct PasswordStore {
    path: PathBuf,
}

impl PasswordStore {
    pub fn new(data_dir: &Path) -> Self {
        Self {
            path: data_dir.join(PASSWORD_FILE),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The stored password, or `None` when none is set.
    pub fn load(&self) -> Result<Option<PilotPassword>, PasswordError> {
        match std::fs::read_to_string(&self.path) {
            Ok(text) => {
                PilotPassword::from_phc(&text)
                    .map(Some)
                    .map_err(|why| PasswordError::Corrupt {
                        path: self.path.clone(),
                        why,
                    })
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(source) => Err(PasswordError::Read {
                path: self.path.clone(),
                source,
            }),
        }
    }

    /// Hashes and stores `password`.
    pub fn set(&self, password: &str) -> Result<(), PasswordError> {
        let hashed = PilotPassword::hash(password)?;
        self.write(&format!("{}\n", hashed.phc()))
    }

    /// Removes the password; true if there was one.
    pub fn clear(&self) -> Result<bool, PasswordError> {
        match std::fs::remove_file(&self.path) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
            Err(source) => Err(PasswordError::Write {
                path: self.path.clone(),
                source,
            }),
        }
    }

    fn write(&self, text: &str) -> Result<(), PasswordError> {
        use std::io::Write as _;
        let err = |source| PasswordError::Write {
            path: self.path.clone(),
            source,
        };
        if let Some(dir) = self.path.parent() {
            std::fs::create_dir_all(dir).map_err(err)?;
        }
        let tmp = self.path.with_extension("tmp");
        let mut opts = std::fs::OpenOptions::new();
        opts.write(true).create(true).truncate(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::OpenOptionsExt as _;
            opts.mode(0o600);
        }
        let mut f = opts.open(&tmp).map_err(err)?;
        // A file left by an older version may carry wider permissions.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            f.set_permissions(std::fs::Permissions::from_mode(0o600))
                .map_err(err)?;
        }
        f.write_all(text.as_bytes()).map_err(err)?;
        f.sync_all().map_err(err)?;
        drop(f);
        std::fs::rename(&tmp, &self.path).map_err(err)
    }
}

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
    if split_host(rest).is_none() {
        return Err(bad("the port is not a number"));
    }
    Ok(lower)
}

/// The host part of `host[:port]` (IPv6 literals keep their brackets off),
/// or `None` when the port is not a number.
fn split_host(hostport: &str) -> Option<&str> {
    if let Some(rest) = hostport.strip_prefix('[') {
        let (host, after) = rest.split_once(']')?;
        return match after {
            "" => Some(host),
            p => p
                .strip_prefix(':')
                .filter(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()))
                .map(|_| host),
        };
    }
    match hostport.rsplit_once(':') {
        Some((host, port)) if !port.is_empty() && port.bytes().all(|b| b.is_ascii_digit()) => {
            Some(host)
        }
        Some(_) => None,
        None => Some(hostport),
    }
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
            if let Some(host) = o.split_once("://").and_then(|(_, r)| split_host(r)) {
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

/// The throttle's key for a client: its IPv4 address, or its IPv6 /64 (one
/// host may hold a whole /64, so per-address counting would not slow it).
pub fn throttle_key(ip: IpAddr) -> IpAddr {
    match ip.to_canonical() {
        IpAddr::V6(v6) => {
            let s = v6.segments();
            IpAddr::from([s[0], s[1], s[2], s[3], 0, 0, 0, 0])
        }
        v4 => v4,
    }
}

/// What the throttle says about a login attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admit {
    /// Check the password.
    Check,
    /// Too many failures: answer "wait" without checking.
    Wait(Duration),
}

/// What to log after a login attempt (at most a few lines per burst).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ThrottleNote {
    /// The first failure of a burst from this address.
    FirstFailure,
    /// A burst ended (quiet, or a success): failures checked and attempts
    /// refused unchecked while waiting.
    Summary {
        ip: IpAddr,
        failures: u64,
        waited: u64,
        over: Duration,
    },
}

#[derive(Debug, Clone)]
struct Failures {
    /// Failures since the last success (drives the delay).
    count: u32,
    blocked_until: Option<Instant>,
    last: Instant,
    /// The current burst: its start, failures checked and attempts refused
    /// unchecked; `None` once summarised.
    burst: Option<(Instant, u64, u64)>,
}

/// Failed pilot logins per client address, with a growing delay: the first
/// [`FREE_FAILURES`] are free, then 1 s, 2 s, 4 s … up to 30 s between
/// checked attempts. Bounded: the oldest address is evicted.
#[derive(Debug, Default)]
pub struct Throttle {
    table: HashMap<IpAddr, Failures>,
}

impl Throttle {
    /// May an attempt from `ip` be checked now?
    pub fn admit(&mut self, ip: IpAddr, now: Instant) -> Admit {
        let Some(f) = self.table.get_mut(&ip) else {
            return Admit::Check;
        };
        f.last = now;
        match f.blocked_until {
            Some(until) if until > now => {
                if let Some(b) = f.burst.as_mut() {
                    b.2 += 1;
                } else {
                    f.burst = Some((now, 0, 1));
                }
                Admit::Wait(until - now)
            }
            _ => Admit::Check,
        }
    }

    /// A checked attempt failed; says whether it starts a burst (log it).
    pub fn failed(&mut self, ip: IpAddr, now: Instant) -> Option<ThrottleNote> {
        if !self.table.contains_key(&ip) && self.table.len() >= THROTTLE_CAPACITY {
            let oldest = self
                .table
                .iter()
                .min_by_key(|(_, f)| f.last)
                .map(|(k, _)| *k);
            if let Some(k) = oldest {
                self.table.remove(&k);
            }
        }
        let f = self.table.entry(ip).or_insert(Failures {
            count: 0,
            blocked_until: None,
            last: now,
            burst: None,
        });
        f.count += 1;
        f.last = now;
        if f.count >= FREE_FAILURES {
            let exp = (f.count - FREE_FAILURES).min(16);
            let delay = Duration::from_secs(1u64 << exp).min(MAX_DELAY);
            f.blocked_until = Some(now + delay);
        }
        match f.burst.as_mut() {
            Some(b) => {
                b.1 += 1;
                None
            }
            None => {
                f.burst = Some((now, 1, 0));
                Some(ThrottleNote::FirstFailure)
            }
        }
    }

    /// A checked attempt succeeded: the address starts afresh; the summary
    /// of its burst, if one was under way.
    pub fn succeeded(&mut self, ip: IpAddr) -> Option<ThrottleNote> {
        let f = self.table.remove(&ip)?;
        summary(ip, &f)
    }

    /// Summaries of bursts that went quiet; forgets long-quiet addresses.
    pub fn sweep(&mut self, now: Instant) -> Vec<ThrottleNote> {
        let mut notes = Vec::new();
        for (ip, f) in &mut self.table {
            if now.saturating_duration_since(f.last) >= BURST_QUIET
                && let Some(n) = summary(*ip, f)
            {
                notes.push(n);
                f.burst = None;
            }
        }
        self.table
            .retain(|_, f| now.saturating_duration_since(f.last) < FORGET_AFTER);
        notes
    }

    pub fn len(&self) -> usize {
        self.table.len()
    }

    pub fn is_empty(&self) -> bool {
        self.table.is_empty()
    }
}

fn summary(ip: IpAddr, f: &Failures) -> Option<ThrottleNote> {
    let (start, failures, waited) = f.burst?;
    Some(ThrottleNote::Summary {
        ip,
        failures,
        waited,
        over: f.last.saturating_duration_since(start),
    })
}

/// Login cookies: random tokens with an expiry, in memory only (a restart
/// logs everybody out). Bounded: the oldest is evicted.
#[derive(Debug, Default)]
pub struct Tokens {
    map: HashMap<String, Instant>,
}

impl Tokens {
    /// A new token (256 random bits, hex) good until `now + LOGIN_LIFETIME`.
    pub fn issue(&mut self, now: Instant) -> String {
        self.map.retain(|_, exp| *exp > now);
        if self.map.len() >= TOKEN_CAPACITY {
            let oldest = self
                .map
                .iter()
                .min_by_key(|(_, e)| **e)
                .map(|(k, _)| k.clone());
            if let Some(k) = oldest {
                self.map.remove(&k);
            }
        }
        let mut bytes = [0u8; 32];
        rand::rng().fill_bytes(&mut bytes);
        let token: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        self.map.insert(token.clone(), now + LOGIN_LIFETIME);
        token
    }

    /// Whether `token` is a live login. (A map lookup, not constant time:
    /// guessing 256 random bits through timing is not a practical attack.)
    pub fn valid(&self, token: &str, now: Instant) -> bool {
        self.map.get(token).is_some_and(|exp| *exp > now)
    }

    pub fn revoke(&mut self, token: &str) {
        self.map.remove(token);
    }
}

/// The value of cookie `name` in a `Cookie` header.
pub fn cookie_value<'a>(header: &'a str, name: &str) -> Option<&'a str> {
    header.split(';').find_map(|kv| {
        let (k, v) = kv.trim().split_once('=')?;
        (k == name).then_some(v.trim())
    })
}

/// Refused requests of one kind (foreign Origin, foreign Host, watcher cap):
/// the first of a burst is logged, the rest counted and summarised when the
/// burst ends.
#[derive(Debug, Default)]
pub struct Bursts {
    /// Total refused since start.
    pub total: u64,
    current: Option<(Instant, Instant, u64)>,
}

impl Bursts {
    /// Counts one; true when it is the first of a burst (log it).
    pub fn hit(&mut self, now: Instant) -> bool {
        self.total += 1;
        match self.current.as_mut() {
            Some((_, last, n)) => {
                *last = now;
                *n += 1;
                false
            }
            None => {
                self.current = Some((now, now, 1));
                true
            }
        }
    }

    /// `(count, over)` of a burst that went quiet, once.
    pub fn sweep(&mut self, now: Instant) -> Option<(u64, Duration)> {
        let (start, last, n) = self.current?;
        if now.saturating_duration_since(last) < BURST_QUIET {
            return None;
        }
        self.current = None;
        (n > 1).then(|| (n, last.saturating_duration_since(start)))
    }
}

/// Text from a client, made safe and short for a log line.
pub fn loggable(s: &str) -> String {
    let mut out: String = s.chars().take(80).collect();
    if s.chars().count() > 80 {
        out.push('…');
    }
    format!("{out:?}")
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
        ] {
            assert!(!g.host_ok(h), "{h}");
        }
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
    }

    #[test]
    fn throttle_grows_caps_and_resets() {
        let ip: IpAddr = "192.168.2.9".parse().unwrap();
        let t0 = Instant::now();
        let mut t = Throttle::default();
        // Three free failures, the first one logged.
        assert_eq!(t.admit(ip, t0), Admit::Check);
        assert_eq!(t.failed(ip, t0), Some(ThrottleNote::FirstFailure));
        assert_eq!(t.admit(ip, t0), Admit::Check);
        assert_eq!(t.failed(ip, t0), None);
        assert_eq!(t.admit(ip, t0), Admit::Check);
        t.failed(ip, t0);
        // Then 1 s, 2 s, 4 s … capped at 30 s.
        assert_eq!(t.admit(ip, t0), Admit::Wait(Duration::from_secs(1)));
        let mut now = t0 + Duration::from_secs(1);
        for expect in [2, 4, 8, 16, 30, 30] {
            assert_eq!(t.admit(ip, now), Admit::Check);
            assert_eq!(t.failed(ip, now), None);
            assert_eq!(t.admit(ip, now), Admit::Wait(Duration::from_secs(expect)));
            now += Duration::from_secs(expect);
        }
        // Another address is not affected.
        assert_eq!(t.admit("10.0.0.1".parse().unwrap(), now), Admit::Check);
        // Quiet: one summary, once.
        let later = now + BURST_QUIET;
        let notes = t.sweep(later);
        assert!(
            matches!(
                notes.as_slice(),
                [ThrottleNote::Summary {
                    failures: 9,
                    waited: 7,
                    ..
                }]
            ),
            "{notes:?}"
        );
        assert!(t.sweep(later).is_empty());
        // A success resets.
        assert_eq!(t.admit(ip, later + MAX_DELAY), Admit::Check);
        t.succeeded(ip);
        assert!(t.is_empty());
    }

    #[test]
    fn ipv6_hosts_are_throttled_per_64() {
        let a = throttle_key("2001:db8:1:2::5".parse().unwrap());
        let b = throttle_key("2001:db8:1:2:ffff::9".parse().unwrap());
        assert_eq!(a, b);
        assert_ne!(a, throttle_key("2001:db8:1:3::5".parse().unwrap()));
        let v4: IpAddr = "192.168.2.9".parse().unwrap();
        assert_eq!(throttle_key(v4), v4);
        assert_eq!(throttle_key("::ffff:192.168.2.9".parse().unwrap()), v4);
    }

    #[test]
    fn throttle_is_bounded() {
        let t0 = Instant::now();
        let mut t = Throttle::default();
        for i in 0..(THROTTLE_CAPACITY as u32 + 10) {
            t.failed(
                IpAddr::from(i.to_be_bytes()),
                t0 + Duration::from_millis(u64::from(i)),
            );
        }
        assert_eq!(t.len(), THROTTLE_CAPACITY);
    }

    #[test]
    fn tokens_expire_and_revoke() {
        let t0 = Instant::now();
        let mut tokens = Tokens::default();
        let a = tokens.issue(t0);
        assert_eq!(a.len(), 64);
        assert!(tokens.valid(&a, t0));
        assert!(!tokens.valid(&a, t0 + LOGIN_LIFETIME));
        assert!(!tokens.valid("nope", t0));
        tokens.revoke(&a);
        assert!(!tokens.valid(&a, t0));
        for _ in 0..TOKEN_CAPACITY + 5 {
            tokens.issue(t0);
        }
        assert!(tokens.map.len() <= TOKEN_CAPACITY);
    }

    #[test]
    fn bursts_log_once() {
        let t0 = Instant::now();
        let mut b = Bursts::default();
        assert!(b.hit(t0));
        for i in 1..1000 {
            assert!(!b.hit(t0 + Duration::from_millis(i)));
        }
        assert_eq!(b.sweep(t0 + Duration::from_secs(1)), None);
        assert_eq!(
            b.sweep(t0 + Duration::from_secs(40)).map(|(n, _)| n),
            Some(1000)
        );
        assert!(b.hit(t0 + Duration::from_secs(41)));
        assert_eq!(b.total, 1001);
    }

    #[test]
    fn password_hash_roundtrip_and_file() {
        let dir = tempfile::tempdir().unwrap();
        let store = PasswordStore::new(dir.path());
        assert!(store.load().unwrap().is_none());
        assert!(matches!(
            store.set("short"),
            Err(PasswordError::Length { chars: 5 })
        ));
        store.set("tide-pool-42").unwrap();
        let text = std::fs::read_to_string(store.path()).unwrap();
        assert!(text.starts_with("$argon2id$"), "{text}");
        assert!(!text.contains("tide-pool"));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(store.path())
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let p = store.load().unwrap().unwrap();
        assert!(p.verify("tide-pool-42"));
        assert!(!p.verify("tide-pool-41"));
        assert!(!format!("{p:?}").contains("argon2id$"));
        std::fs::write(store.path(), "plain text").unwrap();
        assert!(matches!(store.load(), Err(PasswordError::Corrupt { .. })));
        assert!(store.clear().unwrap());
        assert!(!store.clear().unwrap());
    }

    #[test]
    fn cookies() {
        assert_eq!(
            cookie_value("a=1; neptunus_login=abc; b=2", COOKIE),
            Some("abc")
        );
        assert_eq!(cookie_value("a=1", COOKIE), None);
    }
}
