//! The task that owns the vehicle: every input reaches the core with the
//! time it is handled at (not when the wait began: a tick or a datagram must
//! not carry a time up to a tick period old), and the core's outputs go to
//! [`Io`]. The 5-s log line is built from the core's own state.

use std::net::IpAddr;
use std::time::Duration;

use tokio::sync::watch;
use tokio::time::Instant;

use super::io::Io;
use crate::camera::rtp::GroundStations;
use crate::dialect::neptunus::{MavMessage, MavType};
use crate::firmware::codec::Event;
use crate::firmware::emulator::SimSnapshot;
use crate::firmware::link::LinkEvent;
use crate::mavlink::endpoint::Inbound;
use crate::mavlink::frame::{Frame, Undecodable};
use crate::vehicle::machine::{
    BUSY_TICK, Input, NEUTRAL_US, Now, Output, RunMode, Sender, SimTruth, Vehicle,
};

/// The camera's scene follows the vehicle at most this often.
const SCENE_PERIOD: Duration = Duration::from_millis(50);

pub(super) struct VehicleTask {
    pub(super) vehicle: Vehicle,
    pub(super) io: Io,
    outputs: Vec<Output>,
    t0: Instant,
    sim_events: Vec<Event>,
    scene: watch::Sender<crate::camera::Scene>,
    last_scene: Option<Duration>,
    /// How many want the camera's frames: the scene follows the vehicle
    /// every [`SCENE_PERIOD`] only while someone does.
    watched: watch::Receiver<usize>,
    last_tick: Duration,
    /// Per MAVLink endpoint: its stations are trusted (configuration).
    trusted: Vec<bool>,
    /// Where `auto` RTP video goes: ground stations that may control,
    /// heard on UDP.
    stations: GroundStations<Sender>,
    video_to: watch::Sender<Option<IpAddr>>,
}

impl VehicleTask {
    pub(super) fn new(
        vehicle: Vehicle,
        io: Io,
        t0: Instant,
        scene: watch::Sender<crate::camera::Scene>,
        watched: watch::Receiver<usize>,
        trusted: Vec<bool>,
        video_to: watch::Sender<Option<IpAddr>>,
    ) -> Self {
        Self {
            vehicle,
            io,
            outputs: Vec::with_capacity(64),
            t0,
            sim_events: Vec::new(),
            scene,
            last_scene: None,
            watched,
            last_tick: Duration::ZERO,
            trusted,
            stations: GroundStations::default(),
            video_to,
        }
    }

    fn clock(&self) -> Now {
        Now {
            mono: self.t0.elapsed(),
            unix_us: self.io.clock.unix_us(),
        }
    }

    pub(super) fn handle(&mut self, input: Input) {
        let now = self.clock();
        self.vehicle.handle(input, now, &mut self.outputs);
    }

    /// The listeners on an in-process endpoint changed: the core builds its
    /// streams only while there are some.
    pub(super) fn listeners(&mut self, endpoint: usize, count: &mut watch::Receiver<usize>) {
        let listened = *count.borrow_and_update() > 0;
        self.handle(Input::Listeners { endpoint, listened });
    }

    /// When the next tick is due: when the core needs one
    /// ([`Vehicle::next_tick`]), every [`BUSY_TICK`] while the built-in
    /// simulator runs, and every [`SCENE_PERIOD`] while someone watches the
    /// camera.
    fn tick_due(&self) -> Duration {
        let mut at = self.vehicle.next_tick();
        if self.io.simulator.is_some() {
            at = at.min(self.last_tick + BUSY_TICK);
        }
        if *self.watched.borrow() > 0 {
            at = at.min(self.last_scene.map_or(Duration::ZERO, |t| t + SCENE_PERIOD));
        }
        at
    }

