//! The MAVLink camera component (component id [`CAMERA_COMPONENT_ID`] of
//! this vehicle's system): what QGroundControl's camera discovery looks for.
//!
//! It sends its own 1 Hz HEARTBEAT (MAV_TYPE_CAMERA, MAV_AUTOPILOT_INVALID)
//! on every endpoint and answers, COMMAND_ACK first and then the message,
//! the requests addressed to it (or broadcast to component 0):
//! MAV_CMD_REQUEST_MESSAGE for CAMERA_INFORMATION, CAMERA_SETTINGS,
//! STORAGE_INFORMATION, CAMERA_CAPTURE_STATUS, VIDEO_STREAM_INFORMATION and
//! VIDEO_STREAM_STATUS, and the legacy MAV_CMD_REQUEST_CAMERA_* /
//! _VIDEO_STREAM_* commands; with a recorder, MAV_CMD_VIDEO_START_CAPTURE
//! and _STOP_CAPTURE too (`recording.rs`, which also makes the storage
//! information and the capture status). Any other command to it is
//! UNSUPPORTED.
//!
//! It exists only when the vehicle has a camera source
//! ([`Vehicle::with_camera`]). What it says about the video stream comes
//! from [`Input::VideoStream`](super::Input::VideoStream), sent by whoever
//! runs the stream (the RTP sender in `camera/`); with no stream (`None`)
//! VIDEO_STREAM_INFORMATION still describes stream 1 (so a ground station
//! knows the camera streams video) but without the RUNNING flag and with an
//! empty uri, and VIDEO_STREAM_STATUS says it is not running.
//!
//! Sans-IO like the rest of the core. Its requests never change the
//! vehicle and need no authority check; starting and stopping a recording
//! do (`recording.rs`).

use std::time::Duration;

use mavlink_core::{Message, MessageData};

use super::{Now, Output, Sender, To, Vehicle, chars, command::ack, given};
use crate::dialect::neptunus::*;
use crate::vehicle::telemetry::gather;

/// The camera's MAVLink component id (MAV_COMP_ID_CAMERA, the first of the
/// 100–105 range QGroundControl listens on).
pub const CAMERA_COMPONENT_ID: u8 = 100;
/// The one video stream's id (ids start at 1; 0 in a request means all).
pub const VIDEO_STREAM_ID: u8 = 1;
const HEARTBEAT_PERIOD: Duration = Duration::from_secs(1);
const VENDOR: &str = "Neptunus";
const MODEL: &str = "OpenROV camera";
const STREAM_NAME: &str = "Neptunus video";

/// A video stream that runs now, as whoever runs it describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoStreamInfo {
    /// Where the stream goes, `udp://HOST:PORT` (RTP, H.264): the address
    /// the ground station receives on.
    pub uri: String,
    pub width: u16,
    pub height: u16,
    pub fps: f32,
    pub bitrate_kbps: u32,
}

/// The camera as configured (before any stream runs): its nominal picture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSpec {
    pub width: u16,
    pub height: u16,
    pub fps: f32,
}

/// The camera component's state.
#[derive(Debug, Default)]
pub(super) struct Camera {
    /// Some when the vehicle has a camera: the component exists.
    spec: Option<CameraSpec>,
    stream: Option<VideoStreamInfo>,
    next_heartbeat: Option<Duration>,
}

/// MAV_CMD_REQUEST_MESSAGE ids the camera answers.
const CAMERA_MESSAGES: [u32; 6] = [
    CAMERA_INFORMATION_DATA::ID,
    CAMERA_SETTINGS_DATA::ID,
    STORAGE_INFORMATION_DATA::ID,
    CAMERA_CAPTURE_STATUS_DATA::ID,
    VIDEO_STREAM_INFORMATION_DATA::ID,
    VIDEO_STREAM_STATUS_DATA::ID,
];

/// The legacy request commands and the message each one asks for.
fn legacy_request(cmd: MavCmd) -> Option<u32> {
    use MavCmd as C;
    Some(match cmd {
        C::MAV_CMD_REQUEST_CAMERA_INFORMATION => CAMERA_INFORMATION_DATA::ID,
        C::MAV_CMD_REQUEST_CAMERA_SETTINGS => CAMERA_SETTINGS_DATA::ID,
        C::MAV_CMD_REQUEST_STORAGE_INFORMATION => STORAGE_INFORMATION_DATA::ID,
        C::MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS => CAMERA_CAPTURE_STATUS_DATA::ID,
        C::MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION => VIDEO_STREAM_INFORMATION_DATA::ID,
        C::MAV_CMD_REQUEST_VIDEO_STREAM_STATUS => VIDEO_STREAM_STATUS_DATA::ID,
        _ => return None,
    })
}

