//! Telemetry scheduling: which message is due on which endpoint, at what
//! interval, following ArduSub's defaults and honouring
//! SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM and REQUEST_MESSAGE.
//!
//! Pure: intervals are plain numbers and "now" is an argument. Building the
//! messages is the vehicle's job; this module only keeps the schedule.

use std::collections::BTreeMap;
use std::time::Duration;

use mavlink_core::MessageData;

use crate::dialect::neptunus::*;

/// Message ids Neptunus can stream, with ArduSub's default rate in Hz
/// (0 = not streamed unless asked for).
pub const STREAMABLE: &[(u32, f64)] = &[
    (HEARTBEAT_DATA::ID, 1.0),
    (SYS_STATUS_DATA::ID, 2.0),
    (SYSTEM_TIME_DATA::ID, 3.0),
    (ATTITUDE_DATA::ID, 10.0),
    (GLOBAL_POSITION_INT_DATA::ID, 3.0),
    (SERVO_OUTPUT_RAW_DATA::ID, 2.0),
    // The autopilot's setpoints and errors.
    (NAV_CONTROLLER_OUTPUT_DATA::ID, 4.0),
    (VFR_HUD_DATA::ID, 10.0),
    (SCALED_PRESSURE2_DATA::ID, 2.0),
    // The depth sensor in the first barometer slot too (the only one).
    (SCALED_PRESSURE_DATA::ID, 2.0),
    // Attitude and altitude (Cockpit's depth indicator), the estimator's health.
    (AHRS2_DATA::ID, 3.0),
    (EKF_STATUS_REPORT_DATA::ID, 3.0),
    (BATTERY_STATUS_DATA::ID, 3.0),
    // The board's free RAM (with EXTRA3, as ArduPilot sends its own).
    (MEMINFO_DATA::ID, 0.0),
    // A group: Lights1, PilotGain, CamTilt, Laser …
    (NAMED_VALUE_FLOAT_DATA::ID, 2.0),
    (CONTROL_STATUS_DATA::ID, 1.0),
    // Only while simulating.
    (NEPTUNUS_SIM_STATE_DATA::ID, 10.0),
    // Raw readings beside the estimates.
    (NEPTUNUS_ESTIMATE_DATA::ID, 10.0),
    // Setpoints and controller outputs.
    (NEPTUNUS_AUTOPILOT_DATA::ID, 4.0),
    // The camera tilt as a gimbal (protocol v2): QGC needs both to show it.
    (GIMBAL_MANAGER_STATUS_DATA::ID, 1.0),
    (GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID, 5.0),
];

/// Legacy REQUEST_DATA_STREAM groups, as ArduPilot maps them for a submarine.
pub fn stream_group(stream_id: u8) -> &'static [u32] {
    match stream_id {
        // RAW_SENSORS
        1 => &[SCALED_PRESSURE_DATA::ID, SCALED_PRESSURE2_DATA::ID],
        // EXTENDED_STATUS (with the controllers, as ArduPilot)
        2 => &[
            SYS_STATUS_DATA::ID,
            NAV_CONTROLLER_OUTPUT_DATA::ID,
            NEPTUNUS_AUTOPILOT_DATA::ID,
        ],
        // RC_CHANNELS
        3 => &[SERVO_OUTPUT_RAW_DATA::ID],
        // POSITION
        6 => &[GLOBAL_POSITION_INT_DATA::ID],
        // EXTRA1 (attitude and the estimates)
        10 => &[ATTITUDE_DATA::ID, NEPTUNUS_ESTIMATE_DATA::ID],
        // EXTRA2
        11 => &[VFR_HUD_DATA::ID],
        // EXTRA3
        12 => &[
            SYSTEM_TIME_DATA::ID,
            BATTERY_STATUS_DATA::ID,
            MEMINFO_DATA::ID,
            NAMED_VALUE_FLOAT_DATA::ID,
            AHRS2_DATA::ID,
            EKF_STATUS_REPORT_DATA::ID,
        ],
        _ => &[],
    }
}

