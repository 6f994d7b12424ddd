//! The WebRTC signalling state machine (mavlink-camera-manager's protocol,
//! as Cockpit speaks it), driven with the texts a client sends: what each
//! question is answered, what reaches the hub, and that bad input is
//! answered with its reason, counted, and changes nothing.

use neptunus::camera::webrtc::protocol::Stream;
use neptunus::camera::webrtc::signalling::{
    Action, MAX_SESSIONS_PER_CONNECTION, PeerEvent, Signalling,
};
use proptest::prelude::*;
use serde_json::{Value, json};

fn stream() -> Stream {
    Stream {
        id: "cam".into(),
        name: "Neptunus camera".into(),
        encode: Some("H264".into()),
        height: Some(480),
        width: Some(640),
        interval: Some("1/30".into()),
        source: Some("synthetic".into()),
        created: None,
    }
}

/// Ids c0 (the consumer), then s1, s2 … (sessions).
fn machine() -> Signalling {
    let mut n = 0;
    Signalling::new(
        Some(stream()),
        Box::new(move || {
            let id = if n == 0 {
                "c0".to_owned()
            } else {
                format!("s{n}")
            };
            n += 1;
            id
        }),
    )
}

fn sent(actions: &[Action]) -> Vec<Value> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Send(t) => Some(serde_json::from_str(t).expect("we send JSON")),
            _ => None,
        })
        .collect()
}

fn question(q: Value) -> String {
    json!({"type": "question", "content": q}).to_string()
}

fn negotiation(kind: &str, content: Value) -> String {
    json!({"type": "negotiation", "content": {"type": kind, "content": content}}).to_string()
}

fn start(m: &mut Signalling, consumer: &str) -> Vec<Action> {
    let text = question(
        json!({"type": "startSession", "content": {"consumer_id": consumer, "producer_id": "cam"}}),
    );
    let (a, refusal) = m.on_text(&text);
    assert_eq!(refusal, None);
    a
}

fn bind(session: &str) -> Value {
    json!({"consumer_id": "c0", "producer_id": "cam", "session_id": session})
}

fn with(mut v: Value, key: &str, value: Value) -> Value {
    v[key] = value;
    v
}

/// The refusal text of one message.
fn refused(m: &mut Signalling, text: &str) -> String {
    let before = m.refused();
    let (a, refusal) = m.on_text(text);
    assert!(refusal.is_some(), "{text} was not refused: {a:?}");
    assert_eq!(m.refused(), before + 1);
    let out = sent(&a);
    assert_eq!(out.len(), 1, "{a:?}");
    assert_eq!(out[0]["type"], "error", "{out:?}");
    out[0]["content"].as_str().expect("a reason").to_owned()
}

#[test]
fn questions_are_answered_as_mavlink_camera_manager_answers_them() {
    let mut m = machine();
    let (a, _) = m.on_text(&question(json!({"type": "peerId"})));
    assert_eq!(
        sent(&a),
        [json!({"type": "answer", "content": {"type": "peerId", "content": {"id": "c0"}}})]
    );
    // The id stays this connection's.
    let (a, _) = m.on_text(&question(json!({"type": "peerId"})));
    assert_eq!(sent(&a)[0]["content"]["content"]["id"], "c0");
    let (a, _) = m.on_text(&question(json!({"type": "availableStreams"})));
    assert_eq!(
        sent(&a),
        [
            json!({"type": "answer", "content": {"type": "availableStreams", "content": [{
            "id": "cam", "name": "Neptunus camera", "encode": "H264", "height": 480,
            "width": 640, "interval": "1/30", "source": "synthetic", "created": null}]}})
        ]
    );
    let mut none = Signalling::new(None, Box::new(|| "x".to_owned()));
    let (a, _) = none.on_text(&question(json!({"type": "availableStreams"})));
    assert_eq!(sent(&a)[0]["content"]["content"], json!([]));
}