/// Whether a command is a camera request (answered by the camera even when
/// broadcast, and then not by the autopilot).
fn is_camera_request(cmd: MavCmd, p: &[f32; 7]) -> bool {
    legacy_request(cmd).is_some()
        || (cmd == MavCmd::MAV_CMD_REQUEST_MESSAGE
            && given(p[0]).is_some_and(|id| CAMERA_MESSAGES.contains(&(id as u32))))
}

impl Vehicle {
    /// The vehicle has a camera (`Some`): the camera component exists.
    /// Without one nothing is sent from or answered for component 100.
    pub fn with_camera(mut self, spec: Option<CameraSpec>) -> Self {
        self.camera.spec = spec;
        self
    }

    /// Whether the camera component exists.
    pub fn has_camera(&self) -> bool {
        self.camera.spec.is_some()
    }

    /// The video stream the camera component advertises, if one runs.
    pub fn video_stream(&self) -> Option<&VideoStreamInfo> {
        self.camera.stream.as_ref()
    }

    pub(super) fn set_video_stream(&mut self, stream: Option<VideoStreamInfo>) {
        self.camera.stream = stream;
    }

    /// When the camera's next heartbeat is due (None: no camera, or at the next tick).
    pub(super) fn camera_next_heartbeat(&self) -> Option<Duration> {
        self.camera.spec.as_ref().and(self.camera.next_heartbeat)
    }

    /// The camera's heartbeat, once a second on every endpoint: with the
    /// last tick (an idle vehicle's run with the board's lines) before it
    /// is due, on a grid that keeps the rate.
    pub(super) fn camera_tick(&mut self, now: Now, out: &mut Vec<Output>) {
        if self.camera.spec.is_none() {
            return;
        }
        let next = match self.camera.next_heartbeat {
            None => now.mono + HEARTBEAT_PERIOD,
            Some(t) if now.mono + gather(HEARTBEAT_PERIOD) < t => return,
            Some(t) if t + HEARTBEAT_PERIOD <= now.mono => now.mono + HEARTBEAT_PERIOD,
            Some(t) => t + HEARTBEAT_PERIOD,
        };
        self.camera.next_heartbeat = Some(next);
        out.push(camera_out(To::All, camera_heartbeat()));
    }

    /// A message for the camera: aimed at component 100 of our system, or a
    /// camera request broadcast to component 0. Returns whether the camera
    /// answered it (the autopilot then stays silent).
    pub(super) fn on_camera_message(
        &mut self,
        from: Sender,
        msg: &MavMessage,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        if !self.has_camera() {
            return false;
        }
        let system_ok = msg
            .target_system_id()
            .is_some_and(|s| s == 0 || s == self.sysid());
        let component = msg.target_component_id();
        if !system_ok || !matches!(component, Some(0 | CAMERA_COMPONENT_ID)) {
            return false;
        }
        let (cmd, p) = match msg {
            MavMessage::COMMAND_LONG(c) => (
                c.command,
                [
                    c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7,
                ],
            ),
            MavMessage::COMMAND_INT(c) => (
                c.command,
                [
                    c.param1, c.param2, c.param3, c.param4, c.x as f32, c.y as f32, c.z,
                ],
            ),
            // Nothing else is the camera's (and broadcasts stay the autopilot's).
            _ => return component == Some(CAMERA_COMPONENT_ID),
        };
        if component == Some(0) && !is_camera_request(cmd, &p) {
            return false;
        }
        // What a capture command tells everyone goes after the ack.
        let mut after = Vec::new();
        let (result, replies) = match cmd {
            MavCmd::MAV_CMD_VIDEO_START_CAPTURE | MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE => {
                self.capture_command(from, cmd, p, now, &mut after)
            }
            _ => self.camera_command(cmd, p, now),
        };
        let to = from.reply();
        out.push(camera_out(to, ack(cmd, result, from)));
        out.extend(replies.into_iter().map(|m| camera_out(to, m)));
        out.append(&mut after);
        true
    }

