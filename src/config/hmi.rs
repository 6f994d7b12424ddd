//! Resolving the `[hmi]` section: listen address, system ids, who may
//! pilot, origins, connection limits and TLS.
//!
//! Owns the checks and defaults of the browser HMI's settings; the HMI
//! itself only receives the result ([`HmiSettings`](crate::hmi::HmiSettings)).

use super::ConfigError;
use super::cli::{HttpAddr, TlsModeName};
use super::file::HmiFileConfig;

/// `--http` and `--tls` over `[hmi]` over the defaults.
pub(super) fn resolve_hmi(
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
