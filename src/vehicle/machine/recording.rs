//! Recording on the vehicle, as the camera component (id 100) offers it:
//! MAV_CMD_VIDEO_START_CAPTURE / MAV_CMD_VIDEO_STOP_CAPTURE,
//! CAMERA_CAPTURE_STATUS (at 1 Hz to everyone while recording, at start and
//! stop, and on request) and STORAGE_INFORMATION (the storage budget of logs
//! and recordings, as the recorder last measured it).
//!
//! Starting and stopping change what every station sees and spend the
//! vehicle's storage: both are vehicle control, so they pass
//! `check_control` like any command that changes the vehicle — a station
//! that may only watch is refused (NOT_IN_CONTROL or DENIED, the reason to
//! it alone) and can stop nobody's recording.
//!
//! The recorder itself is the app's (`camera/record/`): the core asks it
//! with [`Output::Record`], hears back with [`Input::Recorder`], and while
//! recording hands it the telemetry written beside the video
//! ([`Output::RecordSample`], five a second, on the core's clock). The
//! recorder stops by itself when the storage floor or cap is reached, and
//! says so; the core then tells every station with a STATUSTEXT. Nothing
//! here touches driving: a recording that stops changes nothing else.

use std::time::Duration;

use super::authority::Control;
use super::camera::VIDEO_STREAM_ID;
use super::texts::{ReplyKind, Topic};
use super::{Now, Output, Sender, To, Vehicle, given};
use crate::dialect::neptunus::*;
use crate::vehicle::telemetry::{LINE_SLACK, gather};

/// CAMERA_CAPTURE_STATUS while recording.
const STATUS_PERIOD: Duration = Duration::from_secs(1);
/// The fastest CAMERA_CAPTURE_STATUS a station may ask for (param 2).
const STATUS_FASTEST: Duration = Duration::from_millis(200);
/// Telemetry written beside the video.
pub const SAMPLE_PERIOD: Duration = Duration::from_millis(200);
const MIB: f64 = 1024.0 * 1024.0;

/// What the core asks of the recorder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordControl {
    Start,
    Stop,
}

/// One row of the telemetry written beside a recording. A reading that is
/// not fresh (stale, or the board link down) is `None`: written empty,
/// never as if live.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSample {
    /// The core's monotonic time (`Now::mono`).
    pub mono: Duration,
    pub unix_us: u64,
    pub depth_m: Option<f64>,
    pub heading_deg: Option<f64>,
    pub roll_deg: Option<f64>,
    pub pitch_deg: Option<f64>,
    pub mode: &'static str,
    pub armed: bool,
    /// 0–100 %.
    pub lights_pct: f64,
    /// The camera tilt, degrees, up positive.
    pub tilt_deg: f64,
}

/// The storage of logs and recordings as the recorder measured it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct StorageReport {
    /// What recordings and logs may take in all: the configured cap, or
    /// the file system's size when smaller.
    pub total_bytes: u64,
    /// Logs and recordings now.
    pub used_bytes: u64,
    /// What a recording may still write before the cap or the free-space
    /// floor stops it.
    pub available_bytes: u64,
    /// Why no recording may run now (the floor or the cap reached).
    pub blocked: Option<String>,
}

/// What the recorder tells the core.
#[derive(Debug, Clone, PartialEq)]
pub enum RecorderEvent {
    /// The first picture of recording `name` is on disk.
    Started { name: String },
    /// A recording ended, or could not start. `why` is None when it was
    /// asked to stop; else why it stopped by itself.
    Stopped {
        name: Option<String>,
        duration_s: f64,
        why: Option<String>,
    },
    /// The storage, measured again (sent when it changed).
    Storage(StorageReport),
}

#[derive(Debug, Default, Clone, PartialEq)]
enum State {
    #[default]
    Idle,
    /// Asked of the recorder, waiting for its first picture.
    Starting,
    Running {
        since: Duration,
        name: String,
    },
}

/// The recording's state in the core.
#[derive(Debug, Default)]
pub(super) struct Recording {
    /// The app runs a recorder: the camera says it can record.
    enabled: bool,
    state: State,
    status_period: Option<Duration>,
    next_status: Option<Duration>,
    next_sample: Option<Duration>,
    storage: Option<StorageReport>,
}

impl Vehicle {
    /// The app runs a recorder: the camera component offers recording
    /// (CAMERA_CAP_FLAGS_CAPTURE_VIDEO) and answers the capture commands.
    pub fn with_recording(mut self, enabled: bool) -> Self {
        self.recording.enabled = enabled;
        self
    }

    pub(super) fn can_record(&self) -> bool {
        self.recording.enabled && self.has_camera()
    }

    /// Whether a recording runs or is starting.
    pub fn recording(&self) -> bool {
        self.recording.state != State::Idle
    }

