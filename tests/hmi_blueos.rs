//! What Cockpit asks of a BlueOS vehicle, against the real binary
//! (`neptunus --sim`): the settings bag kept across a restart, its refusals
//! (bad JSON, oversized values, path tricks, another's value, a full
//! quota) answered with the reason, logged and changing nothing; the
//! beacon, the helper and the camera manager's `/streams`; the Cockpit link
//! that logs Cockpit in; the one ICE address a viewer is offered — and,
//! from a stranger's side, the Host, Origin and login rules on every new
//! route, on the HMI's port and on the ports beside it.
//!
//! Every wait is for a condition with a generous deadline; nothing sleeps
//! to let time pass.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::io::{Read as _, Write as _};
use std::net::{IpAddr, SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::Vehicle;
use futures_util::{SinkExt as _, StreamExt as _};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

const GENEROUS: Duration = Duration::from_secs(20);
const PASSWORD: &str = "tide-pool-42";
const COCKPIT: &str = "http://127.0.0.1:5173";
const EVIL: &str = "http://evil.example.com";

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

/// A loopback address of its own (127.0.0.0/8 all reaches this machine),
/// so the vehicle is reached at an address no interface lists.
fn loopback_alias() -> IpAddr {
    let n: u8 = rand::random::<u8>() % 200 + 20;
    IpAddr::from([127, 0, n, 7])
}

/// `neptunus --sim` with its HMI on `http` (port 0: a free one), the
/// signalling and `/streams` on free ports of the same address, Cockpit's
/// origin allowed, and `hmi_toml` in `[hmi]`; the pilot password set first
/// when `password`.
struct Rov {
    v: Vehicle,
    dir: PathBuf,
    http: SocketAddr,
    signalling: SocketAddr,
    streams: SocketAddr,
}

impl Rov {
    fn start(dir: &Path, ip: IpAddr, hmi_toml: &str, password: bool) -> Rov {
        let data = dir.join("data");
        // A restarted vehicle writes its address again: wait for the new one.
        let _ = std::fs::remove_file(data.join("http.addr"));
        if password && !data.join("hmi-password").exists() {
            let out = common::run_cli(
                bin(),
                &data,
                &["hmi", "set-password"],
                &format!("{PASSWORD}\n"),
            );
            assert!(out.status.success(), "set-password: {out:?}");
        }
        let cfg = dir.join("neptunus.toml");
        std::fs::write(
            &cfg,
            format!(
                "[camera]\nsource = \"synthetic\"\n[camera.webrtc]\nstreams = \"{ip}:0\"\n\
                 [hmi]\nallowed_origins = [\"{COCKPIT}\"]\n{hmi_toml}\n"
            ),
        )
        .unwrap();
        let http = format!("{ip}:0");
        let signalling = format!("{ip}:0");
        let mut v = Vehicle::spawn_env(
            bin(),
            &[
                "--sim",
                "--config",
                cfg.to_str().unwrap(),
                "--http",
                &http,
                "--webrtc-signalling",
                &signalling,
                "--video-rtp",
                "off",
                "--mavlink",
                "udpin:127.0.0.1:0",
            ],
            dir,
            "",
            &[("RUST_LOG", "info"), ("NO_COLOR", "1")],
        )
        .unwrap();
        let http = v.http_addr(GENEROUS).unwrap();
        let info = until("the WebRTC ports", || {
            let r = request(http, "GET", "/api/webrtc", &[], b"");
            let v: Value = serde_json::from_slice(&r.body).ok()?;
            Some((v["signalling_port"].as_u64()?, v["streams_port"].as_u64()?))
        });
        Rov {
            v,
            dir: dir.to_path_buf(),
            http,
            signalling: SocketAddr::new(ip, info.0 as u16),
            streams: SocketAddr::new(ip, info.1 as u16),
        }
    }

    fn log(&self) -> String {
        self.v.stderr_text()
    }

    fn get(&self, path: &str) -> Reply {
        request(self.http, "GET", path, &[], b"")
    }

    fn set(&self, path: &str, body: &[u8], headers: &[(&str, &str)]) -> Reply {
        request(self.http, "POST", path, headers, body)
    }

    /// Stops it (SIGTERM) and waits for it to exit.
    fn stop(mut self) -> PathBuf {
        self.v.signal(nix::sys::signal::Signal::SIGTERM).unwrap();
        let end = Instant::now() + GENEROUS;
        while self.v.child.try_wait().unwrap().is_none() {
            assert!(Instant::now() < end, "neptunus did not stop");
            std::thread::sleep(Duration::from_millis(20));
        }
        self.dir
    }
}

fn until<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let end = Instant::now() + GENEROUS;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(Instant::now() < end, "no {what} within {GENEROUS:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
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

    fn json(&self) -> Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&self.body)))
    }

    fn detail(&self) -> String {
        self.json()["detail"]
            .as_str()
            .unwrap_or_default()
            .to_owned()
    }
}

