//! Asking a V4L2 device what it offers ([`DeviceCaps`]) through
//! `v4l2-ctl -d DEVICE --info --list-formats-ext` (Debian's v4l-utils):
//! the driver and card (`VIDIOC_QUERYCAP`), each capture format
//! (`VIDIOC_ENUM_FMT`), its sizes (`VIDIOC_ENUM_FRAMESIZES`) and, per size,
//! its frame intervals (`VIDIOC_ENUM_FRAMEINTERVALS`), as the tool prints
//! them; [`parse`] reads that text.
//!
//! A tool rather than the ioctls in-process: the crates that wrap them
//! either do not build for the BeagleBone's 32-bit ARM or need libclang at
//! build time, and the crate keeps no `unsafe` of its own for them.
//! Blocking (one short-lived process). It only asks: nothing is set, and
//! another program may hold the device meanwhile. Text it does not
//! understand is skipped, never a panic.

use std::path::Path;
use std::process::Command;

use super::caps::{DeviceCaps, FormatCaps, Interval, Intervals, SizeCaps, Sizes, StepwiseSizes};

/// Why a device could not be asked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProbeError {
    #[error(
        "cannot ask camera device {path} what it offers: `v4l2-ctl` is not installed — sudo apt install v4l-utils"
    )]
    NoTool { path: String },
    #[error("camera device {path} did not answer `v4l2-ctl --list-formats-ext`: {detail}")]
    Failed { path: String, detail: String },
}

/// Everything `path` offers for video capture.
pub fn probe(path: &Path) -> Result<DeviceCaps, ProbeError> {
    let p = path.display().to_string();
    let out = Command::new("v4l2-ctl")
        .arg("-d")
        .arg(path)
        .args(["--info", "--list-formats-ext"])
        .output()
        .map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                ProbeError::NoTool { path: p.clone() }
            } else {
                ProbeError::Failed {
                    path: p.clone(),
                    detail: e.to_string(),
                }
            }
        })?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let detail = err
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("");
        return Err(ProbeError::Failed {
            path: p,
            detail: format!("{} {}", out.status, detail.trim()),
        });
    }
    Ok(parse(&String::from_utf8_lossy(&out.stdout)))
}

/// `N.NNN` in `(N.NNN fps)`, or both ends of `(A-B fps)`.
fn fps_in(line: &str) -> Option<(f64, f64)> {
    let inside = line.rsplit_once('(')?.1.strip_suffix("fps)")?.trim();
    match inside.split_once('-') {
        Some((a, b)) => Some((a.trim().parse().ok()?, b.trim().parse().ok()?)),
        None => {
            let f = inside.parse().ok()?;
            Some((f, f))
        }
    }
}

/// `WxH`.
fn size_in(word: &str) -> Option<(u32, u32)> {
    let (w, h) = word.trim().split_once('x')?;
    Some((w.parse().ok()?, h.parse().ok()?))
}

