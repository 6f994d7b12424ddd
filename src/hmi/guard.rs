//! The HTTP side of [`auth`]: a layer in front of every route
//! (Host check, Origin check on the WebSocket and on state-changing
//! requests, login needed for the REST API), the login and logout routes,
//! and the one password check that the page's form, the REST API and the
//! WebSocket `login` message all go through (same throttle, same log).
//!
//! It must never log a password or a token, nor one line per refused
//! request: refusals are counted and logged once per burst.

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::Shared;
use super::auth::{self, Admit, COOKIE, LOGIN_LIFETIME, ThrottleNote};

// Set on every request by the accept loop: with TLS the login cookie is
// `Secure` and the page's own origin is `https://`.
use super::server::ConnInfo;

/// Largest login request body.
const LOGIN_BODY_BYTES: usize = 1024;

/// The client's address, as the accept loop recorded it.
pub fn client_ip(req_ext: &axum::http::Extensions) -> Option<IpAddr> {
    req_ext
        .get::<ConnectInfo<SocketAddr>>()
        .map(|c| c.0.ip().to_canonical())
}

pub(crate) fn is_tls(req_ext: &axum::http::Extensions) -> bool {
    req_ext.get::<ConnInfo>().is_some_and(|c| c.tls)
}

/// The request's Host (HTTP/1.1 header, or the URI's authority).
fn host_of(req: &Request) -> Option<String> {
    req.headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .map(str::to_owned)
        .or_else(|| req.uri().authority().map(|a| a.as_str().to_owned()))
}

/// The login token the request carries, if it is live.
pub(crate) fn logged_in(shared: &Shared, headers: &HeaderMap) -> bool {
    login_token(headers).is_some_and(|t| {
        shared
            .tokens
            .lock()
            .is_ok_and(|tokens| tokens.valid(t, Instant::now()))
    })
}

/// May a client at `ip` pilot — a browser session or a mavlink2rest
/// client alike: logged in with the pilot password, or admitted by `[hmi]
/// open_control` (which never applies with MAVLink signing on: a browser
/// cannot sign frames).
pub(crate) fn may_pilot(shared: &Shared, ip: Option<IpAddr>, logged_in: bool) -> bool {
    logged_in || (!shared.signing && ip.is_some_and(|ip| shared.open_control.admits(ip)))
}

/// Why a client that may not pilot only watches, and what to do about it.
pub(crate) fn watch_only_reason(shared: &Shared) -> String {
    let set = "set one on the vehicle with `neptunus hmi set-password`, then log in";
    if shared.signing {
        if shared.password.is_some() {
            "MAVLink signing is on: log in with the pilot password to pilot".to_owned()
        } else {
            format!("MAVLink signing is on and no pilot password is set: {set}")
        }
    } else if shared.password.is_some() {
        "log in with the pilot password to pilot".to_owned()
    } else {
        let who = match shared.open_control {
            auth::OpenControl::None => {
                "[hmi] open_control = \"none\" lets no address pilot without one".to_owned()
            }
            oc => {
                format!("only {oc} addresses may pilot without one ([hmi] open_control = \"{oc}\")")
            }
        };
        format!("no pilot password is set, and {who}: {set}")
    }
}

fn login_token(headers: &HeaderMap) -> Option<&str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .find_map(|c| auth::cookie_value(c, COOKIE))
}

/// The guard in front of every route.
pub(crate) fn layer(app: Router, shared: Arc<Shared>) -> Router {
    app.layer(axum::middleware::from_fn_with_state(shared, check))
}

/// The same guard for a port beside the HMI's (the WebRTC signalling's):
/// the page's own origin there is still the HMI's, on `page_port`.
pub(crate) fn layer_beside(app: Router, shared: Arc<Shared>, page_port: u16) -> Router {
    app.layer(axum::middleware::from_fn_with_state(
        (shared, page_port),
        check_beside,
    ))
}

async fn check_beside(
    State((shared, page_port)): State<(Arc<Shared>, u16)>,
    req: Request,
    next: Next,
) -> Response {
    guard(&shared, Some(page_port), req, next).await
}

