//! Recording on the vehicle: the camera's H.264, whatever route makes it
//! (the one encode, a camera's stream copied by ffmpeg with `[camera.h264]
//! passthrough`, a V4L2 camera's own H.264), written without re-encoding
//! into MPEG-TS segments, with the telemetry beside it on the same clock
//! (CSV and WebVTT), in `DATA_DIR/recordings/`.
//!
//! The vehicle core decides who may start and stop (`vehicle/machine/
//! recording.rs`); the app hands its [`RecordControl`]s and
//! [`RecordSample`]s here and the [`RecorderEvent`]s back. The H.264 comes
//! like the WebRTC viewers' does: as access units on a queue, from the RTP
//! sender's one stream while a recording runs (or whenever the stream runs
//! anyway — [`VideoTap`]). Nothing is encoded or depacketized here.
//!
//! Everything runs on a thread of its own (`neptunus-record`): file writes
//! and the once-a-second fsync may block on an SD card, and must hold up
//! neither the vehicle nor a browser. Each picture and telemetry line is
//! written at once and synced every second, so a SIGKILL loses nothing
//! written and a power cut at most the last second; MPEG-TS needs no index
//! at the end, so a cut file plays up to the cut.
//!
//! The storage budget (`budget`) is measured every second while a
//! recording runs, every ten seconds otherwise, and afresh at a start: at
//! the free-space floor or the total cap a recording stops by itself, says
//! why, and none starts. This module must never write outside the recordings
//! directory, encode video, or stop anything but a recording.

pub mod budget;
pub mod files;
pub mod sidecar;
pub mod ts;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::{mpsc, watch};

pub use budget::StorageConfig;
pub use files::{FileKind, RECORDINGS_DIR, RecordingFile, list, listed_path, recordings_dir};

use super::h264::AccessUnit;
use super::rtp::VideoTap;
use crate::vehicle::machine::{RecordControl, RecordSample, RecorderEvent, StorageReport};
use crate::wallclock::WallClock;
use files::Files;

/// How often, while a recording runs, the budget is measured and the files
/// synced.
pub const SYNC_PERIOD: Duration = Duration::from_secs(1);
/// How often the budget is measured while no recording runs: a `statvfs`
/// and a `stat` of every log and recording (a season's hundreds of files
/// cost a Cortex-A8 a share of its idle time once a second), for figures
/// that move only as the logs grow. A start measures afresh.
pub const IDLE_MEASURE_PERIOD: Duration = Duration::from_secs(10);
/// A recording whose first picture has not come after this stops.
pub const START_TIMEOUT: Duration = Duration::from_secs(15);
/// A recording that got no picture for this long stops.
pub const PICTURE_TIMEOUT: Duration = Duration::from_secs(30);
/// The video clock follows the pictures' media clock while it stays this
/// close to their arrival; past it (a restart of the source), arrival wins.
const CLOCK_SLIP: Duration = Duration::from_millis(500);
/// Pictures queued for the recorder's thread (about two seconds at 30 fps):
/// past it (a slow card), the recording skips to the next keyframe.
const UNITS_QUEUE: usize = 64;

/// What the recorder needs.
#[derive(Debug, Clone)]
pub struct RecordConfig {
    /// The data directory (its file system is the one measured).
    pub data_dir: PathBuf,
    pub storage: StorageConfig,
    /// Names the recordings (the logs' clock).
    pub clock: Arc<WallClock>,
    /// The instant the vehicle core's `Now::mono` counts from: samples
    /// are put on the video's clock with it.
    pub vehicle_t0: Instant,
}

enum Cmd {
    Control(RecordControl),
    Sample(RecordSample),
    Shutdown,
}

/// The running recorder. [`shutdown`](Recorder::shutdown) ends a recording
/// cleanly (synced) and joins the thread.
#[derive(Debug)]
pub struct Recorder {
    cmds: mpsc::UnboundedSender<Cmd>,
    feed: VideoTap,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl std::fmt::Debug for Cmd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Cmd::Control(_) => "Control",
            Cmd::Sample(_) => "Sample",
            Cmd::Shutdown => "Shutdown",
        })
    }
}

