//! Ports beside the HMI's, where Cockpit looks for mavlink-camera-manager:
//! the WebRTC signalling (6021) and its REST port with `/streams` (6020),
//! served with the HMI's guard (Host and Origin; the page's own origin
//! there is the HMI's port), CORS for the origins it admits, security
//! headers and TLS.
//!
//! The routes are the camera's (`camera::webrtc`); this file only binds
//! and serves them. A port that cannot be bound is a warning, never a
//! failed start: `/webrtc` on the HMI's port still serves the viewers.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;

use tokio::net::TcpListener;
use tokio::task::JoinHandle;

use super::{Shared, cors, guard, headers, server};

/// What the HMI serves of the camera: its routes (`/video.mjpg` …, and
/// WebRTC's when it runs) and the camera manager's own ports.
pub struct VideoRoutes {
    pub routes: axum::Router,
    /// `/webrtc` and `/api/webrtc` are among `routes`.
    pub webrtc: bool,
    /// The signalling's own address and its routes; a port that cannot be
    /// bound is logged and left out.
    pub signalling: Option<(SocketAddr, axum::Router)>,
    /// mavlink-camera-manager's REST port (`/streams`) and its routes.
    pub streams: Option<(SocketAddr, axum::Router)>,
    /// What `GET /api/video` adds: the paths the video takes and why.
    pub info: Option<VideoInfo>,
}

/// Which of the camera manager's ports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BesideKind {
    Signalling,
    Streams,
}

/// The camera's own account of its video paths, as JSON, asked at each
/// `GET /api/video`.
pub type VideoInfo = Arc<dyn Fn() -> serde_json::Value + Send + Sync>;

/// A listener beside the HMI's and what it serves.
pub struct Beside {
    pub kind: BesideKind,
    pub listener: TcpListener,
    pub routes: axum::Router,
}

impl Beside {
    /// Binds `addr`; `None`, with the reason and the fix in the log, when
    /// it cannot.
    pub(super) async fn bind(
        kind: BesideKind,
        addr: SocketAddr,
        routes: axum::Router,
        tls: bool,
    ) -> Option<Beside> {
        match TcpListener::bind(addr).await {
            Ok(listener) => {
                let at = listener.local_addr().unwrap_or(addr);
                match kind {
                    BesideKind::Signalling => {
                        let scheme = if tls { "wss" } else { "ws" };
                        tracing::info!(addr = %at, "WebRTC signalling (mavlink-camera-manager's protocol) on {scheme}://{at}/");
                    }
                    BesideKind::Streams => {
                        let scheme = if tls { "https" } else { "http" };
                        tracing::info!(addr = %at, "the camera's streams (mavlink-camera-manager's REST) on {scheme}://{at}/streams");
                    }
                }
                Some(Beside {
                    kind,
                    listener,
                    routes,
                })
            }
            Err(e) => {
                match kind {
                    BesideKind::Signalling => tracing::warn!(
                        "cannot listen for WebRTC signalling on {addr}: {e} — viewers can still use /webrtc on the HMI's port; \
                         free the port (is mavlink-camera-manager running?) or set camera.webrtc.signalling (--webrtc-signalling)"
                    ),
                    BesideKind::Streams => tracing::warn!(
                        "cannot listen for the camera's streams on {addr}: {e} — Cockpit plays the video all the same but shows \
                         no source or resolution; free the port (is mavlink-camera-manager running?) or set camera.webrtc.streams"
                    ),
                }
                None
            }
        }
    }

    /// Serves the routes behind the guard until `stopped` resolves.
    pub(super) fn spawn(
        self,
        shared: &Arc<Shared>,
        page_port: u16,
        transport: server::Transport,
        stopped: impl Future<Output = ()> + Send + 'static,
    ) -> JoinHandle<std::io::Result<()>> {
        let app = cors::layer(self.routes, Arc::clone(shared), |_| true, Some(page_port));
        let app = guard::layer_beside(app, Arc::clone(shared), page_port)
            .layer(axum::middleware::from_fn(headers::security_headers));
        tokio::spawn(server::run(self.listener, app, transport, stopped))
    }
}
