//! The HMI's HTTP transport: its own accept loop (in place of `axum::serve`),
//! so that the browser side can never starve the rest of the vehicle of
//! file descriptors or time.
//!
//! Owns: accepting TCP connections, the connection caps (in total and per
//! client address), the header-read timeout (also on idle keep-alive
//! connections), the TLS handshake and its timeout, and the extensions every
//! request carries ([`ConnectInfo`](axum::extract::ConnectInfo)`<SocketAddr>` and [`ConnInfo`]).
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
//!   over TLS, e.g. to set a cookie's `Secure` flag; `local`: the vehicle's
//!   address the client reached).
//!
//! This file holds the accept loop and the public types; `connection` serves
//! one connection, `slots` keeps the caps.

pub(crate) mod connection;
mod slots;

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinSet;

use connection::connection;
use slots::{Full, Refusals, Slots};

/// How long graceful shutdown waits for open connections before cutting
/// them (an MJPEG stream or a slow download never ends by itself).
const DRAIN: Duration = Duration::from_millis(400);
/// Pause after an accept error that is about the process, not the client
/// (EMFILE, ENFILE, ENOMEM, ENOBUFS): the condition lasts, retrying at once
/// would spin a core.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// Facts about the connection a request came on, inserted into every
/// request's extensions by the accept loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConnInfo {
    /// The connection is TLS (`https://`, `wss://`): a cookie may be `Secure`.
    pub tls: bool,
    /// The vehicle's address the client reached (the accepted socket's
    /// local address): where a WebRTC viewer can reach the vehicle.
    pub local: Option<std::net::SocketAddr>,
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

#[cfg(test)]
mod tests {
    use std::net::SocketAddr;

    use axum::extract::ConnectInfo;
    use tokio::net::TcpStream;

    use super::*;

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
                    format!("{addr} tls={} local={:?}", info.tls, info.local)
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
        assert!(
            reply.ends_with(&format!("{me} tls=false local=Some({at})")),
            "{reply}"
        );
        let _ = stop.send(());
        server.await.expect("join").expect("serve");
    }
}
