//! The REST view of mavlink2rest: the last message per (system, component,
//! name) with its `status.time` (counter, first and last update, frequency).
//!
//! Owns what was heard, keyed as above, and its JSON on demand. Keeps only
//! the newest message of each kind: its size is bounded by the systems,
//! components and message types heard, never by traffic.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::SystemTime;

use serde_json::{Map, Value, json};

/// One message kind of one component.
#[derive(Debug, Clone)]
struct Entry {
    message: Arc<str>,
    counter: u64,
    first: SystemTime,
    last: SystemTime,
}

/// Systems and components heard are capped: a client naming every id in
/// turn must not grow the view without end.
const MAX_COMPONENTS: usize = 64;

#[derive(Debug, Default)]
pub struct Tree {
    vehicles: BTreeMap<u8, BTreeMap<u8, BTreeMap<&'static str, Entry>>>,
    components: usize,
}

impl Tree {
    /// Records `message` (its JSON) from `system`/`component` at `now`.
    pub fn update(
        &mut self,
        system: u8,
        component: u8,
        name: &'static str,
        message: Arc<str>,
        now: SystemTime,
    ) {
        let known = self
            .vehicles
            .get(&system)
            .is_some_and(|c| c.contains_key(&component));
        if !known {
            if self.components >= MAX_COMPONENTS {
                return;
            }
            self.components += 1;
        }
        let messages = self
            .vehicles
            .entry(system)
            .or_default()
            .entry(component)
            .or_default();
        match messages.get_mut(name) {
            Some(e) => {
                e.message = message;
                e.counter = e.counter.wrapping_add(1);
                e.last = now;
            }
            None => {
                messages.insert(
                    name,
                    Entry {
                        message,
                        counter: 1,
                        first: now,
                        last: now,
                    },
                );
            }
        }
    }

    /// How often `name` was heard from `system`/`component`;
    /// `None` if never.
    pub fn counter(&self, system: u8, component: u8, name: &str) -> Option<u64> {
        self.vehicles
            .get(&system)?
            .get(&component)?
            .get(name)
            .map(|e| e.counter)
    }

    /// The whole view as mavlink2rest writes it:
    /// `{"vehicles":{"1":{"id":1,"components":{"1":{"id":1,"messages":{NAME:{"message":…,"status":{"time":…}}}}}}}}`.
    pub fn to_value(&self) -> Value {
        let mut vehicles = Map::new();
        for (sys, comps) in &self.vehicles {
            let mut components = Map::new();
            for (comp, messages) in comps {
                let mut m = Map::new();
                for (name, e) in messages {
                    m.insert((*name).to_owned(), entry_value(e));
                }
                components.insert(
                    comp.to_string(),
                    json!({ "id": comp, "messages": Value::Object(m) }),
                );
            }
            vehicles.insert(
                sys.to_string(),
                json!({ "id": sys, "components": Value::Object(components) }),
            );
        }
        json!({ "vehicles": Value::Object(vehicles) })
    }
}

fn entry_value(e: &Entry) -> Value {
    let message = serde_json::from_str::<Value>(&e.message).unwrap_or(Value::Null);
    let span_s = e
        .last
        .duration_since(e.first)
        .map_or(0.0, |d| d.as_secs_f64());
    // Messages a second over the time heard (0 until a second message).
    let frequency = if span_s > 0.0 {
        (e.counter.saturating_sub(1)) as f64 / span_s
    } else {
        0.0
    };
    json!({
        "message": message,
        "status": { "time": {
            "counter": e.counter,
            "first_update": rfc3339(e.first),
            "last_update": rfc3339(e.last),
            "frequency": frequency,
        }},
    })
}

/// `2026-11-25T05:30:59.123456+00:00` (UTC; mavlink2rest writes local time
/// with its offset, which is the same instant).
pub fn rfc3339(t: SystemTime) -> String {
    let d = t.duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs();
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, day) = civil_from_days(days as i64);
    format!(
        "{y:04}-{m:02}-{day:02}T{:02}:{:02}:{:02}.{:06}+00:00",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60,
        d.subsec_micros()
    )
}

/// Days since 1970-01-01 → (year, month, day) in the proleptic Gregorian
/// calendar (Howard Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn dates_are_rfc3339() {
        let t = SystemTime::UNIX_EPOCH + Duration::from_micros(1_764_048_659_123_456);
        assert_eq!(rfc3339(t), "2025-11-25T05:30:59.123456+00:00");
        assert_eq!(
            rfc3339(SystemTime::UNIX_EPOCH + Duration::from_secs(951_782_400)),
            "2000-02-29T00:00:00.000000+00:00"
        );
    }

    #[test]
    fn keeps_the_last_message_and_counts() {
        let mut tree = Tree::default();
        let t0 = SystemTime::UNIX_EPOCH + Duration::from_secs(100);
        tree.update(
            1,
            1,
            "ATTITUDE",
            Arc::from("{\"type\":\"ATTITUDE\",\"roll\":0.1}"),
            t0,
        );
        tree.update(
            1,
            1,
            "ATTITUDE",
            Arc::from("{\"type\":\"ATTITUDE\",\"roll\":0.2}"),
            t0 + Duration::from_secs(2),
        );
        let v = tree.to_value();
        let e = v
            .pointer("/vehicles/1/components/1/messages/ATTITUDE")
            .expect("the ATTITUDE just recorded");
        assert_eq!(e["message"]["roll"], 0.2);
        assert_eq!(e["status"]["time"]["counter"], 2);
        assert_eq!(e["status"]["time"]["frequency"], 0.5);
        assert_eq!(v["vehicles"]["1"]["id"], 1);
    }

    /// The camera's HEARTBEAT and the autopilot's are two entries, as
    /// mavlink2rest keeps them (`…/components/100/messages/HEARTBEAT`).
    #[test]
    fn components_keep_their_own_messages() {
        let mut tree = Tree::default();
        let t0 = SystemTime::UNIX_EPOCH + Duration::from_secs(100);
        let sub = "{\"type\":\"HEARTBEAT\",\"mavtype\":{\"type\":\"MAV_TYPE_SUBMARINE\"}}";
        let cam = "{\"type\":\"HEARTBEAT\",\"mavtype\":{\"type\":\"MAV_TYPE_CAMERA\"}}";
        for i in 0..3 {
            let t = t0 + Duration::from_secs(i);
            tree.update(1, 1, "HEARTBEAT", Arc::from(sub), t);
            tree.update(1, 100, "HEARTBEAT", Arc::from(cam), t);
        }
        let v = tree.to_value();
        for (comp, kind) in [(1, "MAV_TYPE_SUBMARINE"), (100, "MAV_TYPE_CAMERA")] {
            let e = v
                .pointer(&format!("/vehicles/1/components/{comp}/messages/HEARTBEAT"))
                .expect("each component's HEARTBEAT");
            assert_eq!(e["message"]["mavtype"]["type"], kind);
            assert_eq!(e["status"]["time"]["counter"], 3);
            assert_eq!(
                v["vehicles"]["1"]["components"][comp.to_string()]["id"],
                comp
            );
        }
    }

    #[test]
    fn components_are_capped() {
        let mut tree = Tree::default();
        for c in 0..=255u8 {
            tree.update(255, c, "HEARTBEAT", Arc::from("{}"), SystemTime::UNIX_EPOCH);
        }
        assert_eq!(tree.components, MAX_COMPONENTS);
    }
}
