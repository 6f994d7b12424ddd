//! The browser HMI: an HTTP server (axum routes on our own hardened accept
//! loop, [`server`]) with the operator and developer interfaces (`web/`,
//! embedded), a JSON WebSocket at `/ws` and a small REST API, over plain
//! HTTP or TLS ([`tls`]), with security headers on every response
//! ([`headers`]).
//!
//! Each WebSocket session is a MAVLink ground station inside the process:
//! it gets its own system id from `[hmi] sysid_min..=sysid_max`, turns the
//! browser's JSON into `MavMessage`s and hands them to the vehicle task as
//! [`Input::Mavlink`] from its own [`Sender`] (endpoint = the HMI's endpoint
//! index, peer = the session id), exactly like a ground station on a socket.
//! The vehicle's [`Output::Send`](crate::vehicle::machine::Output) messages
//! for that endpoint come back through a broadcast hub ([`Outlet`]) as the
//! `MavMessage`s themselves, and each session keeps its own view of the
//! vehicle from them.
//!
//! This module must never touch vehicle state or bypass the core: it has no
//! handle on the vehicle, only the input channel every station's traffic
//! goes through, so the core's authority rules apply to the browser as to
//! any other station (the HMI is not a back door).
//!
//! Who may use it ([`auth`], [`guard`]): every request must name the vehicle
//! in its `Host` (no DNS rebinding); the WebSocket and every state-changing
//! request must come from the page's own origin or an allowed one (no
//! foreign web page); a session holds a system id — and so may pilot — only
//! once it logged in with the pilot password, or when `[hmi] open_control`
//! admits its address and MAVLink signing is off. A session is `signed`
//! (for the core's signing rule) only after a real password login.

pub mod assets;
pub mod auth;
mod beside;
pub mod blueos;
mod cors;
pub mod guard;
pub mod headers;
pub mod m2r;
pub mod model;
pub mod outlet;
pub mod protocol;
mod recordings;
pub mod rest;
pub mod server;
pub mod session;
mod start;
pub mod tls;

pub use beside::{Beside, BesideKind, VideoInfo, VideoRoutes};
pub(crate) use outlet::queued;
pub use outlet::{Deliveries, Delivery, Outlet};
pub use start::Hmi;

use std::collections::BTreeSet;
use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::net::TcpListener;
use tokio::sync::{mpsc, watch};

use crate::vehicle::machine::{Input, Sender};

/// MAVLink component id of every HMI session (MAV_COMP_ID_MISSIONPLANNER, a GCS).
pub const SESSION_COMPID: u8 = 190;
/// The peer id of the server's own requests (parameter list for `/api/params`).
pub const SERVER_PEER: u64 = 0;
/// Capacity of the hub, in passes of the vehicle's loop (each a batch of
/// messages): how far a slow session may fall behind, about 6 s at the
/// vehicle's 20-odd passes a second. The hub keeps the last batches until
/// they are overwritten, so this is memory too (a few hundred kB).
const HUB_CAPACITY: usize = 128;
/// `[hmi] max_watchers` default: a room of onlookers, not a crowd.
pub const DEFAULT_MAX_WATCHERS: usize = 32;

