//! The vehicle core on a bench: one [`Vehicle`], a synthetic clock and a
//! board that reports at its real rates, for the `*_core` tests. No process,
//! no socket, no sleep: every test is a plain function of the inputs it
//! feeds and the `now` it passes.
//!
//! A test builds its rig with [`CoreRig::new`] and the builder calls
//! (`unix_epoch`, `feed`, `alive`), then either [`CoreRig::started`] (board
//! link up and 1.2 s of telemetry: ready to arm) or drives the start itself.
//! The finders below read what the core emitted; each keeps the meaning its
//! tests relied on (e.g. [`statustexts`] one string per message as sent,
//! [`texts`] long ones put together from their chunks).

use std::time::Duration;

use neptunus::dialect::neptunus::*;
use neptunus::firmware::codec::{Command, Event, NavSample, StatusSample};
use neptunus::firmware::link::LinkState;
use neptunus::vehicle::machine::{Input, Now, Output, Sender, To, Vehicle};

/// The core's tick: the I/O loop ticks it at 100 Hz.
pub const TICK: Duration = Duration::from_millis(10);
/// `unix_us` at `t = 0` unless a test sets another (`CoreRig::unix_epoch`).
pub const UNIX_EPOCH_US: u64 = 1_800_000_000_000_000;
/// Motor outputs at rest.
pub const NEUTRAL: [u16; 3] = [1500; 3];

/// What the board reports while the rig runs: the nav line at 10 Hz and the
/// status line at 1 Hz, always the same values.
#[derive(Debug, Clone)]
pub struct BoardFeed {
    pub nav: NavSample,
    pub status: StatusSample,
    /// Stamp each status line with the board's uptime (`time_ms` = the rig's
    /// clock), as the real board does.
    pub uptime: bool,
}

impl BoardFeed {
    /// Level, heading 10°, at 1 m, 12 V: a vehicle ready to drive.
    pub fn level_at_1_m() -> Self {
        Self {
            nav: NavSample {
                heading_deg: Some(10.0),
                depth_m: Some(1.0),
                pitch_deg: Some(0.0),
                roll_deg: Some(0.0),
                yaw_deg: Some(10.0),
                fthr_pct: Some(0.0),
            },
            status: StatusSample {
                vout_v: Some(12.0),
                battery_current_a: Some(0.5),
                pres_mbar: Some(1113.0),
                ..Default::default()
            },
            uptime: false,
        }
    }
}

/// One vehicle core, its clock and its board.
pub struct CoreRig {
    /// The core under test; tests read its state directly.
    pub v: Vehicle,
    /// The monotonic clock. Only [`CoreRig::run`] advances it, unless a test
    /// steps it itself to place an input in time.
    pub t: Duration,
    /// What the board says on each nav/status beat of [`CoreRig::run`].
    pub feed: BoardFeed,
    /// Stations that send a GCS heartbeat every second while `run` ticks.
    pub alive: Vec<Sender>,
    unix_epoch_us: u64,
}

impl CoreRig {
    /// `v` at `t = 0`, nothing handled yet (the board link is down), fed
    /// [`BoardFeed::level_at_1_m`], nobody alive.
    pub fn new(v: Vehicle) -> Self {
        Self {
            v,
            t: Duration::ZERO,
            feed: BoardFeed::level_at_1_m(),
            alive: Vec::new(),
            unix_epoch_us: UNIX_EPOCH_US,
        }
    }
    /// Wall-clock time (`Now::unix_us`) at `t = 0`.
    pub fn unix_epoch(mut self, unix_us: u64) -> Self {
        self.unix_epoch_us = unix_us;
        self
    }
    pub fn feed(mut self, feed: BoardFeed) -> Self {
        self.feed = feed;
        self
    }
    /// `station` sends a heartbeat every second from the first `run` on.
    pub fn alive(mut self, station: Sender) -> Self {
        self.alive.push(station);
        self
    }
    /// Board link up, then 1.2 s of ticks with telemetry: past the core's
    /// freshness checks, so arming is possible.
    pub fn started(mut self) -> Self {
        self.link_up();
        self.run(Duration::from_millis(1200));
        self
    }

