//! One browser session: a MAVLink ground station inside the process.
//!
//! Owns the session's system id (leased from the pool), its pilot rights,
//! its view of the vehicle ([`Model`]) and the conversion of the browser's
//! JSON into MAVLink. It must never invent pilot input: stick messages go
//! out only as the browser sends them; the session itself only sends
//! neutral ones (stop, focus lost, input-mode change) and its heartbeat —
//! and the heartbeat only while the browser itself shows life, so a frozen
//! tab does not keep its owner alive.

use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::ws::{Message, Utf8Bytes, WebSocket};
use futures_util::{SinkExt as _, StreamExt as _};
use tokio::sync::broadcast::error::RecvError;

use super::model::Model;
use super::protocol::{ClientMsg, RunMode, ServerMsg};
use super::{Shared, SysidLease};
use crate::dialect::neptunus::*;
use crate::vehicle::machine::{COMPONENT_ID, HmiEvent, Input};

/// Telemetry push period (20 Hz).
const PUSH_PERIOD: Duration = Duration::from_millis(50);
/// HEARTBEAT period.
const HEARTBEAT_PERIOD: Duration = Duration::from_secs(1);
/// The browser must have shown life this recently for a HEARTBEAT to go out.
const BROWSER_LIFE: Duration = Duration::from_millis(1500);
/// A browser that takes longer than this to accept a message is dropped.
const SEND_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a control request waits for the owner's answer.
const REQUEST_TIMEOUT_S: f32 = 10.0;

/// Telemetry rates this HMI asks the vehicle for on its endpoint (msg id, Hz).
const RATES: [(u32, f32); 8] = [
    (30, 20.0),    // ATTITUDE: heading, roll, pitch
    (74, 20.0),    // VFR_HUD: depth
    (36, 10.0),    // SERVO_OUTPUT_RAW: thrusters
    (1, 4.0),      // SYS_STATUS: health, voltage, current
    (251, 4.0),    // NAMED_VALUE_FLOAT: lights, gain, tilt
    (44101, 20.0), // NEPTUNUS_SIM_STATE
    (44102, 20.0), // NEPTUNUS_ESTIMATE
    (44103, 10.0), // NEPTUNUS_AUTOPILOT
];

/// Why a session ends.
enum End {
    Closed,
    SendFailed,
}

struct Session {
    shared: Arc<Shared>,
    id: u64,
    lease: Option<SysidLease>,
    pilot: bool,
    model: Model,
    last_life: Instant,
    bad: u64,
}