#[test]
fn a_session_is_answered_before_the_hub_is_asked_for_the_offer() {
    let mut m = machine();
    let a = start(&mut m, "c0");
    assert_eq!(a.len(), 2, "{a:?}");
    assert_eq!(
        sent(&a[..1]),
        [json!({"type": "answer", "content": {"type": "startSession", "content": bind("s1")}})]
    );
    let Action::Start(b) = &a[1] else {
        panic!("{a:?}")
    };
    assert_eq!(b.session_id, "s1");
    // The hub's offer and candidates go out with the session's parties.
    let out = m.on_peer(PeerEvent::Offer {
        session_id: "s1".into(),
        sdp: "v=0".into(),
    });
    assert_eq!(
        sent(&out),
        [
            json!({"type": "negotiation", "content": {"type": "mediaNegotiation", "content":
            with(bind("s1"), "sdp", json!({"type": "offer", "sdp": "v=0"}))}})
        ]
    );
    let out = m.on_peer(PeerEvent::Candidate {
        session_id: "s1".into(),
        candidate: "candidate:1 1 udp 1 10.0.0.1 5000 typ host".into(),
        mid: "abc".into(),
    });
    assert_eq!(
        sent(&out)[0]["content"]["content"]["ice"],
        json!({"candidate": "candidate:1 1 udp 1 10.0.0.1 5000 typ host", "sdpMid": "abc", "sdpMLineIndex": 0})
    );
    // The consumer's answer and candidates reach the hub.
    let (a, _) = m.on_text(&negotiation(
        "mediaNegotiation",
        with(
            bind("s1"),
            "sdp",
            json!({"type": "answer", "sdp": "v=0 answer"}),
        ),
    ));
    assert_eq!(
        a,
        [Action::Answer {
            session_id: "s1".into(),
            sdp: "v=0 answer".into()
        }]
    );
    let ice = |c: Value| negotiation("iceNegotiation", with(bind("s1"), "ice", c));
    let (a, _) = m.on_text(&ice(json!({"candidate": "candidate:2 1 udp 2 10.0.0.2 6000 typ host", "sdpMid": "abc", "sdpMLineIndex": 0})));
    assert_eq!(
        a,
        [Action::Candidate {
            session_id: "s1".into(),
            candidate: "candidate:2 1 udp 2 10.0.0.2 6000 typ host".into()
        }]
    );
    // The end of the candidates (an empty one) changes nothing.
    let (a, r) = m.on_text(&ice(json!({"candidate": "", "sdpMid": null})));
    assert!(a.is_empty() && r.is_none());
    // The vehicle ends the session: the consumer hears why.
    let out = m.on_peer(PeerEvent::Ended {
        session_id: "s1".into(),
        reason: "gone".into(),
    });
    assert_eq!(
        sent(&out),
        [
            json!({"type": "question", "content": {"type": "endSession", "content":
            with(bind("s1"), "reason", json!("gone"))}})
        ]
    );
    assert!(m.session_ids().is_empty());
    // Late news of an ended session is dropped.
    assert!(
        m.on_peer(PeerEvent::Offer {
            session_id: "s1".into(),
            sdp: "v=0".into()
        })
        .is_empty()
    );
}

#[test]
fn the_consumer_ends_its_session() {
    let mut m = machine();
    start(&mut m, "c0");
    let end = question(
        json!({"type": "endSession", "content": with(bind("s1"), "reason", json!("bye"))}),
    );
    let (a, _) = m.on_text(&end);
    assert_eq!(
        a,
        [Action::End {
            session_id: "s1".into()
        }]
    );
    assert!(m.session_ids().is_empty());
    assert!(refused(&mut m, &end).contains("no session \"s1\""));
}

#[test]
fn an_earlier_connections_consumer_id_still_gets_a_session() {
    // Cockpit keeps its consumer id across a reconnection of the socket.
    let mut m = machine();
    let a = start(&mut m, "old-id");
    assert_eq!(sent(&a)[0]["content"]["content"]["consumer_id"], "old-id");
    let (a, _) = m.on_text(&negotiation(
        "mediaNegotiation",
        json!({"consumer_id": "old-id", "producer_id": "cam", "session_id": "s1",
               "sdp": {"type": "answer", "sdp": "v=0"}}),
    ));
    assert!(matches!(a[..], [Action::Answer { .. }]), "{a:?}");
}

