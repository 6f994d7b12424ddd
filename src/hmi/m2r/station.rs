//! One mavlink2rest WebSocket client: a ground station inside the process.
//!
//! Its frames enter the core as [`Input::Mavlink`] from the system and
//! component in their header, over the mavlink2rest endpoint with this
//! connection as the peer, so the core's authority rules, failsafes, signs
//! of life and pick-up apply as to any station. A client controls under the
//! browser page's rule ([`guard::may_pilot`]): it presented the pilot
//! password (login cookie, `?password=`, or a `{"password":…}` message), or
//! `[hmi] open_control` admits its address. Otherwise it only watches: of
//! its frames only read-only requests reach the core. Every frame is answered `Ok(N)` (N = bytes of
//! the MAVLink 2 frame) or [`NOT_CONVERTED`], as mavlink2rest does.
//!
//! The vehicle's messages reach the client through a [`Mailbox`]: a client
//! that never reads holds one message per stream (type, component and
//! instance) and never slows the vehicle or other clients.

use std::collections::BTreeSet;
use std::net::IpAddr;
use std::sync::Arc;
use std::time::SystemTime;

use axum::extract::ws::{Message, Utf8Bytes, WebSocket};
use futures_util::{SinkExt as _, StreamExt as _};
use mavlink_core::Message as _;
use tokio::sync::broadcast::error::RecvError;

use super::frame::{self, NOT_CONVERTED};
use super::mailbox::Mailbox;
use super::{Hub, StationSlot};
use crate::dialect::neptunus::MavMessage;
use crate::hmi::{Shared, guard};
use crate::vehicle::machine::{HmiEvent, Input, Sender};

/// What the upgrade found out.
pub(crate) struct Start {
    pub ip: Option<IpAddr>,
    /// Logged in (cookie or `?password=`).
    pub logged_in: bool,
    pub filter: Option<regex::Regex>,
    pub slot: StationSlot,
}

