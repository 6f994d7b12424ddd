//! Fuzzes Cockpit's settings bag: any request path and any body, written by
//! a pilot or a watcher, in any order, must never panic; a path that parses
//! holds no segment that could name a folder or hide a separator; a refused
//! or unchanged write changes nothing, an accepted one reads back and is
//! undone exactly; the bag stays within its total, and its file reads back
//! to the same bag. Every read is JSON.
#![no_main]

use libfuzzer_sys::fuzz_target;
use neptunus::hmi::blueos::bag::{Bag, BagPath, Limits, Writer, Written};

/// Small, so quotas and the total are reached.
const LIMITS: Limits = Limits {
    value_bytes: 512,
    total_bytes: 4096,
    address_bytes: 1024,
    watchers_bytes: 2048,
};

fuzz_target!(|data: &[u8]| {
    let mut bag = Bag::new(LIMITS);
    // What Cockpit keeps, to write over and under.
    for (path, body, writer) in [
        ("cockpit/cockpit-vehicle-id", &br#""6f1c""#[..], Writer::Watcher("10.0.0.1".into())),
        ("cockpit/settings-v2/pilot/k", b"{\"value\":1}", Writer::Pilot),
        ("cockpit/settings-v2/guest/k", b"[1,2]", Writer::Watcher("10.0.0.2".into())),
    ] {
        let _ = bag.set(&BagPath::parse(path).expect("a path"), body, &writer);
    }
    // Each operation: a path length, a writer, a body length, the path, the body.
    let mut rest = data;
    while let [path_len, who, body_len, tail @ ..] = rest {
        let path_len = usize::from(*path_len).min(tail.len());
        let (raw, tail) = tail.split_at(path_len);
        let body_len = usize::from(*body_len).min(tail.len());
        let (body, tail) = tail.split_at(body_len);
        rest = tail;
        let raw = String::from_utf8_lossy(raw);
        let Ok(path) = BagPath::parse(&raw) else {
            continue;
        };
        for s in path.segments() {
            assert!(!s.is_empty() && s != "." && s != "..", "{raw:?}");
            assert!(!s.contains(['/', '\\']) && !s.chars().any(char::is_control), "{raw:?}");
        }
        let writer = match who % 4 {
            0 => Writer::Pilot,
            n => Writer::Watcher(format!("10.0.0.{n}")),
        };
        let before = bag.clone();
        match bag.set(&path, body, &writer) {
            Ok(Written::Changed(undo)) => {
                let sent: serde_json::Value = serde_json::from_slice(body).expect("accepted JSON");
                let read = bag.get(&path).expect("what was written reads back");
                let read: serde_json::Value = serde_json::from_str(&read).expect("the bag answers JSON");
                assert_eq!(read, sent);
                let after = bag.clone();
                bag.undo(undo);
                assert_eq!(bag, before);
                bag = after;
            }
            Ok(Written::Unchanged) | Err(_) => assert_eq!(bag, before),
        }
        assert!(bag.total_bytes() <= LIMITS.total_bytes);
    }
    for p in ["cockpit", "cockpit/settings-v2", "cockpit/settings-v2/guest/k"] {
        if let Some(text) = bag.get(&BagPath::parse(p).expect("a path")) {
            serde_json::from_str::<serde_json::Value>(&text).expect("the bag answers JSON");
        }
    }
    let (again, warnings) = Bag::from_file(&bag.to_file(), LIMITS).expect("its own file");
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(again, bag);
});
