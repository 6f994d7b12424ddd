//! The data directory at start. A broken one (read-only, full, a file in
//! the way) must not keep the vehicle from running: parameters then live in
//! memory, logs are lost, and every such problem is loud and shown in
//! SYS_STATUS. Each problem found is one line of [`Problems`].

use std::path::Path;

use super::AppError;
use crate::vehicle::params::{ParamFile, ParamStore};

/// Storage problems found at start, for the core (SYS_STATUS) and the log.
#[derive(Debug, Default)]
pub(super) struct Problems(Vec<String>);

impl Problems {
    pub(super) fn push(&mut self, problem: String) {
        self.0.push(problem);
    }

    /// All of them in one line, or None when storage is fine.
    pub(super) fn summary(&self) -> Option<String> {
        (!self.0.is_empty()).then(|| self.0.join("; "))
    }
}

/// Creates the data directory; without it, the vehicle runs without storage.
pub(super) fn create_data_dir(dir: &Path) -> Problems {
    let mut problems = Problems::default();
    if let Err(source) = std::fs::create_dir_all(dir) {
        let e = AppError::DataDir {
            path: dir.to_path_buf(),
            source,
        };
        tracing::error!(
            "{e} — running without storage: parameters changes are kept in memory only, logs are lost (fix the directory, or pass another --data-dir)"
        );
        problems.push(e.to_string());
    }
    problems
}

/// The parameters: a save left half-done is removed, a corrupt file is set
/// aside and defaults apply, loudly; a configured system id overrides the file.
pub(super) fn load_params(
    dir: &Path,
    sysid: Option<u8>,
    problems: &mut Problems,
) -> (ParamFile, ParamStore) {
    let param_file = ParamFile::new(dir);
    match param_file.remove_stale_tmp() {
        Ok(true) => tracing::warn!(
            "removed {} left by an interrupted save (params.toml is intact)",
            param_file.tmp_path().display()
        ),
        Ok(false) => {}
        Err(e) if problems.0.is_empty() => {
            tracing::warn!("cannot remove {}: {e}", param_file.tmp_path().display())
        }
        Err(_) => {}
    }
    if problems.0.is_empty()
        && let Err(e) = probe_writable(dir)
    {
        tracing::error!(
            "data directory {} is not writable ({e}): parameter changes will be kept in memory only and reported as not saved until it is",
            dir.display()
        );
        problems.push(format!(
            "data directory {} not writable: {e}",
            dir.display()
        ));
    }
    let (mut store, warnings) = param_file.load();
    for w in &warnings {
        tracing::warn!("parameters: {w}");
    }
    if let Some(sysid) = sysid
        && let Err(e) = store.set("SYSID_THISMAV", f64::from(sysid))
    {
        tracing::warn!("configured sysid refused: {e}");
    }
    (param_file, store)
}

/// Creates and removes a file in `dir`: true writability (permission bits
/// say nothing for root, nor for a read-only mount).
fn probe_writable(dir: &Path) -> std::io::Result<()> {
    let probe = dir.join(".neptunus-write-probe");
    std::fs::write(&probe, b"")?;
    std::fs::remove_file(&probe)
}
