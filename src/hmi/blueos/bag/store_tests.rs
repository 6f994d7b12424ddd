//! The settings bag's store, tested: paths, quotas, who may write what,
//! undo, and the file's round trip.

use super::*;
use serde_json::json;

fn p(s: &str) -> BagPath {
    BagPath::parse(s).unwrap()
}

fn w(a: &str) -> Writer {
    Writer::Watcher(a.into())
}

/// The value read at `path`, parsed.
fn val(bag: &Bag, path: &str) -> Option<Value> {
    bag.get(&p(path))
        .map(|t| serde_json::from_str(&t).expect("the bag answers JSON"))
}

#[test]
fn values_read_back_as_written_keys_in_their_order() {
    let mut bag = Bag::new(Limits::default());
    let action = r#"{"protocol":"cockpit-action","id":"no_function","name":"No function"}"#;
    let mapping = format!(
        r#"{{"value":{{"shift":{{"3":{{"action":{action}}}}}}},"epochLastChangedLocally":5}}"#
    );
    let at = "cockpit/settings-v2/pilot/cockpit-joystick-functions-mapping-v1";
    bag.set(&p(at), mapping.as_bytes(), &w("10.0.0.2")).unwrap();
    assert_eq!(bag.get(&p(at)).unwrap(), mapping);
    assert_eq!(
        bag.get(&p(&format!("{at}/value/shift/3/action"))).unwrap(),
        action
    );
    assert_eq!(
        bag.get(&p("cockpit/settings-v2")).unwrap(),
        format!(r#"{{"pilot":{{"cockpit-joystick-functions-mapping-v1":{mapping}}}}}"#)
    );
    bag.set(
        &p(&format!("{at}/epochLastChangedLocally")),
        b"6",
        &w("10.0.0.2"),
    )
    .unwrap();
    assert_eq!(
        bag.get(&p(at)).unwrap(),
        mapping.replace(":5}", ":6}"),
        "written into: every other key keeps its place"
    );
    let (again, _) = Bag::from_file(&bag.to_file(), Limits::default()).unwrap();
    assert_eq!(again.get(&p(at)), bag.get(&p(at)));
}

#[test]
fn reads_see_one_document() {
    let mut bag = Bag::new(Limits::default());
    assert_eq!(val(&bag, "cockpit"), None);
    bag.set(
        &p("cockpit/cockpit-vehicle-id"),
        br#""abc""#,
        &w("10.0.0.2"),
    )
    .unwrap();
    bag.set(
        &p("cockpit/settings-v2/pilot/cockpit-views"),
        br#"{"epochLastChangedLocally":1,"value":[1,2]}"#,
        &w("10.0.0.2"),
    )
    .unwrap();
    assert_eq!(val(&bag, "cockpit/cockpit-vehicle-id"), Some(json!("abc")));
    assert_eq!(
        val(&bag, "cockpit/settings-v2"),
        Some(json!({"pilot": {"cockpit-views": {"epochLastChangedLocally": 1, "value": [1, 2]}}}))
    );
    assert_eq!(
        val(&bag, "cockpit/settings-v2/pilot/cockpit-views/value"),
        Some(json!([1, 2]))
    );
    assert_eq!(val(&bag, "cockpit/settings-v2/nobody"), None);
    // A set over records replaces them; a set under one changes it.
    bag.set(&p("a"), br#"{"x":1}"#, &Writer::Pilot).unwrap();
    bag.set(&p("a/y/z"), b"2", &Writer::Pilot).unwrap();
    assert_eq!(val(&bag, "a"), Some(json!({"x": 1, "y": {"z": 2}})));
    bag.set(&p("a/x/deeper"), b"3", &Writer::Pilot).unwrap();
    assert_eq!(val(&bag, "a/x"), Some(json!({"deeper": 3})));
    bag.set(&p("cockpit/settings-v2"), b"{}", &Writer::Pilot)
        .unwrap();
    assert_eq!(val(&bag, "cockpit/settings-v2"), Some(json!({})));
    assert_eq!(val(&bag, "cockpit/cockpit-vehicle-id"), Some(json!("abc")));
}

#[test]
fn bad_and_oversized_values_change_nothing() {
    let limits = Limits {
        value_bytes: 100,
        ..Limits::default()
    };
    let mut bag = Bag::new(limits);
    bag.set(&p("k"), b"1", &Writer::Pilot).unwrap();
    let before = bag.clone();
    assert!(matches!(
        bag.set(&p("k"), b"{not json", &Writer::Pilot),
        Err(BagError::NotJson(_))
    ));
    assert!(matches!(
        bag.set(&p("k"), &[b'1'; 101], &Writer::Pilot),
        Err(BagError::ValueTooLarge {
            bytes: 101,
            max: 100
        })
    ));
    let deep = format!("{}{}", "[".repeat(65), "]".repeat(65));
    let mut roomy = Bag::new(Limits::default());
    assert_eq!(
        roomy.set(&p("k"), deep.as_bytes(), &Writer::Pilot),
        Err(BagError::TooDeep)
    );
    assert_eq!(bag, before);
    assert_eq!(
        bag.set(&p("k"), b" 1 ", &Writer::Pilot),
        Ok(Written::Unchanged)
    );
}

#[test]
fn watchers_keep_their_own_and_change_nothing_of_others() {
    let mut bag = Bag::new(Limits::default());
    // Anyone may set the vehicle id once; then it is the vehicle's.
    bag.set(&p("cockpit/cockpit-vehicle-id"), br#""one""#, &w("a"))
        .unwrap();
    assert!(matches!(
        bag.set(&p("cockpit/cockpit-vehicle-id"), br#""two""#, &w("a")),
        Err(BagError::NotYours(_))
    ));
    bag.set(&p("cockpit/settings-v2/pilot/k"), b"1", &Writer::Pilot)
        .unwrap();
    bag.set(&p("cockpit/settings-v2/guest/k"), b"1", &w("a"))
        .unwrap();
    bag.set(&p("cockpit/settings-v2/guest/k"), b"2", &w("a"))
        .unwrap();
    for (path, body) in [
        ("cockpit/settings-v2/pilot/k", "9"),
        ("cockpit/settings-v2/pilot", "{}"),
        ("cockpit/settings-v2", "{}"),
        ("cockpit", "{}"),
        ("cockpit/cockpit-vehicle-id/x", "1"),
    ] {
        assert!(
            matches!(
                bag.set(&p(path), body.as_bytes(), &w("a")),
                Err(BagError::NotYours(_))
            ),
            "{path}"
        );
    }
    assert!(matches!(
        bag.set(&p("cockpit/settings-v2/guest/k"), b"3", &w("b")),
        Err(BagError::NotYours(_))
    ));
    // Its own record may be written into and replaced whole.
    bag.set(&p("cockpit/settings-v2/guest/k/inner"), b"4", &w("a"))
        .unwrap();
    bag.set(&p("cockpit/settings-v2/guest"), br#"{"k":5}"#, &w("a"))
        .unwrap();
    assert_eq!(val(&bag, "cockpit/settings-v2/guest/k"), Some(json!(5)));
    // The pilot may change anything; what it writes into is the pilots'.
    bag.set(&p("cockpit/settings-v2/guest/k"), b"6", &Writer::Pilot)
        .unwrap();
    assert!(matches!(
        bag.set(&p("cockpit/settings-v2/guest"), b"{}", &w("a")),
        Err(BagError::NotYours(_))
    ));
    bag.set(
        &p("cockpit/cockpit-vehicle-id"),
        br#""two""#,
        &Writer::Pilot,
    )
    .unwrap();
    assert_eq!(val(&bag, "cockpit/cockpit-vehicle-id"), Some(json!("two")));
}

#[test]
fn quotas_per_address_for_watchers_and_in_total() {
    let limits = Limits {
        value_bytes: 1000,
        total_bytes: 3500,
        address_bytes: 1500,
        watchers_bytes: 2500,
    };
    let mut bag = Bag::new(limits);
    let value = |n: usize| format!("\"{}\"", "x".repeat(n));
    bag.set(&p("a/1"), value(900).as_bytes(), &w("a")).unwrap();
    assert!(matches!(
        bag.set(&p("a/2"), value(900).as_bytes(), &w("a")),
        Err(BagError::AddressQuota { max: 1500, .. })
    ));
    // Replacing its own value frees what it held.
    bag.set(&p("a/1"), value(950).as_bytes(), &w("a")).unwrap();
    bag.set(&p("b/1"), value(900).as_bytes(), &w("b")).unwrap();
    assert!(matches!(
        bag.set(&p("c/1"), value(900).as_bytes(), &w("c")),
        Err(BagError::WatchersFull { max: 2500, .. })
    ));
    // The pilot still has room, up to the total.
    bag.set(&p("p/1"), value(900).as_bytes(), &Writer::Pilot)
        .unwrap();
    assert!(matches!(
        bag.set(&p("p/2"), value(900).as_bytes(), &Writer::Pilot),
        Err(BagError::Full { max: 3500, .. })
    ));
    assert!(bag.total_bytes() <= 3500);
    // Shrinking is always allowed.
    bag.set(&p("p/1"), b"1", &Writer::Pilot).unwrap();
}

#[test]
fn undo_puts_back_and_the_file_reads_back() {
    let mut bag = Bag::new(Limits::default());
    bag.set(&p("s/a"), b"1", &w("x")).unwrap();
    bag.set(&p("s/b"), b"2", &Writer::Pilot).unwrap();
    let before = bag.clone();
    let Written::Changed(undo) = bag.set(&p("s"), b"{}", &Writer::Pilot).unwrap() else {
        panic!("changed")
    };
    bag.undo(undo);
    assert_eq!(bag, before);
    let Written::Changed(undo) = bag.set(&p("s/a/z"), b"3", &w("x")).unwrap() else {
        panic!("changed")
    };
    bag.undo(undo);
    assert_eq!(bag, before);
    let (again, warnings) = Bag::from_file(&bag.to_file(), Limits::default()).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(again, bag);
    // Written back with the owner: the watcher still owns its record.
    let mut again = again;
    again.set(&p("s/a"), b"4", &w("x")).unwrap();
    assert!(Bag::from_file(b"{", Limits::default()).is_err());
    let odd = br#"{"version":1,"records":[{"path":["a"],"value":1},{"path":["a","b"],"value":2},{"path":[".."],"value":3}]}"#;
    let (bag, warnings) = Bag::from_file(odd, Limits::default()).unwrap();
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert_eq!(val(&bag, "a"), Some(json!(1)));
}
