//! One viewer's peer connection, sans-IO: str0m's `Rtc` offering one
//! send-only H.264 video track, fed the encoder's access units.
//!
//! The offer names one codec, H.264 constrained baseline
//! (`profile-level-id=42e01f`, `packetization-mode=1`: what the encoder
//! makes and every WebRTC browser decodes), and the vehicle's host
//! candidates (plus any server-reflexive one a STUN server gave), and the
//! playout-delay RTP header extension: every picture goes out asking the
//! viewer to show it at once (minimum and maximum delay 0), which a
//! browser that takes the extension (Chromium does) obeys by holding no
//! frame back for smoothness, whatever page plays it. Until
//! its first keyframe a viewer gets no picture (it could not decode one);
//! after that, every access unit, packetized by str0m.
//!
//! str0m's one rule is kept inside: every call that changes the `Rtc`
//! drains its output to the next timeout before returning, so the caller
//! only sends [`Peer::take_transmits`] and calls [`Peer::timeout`] at
//! [`Peer::next_timeout`]. Time is an argument; nothing here reads a clock
//! or touches a socket.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use str0m::change::{SdpAnswer, SdpPendingOffer};
use str0m::format::Codec;
use str0m::media::{Direction, Frequency, MediaKind, MediaTime, Mid, Pt};
use str0m::net::{Protocol, Receive};
use str0m::rtp::Extension;
use str0m::{Candidate, Event, IceConnectionState, Input, Output, Rtc, RtcError};

use crate::camera::h264::AccessUnit;

/// The payload type the offer gives H.264 (and its retransmissions).
const H264_PT: u8 = 96;
const RTX_PT: u8 = 97;
/// The id of the playout-delay extension in the offer (free in str0m's
/// standard map, which the offer keeps).
const PLAYOUT_DELAY_ID: u8 = 5;
/// Constrained baseline, level 3.1.
pub const PROFILE_LEVEL_ID: u32 = 0x42e01f;
/// A viewer that has not connected by then is given up.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(20);

/// Why a peer connection could not go on.
#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    #[error("the SDP answer does not parse: {0}")]
    AnswerSdp(String),
    #[error("the SDP answer does not fit the offer: {0}")]
    Answer(RtcError),
    #[error("the answer came already")]
    Answered,
    #[error(
        "the ICE candidate {0:?} does not parse (a browser's mDNS name is fine: its checks still arrive)"
    )]
    Candidate(String),
    #[error("no local address to offer: the vehicle has no usable network address")]
    NoAddress,
    #[error("str0m made no offer for the video track")]
    NothingToOffer,
}

/// A datagram to send: from which local socket, to where.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Datagram {
    pub from: SocketAddr,
    pub to: SocketAddr,
    pub data: Vec<u8>,
}

/// One viewer.
pub struct Peer {
    rtc: Rtc,
    mid: Mid,
    pending: Option<SdpPendingOffer>,
    pt: Option<Pt>,
    started: Instant,
    connected: bool,
    /// The viewer has had a keyframe: it can decode what follows.
    has_keyframe: bool,
    frames: u64,
    keyframe_requests: u64,
    out: Vec<Datagram>,
    next: Instant,
    ended: Option<String>,
}

impl Peer {
    /// A new peer connection and its SDP offer. `locals`: the candidates
    /// (host, and server-reflexive with their base) the viewer may reach.
    pub fn offer(now: Instant, locals: &[Candidate]) -> Result<(Peer, String), PeerError> {
        if locals.is_empty() {
            return Err(PeerError::NoAddress);
        }
        let mut cfg = Rtc::builder()
            .clear_codecs()
            .set_extension(PLAYOUT_DELAY_ID, Extension::PlayoutDelay);
        cfg.codec_config().add_h264(
            Pt::new_with_value(H264_PT),
            Some(Pt::new_with_value(RTX_PT)),
            true,
            PROFILE_LEVEL_ID,
        );
        let mut rtc = cfg.set_stats_interval(None).build(now);
        for c in locals {
            rtc.add_local_candidate(c.clone());
        }
        let mut sdp = rtc.sdp_api();
        let mid = sdp.add_media(
            MediaKind::Video,
            Direction::SendOnly,
            Some("neptunus".into()),
            Some("camera".into()),
            None,
        );
        let (offer, pending) = sdp.apply().ok_or(PeerError::NothingToOffer)?;
        let mut peer = Peer {
            rtc,
            mid,
            pending: Some(pending),
            pt: None,
            started: now,
            connected: false,
            has_keyframe: false,
            frames: 0,
            keyframe_requests: 0,
            out: Vec::new(),
            next: now,
            ended: None,
        };
        peer.drain(now);
        Ok((peer, offer.to_sdp_string()))
    }

    /// The mid of the video track (`sdpMid` of our candidates).
    pub fn mid(&self) -> String {
        self.mid.to_string()
    }

    pub fn accept_answer(&mut self, now: Instant, sdp: &str) -> Result<(), PeerError> {
        let pending = self.pending.take().ok_or(PeerError::Answered)?;
        let answer =
            SdpAnswer::from_sdp_string(sdp).map_err(|e| PeerError::AnswerSdp(e.to_string()))?;
        let result = self.rtc.sdp_api().accept_answer(pending, answer);
        self.drain(now);
        result.map_err(PeerError::Answer)?;
        self.pt = self.rtc.writer(self.mid).and_then(|w| {
            w.payload_params()
                .find(|p| p.spec().codec == Codec::H264)
                .map(|p| p.pt())
        });
        Ok(())
    }

