//! What a session is and may do: its system id, its pilot rights, its
//! place among the watchers, and how it tells the browser so.
//!
//! Owns [`WatcherSlot`], leasing an id when the session may pilot, the
//! "watch only" reason with its fix, the `welcome` and `identity` messages
//! and the WebSocket `login`. Never grants more than the password or
//! `[hmi] open_control` allow (and `open_control` never with signing on).

use std::sync::Arc;
use std::sync::atomic::Ordering;

use super::Session;
use crate::hmi::protocol::{ModeView, ServerMsg};
use crate::hmi::{Shared, guard};
use crate::vehicle::mode::Mode;

/// A place among the `[hmi] max_watchers` sessions that hold no system id;
/// given back when dropped (the session leased an id, or ended).
pub(crate) struct WatcherSlot {
    shared: Arc<Shared>,
}

impl WatcherSlot {
    /// Takes a place, or `None` when `max_watchers` are watching.
    pub fn take(shared: &Arc<Shared>) -> Option<Self> {
        shared
            .watchers
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < shared.max_watchers).then_some(n + 1)
            })
            .ok()
            .map(|_| Self {
                shared: Arc::clone(shared),
            })
    }
}

impl Drop for WatcherSlot {
    fn drop(&mut self) {
        self.shared.watchers.fetch_sub(1, Ordering::AcqRel);
    }
}

impl Session {
    pub(super) fn sysid(&self) -> Option<u8> {
        self.lease.as_ref().map(|l| l.sysid)
    }

    /// May this session pilot: logged in, or admitted by `open_control`
    /// (which never applies with MAVLink signing on).
    pub(super) fn may_pilot(&self) -> bool {
        guard::may_pilot(&self.shared, self.ip, self.logged_in)
    }

    /// Leases a system id if this session may pilot and holds none; the
    /// watcher place is given back.
    pub(super) fn ensure_sysid(&mut self) -> Option<u8> {
        if self.lease.is_none() && self.may_pilot() {
            self.lease = self.shared.lease_sysid();
            if let Some(l) = &self.lease {
                self.watcher = None;
                self.model.set_me(Some(l.sysid));
                tracing::info!(
                    session = self.id,
                    sysid = l.sysid,
                    "HMI session took a system id to pilot"
                );
            }
        }
        self.sysid()
    }

    /// Why this session may only watch, and what to do about it.
    pub(super) fn watch_only_reason(&self) -> Option<String> {
        if self.sysid().is_some() {
            return None;
        }
        Some(if self.may_pilot() {
            let (lo, hi) = self.shared.sysid_range;
            if self.shared.free_sysids.lock().is_ok_and(|f| f.is_empty()) {
                format!(
                    "all {} HMI system ids ({lo}..{hi}) are held by other pilots: this session may only watch until one is free",
                    u16::from(hi) - u16::from(lo) + 1
                )
            } else {
                return None;
            }
        } else {
            guard::watch_only_reason(&self.shared)
        })
    }

    pub(super) fn welcome(&self) -> ServerMsg {
        ServerMsg::Welcome {
            session: self.id,
            sysid: self.sysid(),
            watch_only_reason: self.watch_only_reason(),
            password_required: self.shared.password.is_some() && !self.may_pilot(),
            password_set: self.shared.password.is_some(),
            pilot: self.may_pilot(),
            logged_in: self.logged_in,
            vehicle_sysid: self.shared.vehicle_sysid,
            camera_rotation_deg: self.shared.camera_rotation_deg,
            version: env!("CARGO_PKG_VERSION"),
            modes: ModeView::offered(),
            boot_mode: Mode::BOOT.number(),
        }
    }

    /// The session's rights changed (logged in, leased an id).
    pub(super) fn identity(&self) -> ServerMsg {
        ServerMsg::Identity {
            sysid: self.sysid(),
            pilot: self.may_pilot(),
            logged_in: self.logged_in,
            watch_only_reason: self.watch_only_reason(),
        }
    }

    /// The WebSocket `login` message, for clients without cookies: the
    /// same check, throttle and log as the page's form.
    pub(super) async fn login(&mut self, password: &str) -> ServerMsg {
        let outcome =
            guard::check_password(&self.shared, self.ip, password, "WebSocket login").await;
        let ok = outcome == guard::Login::Ok;
        if ok {
            self.logged_in = true;
            self.ensure_sysid();
        }
        let mut message = outcome.message();
        if ok && self.sysid().is_none() {
            message.push_str(&format!(
                " — but {}",
                self.watch_only_reason().unwrap_or_default()
            ));
        }
        ServerMsg::LoginResult { ok, message }
    }
}
