//! Starting the HMI for the app ([`Hmi`]): binding its port and the
//! camera manager's ports beside it, loading the pilot password, the
//! signing state and TLS, saying at start who may pilot and where to find
//! the page; and the app's handle on the running server (its sessions'
//! inputs, its outlets, its shutdown).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::TcpListener;
use tokio::sync::mpsc;

use super::{
    Beside, BesideKind, HmiContext, HmiError, HmiSettings, Outlet, VideoRoutes, auth, serve,
    server, tls,
};
use crate::vehicle::machine::Input;

/// One start-up line saying who may pilot from the browser.
fn log_access_policy(settings: &HmiSettings, password: bool, signing: bool) {
    let who = match (signing, password, settings.open_control) {
        (true, true, _) => "MAVLink signing is on: only sessions logged in with the pilot password may pilot".to_owned(),
        (true, false, _) => "MAVLink signing is on and no pilot password is set: no browser session may pilot — set one with `neptunus hmi set-password`".to_owned(),
        (false, _, auth::OpenControl::None) if !password => "no pilot password is set and open_control = \"none\": no browser session may pilot — set one with `neptunus hmi set-password`".to_owned(),
        (false, _, auth::OpenControl::None) => "sessions must log in with the pilot password to pilot".to_owned(),
        (false, true, oc) => format!("sessions from {oc} addresses may pilot without logging in (open_control = \"{oc}\"), others must log in with the pilot password"),
        (false, false, oc) => format!("sessions from {oc} addresses may pilot (open_control = \"{oc}\"); others may only watch until a pilot password is set with `neptunus hmi set-password`"),
    };
    tracing::info!("browser HMI: {who}");
}

/// A pilot password crossing the network in clear text: say so at start
/// (the loopback interface never leaves the machine).
fn warn_plaintext(password_set: bool, local: SocketAddr) {
    if password_set && !local.ip().is_loopback() {
        tracing::warn!(
            "browser HMI on {local} without TLS: the pilot password and the session cross the network in clear text — \
             set [hmi] tls = \"self-signed\" (or --tls self-signed) unless the tether is a private point-to-point link"
        );
    }
}

/// The app's handle on a running HMI: the inputs its sessions produce.
pub struct Hmi {
    inputs: Option<mpsc::Receiver<Input>>,
    /// Where the ports beside listen, those that do.
    beside: Vec<(BesideKind, SocketAddr)>,
    outlet: Outlet,
    m2r_outlet: Outlet,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: Option<tokio::task::JoinHandle<()>>,
}

