//! HTTP routes: the page and its assets, the WebSocket upgrade and the REST
//! API (`/api/status`, `/api/params`, `/api/logs`, `/api/logs/{kind}/{name}`,
//! `/api/recordings` and its files (`recordings.rs`), `/api/login`,
//! `/api/logout`). Who may use which is decided in front of
//! them by [`guard`].
//!
//! The server's own view of the vehicle ([`ServerView`]) is built like a
//! session's, from the messages the core sends to the HMI endpoint. The
//! parameter list is asked of the core (PARAM_REQUEST_LIST), which stays
//! the owner of parameters. Log downloads serve only names from the listing:
//! nothing from the request is ever joined onto a path.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{Path, Request, State, WebSocketUpgrade};
use axum::handler::Handler as _;
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Json, Response};
use axum::routing::{get, post};
use serde::Serialize;
use tokio::sync::{broadcast, watch};

use super::model::Model;
use super::protocol::{MAX_MESSAGE_BYTES, Telemetry};
use super::{Deliveries, SERVER_PEER, Shared, assets, guard, session};
use crate::dialect::neptunus::*;
use crate::vehicle::machine::{COMPONENT_ID, Input};

/// One parameter as the core last reported it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ParamEntry {
    pub index: u16,
    pub value: f32,
}

/// The server's own view of the vehicle.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ServerView {
    pub telemetry: Telemetry,
    pub params: BTreeMap<String, ParamEntry>,
    /// PARAM_VALUE's param_count (0 until one arrived).
    pub param_count: u16,
}

/// How often the REST status follows the vehicle.
const PUBLISH_PERIOD: Duration = Duration::from_millis(200);

/// Keeps [`ServerView`] up to date from the hub (messages for every session
/// and for the server's own peer).
pub(crate) async fn watch_vehicle(
    mut hub: broadcast::Receiver<Deliveries>,
    out: watch::Sender<ServerView>,
) {
    let mut model = Model::new(None, Instant::now());
    let mut events = Vec::new();
    let mut last_publish = Instant::now();
    let mut next = hub.recv().await;
    loop {
        let batch = match next {
            Ok(b) => b,
            Err(broadcast::error::RecvError::Lagged(_)) => {
                next = hub.recv().await;
                continue;
            }
            Err(broadcast::error::RecvError::Closed) => return,
        };
        for d in batch.iter() {
            if d.peer.is_some_and(|p| p != SERVER_PEER) {
                continue;
            }
            if let MavMessage::PARAM_VALUE(p) = &d.msg {
                let name = {
                    let b: &[u8] = p.param_id.as_ref();
                    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
                    String::from_utf8_lossy(&b[..end]).into_owned()
                };
                out.send_modify(|v| {
                    v.param_count = p.param_count;
                    v.params.insert(
                        name,
                        ParamEntry {
                            index: p.param_index,
                            value: p.param_value,
                        },
                    );
                });
                continue;
            }
            model.on_delivery(d, Instant::now(), &mut events);
            events.clear();
        }
        // Everything already queued first; then, once nothing is, the
        // status. It needs no more than a few updates a second: what
        // arrives meanwhile waits in the hub, and this task wakes five
        // times a second rather than at every pass of the vehicle's loop.
        next = match super::queued(&mut hub) {
            Some(n) => n,
            None => {
                if last_publish.elapsed() >= PUBLISH_PERIOD {
                    last_publish = Instant::now();
                    let t = model.snapshot(Instant::now());
                    out.send_modify(|v| v.telemetry = t);
                }
                tokio::time::sleep(PUBLISH_PERIOD).await;
                hub.recv().await
            }
        };
    }
}

pub(crate) fn routes(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(index).layer(assets::compression()))
        .route("/ws", get(ws))
        .route("/api/status", get(status))
        .route("/api/params", get(params))
        .route("/api/video", get(video))
        .route("/api/logs", get(logs))
        .route("/api/logs/{kind}/{name}", get(log_file))
        .route("/api/recordings", get(super::recordings::list))
        .route("/api/recordings/{name}", get(super::recordings::file))
        .route("/api/login", post(guard::login))
        .route("/api/logout", post(guard::logout))
        .route("/api/cockpit-link", post(guard::cockpit_link))
        // Compression around the page's files only (see `assets`).
        .fallback(asset.layer(assets::compression()))
        .with_state(shared)
}

