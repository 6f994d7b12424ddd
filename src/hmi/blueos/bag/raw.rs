//! JSON kept as the text its writer sent, with its keys in their order:
//! Cockpit compares settings it reads back with `JSON.stringify`, so a
//! value whose keys came back sorted differs from the one it wrote (and it
//! says so with a dialog, twice a second). Reading inside a value and
//! writing into one go through the text, object by object, never through a
//! map that sorts.

use std::fmt;

use serde::de::{Deserialize, Deserializer, MapAccess, Visitor};
use serde_json::value::RawValue;

/// An object's entries in their order (a repeated key keeps its first
/// place and its last value, as a browser's `JSON.parse` does).
struct Entries(Vec<(String, Box<RawValue>)>);

impl<'de> Deserialize<'de> for Entries {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Entries;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a JSON object")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Entries, A::Error> {
                let mut out: Vec<(String, Box<RawValue>)> = Vec::new();
                while let Some((k, v)) = m.next_entry::<String, Box<RawValue>>()? {
                    match out.iter_mut().find(|(key, _)| *key == k) {
                        Some(slot) => slot.1 = v,
                        None => out.push((k, v)),
                    }
                }
                Ok(Entries(out))
            }
        }
        d.deserialize_map(V)
    }
}

fn entries(raw: &str) -> Option<Vec<(String, Box<RawValue>)>> {
    serde_json::from_str::<Entries>(raw).ok().map(|e| e.0)
}

/// The text of one JSON value as sent (without the whitespace around it);
/// `None` when it is not one JSON value.
pub(super) fn text_of(body: &[u8]) -> Option<String> {
    serde_json::from_slice::<Box<RawValue>>(body)
        .ok()
        .map(|r| r.get().to_owned())
}

/// The value at `rest` inside `raw` (objects only, as a bag path goes).
pub(super) fn at(raw: &str, rest: &[String]) -> Option<String> {
    let Some((first, more)) = rest.split_first() else {
        return Some(raw.to_owned());
    };
    let (_, inner) = entries(raw)?.into_iter().find(|(k, _)| k == first)?;
    at(inner.get(), more)
}

/// `raw` with `value` put at `rest`, making objects on the way (a value
/// that is not an object is replaced by one, as a set of a path does);
/// every other key keeps its place.
pub(super) fn put(raw: Option<&str>, rest: &[String], value: &str) -> String {
    let Some((first, more)) = rest.split_first() else {
        return value.to_owned();
    };
    let mut out: Vec<(String, String)> = raw
        .and_then(entries)
        .unwrap_or_default()
        .into_iter()
        .map(|(k, v)| (k, v.get().to_owned()))
        .collect();
    match out.iter_mut().find(|(k, _)| k == first) {
        Some(slot) => slot.1 = put(Some(&slot.1), more, value),
        None => out.push((first.clone(), put(None, more, value))),
    }
    object(out.iter().map(|(k, v)| (k.as_str(), v.as_str())))
}

/// An object's text from its entries' keys and texts, in that order.
pub(super) fn object<'a>(entries: impl Iterator<Item = (&'a str, &'a str)>) -> String {
    let mut s = String::from("{");
    for (i, (k, v)) in entries.enumerate() {
        if i > 0 {
            s.push(',');
        }
        s.push_str(&serde_json::to_string(k).unwrap_or_default());
        s.push(':');
        s.push_str(v);
    }
    s.push('}');
    s
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn path(p: &[&str]) -> Vec<String> {
        p.iter().map(|s| (*s).to_owned()).collect()
    }

    #[test]
    fn keys_keep_their_order() {
        let cockpit = r#"{"protocol":"cockpit-action","id":"no_function","name":"No function"}"#;
        assert_eq!(
            text_of(format!(" {cockpit}\n").as_bytes()).unwrap(),
            cockpit
        );
        let doc = format!(r#"{{"z":1,"regular":{{"3":{cockpit}}},"a":[1,{{"y":2,"b":3}}]}}"#);
        assert_eq!(at(&doc, &path(&["regular", "3"])).unwrap(), cockpit);
        assert_eq!(at(&doc, &path(&["a"])).unwrap(), r#"[1,{"y":2,"b":3}]"#);
        assert_eq!(at(&doc, &path(&["nope"])), None);
        assert_eq!(at(&doc, &path(&["z", "deeper"])), None);
        let changed = put(Some(&doc), &path(&["regular", "3", "name"]), r#""x""#);
        assert_eq!(
            changed,
            r#"{"z":1,"regular":{"3":{"protocol":"cockpit-action","id":"no_function","name":"x"}},"a":[1,{"y":2,"b":3}]}"#
        );
        assert_eq!(put(Some("1"), &path(&["k", "j"]), "2"), r#"{"k":{"j":2}}"#);
        assert_eq!(put(None, &path(&[]), "[]"), "[]");
        assert_eq!(at(r#"{"a":1,"a":2}"#, &path(&["a"])).unwrap(), "2");
        assert_eq!(text_of(b"{not json"), None);
        assert_eq!(text_of(b"1 2"), None);
    }
}