/// Reads `v4l2-ctl --info --list-formats-ext` output.
pub fn parse(text: &str) -> DeviceCaps {
    let mut caps = DeviceCaps {
        driver: String::new(),
        card: String::new(),
        formats: Vec::new(),
    };
    for line in text.lines() {
        let l = line.trim();
        if let Some(v) = l.strip_prefix("Driver name") {
            caps.driver = v.trim_start().trim_start_matches(':').trim().to_owned();
        } else if let Some(v) = l.strip_prefix("Card type") {
            caps.card = v.trim_start().trim_start_matches(':').trim().to_owned();
        } else if l.starts_with('[')
            && let Some((_, rest)) = l.split_once("]: '")
            && let Some((fourcc, desc)) = rest.split_once('\'')
        {
            let desc = desc.trim().trim_start_matches('(').trim_end_matches(')');
            caps.formats.push(FormatCaps {
                fourcc: fourcc.trim().to_owned(),
                description: desc.trim_end_matches(", compressed").to_owned(),
                compressed: desc.ends_with(", compressed"),
                sizes: Sizes::Discrete(Vec::new()),
            });
        } else if let Some(v) = l.strip_prefix("Size:") {
            let Some(f) = caps.formats.last_mut() else {
                continue;
            };
            let words: Vec<&str> = v.split_whitespace().collect();
            match words.as_slice() {
                ["Discrete", wh, ..] => {
                    if let (Some((width, height)), Sizes::Discrete(list)) =
                        (size_in(wh), &mut f.sizes)
                    {
                        list.push(SizeCaps {
                            width,
                            height,
                            intervals: Intervals::Discrete(Vec::new()),
                        });
                    }
                }
                [kind @ ("Stepwise" | "Continuous"), min, "-", max, rest @ ..] => {
                    let (Some(min), Some(max)) = (size_in(min), size_in(max)) else {
                        continue;
                    };
                    let step = match (*kind, rest) {
                        ("Stepwise", ["with", "step", s, ..]) => {
                            let (a, b) = s.split_once('/').unwrap_or((s, s));
                            (a.parse().unwrap_or(1), b.parse().unwrap_or(1))
                        }
                        _ => (1, 1),
                    };
                    f.sizes = Sizes::Stepwise(StepwiseSizes {
                        min_width: min.0,
                        max_width: max.0,
                        step_width: step.0,
                        min_height: min.1,
                        max_height: max.1,
                        step_height: step.1,
                        intervals: Intervals::Discrete(Vec::new()),
                    });
                }
                _ => {}
            }
        } else if let Some(v) = l.strip_prefix("Interval:") {
            let Some(f) = caps.formats.last_mut() else {
                continue;
            };
            let target = match &mut f.sizes {
                Sizes::Discrete(list) => match list.last_mut() {
                    Some(s) => &mut s.intervals,
                    None => continue,
                },
                Sizes::Stepwise(s) => &mut s.intervals,
            };
            let Some((slow, fast)) = fps_in(v) else {
                continue;
            };
            if v.trim_start().starts_with("Discrete") {
                if let Intervals::Discrete(list) = target {
                    list.push(Interval::from_fps(fast));
                }
            } else {
                *target = Intervals::Stepwise {
                    min: Interval::from_fps(fast.max(slow)),
                    max: Interval::from_fps(fast.min(slow)),
                };
            }
        }
    }
    caps
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stepwise_sizes_and_intervals_and_odd_lines() {
        let text = "Driver Info:\n\tDriver name      : bcm2835 mmal\n\tCard type        : mmal service 16.1\n\
            ioctl: VIDIOC_ENUM_FMT\n\tType: Video Capture\n\n\
            \t[0]: 'YU12' (Planar YUV 4:2:0)\n\t\tSize: Stepwise 32x32 - 2592x1944 with step 2/2\n\
            \t\t\tInterval: Stepwise 0.033s - 1.000s with step 0.000s (1.000-30.000 fps)\n\
            \t[1]: 'H264' (H.264, compressed)\n\t\tSize: Continuous 32x32 - 1920x1080\n\
            \t\tSize: garbage\n\t\t\tInterval: nonsense\n\t[2: 'broken\n";
        let c = parse(text);
        assert_eq!(c.driver, "bcm2835 mmal");
        assert_eq!(c.card, "mmal service 16.1");
        assert_eq!(c.fourccs(), ["YU12", "H264"]);
        assert!(c.formats[1].compressed && !c.formats[0].compressed);
        assert_eq!(c.formats[1].description, "H.264");
        let Sizes::Stepwise(s) = &c.formats[0].sizes else {
            panic!("stepwise");
        };
        assert_eq!((s.max_width, s.step_width, s.step_height), (2592, 2, 2));
        assert_eq!(
            s.intervals,
            Intervals::Stepwise {
                min: Interval::from_fps(30.0),
                max: Interval::from_fps(1.0)
            }
        );
        assert_eq!(
            c.formats[1].nearest(640, 480, 15.0).map(|(w, h, _)| (w, h)),
            Some((640, 480))
        );
        assert_eq!(parse("").formats, []);
    }
}
