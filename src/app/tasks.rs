//! Starting the tasks around the vehicle, in order, and stopping them in
//! order: the board (real or emulated), the MAVLink endpoints, the serial
//! link, the event log, the camera (and its RTP video) and the browser HMI.

use tokio::sync::{mpsc, watch};
use tokio::time::{Duration, Instant, Interval};

use super::io::Io;
use super::params::ParamSaver;
use super::side::Side;
use super::signing::LinkSigning;
use super::vehicle_task::VehicleTask;
use super::{AppError, storage};
use crate::camera::webrtc::SignallingAddr;
use crate::config::{BoardSource, Settings};
use crate::eventlog::{EventLog, EventLogConfig};
use crate::firmware::emulator::{BoardSnapshot, PtyBoard, SimSnapshot};
use crate::firmware::link::{self, LinkEvent};
use crate::mavlink::endpoint::{Inbound, Router, RouterConfig, RouterHandle};
use crate::mavlink::tlog::TlogConfig;
use crate::vehicle::machine::Vehicle;

/// What the vehicle task waits on, and what is shut down after it.
pub(super) struct Tasks {
    /// The 5-s log line.
    pub(super) report: Interval,
    pub(super) hmi: crate::hmi::Hmi,
    pub(super) saved: mpsc::UnboundedReceiver<Result<(), String>>,
    pub(super) link_events: mpsc::Receiver<LinkEvent>,
    pub(super) inbound: mpsc::Receiver<Inbound>,
    /// The disk worker's answers to the file transfers.
    pub(super) file_replies: mpsc::UnboundedReceiver<crate::files::FileReply>,
    /// The simulated vehicle's ground truth (`--sim`, `--hil`); None on a
    /// real board.
    pub(super) truth: Option<TruthFeed>,
    camera: crate::camera::Camera,
    /// H.264 over RTP to ground stations; its
    /// [`stream`](crate::camera::rtp::RtpVideo::stream) is what the
    /// MAVLink camera component announces.
    pub(super) rtp: crate::camera::rtp::RtpVideo,
    /// The WebRTC viewers (Cockpit, the page), fed by the one H.264 stream.
    webrtc: Option<crate::camera::webrtc::WebRtc>,
    /// Recording on the vehicle, fed by the one H.264 stream.
    recorder: Option<crate::camera::record::Recorder>,
    /// What the recorder tells the core.
    pub(super) recorder_events: mpsc::UnboundedReceiver<crate::vehicle::machine::RecorderEvent>,
    router: RouterHandle,
    event_log: EventLog,
    board: Option<SimulatedBoard>,
    /// The browser side's thread (the HMI, the camera, the emulator).
    side: Side,
}

/// The simulated board behind the link's pseudo-terminal.
enum SimulatedBoard {
    /// `--sim`: the board emulator with the simulator inside.
    Emulator(PtyBoard),
    /// `--hil`: the genuine firmware in simavr, driving the simulator.
    #[cfg(feature = "hil")]
    Genuine(crate::hil::HilRov),
}

impl SimulatedBoard {
    fn truth(&self) -> TruthFeed {
        match self {
            Self::Emulator(b) => TruthFeed::Emulator(b.control().subscribe()),
            #[cfg(feature = "hil")]
            Self::Genuine(r) => TruthFeed::Genuine(r.truth()),
        }
    }

    async fn shutdown(self) {
        match self {
            Self::Emulator(b) => b.shutdown().await,
            // Its threads stop and are joined when dropped.
            #[cfg(feature = "hil")]
            Self::Genuine(r) => {
                let _ = tokio::task::spawn_blocking(move || drop(r)).await;
            }
        }
    }
}

/// Where the simulated vehicle's truth comes from.
pub(super) enum TruthFeed {
    Emulator(watch::Receiver<BoardSnapshot>),
    #[cfg_attr(not(feature = "hil"), allow(dead_code))]
    Genuine(watch::Receiver<SimSnapshot>),
}