#[test]
fn what_does_not_fit_the_sessions_is_refused_with_the_reason() {
    let mut m = machine();
    let wrong_stream = question(
        json!({"type": "startSession", "content": {"consumer_id": "c0", "producer_id": "other"}}),
    );
    assert!(refused(&mut m, &wrong_stream).contains("no stream with id \"other\""));
    start(&mut m, "c0");
    let answer = |b: Value| {
        negotiation(
            "mediaNegotiation",
            with(b, "sdp", json!({"type": "answer", "sdp": "v=0"})),
        )
    };
    // Another connection's (or a made-up) session.
    assert!(refused(&mut m, &answer(bind("s9"))).contains("no session \"s9\""));
    // The right session with other parties.
    let other = with(bind("s1"), "producer_id", json!("x"));
    assert!(refused(&mut m, &answer(other)).contains("another consumer or producer"));
    // An offer from the consumer: the vehicle offers.
    let offer = negotiation(
        "mediaNegotiation",
        with(bind("s1"), "sdp", json!({"type": "offer", "sdp": "v=0"})),
    );
    assert!(refused(&mut m, &offer).contains("the vehicle makes the offer"));
    // One answer per session.
    let (a, _) = m.on_text(&answer(bind("s1")));
    assert_eq!(a.len(), 1);
    assert!(refused(&mut m, &answer(bind("s1"))).contains("already has its SDP answer"));
    // Answers are the producer's to send.
    let peer_answer =
        json!({"type": "answer", "content": {"type": "peerId", "content": {"id": "x"}}});
    assert!(refused(&mut m, &peer_answer.to_string()).contains("a producer sends"));
    let long = "x".repeat(65);
    assert!(refused(&mut m, &answer(bind(&long))).contains("longer than 64"));
    // Nothing of this touched the session.
    assert_eq!(m.session_ids(), ["s1"]);
}

#[test]
fn a_connection_holds_a_few_sessions_at_most() {
    let mut m = machine();
    for _ in 0..MAX_SESSIONS_PER_CONNECTION {
        start(&mut m, "c0");
    }
    let more = question(
        json!({"type": "startSession", "content": {"consumer_id": "c0", "producer_id": "cam"}}),
    );
    assert!(refused(&mut m, &more).contains("end one first"));
    assert_eq!(m.session_ids().len(), MAX_SESSIONS_PER_CONNECTION);
}

#[test]
fn malformed_texts_are_refused_not_fatal() {
    let mut m = machine();
    for bad in [
        "",
        "{",
        "null",
        "42",
        r#"{"type":"question"}"#,
        r#"{"type":"question","content":{"type":"reboot"}}"#,
        r#"{"type":"negotiation","content":{"type":"iceNegotiation","content":{}}}"#,
        r#"{"type":"question","content":{"type":"startSession","content":{"consumer_id":[],"producer_id":"cam"}}}"#,
    ] {
        assert!(
            refused(&mut m, bad).starts_with("not a signalling message"),
            "{bad}"
        );
    }
    // The connection still works.
    let (a, _) = m.on_text(&question(json!({"type": "peerId"})));
    assert_eq!(sent(&a)[0]["content"]["type"], "peerId");
}

proptest! {
    /// Any text — random, or a real message cut short or with a byte
    /// changed — is answered or refused; the machine never panics, and a
    /// refusal never starts or touches a session.
    #[test]
    fn any_text_is_answered_or_refused(cut in 0usize..200, flip in 0usize..200, byte in any::<u8>(), junk in ".{0,80}") {
        let mut m = machine();
        start(&mut m, "c0");
        let real = negotiation("mediaNegotiation", with(bind("s1"), "sdp", json!({"type": "answer", "sdp": "v=0"})));
        let mut bytes = real.into_bytes();
        bytes.truncate(cut.min(bytes.len()));
        if let Some(b) = bytes.get_mut(flip) {
            *b = byte;
        }
        for text in [String::from_utf8_lossy(&bytes).into_owned(), junk] {
            let (a, refusal) = m.on_text(&text);
            if refusal.is_some() {
                prop_assert_eq!(a.len(), 1);
                prop_assert!(matches!(&a[0], Action::Send(t) if t.contains("\"error\"")));
            }
            prop_assert!(m.session_ids().len() <= 1);
        }
    }
}
