//! A mavlink2rest-compatible API on the HMI's port, so Cockpit (Blue
//! Robotics' browser ground station) drives Neptunus with nothing else
//! installed: the WebSocket `ws/mavlink` both ways, the REST view of the
//! last message per (system, component, name) with its `status.time`,
//! `POST mavlink`, `helper/mavlink?name=` (a zeroed example of any message
//! of our dialect) and `info` — under `/mavlink2rest/`, `/mavlink2rest/v1/`,
//! `/v1/` and the root, as mavlink2rest serves them. JSON in mavlink2rest's
//! shape ([`frame`], `dialect::json_shape`).
//!
//! The API is its own MAVLink endpoint (the one after the HMI's): the
//! vehicle's messages for it come through an [`Outlet`](crate::hmi::Outlet)
//! like the HMI's, are serialised once (`fan_out`) and shared by every
//! client and the REST view; Cockpit's message rates are its own and do not
//! change the browser page's. Each WebSocket client is a ground station
//! (`station`); a POST is one frame from a station of the REST peer.
//!
//! Who may use it is decided in front ([`guard`]): the
//! Host rule everywhere, the Origin rule on the WebSocket and on POST; only a
//! client that may pilot by the browser page's rule (the pilot password, or
//! an address `[hmi] open_control` admits) may control.
//! It must never bypass the core: frames go in as `Input::Mavlink` only.

pub mod frame;
mod mailbox;
mod station;
mod stream;
pub mod tree;

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use axum::Router;
use axum::body::Bytes;
use axum::extract::{Path, Query, Request, State, WebSocketUpgrade};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use mavlink_core::Message as _;
use tokio::sync::{broadcast, watch};

use super::{Deliveries, Shared, auth, guard};
use crate::dialect::neptunus::MavMessage;
use crate::vehicle::machine::{COMPONENT_ID, Input, Sender};
use frame::{Header, NOT_CONVERTED};
use tree::Tree;

/// Where mavlink2rest's routes are served.
const PREFIXES: [&str; 4] = ["", "/v1", "/mavlink2rest", "/mavlink2rest/v1"];
/// WebSocket clients at once.
pub const MAX_CLIENTS: usize = 16;
/// Vehicle messages a client's reader may fall behind by before it skips.
const OUT_CAPACITY: usize = 1024;
/// Largest client frame or POST body.
const MAX_FRAME_BYTES: usize = 16 * 1024;

/// What one read of a client's socket takes at most.
const READ_BUFFER_BYTES: usize = 4096;

pub(crate) fn is_api_path(path: &str) -> bool {
    PREFIXES.iter().any(|p| {
        path.strip_prefix(p).is_some_and(|rest| {
            rest == "/mavlink"
                || rest.starts_with("/mavlink/")
                || rest == "/ws/mavlink"
                || rest == "/helper/mavlink"
                || rest == "/info"
        })
    })
}

/// One vehicle message, serialised once for every client.
pub(crate) struct Out {
    /// `Some`: for one client only (an answer to it).
    pub peer: Option<u64>,
    /// What a newer message replaces in a slow client's mailbox.
    pub stream: stream::StreamKey,
    pub json: Arc<str>,
}

/// The API's shared state: the REST view, the clients' feed, who is connected.
pub(crate) struct Hub {
    pub endpoint: usize,
    /// The endpoint's outlet: who listens (WebSocket clients for their
    /// lifetime, REST reads for a while after each).
    outlet: super::Outlet,
    /// Counts the vehicle's passes the REST view has taken in, so a read
    /// that woke the endpoint can wait for the view to follow.
    passes: watch::Sender<u64>,
    /// Sender ids no client may claim.
    pub reserved: frame::Reserved,
    tree: Mutex<Tree>,
    out: broadcast::Sender<Arc<Out>>,
    /// The peer id of frames POSTed over REST.
    post_peer: u64,
    /// Live clients per header system id that may control.
    stations: Mutex<HashMap<u8, usize>>,
    clients: AtomicUsize,
    bad: AtomicU64,
    last_bad: Mutex<Option<Instant>>,
    last_void_link: Mutex<Option<Instant>>,
}

/// A client's place among [`MAX_CLIENTS`]; given back when dropped.
pub(crate) struct StationSlot(Arc<Hub>);

impl Drop for StationSlot {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::AcqRel);
    }
}

