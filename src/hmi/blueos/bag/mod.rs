//! The settings bag Cockpit keeps on a BlueOS vehicle ("bag of holdings"),
//! kept by the vehicle itself: `GET /bag/v1.0/get/PATH` answers the JSON at
//! that path (404 `{"detail":"Invalid path"}` when there is none, as
//! BlueOS answers), `POST /bag/v1.0/set/PATH` stores the JSON body there.
//! Cockpit keeps its vehicle id at `cockpit/cockpit-vehicle-id` and each
//! user's settings under `cockpit/settings-v2/USER/`.
//!
//! [`path`] checks the path, [`store`] holds the document and decides who
//! may write what (sans-IO), [`mod@file`] keeps it across restarts. A refused
//! request (a bad path, bad JSON, a value too large, a full bag, another's
//! value) gets a clear HTTP error with the reason in `detail`, is logged
//! (one line per kind of refusal every few seconds, with the count) and
//! changes nothing; a store that fails puts the value back and says so.

pub mod file;
pub mod path;
mod raw;
pub mod store;

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{StatusCode, Uri, header};
use axum::response::{IntoResponse, Response};

use crate::hmi::{Shared, auth, guard};
pub use file::BagFile;
pub use path::{BagPath, PathError};
pub use store::{Bag, BagError, Limits, Writer, Written};

/// Where the routes are.
pub const GET_PREFIX: &str = "/bag/v1.0/get/";
pub const SET_PREFIX: &str = "/bag/v1.0/set/";
/// At most one log line per kind of refusal this often (the rest counted).
const LOG_EVERY: Duration = Duration::from_secs(5);

/// The bag, its file and the refusals' log.
pub(crate) struct BagService {
    bag: tokio::sync::Mutex<Bag>,
    file: BagFile,
    refusals: Mutex<HashMap<&'static str, (Instant, u64)>>,
}

impl BagService {
    /// Reads the bag from the data directory (blocking: at start).
    pub(crate) fn load(data_dir: &std::path::Path, limits: Limits) -> BagService {
        let file = BagFile::new(data_dir);
        let bag = file.load(limits);
        tracing::debug!(
            file = %file.path().display(),
            bytes = bag.total_bytes(),
            "settings bag loaded"
        );
        BagService {
            bag: tokio::sync::Mutex::new(bag),
            file,
            refusals: Mutex::new(HashMap::new()),
        }
    }

    /// Logs a refusal: the first of its kind at once, then at most one line
    /// per [`LOG_EVERY`] with how many there were.
    fn refused(&self, kind: &'static str, what: &str, client: &str, why: &str) {
        let Ok(mut seen) = self.refusals.lock() else {
            return;
        };
        let now = Instant::now();
        let entry = seen.entry(kind).or_insert((now - LOG_EVERY, 0));
        entry.1 += 1;
        if now.duration_since(entry.0) >= LOG_EVERY {
            tracing::warn!(
                "settings bag refused {what} from {client}: {why} ({} refused of this kind since the last such line)",
                entry.1
            );
            *entry = (now, 0);
        }
    }
}

fn detail(status: StatusCode, text: impl Into<String>) -> Response {
    (
        status,
        axum::Json(serde_json::json!({ "detail": text.into() })),
    )
        .into_response()
}

/// The bag path after `prefix` in the request's own (still encoded) path.
fn raw_path<'a>(uri: &'a Uri, prefix: &str) -> &'a str {
    uri.path().strip_prefix(prefix).unwrap_or("")
}

fn path_refused(e: &PathError) -> Response {
    detail(
        StatusCode::BAD_REQUEST,
        format!("not a bag path: {e} — e.g. /bag/v1.0/get/cockpit/cockpit-vehicle-id"),
    )
}

/// `GET /bag/v1.0/get/PATH`.
pub(crate) async fn get(State(shared): State<Arc<Shared>>, req: Request) -> Response {
    let client = client_of(&req);
    let path = match BagPath::parse(raw_path(req.uri(), GET_PREFIX)) {
        Ok(p) => p,
        Err(e) => {
            shared
                .bag
                .refused("path", "a read", &client, &e.to_string());
            return path_refused(&e);
        }
    };
    match shared.bag.bag.lock().await.get(&path) {
        Some(text) => ([(header::CONTENT_TYPE, "application/json")], text).into_response(),
        None => detail(StatusCode::NOT_FOUND, "Invalid path"),
    }
}

