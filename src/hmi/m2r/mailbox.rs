//! What waits to be written to one WebSocket client: bounded whatever the
//! client does.
//!
//! Owns coalescing: telemetry keeps only the newest message of each
//! *stream* ([`StreamKey`]: type, sending system and component, and the
//! instance it is about — each NAMED_VALUE_FLOAT name, each battery, the
//! camera's HEARTBEAT apart from the autopilot's), so a client that reads
//! slowly gets fresh data and loses no stream, and a client that never reads
//! holds one message per stream, at most [`STREAM_CAP`] of them (beyond
//! that the oldest waiting is dropped and counted). Messages that must each
//! arrive (answers, parameters, texts) and the answers to the client's own
//! frames wait in a FIFO capped at [`QUEUE_CAP`], the oldest dropped and
//! counted beyond it.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use tokio::sync::Notify;

use super::stream::StreamKey;

/// Messages that each matter (a parameter list, command answers, texts):
/// never coalesced. A full parameter list (a few hundred) fits.
pub const QUEUE_CAP: usize = 2048;

/// Streams waiting at once. The vehicle sends a few dozen (its message
/// types, five named values, two components); the cap only bounds a client
/// that never reads against instances without end (MESSAGE_INTERVAL per
/// message id, say).
pub const STREAM_CAP: usize = 256;

/// Message types a client must receive one by one.
pub fn must_queue(name: &str) -> bool {
    matches!(
        name,
        "COMMAND_ACK"
            | "COMMAND_LONG"
            | "COMMAND_INT"
            | "PARAM_VALUE"
            | "PARAM_EXT_VALUE"
            | "STATUSTEXT"
            | "TIMESYNC"
            | "PING"
            | "AUTOPILOT_VERSION"
            | "PROTOCOL_VERSION"
            | "AVAILABLE_MODES"
            | "FILE_TRANSFER_PROTOCOL"
            | "LOG_ENTRY"
            | "LOG_DATA"
    ) || name.starts_with("MISSION_")
}

#[derive(Default)]
struct Inner {
    queue: VecDeque<Arc<str>>,
    latest: HashMap<StreamKey, Arc<str>>,
    /// Streams with a message in `latest`, oldest first.
    order: VecDeque<StreamKey>,
    dropped: u64,
    closed: bool,
}

#[derive(Default)]
pub struct Mailbox {
    inner: Mutex<Inner>,
    ready: Notify,
}

impl Mailbox {
    /// Adds a message of stream `key` (coalesced unless its type must queue).
    pub fn push(&self, key: StreamKey, text: Arc<str>) {
        if must_queue(key.name) {
            self.enqueue(text);
            return;
        }
        let Ok(mut m) = self.inner.lock() else {
            return;
        };
        if m.latest.insert(key, text).is_none() {
            m.order.push_back(key);
            if m.order.len() > STREAM_CAP
                && let Some(oldest) = m.order.pop_front()
            {
                m.latest.remove(&oldest);
                m.dropped += 1;
            }
        }
        drop(m);
        self.ready.notify_one();
    }

    /// An answer to the client's own frame (always queued).
    pub fn reply(&self, text: impl Into<Arc<str>>) {
        self.enqueue(text.into());
    }

    fn enqueue(&self, text: Arc<str>) {
        let Ok(mut m) = self.inner.lock() else {
            return;
        };
        if m.queue.len() >= QUEUE_CAP {
            m.queue.pop_front();
            m.dropped += 1;
        }
        m.queue.push_back(text);
        drop(m);
        self.ready.notify_one();
    }

    /// The next message to write: queued ones first, then the stream
    /// waiting longest.
    pub fn pop(&self) -> Option<Arc<str>> {
        let mut m = self.inner.lock().ok()?;
        if let Some(t) = m.queue.pop_front() {
            return Some(t);
        }
        let key = m.order.pop_front()?;
        m.latest.remove(&key)
    }

    /// Waits for the next message; `None` once closed.
    pub async fn next(&self) -> Option<Arc<str>> {
        loop {
            let notified = self.ready.notified();
            if self.inner.lock().is_ok_and(|m| m.closed) {
                return None;
            }
            if let Some(t) = self.pop() {
                return Some(t);
            }
            notified.await;
        }
    }

    pub fn close(&self) {
        if let Ok(mut m) = self.inner.lock() {
            m.closed = true;
        }
        self.ready.notify_one();
    }

