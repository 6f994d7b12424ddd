//! The recordings directory (`DATA_DIR/recordings/`): the names of its
//! files, their listing, and the files of the recording being written.
//!
//! One flat directory, every file of every recording in it:
//! `rec-YYYYMMDD-HHMMSS-NNN.ts` (the video, a segment every
//! [`SEGMENT`]), `rec-YYYYMMDD-HHMMSS-NNN.vtt` (its subtitles) and
//! `rec-YYYYMMDD-HHMMSS.csv` (the recording's telemetry); a second
//! recording started in the same second gets `-2`, `-3`… after the time.
//! [`list`] gives only names of that form, so whoever serves them (the
//! HMI's downloads, MAVLink FTP) serves what the listing produced and
//! never joins a requested path onto the directory.
//!
//! Written as it comes: each picture and each telemetry line is handed to
//! the kernel at once (a SIGKILL loses nothing written), and [`Files::sync`]
//! makes them durable (a power cut loses at most what came since the last
//! sync, which the recorder runs every second).

use std::fs::{File, OpenOptions};
use std::io::{self, Write as _};
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Serialize;

use super::sidecar::{self, CSV_HEADER, CUE_PERIOD, VTT_HEADER};
use super::ts::TsMuxer;
use crate::vehicle::machine::RecordSample;

/// The recordings' directory in the data directory.
pub const RECORDINGS_DIR: &str = "recordings";
/// A new video file (and subtitle file) starts at the first keyframe
/// after this long.
pub const SEGMENT: Duration = Duration::from_secs(300);

/// `DATA_DIR/recordings`.
pub fn recordings_dir(data_dir: &Path) -> PathBuf {
    data_dir.join(RECORDINGS_DIR)
}

/// What a file of a recording holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FileKind {
    /// MPEG-TS, H.264 as the camera made it.
    Video,
    /// WebVTT beside a video file.
    Subtitles,
    /// CSV of the recording's telemetry.
    Telemetry,
}

/// One file in the recordings directory.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct RecordingFile {
    /// The file name (no directory).
    pub name: String,
    /// The recording it belongs to (`rec-YYYYMMDD-HHMMSS[-N]`).
    pub recording: String,
    pub kind: FileKind,
    pub bytes: u64,
    pub modified_unix_s: u64,
}

/// The recording and kind of one of our file names; None for anything
/// else (which is never listed nor served).
pub fn parse_name(name: &str) -> Option<(&str, FileKind)> {
    let (stem, ext) = name.rsplit_once('.')?;
    if !stem.starts_with("rec-")
        || !stem[4..].bytes().all(|b| b.is_ascii_digit() || b == b'-')
        || stem.len() > 64
    {
        return None;
    }
    match ext {
        "ts" => Some((segment_of(stem)?, FileKind::Video)),
        "vtt" => Some((segment_of(stem)?, FileKind::Subtitles)),
        "csv" if stem.len() >= 19 => Some((stem, FileKind::Telemetry)),
        _ => None,
    }
}

/// The recording of a segment's stem (`rec-…-NNN`).
fn segment_of(stem: &str) -> Option<&str> {
    let (rec, n) = stem.rsplit_once('-')?;
    (n.len() == 3 && n.bytes().all(|b| b.is_ascii_digit()) && rec.len() >= 19).then_some(rec)
}

/// The recordings' files in `dir`, by name (a missing directory is an
/// empty list). What MAVLink FTP's `recordings/` and the HMI list.
pub fn list(dir: &Path) -> Vec<RecordingFile> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut out: Vec<RecordingFile> = entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let (recording, kind) = parse_name(&name)?;
            let recording = recording.to_owned();
            let meta = e.metadata().ok().filter(std::fs::Metadata::is_file)?;
            let modified_unix_s = meta
                .modified()
                .ok()
                .and_then(|m| m.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_secs());
            Some(RecordingFile {
                name,
                recording,
                kind,
                bytes: meta.len(),
                modified_unix_s,
            })
        })
        .collect();
    out.sort_by(|a, b| a.name.cmp(&b.name));
    out
}

