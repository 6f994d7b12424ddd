//! One run of the `v4l2` source: ask the camera what it offers, choose the
//! path ([`choose`]), and pass its pictures on as they come — H.264
//! pictures to the H.264 bus (RTP and WebRTC), JPEG pictures to the page;
//! a raw camera's pictures JPEG-encoded (by the ffmpeg that reads it) only
//! where `encode` allows it.
//!
//! The run ends (and the supervision loop starts it again after its
//! backoff, asking the camera anew) when the device fails or stalls, a
//! recording ends, or the camera offers nothing usable.

use std::path::PathBuf;
use std::time::Duration;

use tokio::time::{Instant, MissedTickBehavior};

use super::capture::{self, Read};
use super::{Kind, Node, node};
use crate::camera::config::{CameraConfig, SourceKind};
use crate::camera::error::SourceError;
use crate::camera::h264::UnitSplitter;
use crate::camera::plan::{Offer, choose};
use crate::camera::publisher::Publisher;
use crate::camera::splitter::JpegSplitter;

const KIND: SourceKind = SourceKind::V4l2;

pub(crate) async fn run(cfg: &CameraConfig, out: &mut Publisher) -> SourceError {
    let v4l2 = cfg.v4l2.clone();
    let offer = tokio::task::spawn_blocking(move || crate::camera::plan::offer(&v4l2))
        .await
        .unwrap_or_else(|_| Offer::Unreadable("asking the camera failed".into()));
    let plan = choose(cfg, &offer);
    out.set_plan(&plan);
    let device = cfg.v4l2.device.clone();
    let Some(cap) = plan.capture.clone() else {
        return SourceError::Unusable {
            kind: KIND,
            why: plan.why.clone(),
            fix: plan
                .fix
                .clone()
                .unwrap_or_else(|| "check the camera".into()),
        };
    };
    let path = PathBuf::from(&device);
    let what = node(&path);
    out.starting(None);
    let mut rx = match what {
        Node::Device => capture::device(
            cfg.ffmpeg.program.clone(),
            capture::device_args(&device, &cap, cfg.jpeg_quality),
        ),
        _ => capture::stream(path),
    };
    // A recording plays at its rate; a device and a pipe pace themselves.
    let mut pace = (what == Node::File).then(|| {
        let mut t = tokio::time::interval(Duration::from_secs_f64(1.0 / cap.fps().max(0.1)));
        t.set_missed_tick_behavior(MissedTickBehavior::Delay);
        t
    });
    let (width, height) = (cap.width, cap.height);
    let mut units = UnitSplitter::new();
    let mut jpegs = JpegSplitter::new();
    let stall = cfg.stall_timeout();
    let mut deadline = Instant::now() + stall;
    loop {
        let read = tokio::select! {
            r = rx.recv() => r,
            () = tokio::time::sleep_until(deadline) => {
                return SourceError::Stalled { kind: KIND, what: device, secs: stall.as_secs_f64() };
            }
        };
        let bytes = match read {
            Some(Read::Bytes(b)) => b,
            Some(Read::Started) => {
                tracing::info!(
                    "camera {device}: {} {width}×{height} at {} fps",
                    cap.fourcc,
                    cap.fps()
                );
                continue;
            }
            Some(Read::Ended(None)) | None => {
                if cap.kind == Kind::H264 {
                    units.end_unit();
                    send_units(&mut units, &mut pace, out, width, height).await;
                }
                return SourceError::StreamEnded {
                    kind: KIND,
                    url: device,
                    detail: String::new(),
                };
            }
            Some(Read::Ended(Some(error))) => {
                return SourceError::Device {
                    kind: KIND,
                    device,
                    error,
                };
            }
        };
        let before = out.frames();
        match cap.kind {
            Kind::H264 => {
                units.push(&bytes);
                send_units(&mut units, &mut pace, out, width, height).await;
            }
            // A raw camera's pictures come JPEG-encoded by its ffmpeg.
            Kind::Mjpeg | Kind::Yuyv => {
                jpegs.push(&bytes);
                while let Some(j) = jpegs.next_frame() {
                    tick(&mut pace).await;
                    out.publish(j.jpeg, j.width, j.height);
                }
            }
        }
        if out.frames() != before {
            deadline = Instant::now() + stall;
        }
    }
}

async fn tick(pace: &mut Option<tokio::time::Interval>) {
    if let Some(p) = pace {
        p.tick().await;
    }
}

async fn send_units(
    units: &mut UnitSplitter,
    pace: &mut Option<tokio::time::Interval>,
    out: &mut Publisher,
    width: u32,
    height: u32,
) {
    while let Some(u) = units.next_unit() {
        tick(pace).await;
        out.publish_unit(u, width, height, units.sps());
    }
}