    /// Messages waiting now (at most [`STREAM_CAP`] plus [`QUEUE_CAP`]).
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.inner
            .lock()
            .map_or(0, |m| m.queue.len() + m.latest.len())
    }

    /// Messages dropped unsent because the client did not read: queued
    /// ones beyond [`QUEUE_CAP`], the oldest stream's beyond
    /// [`STREAM_CAP`] (not those a newer message of their stream replaced).
    pub fn dropped(&self) -> u64 {
        self.inner.lock().map_or(0, |m| m.dropped)
    }
}

#[cfg(test)]
mod tests {
    use super::super::stream::Instance;
    use super::*;

    fn key(name: &'static str, component: u8, instance: Instance) -> StreamKey {
        StreamKey {
            name,
            system: 1,
            component,
            instance,
        }
    }

    fn one(name: &'static str) -> StreamKey {
        key(name, 1, Instance::One)
    }

    fn named(n: &str) -> StreamKey {
        let mut b = [0u8; 10];
        b[..n.len()].copy_from_slice(n.as_bytes());
        key("NAMED_VALUE_FLOAT", 1, Instance::Name(b))
    }

    fn drain(m: &Mailbox) -> Vec<String> {
        std::iter::from_fn(|| m.pop())
            .map(|t| t.to_string())
            .collect()
    }

    #[test]
    fn telemetry_coalesces_and_answers_queue() {
        let m = Mailbox::default();
        for i in 0..1000 {
            m.push(one("ATTITUDE"), Arc::from(format!("a{i}")));
            m.push(one("VFR_HUD"), Arc::from(format!("v{i}")));
        }
        for i in 0..(QUEUE_CAP + 10) {
            m.push(one("PARAM_VALUE"), Arc::from(format!("p{i}")));
        }
        assert_eq!(m.len(), 2 + QUEUE_CAP);
        assert_eq!(m.dropped(), 10);
        assert_eq!(m.pop().as_deref(), Some("p10"));
        for _ in 1..QUEUE_CAP {
            m.pop();
        }
        assert_eq!(m.pop().as_deref(), Some("a999"));
        assert_eq!(m.pop().as_deref(), Some("v999"));
        assert!(m.pop().is_none());
    }

    /// The vehicle's burst of five NAMED_VALUE_FLOATs, and the camera's
    /// HEARTBEAT beside the autopilot's, read late: each one's newest.
    #[test]
    fn each_stream_keeps_its_newest_message() {
        let m = Mailbox::default();
        let names = ["Lights1", "PilotGain", "CamTilt", "Laser", "InputHold"];
        for burst in 0..3 {
            for n in names {
                m.push(named(n), Arc::from(format!("{n}{burst}")));
            }
            m.push(one("HEARTBEAT"), Arc::from(format!("hb1-{burst}")));
            m.push(
                key("HEARTBEAT", 100, Instance::One),
                Arc::from(format!("hb100-{burst}")),
            );
        }
        assert_eq!(
            drain(&m),
            [
                "Lights12",
                "PilotGain2",
                "CamTilt2",
                "Laser2",
                "InputHold2",
                "hb1-2",
                "hb100-2"
            ]
        );
        assert_eq!(m.dropped(), 0, "replaced is not dropped");
    }

    /// A stream updated while it waits keeps its place: a fast stream
    /// never pushes a slow one back.
    #[test]
    fn a_stream_keeps_its_place_in_line() {
        let m = Mailbox::default();
        m.push(one("ATTITUDE"), Arc::from("a0"));
        m.push(one("SYS_STATUS"), Arc::from("s0"));
        m.push(one("ATTITUDE"), Arc::from("a1"));
        assert_eq!(m.pop().as_deref(), Some("a1"));
        m.push(one("ATTITUDE"), Arc::from("a2"));
        assert_eq!(drain(&m), ["s0", "a2"]);
    }

    #[test]
    fn streams_are_capped_the_oldest_dropped_and_counted() {
        let m = Mailbox::default();
        let n = u32::try_from(STREAM_CAP).unwrap_or(u32::MAX) + 10;
        for i in 0..n {
            m.push(
                key("MESSAGE_INTERVAL", 1, Instance::Id(i)),
                Arc::from(format!("i{i}")),
            );
        }
        assert_eq!(m.len(), STREAM_CAP);
        assert_eq!(m.dropped(), 10);
        let got = drain(&m);
        assert_eq!(got.first().map(String::as_str), Some("i10"));
        assert_eq!(
            got.last().map(String::as_str),
            Some(&*format!("i{}", n - 1))
        );
        // A stream waiting again after it was dropped is an ordinary one.
        m.push(
            key("MESSAGE_INTERVAL", 1, Instance::Id(0)),
            Arc::from("again"),
        );
        assert_eq!(drain(&m), ["again"]);
    }
}