/// Starts everything; the vehicle task is returned ready to run.
pub(super) async fn start(mut settings: Settings) -> Result<(Tasks, VehicleTask), AppError> {
    let mut storage_problems = storage::create_data_dir(&settings.data_dir);
    let side = Side::start().map_err(AppError::Side)?;
    let board = match &settings.board {
        BoardSource::Simulated(opts) => {
            let board = {
                let _side = side.handle().enter();
                PtyBoard::spawn(opts.clone(), None)?
            };
            tracing::info!(pty = %board.path().display(), "simulation: board emulator on a pseudo-terminal");
            settings.link.device = board.path().to_path_buf();
            Some(SimulatedBoard::Emulator(board))
        }
        BoardSource::Genuine { firmware, emulator } => {
            let (firmware, emulator) = (firmware.clone(), emulator.clone());
            Some(genuine_board(&firmware, &emulator, &mut settings).await?)
        }
        BoardSource::Serial => {
            link::probe(&settings.link)?;
            None
        }
    };
    let (param_file, store) = storage::load_params(
        &settings.data_dir,
        settings.mavlink.sysid,
        &mut storage_problems,
    );

    // The logs' clock: the system's, until the station in control sets it.
    let clock = crate::wallclock::WallClock::system();
    let (in_tx, inbound) = mpsc::channel(4096);
    let router_cfg = RouterConfig {
        peer_timeout: settings.mavlink.peer_timeout,
        tlog: Some(TlogConfig {
            dir: settings.data_dir.join("tlogs"),
            max_bytes: settings.mavlink.tlog_max_bytes,
            total_bytes: settings.mavlink.tlog_total_bytes,
            clock: clock.clone(),
        }),
    };
    let endpoints = &settings.mavlink.endpoints;
    let specs = endpoints.iter().map(|u| u.spec.clone()).collect();
    let trusted: Vec<bool> = endpoints.iter().map(|u| u.trusted).collect();
    // Without a writable tlog folder the router runs without a tlog (it
    // says so); the vehicle shows it as a storage problem.
    let router = Router::start(specs, router_cfg, in_tx).await?;
    if let Some(e) = router.tlog_error() {
        storage_problems.push(format!("telemetry log: {e}"));
    }
    for (i, spec) in endpoints.iter().enumerate() {
        tracing::info!(endpoint = %spec, local = ?router.local_addr(i), "MAVLink endpoint");
    }

    let (link, link_events) = link::spawn(settings.link.clone());
    // Profiles are checked before anything moves: a bad file is a clear error at start.
    let profiles = match &settings.profiles_dir {
        Some(dir) => crate::vehicle::input::Profiles::load_dir(dir)?,
        None => crate::vehicle::input::Profiles::builtin(),
    };
    // HMI: two more endpoints after the MAVLink ones, for the browser
    // sessions and for the mavlink2rest API (Cockpit).
    let hmi_ep = endpoints.len();
    let z_centered = crate::hmi::z_centered_by(profiles.clone());
    // Which way the video goes: a V4L2 camera is asked what it offers.
    let plan = crate::camera::plan::initial(&settings.camera);
    let mut vehicle = Vehicle::new(settings.mavlink.identity, store, hmi_ep + 2)
        .with_transfer_rates(transfer_rates(endpoints))
        .with_profiles(profiles)
        .with_hmi_sysids(settings.hmi.sysid_min, settings.hmi.sysid_max)
        .with_camera(camera_spec(&settings.camera, &plan))
        .with_wall_clock(
            crate::wallclock::system_sync(),
            crate::wallclock::BUILD_UNIX_S * 1_000_000,
        );
    let (event_log, log_problem) =
        EventLog::start_or_degraded(EventLogConfig::new(settings.data_dir.join("events")));
    if let Some(e) = log_problem {
        tracing::error!(
            "event log: {e} — events are lost until it can be written (retried at every event)"
        );
        storage_problems.push(format!("event log: {e}"));
    }
    let (signing, must_sign) = LinkSigning::start(&settings.data_dir);
    vehicle.set_signing_active(must_sign);
    if let Some(problem) = storage_problems.summary() {
        vehicle.set_storage_problem(Some(problem));
    }
    let t0 = Instant::now();
    let (recorder_tx, recorder_events) = mpsc::unbounded_channel();
    let recorder = start_recorder(&settings, &plan, &clock, t0, recorder_tx);
    let vehicle = vehicle.with_recording(recorder.is_some());
    // The camera: its picture follows the vehicle (the synthetic source draws it).
    let (scene_tx, scene_rx) = watch::channel(crate::camera::Scene::default());
    // It runs only while a browser watches or RTP video has a destination.
    let (video_to, station_rx) = watch::channel(None);
    let (camera, rtp, webrtc) = {
        let _side = side.handle().enter();
        let camera = crate::camera::Camera::start_on_demand_planned(
            settings.camera.clone(),
            scene_rx,
            plan.clone(),
        );
        let webrtc = start_webrtc(&settings, &plan);
        let taps = webrtc
            .as_ref()
            .map(crate::camera::webrtc::WebRtc::feed)
            .into_iter()
            .chain(recorder.as_ref().map(crate::camera::record::Recorder::feed))
            .collect();
        let rtp = crate::camera::rtp::RtpVideo::start(&settings.camera, &camera, station_rx, taps);
        (camera, rtp, webrtc)
    };
    let hmi = {
        let hmi_settings = settings.hmi.clone();
        let (sysid, data_dir) = (vehicle.sysid(), settings.data_dir.clone());
        let mut video = crate::hmi::VideoRoutes {
            routes: camera.routes(),
            webrtc: webrtc.is_some(),
            signalling: None,
            streams: None,
            info: Some(video_info(&camera, &rtp)),
        };
        if let Some(w) = &webrtc {
            video.routes = video.routes.merge(w.routes());
            let at = SignallingAddr::resolve(settings.camera.webrtc.signalling, settings.hmi.http);
            video.signalling = at.map(|addr| (addr, w.signalling_routes()));
            let streams = SignallingAddr::resolve_streams(settings.camera.webrtc.streams, at);
            video.streams =
                streams.map(|addr| (addr, w.streams_routes(rtp.stream(), rtp.running())));
        }
        side.handle()
            .spawn(async move {
                crate::hmi::Hmi::start(
                    &hmi_settings,
                    hmi_ep,
                    sysid,
                    z_centered,
                    data_dir,
                    Some(video),
                )
                .await
            })
            .await
            .map_err(|e| AppError::Side(std::io::Error::other(e.to_string())))??
    };
    if let Some(w) = &webrtc {
        w.set_beside_addrs(
            hmi.beside_addr(crate::hmi::BesideKind::Signalling),
            hmi.beside_addr(crate::hmi::BesideKind::Streams),
        );
    }
    let (saved_tx, saved) = mpsc::unbounded_channel();
    let (files_tx, file_replies) = mpsc::unbounded_channel();
    let files = crate::files::FileWorker::spawn(
        crate::files::WorkerConfig {
            data_dir: settings.data_dir.clone(),
            running: router.tlog_run(),
        },
        files_tx,
    )
    .map_err(AppError::Side)?;
    let io = Io::new(
        [hmi.outlet(), hmi.m2r_outlet()],
        router.clone(),
        link,
        ParamSaver::spawn(param_file, saved_tx),
        event_log.clone(),
        signing,
        files,
        settings.simulator.clone(),
    )
    .with_clock(clock)
    .with_recorder(
        recorder
            .as_ref()
            .map(crate::camera::record::Recorder::handle),
    );
    let report = tokio::time::interval_at(
        Instant::now() + Duration::from_secs(1),
        Duration::from_secs(5),
    );
    // On the emulator, its ground truth is published too (marked as such).
    let truth = board.as_ref().map(SimulatedBoard::truth);
    let watched = camera.watched();
    let tasks = Tasks {
        report,
        hmi,
        saved,
        link_events,
        inbound,
        file_replies,
        truth,
        camera,
        rtp,
        webrtc,
        recorder,
        recorder_events,
        router,
        event_log,
        board,
        side,
    };
    let vt = VehicleTask::new(vehicle, io, t0, scene_tx, watched, trusted, video_to);
    Ok((tasks, vt))
}

