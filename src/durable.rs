//! Files that must survive a power cut: the parameters, the signing key and
//! its timestamps, the HMI password, the TLS key and certificate, Cockpit's
//! settings bag.
//!
//! [`write()`] is the one way they are written: `NAME.tmp` in the same
//! directory, the bytes, fsync of the file, rename over `NAME`, fsync of the
//! directory (without it the rename itself may be lost with the power, and
//! the old file comes back). A cut at any moment leaves the old file or the
//! new one, never a torn or empty one; at worst a `NAME.tmp` stays behind,
//! which the next write replaces.
//!
//! Never refused for want of room by Neptunus itself: no budget or cap
//! applies here, and the budget of logs and recordings keeps a free-space
//! floor so that these small writes find room. One writer per file (each file
//! has one owner), so the fixed tmp name needs no lock.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Write as _};
use std::os::unix::fs::{OpenOptionsExt as _, PermissionsExt as _};
use std::path::{Path, PathBuf};

/// The permission bits a written file gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Exactly these bits whatever the umask (a key: `Exactly(0o600)`).
    Exactly(u32),
    /// These bits less the process umask, as any new file gets them
    /// (`LessUmask(0o666)` is what `File::create` gives).
    LessUmask(u32),
}

/// One step of a durable write failed; the file is then as it was before
/// (unless the step was the directory's sync, after the rename).
#[derive(Debug, thiserror::Error)]
#[error("could not {step} {}: {source}", path.display())]
pub struct DurableError {
    pub step: &'static str,
    pub path: PathBuf,
    #[source]
    pub source: io::Error,
}

impl From<DurableError> for io::Error {
    fn from(e: DurableError) -> Self {
        io::Error::new(e.source.kind(), e.to_string())
    }
}

/// `NAME.tmp` beside `path`, the name [`write()`] writes first.
pub fn tmp_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".tmp");
    PathBuf::from(name)
}

/// Replaces `path` with `contents`, atomically and durably (see the module
/// docs). Creates the directory when it is missing.
pub fn write(path: &Path, contents: &[u8], mode: Mode) -> Result<(), DurableError> {
    let fail = |step, path: &Path| {
        let path = path.to_path_buf();
        move |source| DurableError { step, path, source }
    };
    let dir = parent_dir(path);
    fs::create_dir_all(&dir).map_err(fail("create directory", &dir))?;
    let tmp = tmp_path(path);
    // A tmp file left by a cut may carry other permissions or an owner's
    // data; create_new with our mode guarantees ours.
    match fs::remove_file(&tmp) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(fail("remove stale", &tmp)(e)),
    }
    let bits = match mode {
        Mode::Exactly(bits) | Mode::LessUmask(bits) => bits,
    };
    let mut file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(bits)
        .open(&tmp)
        .map_err(fail("create", &tmp))?;
    let written = (|| {
        if let Mode::Exactly(bits) = mode {
            file.set_permissions(fs::Permissions::from_mode(bits))
                .map_err(fail("set the permissions of", &tmp))?;
        }
        file.write_all(contents).map_err(fail("write", &tmp))?;
        file.sync_all().map_err(fail("fsync", &tmp))
    })();
    drop(file);
    if let Err(e) = written.and_then(|()| fs::rename(&tmp, path).map_err(fail("rename over", path)))
    {
        // A half-written file (disk full) must not linger.
        let _ = fs::remove_file(&tmp);
        return Err(e);
    }
    sync_dir(&dir).map_err(fail("fsync directory", &dir))
}

/// Removes `path` durably (the directory synced after). True when it was
/// there.
pub fn remove(path: &Path) -> io::Result<bool> {
    match fs::remove_file(path) {
        Ok(()) => {
            sync_dir(&parent_dir(path))?;
            Ok(true)
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(e),
    }
}

/// Makes the renames and removals in `dir` durable. A file system that
/// cannot sync a directory (EINVAL) has nothing more to do.
pub fn sync_dir(dir: &Path) -> io::Result<()> {
    match File::open(dir).and_then(|d| d.sync_all()) {
        Err(e) if e.raw_os_error() == Some(nix::errno::Errno::EINVAL as i32) => Ok(()),
        other => other,
    }
}

fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn mode_of(path: &Path) -> u32 {
        fs::metadata(path).unwrap().permissions().mode() & 0o7777
    }

    #[test]
    fn replaces_the_file_and_leaves_no_tmp() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub").join("params.toml");
        write(&path, b"one", Mode::LessUmask(0o644)).unwrap();
        write(&path, b"two", Mode::LessUmask(0o644)).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
        assert!(!tmp_path(&path).exists());
        assert_eq!(
            tmp_path(&path).file_name().unwrap(),
            "params.toml.tmp",
            "the name a start-up looks for"
        );
    }

    #[test]
    fn exact_modes_ignore_a_stale_tmp_and_a_wider_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("signing.key");
        // An old file and a stale tmp, both readable by everyone, the tmp
        // holding something else: neither may leak into the new file.
        fs::write(&path, b"old").unwrap();
        fs::set_permissions(&path, fs::Permissions::from_mode(0o644)).unwrap();
        fs::write(tmp_path(&path), b"stale stale stale").unwrap();
        fs::set_permissions(tmp_path(&path), fs::Permissions::from_mode(0o666)).unwrap();
        write(&path, b"new", Mode::Exactly(0o600)).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"new");
        assert_eq!(mode_of(&path), 0o600);
        assert!(!tmp_path(&path).exists());
        // Exactly widens past the umask too (the replay file is 0644).
        write(&path, b"n", Mode::Exactly(0o644)).unwrap();
        assert_eq!(mode_of(&path), 0o644);
    }

    #[test]
    fn less_umask_never_widens_past_the_mode() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("hmi-cert.pem");
        write(&path, b"cert", Mode::LessUmask(0o640)).unwrap();
        assert_eq!(mode_of(&path) & !0o640, 0, "{:o}", mode_of(&path));
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_leaves_no_tmp() {
        let dir = tempfile::tempdir().unwrap();
        // The target is a directory: the rename fails after the tmp file was
        // written and synced.
        let path = dir.path().join("taken");
        fs::create_dir(&path).unwrap();
        fs::write(path.join("inside"), b"x").unwrap();
        let err = write(&path, b"new", Mode::LessUmask(0o644)).unwrap_err();
        assert_eq!(err.step, "rename over");
        assert!(err.to_string().contains("taken"), "{err}");
        assert!(path.join("inside").exists());
        assert!(!tmp_path(&path).exists());
        let io: io::Error = err.into();
        assert!(io.to_string().contains("rename over"), "{io}");
    }

    #[test]
    fn a_directory_that_cannot_be_created_names_itself() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("plain");
        fs::write(&file, b"").unwrap();
        let err = write(&file.join("x"), b"", Mode::LessUmask(0o644)).unwrap_err();
        assert_eq!(err.step, "create directory");
        assert_eq!(err.path, file);
    }

    #[test]
    fn remove_says_whether_the_file_was_there() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("hmi-password");
        assert!(!remove(&path).unwrap());
        write(&path, b"x", Mode::Exactly(0o600)).unwrap();
        assert!(remove(&path).unwrap());
        assert!(!path.exists());
    }
}
