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
use crate::eventlog::{EventLog, EventLogConfig, EventLogError, LogEvent};
use crate::firmware::codec::{Command, Event, NavSample, StatusSample};
use crate::firmware::emulator::EmulatorOptions;
use crate::firmware::emulator::PtyBoard;
use crate::firmware::link::{self, LinkError, LinkEvent};
use crate::firmware::loopback::LoopbackBoard;
use crate::mavlink::endpoint::{
    EndpointError, Inbound, Outbound, Route, Router, RouterConfig, RouterHandle,
};
use crate::mavlink::frame::{Frame, Undecodable, encode_command_ack_raw, encode_v2};
use crate::mavlink::signing::{
    REPLAY_RESERVATION_AHEAD, ReplayState, Signer, SigningError, SigningKey, SigningStore, Verdict,
    Verifier, timestamp_from_unix_us,
};
use crate::mavlink::tlog::TlogConfig;
use crate::vehicle::machine::{
    COMPONENT_ID, Input, Now, Output, RunMode, Sender, SimTruth, To, Vehicle,
};
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
    #[error("event log: {0}")]
    EventLog(#[from] EventLogError),
    #[error("message signing: {0}")]
    Signing(#[from] SigningError),
    #[error(transparent)]
    Hmi(#[from] crate::hmi::HmiError),
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
    // A broken data directory (read-only, full, a file in the way) must not
    // keep the vehicle from running: parameters then live in memory, logs
    // are lost, and every such problem is loud and shown in SYS_STATUS.
    let mut storage_problems: Vec<String> = Vec::new();
    if let Err(source) = std::fs::create_dir_all(&settings.data_dir) {
        let e = AppError::DataDir {
            path: settings.data_dir.clone(),
            source,
        };
        tracing::error!(
            "{e} — running without storage: parameters changes are kept in memory only, logs are lost (fix the directory, or pass another --data-dir)"
        );
        storage_problems.push(e.to_string());
    }
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
    match param_file.remove_stale_tmp() {
        Ok(true) => tracing::warn!(
            "removed {} left by an interrupted save (params.toml is intact)",
            param_file.tmp_path().display()
        ),
        Ok(false) => {}
        Err(e) if storage_problems.is_empty() => {
            tracing::warn!("cannot remove {}: {e}", param_file.tmp_path().display())
        }
        Err(_) => {}
    }
    if storage_problems.is_empty()
        && let Err(e) = probe_writable(&settings.data_dir)
    {
        tracing::error!(
            "data directory {} is not writable ({e}): parameter changes will be kept in memory only and reported as not saved until it is",
            settings.data_dir.display()
        );
        storage_problems.push(format!(
            "data directory {} not writable: {e}",
            settings.data_dir.display()
        ));
    }
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
            total_bytes: settings.mavlink.tlog_total_bytes,
        }),
    };
    let specs = settings
        .mavlink
        .endpoints
        .iter()
        .map(|u| u.spec.clone())
        .collect();
    let trusted: Vec<bool> = settings
        .mavlink
        .endpoints
        .iter()
        .map(|u| u.trusted)
        .collect();
    // Without a writable tlog folder the router runs without a tlog (it
    // says so); the vehicle shows it as a storage problem.
    let router = Router::start(specs, router_cfg, in_tx).await?;
    if let Some(e) = router.tlog_error() {
        storage_problems.push(format!("telemetry log: {e}"));
    }
    for (i, spec) in settings.mavlink.endpoints.iter().enumerate() {
        tracing::info!(endpoint = %spec, local = ?router.local_addr(i), "MAVLink endpoint");
    }

    let (link, mut events) = link::spawn(settings.link.clone());
    // Profiles are checked before anything moves: a bad file is a clear error at start.
    let profiles = match &settings.profiles_dir {
        Some(dir) => crate::vehicle::input::Profiles::load_dir(dir)?,
        None => crate::vehicle::input::Profiles::builtin(),
    };
    // HMI: one more endpoint after the MAVLink ones, for the browser sessions.
    let hmi_ep = settings.mavlink.endpoints.len();
    let hmi_profiles = profiles.clone();
    let mut vehicle = Vehicle::new(settings.mavlink.identity, store, hmi_ep + 1)
        .with_profiles(profiles)
        .with_hmi_sysids(settings.hmi.sysid_min, settings.hmi.sysid_max);
    let (event_log, log_problem) =
        EventLog::start_or_degraded(EventLogConfig::new(settings.data_dir.join("events")));
    if let Some(e) = log_problem {
        tracing::error!(
            "event log: {e} — events are lost until it can be written (retried at every event)"
        );
        storage_problems.push(format!("event log: {e}"));
    }
    let (signing, fail_closed) = match LinkSigning::load(SigningStore::new(&settings.data_dir)) {
        Ok(s) => (s, false),
        Err(e) => {
            // A data directory that cannot hold a file holds no key either.
            let no_key = matches!(&e, AppError::Signing(SigningError::Read { source, .. })
                if matches!(source.kind(), std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory));
            if no_key {
                tracing::warn!("message signing off: {e}");
            } else {
                // A key may exist that we cannot read: never run open. Only
                // signed traffic may control, and nothing can be signed, so
                // MAVLink stations watch; the browser HMI still controls.
                tracing::error!(
                    "message signing key unusable: {e} — MAVLink ground stations may only watch until it is fixed; the browser HMI can still control after the pilot login"
                );
            }
            (
                LinkSigning::unkeyed(SigningStore::new(&settings.data_dir)),
                !no_key,
            )
        }
    };
    vehicle.set_signing_active(signing.active() || fail_closed);
    if signing.active() {
        tracing::info!(
            "message signing on: unsigned MAVLink stations may watch but not control; browser \
             (HMI) sessions may control only after the pilot login; a signed frame is accepted \
             once (replays refused, also across restarts; after an unclean stop a station's \
             signed frames may be refused for up to {} s)",
            REPLAY_RESERVATION_AHEAD / 100_000
        );
    } else {
        tracing::warn!(
            "message signing off: any station that can reach a MAVLink endpoint and uses an \
             allowed system id (SYSID_MYGCS, NEPT_GCS_ALLOWn) may control the vehicle — set a \
             key with `neptunus signing set-passphrase` on untrusted links"
        );
    }
    if !storage_problems.is_empty() {
        vehicle.set_storage_problem(Some(storage_problems.join("; ")));
    }
    let t0 = Instant::now();
    let clock = move || Now {
        mono: t0.elapsed(),
        unix_us: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_micros() as u64),
    };
    // The camera: its picture follows the vehicle (the synthetic source draws it).
    let (scene_tx, scene_rx) = tokio::sync::watch::channel(crate::camera::Scene::default());
    let camera = crate::camera::Camera::start(settings.camera.clone(), scene_rx);
    let mut last_scene: Option<Duration> = None;
    let z_centered = crate::hmi::z_centered_by(hmi_profiles);
    let hmi_dir = settings.data_dir.clone();
    let mut hmi = crate::hmi::Hmi::start(
        &settings.hmi,
        hmi_ep,
        vehicle.sysid(),
        z_centered,
        hmi_dir,
        Some(camera.routes()),
    )
    .await?;
    let (saved_tx, mut saved_rx) = mpsc::unbounded_channel();
    let saver = ParamSaver::spawn(param_file, saved_tx);
    let mut io = Io {
        hmi: hmi.outlet(),
        router: router.clone(),
        link: link.clone(),
        params: saver,
        seq: 0,
        last_healthy: None,
        events: event_log.clone(),
        signing,
        simulator: None,
        simulator_opts: settings.simulator.clone(),
    };
    let mut sim_events = Vec::new();
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
        // Time is read when an input is handled, not when the wait began: a
        // tick or a datagram must not carry a time up to a tick period old.
        tokio::select! {
            () = &mut shutdown => break,
            _ = tick.tick() => {
                let now = clock();
                // The built-in simulator (run mode SIMULATOR) runs on the same tick.
                if let Some(sim) = io.simulator.as_mut() {
                    sim.advance(now.mono, &mut sim_events);
                    let truth = sim_truth(&sim.snapshot().sim);
                    for ev in sim_events.drain(..) {
                        vehicle.handle(Input::SimBoard(ev), now, &mut outputs);
                    }
                    vehicle.handle(Input::SimTruth(truth), now, &mut outputs);
                }
                vehicle.handle(Input::Tick, now, &mut outputs);
                if last_scene.is_none_or(|t| now.mono.saturating_sub(t) >= Duration::from_millis(50)) {
                    last_scene = Some(now.mono);
                    scene_tx.send_replace(scene(&vehicle, now));
                }
            }
            input = hmi.recv() => vehicle.handle(input, clock(), &mut outputs),
            Some(result) = saved_rx.recv() => {
                vehicle.handle(Input::ParamsSaved(result), clock(), &mut outputs);
            }
            ev = events.recv() => match ev {
                None => break,
                Some(LinkEvent::State { state, reason }) => vehicle.handle(Input::Link { state, reason }, clock(), &mut outputs),
                Some(LinkEvent::Telemetry(ev)) => {
                    match &ev {
                        Event::Nav(n) => nav = merge_nav(nav, *n),
                        Event::Status(s) if s.vout_v.is_some() => status = s.clone(),
                        _ => {}
                    }
                    vehicle.handle(Input::Board(ev), clock(), &mut outputs);
                }
            },
            msg = inbound.recv() => match msg {
                None => break,
                Some(Inbound { endpoint, peer, frame, standing }) => {
                    let now = clock();
                    let Some(signed) = io.signing.check(&frame, now, &event_log) else {
                        continue;
                    };
                    let from = Sender {
                        signed,
                        trusted: trusted.get(endpoint).copied().unwrap_or(false),
                        ..Sender::new(endpoint, peer, frame.sysid, frame.compid)
                    };
                    let input = match (frame.undecodable, &frame.msg) {
                        (None, _) => Input::Mavlink { from, msg: frame.msg },
                        (Some(Undecodable::Command(command)), MavMessage::COMMAND_LONG(c)) => Input::UnknownCommand {
                            from,
                            command,
                            target_system: c.target_system,
                            target_component: c.target_component,
                        },
                        (Some(Undecodable::ParamType(param_type)), MavMessage::PARAM_SET(p)) => Input::BadParamSet {
                            from,
                            target_system: p.target_system,
                            target_component: p.target_component,
                            param_id: p.param_id.into(),
                            param_type,
                        },
                        // A placeholder is never handed on as a real message.
                        (Some(_), _) => continue,
                    };
                    vehicle.handle(input, now, &mut outputs);
                    // The router keeps a slot (and the tlog) for peers that
                    // carry a station that may control. Sticky for the
                    // peer's life: frames spoofed from its address must not
                    // get it evicted.
                    if !standing.may_control()
                        && vehicle.may_control(from)
                        && standing.set_may_control(true)
                    {
                        tracing::debug!(endpoint, peer, sysid = from.sysid, "peer carries a station that may control");
                    }
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
                    let t = sim_truth(&rx.borrow_and_update().sim);
                    // In SIMULATOR run mode the built-in simulator's truth counts.
                    if io.simulator.is_none() {
                        vehicle.handle(Input::SimTruth(t), clock(), &mut outputs);
                    }
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
        io.apply(&mut outputs, &vehicle, clock());
    }
    tracing::info!("shutting down: thrusters to neutral");
    link.send(NEUTRAL);
    // Changes acknowledged but not yet on disk (the debounce, a save in
    // flight, a failing disk) get one last try.
    let unsaved = vehicle.params_unsaved().then(|| vehicle.params().clone());
    let saver = std::mem::replace(&mut io.params, ParamSaver::stopped());
    let _ = tokio::task::spawn_blocking(move || saver.finish(unsaved)).await;
    // Give the link a moment to put the neutral command on the wire.
    tokio::time::sleep(Duration::from_millis(50)).await;
    drop(link);
    hmi.shutdown().await;
    camera.shutdown().await;
    router.shutdown().await;
    io.signing.persist();
    let _ = tokio::task::spawn_blocking(move || event_log.shutdown()).await;
    if let Some(board) = board {
        board.shutdown().await;
    }
    Ok(())
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
        tilt_deg: (f64::from(v.tilt_us()) - 1500.0) / 500.0 * 90.0,
        simulated: v.run_mode() == RunMode::Simulator,
        armed: v.armed(),
    }
}

