//! The HMI's HTTP transport: its own accept loop (in place of `axum::serve`),
//! so that the browser side can never starve the rest of the vehicle of
//! file descriptors or time.
//!
//! Owns: accepting TCP connections, the connection caps (in total and per
//! client address), the header-read timeout (also on idle keep-alive
//! connections), the TLS handshake and its timeout, and the extensions every
//! request carries ([`ConnectInfo`]`<SocketAddr>` and [`ConnInfo`]).
//! Graceful shutdown waits a bounded time for open connections, then cuts
//! them.
//!
//! Must never: hold a descriptor for a connection over a cap (it is closed
//! at once), log per refused connection (one line per burst), spin on accept
//! errors (EMFILE backs off), or run a TLS handshake in the accept loop (one
//! slow client would stall every other).
//!
//! # Contract for handlers
//! Every request that reaches the router carries two extensions:
//! - `axum::extract::ConnectInfo<std::net::SocketAddr>`: the client's address
//!   (extract it as `ConnectInfo(addr): ConnectInfo<SocketAddr>`);
//! - [`ConnInfo`]: facts about the connection itself (`tls`: whether it came
//!   over TLS, e.g. to set a cookie's `Secure` flag).

use std::collections::HashMap;
use std::future::Future;
use std::net::{IpAddr, Ipv6Addr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tokio::task::JoinSet;
use tower::ServiceExt as _;

/// How long graceful shutdown waits for open connections before cutting
/// them (an MJPEG stream or a slow download never ends by itself).
const DRAIN: Duration = Duration::from_millis(400);
/// Pause after an accept error that is about the process, not the client
/// (EMFILE, ENFILE, ENOMEM, ENOBUFS): the condition lasts, retrying at once
/// would spin a core.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);
/// Refused connections are summed up in the log at most this often.
const REFUSAL_LOG_PERIOD: Duration = Duration::from_secs(10);
/// A request head larger than this is refused (hyper's floor is 8 KiB); it
/// bounds what each connection can make the server buffer.
const MAX_BUF_BYTES: usize = 64 * 1024;

/// Facts about the connection a request came on, inserted into every
/// request's extensions by the accept loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnInfo {
    /// The connection is TLS (`https://`, `wss://`): a cookie may be `Secure`.
    pub tls: bool,
}

/// Limits of the transport (`[hmi] max_connections`,
/// `max_connections_per_address`, `header_timeout_s`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Open connections in all (WebSockets included).
    pub max_connections: usize,
    /// Open connections from one client address (one IPv4 address, or one
    /// IPv6 /64, which a single host may own entirely).
    pub max_connections_per_address: usize,
    /// A client must finish its request headers (and its TLS handshake)
    /// within this; an idle keep-alive connection is closed after it too.
    pub header_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_connections: 128,
            max_connections_per_address: 32,
            header_timeout: Duration::from_secs(10),
        }
    }
}

/// How the HMI is served: limits, and TLS when on.
#[derive(Clone, Default)]
pub struct Transport {
    pub limits: Limits,
    /// `Some`: every connection is TLS (`https://`); `None`: plain HTTP.
    pub tls: Option<Arc<rustls::ServerConfig>>,
}

impl std::fmt::Debug for Transport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Transport")
            .field("limits", &self.limits)
            .field("tls", &self.tls.is_some())
            .finish()
    }
}

