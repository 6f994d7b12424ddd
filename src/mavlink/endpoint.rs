//! MAVLink endpoints: the sockets and serial ports ground stations talk to,
//! and the router that fans frames in and out of them.
//!
//! Owns: parsing endpoint URLs (`udpin:`, `udpout:`, `tcpin:`, `tcpout:`,
//! `serial:`), binding/connecting and reconnecting, the per-endpoint peer
//! tables (UDP addresses, TCP connections, the serial port), per-endpoint
//! counters, and feeding the telemetry log. Every decoded frame goes to one
//! inbound channel tagged with where it came from; outbound bytes are routed
//! to all endpoints, one endpoint, or one peer.
//!
//! Under attack: each peer carries a [`PeerStanding`] the vehicle side sets
//! once a station that may control the vehicle speaks through it. A full
//! peer table ([`MAX_PEERS`]) makes room by evicting the least recently heard
//! peer that may not control (closing its TCP connection), so strangers can
//! never shut out a station that may control; idle TCP clients are closed
//! after the peer timeout like UDP peers; frames from peers that may not
//! control reach the telemetry log through a per-endpoint rate limit and may
//! use only part of the inbound channel.
//!
//! It never interprets a message (no authority, no signing, no replies):
//! that is the vehicle core's job. It never blocks the caller of
//! [`RouterHandle::send`]: queues are bounded, and a slow client loses frames
//! (counted in `send_errors`) rather than stalling the vehicle or the other
//! clients. A full inbound channel drops frames (counted) rather than
//! buffering without bound.

use std::collections::HashMap;
use std::fmt;
use std::future::Future;
use std::io;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, ToSocketAddrs};
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use serde::Serialize;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, BufWriter};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::{Instant, MissedTickBehavior};

use super::frame::{Frame, FrameDecoder, FrameStats, decode_datagram};
use super::tlog::{TlogConfig, TlogHandle, TlogSender, unix_time_us};

/// Where a ground station can reach us.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EndpointSpec {
    /// Listen on a UDP address; whoever sends to it becomes a peer.
    UdpIn(SocketAddr),
    /// Send to a UDP address (a ground station listening there), and to
    /// whoever sends to our socket.
    UdpOut(SocketAddr),
    /// Accept any number of TCP clients.
    TcpIn(SocketAddr),
    /// Connect to a TCP server, reconnecting as needed.
    TcpOut(SocketAddr),
    /// A serial port (telemetry radio, USB adapter), reopened as needed.
    Serial { path: PathBuf, baud: u32 },
}

/// Endpoints used when the user names none: QGroundControl's default UDP
/// port on this machine, and a TCP port for MAVProxy/pymavlink scripts.
pub const DEFAULT_ENDPOINTS: [&str; 2] = ["udpout:127.0.0.1:14550", "tcpin:0.0.0.0:5760"];

/// Baud rate used when a `serial:` URL names none (SiK radios' default).
pub const DEFAULT_SERIAL_BAUD: u32 = 57_600;

const EXPECTED_FORMS: &str = "udpin:ADDR:PORT, udpout:HOST:PORT, tcpin:ADDR:PORT, \
     tcpout:HOST:PORT or serial:PATH[:BAUD] (e.g. udpin:0.0.0.0:14550, serial:/dev/ttyUSB0:57600)";

/// Errors at the endpoint boundary.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    #[error("endpoint {url:?} is not valid: {reason}; expected {EXPECTED_FORMS}")]
    Spec { url: String, reason: String },
    #[error(
        "cannot open endpoint {url}: {source}; another program (QGroundControl, MAVProxy, \
         a second neptunus) may be using that address: pick another port or stop it"
    )]
    Bind { url: String, source: io::Error },
    #[error(
        "cannot create the telemetry log in {}: {source}; make the folder writable or turn \
         the telemetry log off",
        dir.display()
    )]
    Tlog { dir: PathBuf, source: io::Error },
}

impl FromStr for EndpointSpec {
    type Err = EndpointError;

    fn from_str(url: &str) -> Result<Self, Self::Err> {
        let err = |reason: String| EndpointError::Spec {
            url: url.to_owned(),
            reason,
        };
        let Some((scheme, rest)) = url.trim().split_once(':') else {
            return Err(err("no scheme".into()));
        };
        let addr = |rest: &str| resolve(rest).map_err(err);
        match scheme.to_ascii_lowercase().as_str() {
            "udpin" => Ok(Self::UdpIn(addr(rest)?)),
            "udpout" => Ok(Self::UdpOut(addr(rest)?)),
            "tcpin" => Ok(Self::TcpIn(addr(rest)?)),
            "tcpout" => Ok(Self::TcpOut(addr(rest)?)),
            "serial" => {
                let (path, baud) = match rest.rsplit_once(':') {
                    Some((path, baud)) if !baud.is_empty() => {
                        let baud =
                            baud.parse::<u32>().ok().filter(|&b| b > 0).ok_or_else(|| {
                                err(format!("baud rate {baud:?} is not a number"))
                            })?;
                        (path, baud)
                    }
                    _ => (rest, DEFAULT_SERIAL_BAUD),
                };
                if path.is_empty() {
                    return Err(err("no serial device path".into()));
                }
                Ok(Self::Serial {
                    path: PathBuf::from(path),
                    baud,
                })
            }
            other => Err(err(format!("unknown scheme {other:?}"))),
        }
    }
}

/// `host:port` or `ip:port` (`[v6]:port`) to one address; hostnames are
/// resolved now, once, so a typo fails at start-up rather than at send time.
fn resolve(text: &str) -> Result<SocketAddr, String> {
    if let Ok(addr) = text.parse::<SocketAddr>() {
        return Ok(addr);
    }
    if text
        .rsplit_once(':')
        .is_none_or(|(host, _)| host.is_empty())
    {
        return Err(format!("{text:?} is not HOST:PORT"));
    }
    let addrs: Vec<SocketAddr> = text
        .to_socket_addrs()
        .map_err(|e| format!("cannot resolve {text:?}: {e}"))?
        .collect();
    // Prefer IPv4: ground stations on robot networks rarely listen on v6.
    addrs
        .iter()
        .find(|a| a.is_ipv4())
        .or_else(|| addrs.first())
        .copied()
        .ok_or_else(|| format!("{text:?} resolves to no address"))
}

