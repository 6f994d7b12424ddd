//! Parameter saving off the vehicle task: `params.toml` is written on its
//! own thread and each result goes back to the core as an input.

use tokio::sync::mpsc;

use crate::vehicle::params::{ParamFile, ParamStore};

/// Writes `params.toml` on its own thread, so a slow or failing disk never
/// stalls the vehicle task; each result goes back to the core. The core asks
/// for one save at a time, so the queue never holds more than one.
pub(super) struct ParamSaver {
    tx: Option<std::sync::mpsc::Sender<ParamStore>>,
    thread: Option<std::thread::JoinHandle<ParamFile>>,
    /// Where results go; also used to answer at once when there is no thread.
    results: Option<mpsc::UnboundedSender<Result<(), String>>>,
}

impl ParamSaver {
    pub(super) fn spawn(
        file: ParamFile,
        results: mpsc::UnboundedSender<Result<(), String>>,
    ) -> Self {
        let (tx, rx) = std::sync::mpsc::channel::<ParamStore>();
        let thread_results = results.clone();
        let thread = std::thread::Builder::new()
            .name("neptunus-params".into())
            .spawn(move || {
                for store in rx {
                    let result = file.save(&store).map_err(|e| {
                        tracing::error!("parameters not saved: {e}");
                        e.to_string()
                    });
                    if result.is_ok() {
                        tracing::debug!(path = %file.path().display(), "parameters saved");
                    }
                    let _ = thread_results.send(result);
                }
                file
            });
        match thread {
            Ok(thread) => Self {
                tx: Some(tx),
                thread: Some(thread),
                results: Some(results),
            },
            Err(e) => {
                tracing::error!(
                    "cannot start the parameter saver thread: {e}; parameters will not be saved"
                );
                Self {
                    results: Some(results),
                    ..Self::stopped()
                }
            }
        }
    }

    pub(super) fn stopped() -> Self {
        Self {
            tx: None,
            thread: None,
            results: None,
        }
    }

    /// Queues a save; without a saver thread the core hears at once that
    /// it failed (and tells the stations).
    pub(super) fn save(&self, store: ParamStore) {
        let sent = self.tx.as_ref().is_some_and(|tx| tx.send(store).is_ok());
        if !sent && let Some(results) = &self.results {
            let _ = results.send(Err("the parameter saver thread is not running".into()));
        }
    }

    /// Blocking: waits for the save in flight, then writes `last` if given.
    pub(super) fn finish(mut self, last: Option<ParamStore>) {
        self.tx = None;
        let file = self.thread.take().and_then(|t| t.join().ok());
        if let (Some(file), Some(store)) = (file, last) {
            match file.save(&store) {
                Ok(()) => tracing::info!("unsaved parameter changes saved at shutdown"),
                Err(e) => tracing::error!("parameter changes lost at shutdown: {e}"),
            }
        }
    }
}
