//! Security headers on every HMI response (pages, assets, the REST API, the
//! camera's routes, 404s), applied as one middleware around the whole
//! router.
//!
//! The Content-Security-Policy is the one the page actually needs: its own
//! scripts and styles only (no inline script or `style` attribute in
//! `web/`; styles set from JavaScript through the CSSOM are not affected),
//! images from itself (`/video.mjpg`) and `data:` (the empty favicon), the
//! WebSocket and `fetch` to its own origin, and no framing by anyone
//! (`frame-ancestors 'none'`, with `X-Frame-Options: DENY` for old
//! browsers): a page that can be framed can be clickjacked into arming.
//!
//! Must never echo anything from the request into a header unless it is
//! checked first (the Host, in `connect-src`, is limited to host-name
//! characters).

use axum::extract::Request;
use axum::http::header::{self, HeaderValue};
use axum::middleware::Next;
use axum::response::Response;

/// `Referrer-Policy`: the vehicle's address and paths never leak to other sites.
const REFERRER_POLICY: &str = "no-referrer";

/// The policy, with the WebSocket's own origin spelt out when the Host is
/// known: CSP Level 3 lets `'self'` cover `ws:`/`wss:` of the same host, but
/// older Safari does not.
pub fn content_security_policy(host: Option<&str>) -> String {
    let ws = host
        .map(|h| format!(" ws://{h} wss://{h}"))
        .unwrap_or_default();
    format!(
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; \
         connect-src 'self'{ws}; object-src 'none'; base-uri 'none'; form-action 'none'; \
         frame-ancestors 'none'"
    )
}

/// Whether a Host header is only `name[:port]` / `[v6]:port` characters, so
/// it cannot add a directive to the policy.
pub(crate) fn plain_host(h: &str) -> bool {
    !h.is_empty()
        && h.len() <= 255
        && h.bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'-' | b':' | b'[' | b']'))
}

/// The middleware: adds the headers to whatever the inner router answered.
pub async fn security_headers(req: Request, next: Next) -> Response {
    let host = req
        .headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .filter(|h| plain_host(h))
        .map(str::to_owned);
    let mut res = next.run(req).await;
    let h = res.headers_mut();
    if let Ok(csp) = HeaderValue::from_str(&content_security_policy(host.as_deref())) {
        h.insert(header::CONTENT_SECURITY_POLICY, csp);
    }
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static(REFERRER_POLICY),
    );
    res
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hostile_host_cannot_extend_the_policy() {
        assert!(plain_host("rov.local:8080"));
        assert!(plain_host("[::1]:8080"));
        assert!(plain_host("192.168.2.2"));
        assert!(!plain_host("x; script-src *"));
        assert!(!plain_host("x'unsafe-inline'"));
        assert!(!plain_host(""));
    }

    #[test]
    fn the_policy_forbids_framing_and_names_the_websocket() {
        let p = content_security_policy(Some("rov:8080"));
        assert!(p.contains("frame-ancestors 'none'"));
        assert!(p.contains("connect-src 'self' ws://rov:8080 wss://rov:8080;"));
        assert!(!content_security_policy(None).contains("ws://"));
    }
}