impl fmt::Display for EndpointSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UdpIn(a) => write!(f, "udpin:{a}"),
            Self::UdpOut(a) => write!(f, "udpout:{a}"),
            Self::TcpIn(a) => write!(f, "tcpin:{a}"),
            Self::TcpOut(a) => write!(f, "tcpout:{a}"),
            Self::Serial { path, baud } => write!(f, "serial:{}:{baud}", path.display()),
        }
    }
}

/// An endpoint as the user writes it: a URL, optionally ending in
/// `?trusted` (SETUP_SIGNING, which sets the signing key, is accepted only
/// on trusted endpoints — a cable or a VPN, never an open radio link).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EndpointUrl {
    pub spec: EndpointSpec,
    pub trusted: bool,
}

const TRUSTED_SUFFIX: &str = "?trusted";

impl FromStr for EndpointUrl {
    type Err = EndpointError;

    fn from_str(url: &str) -> Result<Self, Self::Err> {
        let url = url.trim();
        let (base, trusted) = match url.strip_suffix(TRUSTED_SUFFIX) {
            Some(base) => (base, true),
            None => (url, false),
        };
        if let Some((_, option)) = base.split_once('?') {
            return Err(EndpointError::Spec {
                url: url.to_owned(),
                reason: format!("unknown option {option:?} (the only option is ?trusted)"),
            });
        }
        Ok(Self {
            spec: base.parse()?,
            trusted,
        })
    }
}

impl fmt::Display for EndpointUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.spec)?;
        if self.trusted {
            f.write_str(TRUSTED_SUFFIX)?;
        }
        Ok(())
    }
}

/// Index of an endpoint in the list given to [`Router::start`].
pub type EndpointId = usize;
/// One remote (UDP address, TCP connection, serial port session); never
/// reused while the router runs.
pub type PeerId = u64;

/// A frame from a ground station.
#[derive(Debug, Clone)]
pub struct Inbound {
    pub endpoint: EndpointId,
    pub peer: PeerId,
    pub frame: Frame,
    /// The peer's standing with the router; the vehicle side marks it once a
    /// station that may control speaks through this peer.
    pub standing: PeerStanding,
}

/// What the router knows of one peer that the vehicle side tells it: whether
/// a station that may control the vehicle speaks through it. Shared by the
/// peer's table entry and every [`Inbound`] from it; cheap to clone and to
/// check on every frame (one atomic load).
#[derive(Debug, Clone, Default)]
pub struct PeerStanding(Arc<PeerShared>);

#[derive(Debug, Default)]
struct PeerShared {
    may_control: AtomicBool,
    /// Milliseconds since the router's epoch when it was last heard (TCP).
    last_heard_ms: AtomicU64,
}

impl PeerStanding {
    /// Whether a station that may control has been heard through this peer.
    pub fn may_control(&self) -> bool {
        self.0.may_control.load(Ordering::Relaxed)
    }

    /// Records whether a station that may control speaks through this peer;
    /// true when that changed it. A peer that may control is never evicted to
    /// make room for a newcomer and all its frames are logged.
    pub fn set_may_control(&self, may: bool) -> bool {
        self.may_control() != may && self.0.may_control.swap(may, Ordering::Relaxed) != may
    }

    fn heard(&self, epoch: Instant) {
        let ms = u64::try_from(epoch.elapsed().as_millis()).unwrap_or(u64::MAX);
        self.0.last_heard_ms.store(ms, Ordering::Relaxed);
    }

    fn last_heard_ms(&self) -> u64 {
        self.0.last_heard_ms.load(Ordering::Relaxed)
    }
}

/// Who gets an outbound frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    All,
    Endpoint(EndpointId),
    Peer(EndpointId, PeerId),
}

/// Encoded bytes (MAVLink 2) and where they go.
#[derive(Debug, Clone)]
pub struct Outbound {
    pub route: Route,
    pub bytes: Arc<[u8]>,
}

/// Counters of one endpoint. `frames_out`/`bytes_out` count each delivery to
/// each peer; `send_errors` counts frames a peer did not get (its queue was
/// full, or the OS refused them).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EndpointStats {
    pub spec: String,
    pub local_addr: Option<SocketAddr>,
    pub peers: usize,
    pub frames_in: u64,
    pub frames_out: u64,
    pub bytes_in: u64,
    pub bytes_out: u64,
    pub decode: FrameStats,
    pub send_errors: u64,
    /// Frames decoded but dropped because the inbound channel was full (or
    /// their sender was refused: the peer table was full of peers that may
    /// control).
    pub inbound_dropped: u64,
    /// Peers that may not control evicted to make room for a newcomer.
    pub peers_evicted: u64,
    /// Frames from (and replies to) peers that may not control left out of
    /// the telemetry log by its rate limit.
    pub tlog_dropped: u64,
}

/// Router settings.
#[derive(Debug, Clone)]
pub struct RouterConfig {
    /// UDP peers expire, and TCP clients are closed, after this long without
    /// a frame (a datagram, for UDP).
    pub peer_timeout: Duration,
    pub tlog: Option<TlogConfig>,
}

impl Default for RouterConfig {
    fn default() -> Self {
        Self {
            peer_timeout: Duration::from_secs(10),
            tlog: None,
        }
    }
}

/// Frames queued for one endpoint task before `send` starts dropping.
const ENDPOINT_QUEUE: usize = 1024;
/// Frames queued for one TCP/serial peer before its frames are dropped.
const PEER_QUEUE: usize = 256;
/// Peers per endpoint (UDP addresses or TCP clients). When full, the least
/// recently heard peer that may not control makes room for a newcomer;
/// only a table full of peers that may control refuses one. Bounded so that
/// spoofed source addresses or a connection flood cannot grow memory.
pub const MAX_PEERS: usize = 64;
/// Frames per second (per endpoint, for all its peers that may not control
/// together) that reach the telemetry log…
pub const TLOG_STRANGER_RATE_HZ: f64 = 20.0;
/// …with bursts of this many.
const TLOG_STRANGER_BURST: f64 = 40.0;
/// Peers that may not control may fill the inbound channel only to this
/// fraction: the rest is kept for stations that may control.
const INBOUND_STRANGER_SHARE: (usize, usize) = (3, 4);
/// Evictions are logged at most this often (with the count since).
const EVICTION_REPORT: Duration = Duration::from_secs(10);
const BACKOFF_MIN: Duration = Duration::from_millis(200);
const BACKOFF_MAX: Duration = Duration::from_secs(5);
/// How long `shutdown` waits for an endpoint task before aborting it.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(2);