    /// When the loop must wake: the next tick, or the file transfers' next
    /// pass ([`Vehicle::next_transfer`]) if sooner.
    pub(super) fn next_wake(&self) -> Instant {
        let at = self.tick_due();
        let at = self.vehicle.next_transfer().map_or(at, |t| at.min(t));
        self.t0 + at
    }

    /// The timer fired: the tick if it is due, and the transfers' pass if
    /// theirs is (a pass never moves the tick, whose timing is its own).
    pub(super) fn wake(&mut self) {
        let elapsed = self.t0.elapsed();
        if self.tick_due() <= elapsed {
            self.tick();
        }
        if self
            .vehicle
            .next_transfer()
            .is_some_and(|t| t <= self.t0.elapsed())
        {
            self.handle(Input::Transfer);
        }
    }

    /// A tick: the built-in simulator (run mode SIMULATOR) steps on it,
    /// then the core; the camera's scene and the `auto` video destination
    /// follow.
    fn tick(&mut self) {
        let now = self.clock();
        self.last_tick = now.mono;
        if let Some(sim) = self.io.simulator.as_mut() {
            sim.step(now.mono, &mut self.sim_events);
            let truth = sim_truth(&sim.truth());
            for ev in self.sim_events.drain(..) {
                self.vehicle
                    .handle(Input::SimBoard(ev), now, &mut self.outputs);
            }
            self.vehicle
                .handle(Input::SimTruth(truth), now, &mut self.outputs);
        }
        self.vehicle.handle(Input::Tick, now, &mut self.outputs);
        if self
            .last_scene
            .is_none_or(|t| now.mono.saturating_sub(t) >= SCENE_PERIOD)
        {
            self.last_scene = Some(now.mono);
            self.scene.send_replace(scene(&self.vehicle, now));
            let vehicle = &self.vehicle;
            let to = self
                .stations
                .target(vehicle.owner(), now.mono, |s| vehicle.may_control(*s));
            self.video_to
                .send_if_modified(|old| std::mem::replace(old, to) != to);
        }
    }

    pub(super) fn link_event(&mut self, ev: LinkEvent) {
        match ev {
            LinkEvent::State { state, reason } => self.handle(Input::Link { state, reason }),
            LinkEvent::Telemetry(ev) => self.handle(Input::Board(ev)),
            LinkEvent::Quality(q) => self.handle(Input::LinkQuality(q)),
        }
    }

    /// A frame from a station: signature checked, then to the core.
    pub(super) fn inbound(&mut self, inbound: Inbound) {
        let Inbound {
            endpoint,
            peer,
            udp_from,
            frame,
            standing,
        } = inbound;
        let now = self.clock();
        let Some(signed) = self.io.signing.check(&frame, now, &self.io.events) else {
            return;
        };
        let from = Sender {
            signed,
            trusted: self.trusted.get(endpoint).copied().unwrap_or(false),
            ..Sender::new(endpoint, peer, frame.sysid, frame.compid)
        };
        // A ground station's address on UDP: where `auto` video may go.
        let gcs_beat_from = match (udp_from, &frame.msg) {
            (Some(addr), MavMessage::HEARTBEAT(h))
                if h.mavtype == MavType::MAV_TYPE_GCS && frame.undecodable.is_none() =>
            {
                Some(addr)
            }
            _ => None,
        };
        let Some(input) = input_of(frame, from) else {
            return;
        };
        self.vehicle.handle(input, now, &mut self.outputs);
        // The core's verdict, after the frame: a station that may control
        // (allowed, signed when signing is on), never one that only watches.
        let may_control = self.vehicle.may_control(from);
        // Video follows only a station that may control, from the address
        // its admitted frames come from (an unsigned frame with its id, from
        // elsewhere, moves nothing while signing is on).
        if let Some(addr) = gcs_beat_from
            && may_control
        {
            self.stations.heard(from.sysid, from, addr, now.mono);
        }
        // The router keeps a slot (and the tlog) for peers that carry a
        // station that may control. Sticky for the peer's life: frames
        // spoofed from its address must not get it evicted.
        if !standing.may_control() && may_control && standing.set_may_control(true) {
            tracing::debug!(
                endpoint,
                peer,
                sysid = from.sysid,
                "peer carries a station that may control"
            );
        }
    }

