//! One browser session: a MAVLink ground station inside the process.
//!
//! Owns the session's system id (leased from the pool only when it may
//! pilot and needs one: at login, or at its first command when
//! `[hmi] open_control` admits it), its pilot rights, its view of the
//! vehicle ([`Model`]) and the conversion of the browser's JSON into
//! MAVLink. A watcher holds no id and sends the vehicle nothing.
//!
//! It must never invent pilot input: stick messages go out only as the
//! browser sends them; the session itself only sends
//! neutral ones (stop, focus lost, input-mode change) and its heartbeat —
//! and the heartbeat only while the browser itself shows life, so a frozen
//! tab does not keep its owner alive.
//!
//! This file runs the session (the select loop and its timers); `rights`
//! holds what the session may do, `browser` what the browser sends and
//! `vehicle` what goes to the vehicle.

mod browser;
mod rights;
mod vehicle;

pub(crate) use rights::WatcherSlot;
pub(crate) use vehicle::request_rates;

use std::net::IpAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::ws::{Message, Utf8Bytes, WebSocket};
use futures_util::{SinkExt as _, StreamExt as _};
use tokio::sync::broadcast::error::RecvError;

use super::model::Model;
use super::protocol::ServerMsg;
use super::{Shared, SysidLease};
use crate::vehicle::machine::{HmiEvent, Input};

/// With nothing new from the vehicle, the telemetry is sent again this
/// often anyway (so the ages it carries keep counting).
const REFRESH_PERIOD: Duration = Duration::from_millis(500);
/// HEARTBEAT period.
const HEARTBEAT_PERIOD: Duration = Duration::from_secs(1);
/// The browser must have shown life this recently for a HEARTBEAT to go out.
const BROWSER_LIFE: Duration = Duration::from_millis(1500);
/// A browser that takes longer than this to accept a message is dropped.
const SEND_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a control request waits for the owner's answer.
const REQUEST_TIMEOUT_S: f32 = 10.0;
/// A session that sent nothing (not even a pong) for this long is closed
/// (the page says `alive` every 0.5 s).
const IDLE_TIMEOUT: Duration = Duration::from_secs(30);
/// The server pings this often, so a live browser whose tab is throttled
/// still answers (with a pong) within [`IDLE_TIMEOUT`].
const PING_PERIOD: Duration = Duration::from_secs(10);
/// A watcher's refused stick and thruster input is answered at most this often.
const REFUSAL_REPLY: Duration = Duration::from_secs(2);

/// Why a session ends.
enum End {
    Closed,
    SendFailed,
    Idle,
}

/// What the upgrade found out about the client before the session starts.
pub(crate) struct Start {
    pub ip: Option<IpAddr>,
    /// The request carried a live login cookie.
    pub logged_in: bool,
    /// A logged-in session's id, leased at the upgrade.
    pub lease: Option<SysidLease>,
    /// Otherwise its place among the watchers.
    pub watcher: Option<WatcherSlot>,
}

struct Session {
    shared: Arc<Shared>,
    id: u64,
    ip: Option<IpAddr>,
    lease: Option<SysidLease>,
    watcher: Option<WatcherSlot>,
    /// Logged in with the pilot password (cookie or `login`): a pilot, and
    /// `signed` for the core's signing rule.
    logged_in: bool,
    model: Model,
    /// The browser's JavaScript last said something (HEARTBEAT gate).
    last_life: Instant,
    /// Anything at all last arrived, pongs included (idle timeout).
    last_seen: Instant,
    last_refusal: Option<Instant>,
    bad: u64,
}