/// Runs one WebSocket session to its end, then tells the vehicle it disconnected.
pub(crate) async fn run(socket: WebSocket, shared: Arc<Shared>) {
    let id = shared
        .next_session
        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let lease = shared.lease_sysid();
    let sysid = lease.as_ref().map(|l| l.sysid);
    let pilot = shared.pilot_password.is_none() && sysid.is_some();
    let now = Instant::now();
    let mut s = Session {
        shared: Arc::clone(&shared),
        id,
        lease,
        pilot,
        model: Model::new(sysid, now),
        last_life: now,
        bad: 0,
    };
    match sysid {
        Some(sysid) => tracing::info!(session = id, sysid, "HMI session connected"),
        None => tracing::warn!(
            session = id,
            "HMI session connected watch-only: every system id of the HMI range is in use"
        ),
    }
    let (mut tx, mut rx) = socket.split();
    let mut hub = shared.outlet.subscribe();
    let welcome = ServerMsg::Welcome {
        session: id,
        sysid,
        watch_only_reason: sysid.is_none().then(|| {
            let (lo, hi) = shared.sysid_range;
            format!(
                "all {} HMI system ids ({lo}..{hi}) are in use by other sessions: this one may only watch",
                u16::from(hi) - u16::from(lo) + 1
            )
        }),
        password_required: shared.pilot_password.is_some(),
        pilot,
        vehicle_sysid: shared.vehicle_sysid,
        camera_rotation_deg: shared.camera_rotation_deg,
        version: env!("CARGO_PKG_VERSION"),
    };
    let end = 'session: {
        if send(&mut tx, &welcome).await.is_err() {
            break 'session End::SendFailed;
        }
        s.request_rates().await;
        let mut push = tokio::time::interval(PUSH_PERIOD);
        push.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut beat = tokio::time::interval(HEARTBEAT_PERIOD);
        beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut events = Vec::new();
        loop {
            tokio::select! {
                m = rx.next() => {
                    let reply = match m {
                        None | Some(Err(_)) | Some(Ok(Message::Close(_))) => break 'session End::Closed,
                        Some(Ok(Message::Text(text))) => s.on_text(text.as_str()).await,
                        Some(Ok(Message::Binary(_))) => s.bad_message("binary messages are not part of the protocol — send JSON text"),
                        Some(Ok(Message::Ping(_) | Message::Pong(_))) => {
                            s.last_life = Instant::now();
                            None
                        }
                    };
                    if let Some(reply) = reply
                        && send(&mut tx, &reply).await.is_err()
                    {
                        break 'session End::SendFailed;
                    }
                }
                d = hub.recv() => match d {
                    Ok(d) => {
                        if d.peer.is_some_and(|p| p != s.id) {
                            continue;
                        }
                        s.model.on_message(&d.msg, Instant::now(), &mut events);
                        for ev in events.drain(..) {
                            if send(&mut tx, &ev).await.is_err() {
                                break 'session End::SendFailed;
                            }
                        }
                    }
                    Err(RecvError::Lagged(n)) => {
                        tracing::debug!(session = s.id, "HMI session fell behind by {n} vehicle messages");
                    }
                    Err(RecvError::Closed) => break 'session End::Closed,
                },
                _ = push.tick() => {
                    let t = s.model.snapshot(Instant::now());
                    if send(&mut tx, &ServerMsg::Telemetry(Box::new(t))).await.is_err() {
                        break 'session End::SendFailed;
                    }
                }
                _ = beat.tick() => s.heartbeat().await,
            }
        }
    };
    if let End::SendFailed = end {
        tracing::info!(
            session = id,
            "HMI session dropped: the browser stopped reading"
        );
    }
    // Whatever the browser did, the core hears that this station is gone.
    if let Some(sysid) = sysid {
        let _ = shared
            .inputs
            .send(Input::Hmi {
                sysid,
                event: HmiEvent::Disconnected,
            })
            .await;
    }
    tracing::info!(session = id, sysid = ?sysid, bad_messages = s.bad, "HMI session closed");
    drop(s.lease.take());
}

async fn send(
    tx: &mut futures_util::stream::SplitSink<WebSocket, Message>,
    msg: &ServerMsg,
) -> Result<(), ()> {
    let text = Message::Text(Utf8Bytes::from(msg.to_json()));
    match tokio::time::timeout(SEND_TIMEOUT, tx.send(text)).await {
        Ok(Ok(())) => Ok(()),
        _ => Err(()),
    }
}

impl Session {
    fn sysid(&self) -> Option<u8> {
        self.lease.as_ref().map(|l| l.sysid)
    }

    fn bad_message(&mut self, why: &str) -> Option<ServerMsg> {
        self.bad += 1;
        self.shared.note_bad_message(self.id, why);
        Some(ServerMsg::Error {
            message: why.to_owned(),
        })
    }

    /// Hands a message to the vehicle as coming from this session.
    async fn to_vehicle(&self, msg: MavMessage) {
        // A watcher with no system id has none to speak with (sysid 0 would be
        // the broadcast address); it only asks for telemetry.
        let sysid = self.sysid().unwrap_or(0);
        let from = self.shared.sender(self.id, sysid, self.pilot);
        let _ = self.shared.inputs.send(Input::Mavlink { from, msg }).await;
    }

    async fn hmi_event(&self, event: HmiEvent) {
        if let Some(sysid) = self.sysid() {
            let _ = self.shared.inputs.send(Input::Hmi { sysid, event }).await;
        }
    }

    async fn request_rates(&self) {
        for (id, hz) in RATES {
            self.command(MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL, [id as f32, 1e6 / hz])
                .await;
        }
    }

