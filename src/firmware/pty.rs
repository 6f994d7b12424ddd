//! Pseudo-terminals, so that the board emulator sits behind a real tty and
//! the serial link runs the same code path as on the ROV.
//!
//! Owns: creating a raw-mode pty pair, the async master side, and the
//! optional stable symlink to the slave (`/dev/pts/N` changes every time a
//! pty is created; a symlink lets a restarted emulator appear at the same
//! path, like a USB adapter re-plugged). Never interprets the bytes.

use std::io;
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};

use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use tokio::io::unix::AsyncFd;

/// Errors creating or using a pseudo-terminal, or starting the board
/// emulator behind it.
#[derive(Debug, thiserror::Error)]
pub enum PtyError {
    #[error("{0} (in the emulator's [emulator.sim] options)")]
    Simulator(#[from] crate::sim::SimError),
    #[error("cannot create a pseudo-terminal: {0}")]
    Create(nix::Error),
    #[error("cannot configure the pseudo-terminal: {0}")]
    Configure(nix::Error),
    #[error("cannot create the symlink {path} to the pseudo-terminal: {source}")]
    Symlink { path: PathBuf, source: io::Error },
    #[error("cannot register the pseudo-terminal with the runtime: {0}")]
    Register(io::Error),
}

/// A pty pair in raw mode. The slave side stays open for the life of the
/// pair so that its termios settings persist and the master never sees a
/// hang-up while the serial link reconnects.
#[derive(Debug)]
pub struct PtyPair {
    master: AsyncFd<OwnedFd>,
    _slave: OwnedFd,
    slave_path: PathBuf,
    symlink: Option<PathBuf>,
}

impl PtyPair {
    /// Creates a raw pty pair; the master is non-blocking and registered with
    /// the tokio runtime (call inside a runtime).
    pub fn open() -> Result<Self, PtyError> {
        let raw = open_raw()?;
        // `AsyncFd::new` is deprecated because a registered fd could be closed
        // behind the reactor's back; here the reactor owns the `OwnedFd`
        // outright, so nothing else can close it.
        #[allow(deprecated)]
        let master = AsyncFd::new(raw.master).map_err(PtyError::Register)?;
        Ok(Self {
            master,
            _slave: raw.slave,
            slave_path: raw.slave_path,
            symlink: None,
        })
    }

    /// The slave device path (`/dev/pts/N`), what a serial program opens.
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// The stable symlink, if one was made.
    pub fn symlink(&self) -> Option<&Path> {
        self.symlink.as_deref()
    }

    /// Points `link` at the slave, atomically replacing an older link.
    pub fn make_symlink(&mut self, link: &Path) -> Result<(), PtyError> {
        symlink_to(&self.slave_path, link)?;
        self.symlink = Some(link.to_path_buf());
        Ok(())
    }

    /// Waits until what the serial program wrote can be read, then reads it.
    pub async fn read(&self, buf: &mut [u8]) -> io::Result<usize> {
        loop {
            let mut guard = self.master.readable().await?;
            match guard
                .try_io(|fd| nix::unistd::read(fd.get_ref().as_fd(), buf).map_err(io::Error::from))
            {
                Ok(result) => return result,
                Err(_would_block) => continue,
            }
        }
    }

    /// Writes without blocking; returns how many bytes the tty accepted. When
    /// nobody reads the slave, the tty buffer fills and further bytes are
    /// lost, as on a real UART with nobody listening.
    pub fn try_write(&self, bytes: &[u8]) -> io::Result<usize> {
        match nix::unistd::write(self.master.get_ref().as_fd(), bytes) {
            Ok(n) => Ok(n),
            Err(nix::errno::Errno::EAGAIN) => Ok(0),
            Err(e) => Err(io::Error::from(e)),
        }
    }
}

impl Drop for PtyPair {
    fn drop(&mut self) {
        if let Some(link) = &self.symlink {
            remove_link_to(link, &self.slave_path);
        }
    }
}

/// A raw-mode pty pair before anything is registered: the master
/// non-blocking, the slave kept open by its owner (see [`PtyPair`]).
#[derive(Debug)]
pub struct RawPty {
    pub master: OwnedFd,
    pub slave: OwnedFd,
    pub slave_path: PathBuf,
}

/// Creates a raw-mode pty pair with a non-blocking master.
pub fn open_raw() -> Result<RawPty, PtyError> {
    let pair = nix::pty::openpty(None, None).map_err(PtyError::Create)?;
    // Raw mode on the slave at once: bytes written to the master before the
    // link opens the slave must not be mangled (CR→NL, echo).
    let mut tio = tcgetattr(pair.slave.as_fd()).map_err(PtyError::Configure)?;
    cfmakeraw(&mut tio);
    tcsetattr(pair.slave.as_fd(), SetArg::TCSANOW, &tio).map_err(PtyError::Configure)?;
    // Non-blocking master: a spurious readiness must never block a reader.
    let flags = fcntl(pair.master.as_fd(), FcntlArg::F_GETFL).map_err(PtyError::Configure)?;
    let flags = OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK;
    fcntl(pair.master.as_fd(), FcntlArg::F_SETFL(flags)).map_err(PtyError::Configure)?;
    let slave_path = nix::unistd::ttyname(pair.slave.as_fd()).map_err(PtyError::Configure)?;
    Ok(RawPty {
        master: pair.master,
        slave: pair.slave,
        slave_path,
    })
}

/// Points `link` at `target`, atomically replacing an older link.
pub fn symlink_to(target: &Path, link: &Path) -> Result<(), PtyError> {
    let tmp = link.with_extension("tmp-link");
    let _ = std::fs::remove_file(&tmp);
    let err = |source| PtyError::Symlink {
        path: link.to_path_buf(),
        source,
    };
    std::os::unix::fs::symlink(target, &tmp).map_err(err)?;
    std::fs::rename(&tmp, link).map_err(err)
}

/// Removes `link` if it still points at `target` (a newer board may own it).
pub fn remove_link_to(link: &Path, target: &Path) {
    if std::fs::read_link(link).is_ok_and(|t| t == target) {
        let _ = std::fs::remove_file(link);
    }
}
