//! The WebRTC viewers' one task: it owns every peer connection and the
//! media sockets, and hands each picture of the one stream (access units
//! from the RTP sender, whatever route made them) to every viewer.
//!
//! The signalling connections talk to it with [`Command`]s and hear back
//! through their own [`PeerEvent`] channel. While any viewer exists it says
//! so on the `wanted` watch, which the RTP supervisor reads: the stream
//! (and so the camera) runs, with this hub among its consumers.
//! Nothing here decides who may watch (the HMI's Host and Origin rules are
//! in front of the signalling) or panics on what arrives.

use std::collections::BTreeMap;
use std::net::IpAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::{mpsc, watch};

use crate::camera::h264::AccessUnit;

use super::net::{Inbound, Sockets};
use super::peer::Peer;
use super::protocol::Bind;
use super::signalling::PeerEvent;
use super::stun::Reflexive;

/// What a signalling connection asks of the hub.
#[derive(Debug)]
pub(super) enum Command {
    Start {
        bind: Bind,
        events: mpsc::UnboundedSender<PeerEvent>,
        /// The vehicle's address the viewer's signalling connection
        /// reached: the one host candidate it is offered (`None`: every
        /// address of the vehicle).
        reached: Option<IpAddr>,
    },
    Answer {
        session_id: String,
        sdp: String,
    },
    Candidate {
        session_id: String,
        candidate: String,
    },
    End {
        session_id: String,
    },
}

struct Viewer {
    peer: Peer,
    events: mpsc::UnboundedSender<PeerEvent>,
    consumer: String,
}

pub(super) struct Hub {
    pub commands: mpsc::Receiver<Command>,
    /// The stream's pictures, from the RTP sender.
    pub units: mpsc::Receiver<AccessUnit>,
    pub wanted: watch::Sender<bool>,
    pub max_viewers: usize,
    pub sockets: Sockets,
    pub inbound: mpsc::Receiver<Inbound>,
    pub reflexive: Reflexive,
}

impl Hub {
    pub(super) async fn run(mut self) {
        let mut viewers: BTreeMap<String, Viewer> = BTreeMap::new();
        let mut logged = Instant::now();
        let mut pictures = 0u64;
        loop {
            let next = viewers
                .values()
                .map(|v| v.peer.next_timeout())
                .chain(self.reflexive.next_timeout())
                .min();
            let far = Instant::now() + Duration::from_secs(3600);
            let sleep = tokio::time::sleep_until(next.unwrap_or(far).into());
            tokio::select! {
                c = self.commands.recv() => match c {
                    Some(c) => self.command(c, &mut viewers),
                    None => break,
                },
                Some(au) = self.units.recv() => {
                    pictures += 1;
                    self.picture(&au, &mut viewers);
                }
                Some(d) = self.inbound.recv() => {
                    if let Some(new) = self.reflexive.take(&d) {
                        if new {
                            self.share_reflexive(&mut viewers);
                        }
                    } else if let Some(v) = viewers
                        .values_mut()
                        .find(|v| v.peer.accepts(d.at, d.from, d.local, &d.data))
                    {
                        v.peer.receive(d.at, d.from, d.local, &d.data);
                        flush(&self.sockets, &mut v.peer);
                    }
                }
                () = sleep => {
                    let now = Instant::now();
                    for v in viewers.values_mut().filter(|v| v.peer.next_timeout() <= now) {
                        v.peer.timeout(now);
                        flush(&self.sockets, &mut v.peer);
                    }
                    self.reflexive.timeout(now, &self.sockets);
                }
            }
            reap(&mut viewers);
            self.wanted.send_if_modified(|w| {
                let now = !viewers.is_empty();
                std::mem::replace(w, now) != now
            });
            if logged.elapsed() >= Duration::from_secs(60) && !viewers.is_empty() {
                logged = Instant::now();
                tracing::info!(viewers = viewers.len(), pictures, "WebRTC video");
            }
        }
        for (session_id, v) in viewers {
            let _ = v.events.send(PeerEvent::Ended {
                session_id,
                reason: "the vehicle is shutting down".into(),
            });
        }
    }

    /// One picture to every viewer.
    fn picture(&self, au: &AccessUnit, viewers: &mut BTreeMap<String, Viewer>) {
        let now = Instant::now();
        let data: Arc<[u8]> = Arc::from(au.data.as_slice());
        for v in viewers.values_mut() {
            v.peer.send(now, au, &data);
            flush(&self.sockets, &mut v.peer);
        }
    }

