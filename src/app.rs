//! Wiring: starts the board (real or emulated), the serial link and the
//! vehicle task, and shuts them down in order.
//!
//! Owns task lifetimes and nothing else: every decision about the vehicle
//! lives in the vehicle task; this module only connects channels.

use std::future::Future;
use std::time::Duration;

use tokio::time::Instant;

use crate::config::{BoardSource, Settings};
use crate::firmware::codec::{Command, Event, NavSample, StatusSample};
use crate::firmware::emulator::PtyBoard;
use crate::firmware::link::{self, LinkError, LinkEvent, LinkState};

/// Errors starting the vehicle.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error("cannot start the board emulator: {0}")]
    Emulator(#[from] crate::firmware::pty::PtyError),
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
    let (link, mut events) = link::spawn(settings.link.clone());
    let mut shutdown = std::pin::pin!(shutdown);
    let mut nav = NavSample::default();
    let mut status = StatusSample::default();
    let mut state = LinkState::Down;
    let mut healthy = tokio::time::interval(Duration::from_millis(250));
    let mut report = tokio::time::interval_at(
        Instant::now() + Duration::from_secs(1),
        Duration::from_secs(1),
    );
    loop {
        tokio::select! {
            () = &mut shutdown => break,
            _ = healthy.tick() => link.healthy(),
            ev = events.recv() => match ev {
                None => break,
                Some(LinkEvent::State { state: s, reason }) => {
                    state = s;
                    if s == LinkState::Up {
                        // Disarmed: whatever the board last had, it gets neutral.
                        link.send(NEUTRAL);
                    }
                    tracing::debug!(?s, ?reason, "link state");
                }
                Some(LinkEvent::Telemetry(Event::Nav(n))) => nav = merge_nav(nav, n),
                Some(LinkEvent::Telemetry(Event::Status(s))) => status = s,
                Some(LinkEvent::Telemetry(_)) => {}
            },
            _ = report.tick() => {
                let s = link.stats();
                tracing::info!(
                    link = ?state,
                    heading_deg = nav.heading_deg.unwrap_or(f64::NAN),
                    depth_m = nav.depth_m.unwrap_or(f64::NAN),
                    pitch_deg = nav.pitch_deg.unwrap_or(f64::NAN),
                    roll_deg = nav.roll_deg.unwrap_or(f64::NAN),
                    voltage_v = status.vout_v.unwrap_or(f64::NAN),
                    current_a = status.btti_a.unwrap_or(f64::NAN),
                    telemetry_age_ms = s.telemetry_age_ms.unwrap_or(u64::MAX),
                    lines = s.decode.lines_accepted,
                    rejected = s.decode.rejected_total(),
                    crc_fail = s.crc_failures_echoed,
                    written = s.commands_written,
                    "telemetry"
                );
            }
        }
    }
    tracing::info!("shutting down: thrusters to neutral");
    link.send(NEUTRAL);
    // Give the link a moment to put the neutral command on the wire.
    tokio::time::sleep(Duration::from_millis(50)).await;
    drop(link);
    if let Some(board) = board {
        board.shutdown().await;
    }
    Ok(())
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
