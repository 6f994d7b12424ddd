//! The load of a scenario, from outside the vehicle's process: UDP ground
//! stations (each a thread that sends its traffic and reads everything),
//! browser HMI sessions and a Cockpit-like mavlink2rest client (tasks on
//! the bench's runtime), a video viewer reading `/video.mjpg`, and the
//! MJPEG camera the vehicle relays (a stand-in for mjpg-streamer). Each
//! counts what it receives in the [`Tally`]; a failure is recorded there
//! and printed, never swallowed.

use std::io::{Read as _, Write as _};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use futures_util::{SinkExt as _, StreamExt as _};
use serde_json::json;
use tokio::sync::watch;
use tokio_tungstenite::tungstenite::Message;

use crate::common::{Gcs, Traffic};

/// What the load received (counts since the start) and what went wrong.
#[derive(Default)]
pub struct Tally {
    /// Datagrams received by station 1 (the one behind MAVProxy).
    pub station1: AtomicU64,
    /// Datagrams received by the other stations.
    pub stations: AtomicU64,
    /// WebSocket messages received by the HMI sessions.
    pub hmi: AtomicU64,
    /// WebSocket frames received by the mavlink2rest client.
    pub m2r: AtomicU64,
    /// Bytes of `/video.mjpg` received.
    pub video_bytes: AtomicU64,
    pub errors: Mutex<Vec<String>>,
}

impl Tally {
    pub fn counts(&self) -> [u64; 5] {
        [
            &self.station1,
            &self.stations,
            &self.hmi,
            &self.m2r,
            &self.video_bytes,
        ]
        .map(|c| c.load(Ordering::Relaxed))
    }

    fn error(&self, what: String) {
        if let Ok(mut e) = self.errors.lock() {
            e.push(what);
        }
    }
}

fn add(counter: &AtomicU64, n: u64) {
    counter.fetch_add(n, Ordering::Relaxed);
}

/// A station's thread: sends `traffic` (nothing, heartbeats, or heartbeats
/// and MANUAL_CONTROL at 25 Hz) and reads every datagram (the socket's short
/// read timeout keeps the send schedule) until `stop`.
pub fn station(
    mut gcs: Gcs,
    traffic: Traffic,
    counter: fn(&Tally) -> &AtomicU64,
    tally: Arc<Tally>,
    stop: Arc<AtomicBool>,
) -> JoinHandle<()> {
    thread::spawn(move || {
        let mut buf = [0u8; 4096];
        while !stop.load(Ordering::Relaxed) {
            if let Err(e) = gcs.pump(traffic) {
                tally.error(format!("station {}: {e}", gcs.sysid));
                return;
            }
            if gcs.sock.recv(&mut buf).is_ok() {
                add(counter(&tally), 1);
            }
        }
    })
}

/// Runs a client task until it ends; its error goes to the tally.
pub fn spawn_client(
    rt: &tokio::runtime::Runtime,
    what: String,
    tally: Arc<Tally>,
    client: impl Future<Output = anyhow::Result<()>> + Send + 'static,
) {
    rt.spawn(async move {
        if let Err(e) = client.await {
            tally.error(format!("{what}: {e}"));
        }
    });
}

