//! What the vehicle hands the in-process HMI endpoints in one pass of its
//! loop: each message as the sessions (or mavlink2rest) get it, gathered
//! into one batch so the browser side's thread wakes once for all of it —
//! and who listens there, so the vehicle builds the endpoint's telemetry
//! streams only while someone does.
//!
//! Listeners are counted, not inferred from the hub's receivers (the REST
//! views always hold one): a browser session and a mavlink2rest WebSocket
//! client each hold a [`Listening`] for their lifetime; a REST read
//! ([`Outlet::read`]) keeps the endpoint listened for [`READ_LINGER`] and,
//! when nobody listened before it, waits for the view to follow the vehicle
//! again before it answers.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{broadcast, watch};
use tokio::time::Instant;

use super::HUB_CAPACITY;
use crate::dialect::neptunus::MavMessage;
use crate::vehicle::machine::{CAMERA_COMPONENT_ID, COMPONENT_ID, To, Topic};

/// One message from the vehicle to HMI sessions.
#[derive(Debug, Clone, PartialEq)]
pub struct Delivery {
    /// `None`: for every session; `Some(peer)`: for one session (or the server).
    pub peer: Option<u64>,
    /// The vehicle's component that sent it: the autopilot
    /// ([`COMPONENT_ID`]) but for an outlet that hears every component.
    pub compid: u8,
    pub msg: MavMessage,
    /// For a STATUSTEXT: what it is about, as the core chose it.
    pub topic: Option<Topic>,
}

/// What the vehicle said in one pass of its loop, in order. It crosses to
/// the browser side's thread in one piece, so that thread wakes once for
/// all of it rather than once a message.
pub type Deliveries = Arc<[Delivery]>;

/// The next batch already in the hub, as `recv` would give it (None:
/// nothing is queued): readers drain what waits before they sleep again.
pub(crate) fn queued(
    rx: &mut broadcast::Receiver<Deliveries>,
) -> Option<Result<Deliveries, broadcast::error::RecvError>> {
    use broadcast::error::{RecvError, TryRecvError};
    match rx.try_recv() {
        Ok(b) => Some(Ok(b)),
        Err(TryRecvError::Lagged(n)) => Some(Err(RecvError::Lagged(n))),
        Err(TryRecvError::Closed) => Some(Err(RecvError::Closed)),
        Err(TryRecvError::Empty) => None,
    }
}

/// The vehicle task's side of the hub: delivers the core's messages for the
/// HMI endpoint to the sessions.
#[derive(Debug, Clone)]
pub struct Outlet {
    endpoint: usize,
    /// Whether it hears the vehicle's other components (the camera) as well
    /// as its autopilot: mavlink2rest does, as on the wire; the browser
    /// sessions talk to the autopilot, and hear of the camera only its
    /// recording (capture status, acks).
    every_component: bool,
    hub: broadcast::Sender<Deliveries>,
    listeners: Arc<Listeners>,
}

/// How long a REST read keeps the endpoint's streams built: a script
/// polling every few seconds reads live data without waiting each time.
pub const READ_LINGER: Duration = Duration::from_secs(10);

/// How long a REST read that woke a quiet endpoint waits for the view to
/// follow the vehicle (one pass of the vehicle's loop; it answers with what
/// it has after this).
pub const WAKE_WAIT: Duration = Duration::from_secs(1);

#[derive(Debug)]
struct Listeners {
    count: watch::Sender<usize>,
    /// Until when REST reads keep the endpoint listened (`Some` while the
    /// lingering listener lives).
    reading_until: Mutex<Option<Instant>>,
}

/// One listener on an outlet's endpoint, counted while it lives.
#[derive(Debug)]
#[must_use = "the endpoint counts as listened only while this lives"]
pub struct Listening(Arc<Listeners>);

impl Drop for Listening {
    fn drop(&mut self) {
        self.0.count.send_modify(|n| *n = n.saturating_sub(1));
    }
}

impl Outlet {
    /// An outlet that hears the autopilot alone.
    pub fn new(endpoint: usize) -> Self {
        Self {
            endpoint,
            every_component: false,
            hub: broadcast::channel(HUB_CAPACITY).0,
            listeners: Arc::new(Listeners {
                count: watch::Sender::new(0),
                reading_until: Mutex::new(None),
            }),
        }
    }

