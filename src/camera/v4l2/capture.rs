//! Reading the camera's frames: a V4L2 device on a thread of its own
//! (memory-mapped streaming; each buffer the driver fills is one picture),
//! or a recorded stream from a file or named pipe in its place.
//!
//! Both hand over bytes on a channel ([`Read`]): whole pictures from the
//! device, arbitrary chunks from a stream (the caller cuts them). Nothing
//! is decoded here. The device thread ends when the receiver is dropped
//! (checked at least twice a second), closing the device.

use std::os::fd::AsFd;
use std::path::{Path, PathBuf};

use linuxvideo::Fract;
use linuxvideo::format::{PixFormat, PixelFormat};
use tokio::io::AsyncReadExt;
use tokio::sync::mpsc;

use super::caps::Capture;
use super::probe;

/// What a reader hands over.
#[derive(Debug)]
pub(crate) enum Read {
    /// The device took the format: its size and rate as the driver set them.
    Started {
        width: u32,
        height: u32,
        fps: Option<f64>,
    },
    /// One whole picture (device) or the next bytes (stream).
    Bytes(Vec<u8>),
    /// The device or stream failed, or a stream ended (`None`).
    Ended(Option<String>),
}

/// Starts reading the V4L2 device `path` in `cap`'s format on a thread.
pub(crate) fn device(path: PathBuf, cap: Capture) -> mpsc::Receiver<Read> {
    let (tx, rx) = mpsc::channel(4);
    let spawned = std::thread::Builder::new()
        .name("camera-v4l2".into())
        .spawn({
            let tx = tx.clone();
            move || {
                let end = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    read_device(&path, &cap, &tx)
                })) {
                    Ok(Ok(())) => return,
                    Ok(Err(e)) => e,
                    Err(_) => "its driver answered something unexpected".into(),
                };
                let _ = tx.blocking_send(Read::Ended(Some(end)));
            }
        });
    if let Err(e) = spawned {
        let _ = tx.try_send(Read::Ended(Some(format!("no thread to read it: {e}"))));
    }
    rx
}

fn read_device(path: &Path, cap: &Capture, tx: &mpsc::Sender<Read>) -> Result<(), String> {
    let dev = probe::open(path).map_err(|e| e.to_string())?;
    let fourcc: [u8; 4] = cap
        .fourcc
        .as_bytes()
        .try_into()
        .map_err(|_| format!("{:?} is not a four-character code", cap.fourcc))?;
    let want = PixelFormat::from_fourcc(fourcc);
    let capture = dev
        .video_capture(PixFormat::new(cap.width, cap.height, want))
        .map_err(|e| {
            format!(
                "VIDIOC_S_FMT {} {}×{}: {e}",
                cap.fourcc, cap.width, cap.height
            )
        })?;
    let (got_format, got_width, got_height) = {
        let f = capture.format();
        (f.pixel_format(), f.width(), f.height())
    };
    if got_format != want {
        return Err(format!(
            "asked for {}, the driver set {}",
            cap.fourcc,
            String::from_utf8_lossy(&got_format.as_fourcc())
        ));
    }
    let fps = match capture
        .set_frame_interval(Fract::new(cap.interval.numerator, cap.interval.denominator))
    {
        Ok(f) if f.numerator() > 0 => Some(f64::from(f.denominator()) / f64::from(f.numerator())),
        Ok(_) => None,
        Err(e) => {
            tracing::warn!(
                "camera {}: the frame interval {} was refused ({e}): the camera's own rate is used",
                path.display(),
                cap.interval
            );
            None
        }
    };
    let mut stream = capture
        .into_stream()
        .map_err(|e| format!("starting the stream (VIDIOC_REQBUFS/STREAMON): {e}"))?;
    if tx
        .blocking_send(Read::Started {
            width: got_width,
            height: got_height,
            fps,
        })
        .is_err()
    {
        return Ok(());
    }
    loop {
        if tx.is_closed() {
            return Ok(());
        }
        let ready = {
            use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
            let mut fds = [PollFd::new(stream.as_fd(), PollFlags::POLLIN)];
            match poll(&mut fds, PollTimeout::from(500u16)) {
                Ok(n) => n > 0,
                Err(nix::errno::Errno::EINTR) => false,
                Err(e) => return Err(format!("poll: {e}")),
            }
        };
        if !ready {
            continue;
        }
        let picture = stream
            .dequeue(|buf| {
                Ok(if buf.is_error() {
                    None
                } else {
                    Some(buf.to_vec())
                })
            })
            .map_err(|e| format!("VIDIOC_DQBUF: {e}"))?;
        // A buffer the driver flagged as damaged is dropped.
        if let Some(bytes) = picture.filter(|b| !b.is_empty())
            && tx.blocking_send(Read::Bytes(bytes)).is_err()
        {
            return Ok(());
        }
    }
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
        if tx
            .send(Read::Started {
                width: 0,
                height: 0,
                fps: None,
            })
            .await
            .is_err()
        {
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
