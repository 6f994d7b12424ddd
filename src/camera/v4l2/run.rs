//! One run of the `v4l2` source: ask the camera what it offers, choose the
//! path ([`choose`]), and pass its pictures on as they come — H.264
//! pictures to the H.264 bus (RTP and WebRTC), JPEG pictures to the page;
//! a raw camera's pictures JPEG-encoded only where `encode` allows it.
//!
//! The run ends (and the supervision loop starts it again after its
//! backoff, asking the camera anew) when the device fails or stalls, a
//! recording ends, or the camera offers nothing usable.

use std::path::PathBuf;
use std::time::Duration;

use bytes::Bytes;
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
        Node::Device => capture::device(path, cap.clone()),
        _ => capture::stream(path),
    };
    // A recording plays at its rate; a device and a pipe pace themselves.
    let mut pace = (what == Node::File).then(|| {
        let mut t = tokio::time::interval(Duration::from_secs_f64(1.0 / cap.fps().max(0.1)));
        t.set_missed_tick_behavior(MissedTickBehavior::Delay);
        t
    });
    let whole = what == Node::Device;
    let (mut width, mut height) = (cap.width, cap.height);
    let mut units = UnitSplitter::new();
    let mut jpegs = JpegSplitter::new();
    let stall = cfg.stall_timeout();
    let mut deadline = Instant::now() + stall;
    let quality = cfg.jpeg_quality;
    loop {
        let read = tokio::select! {
            r = rx.recv() => r,
            () = tokio::time::sleep_until(deadline) => {
                return SourceError::Stalled { kind: KIND, what: device, secs: stall.as_secs_f64() };
            }
        };
        let bytes = match read {
            Some(Read::Bytes(b)) => b,
            Some(Read::Started {
                width: w,
                height: h,
                fps,
            }) => {
                if w > 0 && h > 0 {
                    (width, height) = (w, h);
                }
                tracing::info!(
                    "camera {device}: {} {width}×{height}{}",
                    cap.fourcc,
                    fps.map(|f| format!(" at {f:.3} fps")).unwrap_or_default()
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
                if whole {
                    units.end_unit();
                }
                send_units(&mut units, &mut pace, out, width, height).await;
            }
            Kind::Mjpeg => {
                jpegs.push(&bytes);
                while let Some(j) = jpegs.next_frame() {
                    tick(&mut pace).await;
                    out.publish(j.jpeg, j.width, j.height);
                }
            }
            Kind::Yuyv => {
                let (w, h) = (width, height);
                let job = tokio::task::spawn_blocking(move || yuyv_to_jpeg(&bytes, w, h, quality));
                match job.await {
                    Ok(Some(jpeg)) => out.publish(jpeg, w, h),
                    Ok(None) => {
                        tracing::debug!("camera {device}: a raw picture of the wrong size, dropped")
                    }
                    Err(_) => {
                        return SourceError::Read {
                            kind: KIND,
                            what: device,
                            error: "the encoder stopped".into(),
                        };
                    }
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

/// A YUYV (4:2:2) picture as JPEG; `None` when the buffer is not one
/// `width` × `height` picture.
pub(crate) fn yuyv_to_jpeg(yuyv: &[u8], width: u32, height: u32, quality: u8) -> Option<Bytes> {
    let (w, h) = (usize::try_from(width).ok()?, usize::try_from(height).ok()?);
    if w % 2 != 0 || yuyv.len() < w * h * 2 || w == 0 || h == 0 {
        return None;
    }
    let mut ycbcr = Vec::with_capacity(w * h * 3);
    for quad in yuyv[..w * h * 2].chunks_exact(4) {
        let (y0, u, y1, v) = (quad[0], quad[1], quad[2], quad[3]);
        ycbcr.extend_from_slice(&[y0, u, v, y1, u, v]);
    }
    let mut jpeg = Vec::new();
    jpeg_encoder::Encoder::new(&mut jpeg, quality)
        .encode(
            &ycbcr,
            u16::try_from(w).ok()?,
            u16::try_from(h).ok()?,
            jpeg_encoder::ColorType::Ycbcr,
        )
        .ok()?;
    Some(Bytes::from(jpeg))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_raw_picture_becomes_a_jpeg_of_its_size() {
        // Mid grey with neutral chroma.
        let raw = vec![128u8; 64 * 48 * 2];
        let jpeg = yuyv_to_jpeg(&raw, 64, 48, 80).expect("a picture");
        let mut d = jpeg_decoder::Decoder::new(&jpeg[..]);
        let pixels = d.decode().expect("decodes");
        let info = d.info().expect("info");
        assert_eq!((info.width, info.height), (64, 48));
        assert!(
            pixels.iter().all(|&p| p.abs_diff(128) <= 2),
            "grey stays grey"
        );
        assert!(yuyv_to_jpeg(&raw[..100], 64, 48, 80).is_none());
        assert!(yuyv_to_jpeg(&raw, 63, 48, 80).is_none());
    }
}
