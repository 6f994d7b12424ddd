//! Reading the camera's frames: a V4L2 device through an ffmpeg child
//! that copies what the camera gives to its stdout (`-c:v copy`: its
//! H.264 or JPEG as they are, nothing decoded or encoded; only a raw
//! YUYV camera's pictures are JPEG-encoded, where `encode` allows it), or
//! a recorded stream from a file or named pipe in its place, read
//! directly.
//!
//! Both hand over the bytes on a channel ([`Read`]) for the caller to cut
//! into pictures. The child is killed when the receiver is dropped.

use std::path::PathBuf;
use std::process::Stdio;

use tokio::io::AsyncReadExt;
use tokio::sync::mpsc;

use super::caps::{Capture, Kind};
use crate::camera::process::StderrTail;

/// What a reader hands over.
#[derive(Debug)]
pub(crate) enum Read {
    /// The device or stream is open.
    Started,
    /// The next bytes.
    Bytes(Vec<u8>),
    /// The device or stream failed, or a stream ended (`None`).
    Ended(Option<String>),
}

/// ffmpeg's arguments after the program name for reading `device` as
/// `cap` asks.
pub fn device_args(device: &str, cap: &Capture, quality: u8) -> Vec<String> {
    let mut a: Vec<String> = ["-hide_banner", "-nostdin", "-loglevel", "error"]
        .map(String::from)
        .to_vec();
    a.extend(["-fflags", "nobuffer", "-f", "v4l2", "-input_format"].map(String::from));
    a.push(
        match cap.kind {
            Kind::H264 => "h264",
            Kind::Mjpeg => "mjpeg",
            Kind::Yuyv => "yuyv422",
        }
        .into(),
    );
    a.push("-video_size".into());
    a.push(format!("{}x{}", cap.width, cap.height));
    a.push("-framerate".into());
    // A rate, the interval upside down.
    a.push(format!(
        "{}/{}",
        cap.interval.denominator, cap.interval.numerator
    ));
    a.push("-i".into());
    a.push(device.into());
    a.push("-an".into());
    match cap.kind {
        // The camera's own encoding, copied.
        Kind::H264 => a.extend(["-c:v", "copy", "-f", "h264"].map(String::from)),
        // UVC cameras often leave the Huffman tables out: put them back.
        Kind::Mjpeg => {
            a.extend(["-c:v", "copy", "-bsf:v", "mjpeg2jpeg", "-f", "mjpeg"].map(String::from))
        }
        // Raw pictures: JPEG-encoded for the page (allowed by the plan).
        Kind::Yuyv => {
            let q = (31 - u32::from(quality.min(100)) * 29 / 100).to_string();
            a.extend(["-c:v", "mjpeg", "-q:v", &q, "-f", "mjpeg"].map(String::from));
        }
    }
    a.extend(["-flush_packets", "1", "pipe:1"].map(String::from));
    a
}

