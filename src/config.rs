//! Command line and configuration file.
//!
//! Precedence: command-line flags, then the TOML file given by `--config`,
//! then built-in defaults. Unknown keys in the file are errors (with line and
//! column), so a misspelt setting never silently falls back to a default.

use std::path::{Path, PathBuf};

use clap::{Args, Parser, Subcommand};
use serde::{Deserialize, Serialize};

use crate::firmware::codec::Framing;
use crate::firmware::emulator::{EmulatorOptions, FaultOptions};
use crate::firmware::link::LinkConfig;
use crate::mavlink::endpoint::{DEFAULT_ENDPOINTS, EndpointUrl};
use crate::sim::SimError;
use crate::vehicle::machine::Identity;

/// The BeagleBone UART wired to the OpenROV board.
pub const DEFAULT_SERIAL: &str = "/dev/ttyO1";
pub const DEFAULT_BAUD: u32 = 115_200;

/// Neptunus: onboard software for an OpenROV-based ROV.
#[derive(Debug, Parser)]
#[command(name = "neptunus", version, about, long_about = None)]
pub struct Cli {
    #[command(flatten)]
    pub run: RunArgs,
    #[command(subcommand)]
    pub command: Option<CliCommand>,
}

/// Options of the vehicle (the default command).
#[derive(Debug, Args, Default)]
pub struct RunArgs {
    /// Run with no hardware: the board emulator and simulator behind an
    /// internal pseudo-terminal (the real serial code path runs).
    #[arg(long, conflicts_with = "serial")]
    pub sim: bool,
    /// Serial device of the OpenROV board [default: /dev/ttyO1].
    #[arg(long, value_name = "PATH")]
    pub serial: Option<PathBuf>,
    /// Baud rate of the board's serial line [default: 115200].
    #[arg(long)]
    pub baud: Option<u32>,
    /// Command framing: crc8 (2015+ firmware) or plain (December 2014 firmware) [default: crc8].
    #[arg(long, value_name = "crc8|plain")]
    pub framing: Option<Framing>,
    /// TOML configuration file.
    #[arg(long, value_name = "FILE", global = true)]
    pub config: Option<PathBuf>,
    /// Where logs, parameters and telemetry logs go [default: the user's data directory].
    #[arg(long, value_name = "DIR", global = true)]
    pub data_dir: Option<PathBuf>,
    /// MAVLink endpoint, repeatable: udpin:HOST:PORT, udpout:HOST:PORT,
    /// tcpin:HOST:PORT, tcpout:HOST:PORT, serial:PATH:BAUD; add ?trusted
    /// to accept SETUP_SIGNING (the signing key) over it
    /// [default: udpout:127.0.0.1:14550 and tcpin:0.0.0.0:5760].
    #[arg(long = "mavlink", value_name = "URL")]
    pub mavlink: Vec<EndpointUrl>,
    /// How the vehicle presents itself: ardupilot (ArduSub-compatible) or generic.
    #[arg(long, value_name = "ardupilot|generic")]
    pub identity: Option<Identity>,
    /// Ground-station profiles directory (*.toml) replacing the built-in ones;
    /// checked at start.
    #[arg(long, value_name = "DIR")]
    pub profiles: Option<PathBuf>,
    /// Browser HMI address, or `off` [default: 0.0.0.0:8080]; port 0 picks a
    /// free port (logged, and written to DATA_DIR/http.addr).
    #[arg(long, value_name = "ADDR|off")]
    pub http: Option<HttpAddr>,
    /// TLS for the browser HMI: off, self-signed (made in DATA_DIR/tls/ on
    /// first use) or files ([hmi] tls_cert and tls_key) [default: off].
    #[arg(long, value_name = "off|self-signed|files")]
    pub tls: Option<TlsModeName>,
}

/// `--tls` and `[hmi] tls`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TlsModeName {
    Off,
    SelfSigned,
    Files,
}

impl std::str::FromStr for TlsModeName {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "off" => Ok(Self::Off),
            "self-signed" => Ok(Self::SelfSigned),
            "files" => Ok(Self::Files),
            _ => Err(format!(
                "\"{s}\" is not a TLS mode — use off, self-signed or files"
            )),
        }
    }
}