impl Hub {
    pub fn new(outlet: super::Outlet, post_peer: u64, reserved: frame::Reserved) -> Self {
        Self {
            endpoint: outlet.endpoint(),
            outlet,
            passes: watch::Sender::new(0),
            reserved,
            tree: Mutex::new(Tree::default()),
            out: broadcast::channel(OUT_CAPACITY).0,
            post_peer,
            stations: Mutex::new(HashMap::new()),
            clients: AtomicUsize::new(0),
            bad: AtomicU64::new(0),
            last_bad: Mutex::new(None),
            last_void_link: Mutex::new(None),
        }
    }

    /// A client's feed; it counts as a listener while the [`Listening`](super::outlet::Listening) lives.
    fn subscribe(&self) -> (broadcast::Receiver<Arc<Out>>, super::outlet::Listening) {
        (self.out.subscribe(), self.outlet.listen())
    }

    /// Before a REST read of the view for `wanted` (system, component,
    /// message): see [`Outlet::read`](super::Outlet::read). A read that
    /// woke the endpoint answers once `wanted` was heard again (the
    /// vehicle's first pass for a new listener sends everything overdue),
    /// or after the outlet's wait.
    async fn read(&self, wanted: (u8, u8, &str)) {
        let heard = || {
            self.tree
                .lock()
                .ok()
                .and_then(|t| t.counter(wanted.0, wanted.1, wanted.2))
        };
        let before = heard();
        self.outlet
            .read(&mut self.passes.subscribe(), || heard() != before)
            .await;
    }

    fn take_slot(self: &Arc<Self>) -> Option<StationSlot> {
        self.clients
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < MAX_CLIENTS).then_some(n + 1)
            })
            .ok()
            .map(|_| StationSlot(Arc::clone(self)))
    }

    fn record(
        &self,
        system: u8,
        component: u8,
        name: &'static str,
        json: Arc<str>,
        now: SystemTime,
    ) {
        if let Ok(mut t) = self.tree.lock() {
            t.update(system, component, name, json, now);
        }
    }

    fn station_joined(&self, sysid: u8) {
        if let Ok(mut s) = self.stations.lock() {
            *s.entry(sysid).or_default() += 1;
        }
    }

    /// True when no other client carries `sysid` any more.
    fn station_left(&self, sysid: u8) -> bool {
        let Ok(mut s) = self.stations.lock() else {
            return false;
        };
        let n = s.entry(sysid).or_default();
        *n = n.saturating_sub(1);
        if *n == 0 {
            s.remove(&sysid);
            true
        } else {
            false
        }
    }

    /// A Cockpit link that logs in nobody; logs at most every 5 s.
    fn note_void_link(&self, ip: Option<std::net::IpAddr>) {
        let Ok(mut last) = self.last_void_link.lock() else {
            return;
        };
        if last.is_none_or(|t| t.elapsed() >= Duration::from_secs(5)) {
            *last = Some(Instant::now());
            tracing::warn!(
                "mavlink2rest: a Cockpit link from {ip:?} is void (not used within {} s, logged out, used from another address, or made before a restart): the client only watches — open Cockpit again from the vehicle's page",
                auth::LINK_FIRST_USE.as_secs()
            );
        }
    }

    /// Counts a frame that did not convert; logs at most every 5 s.
    fn note_bad(&self, client: u64, why: &str) {
        let n = self.bad.fetch_add(1, Ordering::Relaxed) + 1;
        let Ok(mut last) = self.last_bad.lock() else {
            return;
        };
        if last.is_none_or(|t| t.elapsed() >= Duration::from_secs(5)) {
            *last = Some(Instant::now());
            tracing::warn!("mavlink2rest client {client}: frame dropped ({n} in all): {why}");
        }
    }
}