/// Serves `app` on `listener` until `shutdown` resolves, then stops
/// accepting, asks open connections to finish and cuts those still open
/// after a short drain. Accept errors are never fatal.
pub async fn run(
    listener: TcpListener,
    app: Router,
    transport: Transport,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let tls = transport.tls.map(tokio_rustls::TlsAcceptor::from);
    let limits = transport.limits;
    let slots = Slots::new(limits);
    let (stop_tx, stop_rx) = watch::channel(false);
    let mut conns = JoinSet::new();
    let mut refusals = Refusals::default();
    let mut accept_errors = Refusals::default();
    tokio::pin!(shutdown);
    loop {
        let (stream, peer) = tokio::select! {
            () = &mut shutdown => break,
            Some(_) = conns.join_next(), if !conns.is_empty() => continue,
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) if is_client_error(&e) => continue,
                Err(e) => {
                    accept_errors.note(|n| {
                        tracing::warn!(
                            "browser HMI cannot accept connections: {e} ({n} time(s) since the last report) — \
                             retrying every {ACCEPT_BACKOFF:?}; if it is EMFILE, the process is out of file descriptors"
                        );
                    });
                    tokio::select! {
                        () = &mut shutdown => break,
                        () = tokio::time::sleep(ACCEPT_BACKOFF) => continue,
                    }
                }
            },
        };
        let slot = match slots.take(peer.ip()) {
            Ok(slot) => slot,
            Err(full) => {
                // Closing at once: a connection over the cap holds no descriptor.
                drop(stream);
                refusals.note(|n| match full {
                    Full::Total => tracing::warn!(
                        "browser HMI at its cap of {} connections ([hmi] max_connections): new connections are closed \
                         ({n} refused since the last report; last from {peer})",
                        limits.max_connections
                    ),
                    Full::PerAddress => tracing::warn!(
                        "browser HMI: {} already has {} connections ([hmi] max_connections_per_address): its new \
                         connections are closed ({n} refused since the last report)",
                        peer.ip(),
                        limits.max_connections_per_address
                    ),
                });
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        conns.spawn(connection(
            stream,
            peer,
            app.clone(),
            tls.clone(),
            limits.header_timeout,
            stop_rx.clone(),
            slot,
        ));
    }
    // New connection attempts are refused by the kernel from here on.
    drop(listener);
    let _ = stop_tx.send(true);
    let drained =
        tokio::time::timeout(DRAIN, async { while conns.join_next().await.is_some() {} }).await;
    if drained.is_err() {
        tracing::debug!(
            "browser HMI: {} connection(s) still open after {DRAIN:?}, closed",
            conns.len()
        );
    }
    conns.shutdown().await;
    Ok(())
}

/// Errors of one incoming connection (it was reset before we took it), not
/// of the listener: try the next one at once.
fn is_client_error(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::*;
    matches!(
        e.kind(),
        ConnectionAborted | ConnectionReset | ConnectionRefused | Interrupted | WouldBlock
    ) || matches!(
        e.raw_os_error(),
        Some(libc_errno::EPROTO | libc_errno::EPERM)
    )
}

/// The two errnos not mapped to an `ErrorKind` that accept(2) reports for a
/// single connection (values from Linux; the check is only a fast path, any
/// other error backs off).
mod libc_errno {
    pub const EPERM: i32 = 1;
    pub const EPROTO: i32 = 71;
}

/// One connection: the TLS handshake if on (bounded by the header timeout),
/// then HTTP/1.1 with upgrades (WebSocket).
async fn connection(
    stream: TcpStream,
    peer: SocketAddr,
    app: Router,
    tls: Option<tokio_rustls::TlsAcceptor>,
    header_timeout: Duration,
    mut stop: watch::Receiver<bool>,
    slot: Slot,
) {
    let Some(acceptor) = tls else {
        http(
            Held::new(stream, slot),
            peer,
            false,
            app,
            header_timeout,
            stop,
        )
        .await;
        return;
    };
    // One budget for the first byte and the whole handshake.
    let deadline = tokio::time::Instant::now() + header_timeout;
    let mut first = [0u8; 1];
    let peeked = tokio::select! {
        r = tokio::time::timeout_at(deadline, stream.peek(&mut first)) => r,
        () = stopped(&mut stop) => return,
    };
    match peeked {
        // A TLS handshake starts with 0x16; an HTTP method with a capital.
        Ok(Ok(1..)) if first[0].is_ascii_uppercase() => {
            plain_http_on_tls_port(stream, peer, deadline).await;
            return;
        }
        Ok(Ok(1..)) => {}
        // Closed, failed or silent until the deadline.
        _ => return,
    }
    let handshake = tokio::select! {
        r = tokio::time::timeout_at(deadline, acceptor.accept(Held::new(stream, slot))) => r,
        () = stopped(&mut stop) => return,
    };
    match handshake {
        Ok(Ok(stream)) => http(stream, peer, true, app, header_timeout, stop).await,
        // A plain-HTTP request, a scanner or a browser that distrusts the
        // certificate: the client's business, not the vehicle's.
        Ok(Err(e)) => tracing::debug!("browser HMI: TLS handshake with {peer} failed: {e}"),
        Err(_) => tracing::debug!(
            "browser HMI: TLS handshake with {peer} not done within {header_timeout:?}, closed"
        ),
    }
}