/// Runs one WebSocket session to its end, then tells the vehicle it disconnected.
pub(crate) async fn run(socket: WebSocket, shared: Arc<Shared>, start: Start) {
    let id = shared
        .next_session
        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let now = Instant::now();
    let mut s = Session {
        shared: Arc::clone(&shared),
        id,
        ip: start.ip,
        lease: start.lease,
        watcher: start.watcher,
        logged_in: start.logged_in,
        model: Model::new(None, now),
        last_life: now,
        last_seen: now,
        last_refusal: None,
        bad: 0,
    };
    if s.logged_in && s.lease.is_none() {
        s.ensure_sysid();
    }
    s.model.set_me(s.sysid());
    tracing::info!(session = id, sysid = ?s.sysid(), client = ?s.ip, pilot = s.may_pilot(), logged_in = s.logged_in, "HMI session connected");
    let (mut tx, mut rx) = socket.split();
    let mut hub = shared.outlet.subscribe();
    // The endpoint's telemetry is built while a session (even a watcher's) is open.
    let _listening = shared.outlet.listen();
    let welcome = s.welcome();
    let end = 'session: {
        if send(&mut tx, &welcome).await.is_err() {
            break 'session End::SendFailed;
        }
        // As QGroundControl does: whether the camera records, and whether
        // it records now (the page's record button).
        s.ask_camera().await;
        let mut ping = tokio::time::interval(PING_PERIOD);
        ping.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut pushed_at = tokio::time::Instant::now();
        let mut beat = tokio::time::interval(HEARTBEAT_PERIOD);
        beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut events = Vec::new();
        loop {
            tokio::select! {
                m = rx.next() => {
                    s.last_seen = Instant::now();
                    let rights_before = (s.sysid(), s.logged_in);
                    let reply = match m {
                        None | Some(Err(_)) | Some(Ok(Message::Close(_))) => break 'session End::Closed,
                        Some(Ok(Message::Text(text))) => s.on_text(text.as_str()).await,
                        Some(Ok(Message::Binary(_))) => s.bad_message("binary messages are not part of the protocol — send JSON text"),
                        Some(Ok(Message::Ping(_))) => {
                            s.last_life = Instant::now();
                            None
                        }
                        // The browser engine answers our pings even when the
                        // page's script is frozen: seen, but no sign of life.
                        Some(Ok(Message::Pong(_))) => None,
                    };
                    if let Some(reply) = reply
                        && send(&mut tx, &reply).await.is_err()
                    {
                        break 'session End::SendFailed;
                    }
                    if (s.sysid(), s.logged_in) != rights_before
                        && send(&mut tx, &s.identity()).await.is_err()
                    {
                        break 'session End::SendFailed;
                    }
                }
                _ = ping.tick() => {
                    if s.last_seen.elapsed() > IDLE_TIMEOUT {
                        break 'session End::Idle;
                    }
                    if tx.send(Message::Ping(Default::default())).await.is_err() {
                        break 'session End::SendFailed;
                    }
                }
                d = hub.recv() => {
                    // Telemetry is pushed as the vehicle sends it: this
                    // message and all queued behind it (what arrived while
                    // the last push was being written) go into the model,
                    // which keeps the newest of each kind, and out as one
                    // telemetry message. A slow browser gets fewer, newer
                    // pictures; it never builds a queue or holds anyone up.
                    let mut changed = false;
                    let mut next = d;
                    loop {
                        match next {
                            Ok(batch) => {
                                for d in batch.iter().filter(|d| d.peer.is_none_or(|p| p == s.id)) {
                                    s.model.on_delivery(d, Instant::now(), &mut events);
                                    changed = true;
                                }
                            }
                            Err(RecvError::Lagged(n)) => {
                                tracing::debug!(session = s.id, "HMI session fell behind by {n} vehicle messages");
                            }
                            Err(RecvError::Closed) => break 'session End::Closed,
                        }
                        next = match super::queued(&mut hub) {
                            Some(n) => n,
                            None => break,
                        };
                    }
                    for ev in events.drain(..) {
                        if send(&mut tx, &ev).await.is_err() {
                            break 'session End::SendFailed;
                        }
                    }
                    if changed {
                        pushed_at = tokio::time::Instant::now();
                        let t = s.model.snapshot(Instant::now());
                        if send(&mut tx, &ServerMsg::Telemetry(Box::new(t))).await.is_err() {
                            break 'session End::SendFailed;
                        }
                    }
                }
                () = tokio::time::sleep_until(pushed_at + REFRESH_PERIOD) => {
                    pushed_at = tokio::time::Instant::now();
                    let t = s.model.snapshot(Instant::now());
                    if send(&mut tx, &ServerMsg::Telemetry(Box::new(t))).await.is_err() {
                        break 'session End::SendFailed;
                    }
                }
                _ = beat.tick() => s.heartbeat().await,
            }
        }
    };
    match end {
        End::SendFailed => tracing::info!(
            session = id,
            "HMI session dropped: the browser stopped reading"
        ),
        End::Idle => tracing::info!(
            session = id,
            "HMI session closed: nothing from the browser for {} s",
            IDLE_TIMEOUT.as_secs()
        ),
        End::Closed => {}
    }
    // Whatever the browser did, the core hears that this station is gone.
    let sysid = s.sysid();
    if let Some(sysid) = sysid {
        let _ = shared
            .inputs
            .send(Input::Hmi {
                sysid,
                event: HmiEvent::Disconnected,
            })
            .await;
    }
    tracing::info!(session = id, sysid = ?sysid, bad_messages = s.bad, "HMI session closed");
    drop(s.lease.take());
    drop(s.watcher.take());
}

async fn send(
    tx: &mut futures_util::stream::SplitSink<WebSocket, Message>,
    msg: &ServerMsg,
) -> Result<(), ()> {
    let text = Message::Text(Utf8Bytes::from(msg.to_json()));
    match tokio::time::timeout(SEND_TIMEOUT, tx.send(text)).await {
        Ok(Ok(())) => Ok(()),
        _ => Err(()),
    }
}
