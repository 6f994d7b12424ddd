//! Asking a V4L2 device what it offers ([`DeviceCaps`]), through the
//! `linuxvideo` crate's ioctls: `VIDIOC_QUERYCAP`, then for each capture
//! format `VIDIOC_ENUM_FRAMESIZES` and, for each size,
//! `VIDIOC_ENUM_FRAMEINTERVALS`.
//!
//! Blocking (a few dozen ioctls: milliseconds). It only asks: nothing is
//! set, no stream is started, and another program may hold the device
//! meanwhile. A driver whose answers the crate cannot take (it asserts on
//! some) is an error here, never a panic of the vehicle.

use std::path::Path;

use linuxvideo::format::{FrameIntervals, FrameSizes};
use linuxvideo::{BufType, Device, Fract};

use super::caps::{DeviceCaps, FormatCaps, Interval, Intervals, SizeCaps, Sizes, StepwiseSizes};

/// Why a device could not be asked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProbeError {
    #[error("camera device {path} does not exist")]
    Missing { path: String },
    #[error("camera device {path} cannot be opened: {error}")]
    Open { path: String, error: String },
    #[error("{path} is not a V4L2 video capture device ({detail})")]
    NotCapture { path: String, detail: String },
    #[error("camera device {path} did not answer {what}: {error}")]
    Ioctl {
        path: String,
        what: &'static str,
        error: String,
    },
    #[error("camera device {path}: its driver answered something unexpected while listing {what}")]
    Driver { path: String, what: &'static str },
}

fn interval(f: &Fract) -> Interval {
    Interval {
        numerator: f.numerator(),
        denominator: f.denominator(),
    }
}

fn intervals(i: &FrameIntervals) -> Intervals {
    match i {
        FrameIntervals::Discrete(list) => {
            Intervals::Discrete(list.iter().map(|d| interval(d.fract())).collect())
        }
        FrameIntervals::Stepwise(s) | FrameIntervals::Continuous(s) => Intervals::Stepwise {
            min: interval(s.min()),
            max: interval(s.max()),
        },
    }
}

/// Runs `f`, turning a panic inside the crate into an error.
fn guarded<T>(
    path: &str,
    what: &'static str,
    f: impl FnOnce() -> std::io::Result<T>,
) -> Result<T, ProbeError> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(ProbeError::Ioctl {
            path: path.to_owned(),
            what,
            error: e.to_string(),
        }),
        Err(_) => Err(ProbeError::Driver {
            path: path.to_owned(),
            what,
        }),
    }
}

/// Opens `path` as a V4L2 device (the caller checked it is a character
/// device), checking it captures video.
pub(super) fn open(path: &Path) -> Result<Device, ProbeError> {
    let p = path.display().to_string();
    if !path.exists() {
        return Err(ProbeError::Missing { path: p });
    }
    let dev = Device::open(path).map_err(|e| ProbeError::Open {
        path: p.clone(),
        error: e.to_string(),
    })?;
    if !dev
        .supported_buf_types()
        .contains(linuxvideo::BufTypes::VIDEO_CAPTURE)
    {
        let card = dev
            .capabilities()
            .map(|c| format!("{} ({})", c.card(), c.driver()))
            .unwrap_or_default();
        return Err(ProbeError::NotCapture {
            path: p,
            detail: format!(
                "{card} captures no single-plane video; a camera often has a second node for metadata: try the next /dev/videoN"
            ),
        });
    }
    Ok(dev)
}

/// Everything `path` offers for video capture.
pub fn probe(path: &Path) -> Result<DeviceCaps, ProbeError> {
    let dev = open(path)?;
    probe_device(&dev, &path.display().to_string())
}

pub(super) fn probe_device(dev: &Device, p: &str) -> Result<DeviceCaps, ProbeError> {
    let caps = guarded(p, "VIDIOC_QUERYCAP", || dev.capabilities())?;
    let descs = guarded(p, "VIDIOC_ENUM_FMT", || {
        dev.formats(BufType::VIDEO_CAPTURE)
            .collect::<std::io::Result<Vec<_>>>()
    })?;
    let mut formats = Vec::new();
    for d in descs {
        let pf = d.pixel_format();
        let fourcc = String::from_utf8_lossy(&pf.as_fourcc()).trim().to_owned();
        let sizes = match guarded(p, "VIDIOC_ENUM_FRAMESIZES", || dev.frame_sizes(pf))? {
            FrameSizes::Discrete(list) => {
                let mut out = Vec::new();
                for s in list {
                    let (w, h) = (s.width(), s.height());
                    let iv = guarded(p, "VIDIOC_ENUM_FRAMEINTERVALS", || {
                        dev.frame_intervals(pf, w, h)
                    })?;
                    out.push(SizeCaps {
                        width: w,
                        height: h,
                        intervals: intervals(&iv),
                    });
                }
                Sizes::Discrete(out)
            }
            FrameSizes::Stepwise(s) | FrameSizes::Continuous(s) => {
                let iv = guarded(p, "VIDIOC_ENUM_FRAMEINTERVALS", || {
                    dev.frame_intervals(pf, s.max_width(), s.max_height())
                })?;
                Sizes::Stepwise(StepwiseSizes {
                    min_width: s.min_width(),
                    max_width: s.max_width(),
                    step_width: s.step_width(),
                    min_height: s.min_height(),
                    max_height: s.max_height(),
                    step_height: s.step_height(),
                    intervals: intervals(&iv),
                })
            }
        };
        formats.push(FormatCaps {
            fourcc,
            description: d.description().to_owned(),
            compressed: d
                .flags()
                .contains(linuxvideo::format::FormatFlags::COMPRESSED),
            sizes,
        });
    }
    Ok(DeviceCaps {
        driver: caps.driver().to_owned(),
        card: caps.card().to_owned(),
        formats,
    })
}
