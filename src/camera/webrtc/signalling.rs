//! One signalling connection, sans-IO: the messages a consumer (Cockpit,
//! the HMI page) sends in, what they mean for its sessions, and what goes
//! back — as mavlink-camera-manager answers them.
//!
//! `peerId` gets this connection's consumer id; `availableStreams` the
//! camera, if there is one; `startSession` with the camera's id the
//! answer with a new session id, after which the vehicle (the producer)
//! makes the SDP offer; the consumer's SDP answer and ICE candidates go to
//! that session, and ours to the consumer. A connection touches only the
//! sessions it started: every negotiation names its session, consumer and
//! producer, and anything else is refused with an `error` message saying
//! why, counted, and changes nothing. Nothing here panics on what a client
//! sends.
//!
//! The peer connections themselves are the hub's ([`Action`]s go there,
//! [`PeerEvent`]s come back); this file never touches a socket or a clock.

use std::collections::BTreeMap;

use super::protocol::{
    Answer, Bind, EndSession, IceCandidate, IceNegotiation, MediaNegotiation, Message, Negotiation,
    PeerIdAnswer, Question, SessionDescription, Stream,
};

/// Sessions one connection may hold at once.
pub const MAX_SESSIONS_PER_CONNECTION: usize = 4;
/// Longest id a client may name (ours are 36-character UUIDs).
const MAX_ID_BYTES: usize = 64;

/// What the connection's task must do.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Action {
    /// Send this text to the consumer.
    Send(String),
    /// Start a peer connection for this session: the hub makes the offer.
    Start(Bind),
    /// The consumer's SDP answer for the session.
    Answer { session_id: String, sdp: String },
    /// One ICE candidate of the consumer (`candidate:…`).
    Candidate {
        session_id: String,
        candidate: String,
    },
    /// The session is over: drop its peer connection.
    End { session_id: String },
}

/// What the hub reports about a session.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PeerEvent {
    Offer {
        session_id: String,
        sdp: String,
    },
    Candidate {
        session_id: String,
        candidate: String,
        mid: String,
    },
    /// The peer connection ended (failed, timed out, refused): the
    /// consumer is told with `endSession` and the reason.
    Ended {
        session_id: String,
        reason: String,
    },
}

/// Why a message was refused (sent back as `{"type":"error"}`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    #[error("{0}")]
    Unreadable(String),
    #[error("an id longer than {MAX_ID_BYTES} bytes")]
    LongId,
    #[error("{0} is a message a producer sends, not a consumer")]
    NotFromConsumer(&'static str),
    #[error("no stream with id {0:?}: ask availableStreams for the ids")]
    NoStream(String),
    #[error("no session {0:?} of this connection (started here and not ended)")]
    NoSession(String),
    #[error("session {0:?} names another consumer or producer than it was started with")]
    WrongParties(String),
    #[error("the vehicle makes the offer: answer it with an SDP of type \"answer\"")]
    OfferFromConsumer,
    #[error("session {0:?} already has its SDP answer")]
    AlreadyAnswered(String),
    #[error("this connection already holds {MAX_SESSIONS_PER_CONNECTION} sessions: end one first")]
    TooManySessions,
}

/// A session of this connection.
#[derive(Debug, Clone)]
struct Session {
    bind: Bind,
    answered: bool,
}

/// One connection's state. `new_id` makes the ids this connection hands
/// out (random UUIDs in the vehicle, counters in tests).
pub struct Signalling {
    consumer_id: String,
    stream: Option<Stream>,
    sessions: BTreeMap<String, Session>,
    new_id: Box<dyn FnMut() -> String + Send>,
    refused: u64,
}

impl Signalling {
    /// `stream`: the camera as `availableStreams` lists it (`None`: no
    /// camera, an empty list).
    pub fn new(stream: Option<Stream>, mut new_id: Box<dyn FnMut() -> String + Send>) -> Self {
        Signalling {
            consumer_id: new_id(),
            stream,
            sessions: BTreeMap::new(),
            new_id,
            refused: 0,
        }
    }

    pub fn consumer_id(&self) -> &str {
        &self.consumer_id
    }

    /// Messages refused so far.
    pub fn refused(&self) -> u64 {
        self.refused
    }

    /// The sessions still open (to end when the connection closes).
    pub fn session_ids(&self) -> Vec<String> {
        self.sessions.keys().cloned().collect()
    }

    /// One text from the consumer. A refusal is also returned, for the log.
    pub fn on_text(&mut self, text: &str) -> (Vec<Action>, Option<Refusal>) {
        match self.handle(text) {
            Ok(actions) => (actions, None),
            Err(r) => {
                self.refused += 1;
                let reply = Message::Error(r.to_string()).to_json();
                (vec![Action::Send(reply)], Some(r))
            }
        }
    }