/// All groups, for stream id 0 (ALL).
pub const ALL_GROUPS: [u8; 7] = [1, 2, 3, 6, 10, 11, 12];

/// Default interval of a streamable message, if it has one.
pub fn default_interval(msg_id: u32) -> Option<Duration> {
    STREAMABLE
        .iter()
        .find(|(id, _)| *id == msg_id)
        .and_then(|(_, hz)| (*hz > 0.0).then(|| Duration::from_secs_f64(1.0 / hz)))
}

/// Messages ArduPilot takes a rate for (its table from MAVLink ids to the
/// messages it schedules) that this vehicle has nothing to fill with: no
/// GPS, raw IMU, RC input, rangefinder, vibration or home position. Asked
/// for, they are ACCEPTED and nothing is sent — what ArduSub answers and
/// does for a sensor it lacks — so a ground station made for ArduSub
/// (Cockpit asks for 36 at connect) reports no error ArduSub would not
/// cause. REQUEST_MESSAGE for one of them is ACCEPTED with nothing sent
/// too, as ArduSub answers for HOME_POSITION before it has a home.
// HWSTATUS and BATTERY2 are deprecated in the XML, still scheduled by ArduPilot.
#[allow(deprecated)]
pub const ARDUPILOT_NOTHING_TO_SEND: &[u32] = &[
    PARAM_VALUE_DATA::ID,
    GPS_RAW_INT_DATA::ID,
    SCALED_IMU_DATA::ID,
    RAW_IMU_DATA::ID,
    ATTITUDE_QUATERNION_DATA::ID,
    LOCAL_POSITION_NED_DATA::ID,
    RC_CHANNELS_SCALED_DATA::ID,
    RC_CHANNELS_RAW_DATA::ID,
    MISSION_CURRENT_DATA::ID,
    MISSION_ITEM_REACHED_DATA::ID,
    GPS_GLOBAL_ORIGIN_DATA::ID,
    RC_CHANNELS_DATA::ID,
    ATTITUDE_TARGET_DATA::ID,
    POSITION_TARGET_LOCAL_NED_DATA::ID,
    POSITION_TARGET_GLOBAL_INT_DATA::ID,
    OPTICAL_FLOW_DATA::ID,
    SCALED_IMU2_DATA::ID,
    GPS2_RAW_DATA::ID,
    POWER_STATUS_DATA::ID,
    GPS_RTK_DATA::ID,
    GPS2_RTK_DATA::ID,
    SCALED_IMU3_DATA::ID,
    DISTANCE_SENSOR_DATA::ID,
    TERRAIN_REQUEST_DATA::ID,
    SCALED_PRESSURE3_DATA::ID,
    FENCE_STATUS_DATA::ID,
    AHRS_DATA::ID,
    HWSTATUS_DATA::ID,
    WIND_DATA::ID,
    RANGEFINDER_DATA::ID,
    CAMERA_FEEDBACK_DATA::ID,
    BATTERY2_DATA::ID,
    MAG_CAL_PROGRESS_DATA::ID,
    MAG_CAL_REPORT_DATA::ID,
    PID_TUNING_DATA::ID,
    RPM_DATA::ID,
    VIBRATION_DATA::ID,
    HOME_POSITION_DATA::ID,
    EXTENDED_SYS_STATE_DATA::ID,
    ADSB_VEHICLE_DATA::ID,
    AUTOPILOT_STATE_FOR_GIMBAL_DEVICE_DATA::ID,
];

/// Whether ArduPilot would take a rate for `msg_id` that we have nothing to send for.
pub fn nothing_to_send(msg_id: u32) -> bool {
    ARDUPILOT_NOTHING_TO_SEND.contains(&msg_id)
}

pub fn is_streamable(msg_id: u32) -> bool {
    STREAMABLE.iter().any(|(id, _)| *id == msg_id)
}

