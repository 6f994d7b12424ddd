//! What the core takes in and gives out: [`Input`] (a station's message, a
//! board event, a tick, the disk's and the recorder's answers, a browser
//! session's events) and [`Output`] (frames to stations, commands to the
//! board, saves, log records, requests to the recorder and the disk). The
//! app carries them; the core decides.

use super::*;

/// What the core reacts to.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    Mavlink {
        from: Sender,
        msg: MavMessage,
    },
    Board(Event),
    /// Telemetry of the built-in simulator (run mode SIMULATOR).
    SimBoard(Event),
    Link {
        state: LinkState,
        reason: Option<String>,
    },
    /// The board line's quality changed (SYS_STATUS `drop_rate_comm`,
    /// `errors_comm`).
    LinkQuality(LinkQuality),
    /// Periodic (the app ticks at 100 Hz): telemetry, timeouts.
    Tick,
    /// Ground truth from the simulator (only when running on it).
    SimTruth(SimTruth),
    /// Something happened to a browser HMI session (the HMI sends these; the
    /// core acts on them like on any ground station's).
    Hmi {
        sysid: u8,
        event: HmiEvent,
    },
    /// The answer to [`Output::SaveParams`]: the parameters reached the disk,
    /// or why not.
    ParamsSaved(Result<(), String>),
    /// A PARAM_SET whose `param_type` is not a MAV_PARAM_TYPE value (the
    /// frame decoder cannot represent it as a message): answered with the
    /// parameter's current value.
    BadParamSet {
        from: Sender,
        target_system: u8,
        target_component: u8,
        param_id: [u8; 16],
        param_type: u8,
    },
    /// A COMMAND_LONG/COMMAND_INT whose number our dialect does not define.
    UnknownCommand {
        from: Sender,
        command: u16,
        target_system: u8,
        target_component: u8,
    },
    /// The video stream the camera component advertises (None: none runs).
    VideoStream(Option<VideoStreamInfo>),
    /// Whether anyone listens on an in-process endpoint (the browser
    /// sessions', mavlink2rest's) now. While nobody does, the telemetry
    /// streams of that endpoint are not built (other messages still go);
    /// when someone comes, every stream message whose time passed meanwhile
    /// goes out in the next pass, and then at the endpoint's rates.
    /// Endpoints start listened.
    Listeners {
        endpoint: usize,
        listened: bool,
    },
    /// The recorder's news: a recording started or stopped, the storage.
    Recorder(RecorderEvent),
    /// The disk worker's answer to an [`Output::Files`].
    Files(crate::files::FileReply),
    /// The file transfers may send what their pacing allows (due at
    /// [`Vehicle::next_transfer`]).
    Transfer,
}

/// Events of a browser HMI session that matter for safety.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HmiEvent {
    /// The window lost focus (the operator is looking elsewhere).
    FocusLost,
    /// The operator switched input device (keyboard, touch, gamepad).
    InputModeChanged,
    /// The session's WebSocket closed.
    Disconnected,
}

/// The simulated vehicle's true state, in plain units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimTruth {
    pub north_m: f64,
    pub east_m: f64,
    pub depth_m: f64,
    pub heading_rad: f64,
    pub surge_mps: f64,
    pub sway_mps: f64,
    pub heave_mps: f64,
    pub yaw_rate_rps: f64,
    /// Roll and pitch (0 in the 4-DOF model).
    pub roll_rad: f64,
    pub pitch_rad: f64,
}

/// What the core asks the I/O around it to do.
// Outputs live briefly in a reused Vec; boxing every message would cost an
// allocation per send for no gain.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    Send {
        to: To,
        msg: MavMessage,
    },
    /// A message sent like [`Output::Send`] but from another component of
    /// this system (the camera, [`CAMERA_COMPONENT_ID`]); on the wire and to
    /// mavlink2rest (the browser HMI hears only the camera's recording).
    SendAs {
        to: To,
        compid: u8,
        msg: MavMessage,
    },
    /// A STATUSTEXT (or one chunk of a long one), sent like
    /// [`Output::Send`], with what it is about (the browser HMI files it
    /// under that category).
    Text {
        to: To,
        topic: Topic,
        msg: MavMessage,
    },
    Board(Command),
    /// A command for the built-in simulator's board (run mode SIMULATOR).
    SimBoard(Command),
    /// The run mode changed: route thruster commands and telemetry
    /// accordingly; a new simulator starts at the given depth and heading.
    RunMode {
        mode: RunMode,
        start_depth_m: f64,
        start_heading_deg: f64,
    },
    /// Parameters changed: write `Vehicle::params()` to disk off the
    /// vehicle task, and answer with [`Input::ParamsSaved`]. Never asked
    /// again before that answer.
    SaveParams,
    /// The board's dead-man switch may be fed now: the core is alive and
    /// the owner showed life recently (or the vehicle is disarmed, or a
    /// failsafe action needs thrust).
    Healthy,
    /// A line for the event log.
    Log(LogEvent),
    /// A trusted SETUP_SIGNING: persist this key (all zero = signing off)
    /// and never let our signing timestamp fall below `initial_timestamp`.
    SetSigningKey {
        key: [u8; 32],
        initial_timestamp: u64,
    },
    /// COMMAND_ACK for a command number the dialect cannot represent, from
    /// component `compid` of this system.
    AckUnknown {
        to: To,
        compid: u8,
        command: u16,
        result: MavResult,
        target_system: u8,
        target_component: u8,
    },
    /// The ground station in control gave the time: from now on the wall
    /// clock (logs, `Now::unix_us`) is `unix_us`, carried forward.
    SetWallClock {
        unix_us: u64,
    },
    /// Start or stop recording on the vehicle (answered: [`Input::Recorder`]).
    Record(RecordControl),
    /// A row of the telemetry written beside the recording.
    RecordSample(RecordSample),
    /// File data for one station (LOG_DATA, FTP replies), sent like
    /// [`Output::Send`] on the wire only: never into the telemetry log
    /// (it is a copy of what is on the disk) nor to the in-process stations.
    Bulk {
        to: To,
        msg: MavMessage,
    },
    /// A request for the disk worker; its answer comes back as
    /// [`Input::Files`].
    Files(crate::files::FileRequest),
}

impl Output {
    /// The MAVLink message this output sends, and where ([`Output::Send`]
    /// and [`Output::Text`]).
    pub fn message(&self) -> Option<(To, &MavMessage)> {
        match self {
            Output::Send { to, msg } | Output::Text { to, msg, .. } => Some((*to, msg)),
            _ => None,
        }
    }
}