async fn check(State(shared): State<Arc<Shared>>, req: Request, next: Next) -> Response {
    guard(&shared, None, req, next).await
}

fn refuse(shared: &Shared, status: StatusCode, what: String, text: &'static str) -> Response {
    let first = shared
        .refused
        .lock()
        .is_ok_and(|mut b| b.hit(Instant::now()));
    if first {
        tracing::warn!(
            "browser HMI refused {what} — further refusals are counted and summarised when they stop"
        );
    }
    (status, text).into_response()
}

/// Host, Origin and the records' login; `page_port`: the request came on
/// a port beside the HMI's, whose page is on this port.
async fn guard(shared: &Shared, page_port: Option<u16>, req: Request, next: Next) -> Response {
    let ip = client_ip(req.extensions());
    let client = ip.map_or_else(|| "an unknown address".to_owned(), |i| i.to_string());
    let host = host_of(&req);
    if let Some(h) = &host
        && !shared.gate.host_ok(h)
    {
        return refuse(
            shared,
            StatusCode::FORBIDDEN,
            format!(
                "a request for host {} from {client} (DNS rebinding or a wrong name: use the vehicle's IP address or name, or add the origin to [hmi] allowed_origins)",
                auth::loggable(h)
            ),
            "This vehicle does not answer to that host name: open it by its IP address or its own name (or add the origin to [hmi] allowed_origins).\n",
        );
    }
    let path = req.uri().path();
    // Every WebSocket (the page's, mavlink2rest's) starts as an upgrade.
    let upgrade = req.headers().contains_key(header::UPGRADE);
    let changes_state = !matches!(*req.method(), Method::GET | Method::HEAD | Method::OPTIONS);
    if (upgrade || changes_state)
        && let Some(origin) = req.headers().get(header::ORIGIN)
    {
        let origin = origin.to_str().unwrap_or("(not text)");
        let tls = is_tls(req.extensions());
        let page = page_port.and_then(|p| host.as_deref().and_then(|h| auth::with_port(h, p, tls)));
        let gate = &shared.gate;
        if !gate.origin_ok(origin, host.as_deref(), tls)
            && !page.is_some_and(|h| gate.origin_ok(origin, Some(&h), tls))
        {
            return refuse(
                shared,
                StatusCode::FORBIDDEN,
                format!(
                    "a {} {path} from a page at origin {} (client {client}): not this HMI's own origin nor in [hmi] allowed_origins",
                    req.method(),
                    auth::loggable(origin)
                ),
                "Cross-origin request refused: only the vehicle's own page (or an origin in [hmi] allowed_origins) may use this.\n",
            );
        }
    }
    if is_record(path) && !may_pilot(shared, ip, logged_in(shared, req.headers())) {
        let message = if shared.password.is_some() {
            "the vehicle's records are for pilots: log in first (POST /api/login {\"password\": …} sets the login cookie)".to_owned()
        } else {
            format!(
                "the vehicle's records are for pilots: open only to addresses [hmi] open_control admits ({}) — set a pilot password on the vehicle with `neptunus hmi set-password` and log in",
                shared.open_control
            )
        };
        return (
            StatusCode::UNAUTHORIZED,
            axum::Json(serde_json::json!({ "error": message })),
        )
            .into_response();
    }
    next.run(req).await
}

/// The one read rule, the same for the page, the REST API and mavlink2rest:
/// what the vehicle shows anyone watching — live telemetry and state, the
/// parameters, the video (the page's WebSocket as a watcher, `/api/status`,
/// `/api/params`, `/api/video`, mavlink2rest's GET and WebSocket) — is open
/// to every client the Host and Origin checks admit, as it is to any
/// MAVLink station that listens; the vehicle's records (`/api/logs`: tlogs,
/// the event log with its client addresses, `neptunus.log`;
/// `/api/recordings`: the video recorded on the vehicle) are for those who
/// may pilot ([`may_pilot`]), like every request that acts.
pub(crate) fn is_record(path: &str) -> bool {
    ["/api/logs", "/api/recordings"]
        .iter()
        .any(|p| path == *p || path.strip_prefix(p).is_some_and(|r| r.starts_with('/')))
}

