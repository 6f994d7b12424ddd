//! What a V4L2 capture device offers, as its ioctls answer: the driver and
//! card (`VIDIOC_QUERYCAP`), each pixel format (`VIDIOC_ENUM_FMT`), its
//! frame sizes (`VIDIOC_ENUM_FRAMESIZES`) and, per size, its frame
//! intervals (`VIDIOC_ENUM_FRAMEINTERVALS`).
//!
//! Plain data with serde, so a device's answers can be recorded as JSON and
//! the choice of a video path ([`super::super::plan`]) tested on them
//! without the device. Reading them from a device is `probe`'s.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// A device's answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceCaps {
    /// The kernel driver (`uvcvideo` for USB cameras).
    pub driver: String,
    /// The camera's name as the driver reports it.
    pub card: String,
    pub formats: Vec<FormatCaps>,
}

/// One pixel format and the sizes it comes in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FormatCaps {
    /// The four-character code: `H264`, `MJPG`, `JPEG`, `YUYV`, …
    pub fourcc: String,
    pub description: String,
    /// `V4L2_FMT_FLAG_COMPRESSED`.
    #[serde(default)]
    pub compressed: bool,
    pub sizes: Sizes,
}

/// `VIDIOC_ENUM_FRAMESIZES`: a list (what UVC cameras give), or a range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Sizes {
    Discrete(Vec<SizeCaps>),
    Stepwise(StepwiseSizes),
}

/// One frame size and its frame intervals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SizeCaps {
    pub width: u32,
    pub height: u32,
    pub intervals: Intervals,
}

/// A range of sizes (`V4L2_FRMSIZE_TYPE_STEPWISE` or `_CONTINUOUS`, where
/// the steps are 1); any frame interval in `intervals`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepwiseSizes {
    pub min_width: u32,
    pub max_width: u32,
    pub step_width: u32,
    pub min_height: u32,
    pub max_height: u32,
    pub step_height: u32,
    pub intervals: Intervals,
}

/// `VIDIOC_ENUM_FRAMEINTERVALS`: a list, or a range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Intervals {
    Discrete(Vec<Interval>),
    Stepwise { min: Interval, max: Interval },
}

/// A frame interval in seconds, `numerator/denominator` (`1/30`: 30 fps).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Interval {
    pub numerator: u32,
    pub denominator: u32,
}

impl Interval {
    /// Frames per second; 0 for a zero interval (a driver's nonsense).
    pub fn fps(self) -> f64 {
        if self.numerator == 0 {
            0.0
        } else {
            f64::from(self.denominator) / f64::from(self.numerator)
        }
    }
}

impl Interval {
    /// The interval of `fps` frames a second, as a reduced fraction
    /// (`30` → `1/30`, `7.5` → `2/15`).
    pub fn from_fps(fps: f64) -> Interval {
        let den = (fps.max(0.001) * 1000.0).round() as u32;
        let (mut a, mut b) = (1000u32, den.max(1));
        while b != 0 {
            (a, b) = (b, a % b);
        }
        Interval {
            numerator: 1000 / a,
            denominator: den.max(1) / a,
        }
    }
}

impl fmt::Display for Interval {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.numerator, self.denominator)
    }
}

impl FromStr for Interval {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (n, d) = s
            .split_once('/')
            .ok_or_else(|| format!("frame interval {s:?} is not N/D"))?;
        let parse = |v: &str| {
            v.trim()
                .parse::<u32>()
                .map_err(|e| format!("frame interval {s:?}: {e}"))
        };
        Ok(Interval {
            numerator: parse(n)?,
            denominator: parse(d)?,
        })
    }
}