/// One HTTP/1.0 request with `Host: ADDR` unless `headers` give one.
fn request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Reply {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(GENEROUS)).unwrap();
    let mut head = format!("{method} {path} HTTP/1.0\r\n");
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        head.push_str(&format!("Host: {addr}\r\n"));
    }
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str(&format!("Content-Length: {}\r\n\r\n", body.len()));
    s.write_all(head.as_bytes()).unwrap();
    // A refusal may come before the whole body is sent.
    let _ = s.write_all(body);
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    let split = out
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or(out.len());
    let head = String::from_utf8_lossy(&out[..split]).into_owned();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    Reply {
        status,
        head,
        body: out.get(split + 4..).unwrap_or_default().to_vec(),
    }
}

const ID: &str = "/bag/v1.0/get/cockpit/cockpit-vehicle-id";
const SET_ID: &str = "/bag/v1.0/set/cockpit/cockpit-vehicle-id";

/// The vehicle id Cockpit writes is the one it reads after a restart; the
/// file is written whole (no temporary file left).
#[test]
fn the_vehicle_id_cockpit_stores_is_the_same_after_a_restart() {
    let tmp = tempfile::tempdir().unwrap();
    let ip = loopback_alias();
    let rov = Rov::start(tmp.path(), ip, "", false);
    let absent = rov.get(ID);
    assert_eq!(absent.status, 404);
    assert_eq!(
        absent.json(),
        json!({"detail": "Invalid path"}),
        "what Cockpit looks for"
    );
    let id = "\"0d6c4f0e-6a4e-4e0b-9b1c-3f8f5b1c2a77\"";
    let stored = rov.set(
        SET_ID,
        id.as_bytes(),
        &[("Content-Type", "application/json")],
    );
    assert_eq!(
        stored.status,
        200,
        "{}",
        String::from_utf8_lossy(&stored.body)
    );
    rov.set(
        "/bag/v1.0/set/cockpit/settings-v2/pilot/cockpit-views",
        br#"{"epochLastChangedLocally":1,"value":[{"name":"Video View"}]}"#,
        &[],
    );
    let dir = rov.stop();
    assert!(dir.join("data/bag.json").exists());
    assert!(!dir.join("data/bag.json.tmp").exists());
    let rov = Rov::start(&dir, ip, "", false);
    assert_eq!(
        rov.get(ID).json(),
        serde_json::from_str::<Value>(id).unwrap()
    );
    assert_eq!(
        rov.get("/bag/v1.0/get/cockpit/settings-v2").json(),
        json!({"pilot": {"cockpit-views": {"epochLastChangedLocally": 1, "value": [{"name": "Video View"}]}}})
    );
}