async fn index(headers: HeaderMap) -> Response {
    assets::response("index.html", &headers)
}

async fn asset(uri: axum::http::Uri, headers: HeaderMap) -> Response {
    assets::response(uri.path().trim_start_matches('/'), &headers)
}

/// The upgrade (Host and Origin were checked in front): a logged-in client
/// gets its system id now; any other takes a watcher's place, or is refused
/// when `[hmi] max_watchers` are watching.
async fn ws(
    State(shared): State<Arc<Shared>>,
    upgrade: WebSocketUpgrade,
    req: Request,
) -> Response {
    let ip = guard::client_ip(req.extensions());
    let logged_in = guard::logged_in(&shared, req.headers());
    let lease = if logged_in {
        shared.lease_sysid()
    } else {
        None
    };
    let watcher = if lease.is_some() {
        None
    } else {
        match session::WatcherSlot::take(&shared) {
            Some(w) => Some(w),
            None => {
                let first = shared
                    .refused_watchers
                    .lock()
                    .is_ok_and(|mut b| b.hit(Instant::now()));
                if first {
                    tracing::warn!(
                        "browser HMI refused a WebSocket session from {ip:?}: {} sessions are already watching ([hmi] max_watchers) — further refusals are counted",
                        shared.max_watchers
                    );
                }
                return (
                    StatusCode::SERVICE_UNAVAILABLE,
                    format!(
                        "{} sessions are already watching this vehicle ([hmi] max_watchers): close one, or log in as the pilot\n",
                        shared.max_watchers
                    ),
                )
                    .into_response();
            }
        }
    };
    let start = session::Start {
        ip,
        logged_in,
        lease,
        watcher,
    };
    // The read buffer is zero-filled before every read of the socket
    // (128 KiB by default, a cost on every wake of the session): one
    // largest message is enough, a longer frame grows it.
    upgrade
        .max_message_size(MAX_MESSAGE_BYTES)
        .max_frame_size(MAX_MESSAGE_BYTES)
        .read_buffer_size(MAX_MESSAGE_BYTES)
        .on_upgrade(move |socket| session::run(socket, shared, start))
}

#[derive(Serialize)]
struct StatusBody {
    vehicle_sysid: u8,
    sessions_max: u16,
    sessions_free: usize,
    watchers: usize,
    watchers_max: usize,
    bad_web_messages: u64,
    /// Requests refused for a foreign Host or Origin since start.
    refused_requests: u64,
    telemetry: Telemetry,
}

async fn status(State(shared): State<Arc<Shared>>) -> Json<StatusBody> {
    // Live telemetry also when no session keeps the endpoint's streams built.
    shared
        .outlet
        .read(&mut shared.status.clone(), || true)
        .await;
    let (lo, hi) = shared.sysid_range;
    let free = shared.free_sysids.lock().map_or(0, |f| f.len());
    Json(StatusBody {
        vehicle_sysid: shared.vehicle_sysid,
        sessions_max: u16::from(hi) - u16::from(lo) + 1,
        sessions_free: free,
        watchers: shared.watchers.load(std::sync::atomic::Ordering::Relaxed),
        watchers_max: shared.max_watchers,
        bad_web_messages: shared
            .bad_messages
            .load(std::sync::atomic::Ordering::Relaxed),
        refused_requests: shared.refused.lock().map_or(0, |b| b.total),
        telemetry: shared.status.borrow().telemetry.clone(),
    })
}

