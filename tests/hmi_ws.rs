//! The browser HMI's WebSocket protocol and REST API against the real
//! binary: `neptunus --serial <pty> --http 127.0.0.1:0` on a board emulator
//! in this process, and tokio-tungstenite clients standing in for browsers.
//!
//! Every wait is for a condition with a generous deadline (a child process
//! and a real tty: time is real); nothing sleeps to let time pass.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::net::SocketAddr;
use std::path::Path;
use std::time::{Duration, Instant};

use common::{NEUTRAL_US, Vehicle};
use futures_util::{SinkExt as _, StreamExt as _};
use neptunus::dialect::neptunus::*;
use neptunus::firmware::emulator::{BoardControl, PtyBoard};
use neptunus::mavlink::frame::{FrameStats, decode_datagram, encode_v2};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::http::HeaderValue;

const GENEROUS: Duration = Duration::from_secs(20);

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

/// The vehicle on an emulated board, with its HMI on a free port.
struct HmiRig {
    vehicle: Vehicle,
    board: PtyBoard,
    http: SocketAddr,
    _dir: tempfile::TempDir,
}

/// Runs `neptunus ARGS --data-dir DATA` with `stdin` piped in; panics on failure.
fn cli(data: &Path, args: &[&str], stdin: &str) -> String {
    let out = common::run_cli(bin(), data, args, stdin);
    assert!(
        out.status.success(),
        "neptunus {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

const PASSWORD: &str = "tide-pool-42";

impl HmiRig {
    /// `hmi_toml` is the body of an `[hmi]` section (may be empty).
    fn start(hmi_toml: &str) -> Self {
        Self::start_with(hmi_toml, |_| {})
    }

    /// Like [`start`](Self::start), after `setup` ran on the data directory
    /// (e.g. the CLI setting a password or a signing key).
    fn start_with(hmi_toml: &str, setup: impl FnOnce(&Path)) -> Self {
        let gcs_port = common::free_udp_port().unwrap();
        Self::start_full(hmi_toml, setup, gcs_port)
    }

    /// The rig with a raw MAVLink ground station on UDP: the vehicle sends
    /// to it (`udpout`) and hears it back.
    async fn start_with_station(hmi_toml: &str) -> (Self, Station) {
        let station = Station::bind().await;
        let port = station.sock.local_addr().unwrap().port();
        (Self::start_full(hmi_toml, |_| {}, port), station)
    }

    fn start_full(hmi_toml: &str, setup: impl FnOnce(&Path), gcs_port: u16) -> Self {
        let dir = tempfile::tempdir().unwrap();
        setup(&dir.path().join("data"));
        let board = spawn_board_here();
        let serial = board.path().to_string_lossy().into_owned();
        let config = dir.path().join("neptunus.toml");
        // A real board here, so the vehicle's default is "every browser
        // logs in"; a test bench opens control to loopback unless the test
        // says otherwise.
        let open = if hmi_toml.contains("open_control") {
            ""
        } else {
            "open_control = \"loopback\"\n"
        };
        std::fs::write(&config, format!("[hmi]\n{open}{hmi_toml}\n")).unwrap();
        let mut vehicle = Vehicle::spawn(
            bin(),
            &[
                "--serial",
                &serial,
                "--mavlink",
                &format!("udpout:127.0.0.1:{gcs_port}"),
                "--config",
                config.to_str().unwrap(),
            ],
            dir.path(),
            "",
        )
        .unwrap();
        let http = vehicle.http_addr(GENEROUS).unwrap();
        Self {
            vehicle,
            board,
            http,
            _dir: dir,
        }
    }

    fn control(&self) -> BoardControl {
        self.board.control()
    }

    async fn connect(&self) -> Client {
        Client::connect(self.http).await
    }

    async fn get(&self, path: &str) -> (u16, String, String) {
        http_get(self.http, path).await
    }

    /// Any request; `headers` are extra lines (`Name: value`).
    async fn request(
        &self,
        method: &str,
        path: &str,
        headers: &[String],
        body: &str,
    ) -> (u16, String, String) {
        http_request(self.http, method, path, headers, body).await
    }

    /// `POST /api/login`; the login cookie (`name=value`) on success.
    async fn login(&self, password: &str) -> (u16, Value, Option<String>) {
        let (status, head, body) = self
            .request(
                "POST",
                "/api/login",
                &["Content-Type: application/json".into()],
                &json!({ "password": password }).to_string(),
            )
            .await;
        let cookie = head
            .lines()
            .find_map(|l| {
                l.strip_prefix("set-cookie: ")
                    .or(l.strip_prefix("Set-Cookie: "))
            })
            .map(|c| c.split(';').next().unwrap().to_owned());
        (
            status,
            serde_json::from_str(&body).unwrap_or(Value::Null),
            cookie,
        )
    }

    /// The vehicle's stderr (its log, RUST_LOG=warn).
    fn log(&self) -> String {
        self.vehicle.stderr_text()
    }
}

/// The rig with a pilot password set by the CLI before the start.
fn with_password(hmi_toml: &str) -> HmiRig {
    HmiRig::start_with(hmi_toml, |data| {
        cli(data, &["hmi", "set-password"], &format!("{PASSWORD}\n"));
    })
}

/// The board emulator runs on the test's own runtime.
fn spawn_board_here() -> PtyBoard {
    let rt = tokio::runtime::Handle::current();
    let _guard = rt.enter();
    PtyBoard::spawn(Default::default(), None).unwrap()
}

type Ws =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// A protocol client: sends JSON, waits for messages that match.
struct Client {
    ws: Ws,
    welcome: Value,
    seen: Vec<Value>,
}

impl Client {
    async fn connect(addr: SocketAddr) -> Self {
        Self::connect_with(addr, &[]).await.unwrap()
    }

    /// Connects with extra request headers; the HTTP status when refused.
    async fn connect_with(
        addr: SocketAddr,
        headers: &[(&str, &str)],
    ) -> Result<Self, (u16, String)> {
        let mut req = format!("ws://{addr}/ws").into_client_request().unwrap();
        for (k, v) in headers {
            let name: tokio_tungstenite::tungstenite::http::HeaderName = k.parse().unwrap();
            req.headers_mut()
                .insert(name, HeaderValue::from_str(v).unwrap());
        }
        let ws = match tokio_tungstenite::connect_async(req).await {
            Ok((ws, _)) => ws,
            Err(tokio_tungstenite::tungstenite::Error::Http(r)) => {
                let body = String::from_utf8_lossy(r.body().as_deref().unwrap_or_default());
                return Err((r.status().as_u16(), body.into_owned()));
            }
            Err(e) => panic!("WebSocket connect failed: {e}"),
        };
        let mut c = Self {
            ws,
            welcome: Value::Null,
            seen: Vec::new(),
        };
        c.welcome = c.wait("welcome", |_| true).await;
        Ok(c)
    }

    fn sysid(&self) -> Option<u64> {
        self.welcome["sysid"].as_u64()
    }

    /// Asks for control and waits until this session has it; its system id.
    async fn take_control(&mut self) -> u64 {
        self.send(json!({"type": "request_control"})).await;
        let c = self.wait("control", |c| c["you"] == true).await;
        c["owner"].as_u64().unwrap()
    }

    /// Sends `login` and returns the `login_result`.
    async fn ws_login(&mut self, password: &str) -> Value {
        self.send(json!({"type": "login", "password": password}))
            .await;
        self.wait("login_result", |_| true).await
    }

    async fn send(&mut self, v: Value) {
        self.ws.send(Message::text(v.to_string())).await.unwrap();
    }

    async fn send_raw(&mut self, m: Message) {
        self.ws.send(m).await.unwrap();
    }

    /// The next message of `kind` for which `pred` holds (others are kept in `seen`).
    async fn wait(&mut self, kind: &str, pred: impl Fn(&Value) -> bool) -> Value {
        self.try_wait(kind, GENEROUS, pred)
            .await
            .unwrap_or_else(|| panic!("no {kind} message as expected within {GENEROUS:?}"))
    }

    async fn try_wait(
        &mut self,
        kind: &str,
        within: Duration,
        pred: impl Fn(&Value) -> bool,
    ) -> Option<Value> {
        let end = tokio::time::Instant::now() + within;
        loop {
            let m = tokio::time::timeout_at(end, self.ws.next()).await.ok()??;
            let Ok(Message::Text(t)) = m else { continue };
            let v: Value = serde_json::from_str(t.as_str()).unwrap();
            let hit = v["type"] == kind && pred(&v);
            self.seen.push(v.clone());
            if hit {
                return Some(v);
            }
        }
    }

    /// The next telemetry for which `pred` holds.
    async fn telemetry_until(&mut self, pred: impl Fn(&Value) -> bool) -> Value {
        self.wait("telemetry", pred).await
    }

    /// Waits until the vehicle is ready to arm (pre-arm checks pass).
    async fn ready(&mut self) {
        self.telemetry_until(|t| t["health"]["prearm"] == true && t["vehicle_seen"] == true)
            .await;
    }

    async fn ack(&mut self, command_name: &str) -> Value {
        let name = command_name.to_owned();
        self.wait("ack", move |a| a["command_name"] == name.as_str())
            .await
    }
}

/// A bare MAVLink station on UDP, as pymavlink would be: sysid 255
/// (SYSID_MYGCS, an allowed station), talking to a `udpout` vehicle.
struct Station {
    sock: tokio::net::UdpSocket,
    seq: u8,
    /// Everything the vehicle sent it.
    seen: Vec<MavMessage>,
}

impl Station {
    const SYSID: u8 = 255;

    async fn bind() -> Self {
        Self {
            sock: tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap(),
            seq: 0,
            seen: Vec::new(),
        }
    }

    /// Waits for the vehicle's first datagram, then talks to its sender.
    async fn await_vehicle(&mut self) {
        let mut buf = [0u8; 2048];
        let (_, from) = tokio::time::timeout(GENEROUS, self.sock.recv_from(&mut buf))
            .await
            .expect("no datagram from the vehicle")
            .unwrap();
        self.sock.connect(from).await.unwrap();
    }

    async fn send(&mut self, msg: &MavMessage) {
        let bytes = encode_v2(Self::SYSID, 190, self.seq, msg);
        self.seq = self.seq.wrapping_add(1);
        self.sock.send(&bytes).await.unwrap();
    }

    async fn command(&mut self, command: MavCmd, param1: f32, param2: f32) {
        self.send(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1,
            param2,
            command,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        }))
        .await;
    }

    /// Reads the vehicle until `pred` holds for one of its messages.
    async fn wait(&mut self, what: &str, pred: impl Fn(&MavMessage) -> bool) -> MavMessage {
        let end = tokio::time::Instant::now() + GENEROUS;
        let mut buf = [0u8; 4096];
        loop {
            let n = tokio::time::timeout_at(end, self.sock.recv(&mut buf))
                .await
                .unwrap_or_else(|_| panic!("the station got no {what}"))
                .unwrap();
            let mut frames = Vec::new();
            decode_datagram(&buf[..n], &mut FrameStats::default(), &mut frames);
            for f in frames {
                let hit = pred(&f.msg);
                self.seen.push(f.msg.clone());
                if hit {
                    return f.msg;
                }
            }
        }
    }
}

