//! Login cookies: random tokens with an expiry, held in memory; and the
//! Cockpit links a logged-in page makes from its login.
//!
//! Owns [`Tokens`] and reading the cookie from a `Cookie` header
//! ([`cookie_value`]). Never logs a token.
//!
//! A Cockpit link is a token that opens Cockpit as the pilot: the page
//! puts it in the mavlink2rest URL it opens Cockpit with (Cockpit takes a
//! WebSocket URL from its own address, never a cookie of another site). It
//! is good for a first use within [`LINK_FIRST_USE`]; from then on only
//! from the address that used it (Cockpit reconnects with it), and never
//! beyond the login it was made from: that login's expiry or logout ends it.

use std::collections::HashMap;
use std::net::IpAddr;
use std::time::{Duration, Instant};

use rand::RngCore as _;

/// Name of the login cookie.
pub const COOKIE: &str = "neptunus_login";
/// How long a login cookie is good for.
pub const LOGIN_LIFETIME: Duration = Duration::from_secs(12 * 3600);
/// Login cookies held at once (the oldest is evicted); Cockpit links too.
const TOKEN_CAPACITY: usize = 256;
/// A Cockpit link not used within this is void.
pub const LINK_FIRST_USE: Duration = Duration::from_secs(120);

/// A Cockpit link.
#[derive(Debug, Clone)]
struct Link {
    /// The login token it was made from.
    login: String,
    made: Instant,
    /// The address (login throttle's key) that used it first.
    bound: Option<IpAddr>,
}

/// Login cookies: random tokens with an expiry, in memory only (a restart
/// logs everybody out), and the Cockpit links made from them. Bounded: the
/// oldest is evicted.
#[derive(Debug, Default)]
pub struct Tokens {
    map: HashMap<String, Instant>,
    links: HashMap<String, Link>,
}

fn random_token() -> String {
    let mut bytes = [0u8; 32];
    rand::rng().fill_bytes(&mut bytes);
    bytes.iter().map(|b| format!("{b:02x}")).collect()
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
        let token = random_token();
        self.map.insert(token.clone(), now + LOGIN_LIFETIME);
        token
    }

    /// A Cockpit link made from the live login `login`; `None` when it is not.
    pub fn issue_link(&mut self, login: &str, now: Instant) -> Option<String> {
        if !self.valid(login, now) {
            return None;
        }
        let map = &self.map;
        self.links.retain(|_, l| {
            map.get(&l.login).is_some_and(|exp| *exp > now)
                && (l.bound.is_some() || now.duration_since(l.made) < LINK_FIRST_USE)
        });
        if self.links.len() >= TOKEN_CAPACITY {
            let oldest = self
                .links
                .iter()
                .min_by_key(|(_, l)| l.made)
                .map(|(k, _)| k.clone());
            if let Some(k) = oldest {
                self.links.remove(&k);
            }
        }
        let token = random_token();
        self.links.insert(
            token.clone(),
            Link {
                login: login.to_owned(),
                made: now,
                bound: None,
            },
        );
        Some(token)
    }

    /// Whether the Cockpit link `token` logs in a client at `ip` (the
    /// login throttle's key): its first use binds it to that address.
    pub fn use_link(&mut self, token: &str, ip: IpAddr, now: Instant) -> bool {
        let Some(link) = self.links.get(token) else {
            return false;
        };
        if !self.valid(&link.login, now) {
            self.links.remove(token);
            return false;
        }
        let Some(link) = self.links.get_mut(token) else {
            return false;
        };
        match link.bound {
            Some(at) => at == ip,
            None if now.duration_since(link.made) < LINK_FIRST_USE => {
                link.bound = Some(ip);
                true
            }
            None => false,
        }
    }

    /// Whether `token` is a live login. (A map lookup, not constant time:
    /// guessing 256 random bits through timing is not a practical attack.)
    pub fn valid(&self, token: &str, now: Instant) -> bool {
        self.map.get(token).is_some_and(|exp| *exp > now)
    }

    /// Ends a login, and the Cockpit links made from it.
    pub fn revoke(&mut self, token: &str) {
        self.map.remove(token);
        self.links.retain(|_, l| l.login != token);
    }
}

/// The value of cookie `name` in a `Cookie` header.
pub fn cookie_value<'a>(header: &'a str, name: &str) -> Option<&'a str> {
    header.split(';').find_map(|kv| {
        let (k, v) = kv.trim().split_once('=')?;
        (k == name).then_some(v.trim())
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

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
    fn a_cockpit_link_is_short_lived_then_bound_to_its_address_and_its_login() {
        let t0 = Instant::now();
        let mut tokens = Tokens::default();
        assert_eq!(tokens.issue_link("not a login", t0), None);
        let login = tokens.issue(t0);
        let here: IpAddr = "192.168.254.2".parse().unwrap();
        let there: IpAddr = "192.168.254.9".parse().unwrap();
        // Unused for too long: void.
        let late = tokens.issue_link(&login, t0).unwrap();
        assert!(!tokens.use_link(&late, here, t0 + LINK_FIRST_USE));
        // Used in time: from then on from that address only, also later.
        let link = tokens.issue_link(&login, t0).unwrap();
        assert_eq!(link.len(), 64);
        assert!(!tokens.valid(&link, t0), "a link is not a login cookie");
        assert!(tokens.use_link(&link, here, t0 + Duration::from_secs(5)));
        assert!(tokens.use_link(&link, here, t0 + Duration::from_secs(3600)));
        assert!(!tokens.use_link(&link, there, t0 + Duration::from_secs(6)));
        assert!(!tokens.use_link("guess", here, t0));
        // Never beyond its login.
        assert!(!tokens.use_link(&link, here, t0 + LOGIN_LIFETIME));
        let login = tokens.issue(t0);
        let link = tokens.issue_link(&login, t0).unwrap();
        assert!(tokens.use_link(&link, here, t0));
        tokens.revoke(&login);
        assert!(!tokens.use_link(&link, here, t0));
        for _ in 0..TOKEN_CAPACITY + 5 {
            let login = tokens.issue(t0);
            tokens.issue_link(&login, t0);
        }
        assert!(tokens.links.len() <= TOKEN_CAPACITY);
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