/// Whether the page should load `/video.mjpg`, and where WebRTC is
/// described when it runs (asked first, so a vehicle without a camera or
/// WebRTC costs the page no failed request).
/// Whether the page has video and where; with a camera, the paths its
/// video takes and why (`path`), whether `/video.mjpg` has pictures
/// (`mjpeg`), and what the H.264 sender runs now (`h264`).
async fn video(State(shared): State<Arc<Shared>>) -> Json<serde_json::Value> {
    let mut v = serde_json::json!({
        "available": shared.video,
        "url": "/video.mjpg",
        "webrtc": shared.webrtc.then_some("/api/webrtc"),
    });
    if let (Some(info), Some(map)) = (&shared.video_info, v.as_object_mut())
        && let serde_json::Value::Object(extra) = info()
    {
        map.extend(extra);
    }
    Json(v)
}

#[derive(Serialize)]
struct ParamsBody {
    complete: bool,
    count: u16,
    params: BTreeMap<String, ParamEntry>,
}

/// Asks the core for its parameter list and waits (2 s at most) for all of it.
async fn params(State(shared): State<Arc<Shared>>) -> Response {
    let mut rx = shared.status.clone();
    let from = shared.server_sender();
    let request = MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
        target_system: shared.vehicle_sysid,
        target_component: COMPONENT_ID,
    });
    if shared
        .inputs
        .send(Input::Mavlink { from, msg: request })
        .await
        .is_err()
    {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            "the vehicle task is not running",
        )
            .into_response();
    }
    let complete =
        |v: &ServerView| v.param_count > 0 && v.params.len() >= usize::from(v.param_count);
    let _ = tokio::time::timeout(Duration::from_secs(2), rx.wait_for(complete)).await;
    let v = rx.borrow().clone();
    Json(ParamsBody {
        complete: complete(&v),
        count: v.param_count,
        params: v.params,
    })
    .into_response()
}

/// Log kinds and their folders in the data directory.
const LOG_KINDS: [(&str, &str); 2] = [("tlogs", "tlogs"), ("events", "events")];

#[derive(Serialize)]
struct LogEntry {
    kind: &'static str,
    name: String,
    bytes: u64,
    modified_unix_s: u64,
    url: String,
}

fn list_logs(shared: &Shared) -> Vec<LogEntry> {
    let mut out = Vec::new();
    for (kind, folder) in LOG_KINDS {
        let Ok(dir) = std::fs::read_dir(shared.data_dir.join(folder)) else {
            continue;
        };
        for entry in dir.flatten() {
            let Ok(meta) = entry.metadata() else { continue };
            if !meta.is_file() {
                continue;
            }
            let Some(name) = entry.file_name().to_str().map(str::to_owned) else {
                continue;
            };
            let modified_unix_s = meta
                .modified()
                .ok()
                .and_then(|m| m.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_secs());
            out.push(LogEntry {
                kind,
                url: format!("/api/logs/{kind}/{name}"),
                name,
                bytes: meta.len(),
                modified_unix_s,
            });
        }
    }
    out.sort_by(|a, b| (a.kind, &a.name).cmp(&(b.kind, &b.name)));
    out
}

async fn logs(State(shared): State<Arc<Shared>>) -> Json<serde_json::Value> {
    Json(serde_json::json!({ "logs": list_logs(&shared) }))
}

async fn log_file(
    State(shared): State<Arc<Shared>>,
    Path((kind, name)): Path<(String, String)>,
) -> Response {
    // Only a name the listing itself produced is served.
    let Some((kind, folder)) = LOG_KINDS.iter().find(|(k, _)| *k == kind) else {
        return (
            StatusCode::NOT_FOUND,
            "no such log kind: use tlogs or events",
        )
            .into_response();
    };
    let listed = list_logs(&shared)
        .into_iter()
        .any(|e| e.kind == *kind && e.name == name);
    if !listed {
        return (StatusCode::NOT_FOUND, "no such log: see /api/logs").into_response();
    }
    match tokio::fs::read(shared.data_dir.join(folder).join(&name)).await {
        Ok(bytes) => (
            [
                (header::CONTENT_TYPE, "application/octet-stream".to_owned()),
                (
                    header::CONTENT_DISPOSITION,
                    format!("attachment; filename=\"{name}\""),
                ),
            ],
            bytes,
        )
            .into_response(),
        Err(e) => (StatusCode::NOT_FOUND, format!("cannot read the log: {e}")).into_response(),
    }
}