/// The outcome of one pilot login attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Login {
    Ok,
    Wrong,
    /// Throttled: not checked; try again in this many seconds.
    Wait(u64),
    /// No pilot password is set on the vehicle.
    NoPassword,
}

impl Login {
    pub fn message(self) -> String {
        match self {
            Self::Ok => "logged in: this session may arm, drive and request control".into(),
            Self::Wrong => "wrong pilot password".into(),
            Self::Wait(s) => format!("too many attempts — wait {s} s"),
            Self::NoPassword => "no pilot password is set on this vehicle — set one on the vehicle with `neptunus hmi set-password`".into(),
        }
    }
}

/// Checks a pilot password from `ip`: throttled per address, logged once
/// per burst, at most one check at a time. `via` names the way in for the log.
pub(crate) async fn check_password(
    shared: &Arc<Shared>,
    ip: Option<IpAddr>,
    password: &str,
    via: &str,
) -> Login {
    let Some(expected) = shared.password.clone() else {
        return Login::NoPassword;
    };
    let key = auth::throttle_key(ip.unwrap_or(IpAddr::from([0, 0, 0, 0])));
    let admit = shared
        .throttle
        .lock()
        .map_or(Admit::Wait(Duration::from_secs(1)), |mut t| {
            t.admit(key, Instant::now())
        });
    if let Admit::Wait(d) = admit {
        return Login::Wait(d.as_secs_f64().ceil().max(1.0) as u64);
    }
    let ok = {
        let Ok(_permit) = shared.checks.acquire().await else {
            return Login::Wait(1);
        };
        let password = password.to_owned();
        tokio::task::spawn_blocking(move || expected.verify(&password))
            .await
            .unwrap_or(false)
    };
    let now = Instant::now();
    let Ok(mut throttle) = shared.throttle.lock() else {
        return Login::Wrong;
    };
    if ok {
        if let Some(note) = throttle.succeeded(key) {
            log_note(&note);
        }
        drop(throttle);
        tracing::info!("browser HMI: pilot logged in from {key} ({via})");
        Login::Ok
    } else {
        if let Some(ThrottleNote::FirstFailure) = throttle.failed(key, now) {
            tracing::warn!(
                "browser HMI: wrong pilot password from {key} ({via}) — further failures from this address are counted, slowed down and summarised when they stop"
            );
        }
        Login::Wrong
    }
}

fn log_note(note: &ThrottleNote) {
    if let ThrottleNote::Summary {
        ip,
        failures,
        waited,
        over,
    } = note
    {
        tracing::warn!(
            "browser HMI: pilot login from {ip}: {failures} wrong passwords and {waited} attempts refused unchecked (throttled) over {} s",
            over.as_secs()
        );
    }
}

