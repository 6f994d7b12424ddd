//! The router: opens every endpoint, runs one task per endpoint, and routes
//! outbound frames to them ([`Router`], [`RouterHandle`]).
//!
//! Owns start-up (every endpoint is bound before any task is spawned, so a
//! failure leaves no task behind), the per-endpoint queues, routing by
//! [`Route`], the telemetry log's lifetime, and shutdown. It must never block
//! the caller of [`RouterHandle::send`], the vehicle task: a full queue drops
//! the frame for that endpoint and counts it.

use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use tokio::net::{TcpListener, UdpSocket};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::context::{Counters, EndpointCtx, Queued, Target, TokenBucket};
use super::error::EndpointError;
use super::serial::open_serial;
use super::stream::run_connector;
use super::tcp::{connect_tcp, run_tcp_in};
use super::types::{EndpointId, EndpointStats, Inbound, Outbound, Route};
use super::udp::run_udp;
use super::url::EndpointSpec;
use crate::mavlink::tlog::{TlogConfig, TlogHandle};

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
        let mut tlog_error = None;
        let tlog = match &cfg.tlog {
            Some(tlog_cfg) => match TlogHandle::spawn(tlog_cfg) {
                Ok(tlog) => Some(tlog),
                Err(source) => {
                    let e = EndpointError::Tlog {
                        dir: tlog_cfg.dir.clone(),
                        source,
                    };
                    tracing::error!("{e}. RUNNING WITHOUT A TELEMETRY LOG");
                    tlog_error = Some(e.to_string());
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
                Opened::TcpOut(addr) => {
                    tokio::spawn(run_connector(task_ctx, queue_rx, shutdown, move || {
                        connect_tcp(addr)
                    }))
                }
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
                tlog_error,
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
    /// Why the telemetry log could not be opened (the router runs without).
    tlog_error: Option<String>,
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
            tlog.sender.record(Arc::clone(&out.bytes));
        }
        self.queue(out, true);
    }

    /// As [`RouterHandle::send`], but the frame is not written to the
    /// telemetry log: file contents sent to a station (log download, FTP)
    /// are copies of what is on the disk already.
    pub fn send_unlogged(&self, out: Outbound) {
        self.queue(out, false);
    }

    fn queue(&self, out: Outbound, log: bool) {
        let (slots, target) = match out.route {
            Route::All => (&self.inner.endpoints[..], Target::All),
            Route::Endpoint(e) => (self.slot(e), Target::All),
            Route::Peer(e, p) => (self.slot(e), Target::Peer(p)),
        };
        for slot in slots {
            let queued = Queued {
                target,
                bytes: Arc::clone(&out.bytes),
                log,
            };
            if let Err(mpsc::error::TrySendError::Full(_)) = slot.queue.try_send(queued) {
                slot.ctx
                    .send_error(1, "endpoint queue full: dropping outbound frames");
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

    /// The telemetry log files this run writes (None without a log).
    pub fn tlog_run(&self) -> Option<crate::mavlink::tlog::TlogRun> {
        self.inner.tlog.as_ref().map(|t| t.run.clone())
    }

    /// Why the telemetry log asked for could not be opened, if it could not.
    pub fn tlog_error(&self) -> Option<&str> {
        self.inner.tlog_error.as_deref()
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