/// `--http`: an address to listen on, or `off`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HttpAddr {
    Off,
    At(std::net::SocketAddr),
}

impl std::str::FromStr for HttpAddr {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("off") {
            return Ok(Self::Off);
        }
        s.parse().map(Self::At).map_err(|_| {
            format!(
                "\"{s}\" is not an HTTP listen address — use HOST:PORT (e.g. 0.0.0.0:8080) or off"
            )
        })
    }
}

#[derive(Debug, Subcommand)]
pub enum CliCommand {
    /// Run the OpenROV board emulator on a new pseudo-terminal and print its path.
    EmulateBoard(EmulateArgs),
    /// Ground-station profiles (conventions per sender).
    Profiles {
        #[command(subcommand)]
        command: ProfilesCommand,
    },
    /// The MAVLink 2 signing key in the data directory.
    Signing {
        #[command(subcommand)]
        command: SigningCommand,
    },
    /// The browser HMI: pilot password (stored hashed) and TLS certificate.
    Hmi {
        #[command(subcommand)]
        command: HmiCommand,
    },
    /// Run the autopilot step-response scenarios on the simulator (simulated
    /// time, fixed seeds) and write a CSV and a PNG plot per scenario to DIR.
    SimReport {
        /// Output directory (created if missing).
        dir: PathBuf,
    },
}

/// `neptunus signing …` (the vehicle must not be running: it reads the key at start).
#[derive(Debug, Subcommand)]
pub enum SigningCommand {
    /// Set the key to SHA-256 of a passphrase, as QGroundControl and MAVProxy
    /// derive it. Without PASSPHRASE, one line is read from standard input
    /// (keeps it out of the shell history and the process list).
    SetPassphrase { passphrase: Option<String> },
    /// Remove the key: signing off.
    Clear,
    /// Say whether a key is set (never prints it).
    Status,
}

/// `neptunus hmi …` (takes effect at the next start of the vehicle).
#[derive(Debug, Subcommand)]
pub enum HmiCommand {
    /// Set the pilot password: asked twice on the terminal without echo,
    /// or one line read from standard input when it is not a terminal.
    /// Stored as an argon2 hash in DATA_DIR/hmi-password (mode 0600).
    SetPassword,
    /// Remove the pilot password.
    ClearPassword,
    /// Say whether a pilot password is set (never prints it).
    Status,
    /// Print the SHA-256 fingerprint of the HMI's TLS certificate (the one
    /// `[hmi] tls` serves; the self-signed one is made if it does not exist
    /// yet), to compare with what the browser shows.
    TlsFingerprint,
}

/// `neptunus profiles …`
#[derive(Debug, Subcommand)]
pub enum ProfilesCommand {
    /// Load and validate profiles; print each with its sysids, or the first
    /// error as file:line:column.
    Check {
        /// Directory of *.toml profiles [default: the built-in set].
        dir: Option<PathBuf>,
    },
}

/// Options of `emulate-board`.
#[derive(Debug, Args, Default)]
pub struct EmulateArgs {
    /// Also make a symlink at PATH pointing to the pseudo-terminal (stable across restarts).
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
    /// Command framing the emulated board expects.
    #[arg(long, value_name = "crc8|plain")]
    pub framing: Option<Framing>,
    /// Probability per telemetry line of garbage bytes in front of it.
    #[arg(long, value_name = "P")]
    pub garbage: Option<f64>,
    /// Probability per telemetry line of a torn line.
    #[arg(long, value_name = "P")]
    pub torn: Option<f64>,
    /// Probability per telemetry line of a wild point (0.1×, 10×, 100×).
    #[arg(long, value_name = "P")]
    pub wild: Option<f64>,
    /// Probability per telemetry line of the line being dropped.
    #[arg(long, value_name = "P")]
    pub dropped: Option<f64>,
    /// Seed of the fault generator.
    #[arg(long)]
    pub seed: Option<u64>,
}

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

/// MAVLink settings, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct MavlinkSettings {
    pub endpoints: Vec<EndpointUrl>,
    pub identity: Identity,
    pub sysid: Option<u8>,
    pub peer_timeout: std::time::Duration,
    pub tlog_max_bytes: u64,
    pub tlog_total_bytes: u64,
}

