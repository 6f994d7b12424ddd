//! Video over WebRTC for Cockpit and the browser page, from the one H.264
//! stream the RTP path sends: no encoder per viewer.
//!
//! While any viewer has a session, the RTP supervisor ([`super::rtp`])
//! hands the hub (`hub`) the pictures of the one stream as access units on
//! a channel, whatever route made them (the encoder's RTP is put back
//! together there, once for every consumer). Each picture is handed to
//! every viewer's peer connection
//! (`peer`, str0m's sans-IO WebRTC), which packetizes, encrypts and sends
//! it from the vehicle's own addresses (`net`; `stun` adds the public one
//! when STUN servers are configured).
//!
//! Viewers find the stream through mavlink-camera-manager's signalling
//! protocol (`protocol`, `signalling`), on a WebSocket at `/webrtc` on the
//! HMI's port and at `/` on a port of its own (6021, where Cockpit looks):
//! [`WebRtc::routes`] and [`WebRtc::signalling_routes`], served by the HMI
//! behind its Host and Origin rules (`ws`); and read its source, size and
//! rate from mavlink-camera-manager's `/streams` on the port beside it
//! (6020, [`WebRtc::streams_routes`]). A viewer is offered the vehicle's
//! address its signalling connection reached, where the vehicle knows it.
//!
//! This module must never run a second encoder, send to an address no
//! viewer's ICE checks came from, or panic on what a client or the network
//! sends.

pub mod config;
mod hub;
mod net;
pub mod peer;
pub mod protocol;
pub mod signalling;
pub mod streams;
pub(crate) mod stun;
mod ws;

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Instant;

use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

pub use config::{
    DEFAULT_MAX_VIEWERS, IceServer, IceServerError, MCM_REST_PORT, MCM_SIGNALLING_PORT,
    SignallingAddr, SignallingAddrError, WebRtcConfig, WebRtcConfigError,
};
pub use ws::PATH;

use super::config::{CameraConfig, SourceKind};
use super::plan::{H264Route, VideoPlan};
use protocol::Stream;

/// What the RTP supervisor needs: whether any viewer wants the pictures
/// now, and the hub's queue for them.
pub type WebRtcFeed = super::rtp::VideoTap;

/// The running WebRTC side. Dropping it (or [`shutdown`](WebRtc::shutdown))
/// ends every session.
#[derive(Debug)]
pub struct WebRtc {
    feed: WebRtcFeed,
    ctx: Arc<ws::Ctx>,
    task: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for ws::Ctx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WebRtcCtx")
            .field("stream", &self.stream)
            .finish()
    }
}

impl WebRtc {
    /// Starts the hub (the media sockets are bound on each of the
    /// vehicle's addresses).
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub fn start(cfg: &WebRtcConfig, stream: Option<Stream>) -> WebRtc {
        let (wanted_tx, wanted) = watch::channel(false);
        let (commands_tx, commands) = mpsc::channel(256);
        let (units_tx, units) = mpsc::channel(UNITS_QUEUE);
        let (inbound_tx, inbound) = mpsc::channel(1024);
        let mut sockets = net::Sockets::new(cfg.udp_port, inbound_tx);
        sockets.refresh();
        let stun_servers = cfg
            .ice_servers
            .iter()
            .filter(|s| s.is_stun())
            .filter_map(|s| s.parts().ok().map(|(_, h, p)| (h, p)))
            .collect();
        let hub = hub::Hub {
            commands,
            units,
            wanted: wanted_tx,
            max_viewers: cfg.max_viewers,
            sockets,
            inbound,
            reflexive: stun::Reflexive::new(stun_servers, Instant::now()),
        };
        tracing::info!(
            stream = stream.as_ref().map(|s| s.id.as_str()),
            "WebRTC ready"
        );
        let task = tokio::spawn(hub.run());
        let ctx = Arc::new(ws::Ctx::new(commands_tx, stream, cfg.ice_servers.clone()));
        WebRtc {
            feed: WebRtcFeed {
                units: units_tx,
                wanted,
            },
            ctx,
            task: Some(task),
        }
    }