    fn handle(&mut self, text: &str) -> Result<Vec<Action>, Refusal> {
        let msg = Message::parse(text).map_err(|e| Refusal::Unreadable(e.to_string()))?;
        match msg {
            Message::Question(Question::PeerId) => {
                Ok(vec![send(Message::Answer(Answer::PeerId(PeerIdAnswer {
                    id: self.consumer_id.clone(),
                })))])
            }
            Message::Question(Question::AvailableStreams) => Ok(vec![send(Message::Answer(
                Answer::AvailableStreams(self.stream.iter().cloned().collect()),
            ))]),
            Message::Question(Question::StartSession(offer)) => {
                check_id(&offer.consumer_id)?;
                check_id(&offer.producer_id)?;
                if self
                    .stream
                    .as_ref()
                    .is_none_or(|s| s.id != offer.producer_id)
                {
                    return Err(Refusal::NoStream(offer.producer_id));
                }
                if self.sessions.len() >= MAX_SESSIONS_PER_CONNECTION {
                    return Err(Refusal::TooManySessions);
                }
                // The consumer id is the one the client gives: Cockpit keeps
                // the id of an earlier connection after it reconnects. The
                // session is this connection's either way.
                let bind = Bind {
                    consumer_id: offer.consumer_id,
                    producer_id: offer.producer_id,
                    session_id: (self.new_id)(),
                };
                self.sessions.insert(
                    bind.session_id.clone(),
                    Session {
                        bind: bind.clone(),
                        answered: false,
                    },
                );
                // The answer first: Cockpit listens for the offer only
                // once it has the session id.
                Ok(vec![
                    send(Message::Answer(Answer::StartSession(bind.clone()))),
                    Action::Start(bind),
                ])
            }
            Message::Question(Question::EndSession(end)) => {
                self.session(&end.bind)?;
                self.sessions.remove(&end.bind.session_id);
                Ok(vec![Action::End {
                    session_id: end.bind.session_id,
                }])
            }
            Message::Negotiation(Negotiation::MediaNegotiation(m)) => {
                let session = self.session(&m.bind)?;
                let SessionDescription::Answer { sdp } = m.sdp else {
                    return Err(Refusal::OfferFromConsumer);
                };
                if session.answered {
                    return Err(Refusal::AlreadyAnswered(m.bind.session_id));
                }
                session.answered = true;
                Ok(vec![Action::Answer {
                    session_id: m.bind.session_id,
                    sdp,
                }])
            }
            Message::Negotiation(Negotiation::IceNegotiation(n)) => {
                self.session(&n.bind)?;
                // An empty candidate is the end of the candidates: nothing to do.
                Ok(match n.ice.candidate.filter(|c| !c.trim().is_empty()) {
                    Some(candidate) => vec![Action::Candidate {
                        session_id: n.bind.session_id,
                        candidate,
                    }],
                    None => Vec::new(),
                })
            }
            Message::Answer(a) => Err(Refusal::NotFromConsumer(match a {
                Answer::PeerId(_) => "a peerId answer",
                Answer::AvailableStreams(_) => "an availableStreams answer",
                Answer::StartSession(_) => "a startSession answer",
            })),
            Message::Error(_) => Err(Refusal::NotFromConsumer("an error")),
        }
    }

    /// The session `bind` names, if this connection started it with the
    /// same consumer and producer.
    fn session(&mut self, bind: &Bind) -> Result<&mut Session, Refusal> {
        check_id(&bind.session_id)?;
        let s = self
            .sessions
            .get_mut(&bind.session_id)
            .ok_or_else(|| Refusal::NoSession(bind.session_id.clone()))?;
        if s.bind != *bind {
            return Err(Refusal::WrongParties(bind.session_id.clone()));
        }
        Ok(s)
    }

    /// What the hub says about a session of this connection.
    pub fn on_peer(&mut self, ev: PeerEvent) -> Vec<Action> {
        match ev {
            PeerEvent::Offer { session_id, sdp } => {
                let Some(s) = self.sessions.get(&session_id) else {
                    return Vec::new();
                };
                vec![send(Message::Negotiation(Negotiation::MediaNegotiation(
                    MediaNegotiation {
                        bind: s.bind.clone(),
                        sdp: SessionDescription::Offer { sdp },
                    },
                )))]
            }
            PeerEvent::Candidate {
                session_id,
                candidate,
                mid,
            } => {
                let Some(s) = self.sessions.get(&session_id) else {
                    return Vec::new();
                };
                vec![send(Message::Negotiation(Negotiation::IceNegotiation(
                    IceNegotiation {
                        bind: s.bind.clone(),
                        ice: IceCandidate {
                            candidate: Some(candidate),
                            sdp_mid: Some(mid),
                            sdp_m_line_index: Some(0),
                            username_fragment: None,
                        },
                    },
                )))]
            }
            PeerEvent::Ended { session_id, reason } => {
                let Some(s) = self.sessions.remove(&session_id) else {
                    return Vec::new();
                };
                vec![send(Message::Question(Question::EndSession(EndSession {
                    bind: s.bind,
                    reason,
                })))]
            }
        }
    }
}

fn send(m: Message) -> Action {
    Action::Send(m.to_json())
}

fn check_id(id: &str) -> Result<(), Refusal> {
    if id.len() > MAX_ID_BYTES {
        return Err(Refusal::LongId);
    }
    Ok(())
}