/// Bytes per second file transfers may use over each endpoint: the
/// network's rate over UDP and TCP, half the line over a serial port (the
/// rest stays for telemetry and control), none over the two in-process
/// endpoints after them (the browser sessions have `/api/logs`).
fn transfer_rates(endpoints: &[crate::mavlink::endpoint::EndpointUrl]) -> Vec<u32> {
    use crate::mavlink::EndpointSpec as E;
    use crate::vehicle::machine::NETWORK_RATE;
    let mut rates: Vec<u32> = endpoints
        .iter()
        .map(|e| match &e.spec {
            E::Serial { baud, .. } => baud / 10 / 2,
            E::UdpIn(_) | E::UdpOut(_) | E::TcpIn(_) | E::TcpOut(_) => NETWORK_RATE,
        })
        .collect();
    rates.extend([0, 0]);
    rates
}

/// The simulated vehicle's next ground truth; never, on a real board (or
/// once the simulation has gone).
pub(super) async fn board_truth(truth: &mut Option<TruthFeed>) -> SimSnapshot {
    loop {
        let next = match truth.as_mut() {
            None => return std::future::pending().await,
            Some(TruthFeed::Emulator(rx)) => match rx.changed().await {
                Ok(()) => Some(rx.borrow_and_update().sim),
                Err(_) => None,
            },
            Some(TruthFeed::Genuine(rx)) => match rx.changed().await {
                Ok(()) => Some(*rx.borrow_and_update()),
                Err(_) => None,
            },
        };
        match next {
            Some(s) => return s,
            None => *truth = None,
        }
    }
}

