//! Command line and configuration file.
//!
//! Precedence: command-line flags, then the TOML file given by `--config`,
//! then built-in defaults. Unknown keys in the file are errors (with line and
//! column), so a misspelt setting never silently falls back to a default.
//!
//! One file per concern: `cli` (flags and subcommands), `file` (the TOML
//! file and its sections), `resolve` (the merge into [`Settings`]) and `hmi`
//! (the `[hmi]` section's checks); everything public is re-exported here.

mod cli;
mod file;
mod hmi;
mod resolve;

use std::path::PathBuf;

#[cfg(feature = "hil")]
pub use cli::GenuineArgs;
pub use cli::{
    Cli, CliCommand, EmulateArgs, HmiCommand, HttpAddr, OnOff, ProfilesCommand, RunArgs,
    SigningCommand, TlsModeName,
};
pub use file::{BoardFileConfig, FileConfig, HmiFileConfig, MavlinkFileConfig};
pub use resolve::{BoardSource, MavlinkSettings, Settings, resolve, resolve_emulator};

/// The BeagleBone UART wired to the OpenROV board.
pub const DEFAULT_SERIAL: &str = "/dev/ttyO1";
pub const DEFAULT_BAUD: u32 = 115_200;

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

/// What a build without the `hil` feature answers when asked for the
/// genuine firmware; `example` is the command line that would work with it.
pub fn hil_not_built(example: &str) -> String {
    format!(
        "this neptunus was built without the genuine-firmware simulator: build it with the `hil` feature \
         (`cargo run --features hil -- {example}`; it needs Debian's gcc-avr avr-libc arduino-core-avr \
         libclang-dev libelf-dev libzstd-dev pkg-config)"
    )
}

/// The default data directory (`~/.local/share/neptunus` on Linux).
pub fn default_data_dir() -> Result<PathBuf, ConfigError> {
    directories::ProjectDirs::from("", "", "neptunus")
        .map(|d| d.data_dir().to_path_buf())
        .ok_or(ConfigError::NoDataDir)
}