/// Bad JSON, an oversized value and path tricks get a clear HTTP error
/// with the reason, are logged, and change nothing.
#[test]
fn bad_oversized_and_tricky_bag_writes_are_refused_logged_and_change_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let rov = Rov::start(tmp.path(), loopback_alias(), "", false);
    assert_eq!(rov.set(SET_ID, b"\"kept\"", &[]).status, 200);
    let big = format!("\"{}\"", "x".repeat(300 * 1024));
    let deep = format!("{}{}", "[".repeat(70), "]".repeat(70));
    let tricks: [(&str, &str, u16, &str); 9] = [
        (SET_ID, "{not json", 400, "not JSON"),
        (SET_ID, &big, 413, "at most"),
        (
            "/bag/v1.0/set/cockpit/%2e%2e/cockpit-vehicle-id",
            "1",
            400,
            "\"..\"",
        ),
        (
            "/bag/v1.0/set/cockpit%2Fcockpit-vehicle-id",
            "1",
            400,
            "encoded slash",
        ),
        (
            "/bag/v1.0/set/cockpit/cockpit-vehicle-id%00",
            "1",
            400,
            "control character",
        ),
        ("/bag/v1.0/set//etc/passwd", "1", 400, "absolute"),
        ("/bag/v1.0/set/cockpit//x", "1", 400, "empty segment"),
        ("/bag/v1.0/set/cockpit/%ZZ", "1", 400, "percent-encoded"),
        (SET_ID, &deep, 400, "nested"),
    ];
    for (path, body, status, why) in tricks {
        let r = rov.set(path, body.as_bytes(), &[]);
        assert_eq!(
            r.status,
            status,
            "{path}: {}",
            String::from_utf8_lossy(&r.body)
        );
        assert!(r.detail().contains(why), "{path}: {}", r.detail());
    }
    // Path tricks on reads, too; and nothing changed.
    assert_eq!(rov.get("/bag/v1.0/get/..%2F..%2Fetc").status, 400);
    assert_eq!(rov.get(ID).json(), json!("kept"));
    assert_eq!(
        rov.get("/bag/v1.0/get/cockpit").json(),
        json!({"cockpit-vehicle-id": "kept"})
    );
    let log = rov.log();
    // The first refusal of each kind at once (the next within 5 s are counted).
    for kind in ["not JSON", "at most", "\".\" or \"..\""] {
        assert!(
            log.lines()
                .any(|l| l.contains("settings bag refused") && l.contains(kind)),
            "no log line for {kind}:\n{log}"
        );
    }
}