fn statustext_of(m: &MavMessage) -> Option<String> {
    match m {
        MavMessage::STATUSTEXT(s) => {
            let b: &[u8] = s.text.as_ref();
            Some(String::from_utf8_lossy(b).trim_end_matches('\0').to_owned())
        }
        _ => None,
    }
}

async fn http_get(addr: SocketAddr, path: &str) -> (u16, String, String) {
    http_request(addr, "GET", path, &[], "").await
}

/// One HTTP/1.0 request with `Host: ADDR` unless `headers` give one.
async fn http_request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[String],
    body: &str,
) -> (u16, String, String) {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let mut req = format!("{method} {path} HTTP/1.0\r\n");
    if !headers
        .iter()
        .any(|h| h.to_lowercase().starts_with("host:"))
    {
        req.push_str(&format!("Host: {addr}\r\n"));
    }
    for h in headers {
        req.push_str(&format!("{h}\r\n"));
    }
    req.push_str(&format!("Content-Length: {}\r\n\r\n{body}", body.len()));
    s.write_all(req.as_bytes()).await.unwrap();
    let mut buf = Vec::new();
    tokio::time::timeout(GENEROUS, s.read_to_end(&mut buf))
        .await
        .unwrap()
        .unwrap();
    let text = String::from_utf8_lossy(&buf).into_owned();
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (status, head.to_owned(), body.to_owned())
}

