//! Camera programs as child processes: `ffmpeg` writing MJPEG to its
//! stdout, and `mjpg_streamer` serving MJPEG on a loopback port.
//!
//! One call runs the program once and returns why the run ended; the
//! restart schedule is the caller's. Every child is spawned with
//! `kill_on_drop`, so aborting the camera's task kills it.

use std::collections::VecDeque;
use std::process::Stdio;
use std::time::Duration;

use tokio::io::{AsyncBufReadExt, AsyncReadExt, BufReader, Lines};
use tokio::process::{Child, ChildStderr, Command};
use tokio::time::{Instant, sleep_until, timeout};

use super::client;
use super::config::{CameraConfig, SourceKind, StreamUrl};
use super::error::SourceError;
use super::publisher::Publisher;
use super::splitter::JpegSplitter;

/// Lines of a child's stderr kept for the error message.
const STDERR_TAIL_LINES: usize = 3;
const STDERR_LINE_CHARS: usize = 300;

/// `ffmpeg -hide_banner -nostdin -loglevel error INPUT… OUTPUT…`, frames
/// split from its stdout.
pub(crate) async fn run_ffmpeg(cfg: &CameraConfig, out: &mut Publisher) -> SourceError {
    const KIND: SourceKind = SourceKind::Ffmpeg;
    let f = &cfg.ffmpeg;
    let mut cmd = Command::new(&f.program);
    cmd.args(["-hide_banner", "-nostdin", "-loglevel", "error"])
        .args(&f.input_args)
        .args(&f.output_args);
    let mut child = match spawn(cmd, KIND, &f.program) {
        Ok(c) => c,
        Err(e) => return e,
    };
    out.starting(child.id());
    let mut stderr = StderrTail::new(child.stderr.take(), &f.program);
    let Some(mut stdout) = child.stdout.take() else {
        return SourceError::Read {
            kind: KIND,
            what: format!("the stdout of `{}`", f.program),
            error: "no pipe".into(),
        };
    };
    let stall = cfg.stall_timeout();
    let mut splitter = JpegSplitter::new();
    let mut deadline = Instant::now() + stall;
    let mut buf = vec![0u8; 64 * 1024];
    loop {
        tokio::select! {
            r = stdout.read(&mut buf) => match r {
                Ok(0) => break,
                Ok(n) => {
                    splitter.push(&buf[..n]);
                    while let Some(j) = splitter.next_frame() {
                        out.publish(j.jpeg, j.width, j.height);
                        deadline = Instant::now() + stall;
                    }
                }
                Err(e) => {
                    kill(&mut child).await;
                    return SourceError::Read {
                        kind: KIND,
                        what: format!("the stdout of `{}`", f.program),
                        error: e.to_string(),
                    };
                }
            },
            () = stderr.next() => {}
            () = sleep_until(deadline) => {
                kill(&mut child).await;
                return SourceError::Stalled {
                    kind: KIND,
                    what: format!("`{}`", f.program),
                    secs: stall.as_secs_f64(),
                };
            }
        }
    }
    // stdout closed: the program is exiting (or closed it and hangs).
    let status = match timeout(stall, child.wait()).await {
        Ok(Ok(s)) => s.to_string(),
        Ok(Err(e)) => format!("wait failed: {e}"),
        Err(_) => {
            kill(&mut child).await;
            "closed its output and was killed".into()
        }
    };
    stderr.drain(Duration::from_secs(1)).await;
    SourceError::Exited {
        kind: KIND,
        program: f.program.clone(),
        status,
        stderr: stderr.tail(),
        hint: "check camera.ffmpeg.input_args and that the camera is connected",
    }
}

