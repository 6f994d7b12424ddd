//! TLS for the HMI (`[hmi] tls`): the certificate, its key and the rustls
//! server configuration (ring provider, HTTP/1.1 only).
//!
//! Two sources: a self-signed certificate the vehicle makes on first use in
//! `DATA_DIR/tls/` (`cert.pem`, `key.pem` with mode 0600, each written to a
//! temporary file and renamed, so a power cut never leaves half a key) and
//! reuses afterwards, or the operator's own PEM files. The browser cannot
//! vouch for a self-signed certificate: the operator compares its SHA-256
//! fingerprint ([`fingerprint`], logged at start and printed by `neptunus hmi
//! tls-fingerprint`) with what the browser shows, once per browser.
//!
//! Must never: log or print key material, or silently replace an existing
//! certificate (its fingerprint is what operators have checked).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::durable;
use rustls::pki_types::pem::PemObject as _;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName};
use sha2::{Digest as _, Sha256};

/// Where the certificate comes from.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum TlsMode {
    /// Plain HTTP.
    #[default]
    Off,
    /// Made on first use in `DATA_DIR/tls/`, reused afterwards.
    SelfSigned,
    /// The operator's PEM files.
    Files { cert: PathBuf, key: PathBuf },
}

/// `[hmi] tls`, `tls_cert`, `tls_key`, `tls_names`, resolved.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TlsSettings {
    pub mode: TlsMode,
    /// Extra names (DNS names or IP addresses) for a self-signed certificate.
    pub names: Vec<String>,
}

/// Errors loading or making the certificate; each names the file and the fix.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    #[error("cannot read the HMI's TLS certificate {path}: {source} — {fix}")]
    ReadCert {
        path: PathBuf,
        source: std::io::Error,
        fix: &'static str,
    },
    #[error(
        "the HMI's TLS certificate {path} holds no PEM certificate ({why}) — it must contain \
         \"-----BEGIN CERTIFICATE-----\"; {fix}"
    )]
    BadCert {
        path: PathBuf,
        why: String,
        fix: &'static str,
    },
    #[error("cannot read the HMI's TLS key {path}: {source} — {fix}")]
    ReadKey {
        path: PathBuf,
        source: std::io::Error,
        fix: &'static str,
    },
    #[error(
        "the HMI's TLS key {path} holds no PEM private key ({why}) — it must contain \
         \"-----BEGIN PRIVATE KEY-----\" (or RSA / EC PRIVATE KEY); {fix}"
    )]
    BadKey {
        path: PathBuf,
        why: String,
        fix: &'static str,
    },
    #[error("the HMI's TLS key {key} does not go with the certificate {cert}: {why} — {fix}")]
    Mismatch {
        cert: PathBuf,
        key: PathBuf,
        why: String,
        fix: &'static str,
    },
    #[error("cannot make the HMI's self-signed certificate: {0}")]
    Generate(String),
    #[error("cannot write {path}: {source} — check that the data directory is writable")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

const FIX_FILES: &str =
    "check [hmi] tls_cert and tls_key (PEM files), or use tls = \"self-signed\"";
const FIX_SELF_SIGNED: &str = "delete the folder to have a new certificate made at the next start \
     (browsers will show a new fingerprint)";

/// A loaded certificate, ready to serve.
pub struct Loaded {
    pub config: Arc<rustls::ServerConfig>,
    /// The certificate file served.
    pub cert_path: PathBuf,
    /// SHA-256 of the certificate, colon hex as browsers show it.
    pub fingerprint: String,
    /// A self-signed certificate was made just now.
    pub generated: bool,
}

/// `DATA_DIR/tls/cert.pem` and `DATA_DIR/tls/key.pem`.
pub fn self_signed_paths(data_dir: &Path) -> (PathBuf, PathBuf) {
    let dir = data_dir.join("tls");
    (dir.join("cert.pem"), dir.join("key.pem"))
}

