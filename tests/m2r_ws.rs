//! The mavlink2rest API against the real binary, with clients that speak
//! exactly Cockpit's frames: header system 255 component 240, HEARTBEAT
//! (GCS, bits 192), MANUAL_CONTROL every 40 ms with buttons2 and the
//! extensions, COMMAND_LONG with `confirmation` 0, PARAM_SET with a
//! NUL-padded `param_id` array of one-character strings, target component 0.
//! `neptunus --serial <pty>` runs on a board emulator in this process.
//!
//! Every wait is for a condition with a generous deadline (a child process
//! and a real tty: time is real); nothing sleeps to let time pass.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use common::{NEUTRAL_US, Vehicle};
use futures_util::{SinkExt as _, StreamExt as _};
use neptunus::firmware::emulator::{BoardControl, BoardSnapshot, PtyBoard};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::http::HeaderValue;

const GENEROUS: Duration = Duration::from_secs(20);
const PASSWORD: &str = "reef-lantern-7";
const NOT_CONVERTED: &str = "Could not convert input message.";

fn bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_neptunus"))
}

struct Rig {
    vehicle: Vehicle,
    board: PtyBoard,
    http: SocketAddr,
    _dir: tempfile::TempDir,
}

impl Rig {
    /// The vehicle on an emulated board; `hmi_toml` is the `[hmi]` body;
    /// `password` sets the pilot password first.
    fn start(hmi_toml: &str, password: bool) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("data");
        if password {
            let out = common::run_cli(
                bin(),
                &data,
                &["hmi", "set-password"],
                &format!("{PASSWORD}\n"),
            );
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        let board = {
            let _guard = tokio::runtime::Handle::current().enter();
            PtyBoard::spawn(Default::default(), None).unwrap()
        };
        let serial = board.path().to_string_lossy().into_owned();
        let config = dir.path().join("neptunus.toml");
        // As the HMI's tests do: loopback may pilot without a password
        // unless the test says otherwise (the vehicle's default is "none").
        let open = if hmi_toml.contains("open_control") {
            ""
        } else {
            "open_control = \"loopback\"\n"
        };
        std::fs::write(&config, format!("[hmi]\n{open}{hmi_toml}\n")).unwrap();
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

    async fn cockpit(&self) -> Cockpit {
        Cockpit::connect(self.http, "/mavlink2rest/ws/mavlink", 255, 240, &[])
            .await
            .unwrap()
    }
}

type Ws =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// A client speaking Cockpit's frames.
struct Cockpit {
    ws: Ws,
    sysid: u8,
    compid: u8,
    /// Answers to our frames (`Ok(N)`, `Could not convert…`, `Err(…)`, login).
    replies: VecDeque<String>,
    last_beat: Option<Instant>,
}

fn param_id(name: &str) -> Value {
    let mut chars: Vec<String> = name.chars().map(String::from).collect();
    chars.resize(16, "\u{0}".into());
    json!(chars)
}

fn chars_to_string(v: &Value) -> String {
    v.as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect::<String>()
        .trim_end_matches('\0')
        .to_owned()
}

fn command_long(command: &str, p: [f32; 7]) -> Value {
    json!({"type": "COMMAND_LONG", "param1": p[0], "param2": p[1], "param3": p[2], "param4": p[3],
        "param5": p[4], "param6": p[5], "param7": p[6], "command": {"type": command},
        "target_system": 1, "target_component": 1, "confirmation": 0})
}

fn manual_control(x: i16) -> Value {
    json!({"type": "MANUAL_CONTROL", "target": 1, "x": x, "y": 0, "z": 500, "r": 0, "s": 0, "t": 0,
        "buttons": 0, "buttons2": 0, "enabled_extensions": 0})
}

fn heartbeat() -> Value {
    json!({"type": "HEARTBEAT", "custom_mode": 0, "mavtype": {"type": "MAV_TYPE_GCS"},
        "autopilot": {"type": "MAV_AUTOPILOT_INVALID"}, "base_mode": {"bits": 192},
        "system_status": {"type": "MAV_STATE_ACTIVE"}, "mavlink_version": 2})
}

impl Cockpit {
    async fn connect(
        addr: SocketAddr,
        path: &str,
        sysid: u8,
        compid: u8,
        headers: &[(&str, &str)],
    ) -> Result<Self, (u16, String)> {
        let mut req = format!("ws://{addr}{path}").into_client_request().unwrap();
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
        Ok(Self {
            ws,
            sysid,
            compid,
            replies: VecDeque::new(),
            last_beat: None,
        })
    }

    async fn send_text(&mut self, text: String) {
        self.ws.send(Message::text(text)).await.unwrap();
    }

    async fn send(&mut self, message: Value) {
        let f = json!({"header": {"system_id": self.sysid, "component_id": self.compid, "sequence": 0},
            "message": message});
        self.send_text(f.to_string()).await;
    }

    /// Cockpit's HEARTBEAT, at most once a second.
    async fn beat(&mut self) {
        if self
            .last_beat
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
        {
            self.last_beat = Some(Instant::now());
            self.send(heartbeat()).await;
        }
    }