/// `dir/name` when `name` is in the listing, else None.
pub fn listed_path(dir: &Path, name: &str) -> Option<PathBuf> {
    list(dir)
        .iter()
        .any(|f| f.name == name)
        .then(|| dir.join(name))
}

/// `rec-YYYYMMDD-HHMMSS` (UTC) for a recording started at `unix_us`.
pub fn recording_name(unix_us: u64) -> String {
    let secs = unix_us / 1_000_000;
    let rem = secs % 86_400;
    let (y, m, d) = crate::eventlog::civil_from_days(secs / 86_400);
    format!(
        "rec-{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        (rem / 60) % 60,
        rem % 60
    )
}

fn create_new(path: &Path) -> io::Result<File> {
    OpenOptions::new().write(true).create_new(true).open(path)
}

/// One video segment and its subtitles.
struct Segment {
    name: String,
    /// The recording's time at its first picture.
    start: Duration,
    ts: File,
    vtt: File,
    muxer: TsMuxer,
}

/// The files of the recording being written.
pub struct Files {
    dir: PathBuf,
    name: String,
    csv: File,
    segment: Option<Segment>,
    segments: u32,
    /// The next second of recording time that gets a subtitle.
    next_cue: Duration,
    bytes: u64,
}

impl Files {
    /// Creates the recording `rec-…` for a start at `unix_us` (another
    /// suffix when that name is taken) and its CSV.
    pub fn create(dir: &Path, unix_us: u64) -> io::Result<Files> {
        std::fs::create_dir_all(dir)?;
        let base = recording_name(unix_us);
        let mut n = 1;
        let (name, mut csv) = loop {
            let name = if n == 1 {
                base.clone()
            } else {
                format!("{base}-{n}")
            };
            match create_new(&dir.join(format!("{name}.csv"))) {
                Ok(f) => break (name, f),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists && n < 1000 => n += 1,
                Err(e) => return Err(e),
            }
        };
        csv.write_all(CSV_HEADER.as_bytes())?;
        // The new names must survive a power cut as much as their bytes.
        crate::durable::sync_dir(dir)?;
        Ok(Files {
            dir: dir.to_path_buf(),
            name,
            csv,
            segment: None,
            segments: 0,
            next_cue: Duration::ZERO,
            bytes: CSV_HEADER.len() as u64,
        })
    }

    /// The recording's name (`rec-…`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Bytes written so far.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// One picture at recording time `t`; a keyframe [`SEGMENT`] after the
    /// segment's start begins the next segment.
    pub fn picture(&mut self, au: &[u8], t: Duration, keyframe: bool) -> io::Result<()> {
        let due = self
            .segment
            .as_ref()
            .is_none_or(|s| t.saturating_sub(s.start) >= SEGMENT);
        if keyframe && due {
            self.next_segment(t)?;
        }
        let Some(seg) = self.segment.as_mut() else {
            return Ok(()); // before the first keyframe: undecodable
        };
        let time_90khz = (t.saturating_sub(seg.start).as_micros() * 9 / 100) as u64;
        let bytes = seg
            .muxer
            .access_unit(au, time_90khz, keyframe)
            .map_err(io::Error::other)?;
        seg.ts.write_all(&bytes)?;
        self.bytes += bytes.len() as u64;
        Ok(())
    }

    fn next_segment(&mut self, t: Duration) -> io::Result<()> {
        self.segments += 1;
        let name = format!("{}-{:03}", self.name, self.segments);
        let ts = create_new(&self.dir.join(format!("{name}.ts")))?;
        let mut vtt = create_new(&self.dir.join(format!("{name}.vtt")))?;
        vtt.write_all(VTT_HEADER.as_bytes())?;
        self.bytes += VTT_HEADER.len() as u64;
        if let Some(old) = self.segment.take() {
            old.ts.sync_data()?;
            old.vtt.sync_data()?;
        }
        crate::durable::sync_dir(&self.dir)?;
        self.segment = Some(Segment {
            name,
            start: t,
            ts,
            vtt,
            muxer: TsMuxer::new(),
        });
        Ok(())
    }

