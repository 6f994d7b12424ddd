//! What waits to be written to one WebSocket client: bounded whatever the
//! client does.
//!
//! Owns coalescing: telemetry keeps only the newest message of each type
//! (a client that reads slowly gets fresh data, a client that never reads
//! holds one message per type); messages that must each arrive (answers,
//! parameters, texts) and the answers to the client's own frames wait in
//! a FIFO capped at [`QUEUE_CAP`], the oldest dropped and counted beyond it.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use tokio::sync::Notify;

/// Messages that each matter (a parameter list, command answers, texts):
/// never coalesced. A full parameter list (a few hundred) fits.
pub const QUEUE_CAP: usize = 2048;

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
    latest: HashMap<&'static str, Arc<str>>,
    /// Types with a message in `latest`, oldest first.
    order: VecDeque<&'static str>,
    dropped: u64,
    closed: bool,
}

#[derive(Default)]
pub struct Mailbox {
    inner: Mutex<Inner>,
    ready: Notify,
}

impl Mailbox {
    /// Adds a message of type `name` (coalesced unless it must queue).
    pub fn push(&self, name: &'static str, text: Arc<str>) {
        let Ok(mut m) = self.inner.lock() else {
            return;
        };
        if must_queue(name) {
            if m.queue.len() >= QUEUE_CAP {
                m.queue.pop_front();
                m.dropped += 1;
            }
            m.queue.push_back(text);
        } else if m.latest.insert(name, text).is_none() {
            m.order.push_back(name);
        }
        drop(m);
        self.ready.notify_one();
    }

    /// An answer to the client's own frame (always queued).
    pub fn reply(&self, text: impl Into<Arc<str>>) {
        self.push("COMMAND_ACK", text.into());
    }

    /// The next message to write: queued ones first.
    pub fn pop(&self) -> Option<Arc<str>> {
        let mut m = self.inner.lock().ok()?;
        if let Some(t) = m.queue.pop_front() {
            return Some(t);
        }
        let name = m.order.pop_front()?;
        m.latest.remove(name)
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

    /// Messages waiting now (at most the types heard plus [`QUEUE_CAP`]).
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.inner
            .lock()
            .map_or(0, |m| m.queue.len() + m.latest.len())
    }

    /// Queued messages dropped because the client did not read.
    pub fn dropped(&self) -> u64 {
        self.inner.lock().map_or(0, |m| m.dropped)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn telemetry_coalesces_and_answers_queue() {
        let m = Mailbox::default();
        for i in 0..1000 {
            m.push("ATTITUDE", Arc::from(format!("a{i}")));
            m.push("VFR_HUD", Arc::from(format!("v{i}")));
        }
        for i in 0..(QUEUE_CAP + 10) {
            m.push("PARAM_VALUE", Arc::from(format!("p{i}")));
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
}