/// From a stranger's side: a foreign Host (DNS rebinding) is refused on
/// every new route and port; a foreign page can neither write the bag nor
/// read any answer (no CORS header for it); a client that is not the pilot
/// keeps its own settings but cannot change the vehicle id or another's
/// settings, nor fill the card; the pilot can.
#[test]
fn strangers_cannot_use_the_new_routes_on_either_port() {
    let tmp = tempfile::tempdir().unwrap();
    let rov = Rov::start(
        tmp.path(),
        loopback_alias(),
        "open_control = \"none\"",
        true,
    );
    let foreign = [("Host", "evil.example.com")];
    for (addr, path) in [
        (rov.http, ID),
        (rov.http, "/beacon/v1.0/services"),
        (rov.http, "/beacon/v1.0/vehicle_name"),
        (rov.http, "/helper/v1.0/web_services"),
        (rov.http, "/mavlink2rest/info"),
        (rov.streams, "/streams"),
        (rov.signalling, "/"),
    ] {
        let r = request(addr, "GET", path, &foreign, b"");
        assert_eq!(r.status, 403, "{addr}{path} under a foreign host");
    }
    assert_eq!(
        request(rov.http, "POST", SET_ID, &foreign, b"\"x\"").status,
        403
    );
    // A page of another origin: its write is refused, its reads unreadable.
    let evil = [("Origin", EVIL)];
    assert_eq!(rov.set(SET_ID, b"\"evil\"", &evil).status, 403);
    assert_eq!(rov.get(ID).status, 404, "the refused write changed nothing");
    for (addr, path) in [
        (rov.http, "/beacon/v1.0/services"),
        (rov.http, "/helper/v1.0/web_services"),
        (rov.streams, "/streams"),
    ] {
        let r = request(addr, "GET", path, &evil, b"");
        assert_eq!(
            r.header("access-control-allow-origin"),
            None,
            "{path} readable by {EVIL}"
        );
        let ok = request(addr, "GET", path, &[("Origin", COCKPIT)], b"");
        assert_eq!(ok.status, 200, "{path}");
        assert_eq!(
            ok.header("access-control-allow-origin").as_deref(),
            Some(COCKPIT),
            "{path}"
        );
    }
    let preflight = request(
        rov.http,
        "OPTIONS",
        SET_ID,
        &[
            ("Origin", COCKPIT),
            ("Access-Control-Request-Method", "POST"),
        ],
        b"",
    );
    assert_eq!(preflight.status, 204);
    assert_eq!(
        preflight.header("access-control-allow-origin").as_deref(),
        Some(COCKPIT)
    );
    // Not logged in: its own settings, the vehicle id once, nothing of others.
    let cockpit = [("Origin", COCKPIT)];
    assert_eq!(rov.set(SET_ID, b"\"first\"", &cockpit).status, 200);
    let again = rov.set(SET_ID, b"\"second\"", &cockpit);
    assert_eq!(again.status, 403, "{}", again.detail());
    assert!(
        again.detail().contains("only the pilot"),
        "{}",
        again.detail()
    );
    let mine = "/bag/v1.0/set/cockpit/settings-v2/guest/cockpit-views";
    assert_eq!(rov.set(mine, b"[1]", &cockpit).status, 200);
    assert_eq!(rov.set(mine, b"[2]", &cockpit).status, 200);
    // The card: at most 512 KiB for this address.
    let chunk = format!("\"{}\"", "x".repeat(200 * 1024));
    let mut full = None;
    for n in 0..4 {
        let r = rov.set(
            &format!("/bag/v1.0/set/cockpit/settings-v2/guest/big{n}"),
            chunk.as_bytes(),
            &cockpit,
        );
        if r.status != 200 {
            full = Some(r);
            break;
        }
    }
    let full = full.expect("an address that is not the pilot's cannot keep 800 KiB");
    assert_eq!(full.status, 507, "{}", full.detail());
    assert!(full.detail().contains("at most"), "{}", full.detail());
    // The pilot changes anything.
    let login = request(
        rov.http,
        "POST",
        "/api/login",
        &[("Content-Type", "application/json")],
        json!({"password": PASSWORD}).to_string().as_bytes(),
    );
    assert_eq!(login.status, 200);
    let cookie = login.header("set-cookie").unwrap();
    let cookie = cookie.split(';').next().unwrap();
    assert_eq!(
        rov.set(SET_ID, b"\"pilot's\"", &[("Cookie", cookie)])
            .status,
        200
    );
    assert_eq!(rov.set(mine, b"[3]", &[("Cookie", cookie)]).status, 200);
    assert_eq!(
        rov.set(mine, b"[4]", &cockpit).status,
        403,
        "now the pilot's"
    );
    assert_eq!(rov.get(ID).json(), json!("pilot's"));
}

/// The beacon lists the address the asker reached (a loopback alias is on
/// no interface's list) with its kind of link, the helper the HMI's page on
/// this port, `/streams` the one stream in mavlink-camera-manager's shape
/// named as the signalling names it.
#[test]
fn the_beacon_the_helper_and_streams_answer_as_blueos_does() {
    let tmp = tempfile::tempdir().unwrap();
    let ip = loopback_alias();
    let rov = Rov::start(tmp.path(), ip, "", false);
    let services = rov.get("/beacon/v1.0/services").json();
    let reached = services
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["ip"] == ip.to_string())
        .unwrap_or_else(|| panic!("{ip} not among {services}"));
    assert_eq!(reached["service_type"], "_http");
    assert_eq!(
        reached["interface_type"], "UNKNOWN",
        "loopback is no tether"
    );
    let name = rov.get("/beacon/v1.0/vehicle_name");
    assert_eq!(name.status, 200);
    assert!(!name.body.is_empty());
    let web = rov.get("/helper/v1.0/web_services").json();
    assert_eq!(web[0]["port"], rov.http.port());
    let streams = request(rov.streams, "GET", "/streams", &[], b"").json();
    let s = &streams[0];
    let offered = rov.get("/api/webrtc").json();
    assert_eq!(s["video_and_stream"]["name"], offered["streams"][0]["name"]);
    assert_eq!(s["id"], offered["streams"][0]["id"]);
    let c = &s["video_and_stream"]["stream_information"]["configuration"];
    assert_eq!(c["encode"], "H264");
    assert!(c["width"].as_u64().unwrap() > 0 && c["height"].as_u64().unwrap() > 0);
    assert!(c["frame_interval"]["denominator"].as_u64().unwrap() > 0);
    assert_eq!(s["state"], "idle", "nobody watches: the encoder waits");
    assert_eq!(s["running"], false);
}