    /// MAV_CMD_VIDEO_START_CAPTURE / _STOP_CAPTURE to the camera: the
    /// result and the messages after the ack (to the asker).
    pub(super) fn capture_command(
        &mut self,
        from: Sender,
        cmd: MavCmd,
        p: [f32; 7],
        now: Now,
        out: &mut Vec<Output>,
    ) -> (MavResult, Vec<MavMessage>) {
        if !self.can_record() {
            return (MavResult::MAV_RESULT_UNSUPPORTED, Vec::new());
        }
        let start = cmd == MavCmd::MAV_CMD_VIDEO_START_CAPTURE;
        let what = if start {
            "starting a recording"
        } else {
            "stopping the recording"
        };
        if let Err(why) = self.check_control(from, Control::Command, now, out) {
            return (self.refuse_command(from, what, why, now, out), Vec::new());
        }
        // Stream 0 is all; we have stream 1 only.
        if given(p[0]).is_some_and(|s| s != 0.0 && s != f32::from(VIDEO_STREAM_ID)) {
            return (MavResult::MAV_RESULT_DENIED, Vec::new());
        }
        if !start {
            if self.recording() {
                out.push(Output::Record(RecordControl::Stop));
                self.recording.state = State::Idle;
                self.recording.next_sample = None;
                self.capture_status_to_all(now, out);
            }
            return (MavResult::MAV_RESULT_ACCEPTED, Vec::new());
        }
        if self.recording() {
            return (MavResult::MAV_RESULT_ACCEPTED, Vec::new());
        }
        if let Some(why) = self
            .recording
            .storage
            .as_ref()
            .and_then(|s| s.blocked.clone())
        {
            self.reply_text(
                from,
                ReplyKind::Note,
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Recording refused: {why}"),
                now,
                out,
            );
            return (MavResult::MAV_RESULT_DENIED, Vec::new());
        }
        // Param 2: how often CAMERA_CAPTURE_STATUS goes while recording
        // (0: the default, once a second).
        self.recording.status_period = given(p[1])
            .filter(|hz| *hz > 0.0)
            .map(|hz| Duration::from_secs_f32(1.0 / hz).clamp(STATUS_FASTEST, STATUS_PERIOD));
        self.recording.state = State::Starting;
        self.recording.next_status = Some(now.mono + self.status_period());
        self.recording.next_sample = Some(now.mono);
        out.push(Output::Record(RecordControl::Start));
        self.log(
            "recording",
            Some(from.sysid),
            "recording asked to start".into(),
            out,
        );
        self.capture_status_to_all(now, out);
        (MavResult::MAV_RESULT_ACCEPTED, Vec::new())
    }

    fn status_period(&self) -> Duration {
        self.recording.status_period.unwrap_or(STATUS_PERIOD)
    }

    /// What the recorder said.
    pub(super) fn on_recorder(&mut self, ev: RecorderEvent, now: Now, out: &mut Vec<Output>) {
        match ev {
            RecorderEvent::Storage(report) => self.recording.storage = Some(report),
            RecorderEvent::Started { name } => {
                if self.recording.state != State::Starting {
                    return;
                }
                self.statustext(
                    Topic::General,
                    MavSeverity::MAV_SEVERITY_INFO,
                    &format!("Recording on the vehicle: {name}"),
                    out,
                );
                self.log("recording", None, format!("recording {name} started"), out);
                self.recording.state = State::Running {
                    since: now.mono,
                    name,
                };
                self.capture_status_to_all(now, out);
            }
            RecorderEvent::Stopped {
                name,
                duration_s,
                why,
            } => {
                let was = std::mem::take(&mut self.recording.state);
                self.recording.next_sample = None;
                let shown = name.as_deref().unwrap_or("nothing recorded");
                let (severity, text) = match &why {
                    None => (
                        MavSeverity::MAV_SEVERITY_INFO,
                        format!("Recording stopped: {shown}, {duration_s:.0} s"),
                    ),
                    Some(why) => (
                        MavSeverity::MAV_SEVERITY_WARNING,
                        format!("Recording stopped: {why} ({shown}, {duration_s:.0} s)"),
                    ),
                };
                self.statustext(Topic::General, severity, &text, out);
                self.log("recording", None, text, out);
                if was != State::Idle {
                    self.capture_status_to_all(now, out);
                }
            }
        }
    }

    /// While recording: the telemetry rows and the capture status, on
    /// their clocks (gathered with the board's lines like the heartbeat).
    pub(super) fn recording_tick(&mut self, now: Now, out: &mut Vec<Output>) {
        if !self.recording() {
            return;
        }
        // The rows keep their beat (the vehicle wakes for them): a line
        // a hair before one carries it, no earlier.
        if let Some(due) = self.recording.next_sample
            && now.mono + LINE_SLACK >= due
        {
            out.push(Output::RecordSample(self.record_sample(now)));
            self.recording.next_sample = Some(next_on_grid(due, SAMPLE_PERIOD, now.mono));
        }
        let period = self.status_period();
        if let Some(due) = self.recording.next_status
            && now.mono + gather(period) >= due
        {
            self.capture_status_to_all(now, out);
            self.recording.next_status = Some(next_on_grid(due, period, now.mono));
        }
    }