    /// One telemetry sample at recording time `t`: a CSV row, and a
    /// subtitle when a new second began.
    pub fn sample(&mut self, s: &RecordSample, t: Duration) -> io::Result<()> {
        let (seg_name, seg_t) = match &self.segment {
            Some(seg) => (format!("{}.ts", seg.name), t.saturating_sub(seg.start)),
            None => (String::new(), Duration::ZERO),
        };
        let row = sidecar::csv_row(s, t, &seg_name, seg_t);
        self.csv.write_all(row.as_bytes())?;
        self.bytes += row.len() as u64;
        if let Some(seg) = self.segment.as_mut()
            && t >= self.next_cue
        {
            let cue = sidecar::vtt_cue(s, seg_t, seg_t + CUE_PERIOD);
            seg.vtt.write_all(cue.as_bytes())?;
            self.bytes += cue.len() as u64;
            self.next_cue = t + CUE_PERIOD;
        }
        Ok(())
    }

    /// Makes everything written so far durable.
    pub fn sync(&mut self) -> io::Result<()> {
        self.csv.sync_data()?;
        if let Some(seg) = &self.segment {
            seg.ts.sync_data()?;
            seg.vtt.sync_data()?;
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn only_our_names_are_ours() {
        let r = "rec-20261129-063500";
        assert_eq!(
            parse_name(&format!("{r}-001.ts")),
            Some((r, FileKind::Video))
        );
        assert_eq!(
            parse_name(&format!("{r}-2-013.vtt")),
            Some(("rec-20261129-063500-2", FileKind::Subtitles))
        );
        assert_eq!(
            parse_name(&format!("{r}.csv")),
            Some((r, FileKind::Telemetry))
        );
        assert_eq!(
            parse_name(&format!("{r}-2.csv")),
            Some(("rec-20261129-063500-2", FileKind::Telemetry))
        );
        for bad in [
            "../rec-20261129-063500-001.ts",
            "rec-20261129-063500-001.ts.tmp",
            "rec-20261129-063500.ts",
            "rec-x-001.ts",
            "rec-20261129-063500-001.mp4",
            "params.toml",
            "rec-.csv",
            "",
        ] {
            assert_eq!(parse_name(bad), None, "{bad}");
        }
        assert_eq!(recording_name(1_780_000_000_250_000), "rec-20260528-202640");
    }

    #[test]
    fn segments_start_at_keyframes_and_the_listing_shows_them() {
        let dir = tempfile::tempdir().unwrap();
        let mut f = Files::create(dir.path(), 1_780_000_000_000_000).unwrap();
        let mut again = Files::create(dir.path(), 1_780_000_000_000_000).unwrap();
        assert_eq!(again.name(), "rec-20260528-202640-2");
        again.sync().unwrap();
        let au = [0, 0, 0, 1, 0x65, 1, 2, 3];
        f.picture(&au, Duration::ZERO, false).unwrap();
        f.picture(&au, Duration::from_millis(100), true).unwrap();
        f.picture(&au, SEGMENT, false).unwrap();
        f.picture(&au, SEGMENT + Duration::from_millis(100), true)
            .unwrap();
        f.sync().unwrap();
        std::fs::write(dir.path().join("notes.txt"), "x").unwrap();
        let names: Vec<_> = list(dir.path()).into_iter().map(|f| f.name).collect();
        assert_eq!(
            names,
            [
                "rec-20260528-202640-001.ts",
                "rec-20260528-202640-001.vtt",
                "rec-20260528-202640-002.ts",
                "rec-20260528-202640-002.vtt",
                "rec-20260528-202640-2.csv",
                "rec-20260528-202640.csv",
            ]
        );
        assert!(listed_path(dir.path(), "notes.txt").is_none());
        assert!(listed_path(dir.path(), "rec-20260528-202640.csv").is_some());
    }
}
