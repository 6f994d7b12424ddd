//! Login cookies: random tokens with an expiry, held in memory.
//!
//! Owns [`Tokens`] and reading the cookie from a `Cookie` header
//! ([`cookie_value`]). Never logs a token.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use rand::RngCore as _;

/// Name of the login cookie.
pub const COOKIE: &str = "neptunus_login";
/// How long a login cookie is good for.
pub const LOGIN_LIFETIME: Duration = Duration::from_secs(12 * 3600);
/// Login cookies held at once (the oldest is evicted).
const TOKEN_CAPACITY: usize = 256;

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
    fn cookies() {
        assert_eq!(
            cookie_value("a=1; neptunus_login=abc; b=2", COOKIE),
            Some("abc")
        );
        assert_eq!(cookie_value("a=1", COOKIE), None);
    }
}