/// Serialises each vehicle message for the API once, keeps the REST view
/// and feeds the clients; runs while the server runs.
pub(crate) async fn fan_out(
    mut rx: broadcast::Receiver<Deliveries>,
    hub: Arc<Hub>,
    vehicle_sysid: u8,
) {
    let mut seq: u8 = 0;
    let mut next = rx.recv().await;
    loop {
        let batch = match next {
            Ok(b) => b,
            Err(broadcast::error::RecvError::Lagged(n)) => {
                tracing::debug!("mavlink2rest fell behind the vehicle by {n} passes");
                next = rx.recv().await;
                continue;
            }
            Err(broadcast::error::RecvError::Closed) => return,
        };
        for d in batch.iter() {
            let name = d.msg.message_name();
            let msg_json = match frame::message_json(&d.msg) {
                Ok(j) => j,
                Err(e) => {
                    tracing::debug!("mavlink2rest: {name} not serialisable: {e}");
                    continue;
                }
            };
            let header = Header {
                system_id: vehicle_sysid,
                component_id: d.compid,
                sequence: seq,
            };
            seq = seq.wrapping_add(1);
            let json: Arc<str> = Arc::from(frame::frame_json(header, &msg_json));
            // What the vehicle said to everyone; an answer to one client stays its own.
            if d.peer.is_none() {
                hub.record(
                    vehicle_sysid,
                    d.compid,
                    name,
                    Arc::from(msg_json),
                    SystemTime::now(),
                );
            }
            if hub.out.receiver_count() > 0 {
                let _ = hub.out.send(Arc::new(Out {
                    peer: d.peer,
                    stream: stream::StreamKey::of(vehicle_sysid, d.compid, &d.msg),
                    json,
                }));
            }
        }
        hub.passes.send_modify(|n| *n = n.wrapping_add(1));
        // Everything already queued first. Then, with no client connected,
        // only the REST view follows the vehicle: five times a second is
        // enough, and this task wakes five times a second rather than at
        // every pass of the vehicle's loop.
        next = match super::queued(&mut rx) {
            Some(n) => n,
            None => {
                if hub.out.receiver_count() == 0 {
                    tokio::time::sleep(IDLE_PERIOD).await;
                }
                rx.recv().await
            }
        };
    }
}

/// How often the REST view follows the vehicle while no WebSocket client is connected.
const IDLE_PERIOD: std::time::Duration = std::time::Duration::from_millis(200);

pub(crate) fn routes(shared: Arc<Shared>) -> Router {
    let mut r = Router::new();
    for p in PREFIXES {
        r = r
            .route(&format!("{p}/mavlink"), get(view_all).post(post))
            .route(&format!("{p}/mavlink/{{*path}}"), get(view_path))
            .route(&format!("{p}/ws/mavlink"), get(ws))
            .route(&format!("{p}/helper/mavlink"), get(helper))
            .route(&format!("{p}/info"), get(info));
    }
    super::cors::layer(r, Arc::clone(&shared), is_api_path, None).with_state(shared)
}

fn json_response(status: StatusCode, body: String) -> Response {
    (status, [(header::CONTENT_TYPE, "application/json")], body).into_response()
}

/// What a read of `path` in the view is for: the message it names, or
/// (for the view as a whole or a vehicle's part) the vehicle's heartbeat.
pub(crate) fn wanted(path: &str, vehicle_sysid: u8) -> (u8, u8, &str) {
    let seg: Vec<&str> = path.trim_matches('/').split('/').take(6).collect();
    let named = match seg[..] {
        ["vehicles", sys, "components", comp, "messages", name] => sys
            .parse()
            .ok()
            .zip(comp.parse().ok())
            .map(|(s, c)| (s, c, name)),
        _ => None,
    };
    named.unwrap_or((vehicle_sysid, COMPONENT_ID, "HEARTBEAT"))
}

async fn view_all(State(shared): State<Arc<Shared>>) -> Response {
    shared.m2r.read(wanted("", shared.vehicle_sysid)).await;
    let v = shared
        .m2r
        .tree
        .lock()
        .map(|t| t.to_value())
        .unwrap_or_default();
    json_response(StatusCode::OK, v.to_string())
}

/// A JSON pointer into the view: `vehicles/1/components/1/messages/ATTITUDE[/message/roll]`.
async fn view_path(State(shared): State<Arc<Shared>>, Path(path): Path<String>) -> Response {
    shared.m2r.read(wanted(&path, shared.vehicle_sysid)).await;
    let v = shared
        .m2r
        .tree
        .lock()
        .map(|t| t.to_value())
        .unwrap_or_default();
    match v.pointer(&format!("/{}", path.trim_end_matches('/'))) {
        Some(found) => json_response(StatusCode::OK, found.to_string()),
        None => (
            StatusCode::NOT_FOUND,
            format!("nothing at /{path} yet: see GET /v1/mavlink for what was heard\n"),
        )
            .into_response(),
    }
}

