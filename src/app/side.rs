//! The browser side's own thread: the HMI's HTTP and WebSockets, the
//! mavlink2rest API, the camera and its RTP video — and, with `--sim`, the
//! board emulator, which stands for a processor of its own — run on a
//! single-threaded runtime of their own.
//!
//! The vehicle task, the MAVLink endpoints and the serial link run on the
//! main thread's single-threaded runtime: a stick datagram, the core and
//! the `go()` it causes are handled in one wake-up of one thread, and
//! nothing a browser does (a page load compressed, five sessions'
//! telemetry, a video relay) can hold that thread up. Two threads that
//! sleep until they have something to do suit the BeagleBone's one core
//! better than a pool of workers that wake each other. The two sides talk
//! only over channels.

use std::time::Duration;

use tokio::runtime::Handle;
use tokio::sync::oneshot;

/// The browser side's thread and runtime.
pub(super) struct Side {
    handle: Handle,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Side {
    pub(super) fn start() -> std::io::Result<Self> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .thread_name("neptunus-hmi-blocking")
            // Password checks and the like: a flood of logins queues here
            // instead of spawning a thread each (the unit's TasksMax).
            .max_blocking_threads(4)
            .build()?;
        let handle = rt.handle().clone();
        let (stop, stopped) = oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("neptunus-hmi".into())
            .spawn(move || {
                rt.block_on(async {
                    let _ = stopped.await;
                });
                // A blocking job that never ends (a camera read) must not
                // hold the process up at shutdown.
                rt.shutdown_timeout(Duration::from_secs(1));
            })?;
        Ok(Self {
            handle,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// Where the browser side's tasks are spawned (`handle().enter()` for
    /// code that spawns as it starts).
    pub(super) fn handle(&self) -> &Handle {
        &self.handle
    }

    /// Stops the runtime (its remaining tasks are dropped) and waits for the thread.
    pub(super) async fn stop(mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = tokio::task::spawn_blocking(move || thread.join()).await;
        }
    }
}

impl Drop for Side {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
    }
}
