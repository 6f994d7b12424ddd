//! The signalling messages of mavlink-camera-manager, as Cockpit speaks
//! them: JSON `{"type": "question"|"answer"|"negotiation", "content": …}`,
//! each content again `{"type": …, "content": …}` with camelCase type names
//! and snake_case fields (`consumer_id`, `producer_id`, `session_id`); the
//! SDP and the ICE candidate in the browser's own JSON (`{"type":
//! "offer", "sdp": …}`, `{"candidate", "sdpMid", "sdpMLineIndex",
//! "usernameFragment"}`).
//!
//! One addition of ours: `{"type": "error", "content": "…"}` answers a
//! message that could not be used, with the reason. Cockpit ignores types
//! it does not know, so it costs it nothing; a person or a script reading
//! the socket learns what went wrong.
//!
//! Types and parsing only; what a message does is `signalling`'s.

use serde::{Deserialize, Serialize};

/// One message on the signalling WebSocket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", content = "content", rename_all = "camelCase")]
pub enum Message {
    Question(Question),
    Answer(Answer),
    Negotiation(Negotiation),
    /// Ours: why a message was not used.
    Error(String),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", content = "content", rename_all = "camelCase")]
pub enum Question {
    /// "Who am I?": the consumer id of this connection.
    PeerId,
    AvailableStreams,
    StartSession(BindOffer),
    EndSession(EndSession),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", content = "content", rename_all = "camelCase")]
pub enum Answer {
    PeerId(PeerIdAnswer),
    AvailableStreams(Vec<Stream>),
    StartSession(Bind),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", content = "content", rename_all = "camelCase")]
pub enum Negotiation {
    MediaNegotiation(MediaNegotiation),
    IceNegotiation(IceNegotiation),
}

/// A consumer asks for a session with a producer (a stream).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BindOffer {
    pub consumer_id: String,
    pub producer_id: String,
}

/// A session: who watches, what, and its id.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Bind {
    pub consumer_id: String,
    pub producer_id: String,
    pub session_id: String,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct EndSession {
    #[serde(flatten)]
    pub bind: Bind,
    pub reason: String,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PeerIdAnswer {
    pub id: String,
}

/// A stream a consumer may ask for (mavlink-camera-manager's `Stream`;
/// the unknowns are `null`, as it sends them).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stream {
    pub id: String,
    pub name: String,
    pub encode: Option<String>,
    pub height: Option<u32>,
    pub width: Option<u32>,
    /// The frame interval, `1/FPS`.
    pub interval: Option<String>,
    pub source: Option<String>,
    pub created: Option<String>,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MediaNegotiation {
    #[serde(flatten)]
    pub bind: Bind,
    pub sdp: SessionDescription,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct IceNegotiation {
    #[serde(flatten)]
    pub bind: Bind,
    pub ice: IceCandidate,
}

/// `RTCSessionDescription.toJSON()`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "camelCase")]
pub enum SessionDescription {
    Offer { sdp: String },
    Answer { sdp: String },
}

/// `RTCIceCandidate.toJSON()`: an empty or missing `candidate` is the end
/// of the candidates.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct IceCandidate {
    #[serde(default)]
    pub candidate: Option<String>,
    #[serde(default)]
    pub sdp_mid: Option<String>,
    #[serde(default)]
    pub sdp_m_line_index: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub username_fragment: Option<String>,
}

/// A text that is not a signalling message, with serde's reason (it names
/// the field, or the line and column).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("not a signalling message: {0}")]
pub struct ProtocolError(pub String);

impl Message {
    pub fn parse(text: &str) -> Result<Message, ProtocolError> {
        serde_json::from_str(text).map_err(|e| ProtocolError(e.to_string()))
    }

    /// The message as sent on the socket.
    pub fn to_json(&self) -> String {
        // Plain strings, numbers and options: serialising cannot fail.
        serde_json::to_string(self).unwrap_or_else(|e| {
            serde_json::json!({ "type": "error", "content": e.to_string() }).to_string()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bind() -> Bind {
        Bind {
            consumer_id: "c".into(),
            producer_id: "p".into(),
            session_id: "s".into(),
        }
    }

    #[test]
    fn cockpits_questions_parse() {
        // As Cockpit's signaller.ts sends them.
        assert_eq!(
            Message::parse(r#"{"type":"question","content":{"type":"peerId"}}"#),
            Ok(Message::Question(Question::PeerId))
        );
        assert_eq!(
            Message::parse(r#"{"type":"question","content":{"type":"availableStreams"}}"#),
            Ok(Message::Question(Question::AvailableStreams))
        );
        let start = r#"{"type":"question","content":{"type":"startSession","content":{"consumer_id":"c","producer_id":"p"}}}"#;
        assert_eq!(
            Message::parse(start),
            Ok(Message::Question(Question::StartSession(BindOffer {
                consumer_id: "c".into(),
                producer_id: "p".into()
            })))
        );
        let ice = r#"{"type":"negotiation","content":{"type":"iceNegotiation","content":{"session_id":"s","consumer_id":"c","producer_id":"p","ice":{"candidate":"candidate:1 1 udp 1 1.2.3.4 5 typ host","sdpMid":"0","sdpMLineIndex":0,"usernameFragment":"u"}}}}"#;
        let Ok(Message::Negotiation(Negotiation::IceNegotiation(n))) = Message::parse(ice) else {
            panic!("ice negotiation");
        };
        assert_eq!(n.bind, bind());
        assert_eq!(n.ice.sdp_m_line_index, Some(0));
        assert_eq!(n.ice.username_fragment.as_deref(), Some("u"));
        let sdp = r#"{"type":"negotiation","content":{"type":"mediaNegotiation","content":{"session_id":"s","consumer_id":"c","producer_id":"p","sdp":{"type":"answer","sdp":"v=0"}}}}"#;
        let Ok(Message::Negotiation(Negotiation::MediaNegotiation(m))) = Message::parse(sdp) else {
            panic!("media negotiation");
        };
        assert_eq!(m.sdp, SessionDescription::Answer { sdp: "v=0".into() });
    }

    #[test]
    fn answers_have_cockpits_field_names() {
        let peer = Message::Answer(Answer::PeerId(PeerIdAnswer { id: "c".into() }));
        assert_eq!(
            peer.to_json(),
            r#"{"type":"answer","content":{"type":"peerId","content":{"id":"c"}}}"#
        );
        let streams = Message::Answer(Answer::AvailableStreams(vec![Stream {
            id: "p".into(),
            name: "cam".into(),
            encode: Some("H264".into()),
            height: Some(480),
            width: Some(640),
            interval: Some("1/30".into()),
            source: None,
            created: None,
        }]));
        assert_eq!(
            streams.to_json(),
            r#"{"type":"answer","content":{"type":"availableStreams","content":[{"id":"p","name":"cam","encode":"H264","height":480,"width":640,"interval":"1/30","source":null,"created":null}]}}"#
        );
        let offer = Message::Negotiation(Negotiation::MediaNegotiation(MediaNegotiation {
            bind: bind(),
            sdp: SessionDescription::Offer { sdp: "v=0".into() },
        }));
        assert_eq!(
            offer.to_json(),
            r#"{"type":"negotiation","content":{"type":"mediaNegotiation","content":{"consumer_id":"c","producer_id":"p","session_id":"s","sdp":{"type":"offer","sdp":"v=0"}}}}"#
        );
        let end = Message::Question(Question::EndSession(EndSession {
            bind: bind(),
            reason: "r".into(),
        }));
        assert_eq!(
            end.to_json(),
            r#"{"type":"question","content":{"type":"endSession","content":{"consumer_id":"c","producer_id":"p","session_id":"s","reason":"r"}}}"#
        );
        assert_eq!(
            Message::Error("why".into()).to_json(),
            r#"{"type":"error","content":"why"}"#
        );
    }

    #[test]
    fn bad_texts_are_errors_with_the_reason() {
        for bad in [
            "",
            "null",
            "[]",
            r#"{"type":"question"}"#,
            r#"{"type":"question","content":{"type":"shutdown"}}"#,
            r#"{"type":"question","content":{"type":"startSession","content":{"consumer_id":1}}}"#,
            r#"{"type":"negotiation","content":{"type":"mediaNegotiation","content":{"session_id":"s","consumer_id":"c","producer_id":"p","sdp":{"type":"rollback"}}}}"#,
            "{\"type\":\"question\",\"content\":{\"type\":\"peerId\"}",
        ] {
            let e = Message::parse(bad).expect_err(bad);
            assert!(
                e.to_string().starts_with("not a signalling message: "),
                "{e}"
            );
        }
    }
}