#[derive(serde::Deserialize)]
struct WsQuery {
    filter: Option<String>,
    password: Option<String>,
    /// A Cockpit link from the logged-in page (`/api/cockpit-link`).
    token: Option<String>,
}

/// The upgrade (Host and Origin were checked in front).
async fn ws(
    State(shared): State<Arc<Shared>>,
    Query(q): Query<WsQuery>,
    upgrade: WebSocketUpgrade,
    req: Request,
) -> Response {
    let ip = guard::client_ip(req.extensions());
    let filter = match q.filter.as_deref() {
        None => None,
        Some(f) => match regex::RegexBuilder::new(f).size_limit(1 << 20).build() {
            Ok(re) => Some(re),
            Err(e) => {
                return (
                    StatusCode::BAD_REQUEST,
                    format!("filter {f:?} is not a regular expression: {e}\n"),
                )
                    .into_response();
            }
        },
    };
    let mut logged_in = guard::logged_in(&shared, req.headers());
    if let Some(p) = q.password.as_deref() {
        let outcome = guard::check_password(&shared, ip, p, "mavlink2rest ?password=").await;
        if outcome != guard::Login::Ok {
            return (StatusCode::UNAUTHORIZED, format!("{}\n", outcome.message())).into_response();
        }
        logged_in = true;
    }
    if let Some(t) = q.token.as_deref() {
        // A link that is void (expired, logged out, a restart, another
        // address) still watches: a pilot who sees keeps seeing.
        let key = auth::throttle_key(ip.unwrap_or(std::net::IpAddr::from([0, 0, 0, 0])));
        let used = shared
            .tokens
            .lock()
            .is_ok_and(|mut tokens| tokens.use_link(t, key, Instant::now()));
        if used {
            logged_in = true;
        } else {
            shared.m2r.note_void_link(ip);
        }
    }
    let Some(slot) = shared.m2r.take_slot() else {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            format!("{MAX_CLIENTS} mavlink2rest clients are already connected: close one\n"),
        )
            .into_response();
    };
    let hub = Arc::clone(&shared.m2r);
    let start = station::Start {
        ip,
        logged_in,
        filter,
        slot,
    };
    // The read buffer is zero-filled before every read of the socket (128
    // KiB by default); the frames a client sends are small, a longer one
    // grows it.
    upgrade
        .max_message_size(MAX_FRAME_BYTES)
        .max_frame_size(MAX_FRAME_BYTES)
        .read_buffer_size(READ_BUFFER_BYTES)
        .on_upgrade(move |socket| station::run(socket, shared, hub, start))
}

/// `POST mavlink`: one frame, from the REST peer, under the same rules as a
/// WebSocket client (the password by the login cookie only).
async fn post(State(shared): State<Arc<Shared>>, req: Request) -> Response {
    let ip = guard::client_ip(req.extensions());
    let logged_in = guard::logged_in(&shared, req.headers());
    if !guard::may_pilot(&shared, ip, logged_in) {
        return (
            StatusCode::UNAUTHORIZED,
            format!("{}\n", guard::watch_only_reason(&shared)),
        )
            .into_response();
    }
    let Ok(body): Result<Bytes, _> = axum::body::to_bytes(req.into_body(), MAX_FRAME_BYTES).await
    else {
        return (StatusCode::PAYLOAD_TOO_LARGE, NOT_CONVERTED).into_response();
    };
    let text = String::from_utf8_lossy(&body);
    let f = match frame::parse(&text, shared.m2r.reserved) {
        Ok(f) => f,
        Err(e) => {
            shared.m2r.note_bad(shared.m2r.post_peer, &e.to_string());
            return (StatusCode::NOT_FOUND, NOT_CONVERTED).into_response();
        }
    };
    // A pilot (who may claim control whatever its id, and counts as signed)
    // only when it gave the password, as a WebSocket client.
    let pilot = shared.password.is_some() && logged_in;
    let from = Sender {
        signed: pilot,
        trusted: false,
        pilot,
        ..Sender::new(
            shared.m2r.endpoint,
            shared.m2r.post_peer,
            f.header.system_id,
            f.header.component_id,
        )
    };
    if let Ok(json) = frame::message_json(&f.message) {
        shared.m2r.record(
            f.header.system_id,
            f.header.component_id,
            f.message.message_name(),
            Arc::from(json),
            SystemTime::now(),
        );
    }
    match shared
        .inputs
        .send(Input::Mavlink {
            from,
            msg: f.message,
        })
        .await
    {
        Ok(()) => json_response(StatusCode::OK, "\"Ok.\"".into()),
        Err(_) => (
            StatusCode::SERVICE_UNAVAILABLE,
            "the vehicle task is not running\n",
        )
            .into_response(),
    }
}

