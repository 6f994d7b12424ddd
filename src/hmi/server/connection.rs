//! One accepted connection: the TLS handshake (or the answer to plain HTTP
//! on the TLS port), then HTTP/1.1 with upgrades, with the request
//! extensions handlers rely on.
//!
//! Owns the per-connection deadlines and the socket wrapper that keeps a
//! connection's slot until the socket is gone ([`Held`]). Runs in its own
//! task, never in the accept loop.

use std::net::SocketAddr;
use std::time::Duration;

use axum::Router;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::TcpStream;
use tokio::sync::watch;
use tower::ServiceExt as _;

use super::ConnInfo;
use super::slots::Slot;

/// A request head larger than this is refused (hyper's floor is 8 KiB); it
/// bounds what each connection can make the server buffer.
const MAX_BUF_BYTES: usize = 64 * 1024;

/// One connection: the TLS handshake if on (bounded by the header timeout),
/// then HTTP/1.1 with upgrades (WebSocket).
pub(super) async fn connection(
    stream: TcpStream,
    peer: SocketAddr,
    app: Router,
    tls: Option<tokio_rustls::TlsAcceptor>,
    header_timeout: Duration,
    mut stop: watch::Receiver<bool>,
    slot: Slot,
) {
    let local = stream.local_addr().ok();
    let Some(acceptor) = tls else {
        http(
            Held::new(stream, slot),
            peer,
            local,
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
        Ok(Ok(stream)) => http(stream, peer, local, true, app, header_timeout, stop).await,
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
    let host = redirect_host(&text);
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

/// The Host a plain-HTTP request head names, when it is a plain host name
/// (it goes into the redirect's `Location`); `None` otherwise.
pub(crate) fn redirect_host(head: &str) -> Option<&str> {
    head.lines()
        .skip(1)
        .find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.trim().eq_ignore_ascii_case("host").then(|| v.trim())
        })
        .filter(|h| crate::hmi::headers::plain_host(h))
}

/// The body of the answer to plain HTTP on the TLS port.
const HTTPS_ONLY: &str =
    "This vehicle's HMI is served over HTTPS: open https:// and the same address.\n";

async fn http<S>(
    stream: S,
    peer: SocketAddr,
    local: Option<SocketAddr>,
    tls: bool,
    app: Router,
    header_timeout: Duration,
    mut stop: watch::Receiver<bool>,
) where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let service = hyper::service::service_fn(move |mut req: hyper::Request<Incoming>| {
        req.extensions_mut().insert(ConnectInfo(peer));
        req.extensions_mut().insert(ConnInfo { tls, local });
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
