//! The HMI's HTTP transport from the attacker's side, against the real
//! binary (`neptunus --sim --http 127.0.0.1:0`): half-open connection
//! floods under a low open-file limit, the header-read timeout, the
//! connection caps, security headers and 404 bodies, and TLS (self-signed
//! certificate, fingerprint, WebSocket over TLS, plain HTTP to the TLS port).
//!
//! Every wait is for a condition with a generous deadline; nothing sleeps
//! to let time pass. The tests run one at a time (a lock): each starts a
//! simulator, and the flood test counts telemetry.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::io::{Read as _, Write as _};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use common::{Gcs, Traffic, Vehicle};
use futures_util::{SinkExt as _, StreamExt as _};
use neptunus::dialect::neptunus::*;
use neptunus::mavlink::frame::FrameDecoder;
use serde_json::Value;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};

const GENEROUS: Duration = Duration::from_secs(20);

/// One neptunus with a simulator at a time: the flood test counts telemetry
/// on a 2-core machine.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner())
}

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

/// Writes `[hmi]\n{hmi_toml}` to `DIR/neptunus.toml`.
fn config(dir: &Path, hmi_toml: &str) -> PathBuf {
    let path = dir.join("neptunus.toml");
    std::fs::write(&path, format!("[hmi]\n{hmi_toml}\n")).unwrap();
    path
}

/// `neptunus --sim --http 127.0.0.1:0 --config CFG ARGS…` started by
/// `sh -c SCRIPT` (which ends in `exec "$0" "$@"`), so the script can lower
/// limits or set the log level first (`unsafe` is denied: no pre_exec).
fn spawn_via_sh(dir: &Path, script: &str, cfg: &Path, args: &[&str]) -> Vehicle {
    let bin = bin().to_str().unwrap();
    let mut all = vec![
        "-c",
        script,
        bin,
        "--sim",
        "--http",
        "127.0.0.1:0",
        "--config",
        cfg.to_str().unwrap(),
    ];
    all.extend_from_slice(args);
    Vehicle::spawn(Path::new("/bin/sh"), &all, dir, "").unwrap()
}

fn spawn(dir: &Path, hmi_toml: &str) -> (Vehicle, SocketAddr) {
    let cfg = config(dir, hmi_toml);
    let mut v = spawn_via_sh(dir, "exec \"$0\" \"$@\"", &cfg, &[]);
    let http = v.http_addr(GENEROUS).unwrap();
    (v, http)
}

// ---------------------------------------------------------------------------
// Plain HTTP with std sockets
// ---------------------------------------------------------------------------

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

    fn body_text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

fn parse_reply(bytes: &[u8]) -> Reply {
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

/// Reads until the peer closes (or an error after some bytes, as a TLS
/// stream without close_notify gives).
fn read_all(s: &mut impl std::io::Read) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = [0u8; 8192];
    loop {
        match s.read(&mut buf) {
            Ok(0) => return out,
            Ok(n) => out.extend_from_slice(&buf[..n]),
            Err(e) if out.is_empty() => panic!("read failed: {e}"),
            Err(_) => return out,
        }
    }
}

/// `GET path` with HTTP/1.0 (the server closes after the reply).
fn get(addr: SocketAddr, path: &str) -> Reply {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(GENEROUS)).unwrap();
    write!(s, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n").unwrap();
    parse_reply(&read_all(&mut s))
}

/// Whether the server closed `s` (EOF or reset) within `within`; data it
/// sends first is read and dropped.
fn closed_within(s: &mut TcpStream, within: Duration) -> bool {
    let end = Instant::now() + within;
    let mut buf = [0u8; 4096];
    loop {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return false;
        }
        s.set_read_timeout(Some(left)).unwrap();
        match s.read(&mut buf) {
            Ok(0) => return true,
            Ok(_) => continue,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return false;
            }
            Err(_) => return true,
        }
    }
}

/// A connection from `src` (any 127.0.0.0/8 address is this host).
fn connect_from(src: Ipv4Addr, to: SocketAddr) -> TcpStream {
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.bind(SocketAddr::new(IpAddr::V4(src), 0)).unwrap();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let s = rt.block_on(sock.connect(to)).unwrap();
    let s = s.into_std().unwrap();
    s.set_nonblocking(false).unwrap();
    s
}

