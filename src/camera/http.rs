//! `GET /video.mjpg`, `GET /snapshot.jpg` and `GET /camera/status`.
//!
//! Each viewer's stream waits on the frame `watch` channel and sends the
//! newest frame whenever the connection can take one: a slow viewer skips
//! frames, nothing queues up, and a viewer that goes away just drops its
//! stream.

use std::sync::Arc;

use axum::Json;
use axum::Router;
use axum::body::Body;
use axum::extract::State;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use bytes::Bytes;
use futures_util::Stream;
use serde_json::json;
use tokio::sync::watch;
use tokio::time::Instant;

use super::config::SourceKind;
use super::frame::Frame;
use super::shared::{CameraState, DemandGuard, Shared};

/// The multipart boundary of `/video.mjpg`.
pub const BOUNDARY: &str = "neptunusframe";

#[derive(Clone)]
struct CameraRoutes {
    shared: Arc<Shared>,
    frames: watch::Receiver<Option<Frame>>,
}

pub(crate) fn routes(shared: Arc<Shared>, frames: watch::Receiver<Option<Frame>>) -> Router {
    Router::new()
        .route("/video.mjpg", get(video))
        .route("/snapshot.jpg", get(snapshot))
        .route("/camera/status", get(status))
        .with_state(CameraRoutes { shared, frames })
}

async fn status(State(c): State<CameraRoutes>) -> Response {
    let mut r = Json(c.shared.status(Instant::now())).into_response();
    no_store(&mut r);
    r
}

async fn snapshot(State(c): State<CameraRoutes>) -> Response {
    if let Some(r) = unavailable(&c) {
        return r;
    }
    let frame = c.frames.borrow().clone();
    match frame {
        Some(f) => {
            let mut r = (
                [(header::CONTENT_TYPE, HeaderValue::from_static("image/jpeg"))],
                f.jpeg,
            )
                .into_response();
            no_store(&mut r);
            if let Ok(v) = HeaderValue::from_str(&f.seq.to_string()) {
                r.headers_mut().insert("x-frame-seq", v);
            }
            r
        }
        None => no_frame_yet(&c),
    }
}

async fn video(State(c): State<CameraRoutes>) -> Response {
    if let Some(r) = unavailable(&c) {
        return r;
    }
    let mut r = Response::new(Body::from_stream(mjpeg_stream(
        c.frames.clone(),
        c.shared.clone(),
    )));
    let ct = format!("multipart/x-mixed-replace; boundary={BOUNDARY}");
    if let Ok(v) = HeaderValue::from_str(&ct) {
        r.headers_mut().insert(header::CONTENT_TYPE, v);
    }
    no_store(&mut r);
    r
}

/// 503 when there is no camera or it cannot run at all.
fn unavailable(c: &CameraRoutes) -> Option<Response> {
    let status = c.shared.status(Instant::now());
    let reason = match (c.shared.source(), status.state) {
        (SourceKind::None, _) => {
            "no camera: camera.source is \"none\" — set it to \"synthetic\", \"ffmpeg\", \"mjpg-streamer\" or \"url\" to get video".to_owned()
        }
        (_, CameraState::Failed) => format!(
            "the camera is not running: {}",
            status.last_error.as_deref().unwrap_or("invalid configuration")
        ),
        (_, CameraState::Stopped) => "the camera was shut down".to_owned(),
        _ => {
            // A camera that streams H.264 gives no JPEG pictures.
            let plan = c.shared.plan();
            let plan = plan.borrow();
            if plan.jpeg != crate::camera::plan::JpegRoute::None {
                return None;
            }
            format!("no JPEG pictures: {}", plan.why)
        }
    };
    Some(error_response(&status.source, status.state, &reason))
}

fn no_frame_yet(c: &CameraRoutes) -> Response {
    let s = c.shared.status(Instant::now());
    let reason = match &s.last_error {
        Some(e) => format!(
            "no frame yet from camera source {} ({:?}): {e}",
            s.source, s.state
        ),
        None => format!(
            "no frame yet from camera source {} ({:?})",
            s.source, s.state
        ),
    };
    error_response(&s.source, s.state, &reason)
}

