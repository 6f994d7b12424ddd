//! How the page's files travel, against the real binary (`neptunus --sim
//! --http 127.0.0.1:0`): compressed (brotli or gzip, as `Accept-Encoding`
//! asks) and decompressing to the very bytes served uncompressed; cached
//! with an ETag, so a reload costs a 304 per file; the security headers on
//! every one of those answers; and the camera's MJPEG stream and the
//! WebSocket left alone (never compressed, still streaming).
//!
//! Every wait is for a condition with a generous deadline; nothing sleeps to
//! let time pass.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::io::{Read as _, Write as _};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::time::{Duration, Instant};

use common::Vehicle;
use futures_util::StreamExt as _;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::http::HeaderValue;

const GENEROUS: Duration = Duration::from_secs(20);
/// What Chromium sends with every request.
const BROWSER_ENCODINGS: &str = "gzip, deflate, br, zstd";

fn sim(dir: &Path) -> (Vehicle, SocketAddr) {
    let bin = Path::new(env!("CARGO_BIN_EXE_neptunus"));
    let mut v = Vehicle::spawn(bin, &["--sim", "--mavlink", "udpin:127.0.0.1:0"], dir, "").unwrap();
    let http = v.http_addr(GENEROUS).unwrap();
    (v, http)
}

struct Reply {
    status: u16,
    head: String,
    body: Vec<u8>,
}

impl Reply {
    fn header(&self, name: &str) -> Option<String> {
        self.head.lines().skip(1).find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.trim()
                .eq_ignore_ascii_case(name)
                .then(|| v.trim().to_owned())
        })
    }
}

/// `GET path` over HTTP/1.0 (the server closes after the reply) with the
/// extra request header lines `extra` (each ending in `\r\n`).
fn get(addr: SocketAddr, path: &str, extra: &str) -> Reply {
    let head = format!("GET {path} HTTP/1.0\r\nHost: {addr}\r\n{extra}\r\n");
    send(addr, head.as_bytes())
}

/// Sends `request` as it is and reads the reply until the server closes.
fn send(addr: SocketAddr, request: &[u8]) -> Reply {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(GENEROUS)).unwrap();
    s.write_all(request).unwrap();
    let mut bytes = Vec::new();
    s.read_to_end(&mut bytes).unwrap();
    let split = bytes
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or(bytes.len());
    let head = String::from_utf8_lossy(&bytes[..split]).into_owned();
    let body = bytes.get(split + 4..).unwrap_or_default().to_vec();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    Reply { status, head, body }
}

fn gunzip(b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(b)
        .read_to_end(&mut out)
        .unwrap();
    out
}

fn unbrotli(b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    brotli_decompressor::Decompressor::new(b, 4096)
        .read_to_end(&mut out)
        .unwrap();
    out
}

fn assert_security_headers(r: &Reply, what: &str) {
    let csp = r
        .header("content-security-policy")
        .unwrap_or_else(|| panic!("no Content-Security-Policy on {what}:\n{}", r.head));
    assert!(csp.contains("frame-ancestors 'none'"), "{what}: {csp}");
    assert_eq!(
        r.header("x-frame-options").as_deref(),
        Some("DENY"),
        "{what}"
    );
    assert_eq!(
        r.header("x-content-type-options").as_deref(),
        Some("nosniff"),
        "{what}"
    );
    assert_eq!(
        r.header("referrer-policy").as_deref(),
        Some("no-referrer"),
        "{what}"
    );
}

/// The files of the operator page, and the plotting library.
const FILES: [&str; 5] = [
    "/",
    "/js/main.js",
    "/css/style.css",
    "/vendor/uPlot.esm.js",
    "/vendor/uPlot.min.css",
];

#[test]
fn assets_are_compressed_as_asked_and_decompress_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let (_vehicle, http) = sim(dir.path());
    for path in FILES {
        let plain = get(http, path, "");
        assert_eq!(plain.status, 200, "{path}:\n{}", plain.head);
        assert_eq!(
            plain.header("content-encoding"),
            None,
            "{path}: {}",
            plain.head
        );
        assert!(
            plain.body.len() > 1000,
            "{path}: {} bytes",
            plain.body.len()
        );

        let br = get(
            http,
            path,
            &format!("Accept-Encoding: {BROWSER_ENCODINGS}\r\n"),
        );
        assert_eq!(br.status, 200, "{path}:\n{}", br.head);
        assert_eq!(
            br.header("content-encoding").as_deref(),
            Some("br"),
            "{path}:\n{}",
            br.head
        );
        assert!(
            br.header("vary")
                .is_some_and(|v| v.to_lowercase().contains("accept-encoding")),
            "{path}: a cache must keep encodings apart:\n{}",
            br.head
        );
        assert_eq!(
            br.header("content-type"),
            plain.header("content-type"),
            "{path}"
        );
        assert_security_headers(&br, path);
        assert_eq!(unbrotli(&br.body), plain.body, "{path}: brotli body");
        assert!(
            br.body.len() * 2 < plain.body.len(),
            "{path}: brotli {} of {} bytes",
            br.body.len(),
            plain.body.len()
        );

        let gz = get(http, path, "Accept-Encoding: gzip\r\n");
        assert_eq!(
            gz.header("content-encoding").as_deref(),
            Some("gzip"),
            "{path}:\n{}",
            gz.head
        );
        assert_eq!(gunzip(&gz.body), plain.body, "{path}: gzip body");
        assert!(gz.body.len() < plain.body.len(), "{path}");
    }
}

