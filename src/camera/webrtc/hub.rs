//! The WebRTC viewers' one task: it owns every peer connection and the
//! media sockets, and hands each picture of the one stream (access units
//! from the RTP sender, whatever route made them) to every viewer.
//!
//! The signalling connections talk to it with [`Command`]s and hear back
//! through their own [`PeerEvent`] channel. While any viewer exists it says
//! so on the `wanted` watch, which the RTP supervisor reads: the stream
//! (and so the camera) runs, with this hub among its consumers. A new
//! signalling connection says a viewer is coming: the stream is wanted from
//! then for [`COMING_FOR`], so the encoder starts while the viewer asks
//! for its session and connects, and its first keyframe is not another
//! encoder start-up later (about 0.4 s here, ffmpeg's own).
//!
//! Nor does it wait for the encoder's next keyframe: the hub holds the
//! pictures since the last keyframe (a group of at most [`HELD_PICTURES`]
//! and [`HELD_BYTES`]) and hands a viewer that has just connected the whole
//! group at once, then the live stream. The viewer shows the keyframe and
//! what followed it a little late, for an instant, instead of nothing until
//! the next keyframe — which, with the encoder started before the viewer
//! connected, would be most of a keyframe interval away.
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

/// How long a new signalling connection keeps the stream wanted without
/// a session: the encoder's start-up overlaps the viewer's asking.
pub const COMING_FOR: Duration = Duration::from_secs(5);

/// What a signalling connection asks of the hub.
#[derive(Debug)]
pub(super) enum Command {
    /// A signalling connection opened: a viewer is likely to ask for a
    /// session within [`COMING_FOR`].
    Coming,
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

/// The most pictures held for a viewer's fast start (two seconds at 30
/// fps); a longer group is not held, and a new viewer waits for the next
/// keyframe.
pub const HELD_PICTURES: usize = 60;
/// The most bytes held for a viewer's fast start.
pub const HELD_BYTES: usize = 4 << 20;

/// The pictures since the last keyframe (the keyframe first), each with
/// its bytes as every viewer shares them; empty when the group grew too
/// long or no keyframe came yet.
#[derive(Default)]
struct Held {
    pictures: Vec<(AccessUnit, Arc<[u8]>)>,
    bytes: usize,
}

impl Held {
    fn push(&mut self, au: &AccessUnit, data: &Arc<[u8]>) {
        if au.keyframe {
            self.pictures.clear();
            self.bytes = 0;
        } else if self.pictures.is_empty() {
            return;
        }
        if self.pictures.len() >= HELD_PICTURES || self.bytes + data.len() > HELD_BYTES {
            // A truncated group would not decode up to the live picture.
            self.pictures.clear();
            self.bytes = 0;
            return;
        }
        // The bytes are held once, in `data`; the unit keeps its time.
        let head = AccessUnit {
            data: Vec::new(),
            time_90khz: au.time_90khz,
            keyframe: au.keyframe,
        };
        self.pictures.push((head, Arc::clone(data)));
        self.bytes += data.len();
    }
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
        let mut held = Held::default();
        // Until when a viewer is expected (a signalling connection opened).
        let mut coming: Option<Instant> = None;
        loop {
            let next = viewers
                .values()
                .map(|v| v.peer.next_timeout())
                .chain(self.reflexive.next_timeout())
                .chain(coming)
                .min();
            let far = Instant::now() + Duration::from_secs(3600);
            let sleep = tokio::time::sleep_until(next.unwrap_or(far).into());
            tokio::select! {
                c = self.commands.recv() => match c {
                    Some(Command::Coming) => coming = Some(Instant::now() + COMING_FOR),
                    Some(c) => self.command(c, &mut viewers),
                    None => break,
                },
                Some(au) = self.units.recv() => {
                    pictures += 1;
                    self.picture(&au, &mut held, &mut viewers);
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
            coming = coming.filter(|&until| Instant::now() < until);
            self.wanted.send_if_modified(|w| {
                let now = !viewers.is_empty() || coming.is_some();
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

    /// One picture to every viewer; a viewer connected since the last
    /// picture, still without a keyframe, gets the held group (which ends
    /// with this picture) instead.
    fn picture(&self, au: &AccessUnit, held: &mut Held, viewers: &mut BTreeMap<String, Viewer>) {
        let now = Instant::now();
        let data: Arc<[u8]> = Arc::from(au.data.as_slice());
        held.push(au, &data);
        for v in viewers.values_mut() {
            if v.peer.is_connected() && !v.peer.has_keyframe() && !held.pictures.is_empty() {
                for (unit, bytes) in &held.pictures {
                    v.peer.send(now, unit, bytes);
                }
            } else {
                v.peer.send(now, au, &data);
            }
            flush(&self.sockets, &mut v.peer);
        }
    }

    fn command(&mut self, c: Command, viewers: &mut BTreeMap<String, Viewer>) {
        let now = Instant::now();
        match c {
            // Kept by `run`, which decides what is wanted.
            Command::Coming => {}
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

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(n: u64, keyframe: bool, len: usize) -> (AccessUnit, Arc<[u8]>) {
        let au = AccessUnit {
            data: vec![0; len],
            time_90khz: n * 3000,
            keyframe,
        };
        let data = Arc::from(au.data.as_slice());
        (au, data)
    }

    fn times(h: &Held) -> Vec<u64> {
        h.pictures
            .iter()
            .map(|(u, _)| u.time_90khz / 3000)
            .collect()
    }

    #[test]
    fn the_group_since_the_last_keyframe_is_held_and_nothing_before_a_keyframe() {
        let mut h = Held::default();
        for (n, key) in [(0, false), (1, false), (2, true), (3, false), (4, false)] {
            let (au, d) = unit(n, key, 10);
            h.push(&au, &d);
        }
        assert_eq!(times(&h), [2, 3, 4]);
        assert!(h.pictures[0].0.keyframe && h.pictures[0].0.data.is_empty());
        assert_eq!(h.bytes, 30);
        let (au, d) = unit(5, true, 10);
        h.push(&au, &d);
        assert_eq!(times(&h), [5]);
    }

    #[test]
    fn a_group_too_long_or_too_large_is_dropped_until_the_next_keyframe() {
        let mut h = Held::default();
        for n in 0..=HELD_PICTURES as u64 {
            let (au, d) = unit(n, n == 0, 10);
            h.push(&au, &d);
        }
        assert!(
            h.pictures.is_empty(),
            "a truncated group would not decode to the live picture"
        );
        let (au, d) = unit(100, false, 10);
        h.push(&au, &d);
        assert!(h.pictures.is_empty());
        let (au, d) = unit(101, true, HELD_BYTES / 2);
        h.push(&au, &d);
        let (au, d) = unit(102, false, HELD_BYTES / 2 + 1);
        h.push(&au, &d);
        assert!(h.pictures.is_empty() && h.bytes == 0);
        let (au, d) = unit(103, true, 10);
        h.push(&au, &d);
        assert_eq!(times(&h), [103]);
    }
}
