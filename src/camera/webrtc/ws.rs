//! The signalling WebSocket: each connection runs one [`Signalling`] and
//! carries out its actions — texts to the client, commands to the hub —
//! and the hub's events back. Also `GET /api/webrtc`, what a page needs
//! to start (the path, the dedicated port, the ICE servers, the stream).
//!
//! Who may connect is decided in front of these routes (the HMI's Host and
//! Origin rules, the same for the HMI's port and the dedicated one); the
//! video is for every client they admit, like `/video.mjpg`.

use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::Json;
use axum::Router;
use axum::extract::ws::{Message as WsMessage, Utf8Bytes, WebSocket};
use axum::extract::{State, WebSocketUpgrade};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use futures_util::{SinkExt as _, StreamExt as _};
use tokio::sync::mpsc;

use super::config::IceServer;
use super::hub::Command;
use super::protocol::{Message, Stream};
use super::signalling::{Action, Signalling};

/// The signalling path on the HMI's port.
pub const PATH: &str = "/webrtc";
/// Signalling connections at once (each may hold a few sessions).
const MAX_CONNECTIONS: usize = 32;
/// Largest text a client may send: an SDP answer is a few kB.
const MAX_MESSAGE_BYTES: usize = 64 * 1024;

/// What one read of a viewer's socket takes at most.
const READ_BUFFER_BYTES: usize = 4096;

/// What every connection shares.
pub(super) struct Ctx {
    pub commands: mpsc::Sender<Command>,
    pub stream: Option<Stream>,
    pub ice_servers: Vec<IceServer>,
    /// Where the dedicated signalling port listens, once it does.
    pub signalling: Mutex<Option<SocketAddr>>,
    /// Where `/streams` listens, once it does.
    pub streams: Mutex<Option<SocketAddr>>,
    connections: AtomicUsize,
    refused: AtomicU64,
    last_log: Mutex<Option<Instant>>,
}

impl Ctx {
    pub(super) fn new(
        commands: mpsc::Sender<Command>,
        stream: Option<Stream>,
        ice_servers: Vec<IceServer>,
    ) -> Self {
        Ctx {
            commands,
            stream,
            ice_servers,
            signalling: Mutex::new(None),
            streams: Mutex::new(None),
            connections: AtomicUsize::new(0),
            refused: AtomicU64::new(0),
            last_log: Mutex::new(None),
        }
    }

    /// Counts a refused message; logs at most every 5 s.
    fn note_refused(&self, client: &str, why: &str) {
        let n = self.refused.fetch_add(1, Ordering::Relaxed) + 1;
        let Ok(mut last) = self.last_log.lock() else {
            return;
        };
        if last.is_none_or(|t| t.elapsed() >= Duration::from_secs(5)) {
            *last = Some(Instant::now());
            tracing::warn!(
                "WebRTC signalling: a message from {client} refused ({n} in all): {why}"
            );
        }
    }
}

/// `GET /webrtc` (the WebSocket) and `GET /api/webrtc` on the HMI's port.
pub(super) fn routes(ctx: Arc<Ctx>) -> Router {
    Router::new()
        .route(PATH, get(upgrade))
        .route("/api/webrtc", get(info))
        .with_state(ctx)
}

/// The WebSocket at `/`, where mavlink-camera-manager serves it.
pub(super) fn signalling_routes(ctx: Arc<Ctx>) -> Router {
    Router::new().route("/", get(upgrade)).with_state(ctx)
}

async fn info(State(ctx): State<Arc<Ctx>>) -> Json<serde_json::Value> {
    let port = ctx.signalling.lock().ok().and_then(|a| a.map(|a| a.port()));
    let streams_port = ctx.streams.lock().ok().and_then(|a| a.map(|a| a.port()));
    let ice: Vec<serde_json::Value> = ctx
        .ice_servers
        .iter()
        .map(|s| {
            let mut v = serde_json::json!({ "urls": s.url });
            if let Some(u) = &s.username {
                v["username"] = u.clone().into();
            }
            if let Some(c) = &s.credential {
                v["credential"] = c.clone().into();
            }
            v
        })
        .collect();
    Json(serde_json::json!({
        "path": PATH,
        "signalling_port": port,
        "streams_port": streams_port,
        "ice_servers": ice,
        "streams": ctx.stream.iter().collect::<Vec<_>>(),
    }))
}

/// A connection's place among [`MAX_CONNECTIONS`].
struct Slot(Arc<Ctx>);

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.connections.fetch_sub(1, Ordering::AcqRel);
    }
}