/// Someone typed `http://` for a TLS-only HMI: send them to `https://` on
/// the same host (a 301 to the Host they gave, when it is a plain host
/// name), or say what to do, and close. The request is read (at most 8 KiB,
/// within the header deadline) so the reply is not lost to a reset.
async fn plain_http_on_tls_port(
    mut stream: TcpStream,
    peer: SocketAddr,
    deadline: tokio::time::Instant,
) {
    use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 1024];
    while head.len() < 8192 && !head.windows(4).any(|w| w == b"\r\n\r\n") {
        match tokio::time::timeout_at(deadline, stream.read(&mut buf)).await {
            Ok(Ok(n @ 1..)) => head.extend_from_slice(&buf[..n]),
            _ => return,
        }
    }
    let text = String::from_utf8_lossy(&head);
    let host = text
        .lines()
        .skip(1)
        .find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.trim().eq_ignore_ascii_case("host").then(|| v.trim())
        })
        .filter(|h| super::headers::plain_host(h));
    let reply = match host {
        Some(h) => format!(
            "HTTP/1.1 301 Moved Permanently\r\nLocation: https://{h}/\r\nContent-Type: text/plain; charset=utf-8\r\n\
             X-Content-Type-Options: nosniff\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{}",
            HTTPS_ONLY.len(),
            HTTPS_ONLY
        ),
        None => format!(
            "HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\n\
             X-Content-Type-Options: nosniff\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{}",
            HTTPS_ONLY.len(),
            HTTPS_ONLY
        ),
    };
    let _ = tokio::time::timeout_at(deadline, async {
        let _ = stream.write_all(reply.as_bytes()).await;
        let _ = stream.shutdown().await;
    })
    .await;
    tracing::debug!("browser HMI: plain HTTP from {peer} on the TLS port, sent to https://");
}

/// The body of the answer to plain HTTP on the TLS port.
const HTTPS_ONLY: &str =
    "This vehicle's HMI is served over HTTPS: open https:// and the same address.\n";

async fn http<S>(
    stream: S,
    peer: SocketAddr,
    tls: bool,
    app: Router,
    header_timeout: Duration,
    mut stop: watch::Receiver<bool>,
) where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let service = hyper::service::service_fn(move |mut req: hyper::Request<Incoming>| {
        req.extensions_mut().insert(ConnectInfo(peer));
        req.extensions_mut().insert(ConnInfo { tls });
        app.clone().oneshot(req)
    });
    let conn = http1::Builder::new()
        .timer(TokioTimer::new())
        .header_read_timeout(header_timeout)
        .max_buf_size(MAX_BUF_BYTES)
        .serve_connection(TokioIo::new(stream), service)
        .with_upgrades();
    tokio::pin!(conn);
    let result = tokio::select! {
        r = conn.as_mut() => r,
        () = stopped(&mut stop) => {
            conn.as_mut().graceful_shutdown();
            conn.await
        }
    };
    if let Err(e) = result {
        tracing::debug!("browser HMI: connection from {peer} ended: {e}");
    }
}

/// A connection's socket with its slot: the slot is given back when the
/// socket is dropped, not when the HTTP connection ends, because a WebSocket
/// upgrade hands the socket on to the session (hyper's `Upgraded` owns this
/// value) and a WebSocket must count against the caps like any connection.
struct Held<S> {
    io: S,
    _slot: Slot,
}

impl<S> Held<S> {
    fn new(io: S, slot: Slot) -> Self {
        Self { io, _slot: slot }
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Held<S> {
    fn poll_read(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Held<S> {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        std::pin::Pin::new(&mut self.io).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> std::task::Poll<std::io::Result<usize>> {
        std::pin::Pin::new(&mut self.io).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }

    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.io).poll_flush(cx)
    }

    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.io).poll_shutdown(cx)
    }
}

/// Resolves when the server is stopping (or gone).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    // The guard `wait_for` returns is not `Send`: dropped here, not held
    // across the connection's awaits.
    let _ = stop.wait_for(|s| *s).await.map(|_| ());
}

/// Why a connection was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Full {
    Total,
    PerAddress,
}

/// Open connections, in all and per client address.
#[derive(Clone)]
struct Slots {
    inner: Arc<Mutex<Counts>>,
    limits: Limits,
}

#[derive(Default)]
struct Counts {
    total: usize,
    per_address: HashMap<IpAddr, usize>,
}

/// One taken slot; given back when the connection's task ends (or is cut).
struct Slot {
    slots: Slots,
    key: IpAddr,
}

impl Slots {
    fn new(limits: Limits) -> Self {
        Self {
            inner: Arc::default(),
            limits,
        }
    }

    fn take(&self, ip: IpAddr) -> Result<Slot, Full> {
        let key = address_key(ip);
        let mut c = self.inner.lock().unwrap_or_else(|p| p.into_inner());
        if c.total >= self.limits.max_connections {
            return Err(Full::Total);
        }
        let mine = c.per_address.entry(key).or_insert(0);
        if *mine >= self.limits.max_connections_per_address {
            return Err(Full::PerAddress);
        }
        *mine += 1;
        c.total += 1;
        Ok(Slot {
            slots: self.clone(),
            key,
        })
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut c = self.slots.inner.lock().unwrap_or_else(|p| p.into_inner());
        c.total = c.total.saturating_sub(1);
        if let Some(n) = c.per_address.get_mut(&self.key) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                c.per_address.remove(&self.key);
            }
        }
    }
}

