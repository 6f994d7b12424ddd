//! Wiring: starts the board (real or emulated), the serial link, the
//! MAVLink endpoints, the HMI and the vehicle task, and shuts them down in
//! order.
//!
//! Owns task lifetimes and nothing else: every decision about the vehicle
//! lives in the vehicle core; the files here only connect channels.
//! - `tasks`: start-up and shutdown, in order;
//! - `vehicle_task`: the one task that owns the vehicle, its inputs and the log line;
//! - `io`: the core's outputs carried out (one send path for frames);
//! - `signing`: message signing and its files;
//! - `params`: parameter saving off the vehicle task;
//! - `storage`: the data directory's problems at start;
//! - `side`: the browser side's own thread (HMI, camera, emulator);
//! - `notify`: systemd's READY/WATCHDOG/STOPPING, fed from the vehicle task's loop;
//! - `timer`: the loop's wake-up timer (the kernel's, not the runtime's wheel).
//!
//! `docs/ARCHITECTURE.md` follows a stick input and a telemetry line
//! through these files.

mod io;
mod notify;
mod params;
mod side;
mod signing;
mod storage;
mod tasks;
mod timer;
mod vehicle_task;

use std::future::Future;

use crate::config::Settings;
use crate::eventlog::EventLogError;
use crate::firmware::emulator::PtyBoard;
use crate::firmware::link::LinkError;
use crate::mavlink::endpoint::EndpointError;
use crate::mavlink::signing::SigningError;
use crate::vehicle::machine::Input;

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
    #[error("the browser side's thread: {0}")]
    Side(std::io::Error),
    #[error("the vehicle loop's timer: {0}")]
    Timer(std::io::Error),
    #[error("the genuine firmware in the loop (--hil): {0}")]
    Hil(String),
    #[error("cannot create the data directory {path}: {source}")]
    DataDir {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
}

/// Runs the vehicle until `shutdown` resolves.
pub async fn run(settings: Settings, shutdown: impl Future<Output = ()>) -> Result<(), AppError> {
    // The kernel's timer, moved only when the next wake-up moves (see `timer`).
    let mut wake = timer::WakeTimer::new().map_err(AppError::Timer)?;
    let (mut t, mut vehicle) = tasks::start(settings).await?;
    let mut shutdown = std::pin::pin!(shutdown);
    // The RTP sender says what it sends; the camera component advertises it.
    let mut video_stream = t.rtp.stream();
    // Who listens on the in-process endpoints: their streams are built
    // only while someone does (each starts with its present count).
    let [mut hmi_heard, mut m2r_heard] = vehicle.io.hmi.each_ref().map(|o| {
        let mut rx = o.listeners();
        rx.mark_changed();
        (o.endpoint(), rx)
    });
    let mut notify = notify::Notify::from_env();
    let stall = notify::StallHook::from_env();
    notify.ready();
    // A timer that fails (it cannot, short of a kernel refusing its own
    // clock) ends the run the orderly way: thrusters neutral first.
    let mut failed = None;
    loop {
        if let Err(e) = wake.set(vehicle.next_wake()) {
            failed = Some(e);
            break;
        }
        tokio::select! {
            () = &mut shutdown => break,
            expired = wake.expired() => match expired {
                Ok(()) => vehicle.wake(),
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            },
            input = t.hmi.recv() => vehicle.handle(input),
            Some(result) = t.saved.recv() => vehicle.handle(Input::ParamsSaved(result)),
            Some(reply) = t.file_replies.recv() => vehicle.handle(Input::Files(reply)),
            ev = t.link_events.recv() => match ev {
                None => break,
                Some(ev) => vehicle.link_event(ev),
            },
            msg = t.inbound.recv() => match msg {
                None => break,
                Some(msg) => vehicle.inbound(msg),
            },
            truth = tasks::board_truth(&mut t.truth) => vehicle.board_truth(&truth),
            _ = t.report.tick() => vehicle.report(),
            Ok(()) = hmi_heard.1.changed() => vehicle.listeners(hmi_heard.0, &mut hmi_heard.1),
            Ok(()) = m2r_heard.1.changed() => vehicle.listeners(m2r_heard.0, &mut m2r_heard.1),
            Some(ev) = t.recorder_events.recv() => vehicle.handle(Input::Recorder(ev)),
            Ok(()) = video_stream.changed() => {
                let stream = video_stream.borrow_and_update().clone().map(video_stream_info);
                vehicle.handle(Input::VideoStream(stream));
            }
        }
        vehicle.flush();
        // The watchdog is fed by this loop alone: a hung vehicle task starves it.
        stall.check();
        notify.alive();
    }
    if let Some(e) = &failed {
        tracing::error!(error = %e, "the vehicle loop's timer failed: shutting down");
    }
    t.shutdown(vehicle, &mut notify).await;
    failed.map_or(Ok(()), |e| Err(AppError::Timer(e)))
}

/// The RTP sender's stream as the vehicle core's camera component describes it.
fn video_stream_info(s: crate::camera::rtp::RtpStream) -> crate::vehicle::machine::VideoStreamInfo {
    crate::vehicle::machine::VideoStreamInfo {
        uri: s.uri,
        width: s.width,
        height: s.height,
        fps: s.fps,
        bitrate_kbps: s.bitrate_kbps,
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