/// Logs the summaries of bursts that ended; runs while the server runs.
pub(crate) async fn sweep(shared: Arc<Shared>) {
    let mut tick = tokio::time::interval(Duration::from_secs(5));
    loop {
        tick.tick().await;
        let now = Instant::now();
        let notes = shared
            .throttle
            .lock()
            .map(|mut t| t.sweep(now))
            .unwrap_or_default();
        for n in &notes {
            log_note(n);
        }
        if let Some((n, over)) = shared.refused.lock().ok().and_then(|mut b| b.sweep(now)) {
            tracing::warn!(
                "browser HMI refused {n} requests for a foreign host or origin over {} s",
                over.as_secs()
            );
        }
        if let Some((n, over)) = shared
            .refused_watchers
            .lock()
            .ok()
            .and_then(|mut b| b.sweep(now))
        {
            tracing::warn!(
                "browser HMI refused {n} WebSocket sessions over {} s: {} were already watching ([hmi] max_watchers)",
                over.as_secs(),
                shared.max_watchers
            );
        }
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct LoginBody {
    password: String,
}

fn json(status: StatusCode, ok: bool, message: String) -> Response {
    (
        status,
        axum::Json(serde_json::json!({ "ok": ok, "message": message })),
    )
        .into_response()
}

/// `POST /api/login {"password": …}`: on success an HttpOnly, SameSite=Strict
/// cookie (Secure under TLS) with a random token, good for 12 h.
pub(crate) async fn login(State(shared): State<Arc<Shared>>, req: Request<Body>) -> Response {
    let ip = client_ip(req.extensions());
    let secure = is_tls(req.extensions());
    let body: Bytes = match axum::body::to_bytes(req.into_body(), LOGIN_BODY_BYTES).await {
        Ok(b) => b,
        Err(_) => {
            return json(
                StatusCode::PAYLOAD_TOO_LARGE,
                false,
                format!(
                    "the login request is over {LOGIN_BODY_BYTES} bytes — send {{\"password\": \"…\"}}"
                ),
            );
        }
    };
    let Ok(LoginBody { password }) = serde_json::from_slice::<LoginBody>(&body) else {
        return json(
            StatusCode::BAD_REQUEST,
            false,
            "not a login request — send JSON {\"password\": \"…\"}".into(),
        );
    };
    let outcome = check_password(&shared, ip, &password, "login form").await;
    match outcome {
        Login::Ok => {
            let token = match shared.tokens.lock() {
                Ok(mut t) => t.issue(Instant::now()),
                Err(_) => {
                    return json(StatusCode::INTERNAL_SERVER_ERROR, false, "internal".into());
                }
            };
            let cookie = format!(
                "{COOKIE}={token}; Path=/; HttpOnly; SameSite=Strict; Max-Age={}{}",
                LOGIN_LIFETIME.as_secs(),
                if secure { "; Secure" } else { "" }
            );
            let mut r = json(StatusCode::OK, true, outcome.message());
            if let Ok(v) = HeaderValue::from_str(&cookie) {
                r.headers_mut().insert(header::SET_COOKIE, v);
            }
            r
        }
        Login::Wrong => json(StatusCode::UNAUTHORIZED, false, outcome.message()),
        Login::Wait(s) => {
            let mut r = json(StatusCode::TOO_MANY_REQUESTS, false, outcome.message());
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
            r
        }
        Login::NoPassword => json(StatusCode::CONFLICT, false, outcome.message()),
    }
}

/// `POST /api/cockpit-link`: for a logged-in page, a Cockpit link (see
/// [`auth::Tokens::issue_link`]) and the mavlink2rest URL that carries it,
/// on the address and port the page itself reached.
pub(crate) async fn cockpit_link(State(shared): State<Arc<Shared>>, req: Request) -> Response {
    let link = login_token(req.headers()).and_then(|login| {
        shared
            .tokens
            .lock()
            .ok()
            .and_then(|mut t| t.issue_link(login, Instant::now()))
    });
    let Some(token) = link else {
        return json(
            StatusCode::UNAUTHORIZED,
            false,
            "log in with the pilot password first: the link opens Cockpit with this login".into(),
        );
    };
    let host = req
        .headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .filter(|h| super::headers::plain_host(h))
        .unwrap_or("localhost")
        .to_owned();
    let scheme = if is_tls(req.extensions()) {
        "wss"
    } else {
        "ws"
    };
    tracing::info!(
        "browser HMI: a Cockpit link made for {} (good for its first use within {} s)",
        client_ip(req.extensions()).map_or_else(|| "an unknown address".into(), |i| i.to_string()),
        auth::LINK_FIRST_USE.as_secs()
    );
    (
        StatusCode::OK,
        axum::Json(serde_json::json!({
            "ok": true,
            "mavlink": format!("{scheme}://{host}/mavlink2rest/ws/mavlink?token={token}"),
            "first_use_within_s": auth::LINK_FIRST_USE.as_secs(),
        })),
    )
        .into_response()
}

/// `POST /api/logout`: forgets the token and clears the cookie.
pub(crate) async fn logout(State(shared): State<Arc<Shared>>, headers: HeaderMap) -> Response {
    if let Some(t) = login_token(&headers)
        && let Ok(mut tokens) = shared.tokens.lock()
    {
        tokens.revoke(t);
    }
    let mut r = json(StatusCode::OK, true, "logged out".into());
    r.headers_mut().insert(
        header::SET_COOKIE,
        HeaderValue::from_static("neptunus_login=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0"),
    );
    r
}
