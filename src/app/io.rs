//! Carries the core's outputs out: frames to the stations (one send path:
//! encode → sequence → sign → route), commands to the board link or the
//! built-in simulator, parameter saves, event-log records, the signing key,
//! the recorder's controls and telemetry, requests to the disk worker of
//! the file transfers.
//! Decides nothing about the vehicle.

use std::time::Duration;

use super::params::ParamSaver;
use super::signing::LinkSigning;
use crate::dialect::neptunus::MavMessage;
use crate::eventlog::EventLog;
use crate::firmware::emulator::EmulatorOptions;
use crate::firmware::link::LinkHandle;
use crate::firmware::loopback::BuiltinSim;
use crate::mavlink::endpoint::{Outbound, Route, RouterHandle};
use crate::mavlink::frame::{encode_command_ack_raw, encode_v2};
use crate::vehicle::machine::{COMPONENT_ID, NEUTRAL_GO, Now, Output, RunMode, To, Topic, Vehicle};

/// The link hears that the vehicle is healthy at most this often. Below the
/// idle tick (100 ms, which the board's lines pace with some jitter), so an
/// idle vehicle's every tick reaches the link.
const HEALTHY_PERIOD: Duration = Duration::from_millis(50);

pub(super) struct Io {
    /// The HMI sessions' and the mavlink2rest API's hubs.
    pub(super) hmi: [crate::hmi::Outlet; 2],
    pub(super) router: RouterHandle,
    pub(super) link: LinkHandle,
    pub(super) params: ParamSaver,
    pub(super) events: EventLog,
    pub(super) signing: LinkSigning,
    /// The file transfers' disk worker (log download, MAVLink FTP).
    pub(super) files: crate::files::FileWorker,
    /// The built-in simulator while the run mode is SIMULATOR.
    pub(super) simulator: Option<BuiltinSim>,
    pub(super) simulator_opts: EmulatorOptions,
    /// The wall clock the logs and the core use (set by the station in control).
    pub(super) clock: std::sync::Arc<crate::wallclock::WallClock>,
    /// Recording on the vehicle (None: the camera cannot record).
    recorder: Option<crate::camera::record::RecorderHandle>,
    seq: u8,
    last_healthy: Option<Duration>,
    /// Per outlet, what this pass delivers (handed over at its end).
    delivered: [Vec<crate::hmi::Delivery>; 2],
}