/// Sends a whole request on a kept-alive connection and reads one reply
/// (its Content-Length body).
fn request_on(s: &mut TcpStream, path: &str) -> Reply {
    write!(s, "GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    s.set_read_timeout(Some(GENEROUS)).unwrap();
    let mut bytes = Vec::new();
    let mut buf = [0u8; 8192];
    loop {
        let n = s.read(&mut buf).unwrap();
        assert!(n > 0, "closed before a reply to {path}");
        bytes.extend_from_slice(&buf[..n]);
        let r = parse_reply(&bytes);
        if bytes.windows(4).any(|w| w == b"\r\n\r\n")
            && let Some(len) = r.header("content-length")
            && r.body.len() >= len.parse::<usize>().unwrap()
        {
            return r;
        }
    }
}

/// Open descriptors of a process.
fn fd_count(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| d.count())
        .unwrap_or(0)
}

// ---------------------------------------------------------------------------
// 1. A half-open flood under a low open-file limit
// ---------------------------------------------------------------------------

/// Keeps one half-open connection from `src` open at a time until `stop`:
/// connects, sends part of a request line and headers, never finishes; when
/// the server closes it, pauses (an attacker's reconnect storm would be a
/// CPU benchmark, not this test) and opens the next.
async fn half_open(
    to: SocketAddr,
    src: Ipv4Addr,
    mut stop: tokio::sync::watch::Receiver<bool>,
    opened: Arc<AtomicU64>,
) {
    while !*stop.borrow() {
        let Ok(sock) = tokio::net::TcpSocket::new_v4() else {
            return;
        };
        if sock.bind(SocketAddr::new(IpAddr::V4(src), 0)).is_err() {
            return;
        }
        let connected = tokio::select! {
            c = tokio::time::timeout(Duration::from_secs(2), sock.connect(to)) => c,
            _ = stop.changed() => return,
        };
        if let Ok(Ok(mut s)) = connected {
            opened.fetch_add(1, Ordering::Relaxed);
            let _ = s
                .write_all(b"GET / HTTP/1.1\r\nHost: localhost\r\nUser-Agent: half")
                .await;
            let mut buf = [0u8; 512];
            tokio::select! {
                _ = s.read(&mut buf) => {}
                _ = stop.changed() => return,
            }
        }
        tokio::select! {
            () = tokio::time::sleep(Duration::from_millis(500)) => {}
            _ = stop.changed() => return,
        }
    }
}

/// HEARTBEATs and ATTITUDEs from the vehicle over `window` (the station
/// keeps sending its own heartbeat).
fn count_telemetry(gcs: &mut Gcs, vehicle: &mut Vehicle, window: Duration) -> (u32, u32) {
    let (mut hb, mut att) = (0, 0);
    gcs.run_until(vehicle, Traffic::Heartbeats, window, |msgs| {
        for m in msgs {
            match m {
                MavMessage::HEARTBEAT(_) => hb += 1,
                MavMessage::ATTITUDE(_) => att += 1,
                _ => {}
            }
        }
        false
    })
    .unwrap();
    (hb, att)
}

/// A new MAVLink TCP client: connects and waits for the vehicle's HEARTBEAT.
fn tcp_station_gets_heartbeat(port: u16) -> bool {
    let Ok(mut s) = TcpStream::connect(("127.0.0.1", port)) else {
        return false;
    };
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut dec = FrameDecoder::new();
    let end = Instant::now() + GENEROUS;
    let mut buf = [0u8; 4096];
    while Instant::now() < end {
        match s.read(&mut buf) {
            Ok(0) => return false,
            Ok(n) => {
                let mut frames = Vec::new();
                dec.push(&buf[..n], &mut frames);
                if frames
                    .iter()
                    .any(|f| f.sysid == 1 && matches!(f.msg, MavMessage::HEARTBEAT(_)))
                {
                    return true;
                }
            }
            Err(_) => {}
        }
    }
    false
}