/// `POST /bag/v1.0/set/PATH` with a JSON body.
pub(crate) async fn set(State(shared): State<Arc<Shared>>, req: Request<Body>) -> Response {
    let client = client_of(&req);
    let ip = guard::client_ip(req.extensions());
    let writer = if guard::may_pilot(&shared, ip, guard::logged_in(&shared, req.headers())) {
        Writer::Pilot
    } else {
        Writer::Watcher(ip.map_or_else(
            || "unknown".to_owned(),
            |ip| auth::throttle_key(ip).to_string(),
        ))
    };
    let service = &shared.bag;
    let path = match BagPath::parse(raw_path(req.uri(), SET_PREFIX)) {
        Ok(p) => p,
        Err(e) => {
            service.refused("path", "a write", &client, &e.to_string());
            return path_refused(&e);
        }
    };
    let what = format!("a write of {}", auth::loggable(&path.to_string()));
    let max = service.bag.lock().await.limits().value_bytes;
    let body = match read_body(req.into_body(), max).await {
        Ok(b) => b,
        Err(bytes) => {
            let e = BagError::ValueTooLarge { bytes, max };
            service.refused("size", &what, &client, &e.to_string());
            return detail(StatusCode::PAYLOAD_TOO_LARGE, e.to_string());
        }
    };
    let mut bag = service.bag.lock().await;
    let undo = match bag.set(&path, &body, &writer) {
        Ok(Written::Unchanged) => return stored(),
        Ok(Written::Changed(undo)) => undo,
        Err(e) => {
            let (kind, status) = match e {
                BagError::NotJson(_) | BagError::TooDeep => ("json", StatusCode::BAD_REQUEST),
                BagError::ValueTooLarge { .. } => ("size", StatusCode::PAYLOAD_TOO_LARGE),
                BagError::Full { .. }
                | BagError::AddressQuota { .. }
                | BagError::WatchersFull { .. } => ("full", StatusCode::INSUFFICIENT_STORAGE),
                BagError::NotYours(_) => ("owner", StatusCode::FORBIDDEN),
            };
            service.refused(kind, &what, &client, &e.to_string());
            return detail(status, e.to_string());
        }
    };
    let contents = bag.to_file();
    let at = service.file.path().to_path_buf();
    let saved = tokio::task::spawn_blocking(move || {
        crate::durable::write(&at, &contents, crate::durable::Mode::Exactly(0o600))
            .map_err(std::io::Error::from)
    })
    .await
    .unwrap_or_else(|e| Err(std::io::Error::other(e.to_string())));
    match saved {
        Ok(()) => stored(),
        Err(e) => {
            bag.undo(undo);
            tracing::error!(
                "settings bag: cannot store {} ({e}) — the value is not kept; check the data directory",
                service.file.path().display()
            );
            detail(
                StatusCode::SERVICE_UNAVAILABLE,
                format!("the vehicle cannot store its settings now: {e}"),
            )
        }
    }
}

/// The body, at most `max` bytes; `Err(bytes read)` when it is longer. A
/// longer body is still read (and dropped) up to [`DRAIN_BYTES`], so that
/// the client, still sending, gets the answer rather than a reset
/// connection; beyond that the connection is closed.
async fn read_body(body: Body, max: usize) -> Result<Bytes, usize> {
    use http_body_util::BodyExt as _;
    let mut body = body;
    let mut kept = Vec::new();
    let mut read = 0usize;
    while let Some(frame) = body.frame().await {
        let Ok(frame) = frame else { break };
        let Some(data) = frame.data_ref() else {
            continue;
        };
        read += data.len();
        if read <= max {
            kept.extend_from_slice(data);
        } else if read > DRAIN_BYTES {
            break;
        }
    }
    if read > max {
        Err(read)
    } else {
        Ok(Bytes::from(kept))
    }
}

/// How much of a body over the limit is read to answer it cleanly.
const DRAIN_BYTES: usize = 4 * 1024 * 1024;

fn stored() -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        "{\"detail\":\"stored\"}",
    )
        .into_response()
}

fn client_of(req: &Request) -> String {
    guard::client_ip(req.extensions())
        .map_or_else(|| "an unknown address".to_owned(), |i| i.to_string())
}
