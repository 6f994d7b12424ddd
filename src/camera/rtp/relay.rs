//! One run of the RTP sender that encodes nothing: pictures a camera
//! encoded itself go out as they came, packetized here (RTP to each ground
//! station's destination) and handed to the consumers in the vehicle (the
//! WebRTC hub, the recorder: `fanout`) directly.
//!
//! The pictures come from the camera's H.264 bus (`source = "v4l2"`) or
//! from an ffmpeg child copying a camera's stream (`[camera.h264]
//! passthrough`, see `passthrough`). Either way no process decodes or
//! encodes a picture, and the consumers get the camera's own access
//! units, not RTP read back.

use std::net::SocketAddr;

use tokio::io::AsyncReadExt;
use tokio::net::UdpSocket;
use tokio::sync::broadcast;
use tokio::time::Instant;

use super::encoder::{RtpError, exited};
use super::fanout::Fanout;
use super::passthrough::Copy;
use crate::camera::CameraHandle;
use crate::camera::h264::{AccessUnit, RtpPacketizer, UnitSplitter};
use crate::camera::process::StderrTail;

/// Where one run's pictures go.
pub(super) struct Relay {
    stations: Vec<SocketAddr>,
    v4: Option<UdpSocket>,
    v6: Option<UdpSocket>,
    packetizer: RtpPacketizer,
    /// The consumers in the vehicle, while they get the stream.
    fanout: Fanout,
    pub pictures: u64,
}

impl Relay {
    /// Resolves the destinations and binds a socket for each address
    /// family among them.
    pub async fn new(dests: &[(String, u16)], fanout: Fanout) -> Result<Relay, RtpError> {
        let mut stations = Vec::new();
        for (host, port) in dests {
            match tokio::net::lookup_host((host.as_str(), *port)).await {
                Ok(mut addrs) => stations.extend(addrs.next()),
                Err(e) => {
                    return Err(RtpError::Destination {
                        dest: format!("{host}:{port}"),
                        error: e.to_string(),
                    });
                }
            }
        }
        let bind = |any: &str| {
            let any = any.to_owned();
            async move { UdpSocket::bind(any).await }
        };
        let bind_err = |e: std::io::Error| RtpError::Destination {
            dest: "a local UDP socket".into(),
            error: e.to_string(),
        };
        let v4 = if stations.iter().any(SocketAddr::is_ipv4) {
            Some(bind("0.0.0.0:0").await.map_err(bind_err)?)
        } else {
            None
        };
        let v6 = if stations.iter().any(SocketAddr::is_ipv6) {
            Some(bind("[::]:0").await.map_err(bind_err)?)
        } else {
            None
        };
        Ok(Relay {
            stations,
            v4,
            v6,
            packetizer: RtpPacketizer::new(rand::random(), rand::random()),
            fanout,
            pictures: 0,
        })
    }

    /// Sends one picture to every station and every consumer.
    pub async fn send(&mut self, au: &AccessUnit) {
        self.pictures += 1;
        if !self.stations.is_empty() {
            for packet in self.packetizer.packets(&au.data, au.time_90khz) {
                for to in &self.stations {
                    let sock = if to.is_ipv4() { &self.v4 } else { &self.v6 };
                    if let Some(s) = sock
                        && let Err(e) = s.send_to(&packet, to).await
                    {
                        // A receiver not listening yet (ICMP refused) is
                        // not a failure of the stream.
                        tracing::trace!("RTP video: sending to {to}: {e}");
                    }
                }
            }
        }
        self.fanout.send(au);
    }
}

/// Relays the camera's own H.264 until the camera stops; `started` is
/// called at the first picture.
pub(super) async fn from_camera(
    camera: &CameraHandle,
    relay: &mut Relay,
    mut started: impl FnMut(),
) -> RtpError {
    // The camera runs while its pictures are wanted.
    let _demand = camera.demand();
    let mut units = camera.units();
    let mut need_keyframe = false;
    loop {
        let au = match units.recv().await {
            Ok(au) => au,
            Err(broadcast::error::RecvError::Lagged(n)) => {
                tracing::debug!(
                    "RTP video: {n} pictures of the camera missed, waiting for a keyframe"
                );
                need_keyframe = true;
                continue;
            }
            Err(broadcast::error::RecvError::Closed) => return RtpError::CameraGone,
        };
        if need_keyframe && !au.keyframe {
            continue;
        }
        need_keyframe = false;
        relay.send(&au).await;
        if relay.pictures == 1 {
            started();
        }
    }
}

/// Runs ffmpeg copying the camera's stream (`copy`) and relays its
/// pictures; `started(pid)` at the first. `epoch` is the media clock's
/// zero.
pub(super) async fn from_ffmpeg(
    program: &str,
    copy: &Copy,
    epoch: Instant,
    relay: &mut Relay,
    mut started: impl FnMut(Option<u32>),
) -> RtpError {
    let mut child = match copy.spawn(program) {
        Ok(c) => c,
        Err(e) => return e,
    };
    let pid = child.id();
    let mut stderr = StderrTail::new(child.stderr.take(), program);
    let Some(mut stdout) = child.stdout.take() else {
        return exited(child, stderr, program).await;
    };
    let mut splitter = UnitSplitter::new();
    let mut buf = vec![0u8; 64 * 1024];
    let mut last_new = Instant::now();
    loop {
        let stall_at = last_new + copy.stall;
        tokio::select! {
            r = stdout.read(&mut buf) => match r {
                Ok(0) | Err(_) => break,
                Ok(n) => {
                    splitter.push(&buf[..n]);
                    while let Some(u) = splitter.next_unit() {
                        let at = Instant::now();
                        last_new = at;
                        let since = at.saturating_duration_since(epoch);
                        let au = AccessUnit {
                            data: u.data,
                            time_90khz: (since.as_micros() * 9 / 100) as u64,
                            keyframe: u.keyframe,
                        };
                        relay.send(&au).await;
                        if relay.pictures == 1 {
                            started(pid);
                        }
                    }
                }
            },
            () = stderr.next() => {}
            () = tokio::time::sleep_until(stall_at) => {
                let _ = child.kill().await;
                return RtpError::Stalled {
                    program: program.to_owned(),
                    secs: copy.stall.as_secs_f64(),
                };
            }
        }
    }
    exited(child, stderr, program).await
}