    pub fn now(&self) -> Now {
        Now {
            mono: self.t,
            unix_us: self.unix_epoch_us + self.t.as_micros() as u64,
        }
    }
    /// One input at the current time; what the core emitted for it.
    pub fn input(&mut self, i: Input) -> Vec<Output> {
        let mut out = Vec::new();
        let now = self.now();
        self.v.handle(i, now, &mut out);
        out
    }
    /// Ticks at 100 Hz for `d`, with board telemetry (nav at 10 Hz, status at
    /// 1 Hz) and the heartbeats of the stations in `alive` (1 Hz), in that
    /// order before each tick; everything the core emitted.
    pub fn run(&mut self, d: Duration) -> Vec<Output> {
        self.run_with(d, true)
    }
    /// As [`CoreRig::run`], but the board says nothing.
    pub fn run_board_silent(&mut self, d: Duration) -> Vec<Output> {
        self.run_with(d, false)
    }
    fn run_with(&mut self, d: Duration, board: bool) -> Vec<Output> {
        let end = self.t + d;
        let mut all = Vec::new();
        while self.t < end {
            self.t += TICK;
            let ms = self.t.as_millis();
            if board && ms.is_multiple_of(100) {
                let nav = self.feed.nav;
                all.extend(self.input(Input::Board(Event::Nav(nav))));
            }
            if board && ms.is_multiple_of(1000) {
                let mut status = self.feed.status.clone();
                if self.feed.uptime {
                    status.time_ms = Some(ms as u64);
                }
                all.extend(self.input(Input::Board(Event::Status(status))));
            }
            if ms.is_multiple_of(1000) {
                for s in self.alive.clone() {
                    all.extend(self.heartbeat(s));
                }
            }
            all.extend(self.input(Input::Tick));
        }
        all
    }

    pub fn link_up(&mut self) -> Vec<Output> {
        self.input(Input::Link {
            state: LinkState::Up,
            reason: None,
        })
    }
    pub fn link_down(&mut self, reason: &str) -> Vec<Output> {
        self.input(Input::Link {
            state: LinkState::Down,
            reason: Some(reason.into()),
        })
    }

    // ---- what a station sends ----

    pub fn msg(&mut self, from: Sender, msg: MavMessage) -> Vec<Output> {
        self.input(Input::Mavlink { from, msg })
    }
    pub fn heartbeat(&mut self, from: Sender) -> Vec<Output> {
        self.msg(from, super::gcs_heartbeat())
    }
    /// COMMAND_LONG to system 1, component 1; `params` are param1.., the
    /// rest 0.
    pub fn cmd(&mut self, from: Sender, command: MavCmd, params: &[f32]) -> Vec<Output> {
        self.msg(from, command_long(command, params))
    }
    pub fn arm(&mut self, from: Sender) -> Vec<Output> {
        self.cmd(from, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, &[1.0])
    }
    /// MAV_CMD_REQUEST_OPERATOR_CONTROL for the sender itself.
    pub fn request_control(
        &mut self,
        from: Sender,
        action: f32,
        takeover: f32,
        timeout_s: f32,
    ) -> Vec<Output> {
        self.cmd(
            from,
            MavCmd::MAV_CMD_REQUEST_OPERATOR_CONTROL,
            &[action, takeover, timeout_s, f32::from(from.sysid)],
        )
    }
    /// MANUAL_CONTROL: forward `x`, every other axis centred, no buttons.
    pub fn stick(&mut self, from: Sender, x: i16) -> Vec<Output> {
        self.manual(from, x, 500, 0, 0)
    }
    /// MANUAL_CONTROL with forward `x`, heave `z` (0..1000, 500 centred), yaw
    /// `r` and `buttons`.
    pub fn manual(&mut self, from: Sender, x: i16, z: i16, r: i16, buttons: u16) -> Vec<Output> {
        self.msg(from, manual_control(x, z, r, buttons))
    }
    pub fn param_set(
        &mut self,
        from: Sender,
        name: &str,
        value: f32,
        ty: MavParamType,
    ) -> Vec<Output> {
        self.msg(
            from,
            MavMessage::PARAM_SET(PARAM_SET_DATA {
                param_value: value,
                target_system: 1,
                target_component: 1,
                param_id: name.into(),
                param_type: ty,
            }),
        )
    }
}

/// COMMAND_LONG to system 1, component 1: `params` are param1.., the rest 0.
pub fn command_long(command: MavCmd, params: &[f32]) -> MavMessage {
    let mut p = [0.0; 7];
    p[..params.len()].copy_from_slice(params);
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        command,
        target_system: 1,
        target_component: 1,
        confirmation: 0,
    })
}

/// MANUAL_CONTROL to system 1, y centred.
pub fn manual_control(x: i16, z: i16, r: i16, buttons: u16) -> MavMessage {
    MavMessage::MANUAL_CONTROL(MANUAL_CONTROL_DATA {
        x,
        y: 0,
        z,
        r,
        buttons,
        target: 1,
        ..Default::default()
    })
}

// ---- reading what the core emitted ----

/// Every MAVLink message sent, with where it went.
pub fn sent(out: &[Output]) -> Vec<(To, MavMessage)> {
    out.iter()
        .filter_map(|o| o.message().map(|(to, msg)| (to, msg.clone())))
        .collect()
}