#[test]
fn an_etag_round_trip_costs_a_304_with_no_body() {
    let dir = tempfile::tempdir().unwrap();
    let (_vehicle, http) = sim(dir.path());
    for path in FILES {
        let first = get(
            http,
            path,
            &format!("Accept-Encoding: {BROWSER_ENCODINGS}\r\n"),
        );
        assert_eq!(first.status, 200, "{path}");
        let etag = first
            .header("etag")
            .unwrap_or_else(|| panic!("no ETag on {path}:\n{}", first.head));
        // Revalidated at every load: a new vehicle version is picked up at once.
        let cache = first.header("cache-control").unwrap_or_default();
        assert!(cache.contains("no-cache"), "{path}: {cache}");
        // The same tag whatever the encoding: it names the file's content.
        assert_eq!(
            get(http, path, "").header("etag").as_deref(),
            Some(etag.as_str()),
            "{path}"
        );

        let again = get(
            http,
            path,
            &format!("Accept-Encoding: {BROWSER_ENCODINGS}\r\nIf-None-Match: {etag}\r\n"),
        );
        assert_eq!(again.status, 304, "{path}:\n{}", again.head);
        assert!(
            again.body.is_empty(),
            "{path}: {} body bytes",
            again.body.len()
        );
        assert_eq!(
            again.header("etag").as_deref(),
            Some(etag.as_str()),
            "{path}"
        );
        assert_eq!(again.header("content-encoding"), None, "{path}");
        assert_security_headers(&again, path);

        // A list with the tag in it, and `*`, match too; another tag does not.
        let list = get(http, path, &format!("If-None-Match: \"x\", {etag}\r\n"));
        assert_eq!(list.status, 304, "{path}");
        assert_eq!(
            get(http, path, "If-None-Match: *\r\n").status,
            304,
            "{path}"
        );
        let stale = get(http, path, "If-None-Match: W/\"0123\"\r\n");
        assert_eq!(stale.status, 200, "{path}");
        assert!(!stale.body.is_empty(), "{path}");
    }
    // Different files, different tags.
    let a = get(http, "/js/main.js", "").header("etag");
    let b = get(http, "/css/style.css", "").header("etag");
    assert_ne!(a, b);
    // Garbage in If-None-Match (bytes that are not text, a torn tag) is a
    // miss, never an error.
    let mut req =
        format!("GET /js/main.js HTTP/1.0\r\nHost: {http}\r\nIf-None-Match: W/\"").into_bytes();
    req.extend_from_slice(b"\xff\xfe\r\n\r\n");
    assert_eq!(send(http, &req).status, 200);
    assert_eq!(
        get(http, "/js/main.js", "If-None-Match: W/\r\n").status,
        200
    );
}

/// Reads from `/video.mjpg` until two frames' boundaries went by.
#[test]
fn the_mjpeg_stream_is_never_compressed_and_still_streams() {
    let dir = tempfile::tempdir().unwrap();
    let (mut vehicle, http) = sim(dir.path());
    // The synthetic camera of --sim runs while someone watches: the stream
    // below starts it. Wait for the server.
    let end = Instant::now() + GENEROUS;
    while get(http, "/camera/status", "").status != 200 {
        vehicle.check_running().unwrap();
        assert!(Instant::now() < end, "no camera status within {GENEROUS:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut s = TcpStream::connect(http).unwrap();
    s.set_read_timeout(Some(GENEROUS)).unwrap();
    write!(
        s,
        "GET /video.mjpg HTTP/1.1\r\nHost: {http}\r\nAccept-Encoding: {BROWSER_ENCODINGS}\r\n\r\n"
    )
    .unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 16384];
    let boundary = b"--neptunusframe";
    let end = Instant::now() + GENEROUS;
    while got
        .windows(boundary.len())
        .filter(|w| w == boundary)
        .count()
        < 2
    {
        assert!(Instant::now() < end, "two frames within {GENEROUS:?}");
        let n = s.read(&mut buf).unwrap();
        assert!(n > 0, "the stream ended");
        got.extend_from_slice(&buf[..n]);
    }
    let split = got.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&got[..split]).to_lowercase();
    assert!(head.starts_with("http/1.1 200"), "{head}");
    assert!(
        head.contains("content-type: multipart/x-mixed-replace"),
        "{head}"
    );
    assert!(
        !head.contains("content-encoding"),
        "the stream was compressed:\n{head}"
    );
    // A JPEG (start-of-image marker) is in the stream as sent.
    assert!(
        got.windows(2).any(|w| w == [0xFF, 0xD8]),
        "no JPEG in the stream"
    );
    // The snapshot is an image: never compressed either.
    let snap = get(
        http,
        "/snapshot.jpg",
        &format!("Accept-Encoding: {BROWSER_ENCODINGS}\r\n"),
    );
    assert_eq!(snap.header("content-encoding"), None, "{}", snap.head);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_websocket_upgrade_is_untouched_when_the_browser_accepts_compression() {
    let dir = tempfile::tempdir().unwrap();
    let (_vehicle, http) = sim(dir.path());
    let mut req = format!("ws://{http}/ws").into_client_request().unwrap();
    req.headers_mut().insert(
        "accept-encoding",
        HeaderValue::from_static(BROWSER_ENCODINGS),
    );
    let (mut ws, resp) = tokio_tungstenite::connect_async(req).await.unwrap();
    assert_eq!(resp.status(), 101);
    assert!(resp.headers().get("content-encoding").is_none(), "{resp:?}");
    let welcome = tokio::time::timeout(GENEROUS, async {
        while let Some(m) = ws.next().await {
            if let Ok(Message::Text(t)) = m
                && t.contains("\"welcome\"")
            {
                return Some(t);
            }
        }
        None
    })
    .await
    .unwrap();
    assert!(welcome.is_some(), "no welcome over the WebSocket");
}