impl Io {
    // One argument per thing it carries outputs to.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        hmi: [crate::hmi::Outlet; 2],
        router: RouterHandle,
        link: LinkHandle,
        params: ParamSaver,
        events: EventLog,
        signing: LinkSigning,
        files: crate::files::FileWorker,
        simulator_opts: EmulatorOptions,
    ) -> Self {
        Self {
            hmi,
            router,
            link,
            params,
            events,
            signing,
            files,
            simulator: None,
            simulator_opts,
            clock: crate::wallclock::WallClock::system(),
            recorder: None,
            seq: 0,
            last_healthy: None,
            delivered: Default::default(),
        }
    }

    /// The wall clock shared with the telemetry log (default: a new one).
    pub(super) fn with_clock(mut self, clock: std::sync::Arc<crate::wallclock::WallClock>) -> Self {
        self.clock = clock;
        self
    }

    /// Where the core's recording controls and samples go.
    pub(super) fn with_recorder(
        mut self,
        recorder: Option<crate::camera::record::RecorderHandle>,
    ) -> Self {
        self.recorder = recorder;
        self
    }

    /// A message from component `compid` to the in-process stations it is
    /// for (the browser sessions hear the autopilot and the camera's
    /// recording, mavlink2rest every component), and on the wire to the
    /// endpoints it is for.
    fn send_message(
        &mut self,
        to: To,
        compid: u8,
        msg: &MavMessage,
        topic: Option<Topic>,
        sysid: u8,
        now: Now,
    ) {
        for (outlet, batch) in self.hmi.iter().zip(&mut self.delivered) {
            batch.extend(outlet.delivery(to, compid, msg, topic));
        }
        if !self.local_only(to) {
            self.send_frame(to, now, |seq| encode_v2(sysid, compid, seq, msg));
        }
    }

    pub(super) fn apply(&mut self, outputs: &mut Vec<Output>, vehicle: &Vehicle, mut now: Now) {
        let sysid = vehicle.sysid();
        for out in outputs.drain(..) {
            match out {
                Output::Send { to, msg } => {
                    self.send_message(to, COMPONENT_ID, &msg, None, sysid, now)
                }
                Output::Text { to, topic, msg } => {
                    self.send_message(to, COMPONENT_ID, &msg, Some(topic), sysid, now)
                }
                // Another component of ours (the camera).
                Output::SendAs { to, compid, msg } => {
                    self.send_message(to, compid, &msg, None, sysid, now)
                }
                Output::AckUnknown {
                    to,
                    compid,
                    command,
                    result,
                    target_system,
                    target_component,
                } => self.send_frame(to, now, |seq| {
                    encode_command_ack_raw(
                        sysid,
                        compid,
                        seq,
                        command,
                        result,
                        target_system,
                        target_component,
                    )
                }),
                // File data: on the wire only, never into the telemetry log.
                Output::Bulk { to, msg } => {
                    if !self.local_only(to) {
                        self.send_frame_unlogged(to, now, |seq| {
                            encode_v2(sysid, COMPONENT_ID, seq, &msg)
                        });
                    }
                }
                Output::Files(req) => self.files.send(req),
                Output::Board(cmd) => self.link.send(cmd),
                Output::SimBoard(cmd) => {
                    if let Some(sim) = self.simulator.as_mut() {
                        sim.command(&cmd, now.mono);
                    }
                }
                Output::RunMode {
                    mode,
                    start_depth_m,
                    start_heading_deg,
                } => {
                    self.simulator = match mode {
                        RunMode::Normal => None,
                        RunMode::Simulator => {
                            let mut sim = BuiltinSim::new(self.simulator_opts.clone(), now.mono);
                            sim.place(start_depth_m, start_heading_deg);
                            Some(sim)
                        }
                    };
                    tracing::warn!(?mode, "run mode changed");
                }
                Output::Log(ev) => {
                    tracing::info!(event = ev.kind, sysid = ?ev.sysid, "{}", ev.detail);
                    self.events.record(now.unix_us, now.mono, &ev);
                }
                Output::SetSigningKey {
                    key,
                    initial_timestamp,
                } => {
                    if let Err(e) = self.signing.set_key(key, initial_timestamp) {
                        tracing::error!("signing key not saved: {e}");
                    }
                }
                Output::SaveParams => self.params.save(vehicle.params().clone()),
                Output::SetWallClock { unix_us } => {
                    tracing::warn!(
                        was = %crate::eventlog::rfc3339_utc(now.unix_us),
                        now = %crate::eventlog::rfc3339_utc(unix_us),
                        "wall clock set by the ground station in control"
                    );
                    self.clock.set_unix_us(unix_us);
                    // What follows (the event line saying so) carries the new time.
                    now.unix_us = self.clock.unix_us();
                }
                Output::Record(c) => {
                    if let Some(r) = &self.recorder {
                        r.control(c);
                    }
                }
                Output::RecordSample(sample) => {
                    if let Some(r) = &self.recorder {
                        r.sample(sample);
                    }
                }
                Output::Healthy => {
                    // The link only needs to hear this every few hundred ms.
                    if self
                        .last_healthy
                        .is_none_or(|t| now.mono.saturating_sub(t) >= HEALTHY_PERIOD)
                    {
                        self.last_healthy = Some(now.mono);
                        self.link.healthy();
                    }
                    if let Some(sim) = self.simulator.as_mut() {
                        sim.healthy(now.mono);
                    }
                }
            }
        }
        for (outlet, batch) in self.hmi.iter().zip(&mut self.delivered) {
            outlet.deliver_all(batch);
        }
    }

    /// The one way a frame leaves for the stations: encoded with the next
    /// sequence number, signed (when a key is set), routed.
    fn send_frame(&mut self, to: To, now: Now, encode: impl FnOnce(u8) -> Vec<u8>) {
        let mut bytes = encode(self.seq);
        self.seq = self.seq.wrapping_add(1);
        self.signing.sign(&mut bytes, now);
        self.router.send(Outbound {
            route: route(to),
            bytes: bytes.into(),
        });
    }

    /// As [`Io::send_frame`], for file data: not written to the telemetry log.
    fn send_frame_unlogged(&mut self, to: To, now: Now, encode: impl FnOnce(u8) -> Vec<u8>) {
        let mut bytes = encode(self.seq);
        self.seq = self.seq.wrapping_add(1);
        self.signing.sign(&mut bytes, now);
        self.router.send_unlogged(Outbound {
            route: route(to),
            bytes: bytes.into(),
        });
    }

    /// Whether `to` reaches in-process stations only (nothing to encode).
    fn local_only(&self, to: To) -> bool {
        self.hmi.iter().any(|o| o.only_hmi(to))
    }

    /// Thrusters to neutral, first thing at shutdown.
    pub(super) fn neutral(&self) {
        self.link.send(NEUTRAL_GO);
    }
}

fn route(to: To) -> Route {
    match to {
        To::All => Route::All,
        To::Endpoint(e) => Route::Endpoint(e),
        To::Peer(e, p) => Route::Peer(e, p),
    }
}
