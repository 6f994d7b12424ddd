//! Fuzzes the HMI's own reading of HTTP headers: the Host and Origin rules
//! (DNS rebinding, foreign pages), origins in `[hmi] allowed_origins`, the
//! login cookie, the Host that goes into the Content-Security-Policy and
//! into the redirect of plain HTTP on the TLS port, `If-None-Match`, the
//! log's quoting of client text, and mavlink2rest's REST paths.
//!
//! The input is cut at newlines into a Host, an Origin, an allowed
//! origin, the machine's name and one more value (first byte: flags and a
//! port). Nothing may panic, and:
//! - a Host the gate admits is one the policy may quote, stays admitted
//!   with another port, and its own page's origin is admitted;
//! - an origin that parses is its own normal form and is admitted;
//! - a Host that may go into a header adds no directive and no line;
//! - a cookie value read is a trimmed piece of the header without `;`, and
//!   a cookie written is read back;
//! - a client text quoted for the log has no control character and is short;
//! - `If-None-Match` matches only `*` or a list holding the file's tag;
//! - a REST path names a message only as written.
#![no_main]

use axum::http::{HeaderMap, HeaderValue, header};
use libfuzzer_sys::fuzz_target;
use neptunus::fuzzing::{etag, if_none_match, is_api_path, m2r_wanted, plain_host, redirect_host};
use neptunus::hmi::auth::{COOKIE, Gate, cookie_value, loggable, parse_origin, with_port};
use neptunus::hmi::headers::content_security_policy;

fuzz_target!(|data: &[u8]| {
    let Some((&[flags, port_hi, port_lo], rest)) = data.split_first_chunk::<3>() else {
        return;
    };
    let tls = flags & 1 != 0;
    let port = u16::from_be_bytes([port_hi, port_lo]);
    let text = String::from_utf8_lossy(rest);
    let mut parts = text.split('\n');
    let host = parts.next().unwrap_or_default();
    let origin = parts.next().unwrap_or_default();
    let allowed = parts.next().unwrap_or_default();
    let machine = parts.next().unwrap_or_default();
    let other = parts.next().unwrap_or_default();

    // Origins in the configuration.
    let allowed: Vec<String> = parse_origin(allowed).into_iter().collect();
    if let Some(o) = allowed.first() {
        assert_eq!(*o, o.to_ascii_lowercase());
        assert_eq!(o.trim(), o);
        assert_eq!(
            parse_origin(o).as_deref(),
            Ok(o.as_str()),
            "not its own normal form"
        );
        assert!(o.starts_with("http://") || o.starts_with("https://"));
    }
    let machine = Some(machine).filter(|m| !m.is_empty());
    let gate = Gate::new(&allowed, machine);
    for o in &allowed {
        assert!(gate.origin_ok(o, None, tls), "{o} is allowed but refused");
        assert!(gate.origin_ok(&o.to_ascii_uppercase(), Some(host), !tls));
    }

    // The Host rule.
    if gate.host_ok(host) {
        let names_plain = machine.is_none_or(plain_host)
            && allowed
                .iter()
                .all(|o| o.split_once("://").is_some_and(|(_, h)| plain_host(h)));
        if names_plain {
            assert!(
                plain_host(host.trim()),
                "admitted host {host:?} is not a plain host name"
            );
        }
        let moved = with_port(host, port, tls).expect("an admitted host has a port or none");
        assert!(gate.host_ok(&moved), "{host:?} admitted, {moved:?} not");
        let scheme = if tls { "https" } else { "http" };
        assert!(gate.origin_ok(&format!("{scheme}://{}", host.trim()), Some(host), tls));
    }
    if !gate.origin_ok(origin, Some(host), tls) {
        assert!(!allowed.contains(&origin.trim().to_ascii_lowercase()));
    }

    // What goes into headers.
    if plain_host(host) {
        let csp = content_security_policy(Some(host));
        assert_eq!(csp.split(';').count(), 9, "{csp}");
        assert!(!csp.contains(','));
        assert!(HeaderValue::from_str(&csp).is_ok());
    }
    let head = format!("GET / HTTP/1.1\r\n{other}\r\n\r\n");
    if let Some(h) = redirect_host(&head) {
        assert!(plain_host(h));
        assert!(HeaderValue::from_str(&format!("https://{h}/")).is_ok());
    }
    if let Some(h) = redirect_host(other) {
        assert!(plain_host(h));
    }

    // The login cookie.
    if let Some(v) = cookie_value(other, COOKIE) {
        assert_eq!(v.trim(), v);
        assert!(!v.contains(';'));
        assert!(other.contains(v));
    }
    if !origin.contains(';') {
        let v = origin.trim();
        assert_eq!(
            cookie_value(&format!("a=b; {COOKIE}={v}; c=d"), COOKIE),
            Some(v)
        );
    }

    // Client text in the log.
    for s in [host, origin, other] {
        let l = loggable(s);
        assert!(!l.chars().any(char::is_control), "{l}");
        assert!(l.chars().count() <= 2 + 81 * 10);
    }

    // If-None-Match.
    let mut sha = [0u8; 32];
    for (d, s) in sha.iter_mut().zip(rest.iter().rev()) {
        *d = *s;
    }
    let tag = etag(&sha);
    let ours = tag
        .to_str()
        .expect("an etag is text")
        .trim_start_matches("W/")
        .to_owned();
    if let Ok(v) = HeaderValue::from_bytes(other.as_bytes()) {
        let mut h = HeaderMap::new();
        h.append(header::IF_NONE_MATCH, v);
        if if_none_match(&h, &tag) {
            assert!(
                other.contains(&ours) || other.split(',').any(|t| t.trim() == "*"),
                "{other:?}"
            );
        }
        h.append(header::IF_NONE_MATCH, tag.clone());
        assert!(if_none_match(&h, &tag));
    }

    // mavlink2rest's paths.
    let _ = is_api_path(other);
    let (s, c, name) = m2r_wanted(other, 1);
    if (s, c, name) != (1, 1, "HEARTBEAT") {
        let (s, c) = (s.to_string(), c.to_string());
        assert!(
            other.trim_start_matches('/').starts_with("vehicles/"),
            "{other:?}"
        );
        for piece in ["/components/", "/messages/", &s, &c, name] {
            assert!(other.contains(piece), "{other:?} has no {piece:?}");
        }
    }
    if !origin.is_empty() && !origin.contains('/') {
        let path = format!(
            "vehicles/{}/components/{}/messages/{origin}/",
            port >> 8,
            port & 0xff
        );
        assert_eq!(
            m2r_wanted(&path, 1),
            ((port >> 8) as u8, (port & 0xff) as u8, origin)
        );
    }
});
