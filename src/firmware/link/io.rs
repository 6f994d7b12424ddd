//! The link's I/O loop: the tokio task that owns the serial device.
//!
//! Owns opening the device, reading and writing it, the request and event
//! channels, the published figures and the sleeps. It only moves things:
//! bytes read go to the [`Session`], frames the session hands back are
//! written, requests become session calls, the session's outputs are
//! delivered in order, and it sleeps until the session's next wake. It must
//! never decide what to write, when, or what the link's state is — that is
//! the session's, so it can be tested without a device or a clock.

use futures_util::FutureExt as _;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tokio_serial::SerialPortBuilderExt;

use super::session::{Output, Session};
use super::{LinkConfig, LinkError, LinkEvent, LinkStats, Request};

/// The session's time: tokio's clock, so paused time in tests applies.
fn now() -> std::time::Instant {
    Instant::now().into_std()
}

pub(super) fn open(cfg: &LinkConfig) -> Result<tokio_serial::SerialStream, LinkError> {
    if !cfg.device.exists() {
        return Err(LinkError::NotFound {
            path: cfg.device.clone(),
        });
    }
    tokio_serial::new(cfg.device.to_string_lossy(), cfg.baud)
        .data_bits(tokio_serial::DataBits::Eight)
        .parity(tokio_serial::Parity::None)
        .stop_bits(tokio_serial::StopBits::One)
        .flow_control(tokio_serial::FlowControl::None)
        .open_native_async()
        .map_err(|e| LinkError::Open {
            path: cfg.device.clone(),
            reason: e.to_string(),
        })
}

/// The link task: runs until every [`super::LinkHandle`] is dropped.
pub(super) async fn run(
    cfg: LinkConfig,
    mut rx: mpsc::UnboundedReceiver<Request>,
    events: mpsc::Sender<LinkEvent>,
    stats_tx: watch::Sender<LinkStats>,
) {
    let mut session = Session::new(cfg.clone());
    deliver(&mut session, &events, &stats_tx);
    let mut buf = [0u8; 1024];
    let mut frame = Vec::with_capacity(64);
    'outer: loop {
        let mut port = match open(&cfg) {
            Ok(p) => p,
            Err(e) => {
                let retry_at = session.open_failed(e.to_string(), now());
                deliver(&mut session, &events, &stats_tx);
                if !wait_retry(&mut rx, &mut session, retry_at).await {
                    break 'outer;
                }
                continue 'outer;
            }
        };
        session.opened(now());
        deliver(&mut session, &events, &stats_tx);
        let down_reason: String = loop {
            // What arrived while the loop was away (a busy machine can hold
            // it back for a second) is read before anything is judged by
            // its age: the board's echoes waiting in the device are not
            // lost frames.
            let mut gone = None;
            while let Some(read) = port.read(&mut buf).now_or_never() {
                match read {
                    Ok(0) => gone = Some("device closed".to_owned()),
                    Ok(n) => session.received(&buf[..n], now()),
                    Err(e) => gone = Some(format!("read failed: {e}")),
                }
                if gone.is_some() {
                    break;
                }
            }
            deliver(&mut session, &events, &stats_tx);
            if let Some(reason) = gone {
                break reason;
            }
            let t = now();
            let cmd = session.poll_transmit(t, &mut frame);
            deliver(&mut session, &events, &stats_tx);
            if let Some(cmd) = cmd {
                if let Err(e) = port.write_all(&frame).await {
                    break format!("write failed: {e}");
                }
                session.transmitted(&cmd, frame.len(), t);
            }
            session.poll_timers(t);
            deliver(&mut session, &events, &stats_tx);
            let wake = Instant::from_std(session.next_wake(t));
            tokio::select! {
                read = port.read(&mut buf) => match read {
                    Ok(0) => break "device closed".to_owned(),
                    Ok(n) => {
                        session.received(&buf[..n], now());
                        deliver(&mut session, &events, &stats_tx);
                    }
                    Err(e) => break format!("read failed: {e}"),
                },
                req = rx.recv() => match req {
                    None => break 'outer,
                    Some(req) => {
                        take(&mut session, req);
                        // Drain what else is waiting so that only the newest thrust survives.
                        while let Ok(r) = rx.try_recv() {
                            take(&mut session, r);
                        }
                    }
                },
                _ = tokio::time::sleep_until(wake) => {}
            }
        };
        drop(port);
        let retry_at = session.closed(down_reason, now());
        deliver(&mut session, &events, &stats_tx);
        if !wait_retry(&mut rx, &mut session, retry_at).await {
            break 'outer;
        }
    }
    let _ = stats_tx.send(session.stats().clone());
}

/// Hands one request from the vehicle task to the session.
fn take(session: &mut Session, req: Request) {
    match req {
        Request::Command(c) => session.command(c),
        Request::Healthy => session.healthy(now()),
    }
}

/// Delivers the session's outputs in the order it decided them.
fn deliver(
    session: &mut Session,
    events: &mpsc::Sender<LinkEvent>,
    stats_tx: &watch::Sender<LinkStats>,
) {
    while let Some(out) = session.poll_output() {
        match out {
            Output::Stats(stats) => {
                let _ = stats_tx.send(stats);
            }
            Output::Event(ev) => {
                if let Err(e) = events.try_send(ev) {
                    session.event_dropped(&e.into_inner());
                }
            }
        }
    }
}

/// Waits until `retry_at` while still taking requests, so that the newest
/// thrust command is what goes out once the board is back. `false` when every
/// [`super::LinkHandle`] is gone.
async fn wait_retry(
    rx: &mut mpsc::UnboundedReceiver<Request>,
    session: &mut Session,
    retry_at: std::time::Instant,
) -> bool {
    let retry_at = Instant::from_std(retry_at);
    loop {
        tokio::select! {
            req = rx.recv() => match req {
                None => return false,
                Some(req) => take(session, req),
            },
            _ = tokio::time::sleep_until(retry_at) => return true,
        }
    }
}