fn sim_truth(s: &crate::firmware::emulator::SimSnapshot) -> SimTruth {
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

fn route(to: To) -> Route {
    match to {
        To::All => Route::All,
        To::Endpoint(e) => Route::Endpoint(e),
        To::Peer(e, p) => Route::Peer(e, p),
    }
}

/// Carries the core's outputs to the router, the link and the parameter file.
struct Io {
    hmi: crate::hmi::Outlet,
    router: RouterHandle,
    link: link::LinkHandle,
    params: ParamSaver,
    seq: u8,
    last_healthy: Option<Duration>,
    events: EventLog,
    signing: LinkSigning,
    /// The built-in simulator while the run mode is SIMULATOR.
    simulator: Option<LoopbackBoard>,
    simulator_opts: EmulatorOptions,
}

impl Io {
    fn apply(&mut self, outputs: &mut Vec<Output>, vehicle: &Vehicle, now: Now) {
        for out in outputs.drain(..) {
            match out {
                Output::Send { to, msg } => {
                    self.hmi.deliver(to, &msg);
                    if self.hmi.only_hmi(to) {
                        continue;
                    }
                    let mut bytes = encode_v2(vehicle.sysid(), COMPONENT_ID, self.seq, &msg);
                    self.seq = self.seq.wrapping_add(1);
                    self.signing.sign(&mut bytes, now);
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
                    let mut bytes = encode_command_ack_raw(
                        vehicle.sysid(),
                        COMPONENT_ID,
                        self.seq,
                        command,
                        result,
                        target_system,
                        target_component,
                    );
                    self.seq = self.seq.wrapping_add(1);
                    self.signing.sign(&mut bytes, now);
                    self.router.send(Outbound {
                        route: route(to),
                        bytes: bytes.into(),
                    });
                }
                Output::Board(cmd) => self.link.send(cmd),
                Output::SimBoard(cmd) => {
                    if let Some(sim) = self.simulator.as_mut() {
                        sim.send(&cmd, now.mono);
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
                            let mut sim = LoopbackBoard::new(self.simulator_opts.clone(), now.mono);
                            let mut start = crate::sim::SimState::default();
                            start.eta[2] = start_depth_m;
                            start.eta[3] = start_heading_deg.to_radians();
                            sim.board_mut().set_sim_state(start);
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
                Output::Healthy => {
                    // The link only needs to hear this every few hundred ms.
                    if self
                        .last_healthy
                        .is_none_or(|t| now.mono.saturating_sub(t) >= Duration::from_millis(100))
                    {
                        self.last_healthy = Some(now.mono);
                        self.link.healthy();
                        if let Some(sim) = self.simulator.as_mut() {
                            sim.send(&crate::firmware::codec::Command::Ping(0), now.mono);
                        }
                    }
                }
            }
        }
    }
}

/// Writes `params.toml` on its own thread, so a slow or failing disk never
/// stalls the vehicle task; each result goes back to the core. The core asks
/// for one save at a time, so the queue never holds more than one.
struct ParamSaver {
    tx: Option<std::sync::mpsc::Sender<crate::vehicle::params::ParamStore>>,
    thread: Option<std::thread::JoinHandle<ParamFile>>,
    /// Where results go; also used to answer at once when there is no thread.
    results: Option<mpsc::UnboundedSender<Result<(), String>>>,
}

impl ParamSaver {
    fn spawn(file: ParamFile, results: mpsc::UnboundedSender<Result<(), String>>) -> Self {
        let (tx, rx) = std::sync::mpsc::channel::<crate::vehicle::params::ParamStore>();
        let thread_results = results.clone();
        let thread = std::thread::Builder::new()
            .name("neptunus-params".into())
            .spawn(move || {
                for store in rx {
                    let result = file.save(&store).map_err(|e| {
                        tracing::error!("parameters not saved: {e}");
                        e.to_string()
                    });
                    if result.is_ok() {
                        tracing::debug!(path = %file.path().display(), "parameters saved");
                    }
                    let _ = thread_results.send(result);
                }
                file
            });
        match thread {
            Ok(thread) => Self {
                tx: Some(tx),
                thread: Some(thread),
                results: Some(results),
            },
            Err(e) => {
                tracing::error!(
                    "cannot start the parameter saver thread: {e}; parameters will not be saved"
                );
                Self {
                    results: Some(results),
                    ..Self::stopped()
                }
            }
        }
    }

    fn stopped() -> Self {
        Self {
            tx: None,
            thread: None,
            results: None,
        }
    }

    /// Queues a save; without a saver thread the core hears at once that
    /// it failed (and tells the stations).
    fn save(&self, store: crate::vehicle::params::ParamStore) {
        let sent = self.tx.as_ref().is_some_and(|tx| tx.send(store).is_ok());
        if !sent && let Some(results) = &self.results {
            let _ = results.send(Err("the parameter saver thread is not running".into()));
        }
    }

    /// Blocking: waits for the save in flight, then writes `last` if given.
    fn finish(mut self, last: Option<crate::vehicle::params::ParamStore>) {
        self.tx = None;
        let file = self.thread.take().and_then(|t| t.join().ok());
        if let (Some(file), Some(store)) = (file, last) {
            match file.save(&store) {
                Ok(()) => tracing::info!("unsaved parameter changes saved at shutdown"),
                Err(e) => tracing::error!("parameter changes lost at shutdown: {e}"),
            }
        }
    }
}

/// Creates and removes a file in `dir`: true writability (permission bits
/// say nothing for root, nor for a read-only mount).
fn probe_writable(dir: &std::path::Path) -> std::io::Result<()> {
    let probe = dir.join(".neptunus-write-probe");
    std::fs::write(&probe, b"")?;
    std::fs::remove_file(&probe)
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

/// Signature checks on what comes in, signatures on what goes out, and the
/// key, timestamp and replay files behind them. The vehicle core decides
/// policy from the per-frame result; this only verifies, signs and persists.
struct LinkSigning {
    store: SigningStore,
    keyed: Option<(Verifier, Signer)>,
    /// Floor for a new key's timestamps: ours never go backwards.
    last_timestamp: u64,
    /// Incoming replay state loaded at start, for the first verifier (a key
    /// set later by SETUP_SIGNING inherits the running verifier's state).
    replay: ReplayState,
    rejected: u64,
    last_report: Option<Duration>,
    /// When a replay reservation last failed to be written (logged at most this often).
    last_replay_error: Option<Duration>,
}

/// Rejected signatures are logged at most this often.
const SIGNATURE_REPORT: Duration = Duration::from_secs(5);

impl LinkSigning {
    /// No key and no replay state: signing off, or a key we cannot read
    /// (then the core is told signing is on, and nothing verifies).
    fn unkeyed(store: SigningStore) -> Self {
        Self {
            store,
            keyed: None,
            last_timestamp: 0,
            replay: ReplayState::default(),
            rejected: 0,
            last_report: None,
            last_replay_error: None,
        }
    }

    fn load(store: SigningStore) -> Result<Self, AppError> {
        let key = store.load_key()?;
        let reservation = store.load_reservation();
        // Loaded without a key too: a key set later by SETUP_SIGNING may be
        // the one frames were recorded under.
        let replay = load_replay(&store, key.is_some());
        let mut s = Self {
            store,
            keyed: None,
            last_timestamp: reservation.unwrap_or(0),
            replay,
            rejected: 0,
            last_report: None,
            last_replay_error: None,
        };
        if let Some(key) = key {
            s.keyed = Some(s.pair(key));
        }
        Ok(s)
    }

    fn pair(&self, key: SigningKey) -> (Verifier, Signer) {
        let reservation = self.store.load_reservation().max(Some(self.last_timestamp));
        // Frames accepted under the old key stay refused under the new one.
        let replay = match &self.keyed {
            Some((verifier, _)) => verifier.replay_state(),
            None => self.replay.clone(),
        };
        (
            Verifier::with_replay_state(key.clone(), &replay),
            Signer::new(key, 0, reservation),
        )
    }

    fn active(&self) -> bool {
        self.keyed.is_some()
    }

    /// Some(signed) for a frame to hand to the vehicle, None for one to drop.
    fn check(&mut self, frame: &Frame, now: Now, events: &EventLog) -> Option<bool> {
        let Some((verifier, _)) = self.keyed.as_mut() else {
            return Some(false);
        };
        let why = match verifier.check(&frame.raw, timestamp_from_unix_us(now.unix_us)) {
            Verdict::Valid { .. } => {
                // Write-ahead: the reservation is on disk before the frame acts.
                if let Some(state) = verifier.take_reservation()
                    && let Err(e) = self.store.save_replay(&state)
                    && self
                        .last_replay_error
                        .is_none_or(|t| now.mono.saturating_sub(t) >= SIGNATURE_REPORT)
                {
                    // Refusing the frame would cost the pilot control of the
                    // vehicle whenever the disk fails; accepting it weakens
                    // only replay protection across a restart. Say so.
                    self.last_replay_error = Some(now.mono);
                    tracing::error!(
                        "{e}; signed frames are still accepted, but frames accepted since the \
                         last successful write could be replayed after a restart"
                    );
                }
                return Some(true);
            }
            Verdict::Unsigned => return Some(false),
            Verdict::BadSignature => "bad signature",
            Verdict::Replayed => {
                "replayed (timestamp not newer than the last of its stream, in this run or before a restart)"
            }
            Verdict::TooOld => "stale timestamp (more than 1 min old)",
            Verdict::Malformed => "malformed signature",
        };
        self.rejected += 1;
        if self
            .last_report
            .is_none_or(|t| now.mono.saturating_sub(t) >= SIGNATURE_REPORT)
        {
            self.last_report = Some(now.mono);
            let detail = format!(
                "msg {} from {}/{}: {why} ({} rejected)",
                frame.msg_id, frame.sysid, frame.compid, self.rejected
            );
            tracing::warn!("signature rejected: {detail}");
            events.record(
                now.unix_us,
                now.mono,
                &LogEvent::new("signature_rejected", Some(frame.sysid), detail),
            );
        }
        None
    }

    fn sign(&mut self, bytes: &mut Vec<u8>, now: Now) {
        let Some((_, signer)) = self.keyed.as_mut() else {
            return;
        };
        if let Some(reservation) = signer.sign(bytes, timestamp_from_unix_us(now.unix_us))
            && let Err(e) = self.store.save_reservation(reservation)
        {
            tracing::error!("signing timestamp not saved: {e}");
        }
        self.last_timestamp = signer.last_timestamp();
    }

    fn set_key(&mut self, key: [u8; 32], initial_timestamp: u64) -> Result<(), SigningError> {
        match SigningKey::from_bytes(key) {
            None => {
                self.store.save_key(None)?;
                if let Some((verifier, _)) = &self.keyed {
                    self.replay = verifier.replay_state();
                }
                self.keyed = None;
            }
            Some(key) => {
                self.store.save_key(Some(&key))?;
                let (verifier, mut signer) = self.pair(key);
                signer.raise_floor(initial_timestamp);
                self.keyed = Some((verifier, signer));
            }
        }
        Ok(())
    }

    /// At shutdown: the timestamp in use, so the next start begins above it,
    /// and the exact last timestamp of every incoming stream, so a clean
    /// restart refuses replays without refusing any genuine frame.
    fn persist(&self) {
        let Some((verifier, signer)) = &self.keyed else {
            return;
        };
        if let Err(e) = self
            .store
            .save_reservation(signer.last_timestamp().saturating_add(1))
        {
            tracing::error!("signing timestamp not saved: {e}");
        }
        if let Err(e) = self.store.save_replay(&verifier.replay_state()) {
            tracing::error!("signing replay state not saved: {e}");
        }
    }
}

/// The incoming replay state persisted by the last run. Missing or corrupt:
/// start with the one-minute stale rule only, loudly, never refuse to start.
fn load_replay(store: &SigningStore, keyed: bool) -> ReplayState {
    match store.load_replay() {
        Ok(state) if !keyed => state.unwrap_or_default(),
        Err(_) if !keyed => ReplayState::default(),
        Ok(Some(state)) => {
            tracing::info!(
                path = %store.replay_path().display(),
                streams = state.len(),
                "signing replay state loaded: signed frames accepted before this start are refused"
            );
            state
        }
        Ok(None) => {
            tracing::warn!(
                path = %store.replay_path().display(),
                "no signing replay state (normal on the first start with a key): until a \
                 station's frames are seen, signed frames recorded before this start are \
                 refused only when more than 1 min old"
            );
            ReplayState::default()
        }
        Err(e) => {
            tracing::error!(
                "{e}. REPLAY PROTECTION ACROSS THE RESTART IS LOST: signed frames recorded \
                 before this start are refused only when more than 1 min old"
            );
            ReplayState::default()
        }
    }
}