/// Starts endpoints; see [`Router::start`].
pub struct Router;

impl Router {
    /// Binds/opens every endpoint, spawns one task per endpoint, and returns
    /// the handle. A bind failure is an error naming the URL and the OS
    /// error; `tcpout` and `serial` endpoints that cannot connect yet keep
    /// retrying with backoff instead. Every decoded frame goes to `inbound`
    /// (without waiting: frames are dropped and counted when it is full).
    ///
    /// A telemetry log that cannot be opened (a read-only or full data
    /// directory, no descriptors left) is logged as an error and the router
    /// runs without one: the vehicle must not depend on its disk.
    pub async fn start(
        specs: Vec<EndpointSpec>,
        cfg: RouterConfig,
        inbound: mpsc::Sender<Inbound>,
    ) -> Result<RouterHandle, EndpointError> {
        let tlog = match &cfg.tlog {
            Some(tlog_cfg) => match TlogHandle::spawn(tlog_cfg) {
                Ok(tlog) => Some(tlog),
                Err(source) => {
                    let e = EndpointError::Tlog {
                        dir: tlog_cfg.dir.clone(),
                        source,
                    };
                    tracing::error!("{e}. RUNNING WITHOUT A TELEMETRY LOG");
                    None
                }
            },
            None => None,
        };
        let epoch = Instant::now();
        let next_peer = Arc::new(AtomicU64::new(1));
        let (shutdown_tx, shutdown_rx) = watch::channel(false);

        // Bind everything before spawning anything, so a failure leaves no task behind.
        let mut opened = Vec::with_capacity(specs.len());
        for spec in &specs {
            opened.push(open(spec).await?);
        }

        let mut endpoints = Vec::with_capacity(specs.len());
        let mut tasks = Vec::with_capacity(specs.len());
        for (id, (spec, opened)) in specs.into_iter().zip(opened).enumerate() {
            let ctx = Arc::new(EndpointCtx {
                id,
                url: spec.to_string(),
                counters: Counters::default(),
                inbound: inbound.clone(),
                tlog: tlog.as_ref().map(|t| t.sender.clone()),
                next_peer: Arc::clone(&next_peer),
                epoch,
                tlog_bucket: Mutex::new(TokenBucket::new(epoch)),
                evictions_unreported: AtomicU64::new(0),
                last_eviction_report: Mutex::new(None),
            });
            let (queue_tx, queue_rx) = mpsc::channel(ENDPOINT_QUEUE);
            let shutdown = shutdown_rx.clone();
            let task_ctx = Arc::clone(&ctx);
            let task = match opened {
                Opened::Udp { socket, target } => {
                    ctx.counters.set_local_addr(socket.local_addr().ok());
                    // The udpout target is a peer from the start.
                    ctx.set_peers(usize::from(target.is_some()));
                    tokio::spawn(run_udp(
                        task_ctx,
                        socket,
                        target,
                        cfg.peer_timeout,
                        queue_rx,
                        shutdown,
                    ))
                }
                Opened::TcpListener(listener) => {
                    ctx.counters.set_local_addr(listener.local_addr().ok());
                    tokio::spawn(run_tcp_in(
                        task_ctx,
                        listener,
                        cfg.peer_timeout,
                        queue_rx,
                        shutdown,
                    ))
                }
                Opened::TcpOut(addr) => tokio::spawn(run_connector(
                    task_ctx,
                    queue_rx,
                    shutdown,
                    move || async move {
                        let stream = TcpStream::connect(addr).await?;
                        // MAVLink frames are small and latency matters more than packing.
                        stream.set_nodelay(true)?;
                        let local = stream.local_addr().ok();
                        Ok((stream, local))
                    },
                )),
                Opened::Serial { path, baud } => {
                    tokio::spawn(run_connector(task_ctx, queue_rx, shutdown, move || {
                        let opened = open_serial(&path, baud);
                        async move { opened.map(|s| (s, None)) }
                    }))
                }
            };
            tracing::info!(endpoint = %ctx.url, "MAVLink endpoint started");
            endpoints.push(EndpointSlot {
                ctx,
                queue: queue_tx,
            });
            tasks.push(task);
        }

        Ok(RouterHandle {
            inner: Arc::new(Inner {
                endpoints,
                shutdown: shutdown_tx,
                tasks: Mutex::new(tasks),
                tlog,
            }),
        })
    }
}

/// The running router. Cloning is cheap; dropping every clone stops it (but
/// only [`RouterHandle::shutdown`] waits for the telemetry log to be flushed).
#[derive(Clone)]
pub struct RouterHandle {
    inner: Arc<Inner>,
}

struct Inner {
    endpoints: Vec<EndpointSlot>,
    shutdown: watch::Sender<bool>,
    tasks: Mutex<Vec<JoinHandle<()>>>,
    tlog: Option<TlogHandle>,
}

struct EndpointSlot {
    ctx: Arc<EndpointCtx>,
    queue: mpsc::Sender<Queued>,
}

impl RouterHandle {
    /// Queues bytes for their route. Never blocks: when an endpoint's queue
    /// is full the frame is dropped for that endpoint and counted.
    ///
    /// Logged once per send, however many peers get it; a frame for one peer
    /// is logged by its endpoint, which knows whether that peer may control
    /// (replies to the others share their rate limit: a stranger's requests
    /// cannot fill the log with our answers).
    pub fn send(&self, out: Outbound) {
        if let Some(tlog) = &self.inner.tlog
            && !matches!(out.route, Route::Peer(..))
        {
            tlog.sender.record(unix_time_us(), Arc::clone(&out.bytes));
        }
        let (slots, target) = match out.route {
            Route::All => (&self.inner.endpoints[..], Target::All),
            Route::Endpoint(e) => (self.slot(e), Target::All),
            Route::Peer(e, p) => (self.slot(e), Target::Peer(p)),
        };
        for slot in slots {
            let queued = Queued {
                target,
                bytes: Arc::clone(&out.bytes),
            };
            if let Err(mpsc::error::TrySendError::Full(_)) = slot.queue.try_send(queued) {
                slot.ctx
                    .send_error("endpoint queue full: dropping outbound frames");
            }
        }
    }