/// A mavlink2rest WebSocket from `from` to `http`; the first text answer
/// to a MANUAL_CONTROL frame (`Ok(N)` for a pilot, `Err(…)` for a watcher).
async fn drives(from: IpAddr, http: SocketAddr, query: &str) -> String {
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.bind(SocketAddr::new(from, 0)).unwrap();
    let stream = sock.connect(http).await.unwrap();
    let url = format!("ws://{http}/mavlink2rest/ws/mavlink{query}");
    let (mut ws, _) = tokio_tungstenite::client_async(url, stream).await.unwrap();
    let frame = json!({"header": {"system_id": 255, "component_id": 240, "sequence": 0},
        "message": {"type": "MANUAL_CONTROL", "target": 1, "x": 0, "y": 0, "z": 500, "r": 0, "s": 0, "t": 0,
            "buttons": 0, "buttons2": 0, "enabled_extensions": 0}});
    ws.send(Message::text(frame.to_string())).await.unwrap();
    let end = tokio::time::Instant::now() + GENEROUS;
    loop {
        let m = tokio::time::timeout_at(end, ws.next())
            .await
            .expect("an answer")
            .unwrap()
            .unwrap();
        if let Message::Text(t) = m
            && (t.starts_with("Ok(") || t.starts_with("Err("))
        {
            return t.to_string();
        }
    }
}

/// The Cockpit link: made only for a logged-in page of the vehicle's own
/// origin; it logs Cockpit in (its frames drive) from the address that
/// first used it, never from another, and no longer once the login that
/// made it logged out.
#[tokio::test(flavor = "multi_thread")]
async fn a_cockpit_link_logs_cockpit_in_from_its_address_only() {
    let tmp = tempfile::tempdir().unwrap();
    let rov = tokio::task::block_in_place(|| {
        Rov::start(
            tmp.path(),
            IpAddr::from([127, 0, 0, 1]),
            "open_control = \"none\"",
            true,
        )
    });
    let http = rov.http;
    let post = move |path: &'static str, headers: Vec<(&'static str, String)>, body: Vec<u8>| {
        let h: Vec<(&str, &str)> = headers.iter().map(|(k, v)| (*k, v.as_str())).collect();
        request(http, "POST", path, &h, &body)
    };
    assert_eq!(
        post("/api/cockpit-link", vec![], vec![]).status,
        401,
        "not logged in"
    );
    let login = post(
        "/api/login",
        vec![("Content-Type", "application/json".into())],
        json!({"password": PASSWORD}).to_string().into_bytes(),
    );
    let cookie = login
        .header("set-cookie")
        .unwrap()
        .split(';')
        .next()
        .unwrap()
        .to_owned();
    let evil = post(
        "/api/cockpit-link",
        vec![("Cookie", cookie.clone()), ("Origin", EVIL.into())],
        vec![],
    );
    assert_eq!(evil.status, 403, "a foreign page with the pilot's cookie");
    let link = post(
        "/api/cockpit-link",
        vec![("Cookie", cookie.clone())],
        vec![],
    )
    .json();
    let url = link["mavlink"].as_str().unwrap();
    assert!(
        url.starts_with(&format!("ws://{http}/mavlink2rest/ws/mavlink?token=")),
        "{url}"
    );
    let query = &url[url.find('?').unwrap()..];
    let here = IpAddr::from([127, 0, 0, 1]);
    let there = IpAddr::from([127, 0, 0, 2]);
    assert!(
        drives(here, http, "").await.starts_with("Err("),
        "no link: watches"
    );
    assert!(
        drives(here, http, query).await.starts_with("Ok("),
        "the link logs Cockpit in"
    );
    assert!(
        drives(here, http, query).await.starts_with("Ok("),
        "and again on a reconnect"
    );
    assert!(
        drives(there, http, query).await.starts_with("Err("),
        "from another address: watches"
    );
    assert!(drives(here, http, "?token=0123").await.starts_with("Err("));
    post("/api/logout", vec![("Cookie", cookie)], vec![]);
    assert!(
        drives(here, http, query).await.starts_with("Err("),
        "logged out: watches"
    );
    assert!(
        rov.log().contains("Cockpit link"),
        "the void link is logged"
    );
}