/// The frames a watcher may still send: requests that change nothing and
/// are answered to the asker alone (Cockpit waits for the mission count
/// and covers the picture when it never comes).
fn read_only(msg: &MavMessage) -> bool {
    use crate::dialect::neptunus::MavCmd;
    let asks = |c: MavCmd| c == MavCmd::MAV_CMD_REQUEST_MESSAGE;
    match msg {
        MavMessage::PARAM_REQUEST_LIST(_)
        | MavMessage::PARAM_REQUEST_READ(_)
        | MavMessage::TIMESYNC(_)
        | MavMessage::MISSION_REQUEST_LIST(_) => true,
        MavMessage::COMMAND_LONG(c) => asks(c.command),
        MavMessage::COMMAND_INT(c) => asks(c.command),
        _ => false,
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct LoginMsg {
    password: String,
}

struct Station {
    shared: Arc<Shared>,
    hub: Arc<Hub>,
    id: u64,
    ip: Option<IpAddr>,
    logged_in: bool,
    /// Header system ids whose frames this connection handed to the core as
    /// a station that may control.
    spoke_as: BTreeSet<u8>,
    bad: u64,
}

impl Station {
    /// May this connection's frames control the vehicle (the core still
    /// decides): the HMI's rule for a browser session.
    fn controls(&self) -> bool {
        guard::may_pilot(&self.shared, self.ip, self.logged_in)
    }

    async fn on_text(&mut self, text: &str) -> String {
        if let Ok(LoginMsg { password }) = serde_json::from_str::<LoginMsg>(text) {
            let outcome =
                guard::check_password(&self.shared, self.ip, &password, "mavlink2rest WebSocket")
                    .await;
            let ok = outcome == guard::Login::Ok;
            self.logged_in |= ok;
            return serde_json::json!({ "login": ok, "message": outcome.message() }).to_string();
        }
        let f = match frame::parse(text, self.hub.reserved) {
            Ok(f) => f,
            Err(e) => {
                self.bad += 1;
                self.hub.note_bad(self.id, &e.to_string());
                return NOT_CONVERTED.to_owned();
            }
        };
        let controls = self.controls();
        if !controls && !read_only(&f.message) {
            return format!("Err({})", guard::watch_only_reason(&self.shared));
        }
        let (sysid, compid) = (f.header.system_id, f.header.component_id);
        let n =
            crate::mavlink::frame::encode_v2(sysid, compid, f.header.sequence, &f.message).len();
        let pilot = self.shared.password.is_some() && self.logged_in;
        let from = Sender {
            signed: pilot,
            trusted: false,
            pilot,
            ..Sender::new(self.hub.endpoint, self.id, sysid, compid)
        };
        let name = f.message.message_name();
        if let Ok(json) = frame::message_json(&f.message) {
            self.hub
                .record(sysid, compid, name, Arc::from(json), SystemTime::now());
        }
        if controls && self.spoke_as.insert(sysid) {
            self.hub.station_joined(sysid);
        }
        if self
            .shared
            .inputs
            .send(Input::Mavlink {
                from,
                msg: f.message,
            })
            .await
            .is_err()
        {
            return "Err(the vehicle task is not running)".to_owned();
        }
        format!("Ok({n})")
    }
}

/// Runs one client to its end, then tells the core about the stations it
/// carried that no other client carries.
pub(crate) async fn run(socket: WebSocket, shared: Arc<Shared>, hub: Arc<Hub>, start: Start) {
    let id = shared
        .next_session
        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut st = Station {
        shared: Arc::clone(&shared),
        hub: Arc::clone(&hub),
        id,
        ip: start.ip,
        logged_in: start.logged_in,
        spoke_as: BTreeSet::new(),
        bad: 0,
    };
    tracing::info!(client = id, ip = ?st.ip, controls = st.controls(), "mavlink2rest client connected");
    let (mut tx, mut rx) = socket.split();
    let mailbox = Arc::new(Mailbox::default());
    let writer = {
        let mailbox = Arc::clone(&mailbox);
        tokio::spawn(async move {
            while let Some(text) = mailbox.next().await {
                if tx
                    .send(Message::Text(Utf8Bytes::from(&*text)))
                    .await
                    .is_err()
                {
                    break;
                }
            }
        })
    };
    let (mut out, _listening) = hub.subscribe();
    let mut wanted = std::collections::HashMap::<&'static str, bool>::new();
    loop {
        tokio::select! {
            m = rx.next() => match m {
                None | Some(Err(_)) | Some(Ok(Message::Close(_))) => break,
                Some(Ok(Message::Text(text))) => {
                    let reply = st.on_text(text.as_str()).await;
                    mailbox.reply(reply);
                }
                Some(Ok(Message::Binary(_))) => {
                    st.bad += 1;
                    mailbox.reply(NOT_CONVERTED);
                }
                Some(Ok(_)) => {}
            },
            o = out.recv() => match o {
                Ok(o) => {
                    if o.peer.is_some_and(|p| p != id) {
                        continue;
                    }
                    let name = o.stream.name;
                    let ok = *wanted.entry(name).or_insert_with(|| {
                        start.filter.as_ref().is_none_or(|re| re.is_match(name))
                    });
                    if ok {
                        mailbox.push(o.stream, Arc::clone(&o.json));
                    }
                }
                Err(RecvError::Lagged(n)) => {
                    tracing::debug!(client = id, "mavlink2rest client fell behind by {n} vehicle messages");
                }
                Err(RecvError::Closed) => break,
            },
        }
    }
    mailbox.close();
    writer.abort();
    for sysid in std::mem::take(&mut st.spoke_as) {
        if hub.station_left(sysid) {
            let _ = shared
                .inputs
                .send(Input::Hmi {
                    sysid,
                    event: HmiEvent::Disconnected,
                })
                .await;
        }
    }
    tracing::info!(
        client = id,
        bad_frames = st.bad,
        dropped = mailbox.dropped(),
        "mavlink2rest client closed"
    );
    drop(start.slot);
}