#[test]
fn half_open_flood_under_a_low_fd_limit_starves_nothing_and_the_hmi_recovers() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), "header_timeout_s = 1.0");
    let (mut gcs, gcs_port) = Gcs::bind().unwrap();
    let tcp_port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let udpout = format!("udpout:127.0.0.1:{gcs_port}");
    let tcpin = format!("tcpin:127.0.0.1:{tcp_port}");
    let mut vehicle = spawn_via_sh(
        dir.path(),
        "ulimit -n 256 && exec \"$0\" \"$@\"",
        &cfg,
        &["--mavlink", &udpout, "--mavlink", &tcpin],
    );
    let http = vehicle.http_addr(GENEROUS).unwrap();
    gcs.await_vehicle(&mut vehicle, GENEROUS).unwrap();
    let limits = std::fs::read_to_string(format!("/proc/{}/limits", vehicle.pid())).unwrap();
    let nofile = limits
        .lines()
        .find(|l| l.starts_with("Max open files"))
        .unwrap()
        .to_owned();
    assert!(
        nofile.split_whitespace().nth(3) == Some("256"),
        "the vehicle must run with 256 descriptors for this test to mean anything: {nofile}"
    );

    let (hb_before, att_before) = count_telemetry(&mut gcs, &mut vehicle, Duration::from_secs(5));
    assert!(
        hb_before >= 3 && att_before >= 3,
        "no telemetry before the flood"
    );
    let fds_before = fd_count(vehicle.pid());

    // 300 half-open connections from ten addresses (30 each: under the
    // per-address cap, so the total cap is what holds).
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let opened = Arc::new(AtomicU64::new(0));
    let mut flood = Vec::new();
    for i in 0..300u32 {
        let src = Ipv4Addr::new(127, 0, 0, 2 + (i % 10) as u8);
        flood.push(rt.spawn(half_open(http, src, stop_rx.clone(), Arc::clone(&opened))));
    }
    // The flood is on once 300 connections got in (most then wait over the cap).
    let pid = vehicle.pid();
    let mut fds_max = 0;
    let full = gcs
        .run_until(&mut vehicle, Traffic::Heartbeats, GENEROUS, |_| {
            fds_max = fds_max.max(fd_count(pid));
            opened.load(Ordering::Relaxed) >= 300
        })
        .unwrap();
    assert!(full, "the flood did not get 300 connections in");

    let (hb_during, att_during) = count_telemetry(&mut gcs, &mut vehicle, Duration::from_secs(5));
    let new_tcp_ok = tcp_station_gets_heartbeat(tcp_port);
    gcs.send(&MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: 0.7,
        target_system: 1,
        target_component: 1,
        param_id: "JS_GAIN_DEFAULT".into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    }))
    .unwrap();
    let acked = gcs
        .run_until(&mut vehicle, Traffic::Heartbeats, GENEROUS, |msgs| {
            msgs.iter().any(|m| {
                matches!(m, MavMessage::PARAM_VALUE(v)
                    if v.param_id.to_str() == Ok("JS_GAIN_DEFAULT") && (v.param_value - 0.7).abs() < 1e-6)
            })
        })
        .unwrap();
    let fds_during = fd_count(vehicle.pid());
    eprintln!(
        "flood: {} connections opened; descriptors {fds_before} before, peak {}; HEARTBEAT {hb_before} -> {hb_during}, \
         ATTITUDE {att_before} -> {att_during} per 5 s",
        opened.load(Ordering::Relaxed),
        fds_max.max(fds_during)
    );
    let _ = stop_tx.send(true);
    rt.block_on(async {
        for f in flood {
            let _ = f.await;
        }
    });
    drop(rt);

    assert!(
        hb_during * 2 >= hb_before && att_during * 2 >= att_before,
        "telemetry starved by the flood: HEARTBEAT {hb_during} (before {hb_before}), ATTITUDE {att_during} (before {att_before}) in 5 s"
    );
    assert!(
        new_tcp_ok,
        "a new MAVLink TCP station got no HEARTBEAT during the flood"
    );
    assert!(acked, "PARAM_SET not acknowledged during the flood");
    let fds_peak = fds_max.max(fds_during);
    assert!(
        fds_peak <= fds_before + 128 + 16,
        "the vehicle held {fds_peak} descriptors under the flood ({fds_before} before): the cap of 128 did not hold"
    );
    // The HMI serves a new client once the half-open connections are cut.
    let end = Instant::now() + GENEROUS;
    let page = loop {
        if let Ok(mut s) = TcpStream::connect(http) {
            s.set_read_timeout(Some(GENEROUS)).unwrap();
            if write!(s, "GET / HTTP/1.0\r\nHost: {http}\r\n\r\n").is_ok() {
                let mut bytes = Vec::new();
                let _ = s.read_to_end(&mut bytes);
                let r = parse_reply(&bytes);
                if r.status == 200 {
                    break r;
                }
            }
        }
        vehicle.check_running().unwrap();
        assert!(
            Instant::now() < end,
            "the HMI did not serve the page after the flood"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(page.body_text().contains("<title>Neptunus</title>"));
    // Logged once per burst, not once per refused connection.
    let cap_lines = vehicle
        .stderr_text()
        .lines()
        .filter(|l| l.contains("max_connections"))
        .count();
    assert!(
        (1..=6).contains(&cap_lines),
        "{cap_lines} log lines about the connection cap: want one per 10 s burst\n{}",
        vehicle.stderr_tail()
    );
}

// ---------------------------------------------------------------------------
// 2. The header-read timeout and the caps
// ---------------------------------------------------------------------------

#[test]
fn silent_and_idle_keepalive_connections_are_closed_after_the_header_timeout() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let (mut vehicle, http) = spawn(dir.path(), "header_timeout_s = 1.0");
    // Sends nothing at all.
    let mut silent = TcpStream::connect(http).unwrap();
    // Half a request line.
    let mut partial = TcpStream::connect(http).unwrap();
    partial.write_all(b"GET /api/sta").unwrap();
    // A whole request, then nothing (an idle keep-alive connection).
    let mut idle = TcpStream::connect(http).unwrap();
    let r = request_on(&mut idle, "/api/status");
    assert_eq!(r.status, 200);
    for (name, s) in [
        ("silent", &mut silent),
        ("partial", &mut partial),
        ("idle keep-alive", &mut idle),
    ] {
        assert!(
            closed_within(s, GENEROUS),
            "the {name} connection was still open {GENEROUS:?} after a 1 s header timeout"
        );
    }
    vehicle.check_running().unwrap();
    assert_eq!(get(http, "/api/status").status, 200);
}