/// Errors starting the HMI.
#[derive(Debug, thiserror::Error)]
pub enum HmiError {
    #[error(
        "cannot listen for the browser HMI on {addr}: {source} — pass --http ADDR (e.g. 0.0.0.0:8081) or --http off"
    )]
    Bind {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error(
        "cannot listen for the browser HMI on {addr}: {source} — a port below 1024 needs the capability CAP_NET_BIND_SERVICE, \
         which the packaged service has (sudo systemctl start neptunus); run by hand, use --http 0.0.0.0:8080 \
         (Cockpit then needs the MAVLink URL: see the guide's Cockpit page)"
    )]
    Privileged {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("cannot write the HMI address file {path}: {source}")]
    AddrFile {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Password(#[from] auth::PasswordError),
    #[error(transparent)]
    Tls(#[from] tls::TlsError),
}

impl HmiError {
    /// The error for a port that cannot be bound, with the fix that fits.
    pub fn bind(addr: SocketAddr, source: std::io::Error) -> HmiError {
        if source.kind() == std::io::ErrorKind::PermissionDenied && addr.port() < 1024 {
            HmiError::Privileged { addr, source }
        } else {
            HmiError::Bind { addr, source }
        }
    }
}

/// HMI settings, resolved from `--http` and the `[hmi]` section.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HmiSettings {
    /// Where to listen; `None` = HMI off.
    pub http: Option<SocketAddr>,
    /// The address was asked for (flag or file): failing to bind it is an
    /// error. The default address only warns, so a second vehicle on the
    /// same machine still runs.
    pub http_explicit: bool,
    pub sysid_min: u8,
    pub sysid_max: u8,
    /// Client addresses that may pilot without the pilot password (the
    /// password itself is in `DATA_DIR/hmi-password`, never in the config).
    pub open_control: auth::OpenControl,
    /// Origins (`scheme://host[:port]`) besides the page's own whose pages
    /// may use the WebSocket and the REST API; their hosts are accepted in `Host`.
    pub allowed_origins: Vec<String>,
    /// Sessions that hold no system id (watch only) at once.
    pub max_watchers: usize,
    /// Rotation of the camera image in the page (0, 90, 180, 270).
    pub camera_rotation_deg: i32,
    /// Connection caps and the header-read timeout.
    pub limits: server::Limits,
    /// `[hmi] tls` and its files and names.
    pub tls: tls::TlsSettings,
}

impl Default for HmiSettings {
    fn default() -> Self {
        Self {
            http: Some(SocketAddr::from(([0, 0, 0, 0], 8080))),
            http_explicit: false,
            sysid_min: 200,
            sysid_max: 209,
            open_control: auth::OpenControl::default(),
            allowed_origins: Vec::new(),
            max_watchers: DEFAULT_MAX_WATCHERS,
            camera_rotation_deg: 0,
            limits: server::Limits::default(),
            tls: tls::TlsSettings::default(),
        }
    }
}

/// Everything the HMI server needs, passed in (tests run many side by side).
pub struct HmiContext {
    pub outlet: Outlet,
    /// The mavlink2rest API's endpoint ([`m2r`]): Cockpit's own rates.
    pub m2r_outlet: Outlet,
    /// Where sessions' traffic goes: the vehicle task's input.
    pub inputs: mpsc::Sender<Input>,
    pub vehicle_sysid: u8,
    pub sysid_min: u8,
    pub sysid_max: u8,
    /// For each sysid, whether its ground-station profile reads MANUAL_CONTROL
    /// z centred (±1000) rather than ArduSub's 0..1000.
    pub z_centered: Arc<dyn Fn(u8) -> bool + Send + Sync>,
    /// The pilot password (from `DATA_DIR/hmi-password`); `None`: none set.
    pub password: Option<auth::PilotPassword>,
    pub open_control: auth::OpenControl,
    pub allowed_origins: Vec<String>,
    pub max_watchers: usize,
    /// MAVLink signing is on: only a logged-in session may control
    /// (open_control does not apply: the browser cannot sign frames).
    pub signing: bool,
    pub camera_rotation_deg: i32,
    /// `tlogs/` and `events/` are listed by `/api/logs`.
    pub data_dir: PathBuf,
    /// Routes merged into the server: the camera's (`/video.mjpg`,
    /// `/snapshot.jpg`, `/camera/status`). With them the page shows video;
    /// without, a "no video" placeholder.
    pub extra_routes: Option<axum::Router>,
    /// Connection limits and TLS ([`server::Transport::default`]: the
    /// default limits, plain HTTP).
    pub transport: server::Transport,
    /// WebRTC runs: `/webrtc` and `/api/webrtc` are among `extra_routes`.
    pub webrtc: bool,
    /// Ports beside the HMI's with routes of their own (the camera
    /// manager's: the WebRTC signalling and `/streams`, where Cockpit looks
    /// for them), under the same guard.
    pub beside: Vec<Beside>,
    /// The video paths for `GET /api/video`.
    pub video_info: Option<VideoInfo>,
}

/// State shared by the server's handlers and sessions.
pub(crate) struct Shared {
    pub outlet: Outlet,
    pub inputs: mpsc::Sender<Input>,
    pub vehicle_sysid: u8,
    pub z_centered: Arc<dyn Fn(u8) -> bool + Send + Sync>,
    pub password: Option<auth::PilotPassword>,
    pub open_control: auth::OpenControl,
    pub signing: bool,
    pub gate: auth::Gate,
    pub throttle: Mutex<auth::Throttle>,
    pub tokens: Mutex<auth::Tokens>,
    /// Requests refused for a foreign Host or Origin.
    pub refused: Mutex<auth::Bursts>,
    /// WebSocket upgrades refused because `max_watchers` were watching.
    pub refused_watchers: Mutex<auth::Bursts>,
    /// One password check at a time: argon2 is slow on purpose.
    pub checks: tokio::sync::Semaphore,
    /// Sessions holding no system id now, and the cap.
    pub watchers: AtomicUsize,
    pub max_watchers: usize,
    pub camera_rotation_deg: i32,
    pub data_dir: PathBuf,
    /// Camera routes are merged: `/video.mjpg` exists.
    pub video: bool,
    /// WebRTC's routes are merged: `/api/webrtc` exists.
    pub webrtc: bool,
    pub video_info: Option<VideoInfo>,
    pub free_sysids: Mutex<BTreeSet<u8>>,
    pub sysid_range: (u8, u8),
    pub next_session: AtomicU64,
    pub bad_messages: AtomicU64,
    pub last_bad_report: Mutex<Option<Instant>>,
    /// The server's own view of the vehicle (`/api/status`, `/api/params`).
    pub status: watch::Receiver<rest::ServerView>,
    /// The mavlink2rest API's clients and REST view.
    pub m2r: Arc<m2r::Hub>,
    /// Cockpit's settings bag (`/bag/v1.0/`).
    pub bag: blueos::bag::BagService,
}

/// A system id lent to one session; back in the pool when dropped, whatever
/// way the session ends.
pub(crate) struct SysidLease {
    shared: Arc<Shared>,
    pub sysid: u8,
}

impl Drop for SysidLease {
    fn drop(&mut self) {
        if let Ok(mut free) = self.shared.free_sysids.lock() {
            free.insert(self.sysid);
        }
    }
}

impl Shared {
    pub fn lease_sysid(self: &Arc<Self>) -> Option<SysidLease> {
        let mut free = self.free_sysids.lock().ok()?;
        let sysid = free.pop_first()?;
        Some(SysidLease {
            shared: Arc::clone(self),
            sysid,
        })
    }

    /// Counts a bad web message; logs at most every 5 s.
    pub fn note_bad_message(&self, session: u64, why: &str) {
        let n = self.bad_messages.fetch_add(1, Ordering::Relaxed) + 1;
        let Ok(mut last) = self.last_bad_report.lock() else {
            return;
        };
        if last.is_none_or(|t| t.elapsed() >= Duration::from_secs(5)) {
            *last = Some(Instant::now());
            tracing::warn!("HMI session {session}: bad web message dropped ({n} in all): {why}");
        }
    }

    /// The sender identity of a session. `signed` only for a session that
    /// logged in with the pilot password: with MAVLink signing on, that is
    /// what stands in for the signature a browser cannot make.
    pub fn sender(&self, peer: u64, sysid: u8, pilot: bool, signed: bool) -> Sender {
        Sender {
            signed,
            trusted: false,
            pilot,
            ..Sender::new(self.outlet.endpoint(), peer, sysid, SESSION_COMPID)
        }
    }

    /// The server's own identity. Its peer only ever sends the telemetry
    /// rate requests at start and PARAM_REQUEST_LIST for `/api/params`,
    /// never control, so it may count as a signed pilot: the core refuses
    /// rate changes from stations that may not control.
    pub fn server_sender(&self) -> Sender {
        self.sender(SERVER_PEER, 0, true, true)
    }
}

/// For each sysid, whether its ground-station profile reads MANUAL_CONTROL z
/// centred (the sessions send what the core will read correctly, even when
/// `[hmi]` lends ids that the neptunus-web profile does not list).
pub fn z_centered_by(
    profiles: crate::vehicle::input::Profiles,
) -> Arc<dyn Fn(u8) -> bool + Send + Sync> {
    Arc::new(move |sysid| {
        profiles.for_sysid(sysid).z_convention == crate::vehicle::input::ZConvention::Centered
    })
}

/// Serves the HMI on `listener` until `shutdown` resolves.
pub async fn serve(
    listener: TcpListener,
    ctx: HmiContext,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let (lo, hi) = (
        ctx.sysid_min.min(ctx.sysid_max),
        ctx.sysid_max.max(ctx.sysid_min),
    );
    let (status_tx, status_rx) = watch::channel(rest::ServerView::default());
    let hostname = auth::machine_hostname();
    let bag = {
        let dir = ctx.data_dir.clone();
        tokio::task::spawn_blocking(move || {
            blueos::bag::BagService::load(&dir, blueos::bag::Limits::default())
        })
        .await
        .map_err(std::io::Error::other)?
    };
    // Peer ids: sessions and mavlink2rest clients count from 2; 1 is REST POSTs.
    let m2r_hub = Arc::new(m2r::Hub::new(
        ctx.m2r_outlet.clone(),
        1,
        m2r::frame::Reserved {
            vehicle_sysid: ctx.vehicle_sysid,
            hmi_sysids: (lo, hi),
        },
    ));
    let shared = Arc::new(Shared {
        outlet: ctx.outlet.clone(),
        inputs: ctx.inputs,
        vehicle_sysid: ctx.vehicle_sysid,
        z_centered: ctx.z_centered,
        password: ctx.password,
        open_control: ctx.open_control,
        signing: ctx.signing,
        gate: auth::Gate::new(&ctx.allowed_origins, hostname.as_deref()),
        throttle: Mutex::new(auth::Throttle::default()),
        tokens: Mutex::new(auth::Tokens::default()),
        refused: Mutex::new(auth::Bursts::default()),
        refused_watchers: Mutex::new(auth::Bursts::default()),
        checks: tokio::sync::Semaphore::new(1),
        watchers: AtomicUsize::new(0),
        max_watchers: ctx.max_watchers,
        camera_rotation_deg: ctx.camera_rotation_deg,
        data_dir: ctx.data_dir,
        video: ctx.extra_routes.is_some(),
        webrtc: ctx.webrtc,
        video_info: ctx.video_info,
        free_sysids: Mutex::new((lo..=hi).collect()),
        sysid_range: (lo, hi),
        next_session: AtomicU64::new(2),
        bad_messages: AtomicU64::new(0),
        last_bad_report: Mutex::new(None),
        status: status_rx,
        m2r: Arc::clone(&m2r_hub),
        bag,
    });
    let fan_out = tokio::spawn(m2r::fan_out(
        ctx.m2r_outlet.subscribe(),
        m2r_hub,
        ctx.vehicle_sysid,
    ));
    let watcher = tokio::spawn(rest::watch_vehicle(ctx.outlet.subscribe(), status_tx));
    // The HMI's telemetry rates, asked once for the endpoint: sessions no
    // longer ask (a watcher may not change rates).
    session::request_rates(&shared).await;
    let sweeper = tokio::spawn(guard::sweep(Arc::clone(&shared)));
    let mut app = rest::routes(Arc::clone(&shared))
        .merge(m2r::routes(Arc::clone(&shared)))
        .merge(blueos::routes(Arc::clone(&shared)));
    if let Some(extra) = ctx.extra_routes {
        app = app.merge(extra);
    }
    let app = guard::layer(app, Arc::clone(&shared));
    // Around everything merged, fallback included: every response has them.
    let app = app.layer(axum::middleware::from_fn(headers::security_headers));
    // One shutdown for both listeners.
    let (stop_tx, stop_rx) = watch::channel(false);
    let stopped = move || {
        let mut rx = stop_rx.clone();
        async move {
            let _ = rx.wait_for(|s| *s).await;
        }
    };
    let page_port = listener.local_addr().map_or(0, |a| a.port());
    let beside: Vec<_> = ctx
        .beside
        .into_iter()
        .map(|b| b.spawn(&shared, page_port, ctx.transport.clone(), stopped()))
        .collect();
    let main = server::run(listener, app, ctx.transport, stopped());
    tokio::pin!(main);
    let result = tokio::select! {
        r = &mut main => r,
        () = shutdown => {
            let _ = stop_tx.send(true);
            main.await
        }
    };
    let _ = stop_tx.send(true);
    for b in beside {
        let _ = b.await;
    }
    watcher.abort();
    sweeper.abort();
    fan_out.abort();
    result
}
