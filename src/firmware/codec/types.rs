//! Board → host: what a decoded line yields.
//!
//! Owns the typed telemetry ([`NavSample`], [`StatusSample`], [`Event`]),
//! why a line was dropped ([`RejectReason`]) and the decoder's counters
//! ([`DecodeStats`]). Plain data; no parsing here.

/// The navigation line (10 Hz). Fields absent from the line are `None`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NavSample {
    /// `hdgd`, 0..360.
    pub heading_deg: Option<f64>,
    /// `deep` (or `deap` before March 2015), -10..200.
    pub depth_m: Option<f64>,
    /// `pitc`, -180..180.
    pub pitch_deg: Option<f64>,
    /// `roll`, -180..180.
    pub roll_deg: Option<f64>,
    /// `yaw` (raw), -180..360: the MPU9150 driver's −180..180, or the
    /// BNO055 driver's heading (0..360).
    pub yaw_deg: Option<f64>,
    /// `fthr` forward thrust, -100..100 %.
    pub fthr_pct: Option<f64>,
}

/// The status line (1 Hz). Fields absent from the line are `None`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StatusSample {
    /// `vout` supply voltage, 0..30.
    pub vout_v: Option<f64>,
    /// `iout` board current, 0..20.
    pub iout_a: Option<f64>,
    /// Battery current, 0..40: `BT1I` + `BT2I` (0..20 each), the two battery
    /// tubes' current sensors of controller board 2.5 (either alone if only
    /// one is on the line; a key twice on a line counts once, the last).
    pub battery_current_a: Option<f64>,
    /// `BRDT` controller-board temperature, -40..125.
    pub board_temp_c: Option<f64>,
    /// `pres` pressure, 0..30000.
    pub pres_mbar: Option<f64>,
    /// `temp` water temperature, -10..60.
    pub temp_c: Option<f64>,
    /// `time` board uptime (printed as a float, `912.00`), 0..=2^32.
    pub time_ms: Option<u64>,
    /// `fmem` free RAM (printed as a float), 0..65535.
    pub fmem_bytes: Option<u32>,
    /// `motorAttached` 0/1.
    pub motor_attached: Option<bool>,
    /// `servo` tilt servo current pulse width, 500..2500.
    pub servo_us: Option<u16>,
    /// `starg` tilt servo target pulse width, 500..2500.
    pub starg_us: Option<u16>,
    /// `mtarg` motor targets (port, vertical, starboard), each 500..2500.
    pub mtarg_us: Option<[u16; 3]>,
    /// `motors` actual motor outputs, each 500..2500.
    pub motors_us: Option<[u16; 3]>,
    /// `ver` firmware version text.
    pub version: Option<String>,
    /// `cmpd` when the firmware was compiled (date, time and compiler).
    pub compiled: Option<String>,
}

/// One thing the board said.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// Navigation keys of one line.
    Nav(NavSample),
    /// Status keys of one line.
    Status(StatusSample),
    /// `boot:1;`
    Boot,
    /// `CAPA:<bitmask>;`
    Capabilities(u32),
    /// `crc:pass;`
    CrcPass,
    /// `crc:fail,<calc>/<got>;` (hexadecimal, as the board prints them).
    CrcFail { calc: u8, got: u8 },
    /// `cmd:<text>;` the board's echo of a command it accepted.
    CmdEcho(String),
    /// `rawcmd:<hex>,;` the bytes the board received, verbatim.
    RawCmd(String),
    /// `pong:<anything>;`
    Pong(String),
    /// `LIGT:n;` with `LIGP:fraction;` from the same line.
    Lights { level: u8, fraction: Option<f64> },
    /// `claser:n;`
    Laser(u8),
    /// `log:<text>;`, or a `log:` line the board printed without its `;`
    /// (`log:Failed to read Depth from I2C`, once a second without the depth add-on).
    Log(String),
    /// `icmd:<text>;` a command the board queued for itself and now runs:
    /// `stop()` when its dead-man switch trips, `start()` when a ping ends
    /// that, `ligt(…)` while it blinks the lights, `lift(0)`/`yaw(0)` when
    /// it cancels its own holds.
    InternalCommand(String),
}

/// Why a whole line was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RejectReason {
    /// Not a clean sequence of `key:value;` pairs (lost bytes, merged lines).
    Torn,
    /// Longer than [`MAX_LINE_BYTES`](super::MAX_LINE_BYTES).
    Overlong,
    /// A numeric key whose value is not a plain decimal number.
    NonNumeric,
    /// A numeric key whose value lies outside its physical range.
    OutOfRange,
}

/// Counters kept by a [`LineDecoder`](super::LineDecoder).
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct DecodeStats {
    pub lines_accepted: u64,
    pub rejected_torn: u64,
    pub rejected_overlong: u64,
    pub rejected_non_numeric: u64,
    pub rejected_out_of_range: u64,
    /// Keys this decoder does not know, in accepted lines.
    pub unknown_keys: u64,
    /// Bytes that are neither printable ASCII nor a line terminator.
    pub garbage_bytes: u64,
    /// The board's free-text prints (no `;`, words with spaces: its sensors'
    /// set-up chatter such as `Depth: Calibration constants are:`),
    /// knowingly ignored.
    pub text_lines: u64,
    /// Lines whose `;` came on the next line (the board's `println` before
    /// `;`, as in its status line's `cmpd`), joined and decoded as one.
    pub joined_lines: u64,
}

impl DecodeStats {
    /// Lines rejected for any reason.
    pub fn rejected_total(&self) -> u64 {
        self.rejected_torn
            + self.rejected_overlong
            + self.rejected_non_numeric
            + self.rejected_out_of_range
    }

    /// Lines rejected for `reason`.
    pub fn rejected(&self, reason: RejectReason) -> u64 {
        match reason {
            RejectReason::Torn => self.rejected_torn,
            RejectReason::Overlong => self.rejected_overlong,
            RejectReason::NonNumeric => self.rejected_non_numeric,
            RejectReason::OutOfRange => self.rejected_out_of_range,
        }
    }

    pub(super) fn count_rejected(&mut self, reason: RejectReason) {
        let counter = match reason {
            RejectReason::Torn => &mut self.rejected_torn,
            RejectReason::Overlong => &mut self.rejected_overlong,
            RejectReason::NonNumeric => &mut self.rejected_non_numeric,
            RejectReason::OutOfRange => &mut self.rejected_out_of_range,
        };
        *counter += 1;
    }
}