/// One browser tab: reads everything, says `alive` every 0.5 s as the page
/// does when the pilot does nothing.
pub async fn hmi_session(
    addr: SocketAddr,
    tally: Arc<Tally>,
    mut stop: watch::Receiver<bool>,
) -> anyhow::Result<()> {
    let (ws, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws")).await?;
    let (mut tx, mut rx) = ws.split();
    let mut alive = tokio::time::interval(Duration::from_millis(500));
    loop {
        tokio::select! {
            _ = stop.changed() => return Ok(()),
            _ = alive.tick() => tx.send(Message::text(r#"{"type":"alive"}"#)).await?,
            m = rx.next() => match m {
                Some(Ok(_)) => add(&tally.hmi, 1),
                Some(Err(e)) => return Err(e.into()),
                None => anyhow::bail!("the vehicle closed the WebSocket"),
            },
        }
    }
}

/// The mavlink2rest client's system id (255 is station 1's).
const COCKPIT_SYSID: u8 = 252;

fn cockpit_frame(message: serde_json::Value) -> Message {
    Message::text(
        json!({"header": {"system_id": COCKPIT_SYSID, "component_id": 240, "sequence": 0},
            "message": message})
        .to_string(),
    )
}

/// A Cockpit-like client on `/mavlink2rest/ws/mavlink` that watches: sets
/// Cockpit's message intervals at connect, then a HEARTBEAT every second
/// (no sticks: station 1 drives), reading every frame.
pub async fn cockpit(
    addr: SocketAddr,
    tally: Arc<Tally>,
    mut stop: watch::Receiver<bool>,
) -> anyhow::Result<()> {
    let url = format!("ws://{addr}/mavlink2rest/ws/mavlink");
    let (ws, _) = tokio_tungstenite::connect_async(url).await?;
    let (mut tx, mut rx) = ws.split();
    for (id, hz) in crate::common::COCKPIT_RATES {
        tx.send(cockpit_frame(
            json!({"type": "COMMAND_LONG", "param1": id, "param2": 1e6 / hz,
            "param3": 0, "param4": 0, "param5": 0, "param6": 0, "param7": 0,
            "command": {"type": "MAV_CMD_SET_MESSAGE_INTERVAL"},
            "target_system": 1, "target_component": 1, "confirmation": 0}),
        ))
        .await?;
    }
    let heartbeat = json!({"type": "HEARTBEAT", "custom_mode": 0, "mavtype": {"type": "MAV_TYPE_GCS"},
        "autopilot": {"type": "MAV_AUTOPILOT_INVALID"}, "base_mode": {"bits": 192},
        "system_status": {"type": "MAV_STATE_ACTIVE"}, "mavlink_version": 2});
    let mut beat = tokio::time::interval(Duration::from_secs(1));
    loop {
        tokio::select! {
            _ = stop.changed() => return Ok(()),
            _ = beat.tick() => tx.send(cockpit_frame(heartbeat.clone())).await?,
            m = rx.next() => match m {
                Some(Ok(_)) => add(&tally.m2r, 1),
                Some(Err(e)) => return Err(e.into()),
                None => anyhow::bail!("the vehicle closed the WebSocket"),
            },
        }
    }
}

/// A video player on `/video.mjpg`: reads (and drops) the stream until `stop`.
pub fn video_viewer(addr: SocketAddr, tally: Arc<Tally>, stop: Arc<AtomicBool>) -> JoinHandle<()> {
    thread::spawn(move || {
        let read = || -> anyhow::Result<()> {
            let mut s = TcpStream::connect(addr)?;
            s.set_read_timeout(Some(Duration::from_millis(200)))?;
            write!(
                s,
                "GET /video.mjpg HTTP/1.1\r\nHost: {addr}\r\nAccept: */*\r\n\r\n"
            )?;
            let mut buf = vec![0u8; 64 * 1024];
            while !stop.load(Ordering::Relaxed) {
                match s.read(&mut buf) {
                    Ok(0) => anyhow::bail!("the vehicle ended the stream"),
                    Ok(n) => add(&tally.video_bytes, n as u64),
                    Err(e)
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                        ) => {}
                    Err(e) => return Err(e.into()),
                }
            }
            Ok(())
        };
        if let Err(e) = read() {
            tally.error(format!("video viewer: {e}"));
        }
    })
}

/// The camera the vehicle relays: an MJPEG server on a loopback port, as
/// mjpg-streamer serves the ROV's camera, giving one fixed `jpeg` at `fps`
/// to each connection until `stop`. Returns its address and its thread.
pub fn mjpeg_camera(
    jpeg: bytes::Bytes,
    fps: f64,
    stop: Arc<AtomicBool>,
) -> anyhow::Result<(SocketAddr, JoinHandle<()>)> {
    let listener = TcpListener::bind("127.0.0.1:0")?;
    let addr = listener.local_addr()?;
    // Non-blocking, so that the accept loop sees `stop`.
    listener.set_nonblocking(true)?;
    let period = Duration::from_secs_f64(1.0 / fps);
    let handle = thread::spawn(move || {
        while !stop.load(Ordering::Relaxed) {
            let Ok((mut s, _)) = listener.accept() else {
                thread::sleep(Duration::from_millis(50));
                continue;
            };
            let (jpeg, stop) = (jpeg.clone(), Arc::clone(&stop));
            thread::spawn(move || {
                let _ = s.set_nonblocking(false);
                let _ = s.set_read_timeout(Some(Duration::from_secs(2)));
                let mut request = [0u8; 2048];
                let _ = s.read(&mut request);
                let head = "HTTP/1.1 200 OK\r\nConnection: close\r\n\
                    Content-Type: multipart/x-mixed-replace; boundary=frame\r\n\r\n";
                if s.write_all(head.as_bytes()).is_err() {
                    return;
                }
                while !stop.load(Ordering::Relaxed) {
                    let part = format!(
                        "--frame\r\nContent-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
                        jpeg.len()
                    );
                    let sent = s.write_all(part.as_bytes()).and_then(|()| {
                        s.write_all(&jpeg)?;
                        s.write_all(b"\r\n")
                    });
                    if sent.is_err() {
                        return;
                    }
                    thread::sleep(period);
                }
            });
        }
    });
    Ok((addr, handle))
}