    pub fn feed(&self) -> WebRtcFeed {
        self.feed.clone()
    }

    /// `/webrtc` (the signalling WebSocket) and `GET /api/webrtc`: merge
    /// into the HMI's router.
    pub fn routes(&self) -> axum::Router {
        ws::routes(Arc::clone(&self.ctx))
    }

    /// The signalling WebSocket at `/`, for the dedicated port.
    pub fn signalling_routes(&self) -> axum::Router {
        ws::signalling_routes(Arc::clone(&self.ctx))
    }

    /// mavlink-camera-manager's `GET /streams`, for its REST port: the
    /// stream, with the encoder's state and the RTP stream's shape.
    pub fn streams_routes(
        &self,
        rtp: watch::Receiver<Option<crate::camera::rtp::RtpStream>>,
        sender: watch::Receiver<Option<crate::camera::rtp::Running>>,
    ) -> axum::Router {
        streams::routes(streams::StreamsState {
            stream: self.ctx.stream.clone(),
            rtp,
            sender,
        })
    }

    /// Where the dedicated ports listen (for `GET /api/webrtc`).
    pub fn set_beside_addrs(&self, signalling: Option<SocketAddr>, streams: Option<SocketAddr>) {
        if let Ok(mut a) = self.ctx.signalling.lock() {
            *a = signalling;
        }
        if let Ok(mut a) = self.ctx.streams.lock() {
            *a = streams;
        }
    }

    pub async fn shutdown(mut self) {
        if let Some(t) = self.task.take() {
            t.abort();
            let _ = t.await;
        }
    }
}

impl Drop for WebRtc {
    fn drop(&mut self) {
        if let Some(t) = self.task.take() {
            t.abort();
        }
    }
}

/// Pictures queued for the hub; a sender that finds it full skips to the
/// next keyframe.
const UNITS_QUEUE: usize = 16;

/// The camera as `availableStreams` lists it: one H.264 stream with its
/// size and rate (the camera's as chosen, or the encode's as configured;
/// unknown ones are `null`), or none when the plan gives no H.264. `id` is
/// the stream's id for this run.
pub fn stream_of(cfg: &CameraConfig, plan: &VideoPlan, id: String) -> Option<Stream> {
    let h = &cfg.h264;
    let passthrough = plan.h264 == H264Route::FfmpegCopy;
    if plan.h264 == H264Route::None {
        return None;
    }
    let camera = plan
        .capture
        .as_ref()
        .filter(|_| matches!(plan.h264, H264Route::Camera | H264Route::Pending));
    let (w, hgt, fps) = if let Some(c) = camera {
        (c.width, c.height, c.fps())
    } else if passthrough {
        h.passthrough_shape()
    } else if h.width > 0 {
        (h.width, h.height, if h.fps > 0.0 { h.fps } else { cfg.fps })
    } else if cfg.source == SourceKind::Synthetic {
        (
            cfg.width,
            cfg.height,
            if h.fps > 0.0 { h.fps } else { cfg.fps },
        )
    } else {
        (0, 0, if h.fps > 0.0 { h.fps } else { cfg.fps })
    };
    let known = |v: u32| (v > 0).then_some(v);
    Some(Stream {
        id,
        name: "Neptunus camera".into(),
        encode: Some("H264".into()),
        height: known(hgt),
        width: known(w),
        interval: (fps > 0.0).then(|| format!("1/{}", fps.round() as u32)),
        source: Some(match plan.h264 {
            H264Route::FfmpegCopy => "h264-passthrough".to_owned(),
            H264Route::Camera | H264Route::Pending => "camera-h264".to_owned(),
            _ => cfg.source.as_str().to_owned(),
        }),
        created: None,
    })
}

/// A new stream id (a random UUID, as mavlink-camera-manager's).
pub fn new_stream_id() -> String {
    ws::uuid()
}
