//! CORS for the pages the Origin rule admits: Cockpit served from an origin
//! in `[hmi] allowed_origins` (its own web server, a laptop's `localhost`)
//! reads the answers of the API routes Cockpit uses (mavlink2rest, the
//! settings bag, the beacon, the camera manager's streams), and its
//! preflights pass. Any other origin gets no CORS header, so its page can
//! read nothing; the guard in front has already refused its writes.
//!
//! Must never admit an origin the guard would refuse.

use std::sync::Arc;

use axum::Router;
use axum::extract::{Request, State};
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::{Shared, auth, guard};

/// Which paths answer a preflight (`OPTIONS`) themselves.
pub(crate) type Preflight = fn(&str) -> bool;

/// The layer; `page_port`: the routes are on a port beside the HMI's, whose
/// page is on that port (as for the guard).
pub(crate) fn layer<S: Clone + Send + Sync + 'static>(
    app: Router<S>,
    shared: Arc<Shared>,
    preflight: Preflight,
    page_port: Option<u16>,
) -> Router<S> {
    app.layer(axum::middleware::from_fn_with_state(
        (shared, preflight, page_port),
        cors,
    ))
}

async fn cors(
    State((shared, preflight, page_port)): State<(Arc<Shared>, Preflight, Option<u16>)>,
    req: Request,
    next: Next,
) -> Response {
    let origin = req
        .headers()
        .get(header::ORIGIN)
        .and_then(|o| o.to_str().ok())
        .map(str::to_owned);
    let host = req
        .headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .map(str::to_owned);
    let tls = guard::is_tls(req.extensions());
    let page = page_port.and_then(|p| host.as_deref().and_then(|h| auth::with_port(h, p, tls)));
    let allowed = origin
        .as_deref()
        .filter(|o| {
            shared.gate.origin_ok(o, host.as_deref(), tls)
                || page
                    .as_deref()
                    .is_some_and(|p| shared.gate.origin_ok(o, Some(p), tls))
        })
        .and_then(|o| HeaderValue::from_str(o).ok());
    let mut resp = if req.method() == Method::OPTIONS && preflight(req.uri().path()) {
        StatusCode::NO_CONTENT.into_response()
    } else {
        next.run(req).await
    };
    if let Some(o) = allowed {
        let h = resp.headers_mut();
        h.insert(header::ACCESS_CONTROL_ALLOW_ORIGIN, o);
        h.insert(
            header::ACCESS_CONTROL_ALLOW_METHODS,
            HeaderValue::from_static("GET, POST, OPTIONS"),
        );
        h.insert(
            header::ACCESS_CONTROL_ALLOW_HEADERS,
            HeaderValue::from_static("content-type"),
        );
        h.insert(header::VARY, HeaderValue::from_static("Origin"));
    }
    resp
}