    /// The next frame (within `within`); answers are kept in `replies`.
    async fn next_frame(&mut self, within: Duration) -> Option<Value> {
        let end = Instant::now() + within;
        loop {
            let m = tokio::time::timeout_at(end, self.ws.next()).await.ok()??;
            let Ok(Message::Text(t)) = m else { continue };
            match serde_json::from_str::<Value>(t.as_str()) {
                Ok(v) if v.get("header").is_some() => return Some(v),
                _ => self.replies.push_back(t.as_str().to_owned()),
            }
        }
    }

    /// The next vehicle message `name` for which `pred` holds, sending
    /// Cockpit's HEARTBEAT meanwhile.
    async fn wait(&mut self, name: &str, pred: impl Fn(&Value) -> bool) -> Value {
        self.wait_sending(name, pred, false).await
    }

    /// As [`wait`](Self::wait), with neutral sticks every 40 ms meanwhile,
    /// as Cockpit sends them all the time (an armed vehicle that hears no
    /// pilot input for FS_PILOT_TIMEOUT disarms).
    async fn wait_with_sticks(&mut self, name: &str, pred: impl Fn(&Value) -> bool) -> Value {
        self.wait_sending(name, pred, true).await
    }

    async fn wait_sending(
        &mut self,
        name: &str,
        pred: impl Fn(&Value) -> bool,
        sticks: bool,
    ) -> Value {
        let end = Instant::now() + GENEROUS;
        let poll = Duration::from_millis(if sticks { 40 } else { 200 });
        let mut sticks_at: Option<Instant> = None;
        loop {
            self.beat().await;
            if sticks && sticks_at.is_none_or(|t| t.elapsed() >= poll) {
                sticks_at = Some(Instant::now());
                self.send(manual_control(0)).await;
            }
            assert!(
                Instant::now() < end,
                "no {name} as expected within {GENEROUS:?}"
            );
            let Some(f) = self.next_frame(poll).await else {
                continue;
            };
            if f["message"]["type"] == name && pred(&f["message"]) {
                return f;
            }
        }
    }

    /// The next vehicle message `name`, sending nothing meanwhile.
    async fn watch(&mut self, name: &str) -> Value {
        let end = Instant::now() + GENEROUS;
        loop {
            assert!(Instant::now() < end, "no {name} within {GENEROUS:?}");
            if let Some(f) = self.next_frame(Duration::from_millis(200)).await
                && f["message"]["type"] == name
            {
                return f;
            }
        }
    }

    /// The next answer to one of our frames.
    async fn reply(&mut self) -> String {
        let end = Instant::now() + GENEROUS;
        loop {
            if let Some(r) = self.replies.pop_front() {
                return r;
            }
            assert!(Instant::now() < end, "no answer within {GENEROUS:?}");
            let _ = self.next_frame(Duration::from_millis(200)).await;
        }
    }

    /// Sends a command and waits for its COMMAND_ACK's result.
    async fn command(&mut self, command: &str, p: [f32; 7]) -> String {
        self.send(command_long(command, p)).await;
        let ack = self
            .wait("COMMAND_ACK", |m| m["command"]["type"] == command)
            .await;
        ack["message"]["result"]["type"]
            .as_str()
            .unwrap()
            .to_owned()
    }