impl Recorder {
    /// Starts the thread; what happens is told on `events`.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn start(
        cfg: RecordConfig,
        events: mpsc::UnboundedSender<RecorderEvent>,
    ) -> std::io::Result<Recorder> {
        let (units_tx, units) = mpsc::channel(UNITS_QUEUE);
        let (cmds, rx) = mpsc::unbounded_channel();
        let (wanted_tx, wanted) = watch::channel(false);
        let thread = std::thread::Builder::new()
            .name("neptunus-record".into())
            .spawn(move || {
                let rt = match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt,
                    Err(e) => {
                        tracing::error!("recording: cannot start its runtime: {e}");
                        return;
                    }
                };
                let task = Task {
                    dir: files::recordings_dir(&cfg.data_dir),
                    cfg,
                    events,
                    wanted: wanted_tx,
                    active: None,
                    last_report: None,
                    last_measured: None,
                };
                rt.block_on(task.run(units, rx));
            })?;
        tracing::info!("recording ready");
        Ok(Recorder {
            cmds,
            feed: VideoTap {
                wanted,
                units: units_tx,
            },
            thread: Some(thread),
        })
    }

    /// The recorder as a consumer of the one H.264 stream.
    pub fn feed(&self) -> VideoTap {
        self.feed.clone()
    }

    /// What the vehicle task hands the recorder through.
    pub fn handle(&self) -> RecorderHandle {
        RecorderHandle {
            cmds: self.cmds.clone(),
        }
    }

    /// Ends a recording (synced) and waits for the thread. Blocking.
    pub fn shutdown(mut self) {
        let _ = self.cmds.send(Cmd::Shutdown);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Hands the recorder the core's controls and samples (never blocks).
#[derive(Debug, Clone)]
pub struct RecorderHandle {
    cmds: mpsc::UnboundedSender<Cmd>,
}

impl RecorderHandle {
    pub fn control(&self, c: RecordControl) {
        let _ = self.cmds.send(Cmd::Control(c));
    }

    pub fn sample(&self, s: RecordSample) {
        let _ = self.cmds.send(Cmd::Sample(s));
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        let _ = self.cmds.send(Cmd::Shutdown);
    }
}

/// The recording's clock: recording time 0 is the first keyframe's
/// arrival; pictures follow their media clock (90 kHz) from there.
#[derive(Debug, Clone, Copy)]
struct VideoClock {
    t0: Instant,
    /// An RTP time (90 kHz) and the recording time it stands for.
    base: (u64, Duration),
    /// The last picture's time.
    last: Option<Duration>,
}

impl VideoClock {
    fn new(au: &AccessUnit, arrived: Instant) -> Self {
        Self {
            t0: arrived,
            base: (au.time_90khz, Duration::ZERO),
            last: None,
        }
    }

    /// The recording time of a picture that arrived at `arrived`.
    fn time(&mut self, au: &AccessUnit, arrived: Instant) -> Duration {
        let by_arrival = arrived.saturating_duration_since(self.t0);
        let ticks = au.time_90khz.saturating_sub(self.base.0);
        let by_rtp = self.base.1 + Duration::from_micros(ticks * 100 / 9);
        let t = if by_rtp.abs_diff(by_arrival) > CLOCK_SLIP || au.time_90khz < self.base.0 {
            self.base = (au.time_90khz, by_arrival);
            by_arrival
        } else {
            by_rtp
        };
        // Never back, never the same time twice.
        let t = match self.last {
            Some(last) if t <= last => last + Duration::from_millis(1),
            _ => t,
        };
        self.last = Some(t);
        t
    }

    /// The recording's length so far (its last picture's time).
    fn length(&self) -> Duration {
        self.last.unwrap_or_default()
    }
}

/// The recording being made.
struct Active {
    asked: Instant,
    files: Option<Files>,
    clock: Option<VideoClock>,
    last_picture: Instant,
}

struct Task {
    cfg: RecordConfig,
    dir: PathBuf,
    events: mpsc::UnboundedSender<RecorderEvent>,
    wanted: watch::Sender<bool>,
    active: Option<Active>,
    last_report: Option<StorageReport>,
    last_measured: Option<Instant>,
}

impl Task {
    async fn run(
        mut self,
        mut units: mpsc::Receiver<AccessUnit>,
        mut rx: mpsc::UnboundedReceiver<Cmd>,
    ) {
        let mut tick = tokio::time::interval(SYNC_PERIOD);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                cmd = rx.recv() => match cmd {
                    None | Some(Cmd::Shutdown) => break,
                    Some(Cmd::Control(RecordControl::Start)) => self.start(),
                    Some(Cmd::Control(RecordControl::Stop)) => self.stop(None),
                    Some(Cmd::Sample(s)) => self.sample(&s),
                },
                // Taken whether or not a recording runs: the stream comes
                // whenever it runs.
                Some(au) = units.recv() => self.access_unit(&au, Instant::now()),
                _ = tick.tick() => self.every_second(),
            }
        }
        self.stop(None);
    }

    /// Measures the budget; tells the vehicle when it changed.
    fn measure(&mut self) -> StorageReport {
        self.last_measured = Some(Instant::now());
        let report = match budget::measure(&self.cfg.data_dir) {
            Ok(m) => budget::judge(&self.cfg.storage, &m),
            Err(e) => StorageReport {
                blocked: Some(format!(
                    "cannot measure the data directory {}: {e}",
                    self.cfg.data_dir.display()
                )),
                ..StorageReport::default()
            },
        };
        if self
            .last_report
            .as_ref()
            .is_none_or(|last| budget::changed(last, &report))
        {
            self.last_report = Some(report.clone());
            let _ = self.events.send(RecorderEvent::Storage(report.clone()));
        }
        report
    }

    fn start(&mut self) {
        if self.active.is_some() {
            return;
        }
        if let Some(why) = self.measure().blocked {
            let _ = self.events.send(RecorderEvent::Stopped {
                name: None,
                duration_s: 0.0,
                why: Some(why),
            });
            return;
        }
        let now = Instant::now();
        self.active = Some(Active {
            asked: now,
            files: None,
            clock: None,
            last_picture: now,
        });
        self.wanted.send_replace(true);
        tracing::info!("recording: waiting for the camera's first keyframe");
    }

    /// Ends the recording: synced, its directory too, and said.
    fn stop(&mut self, why: Option<String>) {
        let Some(mut a) = self.active.take() else {
            return;
        };
        self.wanted.send_replace(false);
        let (name, duration_s) = match (&mut a.files, &a.clock) {
            (Some(f), Some(c)) => {
                if let Err(e) = f.sync().and_then(|()| crate::durable::sync_dir(&self.dir)) {
                    tracing::error!("recording {}: the last sync failed: {e}", f.name());
                }
                (Some(f.name().to_owned()), c.length().as_secs_f64())
            }
            _ => (None, 0.0),
        };
        match &why {
            Some(w) => tracing::warn!(?name, "recording stopped: {w}"),
            None => tracing::info!(?name, duration_s, "recording stopped"),
        }
        let _ = self.events.send(RecorderEvent::Stopped {
            name,
            duration_s,
            why,
        });
    }

    fn access_unit(&mut self, au: &AccessUnit, arrived: Instant) {
        if let Err(why) = self.picture(au, arrived) {
            self.stop(Some(why));
        }
    }

    /// One picture of the stream, written while a recording runs (the
    /// files created at its first keyframe).
    fn picture(&mut self, au: &AccessUnit, arrived: Instant) -> Result<(), String> {
        let Some(a) = self.active.as_mut() else {
            return Ok(());
        };
        let (files, clock) = match (a.files.as_mut(), a.clock.as_mut()) {
            (Some(f), Some(c)) => (f, c),
            // A recording starts at a keyframe: a player needs one first.
            _ if !au.keyframe => return Ok(()),
            _ => {
                let files = Files::create(&self.dir, self.cfg.clock.unix_us()).map_err(|e| {
                    format!("cannot create a recording in {}: {e}", self.dir.display())
                })?;
                let _ = self.events.send(RecorderEvent::Started {
                    name: files.name().to_owned(),
                });
                tracing::info!(name = files.name(), "recording started");
                (
                    a.files.insert(files),
                    a.clock.insert(VideoClock::new(au, arrived)),
                )
            }
        };
        a.last_picture = arrived;
        let t = clock.time(au, arrived);
        files
            .picture(&au.data, t, au.keyframe)
            .map_err(|e| format!("cannot write the video: {e}"))
    }

    fn sample(&mut self, s: &RecordSample) {
        let Some(Active {
            files: Some(files),
            clock: Some(clock),
            ..
        }) = self.active.as_mut()
        else {
            return;
        };
        let at = self.cfg.vehicle_t0 + s.mono;
        let Some(t) = at.checked_duration_since(clock.t0) else {
            return; // from before the first picture
        };
        if let Err(e) = files.sample(s, t) {
            self.stop(Some(format!("cannot write the telemetry: {e}")));
        }
    }

    fn every_second(&mut self) {
        if self.active.is_none() {
            if self
                .last_measured
                .is_none_or(|t| t.elapsed() >= IDLE_MEASURE_PERIOD)
            {
                self.measure();
            }
            return;
        }
        let report = self.measure();
        let Some(a) = self.active.as_mut() else {
            return;
        };
        let now = Instant::now();
        let why = if let Some(Err(e)) = a.files.as_mut().map(Files::sync) {
            Some(format!("cannot write to the disk: {e}"))
        } else if let Some(why) = report.blocked {
            Some(why)
        } else if a.clock.is_none() && now.duration_since(a.asked) >= START_TIMEOUT {
            Some(format!(
                "no video from the camera in {} s",
                START_TIMEOUT.as_secs()
            ))
        } else if a.clock.is_some() && now.duration_since(a.last_picture) >= PICTURE_TIMEOUT {
            Some(format!(
                "no video from the camera for {} s",
                PICTURE_TIMEOUT.as_secs()
            ))
        } else {
            None
        };
        if why.is_some() {
            self.stop(why);
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;

    /// An idle recorder with a data directory of its own, and what it tells
    /// the vehicle.
    fn idle_task(dir: &std::path::Path) -> (Task, mpsc::UnboundedReceiver<RecorderEvent>) {
        let (events, rx) = mpsc::unbounded_channel();
        let task = Task {
            cfg: RecordConfig {
                data_dir: dir.to_path_buf(),
                storage: budget::StorageConfig {
                    min_free_mb: 0,
                    total_mb: 1024,
                },
                clock: WallClock::system(),
                vehicle_t0: Instant::now(),
            },
            dir: files::recordings_dir(dir),
            events,
            wanted: watch::channel(false).0,
            active: None,
            last_report: None,
            last_measured: None,
        };
        (task, rx)
    }

    #[test]
    fn idle_the_budget_is_measured_once_a_period_not_every_second() {
        let dir = tempfile::tempdir().unwrap();
        let (mut task, mut rx) = idle_task(dir.path());
        task.every_second();
        let first = task.last_measured.expect("the first tick measures");
        assert!(matches!(rx.try_recv(), Ok(RecorderEvent::Storage(_))));
        task.every_second();
        assert_eq!(
            task.last_measured,
            Some(first),
            "measured again within the period"
        );
        // A period later it measures again.
        let earlier = Instant::now().checked_sub(IDLE_MEASURE_PERIOD).unwrap();
        task.last_measured = Some(earlier);
        task.every_second();
        assert!(task.last_measured.unwrap() > earlier);
    }

    fn au(time_90khz: u64) -> AccessUnit {
        AccessUnit {
            data: Vec::new(),
            time_90khz,
            keyframe: false,
        }
    }

    #[test]
    fn the_clock_follows_rtp_and_arrival_wins_after_a_jump() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let mut c = VideoClock::new(&au(9000), t0);
        assert_eq!(c.time(&au(9000), t0), Duration::ZERO);
        // Arrival jitters, the RTP clock is smooth.
        assert_eq!(c.time(&au(9000 + 9000), t0 + ms(130)), ms(100));
        // An encoder restart: its clock moved one tick, 3 s passed.
        assert_eq!(c.time(&au(18_001), t0 + ms(3100)), ms(3100));
        assert_eq!(c.time(&au(18_001 + 9000), t0 + ms(3190)), ms(3200));
        // Never back.
        assert_eq!(c.time(&au(0), t0 + ms(1000)), ms(3201));
    }
}
