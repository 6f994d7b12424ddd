//! Why a run of a camera source ended ([`SourceError`]): the camera's
//! error type, shared by the supervision loop and every source.

use super::config::SourceKind;
use super::render::RenderError;

/// Why a run of a source ended. Each message names the source, the thing
/// that failed and what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error(
        "camera source {kind}: program `{program}` not found{on_path} — {install} or set camera.source = \"synthetic\""
    )]
    ProgramNotFound {
        kind: SourceKind,
        program: String,
        /// " on PATH" when the program was given by name.
        on_path: &'static str,
        install: &'static str,
    },
    #[error(
        "camera source {kind}: cannot start `{program}`: {error} — check that it is an executable program (camera.{key}.program)"
    )]
    Spawn {
        kind: SourceKind,
        program: String,
        key: &'static str,
        error: std::io::Error,
    },
    #[error("camera source {kind}: `{program}` exited ({status}){stderr} — {hint}")]
    Exited {
        kind: SourceKind,
        program: String,
        status: String,
        /// ": " and its last lines on stderr, when it printed any.
        stderr: String,
        hint: &'static str,
    },
    #[error(
        "camera source {kind}: no frame for {secs:.1} s from {what} — restarting it (camera.stall_timeout_s)"
    )]
    Stalled {
        kind: SourceKind,
        what: String,
        secs: f64,
    },
    #[error(
        "camera source {kind}: cannot connect to {url}: {error} — check camera.url and that the stream is up"
    )]
    Connect {
        kind: SourceKind,
        url: String,
        error: String,
    },
    #[error(
        "camera source {kind}: {url} answered {status} — expected 200 with an MJPEG stream; check camera.url"
    )]
    HttpStatus {
        kind: SourceKind,
        url: String,
        status: String,
    },
    #[error(
        "camera source {kind}: {url} sent Content-Type {content_type:?} — expected multipart/x-mixed-replace (an MJPEG stream); check camera.url"
    )]
    NotMjpeg {
        kind: SourceKind,
        url: String,
        content_type: String,
    },
    #[error("camera source {kind}: the stream from {url} ended{detail} — reconnecting")]
    StreamEnded {
        kind: SourceKind,
        url: String,
        detail: String,
    },
    #[error("camera source {kind}: reading {what} failed: {error}")]
    Read {
        kind: SourceKind,
        what: String,
        error: String,
    },
    #[error("camera source {kind}: {why} — {fix}")]
    Unusable {
        kind: SourceKind,
        why: String,
        fix: String,
    },
    #[error("camera source {kind}: {device}: {error}")]
    Device {
        kind: SourceKind,
        device: String,
        error: String,
    },
    #[error(transparent)]
    Render(#[from] RenderError),
}

impl SourceError {
    /// Logged once per kind (then at debug level) so a camera unplugged for
    /// an hour does not flood the log.
    pub(super) fn kind_name(&self) -> &'static str {
        match self {
            SourceError::ProgramNotFound { .. } => "not-found",
            SourceError::Spawn { .. } => "spawn",
            SourceError::Exited { .. } => "exited",
            SourceError::Stalled { .. } => "stalled",
            SourceError::Connect { .. } => "connect",
            SourceError::HttpStatus { .. } => "http-status",
            SourceError::NotMjpeg { .. } => "not-mjpeg",
            SourceError::StreamEnded { .. } => "stream-ended",
            SourceError::Read { .. } => "read",
            SourceError::Unusable { .. } => "unusable",
            SourceError::Device { .. } => "device",
            SourceError::Render(_) => "render",
        }
    }
}