/// `--hil`: builds (or finds in the data directory's cache) the firmware,
/// powers the genuine board in simavr with the simulator around it, and
/// points the link at its pty with the firmware's framing.
#[cfg(feature = "hil")]
async fn genuine_board(
    firmware: &std::path::Path,
    emulator: &crate::firmware::emulator::EmulatorOptions,
    settings: &mut Settings,
) -> Result<SimulatedBoard, AppError> {
    let cache = settings.data_dir.join("openrov-firmware");
    let source = firmware.to_path_buf();
    tracing::info!(firmware = %source.display(), "hardware in the loop: preparing the genuine firmware (built once, then cached)");
    let built = tokio::task::spawn_blocking(move || crate::hil::prepare(&source, &cache))
        .await
        .map_err(|e| AppError::Hil(e.to_string()))?
        .map_err(|e| AppError::Hil(e.to_string()))?;
    settings.link.framing = built.framing;
    let rov =
        crate::hil::HilRov::spawn(built, emulator).map_err(|e| AppError::Hil(e.to_string()))?;
    tracing::info!(
        pty = %rov.board().path().display(),
        elf = %rov.board().firmware().elf.display(),
        framing = %settings.link.framing,
        "hardware in the loop: the genuine firmware in simavr on a pseudo-terminal"
    );
    settings.link.device = rov.board().path().to_path_buf();
    Ok(SimulatedBoard::Genuine(rov))
}

#[cfg(not(feature = "hil"))]
async fn genuine_board(
    _firmware: &std::path::Path,
    _emulator: &crate::firmware::emulator::EmulatorOptions,
    _settings: &mut Settings,
) -> Result<SimulatedBoard, AppError> {
    Err(AppError::Hil(crate::config::hil_not_built(
        "--hil FIRMWARE",
    )))
}

impl Tasks {
    /// Thrusters to neutral, unsaved parameters saved, then every task
    /// stopped in order.
    pub(super) async fn shutdown(
        self,
        mut vehicle_task: VehicleTask,
        notify: &mut super::notify::Notify,
    ) {
        tracing::info!("shutting down: thrusters to neutral");
        let written = vehicle_task.io.link.subscribe();
        let before = written.borrow().thrust_written;
        vehicle_task.io.neutral();
        // Changes acknowledged but not yet on disk (the debounce, a save in
        // flight, a failing disk) get one last try.
        let vehicle = &vehicle_task.vehicle;
        let unsaved = vehicle.params_unsaved().then(|| vehicle.params().clone());
        let saver = std::mem::replace(&mut vehicle_task.io.params, ParamSaver::stopped());
        let _ = tokio::task::spawn_blocking(move || saver.finish(unsaved)).await;
        // Give the link a moment to put the neutral command on the wire
        // (at once when the board is up; a link that is down never will).
        neutral_written(written, before).await;
        notify.stopping();
        self.hmi.shutdown().await;
        if let Some(w) = self.webrtc {
            w.shutdown().await;
        }
        // A recording ends synced, before its video stops.
        if let Some(r) = self.recorder {
            let _ = tokio::task::spawn_blocking(move || r.shutdown()).await;
        }
        self.rtp.shutdown().await;
        self.camera.shutdown().await;
        self.router.shutdown().await;
        let mut files = vehicle_task.io.files;
        let _ = tokio::task::spawn_blocking(move || files.stop()).await;
        vehicle_task.io.signing.persist();
        let event_log = self.event_log;
        let _ = tokio::task::spawn_blocking(move || event_log.shutdown()).await;
        if let Some(board) = self.board {
            board.shutdown().await;
        }
        self.side.stop().await;
    }
}

