//! Reading an MJPEG stream over HTTP/1.1 (the `url` source, and the
//! `mjpg-streamer` source's own loopback stream).
//!
//! hyper does the HTTP (chunked bodies included); the body's bytes go
//! through the [`JpegSplitter`], for which the multipart boundaries and part
//! headers are bytes between frames. That keeps working with servers that
//! leave out or misstate a part's Content-Length.

use std::time::Duration;

use axum::http::{Request, StatusCode, header};
use bytes::Bytes;
use http_body_util::{BodyExt, Empty};
use hyper::body::Incoming;
use hyper::client::conn::http1::SendRequest;
use hyper_util::rt::TokioIo;
use tokio::net::TcpStream;
use tokio::task::JoinHandle;
use tokio::time::{Instant, sleep, sleep_until, timeout};

use super::config::{SourceKind, StreamUrl};
use super::error::SourceError;
use super::publisher::Publisher;
use super::splitter::JpegSplitter;

/// Reads `url` until the stream ends, fails or stalls, publishing every
/// frame. `connect_for`: keep retrying a refused connection this long (a
/// server that is still starting).
pub(crate) async fn read_stream(
    url: &StreamUrl,
    stall: Duration,
    connect_for: Option<Duration>,
    out: &mut Publisher,
) -> SourceError {
    let kind = out.kind();
    let (mut body, _conn) = match open(url, stall, connect_for, kind).await {
        Ok(b) => b,
        Err(e) => return e,
    };
    let mut splitter = JpegSplitter::new();
    let mut deadline = Instant::now() + stall;
    loop {
        let frame = tokio::select! {
            f = body.frame() => f,
            () = sleep_until(deadline) => {
                return SourceError::Stalled {
                    kind,
                    what: url.text.clone(),
                    secs: stall.as_secs_f64(),
                };
            }
        };
        match frame {
            None => {
                return SourceError::StreamEnded {
                    kind,
                    url: url.text.clone(),
                    detail: String::new(),
                };
            }
            Some(Err(e)) => {
                return SourceError::StreamEnded {
                    kind,
                    url: url.text.clone(),
                    detail: format!(": {e}"),
                };
            }
            Some(Ok(f)) => {
                if let Ok(data) = f.into_data() {
                    splitter.push(&data);
                    while let Some(j) = splitter.next_frame() {
                        out.publish(j.jpeg, j.width, j.height);
                        deadline = Instant::now() + stall;
                    }
                }
            }
        }
    }
}

/// The `url` source's run.
pub(crate) async fn run_url(url: &StreamUrl, stall: Duration, out: &mut Publisher) -> SourceError {
    read_stream(url, stall, None, out).await
}

/// hyper's connection task and the request handle, kept for as long as the
/// body is read; the task is aborted when the stream is dropped.
struct ConnTask {
    task: JoinHandle<()>,
    _sender: SendRequest<Empty<Bytes>>,
}

impl Drop for ConnTask {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn open(
    url: &StreamUrl,
    stall: Duration,
    connect_for: Option<Duration>,
    kind: SourceKind,
) -> Result<(Incoming, ConnTask), SourceError> {
    let connect_err = |error: String| SourceError::Connect {
        kind,
        url: url.text.clone(),
        error,
    };
    let give_up = Instant::now() + connect_for.unwrap_or_default();
    let tcp = loop {
        match timeout(stall, TcpStream::connect((url.host.as_str(), url.port))).await {
            Ok(Ok(s)) => break s,
            Ok(Err(e))
                if e.kind() == std::io::ErrorKind::ConnectionRefused
                    && Instant::now() < give_up =>
            {
                sleep(Duration::from_millis(100)).await;
            }
            Ok(Err(e)) => return Err(connect_err(e.to_string())),
            Err(_) => {
                return Err(connect_err(format!(
                    "no answer within {:.1} s",
                    stall.as_secs_f64()
                )));
            }
        }
    };
    let _ = tcp.set_nodelay(true);
    let (mut sender, conn) = hyper::client::conn::http1::handshake(TokioIo::new(tcp))
        .await
        .map_err(|e| connect_err(e.to_string()))?;
    let task = tokio::spawn(async move {
        if let Err(e) = conn.await {
            tracing::debug!("camera stream connection: {e}");
        }
    });
    let req = Request::get(url.path_and_query.as_str())
        .header(header::HOST, url.authority.as_str())
        .header(header::USER_AGENT, "neptunus-camera")
        .header(header::ACCEPT, "multipart/x-mixed-replace, */*")
        .body(Empty::<Bytes>::new())
        .map_err(|e| connect_err(e.to_string()))?;
    let resp = match timeout(stall, sender.send_request(req)).await {
        Ok(Ok(r)) => r,
        Ok(Err(e)) => return Err(connect_err(e.to_string())),
        Err(_) => {
            return Err(connect_err(format!(
                "no response within {:.1} s",
                stall.as_secs_f64()
            )));
        }
    };
    if resp.status() != StatusCode::OK {
        return Err(SourceError::HttpStatus {
            kind,
            url: url.text.clone(),
            status: resp.status().to_string(),
        });
    }
    let content_type = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .map(|v| String::from_utf8_lossy(v.as_bytes()).into_owned())
        .unwrap_or_default();
    if !content_type
        .to_ascii_lowercase()
        .starts_with("multipart/x-mixed-replace")
    {
        return Err(SourceError::NotMjpeg {
            kind,
            url: url.text.clone(),
            content_type,
        });
    }
    Ok((
        resp.into_body(),
        ConnTask {
            task,
            _sender: sender,
        },
    ))
}