    /// When the recording next needs a tick.
    pub(super) fn recording_next_tick(&self) -> Option<Duration> {
        if !self.recording() {
            return None;
        }
        [self.recording.next_sample, self.recording.next_status]
            .into_iter()
            .flatten()
            .min()
    }

    fn record_sample(&self, now: Now) -> RecordSample {
        let e = self.holds.est.estimate(now.mono);
        let heading_fresh = self.fresh(&self.board.heading_deg, now);
        let depth_fresh = self.fresh(&self.board.depth_m, now);
        let heading = if self.holds.est.heading_filter().initialised() {
            e.heading_deg
        } else {
            self.board.heading_deg.value
        };
        let depth = if self.holds.est.depth_filter().initialised() {
            e.depth_m
        } else {
            self.board.depth_m.value
        };
        RecordSample {
            mono: now.mono,
            unix_us: now.unix_us,
            depth_m: depth_fresh.then_some(depth),
            heading_deg: heading_fresh.then_some(heading.rem_euclid(360.0)),
            roll_deg: heading_fresh.then_some(self.board.roll_deg.value),
            pitch_deg: heading_fresh.then_some(self.board.pitch_deg.value),
            mode: self.mode.name(),
            armed: self.armed,
            lights_pct: f64::from(self.payload.lights) / 255.0 * 100.0,
            tilt_deg: super::gimbal::tilt_deg(self.payload.tilt_us),
        }
    }

    fn capture_status_to_all(&self, now: Now, out: &mut Vec<Output>) {
        out.push(Output::SendAs {
            to: To::All,
            compid: super::CAMERA_COMPONENT_ID,
            msg: self.capture_status(now),
        });
    }

    /// CAMERA_CAPTURE_STATUS: video_status 1 while recording (and while
    /// it starts), its time, and what the storage still takes.
    pub(super) fn capture_status(&self, now: Now) -> MavMessage {
        let recording_time_ms = match &self.recording.state {
            State::Running { since, .. } => now
                .mono
                .saturating_sub(*since)
                .as_millis()
                .min(u128::from(u32::MAX)) as u32,
            _ => 0,
        };
        MavMessage::CAMERA_CAPTURE_STATUS(CAMERA_CAPTURE_STATUS_DATA {
            time_boot_ms: self.boot_ms(now),
            image_status: 0,
            video_status: u8::from(self.recording()),
            image_interval: 0.0,
            recording_time_ms,
            available_capacity: self
                .recording
                .storage
                .as_ref()
                .map_or(0.0, |s| (s.available_bytes as f64 / MIB) as f32),
            image_count: 0,
            ..Default::default()
        })
    }

    /// STORAGE_INFORMATION: the budget of logs and recordings (MiB), ready
    /// once the recorder measured it; not supported without a recorder.
    pub(super) fn storage_information(&self, now: Now) -> MavMessage {
        let (count, status, total, used, available) =
            match (self.can_record(), &self.recording.storage) {
                (false, _) => (
                    0,
                    StorageStatus::STORAGE_STATUS_NOT_SUPPORTED,
                    0.0,
                    0.0,
                    0.0,
                ),
                (true, None) => (
                    1,
                    StorageStatus::STORAGE_STATUS_NOT_SUPPORTED,
                    0.0,
                    0.0,
                    0.0,
                ),
                (true, Some(s)) => (
                    1,
                    StorageStatus::STORAGE_STATUS_READY,
                    s.total_bytes as f64 / MIB,
                    s.used_bytes as f64 / MIB,
                    s.available_bytes as f64 / MIB,
                ),
            };
        MavMessage::STORAGE_INFORMATION(STORAGE_INFORMATION_DATA {
            time_boot_ms: self.boot_ms(now),
            storage_id: u8::from(count > 0),
            storage_count: count,
            status,
            total_capacity: total as f32,
            used_capacity: used as f32,
            available_capacity: available as f32,
            read_speed: f32::NAN,
            write_speed: f32::NAN,
            ..Default::default()
        })
    }
}

/// The next time on `period`'s grid after `due`, never in the past (a
/// late tick does not make a burst).
fn next_on_grid(due: Duration, period: Duration, now: Duration) -> Duration {
    let next = due + period;
    if next <= now { now + period } else { next }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_keeps_its_rate_and_never_bursts() {
        let ms = Duration::from_millis;
        assert_eq!(next_on_grid(ms(1000), ms(200), ms(1010)), ms(1200));
        assert_eq!(next_on_grid(ms(1000), ms(200), ms(1500)), ms(1700));
    }
}
