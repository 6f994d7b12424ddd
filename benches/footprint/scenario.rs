//! The fixed scenarios and their wiring: the board process, the vehicle,
//! MAVProxy between station 1 and the vehicle when the baseline runs, and
//! the load. [`Running`] owns every process, thread and task of one
//! scenario and ends them all when it drops.

use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use tokio::sync::watch;

use crate::children::{self, Guarded};
use crate::common::{self, Gcs, Traffic, Vehicle};
use crate::load::{self, Tally};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scenario {
    Idle,
    Standard,
    Heavy,
    Sim,
}

impl Scenario {
    pub const ALL: [Scenario; 4] = [
        Scenario::Idle,
        Scenario::Standard,
        Scenario::Heavy,
        Scenario::Sim,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Scenario::Idle => "idle",
            Scenario::Standard => "standard",
            Scenario::Heavy => "heavy",
            Scenario::Sim => "sim",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|x| x.name() == s.trim())
    }

    /// What it is, for the header.
    pub fn describe(self) -> &'static str {
        match self {
            Scenario::Idle => {
                "board link up, HMI on, default telemetry to one listening UDP station, nobody driving"
            }
            Scenario::Standard => {
                "one station (HEARTBEAT 1 Hz, MANUAL_CONTROL 25 Hz, default stream rates), one HMI session"
            }
            Scenario::Heavy => {
                "3 stations (255 drives; 254, 253 heartbeats on a udpin endpoint), 5 HMI sessions, 1 mavlink2rest client, 1 /video.mjpg viewer (MJPEG camera relayed)"
            }
            Scenario::Sim => "`--sim` (board emulator + simulator in-process) with the idle load",
        }
    }

    /// The footprint targets, printed beside the figures.
    pub fn target(self) -> &'static str {
        match self {
            Scenario::Idle => "<= 0.4 %, <= 120 cs/s",
            Scenario::Standard => "<= 1.0 %, <= 0.3x MAVProxy, RSS <= 12 MB",
            _ => "",
        }
    }

    fn driving(self) -> bool {
        matches!(self, Scenario::Standard | Scenario::Heavy)
    }

    fn hmi_sessions(self) -> usize {
        match self {
            Scenario::Standard => 1,
            Scenario::Heavy => 5,
            _ => 0,
        }
    }
}

/// The relayed camera's frame rate (the vehicle's camera default).
const CAMERA_FPS: f64 = 10.0;

/// The bench's own threads and tasks of a scenario: stopped and joined
/// when this drops.
struct Background {
    stop: Arc<AtomicBool>,
    stop_tx: watch::Sender<bool>,
    threads: Vec<JoinHandle<()>>,
    rt: Option<tokio::runtime::Runtime>,
}

impl Drop for Background {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.stop_tx.send(true);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        if let Some(rt) = self.rt.take() {
            rt.shutdown_timeout(Duration::from_secs(1));
        }
    }
}

/// One scenario, running. Fields drop in order: the load first, then the
/// vehicle, MAVProxy, the board, the data directory last.
pub struct Running {
    _background: Background,
    pub vehicle: Vehicle,
    pub mavproxy: Option<Guarded>,
    board: Option<Guarded>,
    pub tally: Arc<Tally>,
    _dir: tempfile::TempDir,
}

impl Running {
    /// An error if the vehicle, the board or MAVProxy has exited.
    pub fn check(&mut self) -> anyhow::Result<()> {
        self.vehicle.check_running()?;
        if let Some(b) = &mut self.board {
            b.check_running()?;
        }
        if let Some(m) = &mut self.mavproxy {
            m.check_running()?;
        }
        Ok(())
    }
}

/// Starts `scenario`; with `mavproxy` (the venv's python), MAVProxy
/// forwards between station 1 and the vehicle.
pub fn start(scenario: Scenario, bin: &Path, mavproxy: Option<&Path>) -> anyhow::Result<Running> {
    start_on(scenario, bin, bin, mavproxy)
}