/// A WebRTC viewer is offered one host address, the one its signalling
/// connection reached — also a loopback alias no interface lists (the
/// vehicle binds a media socket there).
#[tokio::test(flavor = "multi_thread")]
async fn a_viewer_is_offered_the_address_it_reached() {
    let tmp = tempfile::tempdir().unwrap();
    let ip = loopback_alias();
    let rov = tokio::task::block_in_place(|| Rov::start(tmp.path(), ip, "", false));
    let (mut ws, _) = tokio_tungstenite::connect_async(format!("ws://{}/", rov.signalling))
        .await
        .unwrap();
    let q =
        |content: Value| Message::text(json!({"type": "question", "content": content}).to_string());
    ws.send(q(json!({"type": "peerId"}))).await.unwrap();
    ws.send(q(json!({"type": "availableStreams"})))
        .await
        .unwrap();
    let mut consumer = None;
    let mut producer = None;
    let mut sdp = None;
    let mut trickled = Vec::new();
    let end = tokio::time::Instant::now() + GENEROUS;
    while sdp.is_none() || trickled.is_empty() {
        let m = tokio::time::timeout_at(end, ws.next())
            .await
            .expect("the offer")
            .unwrap()
            .unwrap();
        let Message::Text(t) = m else { continue };
        let v: Value = serde_json::from_str(&t).unwrap();
        let c = &v["content"];
        match (v["type"].as_str(), c["type"].as_str()) {
            (Some("answer"), Some("peerId")) => {
                consumer = c["content"]["id"].as_str().map(str::to_owned)
            }
            (Some("answer"), Some("availableStreams")) => {
                producer = c["content"][0]["id"].as_str().map(str::to_owned)
            }
            (Some("negotiation"), Some("mediaNegotiation")) => {
                sdp = c["content"]["sdp"]["sdp"].as_str().map(str::to_owned)
            }
            (Some("negotiation"), Some("iceNegotiation")) => trickled.push(
                c["content"]["ice"]["candidate"]
                    .as_str()
                    .unwrap()
                    .to_owned(),
            ),
            _ => {}
        }
        if let (Some(c), Some(p)) = (&consumer, &producer) {
            ws.send(q(
                json!({"type": "startSession", "content": {"consumer_id": c, "producer_id": p}}),
            ))
            .await
            .unwrap();
            producer = None;
        }
    }
    let sdp = sdp.unwrap();
    let offered: Vec<&str> = sdp
        .lines()
        .filter(|l| l.starts_with("a=candidate"))
        .chain(trickled.iter().map(String::as_str))
        .collect();
    assert!(!offered.is_empty());
    for c in &offered {
        let addr = c.split_whitespace().nth(4).unwrap();
        assert_eq!(
            addr,
            ip.to_string(),
            "a candidate not on the address reached: {c}"
        );
    }
    assert!(
        rov.log().contains(&format!("media socket local={ip}:")),
        "no media socket on {ip}"
    );
}
