//! The settings bag's file: `DATA_DIR/bag.json`, every record with its
//! path and writer, replaced whole at every change that changes something
//! ([`crate::durable::write`]: a temporary file, synced, renamed, the folder
//! synced),
//! so a power cut leaves the old bag or the new one, never half of one.
//!
//! A file that cannot be read is set aside (`bag.json.bad`) and the bag
//! starts empty, loudly: Cockpit then makes a new vehicle id, which costs
//! its settings' link to this vehicle, never the vehicle's start.

use std::fs;
use std::path::{Path, PathBuf};

use super::store::{Bag, Limits};

/// The bag's file in the data directory.
pub const BAG_FILE: &str = "bag.json";

/// Where the bag is kept.
#[derive(Debug, Clone)]
pub struct BagFile {
    path: PathBuf,
}

impl BagFile {
    pub fn new(data_dir: &Path) -> BagFile {
        BagFile {
            path: data_dir.join(BAG_FILE),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The bag as the file holds it; an empty one when there is no file,
    /// and when it cannot be read (then set aside, and said why).
    pub fn load(&self, limits: Limits) -> Bag {
        let _ = fs::remove_file(crate::durable::tmp_path(&self.path));
        let bytes = match fs::read(&self.path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Bag::new(limits),
            Err(e) => {
                tracing::error!(
                    "settings bag {}: cannot read it ({e}) — Cockpit's settings start empty; check the data directory",
                    self.path.display()
                );
                return Bag::new(limits);
            }
        };
        match Bag::from_file(&bytes, limits) {
            Ok((bag, warnings)) => {
                for w in warnings {
                    tracing::warn!("settings bag {}: {w}", self.path.display());
                }
                bag
            }
            Err(why) => {
                let aside = self.path.with_extension("json.bad");
                let moved = fs::rename(&self.path, &aside);
                tracing::error!(
                    "settings bag {} is not a bag ({why}) — {}; Cockpit's settings start empty (it makes a new vehicle id)",
                    self.path.display(),
                    match moved {
                        Ok(()) => format!("set aside as {}", aside.display()),
                        Err(e) => format!("could not set it aside: {e}"),
                    }
                );
                Bag::new(limits)
            }
        }
    }

    /// Stores the bag (blocking: off the async threads).
    pub fn save(&self, bag: &Bag) -> std::io::Result<()> {
        crate::durable::write(
            &self.path,
            &bag.to_file(),
            crate::durable::Mode::Exactly(0o600),
        )?;
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::super::path::BagPath;
    use super::super::store::Writer;
    use super::*;

    #[test]
    fn kept_across_a_restart_and_a_bad_file_is_set_aside() {
        let dir = tempfile::tempdir().unwrap();
        let file = BagFile::new(dir.path());
        let mut bag = file.load(Limits::default());
        let id = BagPath::parse("cockpit/cockpit-vehicle-id").unwrap();
        bag.set(&id, br#""6f1c""#, &Writer::Watcher("10.0.0.2".into()))
            .unwrap();
        file.save(&bag).unwrap();
        assert!(!crate::durable::tmp_path(file.path()).exists());
        let again = BagFile::new(dir.path()).load(Limits::default());
        assert_eq!(again, bag);
        fs::write(file.path(), b"{\"version\":1,").unwrap();
        let empty = file.load(Limits::default());
        assert_eq!(empty.get(&id), None);
        assert!(dir.path().join("bag.json.bad").exists());
    }
}
