//! Flags over the file over defaults: the resolved [`Settings`] of the
//! vehicle, and the emulator options of `emulate-board`.
//!
//! Owns [`Settings`], [`MavlinkSettings`], [`BoardSource`] and the merge
//! itself; the `[hmi]` section has its own file (`hmi`). Every error names
//! the setting, its value and the fix.

use std::path::{Path, PathBuf};

use super::cli::{EmulateArgs, RunArgs};
use super::file::FileConfig;
use super::hmi::resolve_hmi;
use super::{ConfigError, DEFAULT_BAUD, DEFAULT_SERIAL, default_data_dir};
use crate::firmware::codec::Framing;
use crate::firmware::emulator::{EmulatorOptions, FaultOptions, FirmwareVersion};
use crate::firmware::link::LinkConfig;
use crate::mavlink::endpoint::{DEFAULT_ENDPOINTS, EndpointUrl};
use crate::vehicle::machine::Identity;

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
    /// The genuine firmware in simavr behind an internal pseudo-terminal,
    /// driving the simulator of these options (`--hil`).
    Genuine {
        firmware: PathBuf,
        emulator: EmulatorOptions,
    },
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
    /// The free-space floor and total cap of logs and recordings.
    pub storage: crate::camera::record::StorageConfig,
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
    let framing = args.framing.or(file.board.framing);
    link.framing = framing.unwrap_or_default();
    // --serial on the command line wins over `sim = true` in the file.
    let sim = args.hil.is_some() || args.sim || (file.sim && args.serial.is_none());
    let board = if let Some(firmware) = &args.hil {
        // The link's framing follows the firmware once it is built.
        BoardSource::Genuine {
            firmware: firmware.clone(),
            emulator: file.emulator.clone(),
        }
    } else if sim {
        let mut emu = file.emulator.clone();
        match framing {
            // The link speaks what it was told; the emulated board follows
            // (plain framing is the 2014-12 firmware's).
            Some(f) => {
                check_firmware_framing(emu.firmware, f, "--framing / [board] framing")?;
                emu.framing = f;
            }
            // Not told: the link speaks the emulated firmware's framing.
            None => {
                link.framing = emu.effective_framing();
                emu.framing = link.framing;
            }
        }
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
        camera: {
            let mut camera = match &file.camera {
                Some(c) => c.clone(),
                None if sim => crate::camera::CameraConfig::synthetic(),
                None => crate::camera::CameraConfig::default(),
            };
            if !args.video_rtp.is_empty() {
                camera.rtp = args.video_rtp.clone();
            }
            if let Some(on) = args.webrtc {
                camera.webrtc.enabled = on == super::cli::OnOff::On;
            }
            if let Some(addr) = args.webrtc_signalling {
                camera.webrtc.signalling = Some(addr);
            }
            if !args.ice_server.is_empty() {
                camera.webrtc.ice_servers = args.ice_server.clone();
            }
            camera
                .validate()
                .map_err(|e| ConfigError::Invalid(format!("camera: {e}")))?;
            camera
        },
        storage: file.storage,
    })
}

/// The 2014-12 firmware has no CRC check: asking it for `crc8` is a mistake
/// worth saying (plain framing with 30.0.2 simply picks 2014-12).
fn check_firmware_framing(
    firmware: FirmwareVersion,
    framing: Framing,
    what: &str,
) -> Result<(), ConfigError> {
    if firmware == FirmwareVersion::V2014_12 && framing == Framing::Crc8 {
        return Err(ConfigError::Invalid(format!(
            "{what} crc8 with emulator firmware 2014-12 — that firmware speaks plain framing: \
             use framing plain, or firmware 30.0.2"
        )));
    }
    Ok(())
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
    if let Some(v) = args.firmware {
        emu.firmware = v;
    }
    if let Some(f) = args.framing {
        check_firmware_framing(emu.firmware, f, "--framing")?;
        emu.framing = f;
    }
    emu.framing = emu.effective_framing();
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