fn error_response(source: &SourceKind, state: CameraState, reason: &str) -> Response {
    let mut r = (
        StatusCode::SERVICE_UNAVAILABLE,
        Json(json!({ "error": reason, "source": source, "state": state })),
    )
        .into_response();
    no_store(&mut r);
    r
}

fn no_store(r: &mut Response) {
    r.headers_mut().insert(
        header::CACHE_CONTROL,
        HeaderValue::from_static("no-cache, no-store, must-revalidate"),
    );
}

/// Counts a viewer for as long as its stream exists; a viewer wants
/// frames (a camera started on demand runs for it).
struct Viewer(
    Arc<Shared>,
    #[allow(dead_code, reason = "held for its Drop")] DemandGuard,
);

impl Viewer {
    fn new(shared: Arc<Shared>) -> Self {
        shared.lock().viewers += 1;
        let demand = DemandGuard::new(&shared);
        Viewer(shared, demand)
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        let mut s = self.0.lock();
        s.viewers = s.viewers.saturating_sub(1);
    }
}

/// The body of `/video.mjpg`: for each frame, a part header chunk and the
/// JPEG itself (shared, not copied). Starts with the frame at hand, if any;
/// ends when the camera stops.
pub(crate) fn mjpeg_stream(
    mut frames: watch::Receiver<Option<Frame>>,
    shared: Arc<Shared>,
) -> impl Stream<Item = Result<Bytes, std::convert::Infallible>> + Send + 'static {
    frames.mark_changed();
    struct St {
        frames: watch::Receiver<Option<Frame>>,
        pending: Option<Bytes>,
        first: bool,
        _viewer: Viewer,
    }
    let st = St {
        frames,
        pending: None,
        first: true,
        _viewer: Viewer::new(shared),
    };
    futures_util::stream::unfold(st, |mut st| async move {
        if let Some(jpeg) = st.pending.take() {
            return Some((Ok(jpeg), st));
        }
        loop {
            if st.frames.changed().await.is_err() {
                return None;
            }
            let frame = st.frames.borrow_and_update().clone();
            if let Some(f) = frame {
                let head = part_header(st.first, f.jpeg.len());
                st.first = false;
                st.pending = Some(f.jpeg);
                return Some((Ok(head), st));
            }
        }
    })
}

fn part_header(first: bool, len: usize) -> Bytes {
    // A part's CRLF before the boundary belongs to the delimiter, so parts
    // after the first start with it.
    let lead = if first { "" } else { "\r\n" };
    Bytes::from(format!(
        "{lead}--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len}\r\n\r\n"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::config::CameraConfig;
    use futures_util::StreamExt;

    fn frame(seq: u64) -> Frame {
        Frame {
            jpeg: Bytes::from(vec![seq as u8; 10 + seq as usize]),
            at: Instant::now(),
            seq,
            width: 1,
            height: 1,
        }
    }

    #[tokio::test]
    async fn a_slow_viewer_gets_the_newest_frame_not_a_backlog() {
        let cfg = CameraConfig::synthetic();
        let shared = Arc::new(Shared::new(&cfg, crate::camera::plan::initial(&cfg)));
        let (tx, rx) = watch::channel(None);
        let mut stream = Box::pin(mjpeg_stream(rx, shared.clone()));
        assert_eq!(shared.lock().viewers, 1);
        for seq in 1..=100 {
            tx.send_replace(Some(frame(seq)));
        }
        let head = stream.next().await.expect("head").expect("ok");
        let head = String::from_utf8(head.to_vec()).expect("text");
        assert!(head.starts_with("--neptunusframe\r\n"), "{head}");
        assert!(head.contains("Content-Type: image/jpeg\r\n"), "{head}");
        assert!(head.ends_with("Content-Length: 110\r\n\r\n"), "{head}");
        let body = stream.next().await.expect("body").expect("ok");
        assert_eq!(body, frame(100).jpeg);

        tx.send_replace(Some(frame(101)));
        let head = stream.next().await.expect("head").expect("ok");
        assert!(head.starts_with(b"\r\n--neptunusframe\r\n"));
        let body = stream.next().await.expect("body").expect("ok");
        assert_eq!(body, frame(101).jpeg);

        // The camera stops: the stream ends, and the viewer is no longer counted.
        drop(tx);
        assert!(stream.next().await.is_none());
        drop(stream);
        assert_eq!(shared.lock().viewers, 0);
    }
}
