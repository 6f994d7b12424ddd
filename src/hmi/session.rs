//! One browser session: a MAVLink ground station inside the process.
//!
//! Owns the session's system id (leased from the pool only when it may
//! pilot and needs one: at login, or at its first command when
//! `[hmi] open_control` admits it), its pilot rights, its view of the
//! vehicle ([`Model`]) and the conversion of the browser's JSON into
//! MAVLink. A watcher holds no id and sends the vehicle nothing.
//!
//! It must never invent pilot input: stick messages go out only as the
//! browser sends them; the session itself only sends
//! neutral ones (stop, focus lost, input-mode change) and its heartbeat —
//! and the heartbeat only while the browser itself shows life, so a frozen
//! tab does not keep its owner alive.

use std::net::IpAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use axum::extract::ws::{Message, Utf8Bytes, WebSocket};
use futures_util::{SinkExt as _, StreamExt as _};
use mavlink_core::MessageData;
use tokio::sync::broadcast::error::RecvError;

use super::auth::OpenControl;
use super::model::Model;
use super::protocol::{ClientMsg, ModeView, RunMode, ServerMsg};
use super::{Shared, SysidLease, guard};
use crate::dialect::neptunus::*;
use crate::vehicle::machine::{COMPONENT_ID, HmiEvent, Input};
use crate::vehicle::mode::Mode;

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
/// A session that sent nothing (not even a pong) for this long is closed
/// (the page says `alive` every 0.5 s).
const IDLE_TIMEOUT: Duration = Duration::from_secs(30);
/// The server pings this often, so a live browser whose tab is throttled
/// still answers (with a pong) within [`IDLE_TIMEOUT`].
const PING_PERIOD: Duration = Duration::from_secs(10);
/// A watcher's refused stick and thruster input is answered at most this often.
const REFUSAL_REPLY: Duration = Duration::from_secs(2);

/// Telemetry rates this HMI asks the vehicle for on its endpoint (msg id, Hz),
/// once, from the server's own peer (see [`request_rates`]).
const RATES: [(u32, f32); 8] = [
    // Heading, roll, pitch.
    (ATTITUDE_DATA::ID, 20.0),
    // Depth.
    (VFR_HUD_DATA::ID, 20.0),
    // Thrusters.
    (SERVO_OUTPUT_RAW_DATA::ID, 10.0),
    // Health, voltage, current.
    (SYS_STATUS_DATA::ID, 4.0),
    // Lights, gain, tilt.
    (NAMED_VALUE_FLOAT_DATA::ID, 4.0),
    (NEPTUNUS_SIM_STATE_DATA::ID, 20.0),
    (NEPTUNUS_ESTIMATE_DATA::ID, 20.0),
    (NEPTUNUS_AUTOPILOT_DATA::ID, 10.0),
];

/// Asks the vehicle for the HMI's telemetry rates on its endpoint, once at
/// start, from the server's own peer (a signed pilot: see
/// [`Shared::server_sender`]). Sessions do not ask: the core refuses rate
/// changes from stations that may not control, and a watcher may not.
pub(crate) async fn request_rates(shared: &Shared) {
    let from = shared.server_sender();
    for (id, hz) in RATES {
        let msg = command_long(
            shared.vehicle_sysid,
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [id as f32, 1e6 / hz],
        );
        let _ = shared.inputs.send(Input::Mavlink { from, msg }).await;
    }
}

/// Why a session ends.
enum End {
    Closed,
    SendFailed,
    Idle,
}

/// A place among the `[hmi] max_watchers` sessions that hold no system id;
/// given back when dropped (the session leased an id, or ended).
pub(crate) struct WatcherSlot {
    shared: Arc<Shared>,
}

impl WatcherSlot {
    /// Takes a place, or `None` when `max_watchers` are watching.
    pub fn take(shared: &Arc<Shared>) -> Option<Self> {
        shared
            .watchers
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < shared.max_watchers).then_some(n + 1)
            })
            .ok()
            .map(|_| Self {
                shared: Arc::clone(shared),
            })
    }
}

impl Drop for WatcherSlot {
    fn drop(&mut self) {
        self.shared.watchers.fetch_sub(1, Ordering::AcqRel);
    }
}

/// What the upgrade found out about the client before the session starts.
pub(crate) struct Start {
    pub ip: Option<IpAddr>,
    /// The request carried a live login cookie.
    pub logged_in: bool,
    /// A logged-in session's id, leased at the upgrade.
    pub lease: Option<SysidLease>,
    /// Otherwise its place among the watchers.
    pub watcher: Option<WatcherSlot>,
}

struct Session {
    shared: Arc<Shared>,
    id: u64,
    ip: Option<IpAddr>,
    lease: Option<SysidLease>,
    watcher: Option<WatcherSlot>,
    /// Logged in with the pilot password (cookie or `login`): a pilot, and
    /// `signed` for the core's signing rule.
    logged_in: bool,
    model: Model,
    /// The browser's JavaScript last said something (HEARTBEAT gate).
    last_life: Instant,
    /// Anything at all last arrived, pongs included (idle timeout).
    last_seen: Instant,
    last_refusal: Option<Instant>,
    bad: u64,
}