    /// An outlet that hears every component of the vehicle.
    pub fn every_component(endpoint: usize) -> Self {
        Self {
            every_component: true,
            ..Self::new(endpoint)
        }
    }

    pub fn endpoint(&self) -> usize {
        self.endpoint
    }

    /// `msg` from component `compid` as the sessions it is addressed to
    /// get it (no encoding: sessions read the message itself); None when
    /// it is for none of them.
    pub fn delivery(
        &self,
        to: To,
        compid: u8,
        msg: &MavMessage,
        topic: Option<Topic>,
    ) -> Option<Delivery> {
        if compid != COMPONENT_ID && !self.every_component && !for_sessions(compid, msg) {
            return None;
        }
        let peer = match to {
            To::All => None,
            To::Endpoint(e) if e == self.endpoint => None,
            To::Peer(e, p) if e == self.endpoint => Some(p),
            _ => return None,
        };
        Some(Delivery {
            peer,
            compid,
            msg: msg.clone(),
            topic,
        })
    }

    /// Hands over what one pass of the vehicle's loop delivered, emptying
    /// `batch` (dropped when nobody listens).
    pub fn deliver_all(&self, batch: &mut Vec<Delivery>) {
        if batch.is_empty() {
            return;
        }
        if self.hub.receiver_count() > 0 {
            let _ = self.hub.send(Arc::from(std::mem::take(batch)));
        } else {
            batch.clear();
        }
    }

    /// Whether `to` reaches nobody but HMI sessions (nothing to encode for the wire).
    pub fn only_hmi(&self, to: To) -> bool {
        matches!(to, To::Endpoint(e) | To::Peer(e, _) if e == self.endpoint)
    }

    pub fn subscribe(&self) -> broadcast::Receiver<Deliveries> {
        self.hub.subscribe()
    }

    /// Counts one listener on the endpoint while the guard lives.
    pub fn listen(&self) -> Listening {
        self.listeners.count.send_modify(|n| *n += 1);
        Listening(Arc::clone(&self.listeners))
    }

    /// How many listen now, as the vehicle task follows it.
    pub fn listeners(&self) -> watch::Receiver<usize> {
        self.listeners.count.subscribe()
    }

    /// A REST read of a view the endpoint's messages keep (`view`): keeps the
    /// endpoint listened for [`READ_LINGER`]; when nobody listened before,
    /// waits (at most [`WAKE_WAIT`]) until `view` changed and `live` says
    /// it holds what the read is for, so the answer is live rather than what
    /// was there when the last listener left (or a pass the vehicle made
    /// before it knew of the reader, which has only what goes to everyone).
    pub async fn read<T>(&self, view: &mut watch::Receiver<T>, live: impl Fn() -> bool) {
        let was_quiet = *self.listeners.count.borrow() == 0;
        view.borrow_and_update();
        self.linger();
        if was_quiet {
            let deadline = Instant::now() + WAKE_WAIT;
            while let Ok(Ok(())) = tokio::time::timeout_at(deadline, view.changed()).await {
                if live() {
                    break;
                }
            }
        }
    }

    /// One listener that lives until [`READ_LINGER`] after the last read.
    fn linger(&self) {
        let until = Instant::now() + READ_LINGER;
        {
            let mut g = lock(&self.listeners.reading_until);
            let lives = g.is_some();
            *g = Some(until);
            if lives {
                return;
            }
        }
        let guard = self.listen();
        tokio::spawn(async move {
            loop {
                let until = {
                    let mut g = lock(&guard.0.reading_until);
                    match *g {
                        Some(t) if t > Instant::now() => t,
                        _ => {
                            *g = None;
                            return;
                        }
                    }
                };
                tokio::time::sleep_until(until).await;
            }
        });
    }
}

/// What the browser sessions hear from the camera (component 100):
/// whether it can record and does, and its answers to their requests —
/// nothing that could pass for the autopilot's state.
fn for_sessions(compid: u8, msg: &MavMessage) -> bool {
    compid == CAMERA_COMPONENT_ID
        && matches!(
            msg,
            MavMessage::CAMERA_INFORMATION(_)
                | MavMessage::CAMERA_CAPTURE_STATUS(_)
                | MavMessage::COMMAND_ACK(_)
        )
}

/// The lock, also after a panic elsewhere while it was held (it guards a
/// plain deadline).
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