    fn camera_command(&self, cmd: MavCmd, p: [f32; 7], now: Now) -> (MavResult, Vec<MavMessage>) {
        let (id, stream) = match legacy_request(cmd) {
            // Legacy: the video-stream requests carry the stream id in p1.
            Some(id)
                if id == VIDEO_STREAM_INFORMATION_DATA::ID
                    || id == VIDEO_STREAM_STATUS_DATA::ID =>
            {
                (id, given(p[0]))
            }
            Some(id) => (id, None),
            None if cmd == MavCmd::MAV_CMD_REQUEST_MESSAGE => {
                (given(p[0]).map_or(u32::MAX, |v| v as u32), given(p[1]))
            }
            None => return (MavResult::MAV_RESULT_UNSUPPORTED, Vec::new()),
        };
        // Stream 0 is "all"; we have stream 1 only.
        let stream_ok = stream.is_none_or(|s| s == 0.0 || s == f32::from(VIDEO_STREAM_ID));
        let msg = match id {
            HEARTBEAT_DATA::ID => Some(camera_heartbeat()),
            CAMERA_INFORMATION_DATA::ID => Some(self.camera_information(now)),
            CAMERA_SETTINGS_DATA::ID => Some(MavMessage::CAMERA_SETTINGS(CAMERA_SETTINGS_DATA {
                time_boot_ms: self.boot_ms(now),
                mode_id: CameraMode::CAMERA_MODE_VIDEO,
                zoomLevel: f32::NAN,
                focusLevel: f32::NAN,
                ..Default::default()
            })),
            STORAGE_INFORMATION_DATA::ID => Some(self.storage_information(now)),
            CAMERA_CAPTURE_STATUS_DATA::ID => Some(self.capture_status(now)),
            VIDEO_STREAM_INFORMATION_DATA::ID if stream_ok => Some(self.video_stream_information()),
            VIDEO_STREAM_STATUS_DATA::ID if stream_ok => Some(self.video_stream_status()),
            VIDEO_STREAM_INFORMATION_DATA::ID | VIDEO_STREAM_STATUS_DATA::ID => {
                return (MavResult::MAV_RESULT_DENIED, Vec::new());
            }
            _ => None,
        };
        match msg {
            Some(m) => (MavResult::MAV_RESULT_ACCEPTED, vec![m]),
            None => (MavResult::MAV_RESULT_UNSUPPORTED, Vec::new()),
        }
    }

    /// The picture: the running stream's, else the configured one.
    fn picture(&self) -> (u16, u16, f32) {
        match (&self.camera.stream, self.camera.spec) {
            (Some(s), _) => (s.width, s.height, s.fps),
            (None, Some(c)) => (c.width, c.height, c.fps),
            (None, None) => (0, 0, 0.0),
        }
    }

    fn camera_information(&self, now: Now) -> MavMessage {
        let (w, h, _) = self.picture();
        let mut vendor = [0u8; 32];
        vendor[..VENDOR.len()].copy_from_slice(VENDOR.as_bytes());
        let mut model = [0u8; 32];
        model[..MODEL.len()].copy_from_slice(MODEL.as_bytes());
        MavMessage::CAMERA_INFORMATION(CAMERA_INFORMATION_DATA {
            time_boot_ms: self.boot_ms(now),
            vendor_name: vendor,
            model_name: model,
            resolution_h: w,
            resolution_v: h,
            flags: if self.can_record() {
                CameraCapFlags::CAMERA_CAP_FLAGS_HAS_VIDEO_STREAM
                    | CameraCapFlags::CAMERA_CAP_FLAGS_CAPTURE_VIDEO
            } else {
                CameraCapFlags::CAMERA_CAP_FLAGS_HAS_VIDEO_STREAM
            },
            // Empty: no camera definition file to download.
            cam_definition_uri: chars(""),
            ..Default::default()
        })
    }

    fn video_stream_information(&self) -> MavMessage {
        let (w, h, fps) = self.picture();
        let (flags, uri, bitrate) = match &self.camera.stream {
            Some(s) => (
                VideoStreamStatusFlags::VIDEO_STREAM_STATUS_FLAGS_RUNNING,
                s.uri.as_str(),
                s.bitrate_kbps.saturating_mul(1000),
            ),
            None => (VideoStreamStatusFlags::empty(), "", 0),
        };
        MavMessage::VIDEO_STREAM_INFORMATION(VIDEO_STREAM_INFORMATION_DATA {
            stream_id: VIDEO_STREAM_ID,
            count: 1,
            mavtype: VideoStreamType::VIDEO_STREAM_TYPE_RTPUDP,
            flags,
            framerate: fps,
            resolution_h: w,
            resolution_v: h,
            bitrate,
            name: chars(STREAM_NAME),
            uri: chars(uri),
            encoding: VideoStreamEncoding::VIDEO_STREAM_ENCODING_H264,
            ..Default::default()
        })
    }

    fn video_stream_status(&self) -> MavMessage {
        let (w, h, fps) = self.picture();
        let (flags, bitrate) = match &self.camera.stream {
            Some(s) => (
                VideoStreamStatusFlags::VIDEO_STREAM_STATUS_FLAGS_RUNNING,
                s.bitrate_kbps.saturating_mul(1000),
            ),
            None => (VideoStreamStatusFlags::empty(), 0),
        };
        MavMessage::VIDEO_STREAM_STATUS(VIDEO_STREAM_STATUS_DATA {
            stream_id: VIDEO_STREAM_ID,
            flags,
            framerate: fps,
            resolution_h: w,
            resolution_v: h,
            bitrate,
            ..Default::default()
        })
    }
}

fn camera_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_CAMERA,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}

fn camera_out(to: To, msg: MavMessage) -> Output {
    Output::SendAs {
        to,
        compid: CAMERA_COMPONENT_ID,
        msg,
    }
}