/// Runs one WebSocket session to its end, then tells the vehicle it disconnected.
pub(crate) async fn run(socket: WebSocket, shared: Arc<Shared>, start: Start) {
    let id = shared
        .next_session
        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let now = Instant::now();
    let mut s = Session {
        shared: Arc::clone(&shared),
        id,
        ip: start.ip,
        lease: start.lease,
        watcher: start.watcher,
        logged_in: start.logged_in,
        model: Model::new(None, now),
        last_life: now,
        last_seen: now,
        last_refusal: None,
        bad: 0,
    };
    if s.logged_in && s.lease.is_none() {
        s.ensure_sysid();
    }
    s.model.set_me(s.sysid());
    tracing::info!(session = id, sysid = ?s.sysid(), client = ?s.ip, pilot = s.may_pilot(), logged_in = s.logged_in, "HMI session connected");
    let (mut tx, mut rx) = socket.split();
    let mut hub = shared.outlet.subscribe();
    let welcome = s.welcome();
    let end = 'session: {
        if send(&mut tx, &welcome).await.is_err() {
            break 'session End::SendFailed;
        }
        let mut ping = tokio::time::interval(PING_PERIOD);
        ping.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut push = tokio::time::interval(PUSH_PERIOD);
        push.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut beat = tokio::time::interval(HEARTBEAT_PERIOD);
        beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut events = Vec::new();
        loop {
            tokio::select! {
                m = rx.next() => {
                    s.last_seen = Instant::now();
                    let rights_before = (s.sysid(), s.logged_in);
                    let reply = match m {
                        None | Some(Err(_)) | Some(Ok(Message::Close(_))) => break 'session End::Closed,
                        Some(Ok(Message::Text(text))) => s.on_text(text.as_str()).await,
                        Some(Ok(Message::Binary(_))) => s.bad_message("binary messages are not part of the protocol — send JSON text"),
                        Some(Ok(Message::Ping(_))) => {
                            s.last_life = Instant::now();
                            None
                        }
                        // The browser engine answers our pings even when the
                        // page's script is frozen: seen, but no sign of life.
                        Some(Ok(Message::Pong(_))) => None,
                    };
                    if let Some(reply) = reply
                        && send(&mut tx, &reply).await.is_err()
                    {
                        break 'session End::SendFailed;
                    }
                    if (s.sysid(), s.logged_in) != rights_before
                        && send(&mut tx, &s.identity()).await.is_err()
                    {
                        break 'session End::SendFailed;
                    }
                }
                _ = ping.tick() => {
                    if s.last_seen.elapsed() > IDLE_TIMEOUT {
                        break 'session End::Idle;
                    }
                    if tx.send(Message::Ping(Default::default())).await.is_err() {
                        break 'session End::SendFailed;
                    }
                }
                d = hub.recv() => match d {
                    Ok(d) => {
                        if d.peer.is_some_and(|p| p != s.id) {
                            continue;
                        }
                        s.model.on_delivery(&d, Instant::now(), &mut events);
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
    match end {
        End::SendFailed => tracing::info!(
            session = id,
            "HMI session dropped: the browser stopped reading"
        ),
        End::Idle => tracing::info!(
            session = id,
            "HMI session closed: nothing from the browser for {} s",
            IDLE_TIMEOUT.as_secs()
        ),
        End::Closed => {}
    }
    // Whatever the browser did, the core hears that this station is gone.
    let sysid = s.sysid();
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
    drop(s.watcher.take());
}

/// COMMAND_LONG to the vehicle with the first params given, the rest 0.
fn command_long<const N: usize>(target: u8, command: MavCmd, params: [f32; N]) -> MavMessage {
    let mut p = [0f32; 7];
    p[..N].copy_from_slice(&params);
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        command,
        target_system: target,
        target_component: COMPONENT_ID,
        confirmation: 0,
    })
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

    /// May this session pilot: logged in, or admitted by `open_control`
    /// (which never applies with MAVLink signing on).
    fn may_pilot(&self) -> bool {
        self.logged_in
            || (!self.shared.signing
                && self
                    .ip
                    .is_some_and(|ip| self.shared.open_control.admits(ip)))
    }

    /// Leases a system id if this session may pilot and holds none; the
    /// watcher place is given back.
    fn ensure_sysid(&mut self) -> Option<u8> {
        if self.lease.is_none() && self.may_pilot() {
            self.lease = self.shared.lease_sysid();
            if let Some(l) = &self.lease {
                self.watcher = None;
                self.model.set_me(Some(l.sysid));
                tracing::info!(
                    session = self.id,
                    sysid = l.sysid,
                    "HMI session took a system id to pilot"
                );
            }
        }
        self.sysid()
    }

    /// Why this session may only watch, and what to do about it.
    fn watch_only_reason(&self) -> Option<String> {
        if self.sysid().is_some() {
            return None;
        }
        let set = "set one on the vehicle with `neptunus hmi set-password`, then log in here";
        Some(if self.may_pilot() {
            let (lo, hi) = self.shared.sysid_range;
            if self.shared.free_sysids.lock().is_ok_and(|f| f.is_empty()) {
                format!(
                    "all {} HMI system ids ({lo}..{hi}) are held by other pilots: this session may only watch until one is free",
                    u16::from(hi) - u16::from(lo) + 1
                )
            } else {
                return None;
            }
        } else if self.shared.signing {
            if self.shared.password.is_some() {
                "MAVLink signing is on: log in with the pilot password to pilot".to_owned()
            } else {
                format!("MAVLink signing is on and no pilot password is set: {set}")
            }
        } else if self.shared.password.is_some() {
            "log in with the pilot password to pilot".to_owned()
        } else {
            let who = match self.shared.open_control {
                OpenControl::None => {
                    "[hmi] open_control = \"none\" lets no address pilot without one".to_owned()
                }
                oc => format!(
                    "only {oc} addresses may pilot without one ([hmi] open_control = \"{oc}\")"
                ),
            };
            format!("no pilot password is set, and {who}: {set}")
        })
    }

    fn welcome(&self) -> ServerMsg {
        ServerMsg::Welcome {
            session: self.id,
            sysid: self.sysid(),
            watch_only_reason: self.watch_only_reason(),
            password_required: self.shared.password.is_some() && !self.may_pilot(),
            password_set: self.shared.password.is_some(),
            pilot: self.may_pilot(),
            logged_in: self.logged_in,
            vehicle_sysid: self.shared.vehicle_sysid,
            camera_rotation_deg: self.shared.camera_rotation_deg,
            version: env!("CARGO_PKG_VERSION"),
            modes: ModeView::offered(),
            boot_mode: Mode::BOOT.number(),
        }
    }

    /// The session's rights changed (logged in, leased an id).
    fn identity(&self) -> ServerMsg {
        ServerMsg::Identity {
            sysid: self.sysid(),
            pilot: self.may_pilot(),
            logged_in: self.logged_in,
            watch_only_reason: self.watch_only_reason(),
        }
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
        let from = self
            .shared
            .sender(self.id, sysid, self.may_pilot(), self.logged_in);
        let _ = self.shared.inputs.send(Input::Mavlink { from, msg }).await;
    }

    async fn hmi_event(&self, event: HmiEvent) {
        if let Some(sysid) = self.sysid() {
            let _ = self.shared.inputs.send(Input::Hmi { sysid, event }).await;
        }
    }

    async fn heartbeat(&self) {
        if self.sysid().is_none() || self.last_life.elapsed() > BROWSER_LIFE {
            return;
        }
        self.to_vehicle(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            // A ground station has no mode.
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
        self.to_vehicle(command_long(self.shared.vehicle_sysid, command, params))
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
        // Messages that only matter from a station with an id: without one
        // they are no-ops (a watcher's page says input_mode at start).
        let harmless = matches!(
            msg,
            ClientMsg::Alive {}
                | ClientMsg::Login { .. }
                | ClientMsg::Stop {}
                | ClientMsg::FocusLost {}
                | ClientMsg::InputMode { .. }
                | ClientMsg::ReleaseControl {}
        );
        if !harmless && self.ensure_sysid().is_none() {
            // Streamed input is answered now and then, not per message: a
            // watcher's held key would otherwise earn 20 errors a second.
            let streamed = matches!(
                msg,
                ClientMsg::Sticks { .. } | ClientMsg::Thrusters { .. } | ClientMsg::Tilt { .. }
            );
            if streamed
                && self
                    .last_refusal
                    .is_some_and(|t| t.elapsed() < REFUSAL_REPLY)
            {
                return None;
            }
            self.last_refusal = Some(Instant::now());
            let why = self
                .watch_only_reason()
                .unwrap_or_else(|| "no system id is free".into());
            return Some(ServerMsg::Error {
                message: format!("this session may only watch: {why}"),
            });
        }
        match msg {
            ClientMsg::Alive {} => {}
            ClientMsg::Login { password } => return Some(self.login(&password).await),
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

    /// The WebSocket `login` message, for clients without cookies: the
    /// same check, throttle and log as the page's form.
    async fn login(&mut self, password: &str) -> ServerMsg {
        let outcome =
            guard::check_password(&self.shared, self.ip, password, "WebSocket login").await;
        let ok = outcome == guard::Login::Ok;
        if ok {
            self.logged_in = true;
            self.ensure_sysid();
        }
        let mut message = outcome.message();
        if ok && self.sysid().is_none() {
            message.push_str(&format!(
                " — but {}",
                self.watch_only_reason().unwrap_or_default()
            ));
        }
        ServerMsg::LoginResult { ok, message }
    }
}