/// Starts `program` reading the V4L2 device with `args`.
pub(crate) fn device(program: String, args: Vec<String>) -> mpsc::Receiver<Read> {
    let (tx, rx) = mpsc::channel(4);
    tokio::spawn(async move {
        let mut cmd = tokio::process::Command::new(&program);
        cmd.args(&args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .kill_on_drop(true);
        let mut child = match cmd.spawn() {
            Ok(c) => c,
            Err(e) => {
                let why = if e.kind() == std::io::ErrorKind::NotFound {
                    format!(
                        "`{program}` is not installed (sudo apt install ffmpeg): it reads the camera"
                    )
                } else {
                    format!("cannot start `{program}`: {e}")
                };
                let _ = tx.send(Read::Ended(Some(why))).await;
                return;
            }
        };
        let mut stderr = StderrTail::new(child.stderr.take(), &program);
        let Some(mut stdout) = child.stdout.take() else {
            return;
        };
        if tx.send(Read::Started).await.is_err() {
            return;
        }
        let mut buf = vec![0u8; 64 * 1024];
        loop {
            tokio::select! {
                r = stdout.read(&mut buf) => match r {
                    Ok(n) if n > 0 => {
                        if tx.send(Read::Bytes(buf[..n].to_vec())).await.is_err() {
                            return;
                        }
                    }
                    _ => break,
                },
                () = stderr.next() => {}
                () = tx.closed() => return,
            }
        }
        let status =
            match tokio::time::timeout(std::time::Duration::from_secs(2), child.wait()).await {
                Ok(Ok(s)) => s.to_string(),
                _ => {
                    let _ = child.kill().await;
                    "killed".into()
                }
            };
        stderr.drain(std::time::Duration::from_secs(1)).await;
        let _ = tx
            .send(Read::Ended(Some(format!(
                "`{program}` reading the camera exited ({status}){}",
                stderr.tail()
            ))))
            .await;
    });
    rx
}

/// Reads a file or named pipe in chunks until it ends.
pub(crate) fn stream(path: PathBuf) -> mpsc::Receiver<Read> {
    let (tx, rx) = mpsc::channel(4);
    tokio::spawn(async move {
        let mut file = match tokio::fs::File::open(&path).await {
            Ok(f) => f,
            Err(e) => {
                let _ = tx.send(Read::Ended(Some(e.to_string()))).await;
                return;
            }
        };
        if tx.send(Read::Started).await.is_err() {
            return;
        }
        let mut buf = vec![0u8; 64 * 1024];
        loop {
            let end = tokio::select! {
                r = file.read(&mut buf) => match r {
                    Ok(0) => Some(None),
                    Ok(n) => {
                        if tx.send(Read::Bytes(buf[..n].to_vec())).await.is_err() {
                            return;
                        }
                        None
                    }
                    Err(e) => Some(Some(e.to_string())),
                },
                () = tx.closed() => return,
            };
            if let Some(end) = end {
                let _ = tx.send(Read::Ended(end)).await;
                return;
            }
        }
    });
    rx
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::v4l2::Interval;

    /// The child-reading half of the device path, on a recording instead
    /// of `-f v4l2`: every picture comes through, and the end is told.
    #[tokio::test]
    async fn an_ffmpeg_child_copying_a_camera_stream_hands_over_every_picture() {
        let dir = tempfile::tempdir().expect("dir");
        let clip = dir.path().join("camera.h264");
        let made = std::process::Command::new("ffmpeg")
            .args(["-hide_banner", "-loglevel", "error", "-f", "lavfi"])
            .args(["-i", "testsrc2=size=320x240:rate=30", "-frames:v", "45"])
            .args([
                "-c:v",
                "libx264",
                "-preset",
                "ultrafast",
                "-g",
                "15",
                "-f",
                "h264",
            ])
            .arg(&clip)
            .status()
            .expect("ffmpeg is needed by this test: apt install ffmpeg");
        assert!(made.success());
        let mut args: Vec<String> = [
            "-hide_banner",
            "-nostdin",
            "-loglevel",
            "error",
            "-f",
            "h264",
            "-i",
        ]
        .map(String::from)
        .to_vec();
        args.push(clip.display().to_string());
        args.extend(
            [
                "-an",
                "-c:v",
                "copy",
                "-f",
                "h264",
                "-flush_packets",
                "1",
                "pipe:1",
            ]
            .map(String::from),
        );
        let mut rx = device("ffmpeg".into(), args);
        let mut split = crate::camera::h264::UnitSplitter::new();
        let (mut started, mut units, mut keyframes) = (false, 0, 0);
        loop {
            match rx.recv().await {
                Some(Read::Started) => started = true,
                Some(Read::Bytes(b)) => split.push(&b),
                Some(Read::Ended(why)) => {
                    assert!(why.expect("a reason").contains("exited (exit status: 0)"));
                    break;
                }
                None => panic!("the reader stopped without saying why"),
            }
        }
        split.end_unit();
        while let Some(u) = split.next_unit() {
            units += 1;
            keyframes += usize::from(u.keyframe);
        }
        assert!(started);
        assert_eq!((units, keyframes), (45, 3));
        let mut rx = device("no-such-ffmpeg".into(), Vec::new());
        match rx.recv().await {
            Some(Read::Ended(Some(why))) => assert!(why.contains("is not installed"), "{why}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_device_is_copied_never_encoded_unless_raw() {
        let cap = |kind, fourcc: &str| Capture {
            kind,
            fourcc: fourcc.into(),
            width: 640,
            height: 480,
            interval: Interval::from_fps(30.0),
        };
        let a = device_args("/dev/video0", &cap(Kind::H264, "H264"), 80).join(" ");
        assert!(
            a.contains("-f v4l2 -input_format h264 -video_size 640x480 -framerate 30/1 -i /dev/video0 -an -c:v copy -f h264"),
            "{a}"
        );
        assert!(!a.contains("libx264"), "{a}");
        let a = device_args("/dev/video0", &cap(Kind::Mjpeg, "MJPG"), 80).join(" ");
        assert!(a.contains("-input_format mjpeg"), "{a}");
        assert!(a.contains("-c:v copy -bsf:v mjpeg2jpeg -f mjpeg"), "{a}");
        let a = device_args("/dev/video0", &cap(Kind::Yuyv, "YUYV"), 80).join(" ");
        assert!(a.contains("-input_format yuyv422"), "{a}");
        assert!(a.contains("-c:v mjpeg -q:v 8 -f mjpeg"), "{a}");
        assert!(a.ends_with("-flush_packets 1 pipe:1"), "{a}");
    }
}
