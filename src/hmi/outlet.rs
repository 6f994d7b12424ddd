//! What the vehicle hands the in-process HMI endpoints in one pass of its
//! loop: each message as the sessions (or mavlink2rest) get it, gathered
//! into one batch so the browser side's thread wakes once for all of it.

use std::sync::Arc;

use tokio::sync::broadcast;

use super::HUB_CAPACITY;
use crate::dialect::neptunus::MavMessage;
use crate::vehicle::machine::{COMPONENT_ID, To, Topic};

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
    /// sessions talk to the autopilot alone.
    every_component: bool,
    hub: broadcast::Sender<Deliveries>,
}

impl Outlet {
    /// An outlet that hears the autopilot alone.
    pub fn new(endpoint: usize) -> Self {
        Self {
            endpoint,
            every_component: false,
            hub: broadcast::channel(HUB_CAPACITY).0,
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
        if compid != COMPONENT_ID && !self.every_component {
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
}