    /// Arms, asking again while pre-arm checks still fail.
    async fn arm(&mut self) {
        let end = Instant::now() + GENEROUS;
        loop {
            let r = self
                .command(
                    "MAV_CMD_COMPONENT_ARM_DISARM",
                    [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                )
                .await;
            if r == "MAV_RESULT_ACCEPTED" {
                return;
            }
            assert!(Instant::now() < end, "arming refused: {r}");
            self.wait("HEARTBEAT", |_| true).await;
        }
    }

    /// MANUAL_CONTROL every 40 ms (and the 1-Hz HEARTBEAT) until `done`
    /// holds for the board's last `go()` [port, vertical, starboard].
    async fn drive_until(&mut self, x: i16, board: &BoardControl, done: impl Fn([u16; 3]) -> bool) {
        self.drive_until_board(x, board, |s| done(s.target_us))
            .await;
    }

    /// As [`drive_until`](Self::drive_until), for anything the board knows
    /// (its simulator's motion too).
    async fn drive_until_board(
        &mut self,
        x: i16,
        board: &BoardControl,
        done: impl Fn(&BoardSnapshot) -> bool,
    ) {
        let end = Instant::now() + GENEROUS;
        loop {
            self.beat().await;
            self.send(manual_control(x)).await;
            let _ = self.next_frame(Duration::from_millis(40)).await;
            let s = board.snapshot();
            if done(&s) {
                return;
            }
            assert!(
                Instant::now() < end,
                "never as expected for x = {x}: go {:?}, surge {:.3} m/s",
                s.target_us,
                s.sim.surge_mps
            );
        }
    }
}

/// Forward in `go()` terms: starboard up, port down (it is wired reversed).
fn forward(m: [u16; 3]) -> bool {
    m[0] < 1500 && m[2] > 1500
}

fn reverse(m: [u16; 3]) -> bool {
    m[0] > 1500 && m[2] < 1500
}

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

/// One HTTP/1.0 request; (status, head, body).
async fn http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[&str],
    body: &str,
) -> (u16, String, String) {
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    let mut req = format!("{method} {path} HTTP/1.0\r\nHost: {addr}\r\n");
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

async fn get_json(addr: SocketAddr, path: &str) -> Value {
    let (status, _, body) = http(addr, "GET", path, &[], "").await;
    assert_eq!(status, 200, "GET {path}: {body}");
    serde_json::from_str(&body).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cockpit_sees_arms_changes_mode_drives_sets_a_parameter_and_reads_rest() {
    let rig = Rig::start("", false);
    let board = rig.control();
    let mut c = rig.cockpit().await;

    // Cockpit's vehicle: the first HEARTBEAT from component 1, ArduPilot + submarine.
    let hb = c
        .wait("HEARTBEAT", |m| {
            m["autopilot"]["type"] == "MAV_AUTOPILOT_ARDUPILOTMEGA"
        })
        .await;
    assert_eq!(hb["header"]["system_id"], 1);
    assert_eq!(hb["header"]["component_id"], 1);
    assert_eq!(hb["message"]["mavtype"]["type"], "MAV_TYPE_SUBMARINE");
    assert!(
        hb["message"]["base_mode"]["bits"].as_u64().unwrap() & 1 == 1,
        "CUSTOM_MODE_ENABLED: {hb}"
    );
    assert!(
        c.reply().await.starts_with("Ok("),
        "HEARTBEAT answered Ok(N)"
    );

    // ATTITUDE at 16 Hz, as Cockpit asks.
    let r = c
        .command(
            "MAV_CMD_SET_MESSAGE_INTERVAL",
            [30.0, 62_500.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await;
    assert_eq!(r, "MAV_RESULT_ACCEPTED");

    // Neutral sticks first (Cockpit's z = 500), then arm.
    c.drive_until(0, &board, |m| m == NEUTRAL_US).await;
    c.arm().await;
    c.wait("HEARTBEAT", |m| {
        m["base_mode"]["bits"].as_u64().unwrap() & 128 != 0
    })
    .await;

    // Modes: STABILIZE (0) and back to MANUAL (19), with the ACK Cockpit waits for.
    for mode in [0u32, 19] {
        let r = c
            .command(
                "MAV_CMD_DO_SET_MODE",
                [1.0, mode as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
            )
            .await;
        assert_eq!(r, "MAV_RESULT_ACCEPTED", "mode {mode}");
        c.wait_with_sticks("HEARTBEAT", |m| m["custom_mode"] == mode)
            .await;
    }

    // Forward: the thrusters push, and the simulated ROV moves ahead.
    c.drive_until(600, &board, forward).await;
    c.drive_until_board(600, &board, |s| s.sim.surge_mps > 0.05)
        .await;

    // A parameter, with the padded param_id array and target component 0.
    c.send(
        json!({"type": "PARAM_SET", "param_value": 5.0, "target_system": 1, "target_component": 0,
        "param_id": param_id("JS_LIGHTS_STEPS"), "param_type": {"type": "MAV_PARAM_TYPE_INT16"}}),
    )
    .await;
    let pv = c
        .wait("PARAM_VALUE", |m| {
            chars_to_string(&m["param_id"]) == "JS_LIGHTS_STEPS"
        })
        .await;
    assert_eq!(pv["message"]["param_value"], 5.0);
    assert_eq!(pv["message"]["param_id"].as_array().unwrap().len(), 16);

    // The REST view of the last ATTITUDE, and its field.
    let a = get_json(
        rig.http,
        "/mavlink2rest/v1/mavlink/vehicles/1/components/1/messages/ATTITUDE",
    )
    .await;
    assert_eq!(a["message"]["type"], "ATTITUDE");
    assert!(a["status"]["time"]["counter"].as_u64().unwrap() >= 1);
    assert!(
        a["status"]["time"]["last_update"]
            .as_str()
            .unwrap()
            .contains('T')
    );
    let roll = get_json(
        rig.http,
        "/v1/mavlink/vehicles/1/components/1/messages/ATTITUDE/message/roll",
    )
    .await;
    assert!(roll.is_number(), "{roll}");
    let counter = get_json(
        rig.http,
        "/mavlink2rest/v1/mavlink/vehicles/1/components/1/messages/ATTITUDE/status/time/counter",
    )
    .await;
    assert!(counter.as_u64().unwrap() >= 1, "{counter}");
    // What Cockpit sent is in the view under its header (it polls this).
    let mc = get_json(
        rig.http,
        "/mavlink2rest/v1/mavlink/vehicles/255/components/240/messages/MANUAL_CONTROL",
    )
    .await;
    assert_eq!(mc["message"]["x"], 600);
    // The helper and info.
    let h = get_json(rig.http, "/v1/helper/mavlink?name=NEPTUNUS_THRUSTERS").await;
    assert_eq!(h["header"]["system_id"], 255);
    assert_eq!(h["message"]["type"], "NEPTUNUS_THRUSTERS");
    let (status, _, _) = http(rig.http, "GET", "/v1/helper/mavlink?name=NOPE", &[], "").await;
    assert_eq!(status, 404);
    let info = get_json(rig.http, "/info").await;
    assert_eq!(info["service"]["name"], "neptunus");

    // The page's own WebSocket and the vehicle are untouched by all this.
    assert!(
        rig.vehicle
            .stderr_text()
            .lines()
            .all(|l| !l.contains("ERROR")),
        "{}",
        rig.vehicle.stderr_text()
    );
}

/// A second client with another header is another station and cannot drive
/// while the first owns the vehicle; a client with the same header is the
/// same station: it drives as the owner (the core knows stations by system
/// id; answers go to whichever connection spoke last). The station is gone
/// — control released, thrusters stopped — when its last connection closes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn other_headers_cannot_drive_same_header_is_the_same_station() {
    let rig = Rig::start("", false);
    let board = rig.control();
    let mut a = rig.cockpit().await;
    a.wait("HEARTBEAT", |_| true).await;
    a.drive_until(0, &board, |m| m == NEUTRAL_US).await;
    a.arm().await;
    a.drive_until(600, &board, forward).await;

    // 245 is an allowed station (NEPT_GCS_ALLOW1) but not the owner.
    let mut b = Cockpit::connect(rig.http, "/v1/ws/mavlink", 245, 190, &[])
        .await
        .unwrap();
    let mut refused = None;
    let end = Instant::now() + GENEROUS;
    while refused.is_none() {
        assert!(Instant::now() < end, "the non-owner heard no refusal");
        a.send(manual_control(600)).await;
        b.send(manual_control(-1000)).await;
        if let Some(f) = b.next_frame(Duration::from_millis(40)).await
            && f["message"]["type"] == "STATUSTEXT"
        {
            refused = Some(chars_to_string(&f["message"]["text"]));
        }
        assert!(!reverse(board.snapshot().target_us), "the non-owner drove");
    }
    assert!(forward(board.snapshot().target_us));

    // Same header, second connection: the owner, so it drives.
    let mut c = rig.cockpit().await;
    c.drive_until(-600, &board, reverse).await;
    drop(b);
    drop(c);
    // One connection of 255 is still there: it still drives.
    a.drive_until(600, &board, forward).await;
    drop(a);
    wait_neutral(&board).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_pilot_password_only_a_client_that_gave_it_controls() {
    let rig = Rig::start("open_control = \"none\"", true);
    let board = rig.control();
    let mut w = rig.cockpit().await;
    w.wait("HEARTBEAT", |_| true).await;
    assert!(
        w.reply().await.starts_with("Err("),
        "a watcher's HEARTBEAT is not handed on"
    );
    w.send(command_long(
        "MAV_CMD_COMPONENT_ARM_DISARM",
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    ))
    .await;
    assert!(w.reply().await.starts_with("Err("));
    w.send(manual_control(800)).await;
    assert!(w.reply().await.starts_with("Err("));
    // Reading parameters is watching.
    w.send(
        json!({"type": "PARAM_REQUEST_READ", "target_system": 1, "target_component": 0,
        "param_id": param_id("JS_LIGHTS_STEPS"), "param_index": -1}),
    )
    .await;
    w.wait("PARAM_VALUE", |m| {
        chars_to_string(&m["param_id"]) == "JS_LIGHTS_STEPS"
    })
    .await;
    let hb = w.wait("HEARTBEAT", |_| true).await;
    assert_eq!(
        hb["message"]["base_mode"]["bits"].as_u64().unwrap() & 128,
        0,
        "armed by a watcher"
    );
    assert_eq!(board.snapshot().motors_us, NEUTRAL_US);

    // A wrong password in the URL is refused at the upgrade.
    let wrong = Cockpit::connect(
        rig.http,
        "/mavlink2rest/ws/mavlink?password=nope",
        255,
        240,
        &[],
    )
    .await;
    assert_eq!(wrong.err().map(|e| e.0), Some(401));

    // The password in the URL: a pilot.
    let path = format!("/mavlink2rest/ws/mavlink?password={PASSWORD}");
    let mut p = Cockpit::connect(rig.http, &path, 255, 240, &[])
        .await
        .unwrap();
    p.wait("HEARTBEAT", |_| true).await;
    p.drive_until(0, &board, |m| m == NEUTRAL_US).await;
    p.arm().await;
    p.drive_until(600, &board, forward).await;
    let r = p
        .command(
            "MAV_CMD_COMPONENT_ARM_DISARM",
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await;
    assert_eq!(r, "MAV_RESULT_ACCEPTED");
    wait_neutral(&board).await;

    // The password as the first message: a pilot too.
    let mut q = rig.cockpit().await;
    q.send_text(json!({ "password": PASSWORD }).to_string())
        .await;
    let login: Value = serde_json::from_str(&q.reply().await).unwrap();
    assert_eq!(login["login"], true, "{login}");
    q.drive_until(0, &board, |m| m == NEUTRAL_US).await;
    q.arm().await;
}

/// The vehicle's default: no pilot password and `open_control = "none"` —
/// a client anywhere, loopback included, only watches, as a browser
/// session does; POST is refused the same way.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_password_and_open_control_none_a_client_only_watches() {
    let rig = Rig::start("open_control = \"none\"", false);
    let board = rig.control();
    let mut w = rig.cockpit().await;
    w.wait("HEARTBEAT", |_| true).await;
    let r = w.reply().await;
    assert!(
        r.starts_with("Err(") && r.contains("open_control"),
        "a watcher's HEARTBEAT is refused with the reason: {r}"
    );
    w.send(command_long(
        "MAV_CMD_COMPONENT_ARM_DISARM",
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    ))
    .await;
    assert!(w.reply().await.starts_with("Err("));
    for _ in 0..10 {
        w.send(manual_control(800)).await;
        assert!(w.reply().await.starts_with("Err("));
    }
    let hb = w.wait("HEARTBEAT", |_| true).await;
    assert_eq!(
        hb["message"]["base_mode"]["bits"].as_u64().unwrap() & 128,
        0,
        "armed by a client that may only watch"
    );
    assert_eq!(board.snapshot().motors_us, NEUTRAL_US);
    let arm = json!({"header": {"system_id": 255, "component_id": 240, "sequence": 0},
        "message": command_long("MAV_CMD_COMPONENT_ARM_DISARM", [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])});
    let (status, _, body) = http(
        rig.http,
        "POST",
        "/mavlink2rest/v1/mavlink",
        &[],
        &arm.to_string(),
    )
    .await;
    assert_eq!(status, 401, "POST from a client that may not pilot: {body}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_that_do_not_convert_are_answered_and_change_nothing() {
    let rig = Rig::start("", false);
    let board = rig.control();
    let mut c = rig.cockpit().await;
    c.watch("HEARTBEAT").await;
    let before = board.snapshot();
    let bad = [
        "{not json".to_owned(),
        json!({"header": {"system_id": 255, "component_id": 240, "sequence": 0},
            "message": {"type": "NO_SUCH_MESSAGE", "x": 1}}).to_string(),
        json!({"header": {"system_id": 255, "component_id": 240, "sequence": 0},
            "message": {"type": "MANUAL_CONTROL", "target": 1, "x": "full", "y": 0, "z": 500, "r": 0, "buttons": 0}}).to_string(),
        json!({"header": {"system_id": 255, "component_id": 240, "sequence": 0},
            "message": {"type": "COMMAND_LONG", "param1": "1", "param2": 0, "param3": 0, "param4": 0,
                "param5": 0, "param6": 0, "param7": 0, "command": {"type": "MAV_CMD_COMPONENT_ARM_DISARM"},
                "target_system": 1, "target_component": 1, "confirmation": 0}}).to_string(),
        json!({"message": manual_control(1000)}).to_string(),
        // Speaking as the vehicle, or as an id the HMI lends its sessions.
        json!({"header": {"system_id": 1, "component_id": 1, "sequence": 0},
            "message": manual_control(1000)}).to_string(),
        json!({"header": {"system_id": 205, "component_id": 190, "sequence": 0},
            "message": manual_control(1000)}).to_string(),
    ];
    for text in bad {
        c.send_text(text.clone()).await;
        assert_eq!(c.reply().await, NOT_CONVERTED, "for {text}");
    }
    c.ws.send(Message::binary(vec![0xfd, 1, 2])).await.unwrap();
    assert_eq!(c.reply().await, NOT_CONVERTED);
    // Still heard, still disarmed, nothing moved.
    let hb = c.watch("HEARTBEAT").await;
    assert_eq!(
        hb["message"]["base_mode"]["bits"].as_u64().unwrap() & 128,
        0
    );
    let after = board.snapshot();
    assert_eq!(after.motors_us, NEUTRAL_US);
    assert_eq!(after.target_us, before.target_us);
    // POST says the same.
    let (status, _, body) = http(
        rig.http,
        "POST",
        "/v1/mavlink",
        &["Content-Type: application/json"],
        "{\"x\":1}",
    )
    .await;
    assert_eq!((status, body.as_str()), (404, NOT_CONVERTED));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_origin_rule_applies() {
    let rig = Rig::start("allowed_origins = [\"http://cockpit.example:8000\"]", false);
    let evil = [("Origin", "http://evil.example")];
    let r = Cockpit::connect(rig.http, "/mavlink2rest/ws/mavlink", 255, 240, &evil).await;
    assert_eq!(r.err().map(|e| e.0), Some(403));
    let (status, _, _) = http(
        rig.http,
        "POST",
        "/v1/mavlink",
        &["Origin: http://evil.example"],
        "{}",
    )
    .await;
    assert_eq!(status, 403);
    let ok = [("Origin", "http://cockpit.example:8000")];
    assert!(
        Cockpit::connect(rig.http, "/mavlink2rest/ws/mavlink", 255, 240, &ok)
            .await
            .is_ok()
    );
    // Its REST answers are readable by that page (CORS), not by others.
    let (status, head, _) = http(
        rig.http,
        "GET",
        "/mavlink2rest/v1/mavlink",
        &["Origin: http://cockpit.example:8000"],
        "",
    )
    .await;
    assert_eq!(status, 200);
    assert!(
        head.to_lowercase()
            .contains("access-control-allow-origin: http://cockpit.example:8000"),
        "{head}"
    );
    let (_, head, _) = http(
        rig.http,
        "GET",
        "/mavlink2rest/v1/mavlink",
        &["Origin: http://evil.example"],
        "",
    )
    .await;
    assert!(
        !head.to_lowercase().contains("access-control-allow-origin"),
        "{head}"
    );
}

/// A client that never reads (a tiny receive buffer, full at once) does not
/// slow the vehicle or another client: the other keeps getting fresh
/// ATTITUDE at Cockpit's rate and drives.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_never_reads_stalls_nothing() {
    let rig = Rig::start("", false);
    let board = rig.control();
    // The stuck client: 4 KiB of receive buffer, never read after the upgrade.
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.set_recv_buffer_size(4096).unwrap();
    let stream = sock.connect(rig.http).await.unwrap();
    let req = format!("ws://{}/mavlink2rest/ws/mavlink", rig.http)
        .into_client_request()
        .unwrap();
    let (mut stuck, _) =
        tokio_tungstenite::client_async(req, tokio_tungstenite::MaybeTlsStream::Plain(stream))
            .await
            .unwrap();
    // It asks for a lot, 100 Hz of ATTITUDE (50 Hz, the vehicle's ceiling),
    // and then reads nothing.
    let f = json!({"header": {"system_id": 255, "component_id": 240, "sequence": 0},
        "message": command_long("MAV_CMD_SET_MESSAGE_INTERVAL", [30.0, 10_000.0, 0.0, 0.0, 0.0, 0.0, 0.0])});
    stuck.send(Message::text(f.to_string())).await.unwrap();

    let mut c = rig.cockpit().await;
    let first = c.wait("ATTITUDE", |_| true).await;
    let t0 = first["message"]["time_boot_ms"].as_u64().unwrap();
    // Five seconds of the vehicle's time, with ATTITUDE arriving all along.
    let mut count = 0;
    let mut last = t0;
    while last < t0 + 5000 {
        let f = c.wait("ATTITUDE", |_| true).await;
        last = f["message"]["time_boot_ms"].as_u64().unwrap();
        count += 1;
    }
    // 100 Hz asked, 50 Hz the vehicle's ceiling: most of them arrive, not a trickle.
    assert!(
        count >= 5 * 40,
        "only {count} ATTITUDE in 5 s of the vehicle's time"
    );
    c.drive_until(0, &board, |m| m == NEUTRAL_US).await;
    c.arm().await;
    c.drive_until(600, &board, forward).await;
    drop(stuck);
}

/// `?filter=REGEX` keeps only the message names it matches; a filter that is
/// not a regular expression is refused at the upgrade.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_filter_keeps_only_what_it_names() {
    let rig = Rig::start("", false);
    let path = "/v1/ws/mavlink?filter=%5E(HEARTBEAT%7CSYS_STATUS)%24";
    let mut c = Cockpit::connect(rig.http, path, 255, 240, &[])
        .await
        .unwrap();
    let mut names = std::collections::BTreeSet::new();
    while names.len() < 2 {
        let f = c
            .next_frame(GENEROUS)
            .await
            .expect("frames through the filter");
        names.insert(f["message"]["type"].as_str().unwrap().to_owned());
    }
    assert_eq!(
        names.into_iter().collect::<Vec<_>>(),
        ["HEARTBEAT", "SYS_STATUS"],
        "only what the filter names"
    );
    for _ in 0..20 {
        let f = c.next_frame(GENEROUS).await.unwrap();
        let t = f["message"]["type"].as_str().unwrap();
        assert!(
            t == "HEARTBEAT" || t == "SYS_STATUS",
            "{t} passed the filter"
        );
    }
    let bad = Cockpit::connect(rig.http, "/v1/ws/mavlink?filter=(", 255, 240, &[]).await;
    assert_eq!(bad.err().map(|e| e.0), Some(400));
}

/// A client that reads nothing until the test says so, on a socket whose
/// kernel buffers fill within seconds, as on a slow link: 4 KiB of receive
/// buffer and 536-byte segments (on loopback the vehicle's send buffer
/// grows with the segment size: to megabytes with 64-KiB segments, to a few
/// hundred KiB with these).
async fn stalling_client(addr: SocketAddr, path: &str) -> Cockpit {
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.set_recv_buffer_size(4096).unwrap();
    nix::sys::socket::setsockopt(&sock, nix::sys::socket::sockopt::TcpMaxSeg, &536).unwrap();
    let stream = sock.connect(addr).await.unwrap();
    let req = format!("ws://{addr}{path}").into_client_request().unwrap();
    let (ws, _) =
        tokio_tungstenite::client_async(req, tokio_tungstenite::MaybeTlsStream::Plain(stream))
            .await
            .unwrap();
    Cockpit {
        ws,
        sysid: 255,
        compid: 240,
        replies: VecDeque::new(),
        last_beat: None,
    }
}

/// The names of the NAMED_VALUE_FLOATs the vehicle sends, in one burst.
const NAMED_VALUES: [&str; 5] = ["CamTilt", "InputHold", "Laser", "Lights1", "PilotGain"];

fn named_value(f: &Value) -> Option<String> {
    (f["message"]["type"] == "NAMED_VALUE_FLOAT").then(|| chars_to_string(&f["message"]["name"]))
}

/// The vehicle sends its five NAMED_VALUE_FLOATs (Cockpit's Lights, Pilot
/// Gain, Cam Tilt… widgets) together, twice a second: a client that asks
/// for them alone gets every name every time, not only the last of each
/// burst.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_named_value_filter_gets_all_five_names() {
    let rig = Rig::start("", false);
    let mut c = Cockpit::connect(
        rig.http,
        "/v1/ws/mavlink?filter=NAMED_VALUE_FLOAT",
        255,
        240,
        &[],
    )
    .await
    .unwrap();
    let mut counts = std::collections::BTreeMap::<String, usize>::new();
    let mut frames = 0;
    let end = Instant::now() + GENEROUS;
    // Ten bursts' worth of each name.
    while counts.len() < NAMED_VALUES.len() || counts.values().any(|n| *n < 10) {
        assert!(
            Instant::now() < end,
            "not every named value within {GENEROUS:?}: {counts:?}"
        );
        let Some(f) = c.next_frame(Duration::from_millis(200)).await else {
            continue;
        };
        frames += 1;
        let name = named_value(&f).unwrap_or_else(|| panic!("{f} passed the filter"));
        *counts.entry(name).or_default() += 1;
    }
    eprintln!("NAMED_VALUE_FLOAT per name in {frames} frames: {counts:?}");
    assert_eq!(
        counts.keys().map(String::as_str).collect::<Vec<_>>(),
        NAMED_VALUES
    );
    let (lo, hi) = (
        counts.values().min().copied().unwrap_or(0),
        counts.values().max().copied().unwrap_or(0),
    );
    assert!(hi - lo <= 1, "a name fell behind the others: {counts:?}");
}

/// The vehicle is two components, the autopilot (1) and the camera (100),
/// each with its own 1-Hz HEARTBEAT: a client hears both, and the REST view
/// keeps each under its component.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn heartbeats_come_from_the_autopilot_and_the_camera() {
    let rig = Rig::start("", false);
    let mut c = rig.cockpit().await;
    let mut per_component = std::collections::BTreeMap::<u64, usize>::new();
    let end = Instant::now() + Duration::from_secs(8);
    while let Some(f) = c
        .next_frame(end.saturating_duration_since(Instant::now()))
        .await
    {
        if f["message"]["type"] != "HEARTBEAT" {
            continue;
        }
        let comp = f["header"]["component_id"].as_u64().unwrap();
        let kind = f["message"]["mavtype"]["type"].as_str().unwrap();
        match comp {
            1 => assert_eq!(kind, "MAV_TYPE_SUBMARINE"),
            100 => assert_eq!(kind, "MAV_TYPE_CAMERA"),
            _ => panic!("a HEARTBEAT from component {comp}: {f}"),
        }
        assert_eq!(f["header"]["system_id"], 1);
        *per_component.entry(comp).or_default() += 1;
    }
    eprintln!("HEARTBEATs in 8 s per component: {per_component:?}");
    for comp in [1, 100] {
        let n = per_component.get(&comp).copied().unwrap_or(0);
        assert!(
            n >= 4,
            "{n} HEARTBEATs from component {comp} in 8 s: {per_component:?}"
        );
    }
    for (comp, kind) in [(1, "MAV_TYPE_SUBMARINE"), (100, "MAV_TYPE_CAMERA")] {
        let hb = get_json(
            rig.http,
            &format!("/mavlink2rest/v1/mavlink/vehicles/1/components/{comp}/messages/HEARTBEAT"),
        )
        .await;
        assert_eq!(hb["message"]["mavtype"]["type"], kind, "component {comp}");
        assert!(hb["status"]["time"]["counter"].as_u64().unwrap() >= 4);
    }
}

/// Messages asked at 50 Hz (the vehicle's ceiling) for the pause test:
/// ATTITUDE, AHRS2, VFR_HUD, NEPTUNUS_ESTIMATE, GLOBAL_POSITION_INT,
/// SERVO_OUTPUT_RAW, SYS_STATUS and the named values.
const BUSY_RATES: [u32; 8] = [30, 178, 74, 44102, 33, 36, 1, 251];

/// Bytes sent to every client while the slow one pauses: several times
/// what the kernel holds for it.
const PAUSE_BYTES: usize = 3 << 19;

/// A client that stops reading while the vehicle sends more than the
/// kernel can buffer for it (1.5 MiB, messages at 50 Hz) gets, once it reads
/// again, each stream's newest message — every named value stamped around
/// the moment it resumed, both components' HEARTBEATs — and not the
/// backlog: what the kernel held, then a gap, then the present.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_pauses_gets_each_streams_newest_and_no_backlog() {
    let rig = Rig::start("", false);
    let mut fast = rig.cockpit().await;
    for id in BUSY_RATES {
        let r = fast
            .command(
                "MAV_CMD_SET_MESSAGE_INTERVAL",
                [id as f32, 20_000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            )
            .await;
        assert_eq!(r, "MAV_RESULT_ACCEPTED", "message {id} at 50 Hz");
    }
    let boot_ms = |f: &Value| f["message"]["time_boot_ms"].as_u64().unwrap();
    let t_start = boot_ms(&fast.wait("ATTITUDE", |_| true).await);
    let mut slow = stalling_client(rig.http, "/mavlink2rest/ws/mavlink").await;
    // The pause: until every client was sent more than the kernel can hold
    // for the slow one, counted by what the fast one reads.
    let need = PAUSE_BYTES;
    let (mut bytes, mut sent, mut t_resume) = (0usize, 0usize, t_start);
    let end = Instant::now() + Duration::from_secs(120);
    while bytes < need {
        assert!(
            Instant::now() < end,
            "only {bytes} of {need} bytes sent in 120 s"
        );
        let Some(Ok(Message::Text(t))) =
            tokio::time::timeout(Duration::from_millis(200), fast.ws.next())
                .await
                .ok()
                .flatten()
        else {
            continue;
        };
        bytes += t.len();
        if let Ok(f) = serde_json::from_str::<Value>(t.as_str())
            && f["message"]["type"] == "ATTITUDE"
        {
            t_resume = boot_ms(&f);
            sent += 1;
        }
    }
    // The slow client reads again, until a second of the vehicle's time
    // after the pause.
    let mut stamps = Vec::new();
    let (mut frames, mut names, mut beats) = (
        0usize,
        std::collections::BTreeSet::new(),
        std::collections::BTreeSet::new(),
    );
    let end = Instant::now() + GENEROUS;
    loop {
        assert!(Instant::now() < end, "the slow client never caught up");
        let Some(f) = slow.next_frame(Duration::from_millis(200)).await else {
            continue;
        };
        frames += 1;
        // Named values from around the moment it read again: the newest.
        if let Some(name) = named_value(&f)
            && boot_ms(&f) + 1000 >= t_resume
        {
            names.insert(name);
        }
        if f["message"]["type"] == "HEARTBEAT" {
            beats.insert(f["header"]["component_id"].as_u64().unwrap());
        }
        if f["message"]["type"] == "ATTITUDE" {
            let t = boot_ms(&f);
            stamps.push(t);
            if t >= t_resume + 1000 {
                break;
            }
        }
    }
    let during = stamps.iter().filter(|t| **t <= t_resume).count();
    let gap_ms = stamps
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]))
        .max()
        .unwrap_or(0);
    eprintln!(
        "paused {} ms of the vehicle's time ({bytes} bytes to each client): of {sent} ATTITUDE \
         sent, {during} reached the paused client, then a {gap_ms} ms gap; {frames} frames \
         until 1 s after; named values {names:?}, HEARTBEAT components {beats:?}",
        t_resume - t_start
    );
    assert!(during < sent, "the whole backlog arrived");
    assert!(
        gap_ms >= 2000,
        "no gap in the paused client's ATTITUDE: the backlog was kept ({during} of {sent})"
    );
    assert_eq!(
        names.iter().map(String::as_str).collect::<Vec<_>>(),
        NAMED_VALUES,
        "each named value's newest"
    );
    assert_eq!(beats.into_iter().collect::<Vec<_>>(), [1, 100]);
}

/// ATTITUDE's `time_boot_ms` in the REST view, read as a script would.
async fn rest_attitude_ms(addr: SocketAddr) -> i64 {
    let v = get_json(
        addr,
        "/mavlink2rest/mavlink/vehicles/1/components/1/messages/ATTITUDE",
    )
    .await;
    v["message"]["time_boot_ms"].as_i64().unwrap()
}

/// With no browser and no WebSocket client the vehicle builds no telemetry
/// for the in-process endpoints, yet a REST read — the first, one after a
/// client left, one after a long quiet — answers with live data, for
/// mavlink2rest's view and for `/api/status` alike.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rest_reads_are_live_when_nobody_else_listens() {
    let rig = Rig::start("", false);
    // The board's attitude is there (the vehicle says nothing it has not read).
    let end = Instant::now() + GENEROUS;
    loop {
        let status = get_json(rig.http, "/api/status").await;
        if status["telemetry"]["health"]["attitude"] == json!(true) {
            let ages = &status["telemetry"]["ages_ms"];
            assert!(
                ages["attitude"].as_u64().unwrap() <= 2000,
                "the status read is not live: {ages}"
            );
            break;
        }
        assert!(Instant::now() < end, "no attitude from the board: {status}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // mavlink2rest's endpoint was quiet all along.
    let first = rest_attitude_ms(rig.http).await;
    let t0 = Instant::now();

    // A client comes and goes.
    let mut c = rig.cockpit().await;
    assert!(c.next_frame(GENEROUS).await.is_some());
    drop(c);

    // Past the time a REST read keeps the telemetry coming (10 s), so the
    // next read finds the endpoints quiet. Time has to pass here: that is
    // what is tested.
    tokio::time::sleep(Duration::from_secs(12)).await;
    let now_ms = first + t0.elapsed().as_millis() as i64;
    let later = rest_attitude_ms(rig.http).await;
    assert!(
        (now_ms - later).abs() < 5000,
        "after a quiet while ATTITUDE says {later} ms, the vehicle has been up about {now_ms} ms"
    );
    let status = get_json(rig.http, "/api/status").await;
    let ages = &status["telemetry"]["ages_ms"];
    assert!(
        ages["attitude"].as_u64().unwrap() <= 2000,
        "the status read after a quiet while is not live: {ages}"
    );
}
