//! Fuzzes the WebRTC signalling (mavlink-camera-manager's protocol, as
//! Cockpit and the HMI page speak it): the input is a connection's texts,
//! one per line, into one connection's state machine, with the hub's
//! offers, candidates and ends for its sessions in between.
//!
//! Never a panic; a message that parses, written back, parses to itself;
//! every text sent is a signalling message; a refusal is counted and
//! answered with one error; a connection holds at most its share of
//! sessions, starts them only for the camera's stream, and answers,
//! candidates and ends reach only sessions it started and has not ended.
#![no_main]

use std::collections::BTreeSet;

use libfuzzer_sys::fuzz_target;
use neptunus::camera::webrtc::protocol::{Message, Stream};
use neptunus::camera::webrtc::signalling::{
    Action, MAX_SESSIONS_PER_CONNECTION, PeerEvent, Signalling,
};

fn machine() -> Signalling {
    let stream = Stream {
        id: "cam".into(),
        name: "Neptunus camera".into(),
        encode: Some("H264".into()),
        height: Some(480),
        width: Some(640),
        interval: Some("1/30".into()),
        source: Some("synthetic".into()),
        created: None,
    };
    let mut n = 0;
    Signalling::new(
        Some(stream),
        Box::new(move || {
            n += 1;
            format!("id{n}")
        }),
    )
}

fn check_sent(actions: &[Action]) {
    for a in actions {
        if let Action::Send(t) = a {
            let m = Message::parse(t).unwrap_or_else(|e| panic!("sent {t:?}: {e}"));
            assert_eq!(m.to_json(), *t);
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let mut m = machine();
    let mut open: BTreeSet<String> = BTreeSet::new();
    for (i, line) in text.split('\n').enumerate() {
        if let Ok(msg) = Message::parse(line) {
            assert_eq!(Message::parse(&msg.to_json()), Ok(msg));
        }
        let refused = m.refused();
        let (actions, refusal) = m.on_text(line);
        check_sent(&actions);
        if refusal.is_some() {
            assert_eq!(m.refused(), refused + 1);
            assert!(
                matches!(&actions[..], [Action::Send(t)] if t.starts_with(r#"{"type":"error""#))
            );
        } else {
            assert_eq!(m.refused(), refused);
        }
        for a in &actions {
            match a {
                Action::Start(bind) => {
                    assert_eq!(bind.producer_id, "cam");
                    assert!(open.insert(bind.session_id.clone()), "a session id twice");
                }
                Action::Answer { session_id, .. } | Action::Candidate { session_id, .. } => {
                    assert!(
                        open.contains(session_id),
                        "to a session not open: {session_id}"
                    );
                }
                Action::End { session_id } => {
                    assert!(
                        open.remove(session_id),
                        "ends a session not open: {session_id}"
                    );
                }
                Action::Send(_) => {}
            }
        }
        assert!(open.len() <= MAX_SESSIONS_PER_CONNECTION);
        assert_eq!(m.session_ids().into_iter().collect::<BTreeSet<_>>(), open);

        // The hub speaks for one open session now and then.
        if let Some(session_id) = open.iter().nth(i % 3).cloned() {
            let ev = match line.len() % 4 {
                0 => PeerEvent::Offer {
                    session_id,
                    sdp: line.to_owned(),
                },
                1 => PeerEvent::Candidate {
                    session_id,
                    candidate: line.to_owned(),
                    mid: "0".into(),
                },
                2 => {
                    open.remove(&session_id);
                    PeerEvent::Ended {
                        session_id,
                        reason: line.to_owned(),
                    }
                }
                _ => continue,
            };
            let actions = m.on_peer(ev);
            assert_eq!(actions.len(), 1);
            check_sent(&actions);
        }
        // And for one that is not (ours are all `idN`).
        let stranger = PeerEvent::Ended {
            session_id: format!("x{line}"),
            reason: String::new(),
        };
        assert!(m.on_peer(stranger).is_empty());
    }
});
