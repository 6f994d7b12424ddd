//! `neptunus doctor`: what an operator runs at the pool side when something
//! is not there. One line per check, with the fix when it fails or warns;
//! exit status 0 only when no check fails (a warning is harmless now: the
//! clock behind at an offline pool); `--json` for scripts.
//!
//! The checks: the configuration parses (`config`); the serial device
//! exists and this user may use it (`serial`); a board answers on it in the
//! configured framing (`board`, `board.rs`); the camera's program, device
//! and formats (`camera`); which path the video takes and, when a viewer
//! gets none, the fix (`video`, `video.rs`); the ports the vehicle listens on are free
//! (`ports`); the data directory is writable with room (`data_dir`); the
//! clock is plausible (`clock`) — the last four in `host.rs`.
//!
//! It only looks: it never changes the configuration or the system, and the
//! only thing it sends the board is `ping`. It must not run while the
//! vehicle holds the serial port (it says so).

mod board;
mod host;
mod video;

use serde::Serialize;

use crate::config::{BoardSource, RunArgs, resolve};

pub use board::{Heard, judge};
pub use host::parse_formats;
pub use video::judge as judge_video;

/// One check's outcome.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Check {
    pub name: &'static str,
    /// Nothing stops the vehicle here (a warning is ok too).
    pub ok: bool,
    /// Worth knowing and fixing some day, but harmless now.
    pub warning: bool,
    /// What was found.
    pub detail: String,
    /// What to do about it (failed checks and warnings).
    pub fix: Option<String>,
}

impl Check {
    pub fn pass(name: &'static str, detail: impl Into<String>) -> Self {
        Self {
            name,
            ok: true,
            warning: false,
            detail: detail.into(),
            fix: None,
        }
    }
    pub fn fail(name: &'static str, detail: impl Into<String>, fix: impl Into<String>) -> Self {
        Self {
            name,
            ok: false,
            warning: false,
            detail: detail.into(),
            fix: Some(fix.into()),
        }
    }
    pub fn warn(name: &'static str, detail: impl Into<String>, fix: impl Into<String>) -> Self {
        Self {
            name,
            ok: true,
            warning: true,
            detail: detail.into(),
            fix: Some(fix.into()),
        }
    }
}

/// Every check, in order.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub ok: bool,
    pub checks: Vec<Check>,
}

impl Report {
    fn new(checks: Vec<Check>) -> Self {
        Self {
            ok: checks.iter().all(|c| c.ok),
            checks,
        }
    }

    /// `ok    name      detail` lines, each failure followed by its fix.
    pub fn text(&self) -> String {
        let mut s = String::new();
        for c in &self.checks {
            let mark = match (c.ok, c.warning) {
                (false, _) => "FAIL",
                (true, true) => "warn",
                (true, false) => "ok  ",
            };
            // A long detail (a TOML error with its excerpt) stays under its check.
            let detail = c.detail.trim_end().replace('\n', "\n                ");
            s.push_str(&format!("{mark}  {:<9} {detail}\n", c.name));
            if let Some(fix) = &c.fix {
                s.push_str(&format!("      {:<9} fix: {fix}\n", ""));
            }
        }
        let failed = self.checks.iter().filter(|c| !c.ok).count();
        let warned = self.checks.iter().filter(|c| c.warning).count();
        if failed == 0 && warned > 0 {
            s.push_str(&format!("all checks passed ({warned} warning)\n"));
        } else if failed == 0 {
            s.push_str("all checks passed\n");
        } else {
            s.push_str(&format!(
                "{failed} of {} checks failed\n",
                self.checks.len()
            ));
        }
        s
    }
}

/// Runs every check for the vehicle `args` describe (blocking: a few
/// seconds for the board).
pub fn run(args: &RunArgs) -> Report {
    let source = args.config.as_ref().map_or_else(
        || "no configuration file: built-in defaults".to_owned(),
        |p| format!("{} parses", p.display()),
    );
    let settings = match resolve(args) {
        Ok(s) => s,
        Err(e) => {
            let mut checks = vec![Check::fail(
                "config",
                e.to_string(),
                "correct the file (the message names the line and the setting); `neptunus --config FILE --check` checks it alone",
            )];
            for name in [
                "serial", "board", "camera", "video", "ports", "data_dir", "clock",
            ] {
                checks.push(Check::fail(
                    name,
                    "not checked: the configuration does not parse",
                    "fix the configuration first",
                ));
            }
            return Report::new(checks);
        }
    };
    let link = &settings.link;
    let mut checks = vec![Check::pass(
        "config",
        format!(
            "{source} (board {} {} baud {}, data {})",
            link.device.display(),
            link.baud,
            link.framing,
            settings.data_dir.display()
        ),
    )];
    if matches!(
        settings.board,
        BoardSource::Simulated(_) | BoardSource::Genuine { .. }
    ) {
        checks.push(Check::pass(
            "serial",
            "simulation (sim = true): no serial device",
        ));
        checks.push(Check::pass(
            "board",
            if matches!(settings.board, BoardSource::Genuine { .. }) {
                "simulation: the genuine firmware runs in simavr, built in (feature hil)"
            } else {
                "simulation: the board emulator is built in"
            },
        ));
    } else {
        let device = board::device(link);
        let usable = device.ok;
        checks.push(device);
        checks.push(if usable {
            board::probe(link)
        } else {
            Check::fail(
                "board",
                "not probed: the serial device is not usable",
                "fix the serial check first",
            )
        });
    }
    checks.push(host::camera(&settings.camera));
    checks.push(video::video(&settings.camera));
    checks.push(host::ports(&settings));
    checks.push(host::data_dir(&settings.data_dir));
    checks.push(host::clock());
    Report::new(checks)
}