#[derive(serde::Deserialize)]
struct HelperQuery {
    name: String,
}

/// A zeroed example of any message of our dialect, in a frame with the
/// default ground-station header.
async fn helper(Query(q): Query<HelperQuery>) -> Response {
    let msg =
        MavMessage::message_id_from_name(&q.name).and_then(MavMessage::default_message_from_id);
    let Some(msg) = msg else {
        return json_response(
            StatusCode::NOT_FOUND,
            serde_json::to_string(&format!("no message {} in the neptunus dialect", q.name))
                .unwrap_or_default(),
        );
    };
    let header = Header {
        system_id: 255,
        component_id: 0,
        sequence: 0,
    };
    let body = serde_json::json!({ "header": header, "message": msg });
    json_response(
        StatusCode::OK,
        serde_json::to_string_pretty(&body).unwrap_or_default(),
    )
}

async fn info() -> Response {
    let body = serde_json::json!({
        "version": 0,
        "service": {
            "name": "neptunus",
            "version": env!("CARGO_PKG_VERSION"),
            "sha": "",
            "build_date": "",
            "authors": "",
        },
    });
    json_response(StatusCode::OK, body.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dialect::neptunus::{HEARTBEAT_DATA, STATUSTEXT_DATA};
    use crate::hmi::Outlet;
    use crate::vehicle::machine::To;

    /// A REST read that wakes a quiet endpoint answers from the vehicle's
    /// first pass for it, not from a pass made before the vehicle knew of
    /// the reader (which carries only what goes to everyone: a STATUSTEXT).
    #[tokio::test(start_paused = true)]
    async fn a_waking_read_waits_for_the_message_it_asks_for() {
        let outlet = Outlet::every_component(1);
        let hub = Arc::new(Hub::new(outlet.clone(), 0, frame::Reserved::vehicle(1)));
        tokio::spawn(fan_out(outlet.subscribe(), Arc::clone(&hub), 1));
        let mut passes = hub.passes.subscribe();
        let mut heard = outlet.listeners();
        let read = tokio::spawn({
            let hub = Arc::clone(&hub);
            async move {
                hub.read(wanted("vehicles/1/components/1/messages/HEARTBEAT", 1))
                    .await;
                let t = hub.tree.lock().expect("the view's lock");
                t.counter(1, COMPONENT_ID, "HEARTBEAT")
            }
        });
        heard.wait_for(|n| *n > 0).await.expect("the read listens");
        let pass = |msg: MavMessage| {
            let mut batch: Vec<_> = outlet
                .delivery(To::All, COMPONENT_ID, &msg, None)
                .into_iter()
                .collect();
            outlet.deliver_all(&mut batch);
        };
        pass(MavMessage::STATUSTEXT(STATUSTEXT_DATA::default()));
        passes
            .wait_for(|n| *n == 1)
            .await
            .expect("the view took in the pass");
        tokio::task::yield_now().await;
        assert!(!read.is_finished(), "answered from a pass without it");
        pass(MavMessage::HEARTBEAT(HEARTBEAT_DATA::default()));
        assert_eq!(read.await.expect("the read ran"), Some(1));
    }

    #[test]
    fn what_a_read_is_for() {
        assert_eq!(
            wanted(
                "vehicles/7/components/100/messages/CAMERA_INFORMATION/message",
                1
            ),
            (7, 100, "CAMERA_INFORMATION")
        );
        assert_eq!(wanted("", 1), (1, COMPONENT_ID, "HEARTBEAT"));
        assert_eq!(wanted("vehicles/1", 1), (1, COMPONENT_ID, "HEARTBEAT"));
        assert_eq!(
            wanted("vehicles/x/components/1/messages/ATTITUDE", 1),
            (1, COMPONENT_ID, "HEARTBEAT")
        );
    }
}