impl Serialize for Interval {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Interval {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// The pixel formats Neptunus can use, by what each path costs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// H.264 from the camera's own encoder: passed through as it is.
    H264,
    /// JPEG pictures (`MJPG`, `JPEG`): passed through to the page as they are.
    Mjpeg,
    /// Raw YUV 4:2:2 (`YUYV`): every path needs an encoder.
    Yuyv,
}

impl Kind {
    /// The kind of a four-character code, `None` for formats Neptunus does
    /// not read.
    pub fn of_fourcc(fourcc: &str) -> Option<Kind> {
        match fourcc.trim() {
            "H264" => Some(Kind::H264),
            "MJPG" | "JPEG" => Some(Kind::Mjpeg),
            "YUYV" => Some(Kind::Yuyv),
            _ => None,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Kind::H264 => "h264",
            Kind::Mjpeg => "mjpeg",
            Kind::Yuyv => "yuyv",
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl DeviceCaps {
    /// The first format of `kind` the device lists.
    pub fn format(&self, kind: Kind) -> Option<&FormatCaps> {
        self.formats
            .iter()
            .find(|f| Kind::of_fourcc(&f.fourcc) == Some(kind))
    }

    /// Every four-character code offered, in the device's order.
    pub fn fourccs(&self) -> Vec<String> {
        self.formats.iter().map(|f| f.fourcc.clone()).collect()
    }
}

/// The size and rate asked of the device for one format, and the fourcc
/// to ask with.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Capture {
    pub kind: Kind,
    pub fourcc: String,
    pub width: u32,
    pub height: u32,
    /// The frame interval asked for (`1/30`).
    pub interval: Interval,
}

impl Capture {
    pub fn fps(&self) -> f64 {
        self.interval.fps()
    }
}

impl FormatCaps {
    /// The offered size nearest to `width` × `height` (the same size when
    /// offered; else the least difference in area, the larger on a tie),
    /// and the offered rate nearest to `fps` at that size.
    pub fn nearest(&self, width: u32, height: u32, fps: f64) -> Option<(u32, u32, Interval)> {
        match &self.sizes {
            Sizes::Discrete(sizes) => {
                let area = |w: u32, h: u32| u64::from(w) * u64::from(h);
                let want = area(width, height);
                let best = sizes
                    .iter()
                    .filter(|s| s.width > 0 && s.height > 0)
                    .min_by_key(|s| {
                        let a = area(s.width, s.height);
                        (
                            !(s.width == width && s.height == height),
                            a.abs_diff(want),
                            std::cmp::Reverse(a),
                        )
                    })?;
                Some((best.width, best.height, best.intervals.nearest(fps)?))
            }
            Sizes::Stepwise(s) => {
                let fit = |v: u32, min: u32, max: u32, step: u32| {
                    let v = v.clamp(min, max.max(min));
                    let step = step.max(1);
                    min + (v - min) / step * step
                };
                Some((
                    fit(width, s.min_width, s.max_width, s.step_width),
                    fit(height, s.min_height, s.max_height, s.step_height),
                    s.intervals.nearest(fps)?,
                ))
            }
        }
    }
}

impl Intervals {
    /// The offered interval whose rate is nearest to `fps` (the faster on
    /// a tie); within a range, `1/fps` itself.
    pub fn nearest(&self, fps: f64) -> Option<Interval> {
        match self {
            // A driver that lists none is asked for the rate wanted.
            Intervals::Discrete(list) if list.is_empty() => Some(Interval::from_fps(fps)),
            Intervals::Discrete(list) => list
                .iter()
                .copied()
                .filter(|i| i.numerator > 0 && i.denominator > 0)
                .min_by(|a, b| {
                    let da = (a.fps() - fps).abs();
                    let db = (b.fps() - fps).abs();
                    da.total_cmp(&db).then(b.fps().total_cmp(&a.fps()))
                }),
            Intervals::Stepwise { min, max } => {
                let (fast, slow) = (min.fps(), max.fps());
                let (lo, hi) = if fast < slow {
                    (fast, slow)
                } else {
                    (slow, fast)
                };
                let f = fps.clamp(lo, hi).round().max(1.0);
                Some(Interval {
                    numerator: 1,
                    denominator: f as u32,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn iv(s: &str) -> Interval {
        s.parse().expect("interval")
    }

    #[test]
    fn intervals_parse_and_print() {
        assert_eq!(
            iv("1/30"),
            Interval {
                numerator: 1,
                denominator: 30
            }
        );
        assert_eq!(iv("1/30").to_string(), "1/30");
        assert_eq!(iv("2/15").fps(), 7.5);
        assert_eq!(iv("0/1").fps(), 0.0);
        assert_eq!(Interval::from_fps(30.0), iv("1/30"));
        assert_eq!(Interval::from_fps(7.5), iv("2/15"));
        assert_eq!(Interval::from_fps(0.1), iv("10/1"));
        assert!("30".parse::<Interval>().is_err());
        assert!("1/x".parse::<Interval>().is_err());
    }

    #[test]
    fn the_nearest_size_and_rate_are_asked_for() {
        let f = FormatCaps {
            fourcc: "MJPG".into(),
            description: "Motion-JPEG".into(),
            compressed: true,
            sizes: Sizes::Discrete(vec![
                SizeCaps {
                    width: 1280,
                    height: 720,
                    intervals: Intervals::Discrete(vec![iv("1/30"), iv("1/15")]),
                },
                SizeCaps {
                    width: 800,
                    height: 600,
                    intervals: Intervals::Discrete(vec![iv("1/30"), iv("1/20"), iv("1/10")]),
                },
                SizeCaps {
                    width: 320,
                    height: 240,
                    intervals: Intervals::Discrete(vec![iv("1/30")]),
                },
            ]),
        };
        assert_eq!(f.nearest(800, 600, 10.0), Some((800, 600, iv("1/10"))));
        // 640×480 is not offered: 800×600 is nearer than 320×240.
        assert_eq!(f.nearest(640, 480, 12.0), Some((800, 600, iv("1/10"))));
        assert_eq!(f.nearest(640, 480, 15.0), Some((800, 600, iv("1/20"))));
        assert_eq!(f.nearest(4000, 3000, 60.0), Some((1280, 720, iv("1/30"))));
        let range = FormatCaps {
            sizes: Sizes::Stepwise(StepwiseSizes {
                min_width: 32,
                max_width: 1920,
                step_width: 16,
                min_height: 32,
                max_height: 1080,
                step_height: 8,
                intervals: Intervals::Stepwise {
                    min: iv("1/60"),
                    max: iv("1/1"),
                },
            }),
            ..f
        };
        assert_eq!(range.nearest(650, 490, 25.0), Some((640, 488, iv("1/25"))));
        assert_eq!(range.nearest(9999, 1, 100.0), Some((1920, 32, iv("1/60"))));
    }

    #[test]
    fn formats_are_known_by_their_fourcc() {
        assert_eq!(Kind::of_fourcc("H264"), Some(Kind::H264));
        assert_eq!(Kind::of_fourcc("MJPG"), Some(Kind::Mjpeg));
        assert_eq!(Kind::of_fourcc("JPEG"), Some(Kind::Mjpeg));
        assert_eq!(Kind::of_fourcc("YUYV"), Some(Kind::Yuyv));
        assert_eq!(Kind::of_fourcc("NV12"), None);
    }
}
