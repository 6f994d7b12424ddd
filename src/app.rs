//! Wiring: starts the board (real or emulated), the serial link and the
//! vehicle task, and shuts them down in order.
//!
//! Owns task lifetimes and nothing else: every decision about the vehicle
//! lives in the vehicle task; this module only connects channels.

use std::future::Future;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::config::{BoardSource, Settings};
use crate::dialect::neptunus::MavMessage;
use crate::firmware::codec::{Command, Event, NavSample, StatusSample};
use crate::firmware::emulator::PtyBoard;
use crate::firmware::link::{self, LinkError, LinkEvent};
use crate::mavlink::endpoint::{
    EndpointError, Inbound, Outbound, Route, Router, RouterConfig, RouterHandle,
};
use crate::mavlink::frame::{encode_command_ack_raw, encode_v2};
use crate::mavlink::tlog::TlogConfig;
use crate::vehicle::machine::{COMPONENT_ID, Input, Now, Output, Sender, SimTruth, To, Vehicle};
use crate::vehicle::params::ParamFile;

/// Errors starting the vehicle.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error("cannot start the board emulator: {0}")]
    Emulator(#[from] crate::firmware::pty::PtyError),
    #[error(transparent)]
    Endpoint(#[from] EndpointError),
    #[error("ground-station profiles: {0}")]
    Profiles(#[from] crate::vehicle::input::ProfileError),
    #[error("cannot create the data directory {path}: {source}")]
    DataDir {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
}

/// Neutral for all three thrusters.
pub const NEUTRAL: Command = Command::Go {
    port_us: 1500,
    vertical_us: 1500,
    starboard_us: 1500,
};

/// Runs the vehicle until `shutdown` resolves.
pub async fn run(
    mut settings: Settings,
    shutdown: impl Future<Output = ()>,
) -> Result<(), AppError> {
    std::fs::create_dir_all(&settings.data_dir).map_err(|source| AppError::DataDir {
        path: settings.data_dir.clone(),
        source,
    })?;
    let board = match &settings.board {
        BoardSource::Simulated(opts) => {
            let board = PtyBoard::spawn(opts.clone(), None)?;
            tracing::info!(pty = %board.path().display(), "simulation: board emulator on a pseudo-terminal");
            settings.link.device = board.path().to_path_buf();
            Some(board)
        }
        BoardSource::Serial => {
            link::probe(&settings.link)?;
            None
        }
    };

    // Parameters: a corrupt file is set aside and defaults apply, loudly.
    let param_file = ParamFile::new(&settings.data_dir);
    let (mut store, warnings) = param_file.load();
    for w in &warnings {
        tracing::warn!("parameters: {w}");
    }
    if let Some(sysid) = settings.mavlink.sysid
        && let Err(e) = store.set("SYSID_THISMAV", f64::from(sysid))
    {
        tracing::warn!("configured sysid refused: {e}");
    }

    let (in_tx, mut inbound) = mpsc::channel(4096);
    let router_cfg = RouterConfig {
        peer_timeout: settings.mavlink.peer_timeout,
        tlog: Some(TlogConfig {
            dir: settings.data_dir.join("tlogs"),
            max_bytes: settings.mavlink.tlog_max_bytes,
        }),
    };
    let router = Router::start(settings.mavlink.endpoints.clone(), router_cfg, in_tx).await?;
    for (i, spec) in settings.mavlink.endpoints.iter().enumerate() {
        tracing::info!(endpoint = %spec, local = ?router.local_addr(i), "MAVLink endpoint");
    }

    let (link, mut events) = link::spawn(settings.link.clone());
    // Profiles are checked before anything moves: a bad file is a clear error at start.
    let profiles = match &settings.profiles_dir {
        Some(dir) => crate::vehicle::input::Profiles::load_dir(dir)?,
        None => crate::vehicle::input::Profiles::builtin(),
    };
    let mut vehicle = Vehicle::new(
        settings.mavlink.identity,
        store,
        settings.mavlink.endpoints.len(),
    )
    .with_profiles(profiles);
    let t0 = Instant::now();
    let clock = move || Now {
        mono: t0.elapsed(),
        unix_us: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_micros() as u64),
    };
    let mut io = Io {
        router: router.clone(),
        link: link.clone(),
        params: param_file,
        seq: 0,
        last_healthy: None,
    };
    let mut shutdown = std::pin::pin!(shutdown);
    let mut outputs = Vec::with_capacity(64);
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut report = tokio::time::interval_at(
        Instant::now() + Duration::from_secs(1),
        Duration::from_secs(5),
    );
    // On the simulator, its ground truth is published too (marked as such).
    let mut truth = board.as_ref().map(|b| b.control().subscribe());
    let mut nav = NavSample::default();
    let mut status = StatusSample::default();
    loop {
        let now = clock();
        tokio::select! {
            () = &mut shutdown => break,
            _ = tick.tick() => vehicle.handle(Input::Tick, now, &mut outputs),
            ev = events.recv() => match ev {
                None => break,
                Some(LinkEvent::State { state, reason }) => vehicle.handle(Input::Link { state, reason }, now, &mut outputs),
                Some(LinkEvent::Telemetry(ev)) => {
                    match &ev {
                        Event::Nav(n) => nav = merge_nav(nav, *n),
                        Event::Status(s) if s.vout_v.is_some() => status = s.clone(),
                        _ => {}
                    }
                    vehicle.handle(Input::Board(ev), now, &mut outputs);
                }
            },
            msg = inbound.recv() => match msg {
                None => break,
                Some(Inbound { endpoint, peer, frame }) => {
                    let from = Sender::new(endpoint, peer, frame.sysid, frame.compid);
                    let input = match (frame.unknown_command, &frame.msg) {
                        (Some(command), MavMessage::COMMAND_LONG(c)) => Input::UnknownCommand {
                            from,
                            command,
                            target_system: c.target_system,
                            target_component: c.target_component,
                        },
                        _ => Input::Mavlink { from, msg: frame.msg },
                    };
                    vehicle.handle(input, now, &mut outputs);
                }
            },
            changed = async {
                match truth.as_mut() {
                    Some(rx) => rx.changed().await,
                    None => std::future::pending().await,
                }
            } => {
                if changed.is_err() {
                    truth = None;
                } else if let Some(rx) = truth.as_mut() {
                    let s = rx.borrow_and_update().sim;
                    let t = SimTruth {
                        north_m: s.north_m,
                        east_m: s.east_m,
                        depth_m: s.depth_m,
                        heading_rad: s.heading_deg.to_radians(),
                        surge_mps: s.surge_mps,
                        sway_mps: s.sway_mps,
                        heave_mps: s.heave_mps,
                        yaw_rate_rps: s.yaw_rate_dps.to_radians(),
                    };
                    vehicle.handle(Input::SimTruth(t), now, &mut outputs);
                }
            }
            _ = report.tick() => {
                let s = link.stats();
                tracing::info!(
                    link = ?s.state,
                    armed = vehicle.armed(),
                    mode = crate::vehicle::machine::mode_name(vehicle.mode()),
                    heading_deg = nav.heading_deg.unwrap_or(f64::NAN),
                    depth_m = nav.depth_m.unwrap_or(f64::NAN),
                    voltage_v = status.vout_v.unwrap_or(f64::NAN),
                    telemetry_age_ms = s.telemetry_age_ms.unwrap_or(u64::MAX),
                    rejected = s.decode.rejected_total(),
                    crc_fail = s.crc_failures_echoed,
                    "telemetry"
                );
            }
        }
        io.apply(&mut outputs, &vehicle, now);
    }
    tracing::info!("shutting down: thrusters to neutral");
    link.send(NEUTRAL);
    // Give the link a moment to put the neutral command on the wire.
    tokio::time::sleep(Duration::from_millis(50)).await;
    drop(link);
    router.shutdown().await;
    if let Some(board) = board {
        board.shutdown().await;
    }
    Ok(())
}

fn route(to: To) -> Route {
    match to {
        To::All => Route::All,
        To::Endpoint(e) => Route::Endpoint(e),
        To::Peer(e, p) => Route::Peer(e, p),
    }
}

/// Carries the core's outputs to the router, the link and the parameter file.
struct Io {
    router: RouterHandle,
    link: link::LinkHandle,
    params: ParamFile,
    seq: u8,
    last_healthy: Option<Duration>,
}

impl Io {
    fn apply(&mut self, outputs: &mut Vec<Output>, vehicle: &Vehicle, now: Now) {
        for out in outputs.drain(..) {
            match out {
                Output::Send { to, msg } => {
                    let bytes = encode_v2(vehicle.sysid(), COMPONENT_ID, self.seq, &msg);
                    self.seq = self.seq.wrapping_add(1);
                    self.router.send(Outbound {
                        route: route(to),
                        bytes: bytes.into(),
                    });
                }
                Output::AckUnknown {
                    to,
                    command,
                    result,
                    target_system,
                    target_component,
                } => {
                    let bytes = encode_command_ack_raw(
                        vehicle.sysid(),
                        COMPONENT_ID,
                        self.seq,
                        command,
                        result,
                        target_system,
                        target_component,
                    );
                    self.seq = self.seq.wrapping_add(1);
                    self.router.send(Outbound {
                        route: route(to),
                        bytes: bytes.into(),
                    });
                }
                Output::Board(cmd) => self.link.send(cmd),
                Output::Log(ev) => {
                    tracing::info!(event = ev.kind, sysid = ?ev.sysid, "{}", ev.detail)
                }
                Output::SetSigningKey { .. } => {}
                Output::SaveParams => {
                    if let Err(e) = self.params.save(vehicle.params()) {
                        tracing::error!("parameters not saved: {e}");
                    }
                }
                Output::Healthy => {
                    // The link only needs to hear this every few hundred ms.
                    if self
                        .last_healthy
                        .is_none_or(|t| now.mono.saturating_sub(t) >= Duration::from_millis(100))
                    {
                        self.last_healthy = Some(now.mono);
                        self.link.healthy();
                    }
                }
            }
        }
    }
}

fn merge_nav(old: NavSample, new: NavSample) -> NavSample {
    NavSample {
        heading_deg: new.heading_deg.or(old.heading_deg),
        depth_m: new.depth_m.or(old.depth_m),
        pitch_deg: new.pitch_deg.or(old.pitch_deg),
        roll_deg: new.roll_deg.or(old.roll_deg),
        yaw_deg: new.yaw_deg.or(old.yaw_deg),
        fthr_pct: new.fthr_pct.or(old.fthr_pct),
    }
}

/// `neptunus emulate-board`: runs the emulator until `shutdown`, printing the
/// device path through `announce`.
pub async fn emulate_board(
    opts: crate::firmware::emulator::EmulatorOptions,
    symlink: Option<std::path::PathBuf>,
    announce: impl FnOnce(&std::path::Path),
    shutdown: impl Future<Output = ()>,
) -> Result<(), AppError> {
    let board = PtyBoard::spawn(opts, symlink)?;
    announce(board.path());
    shutdown.await;
    board.shutdown().await;
    Ok(())
}