    pub fn add_remote_candidate(&mut self, now: Instant, candidate: &str) -> Result<(), PeerError> {
        let line = candidate.trim().trim_start_matches("a=");
        let c = Candidate::from_sdp_string(line)
            .map_err(|_| PeerError::Candidate(candidate.to_owned()))?;
        self.rtc.add_remote_candidate(c);
        self.drain(now);
        Ok(())
    }

    /// One more address of ours (a public one a STUN server told late):
    /// its candidate line for the viewer, when the `Rtc` took it.
    pub fn add_local_candidate(&mut self, now: Instant, c: Candidate) -> Option<String> {
        let line = self
            .rtc
            .add_local_candidate(c)
            .map(Candidate::to_sdp_string);
        self.drain(now);
        line
    }

    /// Whether a datagram that arrived on `local` from `from` is this
    /// peer's (ICE by its credentials, the rest by its address).
    pub fn accepts(&self, now: Instant, from: SocketAddr, local: SocketAddr, data: &[u8]) -> bool {
        match Receive::new(Protocol::Udp, from, local, data) {
            Ok(r) => self.rtc.accepts(&Input::Receive(now, r)),
            Err(_) => false,
        }
    }

    pub fn receive(&mut self, now: Instant, from: SocketAddr, local: SocketAddr, data: &[u8]) {
        let Ok(r) = Receive::new(Protocol::Udp, from, local, data) else {
            return;
        };
        if let Err(e) = self.rtc.handle_input(Input::Receive(now, r)) {
            self.end(format!("WebRTC failed: {e}"));
        }
        self.drain(now);
    }

    /// One picture of the encoder, shared by every viewer: `data` holds
    /// its bytes, allocated once for all (`au.data` is not read; the hub
    /// leaves it empty in the pictures it holds).
    pub fn send(&mut self, now: Instant, au: &AccessUnit, data: &Arc<[u8]>) {
        let Some(pt) = self.pt.filter(|_| self.connected && self.ended.is_none()) else {
            return;
        };
        if !self.has_keyframe && !au.keyframe {
            return;
        }
        self.has_keyframe = true;
        let time = MediaTime::new(au.time_90khz, Frequency::NINETY_KHZ);
        // No playout delay: the picture is for a pilot, shown when whole.
        let zero = MediaTime::from_hundredths(0);
        let written = match self.rtc.writer(self.mid) {
            Some(w) => w
                .playout_delay(zero, zero)
                .write(pt, now, time, Arc::clone(data)),
            None => return,
        };
        match written {
            Ok(()) => self.frames += 1,
            Err(e) => self.end(format!("WebRTC failed: {e}")),
        }
        self.drain(now);
    }

    /// Time passes (call at [`next_timeout`](Peer::next_timeout) or later).
    pub fn timeout(&mut self, now: Instant) {
        if !self.connected && now.duration_since(self.started) >= CONNECT_TIMEOUT {
            self.end(format!(
                "no connection within {} s: the viewer could not reach any of the vehicle's addresses (check the network; away from the tether, configure ICE servers)",
                CONNECT_TIMEOUT.as_secs()
            ));
        }
        if let Err(e) = self.rtc.handle_input(Input::Timeout(now)) {
            self.end(format!("WebRTC failed: {e}"));
        }
        self.drain(now);
    }

    /// When [`timeout`](Peer::timeout) is due.
    pub fn next_timeout(&self) -> Instant {
        if self.connected {
            self.next
        } else {
            self.next.min(self.started + CONNECT_TIMEOUT)
        }
    }

    pub fn take_transmits(&mut self) -> Vec<Datagram> {
        std::mem::take(&mut self.out)
    }

    /// Why the connection is over; `None` while it goes on.
    pub fn ended(&self) -> Option<&str> {
        self.ended.as_deref()
    }

    pub fn is_connected(&self) -> bool {
        self.connected
    }

    /// The viewer has been sent a keyframe: what follows decodes.
    pub fn has_keyframe(&self) -> bool {
        self.has_keyframe
    }

    /// Pictures handed to str0m so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The viewer's requests for a keyframe (PLI, FIR): it gets the
    /// encoder's next one, at most half a second away (it cannot be
    /// asked for one: see `rtp::encoder::Encode::gop`).
    pub fn keyframe_requests(&self) -> u64 {
        self.keyframe_requests
    }

    /// Closes the connection with a reason (sent as the session's end).
    pub fn end(&mut self, reason: String) {
        if self.ended.is_none() {
            self.ended = Some(reason);
            self.rtc.disconnect();
        }
    }

    /// str0m's rule: after a change, everything out until the next timeout.
    fn drain(&mut self, now: Instant) {
        // A bound that a healthy Rtc never reaches: a burst of packets for
        // one picture is a few hundred outputs.
        for _ in 0..100_000 {
            match self.rtc.poll_output() {
                Ok(Output::Timeout(t)) => {
                    self.next = t.max(now);
                    return;
                }
                Ok(Output::Transmit(t)) => self.out.push(Datagram {
                    from: t.source,
                    to: t.destination,
                    data: t.contents.into(),
                }),
                Ok(Output::Event(e)) => self.on_event(e),
                Err(e) => {
                    self.end(format!("WebRTC failed: {e}"));
                    self.next = now + Duration::from_secs(1);
                    return;
                }
            }
        }
        self.next = now + Duration::from_millis(1);
    }

    fn on_event(&mut self, e: Event) {
        match e {
            Event::Connected => self.connected = true,
            Event::IceConnectionStateChange(IceConnectionState::Disconnected) => {
                self.end("the viewer stopped answering (ICE disconnected)".into());
            }
            Event::KeyframeRequest(_) => self.keyframe_requests += 1,
            _ => {}
        }
        if !self.rtc.is_alive() && self.ended.is_none() {
            self.ended = Some("the viewer closed the connection".into());
        }
    }
}