    fn command(&mut self, c: Command, viewers: &mut BTreeMap<String, Viewer>) {
        let now = Instant::now();
        match c {
            Command::Start {
                bind,
                events,
                reached,
            } => {
                let session_id = bind.session_id.clone();
                let refuse = |reason: String| PeerEvent::Ended {
                    session_id: session_id.clone(),
                    reason,
                };
                if viewers.len() >= self.max_viewers {
                    let _ = events.send(refuse(format!(
                        "the vehicle serves at most {} WebRTC viewers at once (camera.webrtc.max_viewers), all watching now: close one",
                        self.max_viewers
                    )));
                    return;
                }
                // The address the viewer reached is one it can reach: offer
                // it alone (one route, no guessing for the viewer), else all.
                let hosts = match reached.and_then(|ip| self.sockets.ensure(ip)) {
                    Some(local) => vec![local],
                    None => self.sockets.refresh(),
                };
                let mut locals: Vec<str0m::Candidate> = hosts
                    .into_iter()
                    .filter_map(|a| str0m::Candidate::host(a, "udp").ok())
                    .collect();
                locals.extend(self.reflexive.candidates());
                match Peer::offer(now, &locals) {
                    Ok((mut peer, sdp)) => {
                        tracing::info!(
                            session = %session_id,
                            consumer = %bind.consumer_id,
                            candidates = locals.len(),
                            "WebRTC: viewer session started"
                        );
                        let _ = events.send(PeerEvent::Offer {
                            session_id: session_id.clone(),
                            sdp,
                        });
                        let mid = peer.mid();
                        for c in &locals {
                            let _ = events.send(PeerEvent::Candidate {
                                session_id: session_id.clone(),
                                candidate: c.to_sdp_string(),
                                mid: mid.clone(),
                            });
                        }
                        flush(&self.sockets, &mut peer);
                        viewers.insert(
                            session_id,
                            Viewer {
                                peer,
                                events,
                                consumer: bind.consumer_id,
                            },
                        );
                    }
                    Err(e) => {
                        tracing::warn!("WebRTC: no session for a viewer: {e}");
                        let _ = events.send(refuse(e.to_string()));
                    }
                }
            }
            Command::Answer { session_id, sdp } => {
                if let Some(v) = viewers.get_mut(&session_id) {
                    if let Err(e) = v.peer.accept_answer(now, &sdp) {
                        v.peer.end(e.to_string());
                    }
                    flush(&self.sockets, &mut v.peer);
                }
            }
            Command::Candidate {
                session_id,
                candidate,
            } => {
                if let Some(v) = viewers.get_mut(&session_id) {
                    // A browser hides its addresses behind mDNS names; its
                    // checks arrive all the same (as peer-reflexive).
                    if let Err(e) = v.peer.add_remote_candidate(now, &candidate) {
                        tracing::debug!(session = %session_id, "{e}");
                    }
                    flush(&self.sockets, &mut v.peer);
                }
            }
            Command::End { session_id } => {
                if let Some(v) = viewers.remove(&session_id) {
                    tracing::info!(
                        session = %session_id,
                        consumer = %v.consumer,
                        pictures = v.peer.frames(),
                        "WebRTC: viewer session ended by the viewer"
                    );
                }
            }
        }
    }

    /// A STUN server told us our public address: later offers carry it;
    /// sessions still connecting get it as a trickled candidate.
    fn share_reflexive(&mut self, viewers: &mut BTreeMap<String, Viewer>) {
        let now = Instant::now();
        for c in self.reflexive.candidates() {
            for (session_id, v) in viewers.iter_mut().filter(|(_, v)| !v.peer.is_connected()) {
                if let Some(candidate) = v.peer.add_local_candidate(now, c.clone()) {
                    let _ = v.events.send(PeerEvent::Candidate {
                        session_id: session_id.clone(),
                        candidate,
                        mid: v.peer.mid(),
                    });
                }
                flush(&self.sockets, &mut v.peer);
            }
        }
    }
}

/// Sends what a peer has to send.
fn flush(sockets: &Sockets, peer: &mut Peer) {
    for d in peer.take_transmits() {
        sockets.send(d.from, d.to, &d.data);
    }
}

/// Removes the viewers whose connection ended, telling their signalling.
fn reap(viewers: &mut BTreeMap<String, Viewer>) {
    let ended: Vec<String> = viewers
        .iter()
        .filter(|(_, v)| v.peer.ended().is_some())
        .map(|(k, _)| k.clone())
        .collect();
    for session_id in ended {
        let Some(v) = viewers.remove(&session_id) else {
            continue;
        };
        let reason = v.peer.ended().unwrap_or("ended").to_owned();
        tracing::info!(
            session = %session_id,
            consumer = %v.consumer,
            pictures = v.peer.frames(),
            keyframe_requests = v.peer.keyframe_requests(),
            "WebRTC: viewer session ended: {reason}"
        );
        let _ = v.events.send(PeerEvent::Ended { session_id, reason });
    }
}