/// What counts as one client: an IPv4 address (IPv4-mapped IPv6 included),
/// or an IPv6 /64 (one host is routinely given a whole /64).
fn address_key(ip: IpAddr) -> IpAddr {
    match ip.to_canonical() {
        IpAddr::V4(v4) => IpAddr::V4(v4),
        IpAddr::V6(v6) => {
            let s = v6.segments();
            IpAddr::V6(Ipv6Addr::new(s[0], s[1], s[2], s[3], 0, 0, 0, 0))
        }
    }
}

/// Rate-limited reporting of a repeated condition: the first occurrence is
/// reported at once, then at most one line (with the count since the last)
/// per [`REFUSAL_LOG_PERIOD`]. Under attack, slots free up and are taken
/// again all the time, so there is no reliable "end of burst" to report.
#[derive(Default)]
struct Refusals {
    /// Occurrences since the last report.
    unreported: u64,
    last_report: Option<Instant>,
}

impl Refusals {
    fn note(&mut self, report: impl FnOnce(u64)) {
        self.unreported += 1;
        if self
            .last_report
            .is_none_or(|t| t.elapsed() >= REFUSAL_LOG_PERIOD)
        {
            report(self.unreported);
            self.unreported = 0;
            self.last_report = Some(Instant::now());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_hold_both_caps_and_come_back() {
        let slots = Slots::new(Limits {
            max_connections: 3,
            max_connections_per_address: 2,
            header_timeout: Duration::from_secs(1),
        });
        let a: IpAddr = "10.0.0.1".parse().expect("ip");
        let b: IpAddr = "10.0.0.2".parse().expect("ip");
        let c: IpAddr = "10.0.0.3".parse().expect("ip");
        let a1 = slots.take(a).expect("first");
        let _a2 = slots.take(a).expect("second");
        assert_eq!(slots.take(a).err(), Some(Full::PerAddress));
        let _b1 = slots.take(b).expect("b");
        assert_eq!(slots.take(c).err(), Some(Full::Total));
        drop(a1);
        let _c1 = slots.take(c).expect("a slot came back");
        assert_eq!(slots.take(a).err(), Some(Full::Total));
    }

    #[test]
    fn ipv4_mapped_and_ipv6_64_count_as_one_client() {
        let mapped: IpAddr = "::ffff:10.0.0.1".parse().expect("ip");
        assert_eq!(
            address_key(mapped),
            "10.0.0.1".parse::<IpAddr>().expect("ip")
        );
        let x: IpAddr = "2001:db8:1:2::1".parse().expect("ip");
        let y: IpAddr = "2001:db8:1:2:ffff::9".parse().expect("ip");
        let z: IpAddr = "2001:db8:1:3::1".parse().expect("ip");
        assert_eq!(address_key(x), address_key(y));
        assert_ne!(address_key(x), address_key(z));
    }

    /// The contract with handlers: both extensions are on every request.
    #[tokio::test]
    async fn handlers_get_the_client_address_and_conn_info() {
        use axum::extract::Extension;
        use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
        let app = Router::new().route(
            "/",
            axum::routing::get(
                |ConnectInfo(addr): ConnectInfo<SocketAddr>,
                 Extension(info): Extension<ConnInfo>| async move {
                    format!("{addr} tls={}", info.tls)
                },
            ),
        );
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let at = listener.local_addr().expect("addr");
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let server = tokio::spawn(run(listener, app, Transport::default(), async move {
            let _ = stopped.await;
        }));
        let mut s = TcpStream::connect(at).await.expect("connect");
        let me = s.local_addr().expect("local");
        s.write_all(b"GET / HTTP/1.0\r\n\r\n").await.expect("write");
        let mut reply = String::new();
        s.read_to_string(&mut reply).await.expect("read");
        assert!(reply.ends_with(&format!("{me} tls=false")), "{reply}");
        let _ = stop.send(());
        server.await.expect("join").expect("serve");
    }

    #[test]
    fn refusals_report_once_per_period() {
        let mut r = Refusals::default();
        let mut reports = Vec::new();
        for _ in 0..100 {
            r.note(|n| reports.push(n));
        }
        assert_eq!(
            reports,
            vec![1],
            "one line for a burst, not one per connection"
        );
        assert_eq!(r.unreported, 99, "the rest are counted for the next line");
    }
}