async fn upgrade(
    State(ctx): State<Arc<Ctx>>,
    axum::extract::ConnectInfo(client): axum::extract::ConnectInfo<SocketAddr>,
    conn: Option<axum::Extension<crate::hmi::server::ConnInfo>>,
    ws: WebSocketUpgrade,
) -> Response {
    // The vehicle's address this viewer reached: the one it is offered.
    let reached = conn.and_then(|c| c.local).map(|a| a.ip());
    let taken = ctx
        .connections
        .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
            (n < MAX_CONNECTIONS).then_some(n + 1)
        });
    if taken.is_err() {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "{MAX_CONNECTIONS} WebRTC signalling connections are open already: close one\n"
            ),
        )
            .into_response();
    }
    let slot = Slot(Arc::clone(&ctx));
    // The read buffer is zero-filled before every read of the socket (128
    // KiB by default); offers and candidates are small, a longer message
    // grows it.
    ws.max_message_size(MAX_MESSAGE_BYTES)
        .max_frame_size(MAX_MESSAGE_BYTES)
        .read_buffer_size(READ_BUFFER_BYTES)
        .on_upgrade(move |socket| run(socket, ctx, client, reached, slot))
}

/// A random (version 4) UUID, the shape of mavlink-camera-manager's ids.
pub(super) fn uuid() -> String {
    let mut b: [u8; 16] = rand::random();
    b[6] = (b[6] & 0x0f) | 0x40;
    b[8] = (b[8] & 0x3f) | 0x80;
    let h: String = b.iter().map(|x| format!("{x:02x}")).collect();
    format!(
        "{}-{}-{}-{}-{}",
        &h[0..8],
        &h[8..12],
        &h[12..16],
        &h[16..20],
        &h[20..32]
    )
}

async fn run(
    socket: WebSocket,
    ctx: Arc<Ctx>,
    client: SocketAddr,
    reached: Option<IpAddr>,
    slot: Slot,
) {
    let mut sig = Signalling::new(ctx.stream.clone(), Box::new(uuid));
    let who = client.to_string();
    tracing::info!(client = %who, consumer = sig.consumer_id(), "WebRTC signalling connected");
    // A viewer is coming: its stream starts while it asks for a session.
    let _ = ctx.commands.send(Command::Coming).await;
    let (mut tx, mut rx) = socket.split();
    // Unbounded: a session makes a handful of events (an offer, its
    // candidates, its end), and the hub must never wait on one client.
    let (events_tx, mut events) = mpsc::unbounded_channel();
    loop {
        let actions = tokio::select! {
            m = rx.next() => match m {
                None | Some(Err(_)) | Some(Ok(WsMessage::Close(_))) => break,
                Some(Ok(WsMessage::Text(text))) => {
                    let (actions, refusal) = sig.on_text(text.as_str());
                    if let Some(r) = refusal {
                        ctx.note_refused(&who, &r.to_string());
                    }
                    actions
                }
                Some(Ok(WsMessage::Binary(_))) => {
                    ctx.note_refused(&who, "a binary message");
                    vec![Action::Send(
                        Message::Error("signalling messages are JSON text".into()).to_json(),
                    )]
                }
                Some(Ok(_)) => continue,
            },
            Some(ev) = events.recv() => sig.on_peer(ev),
        };
        if !carry_out(actions, &ctx, &mut tx, &events_tx, reached).await {
            break;
        }
    }
    for session_id in sig.session_ids() {
        let _ = ctx.commands.send(Command::End { session_id }).await;
    }
    tracing::info!(
        client = %who,
        consumer = sig.consumer_id(),
        refused = sig.refused(),
        "WebRTC signalling closed"
    );
    drop(slot);
}

/// False when the client is gone.
async fn carry_out(
    actions: Vec<Action>,
    ctx: &Ctx,
    tx: &mut futures_util::stream::SplitSink<WebSocket, WsMessage>,
    events: &mpsc::UnboundedSender<super::signalling::PeerEvent>,
    reached: Option<IpAddr>,
) -> bool {
    for a in actions {
        let command = match a {
            Action::Send(text) => {
                if tx
                    .send(WsMessage::Text(Utf8Bytes::from(text)))
                    .await
                    .is_err()
                {
                    return false;
                }
                continue;
            }
            Action::Start(bind) => Command::Start {
                bind,
                events: events.clone(),
                reached,
            },
            Action::Answer { session_id, sdp } => Command::Answer { session_id, sdp },
            Action::Candidate {
                session_id,
                candidate,
            } => Command::Candidate {
                session_id,
                candidate,
            },
            Action::End { session_id } => Command::End { session_id },
        };
        if ctx.commands.send(command).await.is_err() {
            let gone = Message::Error("WebRTC is not running on the vehicle".into()).to_json();
            let _ = tx.send(WsMessage::Text(Utf8Bytes::from(gone))).await;
            return false;
        }
    }
    true
}