/// `mjpg_streamer -i INPUT -o "OUTPUT_PLUGIN -p PORT"`, read over HTTP at
/// `http://127.0.0.1:PORT` + `stream_path`.
pub(crate) async fn run_mjpg_streamer(cfg: &CameraConfig, out: &mut Publisher) -> SourceError {
    const KIND: SourceKind = SourceKind::MjpgStreamer;
    let m = &cfg.mjpg_streamer;
    let port = if m.port != 0 {
        m.port
    } else {
        match free_loopback_port() {
            Ok(p) => p,
            Err(e) => {
                return SourceError::Read {
                    kind: KIND,
                    what: "a free loopback port for mjpg_streamer".into(),
                    error: e.to_string(),
                };
            }
        }
    };
    let mut cmd = Command::new(&m.program);
    cmd.arg("-i")
        .arg(&m.input)
        .arg("-o")
        .arg(format!("{} -p {port}", m.output_plugin));
    let mut child = match spawn(cmd, KIND, &m.program) {
        Ok(c) => c,
        Err(e) => return e,
    };
    out.starting(child.id());
    let mut stderr = StderrTail::new(child.stderr.take(), &m.program);
    let url = StreamUrl {
        host: "127.0.0.1".into(),
        port,
        authority: format!("127.0.0.1:{port}"),
        path_and_query: m.stream_path.clone(),
        text: format!("http://127.0.0.1:{port}{}", m.stream_path),
    };
    let stall = cfg.stall_timeout();
    // It opens the camera before it listens: give it the stall timeout.
    let stream = client::read_stream(&url, stall, Some(stall), out);
    tokio::pin!(stream);
    loop {
        tokio::select! {
            status = child.wait() => {
                let status = match status {
                    Ok(s) => s.to_string(),
                    Err(e) => format!("wait failed: {e}"),
                };
                stderr.drain(Duration::from_secs(1)).await;
                return SourceError::Exited {
                    kind: KIND,
                    program: m.program.clone(),
                    status,
                    stderr: stderr.tail(),
                    hint: "check camera.mjpg_streamer.input and that the camera is connected",
                };
            }
            err = &mut stream => {
                kill(&mut child).await;
                return err;
            }
            () = stderr.next() => {}
        }
    }
}

fn spawn(mut cmd: Command, kind: SourceKind, program: &str) -> Result<Child, SourceError> {
    cmd.stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true);
    cmd.spawn().map_err(|error| {
        if error.kind() == std::io::ErrorKind::NotFound {
            SourceError::ProgramNotFound {
                kind,
                program: program.to_owned(),
                on_path: if program.contains('/') {
                    ""
                } else {
                    " on PATH"
                },
                install: match kind {
                    SourceKind::Ffmpeg => "install it (apt install ffmpeg)",
                    _ => "install mjpg-streamer (Debian does not package it: build it from source)",
                },
            }
        } else {
            SourceError::Spawn {
                kind,
                program: program.to_owned(),
                key: match kind {
                    SourceKind::Ffmpeg => "ffmpeg",
                    _ => "mjpg_streamer",
                },
                error,
            }
        }
    })
}

/// SIGKILL and reap.
async fn kill(child: &mut Child) {
    if let Err(e) = child.kill().await {
        tracing::debug!("camera: killing the child failed: {e}");
    }
}

/// A port nobody listens on now. Another process could take it before the
/// child binds it; the child then fails, and the next start picks again.
fn free_loopback_port() -> std::io::Result<u16> {
    let l = std::net::TcpListener::bind(("127.0.0.1", 0))?;
    Ok(l.local_addr()?.port())
}

/// The last lines a child printed on stderr (each also logged at debug
/// level), for the message when it exits.
pub(super) struct StderrTail {
    lines: Option<Lines<BufReader<ChildStderr>>>,
    tail: VecDeque<String>,
    program: String,
}

impl StderrTail {
    pub(super) fn new(stderr: Option<ChildStderr>, program: &str) -> Self {
        StderrTail {
            lines: stderr.map(|s| BufReader::new(s).lines()),
            tail: VecDeque::new(),
            program: program.to_owned(),
        }
    }

    /// Reads one line; never completes once stderr is closed, so it can sit
    /// in a `select!` without spinning.
    pub(super) async fn next(&mut self) {
        let Some(lines) = &mut self.lines else {
            return std::future::pending().await;
        };
        match lines.next_line().await {
            Ok(Some(line)) => {
                let line: String = line.chars().take(STDERR_LINE_CHARS).collect();
                tracing::debug!("camera: {}: {line}", self.program);
                if !line.trim().is_empty() {
                    if self.tail.len() == STDERR_TAIL_LINES {
                        self.tail.pop_front();
                    }
                    self.tail.push_back(line);
                }
            }
            // Closed, or not text: stop reading it.
            Ok(None) | Err(_) => self.lines = None,
        }
    }

    /// Reads what is left, for at most `limit` (a grandchild may hold the
    /// pipe open).
    pub(super) async fn drain(&mut self, limit: Duration) {
        let _ = timeout(limit, async {
            while self.lines.is_some() {
                self.next().await;
            }
        })
        .await;
    }

    pub(super) fn tail(&self) -> String {
        if self.tail.is_empty() {
            String::new()
        } else {
            format!(": {}", Vec::from(self.tail.clone()).join(" | "))
        }
    }
}