/// Waits until the link has written a thruster command after `before`
/// (the neutral one: nothing else is sent after it), at most 200 ms, then
/// until the board has echoed it (it took it) or its echo timed out.
async fn neutral_written(
    mut stats: watch::Receiver<crate::firmware::link::LinkStats>,
    before: u64,
) {
    let wait = stats.wait_for(|s| s.thrust_written > before);
    if tokio::time::timeout(Duration::from_millis(200), wait)
        .await
        .is_err()
    {
        tracing::warn!("the neutral command was not written within 200 ms (board link down?)");
        return;
    }
    // The figures that showed it written were published after the write:
    // none in flight there means the board has taken it already.
    let taken = stats.wait_for(|s| s.thrust_unechoed == 0);
    let within =
        crate::firmware::link::LinkConfig::new("").echo_timeout + Duration::from_millis(200);
    if tokio::time::timeout(within, taken).await.is_err() {
        tracing::warn!("the board did not echo the neutral command (busy or gone?)");
    }
}

/// The WebRTC viewers' side, when the camera gives a picture, WebRTC is
/// on and the HMI (which serves the signalling) runs.
fn start_webrtc(
    settings: &Settings,
    plan: &crate::camera::VideoPlan,
) -> Option<crate::camera::webrtc::WebRtc> {
    use crate::camera::webrtc;
    let cfg = &settings.camera;
    if !cfg.webrtc.enabled {
        tracing::info!("WebRTC video off (--webrtc off)");
        return None;
    }
    let Some(stream) = webrtc::stream_of(cfg, plan, webrtc::new_stream_id()) else {
        if cfg.source != crate::camera::SourceKind::None {
            tracing::info!("WebRTC video off: no H.264 — {}", plan.why);
        }
        return None;
    };
    if settings.hmi.http.is_none() {
        tracing::info!(
            "WebRTC video off: its signalling is served with the browser HMI (--http off)"
        );
        return None;
    }
    Some(webrtc::WebRtc::start(&cfg.webrtc, Some(stream)))
}

/// Recording on the vehicle, when there is a camera: its own thread, fed
/// by the one H.264 stream; None (and the camera cannot record) when its
/// thread cannot be started.
fn start_recorder(
    settings: &Settings,
    plan: &crate::camera::VideoPlan,
    clock: &std::sync::Arc<crate::wallclock::WallClock>,
    t0: Instant,
    events: mpsc::UnboundedSender<crate::vehicle::machine::RecorderEvent>,
) -> Option<crate::camera::record::Recorder> {
    use crate::camera::record::{RecordConfig, Recorder};
    camera_spec(&settings.camera, plan)?;
    let cfg = RecordConfig {
        data_dir: settings.data_dir.clone(),
        storage: settings.storage,
        clock: clock.clone(),
        vehicle_t0: t0.into_std(),
    };
    match Recorder::start(cfg, events) {
        Ok(r) => Some(r),
        Err(e) => {
            tracing::error!("recording on the vehicle is off: {e}");
            None
        }
    }
}

/// What `GET /api/video` adds: the paths (the plan as it is now), whether
/// `/video.mjpg` has pictures, and what the H.264 sender runs.
fn video_info(
    camera: &crate::camera::Camera,
    rtp: &crate::camera::rtp::RtpVideo,
) -> crate::hmi::VideoInfo {
    let plan = camera.plan();
    let running = rtp.running();
    let status = camera.status_handle();
    std::sync::Arc::new(move || {
        crate::camera::api_json(&plan.borrow(), *running.borrow(), status().h264_profile)
    })
}

/// The MAVLink camera component exists when a camera source is configured
/// or H.264 comes from elsewhere; its nominal picture is the camera's as
/// chosen, or the configured size and rate (the running stream's, once the
/// stream reports it).
fn camera_spec(
    c: &crate::camera::CameraConfig,
    plan: &crate::camera::VideoPlan,
) -> Option<crate::vehicle::machine::CameraSpec> {
    use crate::camera::H264Route;
    use crate::camera::rtp::RtpDest;
    let sent = c.webrtc.enabled || !c.rtp.iter().all(|d| *d == RtpDest::Off);
    let passthrough = plan.h264 == H264Route::FfmpegCopy && sent;
    let (width, height, fps) = match &plan.capture {
        Some(cap) => (cap.width, cap.height, cap.fps()),
        None if passthrough => c.h264.passthrough_shape(),
        None => (c.width, c.height, c.fps),
    };
    (c.source != crate::camera::SourceKind::None || passthrough).then(|| {
        crate::vehicle::machine::CameraSpec {
            width: u16::try_from(width).unwrap_or(u16::MAX),
            height: u16::try_from(height).unwrap_or(u16::MAX),
            fps: fps as f32,
        }
    })
}