#[test]
fn connection_caps_close_extra_connections_at_once() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    // A header timeout far beyond the wait below: a close seen within it
    // can only be the cap's.
    let (mut vehicle, http) = spawn(
        dir.path(),
        "header_timeout_s = 120.0\nmax_connections = 6\nmax_connections_per_address = 3",
    );
    let a = Ipv4Addr::new(127, 0, 0, 1);
    let b = Ipv4Addr::new(127, 0, 0, 2);
    let c = Ipv4Addr::new(127, 0, 0, 3);
    // Connections are accepted in the order they were made: the first three
    // from A take A's slots, and a whole request on one proves it is served.
    let mut held_a: Vec<TcpStream> = (0..3).map(|_| connect_from(a, http)).collect();
    assert_eq!(request_on(&mut held_a[0], "/api/status").status, 200);
    let mut fourth_a = connect_from(a, http);
    assert!(
        closed_within(&mut fourth_a, GENEROUS),
        "a 4th connection from one address was not closed (per-address cap 3)"
    );
    // B fills the total.
    let mut held_b: Vec<TcpStream> = (0..3).map(|_| connect_from(b, http)).collect();
    assert_eq!(request_on(&mut held_b[2], "/api/status").status, 200);
    let mut seventh = connect_from(c, http);
    assert!(
        closed_within(&mut seventh, GENEROUS),
        "a 7th connection was not closed (total cap 6)"
    );
    // The held ones still work.
    assert_eq!(request_on(&mut held_a[2], "/").status, 200);
    // A slot given back is a slot for the next client.
    drop(held_b.pop());
    let end = Instant::now() + GENEROUS;
    loop {
        let mut s = connect_from(c, http);
        write!(s, "GET /api/status HTTP/1.0\r\nHost: localhost\r\n\r\n").unwrap();
        s.set_read_timeout(Some(GENEROUS)).unwrap();
        let mut bytes = Vec::new();
        let _ = s.read_to_end(&mut bytes);
        if parse_reply(&bytes).status == 200 {
            break;
        }
        vehicle.check_running().unwrap();
        assert!(Instant::now() < end, "the freed slot was never given to C");
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(held_a);
    drop(held_b);
}