/// `[board]` section.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoardFileConfig {
    pub serial: Option<PathBuf>,
    pub baud: Option<u32>,
    pub framing: Option<Framing>,
}

/// Configuration errors, each naming the file, the place and the fix.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read configuration file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("configuration file {path} is invalid: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("configuration: {0}")]
    Invalid(String),
    #[error("no data directory: the user's home could not be determined — pass --data-dir DIR")]
    NoDataDir,
}

/// Where the vehicle's board is.
#[derive(Debug, Clone, PartialEq)]
#[allow(
    clippy::large_enum_variant,
    reason = "resolved once at start; boxing would only move the bytes"
)]
pub enum BoardSource {
    /// The emulator behind an internal pseudo-terminal.
    Simulated(EmulatorOptions),
    /// A real board on a serial device.
    Serial,
}

/// Everything the vehicle needs, resolved.
#[derive(Debug, Clone)]
pub struct Settings {
    pub board: BoardSource,
    /// For `Serial`, the device; for `Simulated`, filled in once the pty exists.
    pub link: LinkConfig,
    pub data_dir: PathBuf,
    pub mavlink: MavlinkSettings,
    /// `None`: the profiles built into the binary.
    pub profiles_dir: Option<PathBuf>,
    /// The built-in simulator of run mode SIMULATOR (the file's `[emulator]`,
    /// on a real board as in `--sim`).
    pub simulator: EmulatorOptions,
    pub hmi: crate::hmi::HmiSettings,
    pub camera: crate::camera::CameraConfig,
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

/// The default data directory (`~/.local/share/neptunus` on Linux).
pub fn default_data_dir() -> Result<PathBuf, ConfigError> {
    directories::ProjectDirs::from("", "", "neptunus")
        .map(|d| d.data_dir().to_path_buf())
        .ok_or(ConfigError::NoDataDir)
}

/// Resolves flags over the file over defaults.
pub fn resolve(args: &RunArgs) -> Result<Settings, ConfigError> {
    let file = match &args.config {
        Some(p) => FileConfig::load(p)?,
        None => FileConfig::default(),
    };
    let data_dir = match args.data_dir.clone().or(file.data_dir.clone()) {
        Some(d) => d,
        None => default_data_dir()?,
    };
    let device = args
        .serial
        .clone()
        .or(file.board.serial.clone())
        .unwrap_or_else(|| PathBuf::from(DEFAULT_SERIAL));
    let mut link = LinkConfig::new(device);
    link.baud = args.baud.or(file.board.baud).unwrap_or(DEFAULT_BAUD);
    if link.baud == 0 {
        return Err(ConfigError::Invalid(
            "--baud 0 — use the board's baud rate, 115200".into(),
        ));
    }
    link.framing = args.framing.or(file.board.framing).unwrap_or_default();
    // --serial on the command line wins over `sim = true` in the file.
    let sim = args.sim || (file.sim && args.serial.is_none());
    let board = if sim {
        let mut emu = file.emulator.clone();
        emu.framing = link.framing;
        BoardSource::Simulated(emu)
    } else {
        BoardSource::Serial
    };
    let endpoints = if !args.mavlink.is_empty() {
        args.mavlink.clone()
    } else if let Some(urls) = &file.mavlink.endpoints {
        urls.iter()
            .map(|u| {
                u.parse::<EndpointUrl>()
                    .map_err(|e| ConfigError::Invalid(format!("mavlink.endpoints: {e}")))
            })
            .collect::<Result<_, _>>()?
    } else {
        DEFAULT_ENDPOINTS
            .iter()
            .map(|u| {
                u.parse::<EndpointUrl>()
                    .map_err(|e| ConfigError::Invalid(e.to_string()))
            })
            .collect::<Result<_, _>>()?
    };
    let peer_timeout_s = file.mavlink.peer_timeout_s.unwrap_or(10.0);
    if !(peer_timeout_s > 0.0 && peer_timeout_s <= 86_400.0) {
        return Err(ConfigError::Invalid(format!(
            "mavlink.peer_timeout_s = {peer_timeout_s} — use a number of seconds in 0..86400"
        )));
    }
    let mavlink = MavlinkSettings {
        endpoints,
        identity: args.identity.or(file.mavlink.identity).unwrap_or_default(),
        sysid: file.mavlink.sysid,
        peer_timeout: std::time::Duration::from_secs_f64(peer_timeout_s),
        tlog_max_bytes: file.mavlink.tlog_max_mb.unwrap_or(64).clamp(1, 1 << 20) * 1024 * 1024,
        tlog_total_bytes: file.mavlink.tlog_total_mb.unwrap_or(256).clamp(1, 1 << 24) * 1024 * 1024,
    };
    Ok(Settings {
        board,
        link,
        data_dir,
        mavlink,
        profiles_dir: args.profiles.clone().or(file.profiles_dir.clone()),
        simulator: file.emulator.clone(),
        hmi: resolve_hmi(args.http, args.tls, &file.hmi, sim)?,
        camera: match &file.camera {
            Some(c) => {
                c.validate()
                    .map_err(|e| ConfigError::Invalid(format!("camera: {e}")))?;
                c.clone()
            }
            None if sim => crate::camera::CameraConfig::synthetic(),
            None => crate::camera::CameraConfig::default(),
        },
    })
}

/// `--http` and `--tls` over `[hmi]` over the defaults.
fn resolve_hmi(
    flag: Option<HttpAddr>,
    tls_flag: Option<TlsModeName>,
    file: &HmiFileConfig,
    sim: bool,
) -> Result<crate::hmi::HmiSettings, ConfigError> {
    let mut hmi = crate::hmi::HmiSettings::default();
    let from_file = file
        .http
        .as_deref()
        .map(|s| {
            s.parse::<HttpAddr>()
                .map_err(|e| ConfigError::Invalid(format!("hmi.http: {e}")))
        })
        .transpose()?;
    if let Some(addr) = flag.or(from_file) {
        hmi.http_explicit = true;
        hmi.http = match addr {
            HttpAddr::Off => None,
            HttpAddr::At(a) => Some(a),
        };
    }
    hmi.sysid_min = file.sysid_min.unwrap_or(hmi.sysid_min);
    hmi.sysid_max = file.sysid_max.unwrap_or(hmi.sysid_max);
    if hmi.sysid_min == 0 || hmi.sysid_min > hmi.sysid_max {
        return Err(ConfigError::Invalid(format!(
            "hmi.sysid_min = {}, hmi.sysid_max = {} — use 1 <= sysid_min <= sysid_max <= 255",
            hmi.sysid_min, hmi.sysid_max
        )));
    }
    // On the vehicle every browser logs in unless the configuration opens
    // control to some addresses (a reverse proxy or an SSH tunnel makes
    // every client loopback). A simulation moves no thruster: there a
    // browser on the same machine may pilot at once.
    hmi.open_control = file.open_control.unwrap_or(if sim {
        crate::hmi::auth::OpenControl::Loopback
    } else {
        crate::hmi::auth::OpenControl::None
    });
    hmi.allowed_origins = file
        .allowed_origins
        .iter()
        .flatten()
        .map(|o| {
            crate::hmi::auth::parse_origin(o)
                .map_err(|e| ConfigError::Invalid(format!("hmi.allowed_origins: {e}")))
        })
        .collect::<Result<_, _>>()?;
    hmi.max_watchers = file.max_watchers.unwrap_or(hmi.max_watchers);
    if hmi.max_watchers > 1000 {
        return Err(ConfigError::Invalid(format!(
            "hmi.max_watchers = {} — use 0..1000 (each watcher costs the vehicle a 20 Hz telemetry stream)",
            hmi.max_watchers
        )));
    }
    let rot = file.camera_rotation_deg.unwrap_or(0);
    if ![0, 90, 180, 270].contains(&rot) {
        return Err(ConfigError::Invalid(format!(
            "hmi.camera_rotation_deg = {rot} — use 0, 90, 180 or 270"
        )));
    }
    hmi.camera_rotation_deg = rot;
    hmi.limits = resolve_limits(file)?;
    hmi.tls = resolve_tls(tls_flag, file)?;
    Ok(hmi)
}

/// `[hmi] max_connections`, `max_connections_per_address`, `header_timeout_s`.
fn resolve_limits(file: &HmiFileConfig) -> Result<crate::hmi::server::Limits, ConfigError> {
    let mut limits = crate::hmi::server::Limits::default();
    let total = file.max_connections.unwrap_or(limits.max_connections);
    if !(1..=65_536).contains(&total) {
        return Err(ConfigError::Invalid(format!(
            "hmi.max_connections = {total} — use 1..65536 (each connection is a file descriptor; 128 suits a vehicle)"
        )));
    }
    let per = file
        .max_connections_per_address
        .unwrap_or(limits.max_connections_per_address.min(total));
    if per == 0 || per > total {
        return Err(ConfigError::Invalid(format!(
            "hmi.max_connections_per_address = {per} — use 1..={total} (at most hmi.max_connections), \
             so that one host cannot take every connection"
        )));
    }
    let timeout_s = file
        .header_timeout_s
        .unwrap_or(limits.header_timeout.as_secs_f64());
    if !(0.1..=300.0).contains(&timeout_s) {
        return Err(ConfigError::Invalid(format!(
            "hmi.header_timeout_s = {timeout_s} — use a number of seconds in 0.1..300 (10 is the default)"
        )));
    }
    limits.max_connections = total;
    limits.max_connections_per_address = per;
    limits.header_timeout = std::time::Duration::from_secs_f64(timeout_s);
    Ok(limits)
}

/// `--tls` over `[hmi] tls`, with its files and names checked.
fn resolve_tls(
    flag: Option<TlsModeName>,
    file: &HmiFileConfig,
) -> Result<crate::hmi::tls::TlsSettings, ConfigError> {
    use crate::hmi::tls::{TlsMode, TlsSettings};
    let mode = match flag.or(file.tls).unwrap_or(TlsModeName::Off) {
        TlsModeName::Off => TlsMode::Off,
        TlsModeName::SelfSigned => TlsMode::SelfSigned,
        TlsModeName::Files => match (&file.tls_cert, &file.tls_key) {
            (Some(cert), Some(key)) => TlsMode::Files {
                cert: cert.clone(),
                key: key.clone(),
            },
            _ => {
                return Err(ConfigError::Invalid(
                    "hmi.tls = \"files\" needs both hmi.tls_cert and hmi.tls_key (PEM files) — \
                     set them, or use tls = \"self-signed\""
                        .into(),
                ));
            }
        },
    };
    if !matches!(mode, TlsMode::Files { .. }) && (file.tls_cert.is_some() || file.tls_key.is_some())
    {
        return Err(ConfigError::Invalid(
            "hmi.tls_cert / hmi.tls_key are set but hmi.tls is not \"files\" — \
             set tls = \"files\" to serve them, or remove them"
                .into(),
        ));
    }
    let names = file.tls_names.clone().unwrap_or_default();
    for n in &names {
        if rustls::pki_types::ServerName::try_from(n.as_str()).is_err() {
            return Err(ConfigError::Invalid(format!(
                "hmi.tls_names contains \"{n}\" — each must be a DNS name (rov.local) or an IP address (192.168.2.2)"
            )));
        }
    }
    Ok(TlsSettings { mode, names })
}

/// Emulator options for `emulate-board`: flags over the file's `[emulator]`.
pub fn resolve_emulator(
    args: &EmulateArgs,
    config: Option<&Path>,
) -> Result<EmulatorOptions, ConfigError> {
    let file = match config {
        Some(p) => FileConfig::load(p)?,
        None => FileConfig::default(),
    };
    let mut emu = file.emulator;
    if let Some(f) = args.framing {
        emu.framing = f;
    }
    let faults: &mut FaultOptions = &mut emu.faults;
    for (slot, value, name) in [
        (&mut faults.garbage, args.garbage, "--garbage"),
        (&mut faults.torn, args.torn, "--torn"),
        (&mut faults.wild, args.wild, "--wild"),
        (&mut faults.dropped, args.dropped, "--dropped"),
    ] {
        if let Some(p) = value {
            if !(0.0..=1.0).contains(&p) {
                return Err(ConfigError::Invalid(format!(
                    "{name} {p} is not a probability — use a value in 0..1"
                )));
            }
            *slot = p;
        }
    }
    if let Some(seed) = args.seed {
        faults.seed = seed;
    }
    Ok(emu)
}