/// Messages made from the board's navigation line (heading, depth,
/// attitude and the estimates they update). At about the lines' rate or
/// faster they follow the lines: each goes out when a line arrives, at most
/// at its rate (a line that comes sooner waits for the interval), so a
/// ground station and the browser see a reading as soon as the vehicle has
/// it. Asked for faster than the lines come, the last values are repeated
/// on the message's own clock to keep the asked rate, as ArduSub keeps it.
/// Slower (two line periods or more, as GLOBAL_POSITION_INT and AHRS2 at
/// ArduSub's 3 Hz) they keep their own clock like any other message and go
/// with the last line before they are due: following the lines one for one
/// would round their interval to whole line periods (3 Hz would become
/// 3.3 Hz), and waiting for the line after would cost a wake-up of its own
/// between lines, for values no newer than the line's.
pub const NAV_FED: &[u32] = &[
    ATTITUDE_DATA::ID,
    GLOBAL_POSITION_INT_DATA::ID,
    VFR_HUD_DATA::ID,
    AHRS2_DATA::ID,
    NEPTUNUS_ESTIMATE_DATA::ID,
];

/// How early a line may come and still go out at once: the board's line
/// timing jitters by a few milliseconds, and a line a little early must not
/// wait a whole interval. At most a quarter of the interval, so a stream
/// slower than the lines keeps its rate.
const EARLY: Duration = Duration::from_millis(15);

fn early(interval: Duration) -> Duration {
    EARLY.min(interval / 4)
}

/// The board's navigation line period (10 Hz).
pub const LINE_GATHER: Duration = Duration::from_millis(100);

/// How late a navigation line may come and still be the one that carries
/// what is due with it: the board's timing jitters by a few milliseconds,
/// and something due just as the next line comes must not wake the vehicle
/// a moment before it.
pub const LINE_SLACK: Duration = Duration::from_millis(25);

/// How far ahead of its time something clocked (a message, the camera's
/// heartbeat) may go with a navigation line: a line period and its slack,
/// so one line always comes in time while they come on their beat (for
/// something faster than the lines, its own interval and the slack). Its
/// clock keeps its grid, so its average rate is exact, and it goes at most
/// once per line.
pub fn gather(interval: Duration) -> Duration {
    (LINE_GATHER + LINE_SLACK).min(interval + LINE_SLACK)
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Slot {
    interval: Duration,
    next_due: Duration,
    /// Made from the navigation line ([`NAV_FED`]) and fast enough to
    /// follow the lines one for one.
    fed: bool,
    /// A line arrived that has not gone out yet (it came early: it goes
    /// at its deadline, unless a newer line comes first).
    waiting: bool,
}

impl Slot {
    fn new(msg_id: u32, interval: Duration, next_due: Duration) -> Self {
        Self {
            interval,
            next_due,
            fed: NAV_FED.contains(&msg_id) && interval < 2 * LINE_GATHER,
            waiting: false,
        }
    }

    /// When it next goes out without new input: at `next_due`, but a fed
    /// message gives a late line its slack ([`LINE_SLACK`], at most a
    /// quarter of its interval) before it repeats the last values, or
    /// sends a line that came too early (a newer line arriving in the
    /// slack goes instead).
    fn deadline(&self) -> Duration {
        if self.fed {
            self.next_due + LINE_SLACK.min(self.interval / 4)
        } else {
            self.next_due
        }
    }

    /// Gone out at `now`. A line sets the next one an interval later (the
    /// grid follows the lines); otherwise the grid is kept, so the average
    /// rate is exact and a late tick does not cause a burst of catch-up sends.
    fn sent(&mut self, now: Duration) {
        let line = std::mem::take(&mut self.waiting);
        if self.fed && line {
            self.next_due = now + self.interval;
            return;
        }
        self.next_due += self.interval;
        if self.next_due <= now {
            self.next_due = now + self.interval;
        }
    }
}

/// One endpoint's schedule.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Schedule {
    slots: BTreeMap<u32, Slot>,
}