// ---------------------------------------------------------------------------
// 3. Headers and 404s
// ---------------------------------------------------------------------------

fn assert_security_headers(r: &Reply, what: &str) {
    let csp = r
        .header("content-security-policy")
        .unwrap_or_else(|| panic!("no Content-Security-Policy on {what}:\n{}", r.head));
    assert!(csp.contains("frame-ancestors 'none'"), "{what}: {csp}");
    assert!(csp.contains("default-src 'self'"), "{what}: {csp}");
    assert!(!csp.contains("unsafe-inline"), "{what}: {csp}");
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

#[test]
fn security_headers_on_every_response_and_404s_do_not_echo_the_path() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let (_vehicle, http) = spawn(dir.path(), "");
    for (path, status) in [
        ("/", 200),
        ("/js/main.js", 200),
        ("/css/style.css", 200),
        ("/api/status", 200),
        ("/camera/status", 200),
        ("/no/such/page", 404),
    ] {
        let r = get(http, path);
        assert_eq!(r.status, status, "{path}:\n{}", r.head);
        assert_security_headers(&r, path);
    }
    let r = get(http, "/");
    let csp = r.header("content-security-policy").unwrap();
    assert!(
        csp.contains(&format!("ws://{http}")),
        "the WebSocket's own origin is allowed: {csp}"
    );
    for path in [
        "/%3Cscript%3Ealert(1)%3C/script%3E",
        "/<script>alert(1)</script>",
        "/vendor/%3Cimg%20src=x%20onerror=alert(1)%3E",
    ] {
        let r = get(http, path);
        assert!(
            r.status == 404 || r.status == 400,
            "{path}: status {}",
            r.status
        );
        let body = r.body_text();
        assert!(
            !body.contains("alert") && !body.contains("script") && !body.contains("img"),
            "the 404 for {path} echoes it: {body}"
        );
        if r.status == 404 {
            assert_security_headers(&r, path);
        }
    }
}

// ---------------------------------------------------------------------------
// 4. TLS
// ---------------------------------------------------------------------------

/// A TLS client that trusts exactly the certificate in `cert_pem`.
fn connector(cert_pem: &Path) -> tokio_rustls::TlsConnector {
    use rustls::pki_types::CertificateDer;
    use rustls::pki_types::pem::PemObject as _;
    let mut roots = rustls::RootCertStore::empty();
    for c in CertificateDer::pem_file_iter(cert_pem).unwrap() {
        roots.add(c.unwrap()).unwrap();
    }
    let provider = Arc::new(rustls::crypto::aws_lc_rs::default_provider());
    let cfg = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth();
    tokio_rustls::TlsConnector::from(Arc::new(cfg))
}

type TlsStream = tokio_rustls::client::TlsStream<tokio::net::TcpStream>;

async fn tls_connect(tls: &tokio_rustls::TlsConnector, addr: SocketAddr) -> TlsStream {
    let tcp = tokio::net::TcpStream::connect(addr).await.unwrap();
    let name = rustls::pki_types::ServerName::try_from("localhost").unwrap();
    tokio::time::timeout(GENEROUS, tls.connect(name, tcp))
        .await
        .unwrap()
        .unwrap()
}

async fn tls_get(tls: &tokio_rustls::TlsConnector, addr: SocketAddr, path: &str) -> Reply {
    let mut s = tls_connect(tls, addr).await;
    s.write_all(
        format!(
            "GET {path} HTTP/1.0\r\nHost: localhost:{}\r\n\r\n",
            addr.port()
        )
        .as_bytes(),
    )
    .await
    .unwrap();
    let mut out = Vec::new();
    let mut buf = [0u8; 8192];
    loop {
        match tokio::time::timeout(GENEROUS, s.read(&mut buf))
            .await
            .unwrap()
        {
            Ok(0) => break,
            Ok(n) => out.extend_from_slice(&buf[..n]),
            Err(_) if !out.is_empty() => break,
            Err(e) => panic!("TLS read failed: {e}"),
        }
    }
    parse_reply(&out)
}

type Wss = tokio_tungstenite::WebSocketStream<TlsStream>;

/// The pilot password the TLS test sets with the CLI before the start.
const PASSWORD: &str = "tide-pool-42";