    /// The board emulator's ground truth (`--sim`). In SIMULATOR run mode
    /// the built-in simulator's truth counts instead.
    pub(super) fn board_truth(&mut self, s: &SimSnapshot) {
        if self.io.simulator.is_none() {
            self.handle(Input::SimTruth(sim_truth(s)));
        }
    }

    /// The 5-s log line.
    pub(super) fn report(&self) {
        let s = self.io.link.stats();
        let v = &self.vehicle;
        tracing::info!(
            link = ?s.state,
            armed = v.armed(),
            mode = v.mode().name(),
            heading_deg = v.raw_heading_deg().unwrap_or(f64::NAN),
            depth_m = v.raw_depth_m().unwrap_or(f64::NAN),
            voltage_v = v.battery_v().unwrap_or(f64::NAN),
            telemetry_age_ms = s.telemetry_age_ms.unwrap_or(u64::MAX),
            rejected = s.decode.rejected_total(),
            crc_fail = s.crc_failures_echoed,
            echoes_missed = s.echoes_missed,
            thrust_resent = s.thrust_resent,
            line_drop_pct = f64::from(s.drop_rate_cpct) / 100.0,
            "telemetry"
        );
    }

    /// The outputs of what was just handled, carried out.
    pub(super) fn flush(&mut self) {
        let now = self.clock();
        self.io.apply(&mut self.outputs, &self.vehicle, now);
    }
}

/// The core's input for a frame; None for a placeholder (never handed on
/// as a real message).
fn input_of(frame: Frame, from: Sender) -> Option<Input> {
    Some(match (frame.undecodable, &frame.msg) {
        (None, _) => Input::Mavlink {
            from,
            msg: frame.msg,
        },
        (Some(Undecodable::Command(command)), MavMessage::COMMAND_LONG(c)) => {
            Input::UnknownCommand {
                from,
                command,
                target_system: c.target_system,
                target_component: c.target_component,
            }
        }
        (Some(Undecodable::ParamType(param_type)), MavMessage::PARAM_SET(p)) => {
            Input::BadParamSet {
                from,
                target_system: p.target_system,
                target_component: p.target_component,
                param_id: p.param_id.into(),
                param_type,
            }
        }
        (Some(_), _) => return None,
    })
}

/// What the camera shows: the vehicle as it knows itself.
fn scene(v: &Vehicle, now: Now) -> crate::camera::Scene {
    let e = v.estimate(now);
    let (roll_deg, pitch_deg) = v.attitude_deg();
    crate::camera::Scene {
        depth_m: e.depth_m,
        heading_deg: e.heading_deg,
        roll_deg,
        pitch_deg,
        // 1000..2000 µs spans ±90° (DO_MOUNT_CONTROL's mapping).
        tilt_deg: (f64::from(v.tilt_us()) - f64::from(NEUTRAL_US)) / 500.0 * 90.0,
        simulated: v.run_mode() == RunMode::Simulator,
        armed: v.armed(),
    }
}

/// A simulator's state (the emulator's, in or out of process) as the core
/// takes it.
fn sim_truth(s: &SimSnapshot) -> SimTruth {
    SimTruth {
        north_m: s.north_m,
        east_m: s.east_m,
        depth_m: s.depth_m,
        heading_rad: s.heading_deg.to_radians(),
        surge_mps: s.surge_mps,
        sway_mps: s.sway_mps,
        heave_mps: s.heave_mps,
        yaw_rate_rps: s.yaw_rate_dps.to_radians(),
        roll_rad: s.roll_deg.to_radians(),
        pitch_rad: s.pitch_deg.to_radians(),
    }
}
