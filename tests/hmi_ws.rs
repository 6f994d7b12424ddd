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
use neptunus::firmware::emulator::{BoardControl, PtyBoard};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio_tungstenite::tungstenite::Message;

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

impl HmiRig {
    /// `hmi_toml` is the body of an `[hmi]` section (may be empty).
    fn start(hmi_toml: &str) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let board = spawn_board_here();
        let serial = board.path().to_string_lossy().into_owned();
        let config = dir.path().join("neptunus.toml");
        std::fs::write(&config, format!("[hmi]\n{hmi_toml}\n")).unwrap();
        let gcs_port = common::free_udp_port().unwrap();
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
        let (ws, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws"))
            .await
            .unwrap();
        let mut c = Self {
            ws,
            welcome: Value::Null,
            seen: Vec::new(),
        };
        c.welcome = c.wait("welcome", |_| true).await;
        c
    }

    fn sysid(&self) -> Option<u64> {
        self.welcome["sysid"].as_u64()
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

async fn http_get(addr: SocketAddr, path: &str) -> (u16, String, String) {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(format!("GET {path} HTTP/1.0\r\nHost: x\r\n\r\n").as_bytes())
        .await
        .unwrap();
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
    assert_eq!(a.sysid(), Some(200), "{}", a.welcome);
    assert_eq!(b.sysid(), Some(201), "{}", b.welcome);
    assert_eq!(a.welcome["pilot"], true);
    assert_eq!(a.welcome["password_required"], false);
    let t = a
        .telemetry_until(|t| {
            t["heading_deg"].is_number() && t["depth_m"].is_number() && t["vehicle_seen"] == true
        })
        .await;
    assert_eq!(t["mode_name"], "MANUAL", "{t}");
    b.telemetry_until(|t| t["vehicle_seen"] == true).await;
    // A closed session gives its sysid back.
    drop(a);
    let end = Instant::now() + GENEROUS;
    loop {
        let c = rig.connect().await;
        if c.sysid() == Some(200) {
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
    let mut rig = HmiRig::start("pilot_password = \"tide-pool-42\"");
    let mut c = rig.connect().await;
    assert_eq!(c.welcome["password_required"], true);
    assert_eq!(c.welcome["pilot"], false);
    c.ready().await;
    c.send(json!({"type": "request_control"})).await;
    let ack = c.ack("REQUEST_OPERATOR_CONTROL").await;
    assert_eq!(ack["result_name"], "DENIED", "{ack}");
    c.send(json!({"type": "arm", "arm": true})).await;
    let ack = c.ack("COMPONENT_ARM_DISARM").await;
    assert_ne!(ack["result_name"], "ACCEPTED", "{ack}");
    c.send(json!({"type": "login", "password": "tide-pool-41"}))
        .await;
    let r = c.wait("login_result", |_| true).await;
    assert_eq!(r["ok"], false);
    c.send(json!({"type": "login", "password": "tide-pool-42"}))
        .await;
    let r = c.wait("login_result", |_| true).await;
    assert_eq!(r["ok"], true);
    c.send(json!({"type": "request_control"})).await;
    c.wait("control", |v| v["you"] == true).await;
    drop(c);
    rig.vehicle.check_running().unwrap();
    let log = rig.vehicle.stderr_text();
    assert!(
        !log.contains("tide-pool"),
        "the password leaked into the log"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn handover_between_sessions_and_watch_only_when_ids_run_out() {
    let rig = HmiRig::start("sysid_min = 200\nsysid_max = 201");
    let mut a = rig.connect().await;
    let mut b = rig.connect().await;
    let mut c = rig.connect().await;
    assert_eq!(c.sysid(), None);
    assert!(
        c.welcome["watch_only_reason"]
            .as_str()
            .unwrap()
            .contains("in use"),
        "{}",
        c.welcome
    );
    c.send(json!({"type": "request_control"})).await;
    c.wait("error", |_| true).await;
    a.ready().await;
    a.send(json!({"type": "request_control"})).await;
    a.wait("control", |v| v["you"] == true).await;
    // b asks; a is asked and refuses; then b asks again and a accepts.
    b.send(json!({"type": "request_control"})).await;
    let req = a.wait("control_request", |_| true).await;
    assert_eq!(req["requester"], 201);
    a.send(json!({"type": "answer_request", "accept": false}))
        .await;
    b.wait("statustext", |s| {
        s["text"].as_str().unwrap().contains("refused by GCS 200")
    })
    .await;
    b.send(json!({"type": "request_control"})).await;
    a.wait("control_request", |_| true).await;
    a.send(json!({"type": "answer_request", "accept": true}))
        .await;
    b.wait("control", |v| v["you"] == true && v["owner"] == 201)
        .await;
    a.wait("control", |v| v["you"] == false).await;
    // The watcher sees it as well.
    c.wait("control", |v| v["owner"] == 201).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rest_api_and_assets() {
    let rig = HmiRig::start("");
    let mut c = rig.connect().await;
    c.ready().await;
    let (status, head, body) = rig.get("/api/status").await;
    assert_eq!(status, 200, "{head}");
    let v: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(v["vehicle_sysid"], 1);
    assert_eq!(v["sessions_max"], 10);
    assert_eq!(v["sessions_free"], 9, "{v}");
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