/// Opens a browser session over `stream`: the WebSocket, the welcome, then
/// the pilot login with `PASSWORD` — the password crosses only the TLS
/// stream. Returns the welcome.
async fn open_session(stream: TlsStream, addr: SocketAddr) -> (Wss, Value) {
    let url = format!("wss://localhost:{}/ws", addr.port());
    let (mut ws, _) = tokio_tungstenite::client_async(url, stream).await.unwrap();
    let welcome = next_of(&mut ws, "welcome").await;
    assert_eq!(welcome["password_required"], true, "{welcome}");
    let login = serde_json::json!({"type": "login", "password": PASSWORD}).to_string();
    ws.send(tokio_tungstenite::tungstenite::Message::Text(login.into()))
        .await
        .unwrap();
    let r = next_of(&mut ws, "login_result").await;
    assert_eq!(r["ok"], true, "the pilot login over TLS failed: {r}");
    (ws, welcome)
}

async fn next_of(ws: &mut Wss, kind: &str) -> Value {
    let end = tokio::time::Instant::now() + GENEROUS;
    loop {
        let m = tokio::time::timeout_at(end, ws.next())
            .await
            .unwrap_or_else(|_| panic!("no {kind} message within {GENEROUS:?}"))
            .expect("WebSocket closed")
            .unwrap();
        if let tokio_tungstenite::tungstenite::Message::Text(t) = m {
            let v: Value = serde_json::from_str(t.as_str()).unwrap();
            if v["type"] == kind {
                return v;
            }
        }
    }
}

/// `neptunus hmi set-password` with `PASSWORD` piped in.
fn set_password(data: &Path) {
    let out = common::run_cli(
        bin(),
        data,
        &["hmi", "set-password"],
        &format!("{PASSWORD}\n"),
    );
    assert!(
        out.status.success(),
        "hmi set-password: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The colon-hex SHA-256 fingerprints in `text`.
fn fingerprints(text: &str) -> Vec<String> {
    text.split(|c: char| c.is_whitespace() || c == ',' || c == '"')
        .filter(|w| w.len() == 95 && w.split(':').all(|b| b.len() == 2))
        .map(str::to_owned)
        .collect()
}

#[test]
fn self_signed_tls_serves_the_page_and_websocket_and_keeps_its_certificate() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    // A remote pilot: nobody may pilot without the password.
    let cfg = config(
        dir.path(),
        "tls = \"self-signed\"\ntls_names = [\"rov.test\"]\nheader_timeout_s = 2.0\nopen_control = \"none\"",
    );
    set_password(&dir.path().join("data"));
    let script = "export RUST_LOG=info && exec \"$0\" \"$@\"";
    let mut vehicle = spawn_via_sh(dir.path(), script, &cfg, &[]);
    let http = vehicle.http_addr(GENEROUS).unwrap();
    let data = vehicle.data_dir().to_path_buf();
    let addr_text = std::fs::read_to_string(data.join("http.addr")).unwrap();
    assert_eq!(addr_text.trim(), format!("https://{http}/"));
    let cert = data.join("tls/cert.pem");
    let key = data.join("tls/key.pem");
    assert!(
        cert.is_file() && key.is_file(),
        "no certificate in DATA_DIR/tls/"
    );
    {
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(&key).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600, "the key file is readable by others");
    }
    let cert_bytes = std::fs::read(&cert).unwrap();
    let tls = connector(&cert);

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let page = tls_get(&tls, http, "/").await;
        assert_eq!(page.status, 200, "{}", page.head);
        assert!(page.body_text().contains("<title>Neptunus</title>"));
        assert_security_headers(&page, "/ over TLS");
        let (mut ws, welcome) = open_session(tls_connect(&tls, http).await, http).await;
        assert!(welcome["session"].is_u64(), "{welcome}");
        let t = next_of(&mut ws, "telemetry").await;
        assert!(t["t_ms"].is_number(), "{t}");

        // Plain HTTP to the TLS port: no page, a pointer to https://, and
        // the server carries on.
        for (host, status) in [(format!("{http}"), 301), ("x y".to_owned(), 400)] {
            let mut plain = tokio::net::TcpStream::connect(http).await.unwrap();
            plain
                .write_all(format!("GET / HTTP/1.1\r\nHost: {host}\r\n\r\n").as_bytes())
                .await
                .unwrap();
            let mut got = Vec::new();
            let _ = tokio::time::timeout(GENEROUS, plain.read_to_end(&mut got))
                .await
                .expect("the TLS port kept a plain-HTTP connection open");
            let r = parse_reply(&got);
            assert_eq!(r.status, status, "{}", r.head);
            assert!(r.body_text().contains("https://"), "{}", r.body_text());
            if status == 301 {
                assert_eq!(r.header("location"), Some(format!("https://{http}/")));
            }
        }
        // Bytes that are neither TLS nor HTTP: closed, nothing served.
        let mut junk = tokio::net::TcpStream::connect(http).await.unwrap();
        junk.write_all(&[0u8; 64]).await.unwrap();
        let mut got = Vec::new();
        let _ = tokio::time::timeout(GENEROUS, junk.read_to_end(&mut got))
            .await
            .expect("the TLS port kept a junk connection open");
        assert!(!String::from_utf8_lossy(&got).contains("200 OK"));
        next_of(&mut ws, "telemetry").await;
        // With a password the vehicle's records need the login cookie, over
        // TLS too.
        assert_eq!(tls_get(&tls, http, "/api/logs").await.status, 401);
    });

    // The log and the CLI give the same fingerprint.
    let logged = fingerprints(&vehicle.stderr_text());
    assert!(!logged.is_empty(), "no fingerprint in the log");
    let out = std::process::Command::new(bin())
        .args(["hmi", "tls-fingerprint", "--config"])
        .arg(&cfg)
        .arg("--data-dir")
        .arg(&data)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let printed = fingerprints(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(printed.len(), 1, "{}", String::from_utf8_lossy(&out.stdout));
    assert_eq!(printed[0], logged[0]);

    // A second start serves the same certificate.
    drop(vehicle);
    // The old address file would be read before the new process writes its own.
    std::fs::remove_file(data.join("http.addr")).unwrap();
    let mut again = spawn_via_sh(dir.path(), script, &cfg, &[]);
    let http = again.http_addr(GENEROUS).unwrap();
    assert_eq!(
        std::fs::read(&cert).unwrap(),
        cert_bytes,
        "the certificate was replaced"
    );
    rt.block_on(async {
        assert_eq!(tls_get(&tls, http, "/").await.status, 200);
    });
    let logged_again = fingerprints(&again.stderr_text());
    assert_eq!(logged_again.first(), logged.first());
}