/// As [`start`], the vehicle run by `bin` and the board by `board_bin` (the
/// CPU budget runs the armhf vehicle under qemu-arm, the board natively).
pub fn start_on(
    scenario: Scenario,
    bin: &Path,
    board_bin: &Path,
    mavproxy: Option<&Path>,
) -> anyhow::Result<Running> {
    let dir = tempfile::tempdir()?;
    let tally = Arc::new(Tally::default());
    let stop = Arc::new(AtomicBool::new(false));
    let (stop_tx, stop_rx) = watch::channel(false);
    // Declared before every process: on an early error it drops after them.
    let mut bg = Background {
        stop: Arc::clone(&stop),
        stop_tx,
        threads: Vec::new(),
        rt: Some(
            tokio::runtime::Builder::new_multi_thread()
                .worker_threads(1)
                .enable_all()
                .build()?,
        ),
    };

    let mut args: Vec<String> = Vec::new();
    let board = if scenario == Scenario::Sim {
        args.push("--sim".into());
        None
    } else {
        let (board, pty) = children::board(board_bin, dir.path())?;
        args.extend(["--serial".into(), pty]);
        Some(board)
    };
    // Station 1 listens, as QGroundControl does on 14550; the vehicle (or
    // MAVProxy, forwarding) sends to it.
    let (mut gcs1, port1) = Gcs::bind()?;
    let (mut mavproxy, vehicle_port) = match mavproxy {
        Some(python) => {
            let master = common::free_udp_port()?;
            let mp = children::mavproxy(python, master, port1, dir.path())?;
            (Some(mp), master)
        }
        None => (None, port1),
    };
    args.push(format!("--mavlink=udpout:127.0.0.1:{vehicle_port}"));
    let udpin = common::free_udp_port()?;
    if scenario == Scenario::Heavy {
        args.push(format!("--mavlink=udpin:127.0.0.1:{udpin}"));
        // The ROV's camera is mjpg-streamer read over HTTP on loopback:
        // the `url` source reads the same way (`synthetic` would draw and
        // encode the pictures in the vehicle, which the ROV never does).
        let jpeg = neptunus::camera::SyntheticRenderer::new(640, 480, 80)
            .render_jpeg(&neptunus::camera::Scene::default())?;
        let (cam, t) = load::mjpeg_camera(jpeg, CAMERA_FPS, Arc::clone(&stop))?;
        bg.threads.push(t);
        let config = dir.path().join("neptunus.toml");
        std::fs::write(
            &config,
            format!("[camera]\nsource = \"url\"\nurl = \"http://{cam}/?action=stream\"\n"),
        )?;
        args.push(format!("--config={}", config.display()));
    }
    // RTP video would start an ffmpeg child for any station heard (`auto`):
    // not part of these loads.
    args.push("--video-rtp=off".into());
    let argv: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut vehicle = Vehicle::spawn(bin, &argv, dir.path(), "")?;

    // In steps, so that a MAVProxy that exits is seen at once.
    let end = Instant::now() + Duration::from_secs(30);
    while let Err(e) = gcs1.await_vehicle(&mut vehicle, Duration::from_secs(1)) {
        if let Some(mp) = &mut mavproxy {
            mp.check_running()?;
        }
        if Instant::now() >= end {
            return Err(match &mavproxy {
                Some(mp) => e.context(format!(
                    "MAVProxy forwarded nothing to station 1 within 30 s; it said:\n{}",
                    mp.tail()
                )),
                None => e,
            });
        }
    }
    let traffic = if scenario.driving() {
        Traffic::Drive(0)
    } else {
        Traffic::Silent
    };
    let t = load::station(
        gcs1,
        traffic,
        |t| &t.station1,
        Arc::clone(&tally),
        Arc::clone(&stop),
    );
    bg.threads.push(t);
    if scenario == Scenario::Heavy {
        for sysid in [254, 253] {
            let mut gcs = Gcs::connect(udpin)?;
            gcs.sysid = sysid;
            let t = load::station(
                gcs,
                Traffic::Heartbeats,
                |t| &t.stations,
                Arc::clone(&tally),
                Arc::clone(&stop),
            );
            bg.threads.push(t);
        }
    }

    let http: SocketAddr = vehicle
        .http_addr(Duration::from_secs(30))
        .context("the HMI's address")?;
    let rt = bg.rt.as_ref().context("no runtime")?;
    for i in 0..scenario.hmi_sessions() {
        let client = load::hmi_session(http, Arc::clone(&tally), stop_rx.clone());
        load::spawn_client(rt, format!("HMI session {i}"), Arc::clone(&tally), client);
    }
    if scenario == Scenario::Heavy {
        let client = load::cockpit(http, Arc::clone(&tally), stop_rx.clone());
        load::spawn_client(rt, "mavlink2rest client".into(), Arc::clone(&tally), client);
        bg.threads.push(load::video_viewer(
            http,
            Arc::clone(&tally),
            Arc::clone(&stop),
        ));
    }
    Ok(Running {
        _background: bg,
        vehicle,
        mavproxy,
        board,
        tally,
        _dir: dir,
    })
}