    async fn heartbeat(&self) {
        if self.sysid().is_none() || self.last_life.elapsed() > BROWSER_LIFE {
            return;
        }
        self.to_vehicle(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_GCS,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }))
        .await;
    }

    /// COMMAND_LONG to the vehicle with the first params given, the rest 0.
    async fn command<const N: usize>(&self, command: MavCmd, params: [f32; N]) {
        let mut p = [0f32; 7];
        p[..N].copy_from_slice(&params);
        self.to_vehicle(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            command,
            target_system: self.shared.vehicle_sysid,
            target_component: COMPONENT_ID,
            confirmation: 0,
        }))
        .await;
    }

    fn manual_control(&self, surge: f64, sway: f64, heave_up: f64, yaw: f64) -> MavMessage {
        let axis = |v: f64| (v.clamp(-1.0, 1.0) * 1000.0).round() as i16;
        let centred = self.sysid().is_some_and(|s| (self.shared.z_centered)(s));
        let z = if centred {
            axis(heave_up)
        } else {
            // ArduSub's 0..1000 with 500 neutral.
            (500.0 + heave_up.clamp(-1.0, 1.0) * 500.0).round() as i16
        };
        MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
            x: axis(surge),
            y: axis(sway),
            z,
            r: axis(yaw),
            target: self.shared.vehicle_sysid,
            ..Default::default()
        })
    }

    fn thrusters(&self, port: f64, vertical: f64, starboard: f64) -> MavMessage {
        MavMessage::NEPTUNUS_THRUSTERS(NEPTUNUS_THRUSTERS_DATA {
            target_system: self.shared.vehicle_sysid,
            target_component: COMPONENT_ID,
            port: port as f32,
            vertical: vertical as f32,
            starboard: starboard as f32,
        })
    }

    /// Neutral input, sent only by the station in control: from anyone else
    /// it could claim an unowned vehicle, and there is nothing of theirs to stop.
    async fn stop(&self) {
        if self.model.in_control() {
            self.to_vehicle(self.manual_control(0.0, 0.0, 0.0, 0.0))
                .await;
            self.to_vehicle(self.thrusters(0.0, 0.0, 0.0)).await;
        }
    }

    async fn on_text(&mut self, text: &str) -> Option<ServerMsg> {
        let msg = match ClientMsg::parse(text) {
            Ok(m) => m,
            Err(why) => return self.bad_message(&why),
        };
        self.last_life = Instant::now();
        let sysid = self.sysid();
        let drives = !matches!(
            msg,
            ClientMsg::Alive {}
                | ClientMsg::Login { .. }
                | ClientMsg::Stop {}
                | ClientMsg::FocusLost {}
        );
        if drives && sysid.is_none() {
            return Some(ServerMsg::Error {
                message: "this session is watch-only (no free HMI system id): it cannot command the vehicle".into(),
            });
        }
        match msg {
            ClientMsg::Alive {} => {}
            ClientMsg::Login { password } => return Some(self.login(&password)),
            ClientMsg::Sticks {
                surge,
                sway,
                heave_up,
                yaw,
            } => {
                self.to_vehicle(self.manual_control(surge, sway, heave_up, yaw))
                    .await
            }
            ClientMsg::Thrusters {
                port,
                vertical,
                starboard,
            } => {
                self.to_vehicle(self.thrusters(port, vertical, starboard))
                    .await
            }
            ClientMsg::Stop {} => self.stop().await,
            ClientMsg::FocusLost {} => {
                self.stop().await;
                self.hmi_event(HmiEvent::FocusLost).await;
            }
            ClientMsg::InputMode { .. } => {
                self.stop().await;
                self.hmi_event(HmiEvent::InputModeChanged).await;
            }
            ClientMsg::Arm { arm } => {
                self.command(
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                    [if arm { 1.0 } else { 0.0 }],
                )
                .await
            }
            ClientMsg::Mode { mode } => {
                self.command(MavCmd::MAV_CMD_DO_SET_MODE, [1.0, mode as f32])
                    .await
            }
            ClientMsg::RunMode { mode } => {
                let m = match mode {
                    RunMode::Normal => 0.0,
                    RunMode::Simulator => 1.0,
                };
                self.command(MavCmd::MAV_CMD_NEPTUNUS_SET_RUN_MODE, [m])
                    .await
            }
            ClientMsg::AutopilotTarget {
                depth_m,
                heading_deg,
            } => {
                let p = |v: Option<f64>| v.map_or(f32::NAN, |v| v as f32);
                self.command(
                    MavCmd::MAV_CMD_NEPTUNUS_SET_AUTOPILOT_TARGET,
                    [p(depth_m), p(heading_deg)],
                )
                .await
            }
            ClientMsg::Gain { value } => {
                self.to_vehicle(MavMessage::PARAM_SET(PARAM_SET_DATA {
                    param_value: value as f32,
                    target_system: self.shared.vehicle_sysid,
                    target_component: COMPONENT_ID,
                    param_id: "JS_GAIN_DEFAULT".into(),
                    param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
                }))
                .await
            }
            ClientMsg::Lights { level } => {
                let pct = (level / 255.0 * 100.0) as f32;
                self.command(MavCmd::MAV_CMD_DO_ILLUMINATOR_CONFIGURE, [0.0, pct])
                    .await
            }
            ClientMsg::Laser { on } => {
                // Output 6 is the laser (SERVO6_FUNCTION 60).
                let pwm = if on { 1900.0 } else { 1100.0 };
                self.command(MavCmd::MAV_CMD_DO_SET_SERVO, [6.0, pwm]).await
            }
            ClientMsg::Tilt { deg } => {
                // The core takes the legacy MOUNT_CONTROL (centidegrees), as ArduSub does.
                #[allow(deprecated)]
                self.command(MavCmd::MAV_CMD_DO_MOUNT_CONTROL, [(deg * 100.0) as f32])
                    .await
            }
            ClientMsg::RequestControl { takeover_allowed } => {
                let p2 = if takeover_allowed { 1.0 } else { 0.0 };
                self.command(
                    MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
                    [1.0, p2, REQUEST_TIMEOUT_S],
                )
                .await
            }
            ClientMsg::ReleaseControl {} => {
                self.command(MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL, [0.0])
                    .await
            }
            ClientMsg::AnswerRequest { accept } => {
                if accept {
                    // The owner's yes is letting go: the core hands control to the requester.
                    self.command(MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL, [0.0])
                        .await
                } else {
                    self.to_vehicle(MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                        command: MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
                        result: MavResult::MAV_RESULT_DENIED,
                        progress: 0,
                        result_param2: 0,
                        target_system: self.shared.vehicle_sysid,
                        target_component: COMPONENT_ID,
                    }))
                    .await
                }
            }
        }
        None
    }

    fn login(&mut self, password: &str) -> ServerMsg {
        let Some(expected) = &self.shared.pilot_password else {
            return ServerMsg::LoginResult {
                ok: true,
                message: "no pilot password is configured: every session may pilot".into(),
            };
        };
        if self.sysid().is_none() {
            return ServerMsg::LoginResult {
                ok: false,
                message: "this session is watch-only (no free HMI system id)".into(),
            };
        }
        if constant_time_eq(password.as_bytes(), expected.as_bytes()) {
            self.pilot = true;
            tracing::info!(session = self.id, sysid = ?self.sysid(), "HMI session logged in as pilot");
            ServerMsg::LoginResult {
                ok: true,
                message: "logged in: this session may arm, drive and request control".into(),
            }
        } else {
            tracing::warn!(session = self.id, "HMI pilot login refused: wrong password");
            ServerMsg::LoginResult {
                ok: false,
                message: "wrong pilot password".into(),
            }
        }
    }
}

/// Compares without an early exit, so the time taken says nothing about
/// how much of the password matched.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let n = a.len().max(b.len());
    let mut diff = u8::from(a.len() != b.len());
    for i in 0..n {
        diff |= a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0xff);
    }
    diff == 0
}

#[cfg(test)]
mod tests {
    use super::constant_time_eq;

    #[test]
    fn password_compare() {
        assert!(constant_time_eq(b"secret", b"secret"));
        assert!(!constant_time_eq(b"secret", b"secreT"));
        assert!(!constant_time_eq(b"secret", b"secret2"));
        assert!(!constant_time_eq(b"", b"x"));
        assert!(constant_time_eq(b"", b""));
    }
}