/// The rustls configuration for `settings` (`None` when TLS is off); makes
/// the self-signed certificate first if it does not exist yet.
pub fn load(settings: &TlsSettings, data_dir: &Path) -> Result<Option<Loaded>, TlsError> {
    let (cert, key, generated, fix) = match &settings.mode {
        TlsMode::Off => return Ok(None),
        TlsMode::SelfSigned => {
            let generated = ensure_self_signed(data_dir, &settings.names)?;
            let (cert, key) = self_signed_paths(data_dir);
            (cert, key, generated, FIX_SELF_SIGNED)
        }
        TlsMode::Files { cert, key } => (cert.clone(), key.clone(), false, FIX_FILES),
    };
    let chain = read_certs(&cert, fix)?;
    let fingerprint = fingerprint(&chain[0]);
    let key_der = read_key(&key, fix)?;
    let provider = Arc::new(rustls::crypto::aws_lc_rs::default_provider());
    let mut config = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| TlsError::Generate(e.to_string()))?
        .with_no_client_auth()
        .with_single_cert(chain, key_der)
        .map_err(|e| TlsError::Mismatch {
            cert: cert.clone(),
            key: key.clone(),
            why: e.to_string(),
            fix,
        })?;
    // The server speaks HTTP/1.1 only (WebSocket upgrades are HTTP/1.1).
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(Some(Loaded {
        config: Arc::new(config),
        cert_path: cert,
        fingerprint,
        generated,
    }))
}

/// The fingerprint of the certificate `settings` serves (making the
/// self-signed one if needed; with TLS off, the one `self-signed` would use).
pub fn served_fingerprint(
    settings: &TlsSettings,
    data_dir: &Path,
) -> Result<(PathBuf, String, bool), TlsError> {
    let (cert, generated, fix) = match &settings.mode {
        TlsMode::Files { cert, .. } => (cert.clone(), false, FIX_FILES),
        TlsMode::Off | TlsMode::SelfSigned => {
            let generated = ensure_self_signed(data_dir, &settings.names)?;
            (self_signed_paths(data_dir).0, generated, FIX_SELF_SIGNED)
        }
    };
    let chain = read_certs(&cert, fix)?;
    Ok((cert.clone(), fingerprint(&chain[0]), generated))
}

/// SHA-256 of a DER certificate as browsers show it: `AB:CD:…` (32 bytes).
pub fn fingerprint(der: &[u8]) -> String {
    Sha256::digest(der)
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(":")
}

fn read_certs(path: &Path, fix: &'static str) -> Result<Vec<CertificateDer<'static>>, TlsError> {
    let bytes = std::fs::read(path).map_err(|source| TlsError::ReadCert {
        path: path.into(),
        source,
        fix,
    })?;
    let chain = CertificateDer::pem_slice_iter(&bytes)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| TlsError::BadCert {
            path: path.into(),
            why: e.to_string(),
            fix,
        })?;
    if chain.is_empty() {
        return Err(TlsError::BadCert {
            path: path.into(),
            why: "no certificate section".into(),
            fix,
        });
    }
    Ok(chain)
}