/// Sends full-forward sticks at 20 Hz until the board's motors leave
/// neutral; returns the snapshot's motors.
async fn drive_until_moving(c: &mut Client, board: &BoardControl) -> [u16; 3] {
    let end = Instant::now() + GENEROUS;
    loop {
        c.send(json!({"type": "sticks", "surge": 1.0, "heave_up": 0.0, "yaw": 0.0}))
            .await;
        c.try_wait("none", Duration::from_millis(50), |_| false)
            .await;
        let m = board.snapshot().motors_us;
        if m != NEUTRAL_US {
            return m;
        }
        assert!(Instant::now() < end, "motors stayed neutral while driving");
    }
}

/// Waits for the board's motors to be neutral.
async fn wait_neutral(board: &BoardControl) {
    let end = Instant::now() + GENEROUS;
    while board.snapshot().motors_us != NEUTRAL_US {
        assert!(
            Instant::now() < end,
            "motors not neutral: {:?}",
            board.snapshot()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_get_telemetry_and_distinct_sysids() {
    let rig = HmiRig::start("");
    let mut a = rig.connect().await;
    let mut b = rig.connect().await;
    // Loopback may pilot (open_control "loopback"), but an id is lent only
    // when the session first asks for something that needs one.
    assert_eq!(a.sysid(), None, "{}", a.welcome);
    assert_eq!(a.welcome["pilot"], true);
    assert_eq!(a.welcome["password_required"], false);
    assert!(a.welcome["watch_only_reason"].is_null(), "{}", a.welcome);
    a.send(json!({"type": "lights", "level": 10})).await;
    let id = a.wait("identity", |_| true).await;
    assert_eq!(id["sysid"], 200, "{id}");
    b.send(json!({"type": "lights", "level": 20})).await;
    assert_eq!(b.wait("identity", |_| true).await["sysid"], 201);
    let t = a
        .telemetry_until(|t| {
            t["heading_deg"].is_number() && t["depth_m"].is_number() && t["vehicle_seen"] == true
        })
        .await;
    assert_eq!(t["mode_name"], "MANUAL", "{t}");
    // Each kind of data says how old it is: fresh while the board talks
    // (once the vehicle reported its link up: the battery reading counts
    // from then on).
    let t = a
        .telemetry_until(|t| t["critical"] == false && t["ages_ms"]["battery"].is_number())
        .await;
    for kind in ["heartbeat", "attitude", "depth", "battery"] {
        let age = t["ages_ms"][kind].as_u64();
        assert!(age.is_some_and(|a| a < 3000), "{kind}: {t}");
    }
    assert_eq!(t["failsafes"], json!([]), "{t}");
    b.telemetry_until(|t| t["vehicle_seen"] == true).await;
    // A closed session gives its sysid back.
    drop(a);
    let end = Instant::now() + GENEROUS;
    loop {
        let mut c = rig.connect().await;
        c.send(json!({"type": "lights", "level": 10})).await;
        if c.wait("identity", |_| true).await["sysid"] == 200 {
            break;
        }
        assert!(Instant::now() < end, "sysid 200 never came back");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn control_drive_and_close_releases_and_stops() {
    let rig = HmiRig::start("");
    let board = rig.control();
    let mut pilot = rig.connect().await;
    let mut watcher = rig.connect().await;
    pilot.ready().await;
    pilot.send(json!({"type": "request_control"})).await;
    let c = pilot.wait("control", |c| c["you"] == true).await;
    assert_eq!(c["owner"], 200);
    watcher
        .wait("control", |c| c["owner"] == 200 && c["you"] == false)
        .await;
    pilot.send(json!({"type": "arm", "arm": true})).await;
    let ack = pilot.ack("COMPONENT_ARM_DISARM").await;
    assert_eq!(ack["result_name"], "ACCEPTED", "{ack}");
    let motors = drive_until_moving(&mut pilot, &board).await;
    assert_ne!(motors, NEUTRAL_US);
    // The session's view shows the thrusters move too.
    pilot
        .telemetry_until(|t| {
            t["armed"] == true
                && t["thrusters_us"]["starboard"]
                    .as_u64()
                    .is_some_and(|s| s != 1500)
        })
        .await;
    // Closing the socket, however abruptly, releases control and stops.
    drop(pilot);
    watcher.wait("control", |c| c["owner"].is_null()).await;
    wait_neutral(&board).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn focus_lost_stops_the_owner() {
    let rig = HmiRig::start("");
    let board = rig.control();
    let mut pilot = rig.connect().await;
    pilot.ready().await;
    pilot.send(json!({"type": "request_control"})).await;
    pilot.wait("control", |c| c["you"] == true).await;
    pilot.send(json!({"type": "arm", "arm": true})).await;
    pilot.ack("COMPONENT_ARM_DISARM").await;
    drive_until_moving(&mut pilot, &board).await;
    pilot.send(json!({"type": "focus_lost"})).await;
    wait_neutral(&board).await;
    // Still in control and armed: only stopped.
    pilot
        .telemetry_until(|t| t["armed"] == true && t["control"]["you"] == true)
        .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_messages_get_errors_and_move_nothing() {
    let rig = HmiRig::start("");
    let board = rig.control();
    let mut c = rig.connect().await;
    c.ready().await;
    c.send(json!({"type": "request_control"})).await;
    c.wait("control", |v| v["you"] == true).await;
    c.send(json!({"type": "arm", "arm": true})).await;
    c.ack("COMPONENT_ARM_DISARM").await;
    let before = board.snapshot().executed_total;
    let bad: Vec<Message> = vec![
        Message::text("not json"),
        Message::text(r#"{"type":"warp_drive"}"#),
        Message::text(r#"{"type":"sticks","surge":5,"heave_up":0,"yaw":0}"#),
        Message::text(r#"{"type":"sticks","surge":NaN,"heave_up":0,"yaw":0}"#),
        Message::text(r#"{"type":"sticks","surge":1e999,"heave_up":0,"yaw":0}"#),
        Message::text(r#"{"type":"thrusters","port":"full","vertical":0,"starboard":0}"#),
        Message::text(r#"{"type":"mode","mode":4}"#),
        Message::text(r#"{"type":"lights","level":-1}"#),
        Message::text(r#"[1,2,3]"#),
        Message::binary(vec![0u8, 1, 2]),
    ];
    let n = bad.len();
    for m in bad {
        c.send_raw(m).await;
    }
    for _ in 0..n {
        let e = c.wait("error", |_| true).await;
        assert!(!e["message"].as_str().unwrap().is_empty());
    }
    // Still alive and talking, and nothing moved.
    c.telemetry_until(|t| t["armed"] == true).await;
    let after = board.snapshot();
    assert_eq!(after.motors_us, NEUTRAL_US, "{after:?}");
    let executed = after.executed_total - before;
    assert!(executed < 100, "unexpected commands executed: {executed}");
    // An oversized message closes that one connection, not the server.
    c.send_raw(Message::text(format!(
        r#"{{"type":"login","password":"{}"}}"#,
        "x".repeat(100_000)
    )))
    .await;
    let mut other = rig.connect().await;
    other.telemetry_until(|t| t["vehicle_seen"] == true).await;
    let (status, _, body) = rig.get("/api/status").await;
    assert_eq!(status, 200);
    let v: Value = serde_json::from_str(&body).unwrap();
    assert!(v["bad_web_messages"].as_u64().unwrap() >= n as u64, "{v}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pilot_password_gates_control() {
    let mut rig = with_password("open_control = \"none\"");
    // The CLI stored an argon2 PHC string, 0600, never the password itself.
    let file = rig._dir.path().join("data/hmi-password");
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(text.starts_with("$argon2id$"), "{text}");
    assert!(!text.contains(PASSWORD));
    use std::os::unix::fs::PermissionsExt as _;
    assert_eq!(
        std::fs::metadata(&file).unwrap().permissions().mode() & 0o777,
        0o600
    );
    let board = rig.control();
    let mut c = rig.connect().await;
    assert_eq!(c.welcome["password_required"], true);
    assert_eq!(c.welcome["pilot"], false);
    c.ready().await;
    for m in [
        json!({"type": "request_control"}),
        json!({"type": "arm", "arm": true}),
    ] {
        c.send(m).await;
        let e = c.wait("error", |_| true).await;
        assert!(e["message"].as_str().unwrap().contains("log in"), "{e}");
    }
    let r = c.ws_login("tide-pool-41").await;
    assert_eq!(r["ok"], false, "{r}");
    assert_eq!(r["message"], "wrong pilot password");
    let r = c.ws_login(PASSWORD).await;
    assert_eq!(r["ok"], true, "{r}");
    let id = c.wait("identity", |_| true).await;
    assert_eq!(id["sysid"], 200, "{id}");
    assert_eq!(id["logged_in"], true, "{id}");
    assert_eq!(c.take_control().await, 200);
    c.send(json!({"type": "arm", "arm": true})).await;
    assert_eq!(
        c.ack("COMPONENT_ARM_DISARM").await["result_name"],
        "ACCEPTED"
    );
    drive_until_moving(&mut c, &board).await;
    drop(c);
    wait_neutral(&board).await;
    rig.vehicle.check_running().unwrap();
    let log = rig.log();
    assert!(
        !log.contains("tide-pool"),
        "the password leaked into the log"
    );
}

/// C1: a page from another origin opens a WebSocket to the vehicle (the
/// browser adds its Origin), or a rebinding page reaches it under a foreign
/// host name. Both are refused before any session exists; the same-origin
/// page and scripts without an Origin still work.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn foreign_origin_and_rebinding_are_refused() {
    let rig = HmiRig::start("");
    let board = rig.control();
    let addr = rig.http;
    for _ in 0..30 {
        let r = Client::connect_with(addr, &[("Origin", "http://evil.example.com")]).await;
        assert_eq!(
            r.err().map(|e| e.0),
            Some(403),
            "a foreign origin got a session"
        );
    }
    let r = Client::connect_with(addr, &[("Host", "evil.example.com")]).await;
    assert_eq!(
        r.err().map(|e| e.0),
        Some(403),
        "a rebinding host got a session"
    );
    let r = Client::connect_with(addr, &[("Origin", "null")]).await;
    assert_eq!(r.err().map(|e| e.0), Some(403));
    // A state-changing request from the foreign page is refused too.
    let (status, _, body) = rig
        .request(
            "POST",
            "/api/login",
            &["Origin: http://evil.example.com".into()],
            r#"{"password":"x"}"#,
        )
        .await;
    assert_eq!(status, 403, "{body}");
    // DNS rebinding: the page and the REST API under a foreign name.
    for path in ["/", "/api/status", "/api/logs"] {
        let (status, _, body) = rig
            .request("GET", path, &["Host: evil.example.com:8080".into()], "")
            .await;
        assert_eq!(status, 403, "{path}: {body}");
        assert!(body.contains("host name"), "{body}");
    }
    // The vehicle's own page (same origin), and localhost, work.
    let mut own = Client::connect_with(addr, &[("Origin", &format!("http://{addr}"))])
        .await
        .unwrap();
    own.ready().await;
    let (status, _, _) = rig
        .request(
            "GET",
            "/",
            &[format!("Host: localhost:{}", addr.port())],
            "",
        )
        .await;
    assert_eq!(status, 200);
    // Nothing armed, nothing moved; no id was lent to the refused ones.
    let (_, _, body) = rig.get("/api/status").await;
    let v: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(v["sessions_free"], 10, "{v}");
    assert!(v["refused_requests"].as_u64().unwrap() >= 35, "{v}");
    assert_eq!(v["telemetry"]["armed"], false, "{v}");
    assert_eq!(board.snapshot().motors_us, NEUTRAL_US);
    // Counted, and logged once per burst, not per request.
    let lines = rig.log().lines().filter(|l| l.contains("refused")).count();
    assert!(
        (1..=3).contains(&lines),
        "{lines} log lines:\n{}",
        rig.log()
    );
}

/// With open_control "none" and no password, nobody can pilot from the
/// browser: sessions hold no id, arming is refused, and the page is told
/// how to set a password.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn open_control_none_without_login_cannot_arm() {
    let rig = HmiRig::start("open_control = \"none\"");
    let mut c = rig.connect().await;
    assert_eq!(c.welcome["pilot"], false, "{}", c.welcome);
    let why = c.welcome["watch_only_reason"].as_str().unwrap().to_owned();
    assert!(why.contains("neptunus hmi set-password"), "{why}");
    c.ready().await;
    c.send(json!({"type": "arm", "arm": true})).await;
    c.wait("error", |_| true).await;
    c.send(json!({"type": "sticks", "surge": 1.0, "heave_up": 0.0, "yaw": 0.0}))
        .await;
    c.send(json!({"type": "login", "password": "anything"}))
        .await;
    let r = c.wait("login_result", |_| true).await;
    assert!(
        r["message"].as_str().unwrap().contains("set-password"),
        "{r}"
    );
    c.telemetry_until(|t| t["armed"] == false && t["control"]["owner"].is_null())
        .await;
    let (_, _, body) = rig.get("/api/status").await;
    let v: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(v["sessions_free"], 10, "{v}");
    assert_eq!(rig.control().snapshot().motors_us, NEUTRAL_US);
    // The records are for those who may pilot; what a watcher sees is open.
    assert_eq!(rig.get("/api/logs").await.0, 401);
    assert_eq!(rig.get("/api/params").await.0, 200);
    assert_eq!(rig.get("/api/status").await.0, 200);
}

/// C2: with MAVLink signing on, a browser session that did not log in
/// cannot arm or drive, even from loopback; after the login it can.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn signing_on_needs_the_pilot_login() {
    let rig = HmiRig::start_with("", |data| {
        cli(data, &["signing", "set-passphrase"], "long and secret\n");
        cli(data, &["hmi", "set-password"], &format!("{PASSWORD}\n"));
    });
    let board = rig.control();
    let mut c = rig.connect().await;
    assert_eq!(c.welcome["pilot"], false, "{}", c.welcome);
    assert!(
        c.welcome["watch_only_reason"]
            .as_str()
            .unwrap()
            .contains("signing is on"),
        "{}",
        c.welcome
    );
    c.ready().await;
    c.send(json!({"type": "arm", "arm": true})).await;
    c.wait("error", |_| true).await;
    for _ in 0..20 {
        c.send(json!({"type": "sticks", "surge": 1.0, "heave_up": 0.0, "yaw": 0.0}))
            .await;
    }
    c.telemetry_until(|t| t["armed"] == false).await;
    assert_eq!(board.snapshot().motors_us, NEUTRAL_US);
    // With the login (cookie this time) it pilots.
    let (status, body, cookie) = rig.login(PASSWORD).await;
    assert_eq!(status, 200, "{body}");
    let cookie = cookie.unwrap();
    let mut p = Client::connect_with(rig.http, &[("Cookie", &cookie)])
        .await
        .unwrap();
    assert_eq!(p.welcome["logged_in"], true, "{}", p.welcome);
    assert_eq!(p.sysid(), Some(200), "{}", p.welcome);
    p.ready().await;
    p.take_control().await;
    p.send(json!({"type": "arm", "arm": true})).await;
    assert_eq!(
        p.ack("COMPONENT_ARM_DISARM").await["result_name"],
        "ACCEPTED"
    );
    drive_until_moving(&mut p, &board).await;
}

/// H4: ten sessions that never log in used to hold all ten ids; now they
/// hold none, and the pilot logs in and arms.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_sessions_do_not_lock_out_the_pilot() {
    let rig = with_password("open_control = \"none\"");
    let mut idle = Vec::new();
    for _ in 0..10 {
        idle.push(rig.connect().await);
    }
    assert!(idle.iter().all(|c| c.sysid().is_none()));
    let mut p = rig.connect().await;
    let r = p.ws_login(PASSWORD).await;
    assert_eq!(r["ok"], true, "{r}");
    p.ready().await;
    assert_eq!(p.take_control().await, 200);
    p.send(json!({"type": "arm", "arm": true})).await;
    assert_eq!(
        p.ack("COMPONENT_ARM_DISARM").await["result_name"],
        "ACCEPTED"
    );
    // The watchers still hold nothing.
    assert!(idle.iter().all(|c| c.sysid().is_none()));
}

/// H8: guessing the password as fast as one WebSocket allows gets a few
/// real checks a second at most, and a handful of log lines, not thousands.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn password_guessing_is_throttled_and_quiet() {
    let rig = with_password("open_control = \"none\"");
    let mut c = rig.connect().await;
    let (mut checked, mut waited) = (0u32, 0u32);
    let start = Instant::now();
    let mut i = 0;
    while start.elapsed() < Duration::from_secs(3) {
        i += 1;
        let r = c.ws_login(&format!("guess-{i}")).await;
        let m = r["message"].as_str().unwrap();
        if m == "wrong pilot password" {
            checked += 1;
        } else {
            assert!(m.starts_with("too many attempts — wait"), "{r}");
            waited += 1;
        }
    }
    // 3 free, then 1 s, 2 s: about 5 in 3 s (one more for slack).
    assert!(checked <= 6, "{checked} real checks in 3 s");
    assert!(waited > 10, "only {waited} attempts were throttled");
    // The REST login from the same address is throttled as well, unchecked.
    let (status, body, cookie) = rig.login(PASSWORD).await;
    assert_eq!(status, 429, "{body}");
    assert!(cookie.is_none());
    let log = rig.log();
    let lines = log.lines().filter(|l| l.contains("password")).count();
    assert!(lines <= 3, "{lines} log lines about passwords:\n{log}");
    assert!(!log.contains("guess-"), "a guess reached the log");
}

/// One read rule for the page, the REST API and mavlink2rest: with a pilot
/// password set, an HTTP client without the login reads what a watcher
/// sees everywhere (status, parameters, mavlink2rest's messages and
/// WebSocket) and nowhere the vehicle's records; nothing it sends acts.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_the_login_reading_follows_one_rule_everywhere() {
    let rig = with_password("open_control = \"none\"");
    let (status, _, body) = rig.get("/api/params").await;
    assert_eq!(status, 200, "{body}");
    let v: Value = serde_json::from_str(&body).unwrap();
    assert!(v["count"].as_u64().unwrap() > 100, "{v}");
    assert_eq!(rig.get("/api/status").await.0, 200);
    let (status, _, body) = rig
        .get("/mavlink2rest/mavlink/vehicles/1/components/1/messages/HEARTBEAT")
        .await;
    assert_eq!(status, 200, "{body}");
    assert!(body.contains("HEARTBEAT"), "{body}");
    // mavlink2rest's WebSocket admits a watcher, which hears the vehicle.
    let url = format!("ws://{}/mavlink2rest/ws/mavlink?filter=HEARTBEAT", rig.http);
    let (mut ws, _) = tokio_tungstenite::connect_async(url).await.unwrap();
    let heard = tokio::time::timeout(Duration::from_secs(20), async {
        while let Some(Ok(m)) = ws.next().await {
            if let Message::Text(t) = m
                && t.contains("HEARTBEAT")
            {
                return true;
            }
        }
        false
    })
    .await;
    assert_eq!(heard, Ok(true), "the watcher heard no HEARTBEAT");
    // The records are not for it, through any path.
    for path in ["/api/logs", "/api/logs/events/x", "/api/logs/tlogs/x"] {
        let (status, _, body) = rig.get(path).await;
        assert_eq!(status, 401, "{path}: {body}");
        assert!(body.contains("records are for pilots"), "{body}");
    }
    // Acting is not for it either.
    let arm = json!({"header": {"system_id": 255, "component_id": 240, "sequence": 0},
        "message": {"type": "COMMAND_LONG", "target_system": 1, "target_component": 1,
            "command": {"type": "MAV_CMD_COMPONENT_ARM_DISARM"}, "confirmation": 0,
            "param1": 1.0, "param2": 0.0, "param3": 0.0, "param4": 0.0,
            "param5": 0.0, "param6": 0.0, "param7": 0.0}});
    let (status, _, body) = rig
        .request(
            "POST",
            "/mavlink2rest/mavlink",
            &["Content-Type: application/json".into()],
            &arm.to_string(),
        )
        .await;
    assert_eq!(status, 401, "{body}");
    assert_eq!(rig.control().snapshot().motors_us, NEUTRAL_US);
}

/// L1: with a password, the vehicle's records need the login cookie
/// (HttpOnly, SameSite=Strict), and logging out ends it; what a watcher
/// sees does not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn records_need_the_login_cookie() {
    let rig = with_password("open_control = \"none\"");
    for path in ["/api/logs", "/api/logs/tlogs/x"] {
        let (status, _, body) = rig.get(path).await;
        assert_eq!(status, 401, "{path}: {body}");
        assert!(body.contains("log in"), "{body}");
    }
    for path in ["/api/status", "/api/params", "/api/video", "/"] {
        let (status, _, body) = rig.get(path).await;
        assert_eq!(status, 200, "{path}: {body}");
    }
    let (status, body, cookie) = rig.login("not-it-at-all").await;
    assert_eq!(
        (status, &body["message"]),
        (401, &json!("wrong pilot password"))
    );
    assert!(cookie.is_none());
    let (status, _, head_body) = rig
        .request("POST", "/api/login", &[], "{\"pass\": 1}")
        .await;
    assert_eq!(status, 400, "{head_body}");
    let (status, head, _) = rig
        .request(
            "POST",
            "/api/login",
            &["Content-Type: application/json".into()],
            &json!({ "password": PASSWORD }).to_string(),
        )
        .await;
    assert_eq!(status, 200, "{head}");
    let set = head
        .lines()
        .find(|l| l.to_lowercase().starts_with("set-cookie:"))
        .unwrap();
    for attr in ["HttpOnly", "SameSite=Strict", "Path=/", "Max-Age=43200"] {
        assert!(set.contains(attr), "{set}");
    }
    assert!(!set.contains("Secure"), "no TLS here: {set}");
    let cookie = format!("Cookie: {}", set[12..].trim().split(';').next().unwrap());
    let (status, _, body) = rig
        .request("GET", "/api/logs", std::slice::from_ref(&cookie), "")
        .await;
    assert_eq!(status, 200, "{body}");
    let (status, _, _) = rig
        .request("GET", "/api/status", std::slice::from_ref(&cookie), "")
        .await;
    assert_eq!(status, 200);
    let (status, _, _) = rig
        .request("POST", "/api/logout", std::slice::from_ref(&cookie), "")
        .await;
    assert_eq!(status, 200);
    let (status, _, _) = rig.request("GET", "/api/logs", &[cookie], "").await;
    assert_eq!(status, 401);
}

/// L5: sessions that only watch are capped; the cap says why.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watchers_are_capped() {
    let rig = HmiRig::start("max_watchers = 3\nopen_control = \"none\"");
    let mut w = Vec::new();
    for _ in 0..3 {
        w.push(rig.connect().await);
    }
    for _ in 0..5 {
        let (status, body) = Client::connect_with(rig.http, &[]).await.err().unwrap();
        assert_eq!(status, 503);
        assert!(body.contains("max_watchers"), "{body}");
    }
    // One leaves: a place is free again.
    drop(w.pop());
    let end = Instant::now() + GENEROUS;
    while Client::connect_with(rig.http, &[]).await.is_err() {
        assert!(Instant::now() < end, "the watcher's place never came back");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn handover_between_sessions_and_watch_only_when_ids_run_out() {
    let rig = HmiRig::start("sysid_min = 200\nsysid_max = 201");
    let mut a = rig.connect().await;
    let mut b = rig.connect().await;
    let mut c = rig.connect().await;
    a.ready().await;
    assert_eq!(a.take_control().await, 200);
    b.send(json!({"type": "lights", "level": 10})).await;
    assert_eq!(b.wait("identity", |_| true).await["sysid"], 201);
    // Both ids are held by pilots: the third may only watch, and is told why.
    c.send(json!({"type": "request_control"})).await;
    let e = c.wait("error", |_| true).await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("held by other pilots"),
        "{e}"
    );
    // b asks; a is asked and refuses; then b asks again and a accepts.
    b.send(json!({"type": "request_control"})).await;
    let req = a.wait("control_request", |_| true).await;
    assert_eq!(req["requester"], 201);
    // The requester reads that it waits for the owner, not that it failed
    // (the vehicle acks a forwarded request FAILED, as MAVLink says).
    let pending = b.wait("request_pending", |_| true).await;
    assert_eq!(pending["owner"], 200, "{pending}");
    assert_eq!(pending["timeout_s"], 10.0, "{pending}");
    a.send(json!({"type": "answer_request", "accept": false}))
        .await;
    let refused = b
        .wait("statustext", |s| {
            s["text"].as_str().unwrap().contains("refused by GCS 200")
        })
        .await;
    // Filed by the core under the logger's "Transfer of control", not
    // guessed by the page from its wording.
    assert_eq!(refused["category"], "control", "{refused}");
    b.send(json!({"type": "request_control"})).await;
    a.wait("control_request", |_| true).await;
    b.wait("request_pending", |p| p["owner"] == 200).await;
    a.send(json!({"type": "answer_request", "accept": true}))
        .await;
    b.wait("control", |v| v["you"] == true && v["owner"] == 201)
        .await;
    a.wait("control", |v| v["you"] == false).await;
    // The owner's yes was a release, and reads as one.
    let yes = a.ack("REQUEST_OPERATOR_CONTROL").await;
    assert_eq!(yes["text"], "Control release: done", "{yes}");
    // The watcher sees it as well.
    c.wait("control", |v| v["owner"] == 201).await;
    let failed: Vec<&Value> = b
        .seen
        .iter()
        .filter(|m| m["type"] == "ack" && m["result_name"] == "FAILED")
        .collect();
    assert!(
        failed.is_empty(),
        "the requester was told FAILED: {failed:?}"
    );
}

/// Replies the vehicle aims at one station reach that station alone: the
/// owner's page sees nothing of a watcher's or another ground station's
/// refused arm, mode change, lights and sticks.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_owner_sees_only_what_concerns_it() {
    let (rig, mut station) = HmiRig::start_with_station("").await;
    let mut owner = rig.connect().await;
    let mut other = rig.connect().await;
    owner.ready().await;
    assert_eq!(owner.take_control().await, 200);

    // Another browser session: arm, a mode, lights and sticks, all refused.
    other.send(json!({"type": "arm", "arm": true})).await;
    let ack = other.ack("COMPONENT_ARM_DISARM").await;
    assert_eq!(ack["result_name"], "NOT_IN_CONTROL", "{ack}");
    assert_eq!(ack["text"], "Arm/disarm: refused: not in control", "{ack}");
    other.send(json!({"type": "mode", "mode": 0})).await;
    other.ack("DO_SET_MODE").await;
    other.send(json!({"type": "lights", "level": 200})).await;
    other.ack("DO_ILLUMINATOR_CONFIGURE").await;
    other
        .send(json!({"type": "sticks", "surge": 1.0, "heave_up": 0.0, "yaw": 0.0}))
        .await;
    other
        .wait("statustext", |s| {
            s["text"].as_str().unwrap().starts_with("Ignoring")
        })
        .await;
    assert!(
        other.seen.iter().any(|m| m["type"] == "statustext"
            && m["text"]
                .as_str()
                .unwrap()
                .contains("Refused arm from sysid 201")),
        "{:?}",
        other.seen
    );

    // A MAVLink station on UDP does the same.
    station.await_vehicle().await;
    station
        .command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0)
        .await;
    station
        .wait("its arm ack", |m| {
            matches!(m, MavMessage::COMMAND_ACK(a)
                if a.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM
                    && a.result == MavResult::MAV_RESULT_NOT_IN_CONTROL)
        })
        .await;
    station.command(MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 2.0).await;
    station
        .send(&MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
            x: 800,
            z: 500,
            target: 1,
            ..Default::default()
        }))
        .await;
    station
        .wait("its refusal text", |m| {
            statustext_of(m).is_some_and(|t| t.contains("Ignoring") && t.contains("sysid 255"))
        })
        .await;
    assert!(
        station
            .seen
            .iter()
            .filter_map(statustext_of)
            .any(|t| t.contains("Refused arm from sysid 255")),
        "{:?}",
        station.seen
    );

    // Everything the vehicle said before the owner's own ack has reached
    // the owner's page by then (one ordered hub).
    owner.send(json!({"type": "lights", "level": 30})).await;
    let lights = owner.ack("DO_ILLUMINATOR_CONFIGURE").await;
    assert_eq!(lights["text"], "Lights: done", "{lights}");
    for m in &owner.seen {
        if m["type"] == "statustext" {
            let t = m["text"].as_str().unwrap();
            assert!(
                !t.contains("Refused") && !t.contains("Ignoring") && !t.contains("sysid"),
                "the owner saw a reply aimed at another station: {m}"
            );
        }
        if m["type"] == "ack" {
            assert!(
                m["command_name"] == "REQUEST_OPERATOR_CONTROL"
                    || (m["command_name"] == "DO_ILLUMINATOR_CONFIGURE"
                        && m["result_name"] == "ACCEPTED"),
                "the owner saw another station's ack: {m}"
            );
        }
    }
    // The station never heard the browser session's refusals either.
    assert!(
        !station
            .seen
            .iter()
            .filter_map(statustext_of)
            .any(|t| t.contains("sysid 201")),
        "{:?}",
        station.seen
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rest_api_and_assets() {
    let rig = HmiRig::start("");
    let mut c = rig.connect().await;
    c.ready().await;
    // The REST status follows the vehicle a few times a second, so it may
    // be a moment behind what the session just saw: read until it shows
    // the board's heading.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    let v = loop {
        let (status, head, body) = rig.get("/api/status").await;
        assert_eq!(status, 200, "{head}");
        let v: Value = serde_json::from_str(&body).unwrap();
        if v["telemetry"]["heading_deg"].is_number() || tokio::time::Instant::now() > deadline {
            break v;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(v["vehicle_sysid"], 1);
    assert_eq!(v["sessions_max"], 10);
    // A session that only watches holds no id.
    assert_eq!(v["sessions_free"], 10, "{v}");
    assert_eq!(v["watchers"], 1, "{v}");
    assert!(v["telemetry"]["heading_deg"].is_number(), "{v}");

    let (status, _, body) = rig.get("/api/params").await;
    assert_eq!(status, 200);
    let v: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(v["complete"], true, "{v}");
    assert!(v["params"]["JS_GAIN_DEFAULT"]["value"].as_f64().unwrap() > 0.0);
    assert_eq!(
        v["params"].as_object().unwrap().len() as u64,
        v["count"].as_u64().unwrap()
    );

    let (status, _, body) = rig.get("/api/logs").await;
    assert_eq!(status, 200);
    let v: Value = serde_json::from_str(&body).unwrap();
    let logs = v["logs"].as_array().unwrap();
    let tlog = logs
        .iter()
        .find(|l| l["kind"] == "tlogs")
        .unwrap_or_else(|| panic!("no tlog listed: {v}"));
    let (status, head, _) = rig.get(tlog["url"].as_str().unwrap()).await;
    assert_eq!(status, 200, "{head}");
    assert!(head.contains("attachment"), "{head}");
    for bad in [
        "/api/logs/tlogs/..%2F..%2Fparams.toml",
        "/api/logs/tlogs/../params.toml",
        "/api/logs/secrets/x",
        "/api/logs/events/..",
    ] {
        let (status, _, body) = rig.get(bad).await;
        assert!(status == 404 || status == 400, "{bad}: {status} {body}");
        assert!(!body.contains("SYSID"), "{bad} served a file: {body}");
    }
    // The page and its assets, with their MIME types.
    let (status, head, body) = rig.get("/").await;
    assert_eq!(status, 200);
    assert!(
        head.to_lowercase().contains("content-type: text/html"),
        "{head}"
    );
    assert!(body.contains("<html"), "{body}");
    for (path, mime) in [
        ("/js/main.js", "javascript"),
        ("/js/session.js", "javascript"),
        ("/js/view.js", "javascript"),
        ("/js/controls.js", "javascript"),
        ("/js/recorder.js", "javascript"),
        ("/js/dev.js", "javascript"),
        ("/css/style.css", "text/css"),
        ("/vendor/uPlot.esm.js", "javascript"),
        ("/vendor/uPlot.min.css", "text/css"),
    ] {
        let (status, head, _) = rig.get(path).await;
        assert_eq!(status, 200, "{path}: {head}");
        assert!(head.to_lowercase().contains(mime), "{path}: {head}");
    }
    let (status, _, _) = rig.get("/node_modules/uplot/package.json").await;
    assert_eq!(status, 404);
}

/// Depth hold from the browser protocol: ALT_HOLD, a depth setpoint, the
/// simulated vehicle goes there; then the run mode switch stops the board's
/// thrusters and the telemetry says "simulated".
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn depth_hold_setpoint_and_run_mode_from_the_page() {
    let rig = HmiRig::start("");
    let board = rig.control();
    let mut pilot = rig.connect().await;
    pilot.ready().await;
    pilot.send(json!({"type": "request_control"})).await;
    pilot.wait("control", |c| c["you"] == true).await;
    pilot.send(json!({"type": "arm", "arm": true})).await;
    let ack = pilot.ack("COMPONENT_ARM_DISARM").await;
    assert_eq!(ack["result_name"], "ACCEPTED", "{ack}");
    // Depth hold needs a depth: the board's first pressure reading comes
    // about a second after its set-up.
    pilot
        .telemetry_until(|t| t["health"]["depth"] == true)
        .await;
    pilot.send(json!({"type": "mode", "mode": 2})).await;
    let ack = pilot.ack("DO_SET_MODE").await;
    assert_eq!(ack["result_name"], "ACCEPTED", "{ack}");
    pilot
        .send(json!({"type": "autopilot_target", "depth_m": 1.0}))
        .await;
    let ack = pilot.ack("NEPTUNUS_SET_AUTOPILOT_TARGET").await;
    assert_eq!(ack["result_name"], "ACCEPTED", "{ack}");
    // A live page: alive and centred sticks at 5 Hz while it waits.
    let end = tokio::time::Instant::now() + GENEROUS * 2;
    let mut reached = None;
    while reached.is_none() && tokio::time::Instant::now() < end {
        pilot.send(json!({"type": "alive"})).await;
        pilot
            .send(json!({"type": "sticks", "surge": 0.0, "sway": 0.0, "heave_up": 0.0, "yaw": 0.0}))
            .await;
        reached = pilot
            .try_wait("telemetry", Duration::from_millis(200), |t| {
                t["autopilot"]["depth_target_m"].as_f64() == Some(1.0)
                    && t["depth_m"]
                        .as_f64()
                        .is_some_and(|d| (d - 1.0).abs() < 0.15)
            })
            .await;
    }
    let last = pilot.seen.iter().rev().find(|m| m["type"] == "telemetry");
    let t = reached
        .unwrap_or_else(|| panic!("the held depth was never reached; last telemetry {last:?}"));
    assert_eq!(t["mode"], 2, "{t}");
    // The simulator run mode: the board is stopped, the telemetry says so.
    pilot
        .send(json!({"type": "run_mode", "mode": "simulator"}))
        .await;
    let ack = pilot.ack("NEPTUNUS_SET_RUN_MODE").await;
    assert_eq!(ack["result_name"], "ACCEPTED", "{ack}");
    pilot.telemetry_until(|t| t["simulated"] == true).await;
    wait_neutral(&board).await;
}