    fn slot(&self, endpoint: EndpointId) -> &[EndpointSlot] {
        let slots = self.inner.endpoints.get(endpoint..=endpoint).unwrap_or(&[]);
        if slots.is_empty() {
            tracing::debug!(
                endpoint,
                "outbound frame for an endpoint that does not exist"
            );
        }
        slots
    }

    /// Counters of every endpoint, in the order given to [`Router::start`].
    pub fn stats(&self) -> Vec<EndpointStats> {
        self.inner
            .endpoints
            .iter()
            .map(|slot| slot.ctx.stats())
            .collect()
    }

    /// The address an endpoint is bound to (for `tcpout`, the local end of
    /// the current connection; `None` for serial).
    pub fn local_addr(&self, endpoint: EndpointId) -> Option<SocketAddr> {
        self.inner
            .endpoints
            .get(endpoint)
            .and_then(|slot| slot.ctx.counters.local_addr())
    }

    /// Stops every endpoint, closes every socket and connection, and flushes
    /// the telemetry log.
    pub async fn shutdown(self) {
        self.inner.shutdown.send_replace(true);
        let tasks = std::mem::take(
            &mut *self
                .inner
                .tasks
                .lock()
                .unwrap_or_else(PoisonError::into_inner),
        );
        for mut task in tasks {
            if tokio::time::timeout(SHUTDOWN_GRACE, &mut task)
                .await
                .is_err()
            {
                task.abort();
            }
        }
        if let Some(tlog) = &self.inner.tlog {
            tlog.stop().await;
        }
    }
}

// ---------------------------------------------------------------------------
// per-endpoint context and counters
// ---------------------------------------------------------------------------

#[derive(Debug, Clone, Copy)]
enum Target {
    All,
    Peer(PeerId),
}

struct Queued {
    target: Target,
    bytes: Arc<[u8]>,
}

/// What every task of one endpoint shares.
struct EndpointCtx {
    id: EndpointId,
    url: String,
    counters: Counters,
    inbound: mpsc::Sender<Inbound>,
    tlog: Option<TlogSender>,
    next_peer: Arc<AtomicU64>,
    /// Zero of [`PeerStanding`]'s last-heard times.
    epoch: Instant,
    /// The telemetry log's share for peers that may not control.
    tlog_bucket: Mutex<TokenBucket>,
    evictions_unreported: AtomicU64,
    last_eviction_report: Mutex<Option<Instant>>,
}

/// Frames allowed at [`TLOG_STRANGER_RATE_HZ`] with bursts of [`TLOG_STRANGER_BURST`].
struct TokenBucket {
    tokens: f64,
    last: Instant,
}

impl TokenBucket {
    fn new(now: Instant) -> Self {
        Self {
            tokens: TLOG_STRANGER_BURST,
            last: now,
        }
    }