fn read_key(path: &Path, fix: &'static str) -> Result<PrivateKeyDer<'static>, TlsError> {
    let bytes = std::fs::read(path).map_err(|source| TlsError::ReadKey {
        path: path.into(),
        source,
        fix,
    })?;
    PrivateKeyDer::from_pem_slice(&bytes).map_err(|e| TlsError::BadKey {
        path: path.into(),
        why: e.to_string(),
        fix,
    })
}

/// The names a self-signed certificate is made for: loopback, the machine's
/// host name (and `NAME.local` for mDNS), and `extra`. Names that are
/// neither a DNS name nor an IP address are skipped with a warning.
pub fn certificate_names(extra: &[String]) -> Vec<String> {
    let mut names: Vec<String> = vec!["localhost".into(), "127.0.0.1".into(), "::1".into()];
    if let Some(host) = hostname() {
        if !host.contains('.') {
            names.push(format!("{host}.local"));
        }
        names.push(host);
    }
    names.extend(extra.iter().cloned());
    let mut out: Vec<String> = Vec::new();
    for n in names {
        if out.contains(&n) {
            continue;
        }
        if ServerName::try_from(n.as_str()).is_err() {
            tracing::warn!(
                "TLS certificate: \"{n}\" is neither a DNS name nor an IP address, left out"
            );
            continue;
        }
        out.push(n);
    }
    out
}

fn hostname() -> Option<String> {
    let h = nix::unistd::gethostname().ok()?.into_string().ok()?;
    let h = h.trim().to_owned();
    (!h.is_empty()).then_some(h)
}

/// Makes the self-signed certificate in `DATA_DIR/tls/` unless both files
/// exist; returns whether it made one.
pub fn ensure_self_signed(data_dir: &Path, extra_names: &[String]) -> Result<bool, TlsError> {
    let (cert_path, key_path) = self_signed_paths(data_dir);
    if cert_path.is_file() && key_path.is_file() {
        return Ok(false);
    }
    let names = certificate_names(extra_names);
    let key = rcgen::KeyPair::generate().map_err(|e| TlsError::Generate(e.to_string()))?;
    let mut params =
        rcgen::CertificateParams::new(names).map_err(|e| TlsError::Generate(e.to_string()))?;
    // rcgen's validity (1975 to 4096) is kept: a vehicle without a real-time
    // clock must never serve a certificate its own clock calls expired or
    // not yet valid, and there is no CA to renew it with.
    params.distinguished_name = rcgen::DistinguishedName::new();
    params.distinguished_name.push(
        rcgen::DnType::CommonName,
        format!("Neptunus HMI {}", hostname().unwrap_or_default()).trim_end(),
    );
    params.extended_key_usages = vec![rcgen::ExtendedKeyUsagePurpose::ServerAuth];
    let cert = params
        .self_signed(&key)
        .map_err(|e| TlsError::Generate(e.to_string()))?;
    let dir = cert_path.parent().unwrap_or(data_dir);
    std::fs::create_dir_all(dir).map_err(|source| TlsError::Write {
        path: dir.into(),
        source,
    })?;
    // The key first: a certificate without its key would be unusable.
    write_atomically(
        &key_path,
        key.serialize_pem().as_bytes(),
        durable::Mode::Exactly(0o600),
    )?;
    write_atomically(
        &cert_path,
        cert.pem().as_bytes(),
        durable::Mode::LessUmask(0o644),
    )?;
    Ok(true)
}

/// Writes `bytes` to `path` with [`durable::write`].
fn write_atomically(path: &Path, bytes: &[u8], mode: durable::Mode) -> Result<(), TlsError> {
    durable::write(path, bytes, mode).map_err(|e| TlsError::Write {
        path: path.into(),
        source: e.into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprint_is_colon_hex_of_sha256() {
        let f = fingerprint(b"");
        assert_eq!(f.len(), 32 * 3 - 1);
        assert!(f.starts_with("E3:B0:C4:42:98:FC:1C:14"));
    }

    #[test]
    fn self_signed_is_made_once_with_a_private_key_file() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().expect("tempdir");
        let settings = TlsSettings {
            mode: TlsMode::SelfSigned,
            names: vec![
                "rov.example".into(),
                "192.168.2.2".into(),
                "bad name".into(),
            ],
        };
        let first = load(&settings, dir.path()).expect("load").expect("on");
        assert!(first.generated);
        let (cert, key) = self_signed_paths(dir.path());
        let mode = std::fs::metadata(&key).expect("key").permissions().mode();
        assert_eq!(mode & 0o777, 0o600);
        let again = load(&settings, dir.path()).expect("load").expect("on");
        assert!(!again.generated);
        assert_eq!(first.fingerprint, again.fingerprint);
        assert_eq!(
            served_fingerprint(&settings, dir.path()).expect("fp").1,
            first.fingerprint
        );
        assert_eq!(first.cert_path, cert);
    }

    #[test]
    fn bad_files_name_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let cert = dir.path().join("c.pem");
        let key = dir.path().join("k.pem");
        std::fs::write(&cert, "not a certificate").expect("write");
        let settings = TlsSettings {
            mode: TlsMode::Files {
                cert: cert.clone(),
                key: key.clone(),
            },
            names: vec![],
        };
        let e = load(&settings, dir.path())
            .err()
            .expect("error")
            .to_string();
        assert!(
            e.contains("c.pem") && e.contains("BEGIN CERTIFICATE"),
            "{e}"
        );
        // A key from another certificate.
        ensure_self_signed(dir.path(), &[]).expect("make");
        let other = tempfile::tempdir().expect("tempdir");
        ensure_self_signed(other.path(), &[]).expect("make");
        let settings = TlsSettings {
            mode: TlsMode::Files {
                cert: self_signed_paths(dir.path()).0,
                key: self_signed_paths(other.path()).1,
            },
            names: vec![],
        };
        let e = load(&settings, dir.path())
            .err()
            .expect("error")
            .to_string();
        assert!(e.contains("does not go with"), "{e}");
        let settings = TlsSettings {
            mode: TlsMode::Files {
                cert: self_signed_paths(dir.path()).0,
                key,
            },
            names: vec![],
        };
        let e = load(&settings, dir.path())
            .err()
            .expect("error")
            .to_string();
        assert!(e.contains("k.pem") && e.contains("tls_key"), "{e}");
    }
}