/// No message is streamed faster than 50 Hz, whoever asks: the board
/// reports navigation at 10 Hz, so faster only repeats values, and 50 Hz is
/// the top of ArduPilot's own SRn_* stream-rate range. It bounds what one
/// request can cost an endpoint (17 messages at 50 Hz is about 35 kB/s).
pub const MIN_INTERVAL: Duration = Duration::from_millis(20);

/// The slowest a message may be made, if it must be sent at all: HEARTBEAT
/// stays at 1 Hz or faster, because ground stations detect link loss from
/// it (QGC after a few seconds, MAVProxy's "link down", our own GCS
/// failsafe on their side).
pub fn max_interval(msg_id: u32) -> Option<Duration> {
    (msg_id == HEARTBEAT_DATA::ID).then_some(Duration::from_secs(1))
}

/// Whether a message may be turned off (HEARTBEAT may not).
pub fn may_disable(msg_id: u32) -> bool {
    max_interval(msg_id).is_none()
}

impl Schedule {
    /// ArduSub's default streams, starting at `now`.
    pub fn with_defaults(now: Duration) -> Self {
        let mut s = Self::default();
        for (id, _) in STREAMABLE {
            if let Some(iv) = default_interval(*id) {
                s.slots.insert(*id, Slot::new(*id, iv, now));
            }
        }
        s
    }

    /// Sets an interval, kept within [`MIN_INTERVAL`] and the message's
    /// [`max_interval`]; `None` stops the message (unless it may not be
    /// stopped: then it runs at its slowest allowed interval).
    pub fn set(&mut self, msg_id: u32, interval: Option<Duration>, now: Duration) {
        let interval = match (interval, max_interval(msg_id)) {
            (None, Some(slowest)) => Some(slowest),
            (Some(iv), Some(slowest)) => Some(iv.min(slowest)),
            (iv, None) => iv,
        };
        match interval {
            None => {
                self.slots.remove(&msg_id);
            }
            Some(iv) => {
                let iv = iv.max(MIN_INTERVAL);
                let old = self.slots.get(&msg_id);
                let next_due = old.map_or(now, |s| s.next_due.min(now + iv));
                let mut slot = Slot::new(msg_id, iv, next_due);
                slot.waiting = old.is_some_and(|s| s.waiting);
                self.slots.insert(msg_id, slot);
            }
        }
    }

    /// The current interval (`None` = not streamed).
    pub fn interval(&self, msg_id: u32) -> Option<Duration> {
        self.slots.get(&msg_id).map(|s| s.interval)
    }

    /// Message ids due at `now`; each is rescheduled one interval later.
    pub fn due(&mut self, now: Duration, out: &mut Vec<u32>) {
        for (id, slot) in &mut self.slots {
            if now >= slot.deadline() {
                out.push(*id);
                slot.sent(now);
            }
        }
    }

    /// A navigation line arrived at `now`: the fed messages whose interval
    /// has (nearly) passed are due at once; the others wait for it. A
    /// clocked message due before the next line is expected goes with
    /// this one: the vehicle is awake for the line anyway, and an idle
    /// vehicle then wakes for little but the lines. Its grid is kept, so its
    /// rate stays exact; it leaves at most [`LINE_GATHER`] early.
    pub fn line_arrived(&mut self, now: Duration, out: &mut Vec<u32>) {
        for (id, slot) in &mut self.slots {
            if !slot.fed {
                if now + gather(slot.interval) >= slot.next_due {
                    out.push(*id);
                    slot.sent(now);
                }
                continue;
            }
            if now + early(slot.interval) >= slot.next_due {
                out.push(*id);
                slot.waiting = true;
                slot.sent(now);
            } else {
                slot.waiting = true;
            }
        }
    }

    /// When a message is next due without new input: the vehicle need not
    /// wake before then for this schedule (None: nothing is).
    pub fn next_deadline(&self) -> Option<Duration> {
        self.slots.values().map(Slot::deadline).min()
    }
}
