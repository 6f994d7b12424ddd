//! The TOML configuration file, one struct per section.
//!
//! Owns [`FileConfig`] and its sections (`[board]`, `[mavlink]`, `[hmi]`;
//! `[emulator]` and `[camera]` are their modules' own types), reading it
//! and the checks serde cannot express. Unknown keys are errors with line
//! and column; nothing here applies defaults (that is `resolve`).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::ConfigError;
use super::cli::TlsModeName;
use crate::firmware::codec::Framing;
use crate::firmware::emulator::EmulatorOptions;
use crate::sim::SimError;
use crate::vehicle::machine::Identity;

/// The configuration file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FileConfig {
    pub data_dir: Option<PathBuf>,
    pub sim: bool,
    pub board: BoardFileConfig,
    pub emulator: EmulatorOptions,
    pub mavlink: MavlinkFileConfig,
    /// Ground-station profiles directory replacing the built-in profiles.
    pub profiles_dir: Option<PathBuf>,
    pub hmi: HmiFileConfig,
    /// `[camera]`: the video source (default: `synthetic` with `--sim`,
    /// mjpg-streamer on the vehicle).
    pub camera: Option<crate::camera::CameraConfig>,
    /// `[storage]`: the free-space floor and the total cap of logs and
    /// recordings.
    pub storage: crate::camera::record::StorageConfig,
}

/// `[hmi]` section: the browser HMI.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HmiFileConfig {
    /// Listen address (`HOST:PORT`) or "off".
    pub http: Option<String>,
    /// System ids lent to browser sessions, one each.
    pub sysid_min: Option<u8>,
    pub sysid_max: Option<u8>,
    /// Client addresses that may pilot without the pilot password:
    /// "none", "loopback" (default) or "private". Ignored with signing on.
    pub open_control: Option<crate::hmi::auth::OpenControl>,
    /// Origins (`scheme://host[:port]`) besides the page's own that may use
    /// the WebSocket and the REST API.
    pub allowed_origins: Option<Vec<String>>,
    /// Sessions holding no system id (watch only) at once.
    pub max_watchers: Option<usize>,
    /// No longer read: the password is stored hashed by `neptunus hmi
    /// set-password`. Kept only to say so, with its line and column.
    #[serde(skip_serializing)]
    pub pilot_password: Option<toml::Spanned<toml::Value>>,
    /// Rotation of the camera image in the page: 0, 90, 180 or 270.
    pub camera_rotation_deg: Option<i32>,
    /// Open HTTP connections in all (default 128).
    pub max_connections: Option<usize>,
    /// Open HTTP connections from one client address (default 32).
    pub max_connections_per_address: Option<usize>,
    /// Seconds a client has to send its request headers (and finish the TLS
    /// handshake); idle keep-alive connections close after it (default 10).
    pub header_timeout_s: Option<f64>,
    /// "off" (default), "self-signed" or "files".
    pub tls: Option<TlsModeName>,
    /// PEM certificate (chain) for `tls = "files"`.
    pub tls_cert: Option<PathBuf>,
    /// PEM private key for `tls = "files"`.
    pub tls_key: Option<PathBuf>,
    /// Extra DNS names or IP addresses for the self-signed certificate.
    pub tls_names: Option<Vec<String>>,
}

/// `[mavlink]` section.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MavlinkFileConfig {
    /// Endpoint URLs (replace the defaults).
    pub endpoints: Option<Vec<String>>,
    pub identity: Option<Identity>,
    /// Our system id (sets SYSID_THISMAV at start).
    pub sysid: Option<u8>,
    /// UDP peers are forgotten after this many seconds of silence.
    pub peer_timeout_s: Option<f64>,
    /// Telemetry logs rotate at this size.
    pub tlog_max_mb: Option<u64>,
    /// All telemetry logs together stay under this (oldest deleted first).
    pub tlog_total_mb: Option<u64>,
}

/// `[board]` section.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoardFileConfig {
    pub serial: Option<PathBuf>,
    pub baud: Option<u32>,
    pub framing: Option<Framing>,
}

impl FileConfig {
    /// Reads and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.into(),
            source,
        })?;
        Self::parse(&text).map_err(|message| ConfigError::Parse {
            path: path.into(),
            message,
        })
    }

    /// Parses TOML text; the error text carries line and column.
    pub fn parse(text: &str) -> Result<Self, String> {
        let cfg: Self = toml::from_str(text).map_err(|e| e.to_string().trim_end().to_owned())?;
        if let Some(old) = &cfg.hmi.pilot_password {
            let (line, column) = line_column(text, old.span().start);
            return Err(format!(
                "line {line}, column {column}: hmi.pilot_password is no longer read — a password in a config file is readable by anyone who can read the file; remove the line and run `neptunus hmi set-password` on the vehicle (stores it hashed in DATA_DIR/hmi-password)"
            ));
        }
        cfg.validate()?;
        Ok(cfg)
    }

    fn validate(&self) -> Result<(), String> {
        let f = &self.emulator.faults;
        for (name, p) in [
            ("garbage", f.garbage),
            ("torn", f.torn),
            ("wild", f.wild),
            ("dropped", f.dropped),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return Err(format!(
                    "emulator.faults.{name} = {p} is not a probability — use a value in 0..1"
                ));
            }
        }
        self.storage.validate()?;
        if self.board.baud == Some(0) {
            return Err("board.baud = 0 — use the board's baud rate, 115200".into());
        }
        for d in self.emulator.wiring_directions {
            if d != 1 && d != -1 {
                return Err(format!(
                    "emulator.wiring_directions contains {d} — each must be 1 or -1"
                ));
            }
        }
        match self.emulator.sim.validate() {
            Ok(()) => {}
            Err(SimError::Invalid { key, value, fix }) => {
                return Err(format!(
                    "emulator.sim.{key} = {value} is out of range — {fix}"
                ));
            }
            Err(e) => return Err(format!("emulator.sim: {e}")),
        }
        Ok(())
    }
}

/// 1-based line and column of byte `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}
