//! The command line: the vehicle's flags, the subcommands and their options.
//!
//! Owns the clap types ([`Cli`], [`RunArgs`], [`CliCommand`] …) and the small
//! flag values that parse themselves ([`HttpAddr`], [`TlsModeName`]). Only
//! parsing here: merging with the file and the defaults is in `resolve`.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use serde::{Deserialize, Serialize};

use crate::firmware::codec::Framing;
use crate::firmware::emulator::FirmwareVersion;
use crate::mavlink::endpoint::EndpointUrl;
use crate::vehicle::machine::Identity;

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
    /// Hardware in the loop: as --sim, but the board is the genuine OpenROV
    /// firmware (FIRMWARE: a checkout of openrov-software-arduino, its
    /// OpenROV folder, or a built .elf) in the simavr AVR simulator, reading
    /// the simulator's sensors and driving its thrusters. Needs a build with
    /// the `hil` feature.
    #[arg(long, value_name = "FIRMWARE", conflicts_with_all = ["serial", "sim"])]
    pub hil: Option<PathBuf>,
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
    #[allow(
        rustdoc::broken_intra_doc_links,
        reason = "clap prints this comment as --help verbatim: [hmi] is the file's section, not a link"
    )]
    #[arg(long, value_name = "off|self-signed|files")]
    pub tls: Option<TlsModeName>,
    /// H.264 video over RTP, repeatable: udp://HOST:PORT, `auto` (port 5600
    /// of the ground station in control, else of the first heard on UDP
    /// that may control; with signing on, only signed frames count) or
    /// `off` [default: auto].
    #[arg(long = "video-rtp", value_name = "udp://HOST:PORT|auto|off")]
    pub video_rtp: Vec<crate::camera::rtp::RtpDest>,
    /// Video over WebRTC for Cockpit and the browser page, from the same
    /// H.264 encode as the RTP video: on or off [default: on]. Independent
    /// of --video-rtp: with `--video-rtp off` WebRTC viewers still watch.
    #[arg(long, value_name = "on|off")]
    pub webrtc: Option<OnOff>,
    /// The WebRTC signalling WebSocket (mavlink-camera-manager's protocol)
    /// on a port of its own, or `off` [default: port 6021, where Cockpit
    /// looks, on the HMI's address]; it is also on the HMI's port at /webrtc.
    #[arg(long, value_name = "ADDR|off")]
    pub webrtc_signalling: Option<crate::camera::webrtc::SignallingAddr>,
    /// ICE server for WebRTC viewers away from the tether, repeatable:
    /// stun:HOST[:PORT] (the vehicle asks it for its public address) or
    /// turn:HOST[:PORT] (for the browser; credentials in [camera.webrtc]
    /// ice_servers) [default: none].
    #[allow(
        rustdoc::broken_intra_doc_links,
        reason = "clap prints this comment as --help verbatim: [camera.webrtc] is the file's section, not a link"
    )]
    #[arg(long = "ice-server", value_name = "URL")]
    pub ice_server: Vec<crate::camera::webrtc::IceServer>,
    /// Check the configuration (file and flags), print what it resolves
    /// to, and exit: 0 when it is valid.
    #[arg(long)]
    pub check: bool,
}

/// `on` or `off`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OnOff {
    On,
    Off,
}

impl std::str::FromStr for OnOff {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "on" => Ok(Self::On),
            "off" => Ok(Self::Off),
            _ => Err(format!("\"{s}\" is neither on nor off")),
        }
    }
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
    /// Run the OpenROV board emulator on a new pseudo-terminal and print its
    /// path. It imitates a genuine firmware release (`--firmware`): the same
    /// bytes in give the same replies, set-up chatter and status lines, with
    /// the readings of the built-in simulator.
    EmulateBoard(EmulateArgs),
    /// Run the genuine OpenROV controller-board firmware in the simavr AVR
    /// simulator on a new pseudo-terminal and print its path (built with the
    /// `hil` feature).
    #[cfg(feature = "hil")]
    GenuineBoard(GenuineArgs),
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
    /// Check what the vehicle needs on this machine — the configuration, the
    /// serial device and a board answering on it (framing crc8 or plain),
    /// the camera, the ports, the data directory, the clock — one line each
    /// with the fix; exit status 0 only when all pass. Stop the service
    /// first: the vehicle holds the serial port.
    Doctor {
        /// One JSON object (`ok`, `checks`: name, ok, detail, fix) for scripts.
        #[arg(long)]
        json: bool,
    },
    /// Run the autopilot step-response scenarios on the simulator (simulated
    /// time, fixed seeds) and write a CSV and a PNG plot per scenario to DIR.
    SimReport {
        /// Also run them with the genuine OpenROV firmware in the loop
        /// (FIRMWARE as for --hil: a checkout of openrov-software-arduino,
        /// its OpenROV folder, or a built .elf), stepped on simulated time,
        /// and print its figures beside the simulator's; its files end in
        /// `-hil`. Needs a build with the `hil` feature.
        #[arg(long, value_name = "FIRMWARE")]
        hil: Option<PathBuf>,
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

/// Options of `genuine-board`.
#[cfg(feature = "hil")]
#[derive(Debug, Args)]
pub struct GenuineArgs {
    /// The firmware: a checkout of openrov-software-arduino (built with
    /// avr-gcc on first use and cached), its OpenROV folder, or a built .elf.
    #[arg(value_name = "FIRMWARE")]
    pub firmware: PathBuf,
    /// Also make a symlink at PATH pointing to the pseudo-terminal.
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
    /// Battery voltage on the board's voltage divider (V).
    #[arg(long, value_name = "V", default_value_t = 12.0)]
    pub battery_v: f64,
    /// A basic kit: no depth sensor on the board's I2C bus (the firmware
    /// then reads zeros and says so once a second).
    #[arg(long)]
    pub no_depth_sensor: bool,
    /// No BNO055 IMU on the board's I2C bus (the firmware then finds no
    /// IMU and prints a level attitude heading north).
    #[arg(long)]
    pub no_imu: bool,
    /// Build (or find in the cache) the firmware, print the built .elf's
    /// path and its framing, and exit: `--hil` and `genuine-board` take the
    /// .elf without building again.
    #[arg(long)]
    pub build_only: bool,
}

/// Options of `emulate-board`.
#[derive(Debug, Args, Default)]
pub struct EmulateArgs {
    /// Also make a symlink at PATH pointing to the pseudo-terminal (stable across restarts).
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
    /// Which genuine firmware the emulated board imitates: 30.0.2 (2015,
    /// crc8 framing, the default) or 2014-12 (December 2014, plain
    /// framing). Overrides `[emulator] firmware` of the config file.
    #[arg(long, value_name = "30.0.2|2014-12")]
    pub firmware: Option<FirmwareVersion>,
    /// Command framing the emulated board expects: plain picks the 2014-12
    /// firmware (the one that speaks it); crc8 with 2014-12 is refused.
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