// ---------------------------------------------------------------------------
// 5. Shutdown
// ---------------------------------------------------------------------------

#[test]
fn shutdown_is_not_held_up_by_open_connections() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let (mut vehicle, http) = spawn(dir.path(), "");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    // A WebSocket session, an MJPEG stream that never ends, a half-open
    // request and an idle connection, all open at the signal.
    let (_ws, _) = rt
        .block_on(tokio_tungstenite::connect_async(format!("ws://{http}/ws")))
        .unwrap();
    let mut video = TcpStream::connect(http).unwrap();
    write!(video, "GET /video.mjpg HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    video.set_read_timeout(Some(GENEROUS)).unwrap();
    let mut first = [0u8; 64];
    let n = video.read(&mut first).unwrap();
    assert!(first[..n].starts_with(b"HTTP/1.1 200"), "no video stream");
    let mut partial = TcpStream::connect(http).unwrap();
    partial.write_all(b"GET / HTTP/1.1\r\nHo").unwrap();
    let _idle = TcpStream::connect(http).unwrap();
    vehicle.signal(nix::sys::signal::Signal::SIGTERM).unwrap();
    let end = Instant::now() + GENEROUS;
    let status = loop {
        if let Some(status) = vehicle.child.try_wait().unwrap() {
            break status;
        }
        assert!(
            Instant::now() < end,
            "neptunus still running {GENEROUS:?} after SIGTERM with HMI connections open"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "{status}:\n{}", vehicle.stderr_tail());
}

#[test]
fn websockets_count_against_the_caps() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let (mut vehicle, http) = spawn(
        dir.path(),
        "header_timeout_s = 120.0\nmax_connections = 4\nmax_connections_per_address = 3",
    );
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    // Three WebSockets from 127.0.0.1: its share, though the HTTP
    // connections they started on have been handed over.
    let mut sockets = Vec::new();
    for _ in 0..3 {
        let (ws, _) = rt
            .block_on(tokio_tungstenite::connect_async(format!("ws://{http}/ws")))
            .unwrap();
        sockets.push(ws);
    }
    let mut fourth = connect_from(Ipv4Addr::new(127, 0, 0, 1), http);
    assert!(
        closed_within(&mut fourth, GENEROUS),
        "a 4th connection from an address with 3 open WebSockets was not closed"
    );
    // Closing one gives its slot back.
    let ws = sockets.pop().unwrap();
    drop(ws);
    let end = Instant::now() + GENEROUS;
    while get_status(http) != Some(200) {
        vehicle.check_running().unwrap();
        assert!(
            Instant::now() < end,
            "the closed WebSocket's slot never came back"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(sockets);
}

/// `GET /api/status`'s status, or `None` when the connection was closed.
fn get_status(addr: SocketAddr) -> Option<u16> {
    let mut s = TcpStream::connect(addr).ok()?;
    s.set_read_timeout(Some(GENEROUS)).ok()?;
    write!(s, "GET /api/status HTTP/1.0\r\nHost: localhost\r\n\r\n").ok()?;
    let mut bytes = Vec::new();
    let _ = s.read_to_end(&mut bytes);
    let r = parse_reply(&bytes);
    (r.status != 0).then_some(r.status)
}

#[test]
fn out_of_descriptors_the_accept_loop_backs_off_and_recovers() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    // Caps set above what the descriptor limit allows (a misfit
    // configuration): accept(2) itself fails with EMFILE.
    let cfg = config(
        dir.path(),
        "header_timeout_s = 1.0\nmax_connections = 1000\nmax_connections_per_address = 1000",
    );
    let mut vehicle = spawn_via_sh(dir.path(), "ulimit -n 64 && exec \"$0\" \"$@\"", &cfg, &[]);
    let http = vehicle.http_addr(GENEROUS).unwrap();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let opened = Arc::new(AtomicU64::new(0));
    let flood: Vec<_> = (0..100)
        .map(|_| {
            rt.spawn(half_open(
                http,
                Ipv4Addr::LOCALHOST,
                stop_rx.clone(),
                Arc::clone(&opened),
            ))
        })
        .collect();
    let end = Instant::now() + GENEROUS;
    while !vehicle.stderr_text().contains("cannot accept") {
        vehicle.check_running().unwrap();
        assert!(
            Instant::now() < end,
            "the flood never ran the vehicle out of descriptors"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = stop_tx.send(true);
    rt.block_on(async {
        for f in flood {
            let _ = f.await;
        }
    });
    drop(rt);
    let end = Instant::now() + GENEROUS;
    while get_status(http) != Some(200) {
        vehicle.check_running().unwrap();
        assert!(
            Instant::now() < end,
            "the HMI did not come back after EMFILE"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let lines = vehicle
        .stderr_text()
        .lines()
        .filter(|l| l.contains("cannot accept"))
        .count();
    assert!(
        lines <= 3,
        "{lines} accept-error lines: want at most one per 10 s\n{}",
        vehicle.stderr_tail()
    );
}

#[test]
fn bad_certificate_files_stop_the_start_with_one_line_naming_the_file() {
    let _one = serial();
    let dir = tempfile::tempdir().unwrap();
    let cert = dir.path().join("rov-cert.pem");
    std::fs::write(&cert, "this is not PEM\n").unwrap();
    let key = dir.path().join("missing-key.pem");
    let cfg = config(
        dir.path(),
        &format!(
            "tls = \"files\"\ntls_cert = \"{}\"\ntls_key = \"{}\"",
            cert.display(),
            key.display()
        ),
    );
    let out = std::process::Command::new(bin())
        .args(["--sim", "--http", "127.0.0.1:0", "--config"])
        .arg(&cfg)
        .arg("--data-dir")
        .arg(dir.path().join("data"))
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let line = err
        .lines()
        .find(|l| l.starts_with("neptunus: "))
        .unwrap_or_else(|| panic!("no error line:\n{err}"));
    assert!(
        line.contains("rov-cert.pem")
            && line.contains("BEGIN CERTIFICATE")
            && line.contains("tls_cert"),
        "{line}"
    );
}