    fn take(&mut self, now: Instant) -> bool {
        let dt = now.saturating_duration_since(self.last).as_secs_f64();
        self.last = now;
        self.tokens = (self.tokens + dt * TLOG_STRANGER_RATE_HZ).min(TLOG_STRANGER_BURST);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

#[derive(Default)]
struct Counters {
    peers: AtomicUsize,
    frames_in: AtomicU64,
    frames_out: AtomicU64,
    bytes_in: AtomicU64,
    bytes_out: AtomicU64,
    send_errors: AtomicU64,
    inbound_dropped: AtomicU64,
    peers_evicted: AtomicU64,
    tlog_dropped: AtomicU64,
    decode: Mutex<FrameStats>,
    local_addr: Mutex<Option<SocketAddr>>,
    /// Kinds of trouble already logged (bit per kind): log once, count always.
    warned: AtomicU32,
}

impl Counters {
    fn set_local_addr(&self, addr: Option<SocketAddr>) {
        *self
            .local_addr
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = addr;
    }

    fn local_addr(&self) -> Option<SocketAddr> {
        *self
            .local_addr
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
}

const WARN_BAD_CRC: u32 = 1;
const WARN_UNKNOWN: u32 = 2;
const WARN_BAD_PAYLOAD: u32 = 4;
const WARN_GARBAGE: u32 = 8;
const WARN_SEND: u32 = 16;
const WARN_INBOUND: u32 = 32;
const WARN_PEERS: u32 = 64;
const WARN_TLOG_RATE: u32 = 128;
const WARN_INBOUND_SHARE: u32 = 256;

impl EndpointCtx {
    fn new_peer(&self) -> PeerId {
        self.next_peer.fetch_add(1, Ordering::Relaxed)
    }

    fn set_peers(&self, n: usize) {
        self.counters.peers.store(n, Ordering::Relaxed);
    }

    fn first_time(&self, bit: u32) -> bool {
        self.counters.warned.fetch_or(bit, Ordering::Relaxed) & bit == 0
    }

    fn send_error(&self, what: &str) {
        self.counters.send_errors.fetch_add(1, Ordering::Relaxed);
        if self.first_time(WARN_SEND) {
            tracing::warn!(endpoint = %self.url, "{what} (logged once; see send_errors)");
        }
    }

    /// A new peer was refused because the table is full of peers that may
    /// control; its `frames` are dropped (counted as inbound drops).
    fn refuse_peer(&self, from: &str, frames: usize) {
        self.counters
            .inbound_dropped
            .fetch_add(frames as u64, Ordering::Relaxed);
        if self.first_time(WARN_PEERS) {
            tracing::warn!(endpoint = %self.url, %from, "peer table full ({MAX_PEERS} peers, all stations that may control): refusing new peers (logged once)");
        }
    }

    /// A peer that may not control was evicted for `newcomer`: counted
    /// always, logged once per burst.
    fn evicted(&self, victim: &str, newcomer: &str) {
        self.counters.peers_evicted.fetch_add(1, Ordering::Relaxed);
        let unreported = self.evictions_unreported.fetch_add(1, Ordering::Relaxed) + 1;
        let now = Instant::now();
        let mut last = self
            .last_eviction_report
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if last.is_none_or(|t| now.saturating_duration_since(t) >= EVICTION_REPORT) {
            *last = Some(now);
            self.evictions_unreported.store(0, Ordering::Relaxed);
            tracing::warn!(
                endpoint = %self.url, %victim, %newcomer, evicted = unreported,
                "peer table full ({MAX_PEERS}): evicting the least recently heard peers that may \
                 not control to admit new ones (a flood of peers? logged once per {} s; see \
                 peers_evicted)",
                EVICTION_REPORT.as_secs()
            );
        }
    }

    /// Logs a frame addressed to one peer: always for a peer that may
    /// control, through the shared rate limit for the others.
    fn log_reply(&self, standing: &PeerStanding, bytes: &Arc<[u8]>) {
        let Some(tlog) = &self.tlog else { return };
        if standing.may_control() || self.tlog_allows_stranger(Instant::now()) {
            tlog.record(unix_time_us(), Arc::clone(bytes));
        }
    }

    /// One frame of a peer that may not control into the log, if the rate
    /// limit allows; counted (and said once) when it does not.
    fn tlog_allows_stranger(&self, now: Instant) -> bool {
        let allowed = self
            .tlog_bucket
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take(now);
        if !allowed {
            self.counters.tlog_dropped.fetch_add(1, Ordering::Relaxed);
            if self.first_time(WARN_TLOG_RATE) {
                tracing::warn!(endpoint = %self.url, "frames to and from stations that may not control reach the telemetry log at most {TLOG_STRANGER_RATE_HZ}/s per endpoint: dropping the rest from the log (logged once; see tlog_dropped)");
            }
        }
        allowed
    }

    fn sent(&self, bytes: usize) {
        self.counters.frames_out.fetch_add(1, Ordering::Relaxed);
        self.counters
            .bytes_out
            .fetch_add(bytes as u64, Ordering::Relaxed);
    }

    /// Accounts for `bytes_in` bytes that decoded to `frames` (drained) with
    /// `delta` decoder counters, and passes the frames on.
    fn deliver(
        &self,
        peer: PeerId,
        standing: &PeerStanding,
        bytes_in: usize,
        frames: &mut Vec<Frame>,
        delta: &FrameStats,
    ) {
        let c = &self.counters;
        c.bytes_in.fetch_add(bytes_in as u64, Ordering::Relaxed);
        c.frames_in
            .fetch_add(frames.len() as u64, Ordering::Relaxed);
        if delta != &FrameStats::default() {
            c.decode
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .add(delta);
            for (count, bit, what) in [
                (delta.bad_crc, WARN_BAD_CRC, "frames with a bad CRC"),
                (
                    delta.unknown_msg,
                    WARN_UNKNOWN,
                    "frames of unknown message ids",
                ),
                (
                    delta.bad_payload,
                    WARN_BAD_PAYLOAD,
                    "frames with undecodable payloads",
                ),
                (
                    delta.garbage_bytes,
                    WARN_GARBAGE,
                    "bytes that are not MAVLink",
                ),
            ] {
                if count > 0 && self.first_time(bit) {
                    tracing::warn!(endpoint = %self.url, peer, "dropping {what} (logged once; see the endpoint's decode stats)");
                }
            }
        }
        if frames.is_empty() {
            return;
        }
        let now_us = unix_time_us();
        let may_control = standing.may_control();
        let now = Instant::now();
        standing.heard(self.epoch);
        for frame in frames.drain(..) {
            if let Some(tlog) = &self.tlog
                && (may_control || self.tlog_allows_stranger(now))
            {
                tlog.record(now_us, Arc::from(frame.raw.as_slice()));
            }
            // Strangers may not crowd out the stations that may control.
            let (num, den) = INBOUND_STRANGER_SHARE;
            if !may_control
                && self.inbound.capacity() * den < self.inbound.max_capacity() * (den - num)
            {
                c.inbound_dropped.fetch_add(1, Ordering::Relaxed);
                if self.first_time(WARN_INBOUND_SHARE) {
                    tracing::warn!(endpoint = %self.url, peer, "inbound channel filling up: dropping frames from stations that may not control (logged once)");
                }
                continue;
            }
            let inbound = Inbound {
                endpoint: self.id,
                peer,
                frame,
                standing: standing.clone(),
            };
            if let Err(mpsc::error::TrySendError::Full(_)) = self.inbound.try_send(inbound) {
                c.inbound_dropped.fetch_add(1, Ordering::Relaxed);
                if self.first_time(WARN_INBOUND) {
                    tracing::warn!(endpoint = %self.url, "inbound channel full: dropping frames (logged once)");
                }
            }
        }
    }

    fn stats(&self) -> EndpointStats {
        let c = &self.counters;
        EndpointStats {
            spec: self.url.clone(),
            local_addr: c.local_addr(),
            peers: c.peers.load(Ordering::Relaxed),
            frames_in: c.frames_in.load(Ordering::Relaxed),
            frames_out: c.frames_out.load(Ordering::Relaxed),
            bytes_in: c.bytes_in.load(Ordering::Relaxed),
            bytes_out: c.bytes_out.load(Ordering::Relaxed),
            decode: c
                .decode
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone(),
            send_errors: c.send_errors.load(Ordering::Relaxed),
            inbound_dropped: c.inbound_dropped.load(Ordering::Relaxed),
            peers_evicted: c.peers_evicted.load(Ordering::Relaxed),
            tlog_dropped: c.tlog_dropped.load(Ordering::Relaxed),
        }
    }
}

// ---------------------------------------------------------------------------
// opening
// ---------------------------------------------------------------------------

enum Opened {
    Udp {
        socket: UdpSocket,
        target: Option<SocketAddr>,
    },
    TcpListener(TcpListener),
    TcpOut(SocketAddr),
    Serial {
        path: PathBuf,
        baud: u32,
    },
}

async fn open(spec: &EndpointSpec) -> Result<Opened, EndpointError> {
    let bind_err = |source| EndpointError::Bind {
        url: spec.to_string(),
        source,
    };
    Ok(match spec {
        EndpointSpec::UdpIn(addr) => {
            let socket = UdpSocket::bind(addr).await.map_err(bind_err)?;
            allow_broadcast(&socket);
            Opened::Udp {
                socket,
                target: None,
            }
        }
        EndpointSpec::UdpOut(target) => {
            let any: SocketAddr = if target.is_ipv4() {
                (Ipv4Addr::UNSPECIFIED, 0).into()
            } else {
                (Ipv6Addr::UNSPECIFIED, 0).into()
            };
            let socket = UdpSocket::bind(any).await.map_err(bind_err)?;
            allow_broadcast(&socket);
            Opened::Udp {
                socket,
                target: Some(*target),
            }
        }
        EndpointSpec::TcpIn(addr) => {
            Opened::TcpListener(TcpListener::bind(addr).await.map_err(bind_err)?)
        }
        EndpointSpec::TcpOut(addr) => Opened::TcpOut(*addr),
        EndpointSpec::Serial { path, baud } => Opened::Serial {
            path: path.clone(),
            baud: *baud,
        },
    })
}

/// `udpout:192.168.2.255:14550` (a subnet broadcast) is a common set-up on
/// tethered ROVs; without SO_BROADCAST every send would fail.
fn allow_broadcast(socket: &UdpSocket) {
    if let Err(e) = socket.set_broadcast(true) {
        tracing::debug!(error = %e, "cannot enable UDP broadcast");
    }
}

fn open_serial(path: &std::path::Path, baud: u32) -> io::Result<tokio_serial::SerialStream> {
    use tokio_serial::SerialPortBuilderExt;
    let mut port = tokio_serial::new(path.to_string_lossy(), baud)
        .data_bits(tokio_serial::DataBits::Eight)
        .parity(tokio_serial::Parity::None)
        .stop_bits(tokio_serial::StopBits::One)
        .flow_control(tokio_serial::FlowControl::None)
        .open_native_async()
        .map_err(io::Error::from)?;
    // Not exclusive: a technician may want to sniff the radio link; and on a
    // pty some ioctls are unsupported, which is harmless here.
    if let Err(e) = port.set_exclusive(false) {
        tracing::debug!(path = %path.display(), error = %e, "cannot clear exclusive mode");
    }
    Ok(port)
}

/// Resolves when the router shuts down (or every handle is gone).
async fn stopped(shutdown: &mut watch::Receiver<bool>) {
    // An error means the sender is gone: nobody can ever use us again.
    let _ = shutdown.wait_for(|&stop| stop).await;
}

// ---------------------------------------------------------------------------
// UDP
// ---------------------------------------------------------------------------

struct UdpPeer {
    id: PeerId,
    last_seen: Instant,
    standing: PeerStanding,
}

/// The peer for a datagram of valid MAVLink from `from`: known, admitted
/// (evicting the least recently heard peer that may not control when the
/// table is full), or `None` when every slot holds a peer that may control.
fn admit_udp(
    ctx: &EndpointCtx,
    peers: &mut HashMap<SocketAddr, UdpPeer>,
    from: SocketAddr,
    now: Instant,
) -> Option<(PeerId, PeerStanding)> {
    if let Some(known) = peers.get_mut(&from) {
        known.last_seen = now;
        return Some((known.id, known.standing.clone()));
    }
    let full = peers.len() >= MAX_PEERS;
    if full {
        let victim = peers
            .iter()
            .filter(|(_, p)| !p.standing.may_control())
            .min_by_key(|(_, p)| (p.last_seen, p.id))
            .map(|(addr, _)| *addr)?;
        if let Some(old) = peers.remove(&victim) {
            tracing::debug!(endpoint = %ctx.url, %victim, peer = old.id, "UDP peer evicted");
        }
        ctx.evicted(&victim.to_string(), &from.to_string());
    }
    let id = ctx.new_peer();
    if full {
        // A churning flood of source ports: the eviction report sums it up.
        tracing::debug!(endpoint = %ctx.url, %from, peer = id, "new UDP peer");
    } else {
        tracing::info!(endpoint = %ctx.url, %from, peer = id, "new UDP peer");
    }
    let standing = PeerStanding::default();
    peers.insert(
        from,
        UdpPeer {
            id,
            last_seen: now,
            standing: standing.clone(),
        },
    );
    Some((id, standing))
}

async fn run_udp(
    ctx: Arc<EndpointCtx>,
    socket: UdpSocket,
    target: Option<SocketAddr>,
    peer_timeout: Duration,
    mut queue: mpsc::Receiver<Queued>,
    mut shutdown: watch::Receiver<bool>,
) {
    // The configured target is a permanent peer; it never expires.
    let target = target.map(|addr| (addr, ctx.new_peer()));
    let target_standing = PeerStanding::default();
    let fixed = usize::from(target.is_some());
    let mut peers: HashMap<SocketAddr, UdpPeer> = HashMap::new();
    ctx.set_peers(fixed);
    let mut buf = vec![0u8; 65_536];
    let mut frames = Vec::new();
    let mut sweep = tokio::time::interval((peer_timeout / 4).max(Duration::from_millis(10)));
    sweep.set_missed_tick_behavior(MissedTickBehavior::Delay);

    loop {
        tokio::select! {
            () = stopped(&mut shutdown) => break,
            received = socket.recv_from(&mut buf) => match received {
                Ok((n, from)) => {
                    let mut delta = FrameStats::default();
                    decode_datagram(&buf[..n], &mut delta, &mut frames);
                    // Only a sender of valid MAVLink becomes a peer: a port
                    // scan or a stray packet must not start a telemetry stream.
                    let peer = match target {
                        Some((addr, id)) if addr == from => Some((id, target_standing.clone())),
                        _ if frames.is_empty() => None,
                        _ => {
                            let admitted = admit_udp(&ctx, &mut peers, from, Instant::now());
                            ctx.set_peers(fixed + peers.len());
                            admitted
                        }
                    };
                    match peer {
                        Some((peer, standing)) => ctx.deliver(peer, &standing, n, &mut frames, &delta),
                        None => {
                            if !frames.is_empty() {
                                ctx.refuse_peer(&from.to_string(), frames.len());
                                frames.clear();
                            }
                            ctx.deliver(0, &PeerStanding::default(), n, &mut frames, &delta);
                        }
                    }
                }
                Err(e) => {
                    // Linux reports ICMP errors from earlier sends here; they
                    // say nothing about the next datagram.
                    tracing::debug!(endpoint = %ctx.url, error = %e, "UDP receive error");
                }
            },
            queued = queue.recv() => {
                let Some(queued) = queued else { break };
                let mut dests: Vec<SocketAddr> = Vec::new();
                match queued.target {
                    Target::All => {
                        dests.extend(target.map(|(addr, _)| addr));
                        dests.extend(peers.keys().copied());
                    }
                    Target::Peer(id) => {
                        if let Some((addr, _)) = target.filter(|&(_, t)| t == id) {
                            ctx.log_reply(&target_standing, &queued.bytes);
                            dests.push(addr);
                        } else if let Some((addr, p)) = peers.iter().find(|(_, p)| p.id == id) {
                            ctx.log_reply(&p.standing, &queued.bytes);
                            dests.push(*addr);
                        }
                    }
                }
                for dest in dests {
                    match socket.send_to(&queued.bytes, dest).await {
                        Ok(_) => ctx.sent(queued.bytes.len()),
                        Err(e) => ctx.send_error(&format!("UDP send to {dest} failed: {e}")),
                    }
                }
            }
            _ = sweep.tick() => {
                let now = Instant::now();
                peers.retain(|addr, peer| {
                    let live = now.duration_since(peer.last_seen) < peer_timeout;
                    if !live {
                        tracing::info!(endpoint = %ctx.url, %addr, peer = peer.id, "UDP peer timed out");
                    }
                    live
                });
                ctx.set_peers(fixed + peers.len());
            }
        }
    }
    ctx.set_peers(0);
}

// ---------------------------------------------------------------------------
// TCP server
// ---------------------------------------------------------------------------

/// One TCP client of a `tcpin` endpoint.
struct Conn {
    tx: mpsc::Sender<Arc<[u8]>>,
    abort: tokio::task::AbortHandle,
    standing: PeerStanding,
}

async fn run_tcp_in(
    ctx: Arc<EndpointCtx>,
    listener: TcpListener,
    idle_timeout: Duration,
    mut queue: mpsc::Receiver<Queued>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut conns: HashMap<PeerId, Conn> = HashMap::new();
    let mut task_peer: HashMap<tokio::task::Id, PeerId> = HashMap::new();
    // Dropping the set at the end aborts every connection.
    let mut tasks = tokio::task::JoinSet::new();
    // After a failed accept (out of descriptors, mostly) accepting pauses
    // while everything else goes on: the queue keeps being served, so the
    // clients already connected keep their telemetry, fresh.
    let accept_pause = tokio::time::sleep(Duration::ZERO);
    tokio::pin!(accept_pause);
    let mut paused = false;
    let mut accept_failures = 0u64;

    loop {
        tokio::select! {
            () = stopped(&mut shutdown) => break,
            () = &mut accept_pause, if paused => paused = false,
            accepted = listener.accept(), if !paused => match accepted {
                Ok((stream, from)) => {
                    if accept_failures > 0 {
                        tracing::info!(endpoint = %ctx.url, failures = accept_failures, "accepting TCP clients again");
                        accept_failures = 0;
                    }
                    if conns.len() >= MAX_PEERS {
                        // Each client costs a queue and a task: bound them,
                        // at the expense of those that may not control.
                        let victim = conns
                            .iter()
                            .filter(|(_, c)| !c.standing.may_control())
                            // Ties (same millisecond): the oldest connection.
                            .min_by_key(|(id, c)| (c.standing.last_heard_ms(), **id))
                            .map(|(id, _)| *id);
                        match victim.and_then(|id| conns.remove(&id).map(|c| (id, c))) {
                            Some((id, conn)) => {
                                conn.abort.abort();
                                ctx.evicted(&format!("TCP peer {id}"), &from.to_string());
                            }
                            None => {
                                drop(stream);
                                ctx.refuse_peer(&from.to_string(), 0);
                                continue;
                            }
                        }
                    }
                    let peer = ctx.new_peer();
                    if let Err(e) = stream.set_nodelay(true) {
                        tracing::debug!(error = %e, "cannot set TCP_NODELAY");
                    }
                    tracing::info!(endpoint = %ctx.url, %from, peer, "TCP client connected");
                    let (tx, rx) = mpsc::channel(PEER_QUEUE);
                    let standing = PeerStanding::default();
                    standing.heard(ctx.epoch);
                    let handle = tasks.spawn(run_stream(
                        Arc::clone(&ctx),
                        peer,
                        standing.clone(),
                        stream,
                        rx,
                        Some(idle_timeout),
                    ));
                    task_peer.insert(handle.id(), peer);
                    conns.insert(peer, Conn { tx, abort: handle, standing });
                    ctx.set_peers(conns.len());
                }
                Err(e) => {
                    // EMFILE/ENFILE mostly: back off instead of spinning.
                    if accept_failures == 0 {
                        tracing::warn!(
                            endpoint = %ctx.url, error = %e,
                            "cannot accept TCP clients (out of file descriptors?); retrying every \
                             {} ms, connected clients are still served", BACKOFF_MIN.as_millis()
                        );
                    }
                    accept_failures += 1;
                    accept_pause.as_mut().reset(Instant::now() + BACKOFF_MIN);
                    paused = true;
                }
            },
            Some(done) = tasks.join_next_with_id() => {
                let id = match done {
                    Ok((id, ())) => id,
                    Err(e) => e.id(),
                };
                if let Some(peer) = task_peer.remove(&id) {
                    conns.remove(&peer);
                    tracing::info!(endpoint = %ctx.url, peer, "TCP client disconnected");
                }
                ctx.set_peers(conns.len());
            }
            queued = queue.recv() => {
                let Some(queued) = queued else { break };
                if let Target::Peer(id) = queued.target
                    && let Some(conn) = conns.get(&id)
                {
                    ctx.log_reply(&conn.standing, &queued.bytes);
                }
                dispatch(&ctx, conns.iter().map(|(id, c)| (*id, &c.tx)), &queued);
            }
        }
    }
    ctx.set_peers(0);
}

/// Hands a frame to stream peers' queues without waiting.
fn dispatch<'a>(
    ctx: &EndpointCtx,
    conns: impl Iterator<Item = (PeerId, &'a mpsc::Sender<Arc<[u8]>>)>,
    q: &Queued,
) {
    for (id, tx) in conns {
        if matches!(q.target, Target::Peer(p) if p != id) {
            continue;
        }
        if let Err(mpsc::error::TrySendError::Full(_)) = tx.try_send(Arc::clone(&q.bytes)) {
            ctx.send_error("a client is not reading: dropping its frames");
        }
    }
}

/// Runs one byte-stream peer (TCP connection or serial port) until it
/// closes or fails: decodes what it sends, writes what is queued for it.
/// Reading and writing are polled together so a peer that does not read
/// still has its input decoded. With `idle_timeout`, a peer that sends no
/// frame for that long is closed (a connection that only holds a slot).
async fn run_stream<S>(
    ctx: Arc<EndpointCtx>,
    peer: PeerId,
    standing: PeerStanding,
    stream: S,
    mut rx: mpsc::Receiver<Arc<[u8]>>,
    idle_timeout: Option<Duration>,
) where
    S: AsyncRead + AsyncWrite + Send + 'static,
{
    let (mut rd, wr) = tokio::io::split(stream);
    let reader = async {
        let mut decoder = FrameDecoder::new();
        let mut buf = vec![0u8; 4096];
        let mut frames = Vec::new();
        let mut last_frame = Instant::now();
        loop {
            let read = match idle_timeout {
                Some(idle) => {
                    match tokio::time::timeout_at(last_frame + idle, rd.read(&mut buf)).await {
                        Ok(read) => read,
                        Err(_) => {
                            return Err(io::Error::new(
                                io::ErrorKind::TimedOut,
                                format!(
                                    "no MAVLink frame for {:.1} s (peer_timeout_s): closed",
                                    idle.as_secs_f64()
                                ),
                            ));
                        }
                    }
                }
                None => rd.read(&mut buf).await,
            };
            match read {
                Ok(0) => return Ok(()),
                Ok(n) => {
                    decoder.push(&buf[..n], &mut frames);
                    let delta = decoder.take_stats();
                    // Garbage does not keep a connection alive; frames do.
                    if !frames.is_empty() {
                        last_frame = Instant::now();
                    }
                    ctx.deliver(peer, &standing, n, &mut frames, &delta);
                }
                Err(e) => return Err(e),
            }
        }
    };
    let writer = async {
        let mut wr = BufWriter::new(wr);
        while let Some(bytes) = rx.recv().await {
            wr.write_all(&bytes).await?;
            ctx.sent(bytes.len());
            // Batch whatever else is already queued into the same write.
            while let Ok(bytes) = rx.try_recv() {
                wr.write_all(&bytes).await?;
                ctx.sent(bytes.len());
            }
            wr.flush().await?;
        }
        Ok::<(), io::Error>(())
    };
    let result = tokio::select! {
        r = reader => r,
        w = writer => w,
    };
    if let Err(e) = result {
        tracing::info!(endpoint = %ctx.url, peer, error = %e, "peer connection ended");
    }
}

// ---------------------------------------------------------------------------
// TCP client and serial: one peer, reconnect with backoff
// ---------------------------------------------------------------------------

async fn run_connector<S, F, Fut>(
    ctx: Arc<EndpointCtx>,
    mut queue: mpsc::Receiver<Queued>,
    mut shutdown: watch::Receiver<bool>,
    mut connect: F,
) where
    S: AsyncRead + AsyncWrite + Send + 'static,
    F: FnMut() -> Fut,
    Fut: Future<Output = io::Result<(S, Option<SocketAddr>)>>,
{
    let mut backoff = BACKOFF_MIN;
    let mut failures = 0u32;
    loop {
        let attempt = while_discarding(&mut queue, &mut shutdown, connect()).await;
        let (stream, local) = match attempt {
            None => break,
            Some(Ok(opened)) => opened,
            Some(Err(e)) => {
                if failures == 0 {
                    tracing::warn!(endpoint = %ctx.url, error = %e, "cannot connect; retrying with backoff");
                } else {
                    tracing::debug!(endpoint = %ctx.url, error = %e, "still cannot connect");
                }
                failures = failures.saturating_add(1);
                let wait = tokio::time::sleep(backoff);
                backoff = (backoff * 2).min(BACKOFF_MAX);
                if while_discarding(&mut queue, &mut shutdown, wait)
                    .await
                    .is_none()
                {
                    break;
                }
                continue;
            }
        };
        backoff = BACKOFF_MIN;
        failures = 0;
        let peer = ctx.new_peer();
        tracing::info!(endpoint = %ctx.url, peer, "connected");
        ctx.counters.set_local_addr(local);
        ctx.set_peers(1);
        let (tx, rx) = mpsc::channel(PEER_QUEUE);
        let standing = PeerStanding::default();
        // tcpout and serial links are ours to keep: no idle timeout.
        let session = run_stream(Arc::clone(&ctx), peer, standing.clone(), stream, rx, None);
        tokio::pin!(session);
        let stop = loop {
            tokio::select! {
                () = stopped(&mut shutdown) => break true,
                () = &mut session => break false,
                queued = queue.recv() => match queued {
                    Some(queued) => {
                        if matches!(queued.target, Target::Peer(p) if p == peer) {
                            ctx.log_reply(&standing, &queued.bytes);
                        }
                        dispatch(&ctx, std::iter::once((peer, &tx)), &queued);
                    }
                    None => break true,
                },
            }
        };
        ctx.set_peers(0);
        if stop {
            break;
        }
        tracing::warn!(endpoint = %ctx.url, peer, "disconnected; reconnecting");
        // A peer that drops us at once must not make us hammer it.
        if while_discarding(&mut queue, &mut shutdown, tokio::time::sleep(BACKOFF_MIN))
            .await
            .is_none()
        {
            break;
        }
    }
    ctx.set_peers(0);
}

/// Runs `fut` while throwing away frames queued for a peer that is not
/// there (as UDP does with no peers), so `send` never sees a full queue
/// because of a disconnected link. `None` on shutdown.
async fn while_discarding<T>(
    queue: &mut mpsc::Receiver<Queued>,
    shutdown: &mut watch::Receiver<bool>,
    fut: impl Future<Output = T>,
) -> Option<T> {
    tokio::pin!(fut);
    loop {
        tokio::select! {
            () = stopped(shutdown) => return None,
            out = &mut fut => return Some(out),
            // A closed queue means the router is gone.
            queued = queue.recv() => { queued.as_ref()?; }
        }
    }
}