/// The messages of one kind, in order: `msgs!(&out, HEARTBEAT)` is a
/// `Vec<HEARTBEAT_DATA>`.
macro_rules! msgs {
    ($out:expr, $kind:ident) => {
        $crate::common::core_rig::sent($out)
            .into_iter()
            .filter_map(|(_, m)| match m {
                ::neptunus::dialect::neptunus::MavMessage::$kind(d) => Some(d),
                _ => None,
            })
            .collect::<Vec<_>>()
    };
}
/// As [`msgs!`], each with where it went: `Vec<(To, PARAM_VALUE_DATA)>`.
#[allow(unused_macros, reason = "each test binary uses a part of this module")]
macro_rules! sends {
    ($out:expr, $kind:ident) => {
        $crate::common::core_rig::sent($out)
            .into_iter()
            .filter_map(|(to, m)| match m {
                ::neptunus::dialect::neptunus::MavMessage::$kind(d) => Some((to, d)),
                _ => None,
            })
            .collect::<Vec<_>>()
    };
}
#[allow(unused_imports, reason = "each test binary uses a part of this module")]
pub(crate) use {msgs, sends};

/// Whether a message sent `to` reaches station `s`.
pub fn reaches(to: To, s: Sender) -> bool {
    match to {
        To::All => true,
        To::Endpoint(e) => e == s.endpoint,
        To::Peer(e, p) => e == s.endpoint && p == s.peer,
    }
}

/// How many messages with id `id` were sent to exactly `to`.
pub fn count_sent(out: &[Output], id: u32, to: To) -> usize {
    use mavlink_core::Message as _;
    sent(out)
        .iter()
        .filter(|(t, m)| *t == to && m.message_id() == id)
        .count()
}

/// How many messages with id `id` reach station `s` (its endpoint, everyone,
/// or it).
pub fn count_reaching(out: &[Output], id: u32, s: Sender) -> usize {
    use mavlink_core::Message as _;
    sent(out)
        .iter()
        .filter(|(to, m)| m.message_id() == id && reaches(*to, s))
        .count()
}

pub fn acks(out: &[Output]) -> Vec<COMMAND_ACK_DATA> {
    msgs!(out, COMMAND_ACK)
}

/// The result of the first COMMAND_ACK for `cmd`; panics if there is none.
pub fn ack_of(out: &[Output], cmd: MavCmd) -> MavResult {
    acks(out)
        .into_iter()
        .find(|a| a.command == cmd)
        .map(|a| a.result)
        .unwrap_or_else(|| panic!("no ACK for {cmd:?} in {out:?}"))
}

/// One string per STATUSTEXT as sent: a long text is several (50-byte
/// chunks).
pub fn statustexts(out: &[Output]) -> Vec<String> {
    msgs!(out, STATUSTEXT)
        .iter()
        .map(super::statustext)
        .collect()
}

/// The STATUSTEXTs, long ones put together from their chunks.
pub fn texts(out: &[Output]) -> Vec<String> {
    joined(sent(out).into_iter().map(|(_, m)| m))
}

/// The STATUSTEXTs that reach station `who`, long ones put together.
pub fn texts_to(out: &[Output], who: Sender) -> Vec<String> {
    joined(
        sent(out)
            .into_iter()
            .filter(|(to, _)| reaches(*to, who))
            .map(|(_, m)| m),
    )
}

fn joined(msgs: impl Iterator<Item = MavMessage>) -> Vec<String> {
    let mut all: Vec<(u16, String)> = Vec::new();
    for m in msgs {
        let MavMessage::STATUSTEXT(s) = m else {
            continue;
        };
        let part = super::statustext(&s);
        match all.last_mut() {
            Some((id, text)) if s.id != 0 && *id == s.id && s.chunk_seq > 0 => text.push_str(&part),
            _ => all.push((s.id, part)),
        }
    }
    all.into_iter().map(|(_, t)| t).collect()
}

pub fn has_text(out: &[Output], needle: &str) -> bool {
    texts(out).iter().any(|t| t.contains(needle))
}

/// Every `go()` for the board, as `[port, vertical, starboard]` µs.
pub fn gos(out: &[Output]) -> Vec<[u16; 3]> {
    board_commands(out)
        .into_iter()
        .filter_map(|c| match c {
            Command::Go {
                port_us,
                vertical_us,
                starboard_us,
            } => Some([port_us, vertical_us, starboard_us]),
            _ => None,
        })
        .collect()
}

/// Every command for the (real) board.
pub fn board_commands(out: &[Output]) -> Vec<Command> {
    out.iter()
        .filter_map(|o| match o {
            Output::Board(c) => Some(*c),
            _ => None,
        })
        .collect()
}

/// The event log's entries: kind and station.
pub fn events(out: &[Output]) -> Vec<(&'static str, Option<u8>)> {
    out.iter()
        .filter_map(|o| match o {
            Output::Log(e) => Some((e.kind, e.sysid)),
            _ => None,
        })
        .collect()
}

pub fn has_event(out: &[Output], kind: &str, sysid: Option<u8>) -> bool {
    events(out).iter().any(|e| e.0 == kind && e.1 == sysid)
}

/// How many times the core asked for the parameters to be saved.
pub fn saves(out: &[Output]) -> usize {
    out.iter().filter(|o| **o == Output::SaveParams).count()
}