impl Hmi {
    /// Binds and starts the HMI server for endpoint index `endpoint` (its
    /// mavlink2rest API is endpoint `endpoint + 1`) (or does nothing with
    /// `--http off`). The bound address is logged
    /// and written to `DATA_DIR/http.addr` (`ADDR`, or `https://ADDR/` with
    /// TLS on). With TLS, the certificate is loaded (or made) first: a bad
    /// certificate or key file is an error naming it. `video`: the camera's
    /// routes, and the WebRTC signalling's own port under the same guard
    /// and TLS.
    pub async fn start(
        settings: &HmiSettings,
        endpoint: usize,
        vehicle_sysid: u8,
        z_centered: Arc<dyn Fn(u8) -> bool + Send + Sync>,
        data_dir: PathBuf,
        video: Option<VideoRoutes>,
    ) -> Result<Self, HmiError> {
        let (extra_routes, webrtc, ports, video_info) = match video {
            Some(v) => (
                Some(v.routes),
                v.webrtc,
                [
                    v.signalling.map(|s| (BesideKind::Signalling, s)),
                    v.streams.map(|s| (BesideKind::Streams, s)),
                ],
                v.info,
            ),
            None => (None, false, [None, None], None),
        };
        let outlet = Outlet::new(endpoint);
        let m2r_outlet = Outlet::every_component(endpoint + 1);
        let off = Self {
            inputs: None,
            beside: Vec::new(),
            outlet: outlet.clone(),
            m2r_outlet: m2r_outlet.clone(),
            stop: None,
            task: None,
        };
        let addr_file = data_dir.join("http.addr");
        let _ = std::fs::remove_file(&addr_file);
        let Some(addr) = settings.http else {
            tracing::info!("browser HMI off (--http off)");
            return Ok(off);
        };
        let listener = match TcpListener::bind(addr).await {
            Ok(l) => l,
            Err(source) if !settings.http_explicit => {
                tracing::warn!("{} — the browser HMI is off", HmiError::bind(addr, source));
                return Ok(off);
            }
            Err(source) => return Err(HmiError::bind(addr, source)),
        };
        let local = listener.local_addr().unwrap_or(addr);
        let password = auth::PasswordStore::new(&data_dir).load()?;
        let signing = crate::mavlink::signing::SigningStore::new(&data_dir)
            .load_key_checked()
            .is_ok_and(|(k, _)| k.is_some());
        let tls = tls::load(&settings.tls, &data_dir)?;
        let url = match &tls {
            Some(t) => {
                if t.generated {
                    tracing::info!(
                        "browser HMI: self-signed TLS certificate made in {}",
                        t.cert_path.display()
                    );
                }
                tracing::info!(
                    "browser HMI TLS certificate {}: SHA-256 fingerprint {} — check that the browser shows the same \
                     (also printed by `neptunus hmi tls-fingerprint`)",
                    t.cert_path.display(),
                    t.fingerprint
                );
                format!("https://{local}/")
            }
            None => {
                warn_plaintext(password.is_some(), local);
                format!("http://{local}/")
            }
        };
        // Plain HTTP keeps the bare address (what scripts already read).
        let addr_text = if tls.is_some() {
            url.clone()
        } else {
            local.to_string()
        };
        // A read-only data directory must not keep the pilot from the page:
        // the address is in the log line below too.
        if let Err(source) = std::fs::write(&addr_file, format!("{addr_text}\n")) {
            tracing::warn!(
                "{}",
                HmiError::AddrFile {
                    path: addr_file.clone(),
                    source,
                }
            );
        }
        tracing::info!(addr = %local, "browser HMI listening on {url}");
        log_access_policy(settings, password.is_some(), signing);
        let mut beside = Vec::new();
        for (kind, (addr, routes)) in ports.into_iter().flatten() {
            if let Some(b) = Beside::bind(kind, addr, routes, tls.is_some()).await {
                beside.push(b);
            }
        }
        let beside_addr: Vec<_> = beside
            .iter()
            .filter_map(|b| Some((b.kind, b.listener.local_addr().ok()?)))
            .collect();
        let (tx, rx) = mpsc::channel(1024);
        let ctx = HmiContext {
            outlet: outlet.clone(),
            m2r_outlet: m2r_outlet.clone(),
            inputs: tx,
            vehicle_sysid,
            sysid_min: settings.sysid_min,
            sysid_max: settings.sysid_max,
            z_centered,
            password,
            open_control: settings.open_control,
            allowed_origins: settings.allowed_origins.clone(),
            max_watchers: settings.max_watchers,
            signing,
            camera_rotation_deg: settings.camera_rotation_deg,
            data_dir,
            extra_routes,
            webrtc,
            video_info,
            transport: server::Transport {
                limits: settings.limits,
                tls: tls.map(|t| t.config),
            },
            beside,
        };
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(async move {
            let shutdown = async move {
                let _ = stop_rx.await;
            };
            if let Err(e) = serve(listener, ctx, shutdown).await {
                tracing::error!("browser HMI server stopped: {e}");
            }
        });
        Ok(Self {
            inputs: Some(rx),
            beside: beside_addr,
            outlet,
            m2r_outlet,
            stop: Some(stop_tx),
            task: Some(task),
        })
    }

    /// The next input from a session (pending forever when the HMI is off).
    pub async fn recv(&mut self) -> Input {
        match self.inputs.as_mut() {
            Some(rx) => match rx.recv().await {
                Some(input) => input,
                None => std::future::pending().await,
            },
            None => std::future::pending().await,
        }
    }

    /// Where a port beside the HMI's listens (the WebRTC signalling, the
    /// camera's streams).
    pub fn beside_addr(&self, kind: BesideKind) -> Option<SocketAddr> {
        self.beside
            .iter()
            .find(|(k, _)| *k == kind)
            .map(|(_, a)| *a)
    }

    /// The vehicle task's side of the hub.
    pub fn outlet(&self) -> Outlet {
        self.outlet.clone()
    }

    /// The mavlink2rest API's side of the hub.
    pub fn m2r_outlet(&self) -> Outlet {
        self.m2r_outlet.clone()
    }

    /// Stops the server; sessions' sockets close.
    pub async fn shutdown(mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(mut task) = self.task.take() {
            // Sessions with open sockets keep a graceful shutdown waiting; do not hang on them.
            if tokio::time::timeout(Duration::from_millis(500), &mut task)
                .await
                .is_err()
            {
                task.abort();
            }
        }
    }
}
