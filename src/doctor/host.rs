//! `neptunus doctor`'s checks of the machine around the vehicle: the
//! camera (device, program, a usable format), the ports the vehicle will
//! listen on, the data directory and the clock.

use std::net::{SocketAddr, TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::Command;

use super::Check;
use crate::camera::webrtc::SignallingAddr;
use crate::camera::{CameraConfig, SourceKind};
use crate::config::Settings;
use crate::mavlink::endpoint::EndpointSpec;
use crate::wallclock::{BUILD_UNIX_S, ClockSync, system_sync, system_unix_us};

/// Less free space than this on the data directory fails the check.
const MIN_FREE_BYTES: u64 = 100 * 1024 * 1024;

/// `name` on PATH (or as a path).
pub(super) fn find_program(name: &str) -> Option<PathBuf> {
    if name.contains('/') {
        return Path::new(name).is_file().then(|| PathBuf::from(name));
    }
    std::env::var_os("PATH")
        .iter()
        .flat_map(std::env::split_paths)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// The V4L2 device a camera source reads, from its arguments.
fn camera_device(c: &CameraConfig) -> Option<PathBuf> {
    match c.source {
        SourceKind::Ffmpeg => c
            .ffmpeg
            .input_args
            .windows(2)
            .find(|w| w[0] == "-i" && w[1].starts_with("/dev/"))
            .map(|w| PathBuf::from(&w[1])),
        SourceKind::MjpgStreamer => {
            let words: Vec<&str> = c.mjpg_streamer.input.split_whitespace().collect();
            let given = words
                .windows(2)
                .find(|w| w[0] == "-d")
                .map(|w| PathBuf::from(w[1]));
            // input_uvc's default device.
            given.or_else(|| {
                words
                    .first()
                    .is_some_and(|p| p.starts_with("input_uvc"))
                    .then(|| PathBuf::from("/dev/video0"))
            })
        }
        _ => None,
    }
}

/// Pixel formats named in `ffmpeg -f v4l2 -list_formats all` or
/// `v4l2-ctl --list-formats` output, lower case (`mjpeg`, `yuyv422`, `mjpg`, `yuyv`, `h264`).
pub fn parse_formats(text: &str) -> Vec<String> {
    let mut formats = Vec::new();
    for line in text.lines() {
        // ffmpeg: "[video4linux2,v4l2 @ 0x…] Compressed:       mjpeg :  Motion-JPEG : 640x480 …"
        if let Some(rest) = line
            .split_once("] Compressed:")
            .or_else(|| line.split_once("] Raw       :"))
            .or_else(|| line.split_once("] Raw:"))
            .map(|(_, r)| r)
            && let Some(name) = rest.split(':').next()
        {
            formats.push(name.trim().to_ascii_lowercase());
        }
        // v4l2-ctl: "	[0]: 'MJPG' (Motion-JPEG, compressed)"
        if let Some((_, rest)) = line.trim_start().split_once("]: '")
            && let Some((name, _)) = rest.split_once('\'')
        {
            formats.push(name.trim().to_ascii_lowercase());
        }
    }
    formats
}

/// Formats the camera sources can use: MJPEG as it is, YUYV encoded by
/// ffmpeg or by mjpg-streamer's `-y`, H.264 decoded by ffmpeg.
fn usable(formats: &[String], source: SourceKind) -> Option<&String> {
    formats.iter().find(|f| match f.as_str() {
        "mjpeg" | "mjpg" | "yuyv422" | "yuyv" => true,
        "h264" => source == SourceKind::Ffmpeg,
        _ => false,
    })
}

/// The camera: its program, its device, and a usable format.
pub fn camera(c: &CameraConfig) -> Check {
    let name = "camera";
    let (program, install) = match c.source {
        SourceKind::None => {
            return Check::pass(name, "no camera configured (camera.source = \"none\")");
        }
        SourceKind::Synthetic => {
            return Check::pass(
                name,
                "synthetic camera (pictures of the simulator): nothing to check",
            );
        }
        SourceKind::Url => {
            return Check::pass(
                name,
                format!(
                    "camera.source = \"url\" ({}): served by another program, not checked here",
                    c.url.as_deref().unwrap_or("?")
                ),
            );
        }
        SourceKind::V4l2 => return v4l2_camera(c),
        SourceKind::Ffmpeg => (c.ffmpeg.program.as_str(), "sudo apt install ffmpeg"),
        SourceKind::MjpgStreamer => (
            c.mjpg_streamer.program.as_str(),
            "install mjpg-streamer (the OpenROV image has it), or set camera.source = \"ffmpeg\" and `sudo apt install ffmpeg`",
        ),
    };
    if find_program(program).is_none() {
        return Check::fail(
            name,
            format!(
                "{program} (camera.source = \"{}\") is not installed or not on PATH",
                c.source.as_str()
            ),
            install.to_owned(),
        );
    }
    let Some(dev) = camera_device(c) else {
        return Check::pass(
            name,
            format!("{program} found; its input names no /dev/video device: not checked"),
        );
    };
    if !dev.exists() {
        return Check::fail(
            name,
            format!("camera device {} does not exist", dev.display()),
            "plug in the USB camera (`ls /dev/video*` lists the devices) or name the right one in [camera]".to_owned(),
        );
    }
    use nix::unistd::{AccessFlags, access};
    if let Err(e) = access(dev.as_path(), AccessFlags::R_OK | AccessFlags::W_OK) {
        return Check::fail(
            name,
            format!("camera device {} is not usable by this user: {e}", dev.display()),
            "add the user to the video group (`sudo adduser USER video`); the service's user neptunus is in it".to_owned(),
        );
    }
    let dev_s = dev.to_string_lossy();
    let listing = if find_program("ffmpeg").is_some() {
        Command::new("ffmpeg")
            .args([
                "-hide_banner",
                "-f",
                "v4l2",
                "-list_formats",
                "all",
                "-i",
                &dev_s,
            ])
            .output()
    } else if find_program("v4l2-ctl").is_some() {
        Command::new("v4l2-ctl")
            .args(["-d", &dev_s, "--list-formats"])
            .output()
    } else {
        return Check::fail(
            name,
            format!(
                "cannot list the formats of {}: neither ffmpeg nor v4l2-ctl is installed",
                dev.display()
            ),
            "sudo apt install v4l-utils".to_owned(),
        );
    };
    let text = match listing {
        Ok(o) => format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) => {
            return Check::fail(
                name,
                format!("cannot list the formats of {}: {e}", dev.display()),
                "sudo apt install v4l-utils".to_owned(),
            );
        }
    };
    let formats = parse_formats(&text);
    match usable(&formats, c.source) {
        Some(f) => Check::pass(
            name,
            format!(
                "{} offers {f} (all: {}); {program} found",
                dev.display(),
                formats.join(", ")
            ),
        ),
        None => Check::fail(
            name,
            format!(
                "{} offers no usable format ({})",
                dev.display(),
                if formats.is_empty() {
                    "none listed".to_owned()
                } else {
                    formats.join(", ")
                }
            ),
            "use a UVC camera that gives MJPEG or YUYV (the OpenROV HD camera gives MJPEG)"
                .to_owned(),
        ),
    }
}

/// `source = "v4l2"`: the device is there, this user may use it, and it
/// answers what it offers (`v4l2-ctl --list-formats-ext`).
fn v4l2_camera(c: &CameraConfig) -> Check {
    use crate::camera::v4l2::{Node, node, probe};
    let name = "camera";
    let dev = Path::new(&c.v4l2.device);
    match node(dev) {
        Node::Missing => {
            return Check::fail(
                name,
                format!("camera device {} does not exist", dev.display()),
                "plug in the USB camera (`v4l2-ctl --list-devices` lists the devices) or name the right one in camera.v4l2.device".to_owned(),
            );
        }
        Node::File | Node::Pipe => {
            return Check::pass(
                name,
                format!(
                    "{} is not a device: read as a recorded {} stream (camera.v4l2.format)",
                    dev.display(),
                    c.v4l2.format
                ),
            );
        }
        Node::Device => {}
    }
    use nix::unistd::{AccessFlags, access};
    if let Err(e) = access(dev, AccessFlags::R_OK | AccessFlags::W_OK) {
        return Check::fail(
            name,
            format!("camera device {} is not usable by this user: {e}", dev.display()),
            "add the user to the video group (`sudo adduser USER video`); the service's user neptunus is in it".to_owned(),
        );
    }
    match probe(dev) {
        Ok(caps) => Check::pass(
            name,
            format!(
                "{} is {} ({}), offers {}",
                dev.display(),
                caps.card,
                caps.driver,
                if caps.formats.is_empty() {
                    "no format".to_owned()
                } else {
                    caps.fourccs().join(", ")
                }
            ),
        ),
        Err(e @ crate::camera::v4l2::ProbeError::NoTool { .. }) => {
            Check::fail(name, e.to_string(), "sudo apt install v4l-utils".to_owned())
        }
        Err(e) => Check::fail(
            name,
            e.to_string(),
            "is it the camera's capture node? A camera often has a second node for metadata: name the right one in camera.v4l2.device (`v4l2-ctl --list-devices`)".to_owned(),
        ),
    }
}

/// The addresses the vehicle will listen on are free.
pub fn ports(settings: &Settings) -> Check {
    let name = "ports";
    let mut listens: Vec<(String, Result<(), std::io::Error>)> = Vec::new();
    let udp = |a: SocketAddr| UdpSocket::bind(a).map(drop);
    let tcp = tcp_free;
    for url in &settings.mavlink.endpoints {
        match &url.spec {
            EndpointSpec::UdpIn(a) => listens.push((format!("udpin:{a}"), udp(*a))),
            EndpointSpec::TcpIn(a) => listens.push((format!("tcpin:{a}"), tcp(*a))),
            _ => {}
        }
    }
    if let Some(a) = settings.hmi.http {
        listens.push((format!("HMI http {a}"), tcp(a)));
    }
    // The camera manager's ports beside the HMI are optional: the vehicle
    // starts without them (a warning), and viewers still have /webrtc on
    // the HMI.
    let mut optional: Vec<(String, Result<(), std::io::Error>)> = Vec::new();
    let w = &settings.camera.webrtc;
    if w.enabled {
        let signalling = SignallingAddr::resolve(w.signalling, settings.hmi.http);
        if let Some(a) = signalling {
            optional.push((format!("WebRTC signalling {a}"), tcp(a)));
        }
        if let Some(a) = SignallingAddr::resolve_streams(w.streams, signalling) {
            optional.push((format!("camera streams {a}"), tcp(a)));
        }
        if w.udp_port != 0 {
            let a = SocketAddr::from(([0, 0, 0, 0], w.udp_port));
            listens.push((format!("WebRTC media udp {a}"), udp(a)));
        }
    }
    let in_use = |(what, r): &(String, Result<(), std::io::Error>)| {
        r.as_ref().err().map(|e| format!("{what}: {e}"))
    };
    let mut taken: Vec<String> = listens.iter().filter_map(in_use).collect();
    let signalling_taken: Vec<String> = optional.iter().filter_map(in_use).collect();
    if taken.is_empty() && !signalling_taken.is_empty() {
        return Check::warn(
            name,
            format!(
                "in use: {}; the vehicle starts without it, and Cockpit then finds no video there (or another program's)",
                signalling_taken.join("; ")
            ),
            "stop the program listening there (mavlink-camera-manager, or another neptunus: `systemctl status neptunus`), or set [camera.webrtc] signalling / streams to another address or off".to_owned(),
        );
    }
    // With a required address taken too, the signalling's is named with it.
    taken.extend(signalling_taken);
    listens.extend(optional);
    if taken.is_empty() {
        let all: Vec<&str> = listens.iter().map(|(w, _)| w.as_str()).collect();
        Check::pass(
            name,
            format!(
                "free: {}",
                if all.is_empty() {
                    "none to listen on".to_owned()
                } else {
                    all.join(", ")
                }
            ),
        )
    } else {
        Check::fail(
            name,
            format!("in use: {}", taken.join("; ")),
            "another program listens there — is neptunus (or mavlink-camera-manager, on 6021) already running (`systemctl status neptunus`; stop it to run doctor)? Otherwise change [mavlink] endpoints, [hmi] http or [camera.webrtc] signalling and udp_port".to_owned(),
        )
    }
}

/// Whether a TCP address is free. A port below 1024 this user may not bind
/// (the service binds port 80 with CAP_NET_BIND_SERVICE, which `sudo -u
/// neptunus … doctor` does not have) is free when nothing answers there.
fn tcp_free(a: SocketAddr) -> Result<(), std::io::Error> {
    match TcpListener::bind(a) {
        Ok(_) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied && a.port() < 1024 => {
            let ip = match a.ip() {
                std::net::IpAddr::V4(v4) if v4.is_unspecified() => {
                    std::net::Ipv4Addr::LOCALHOST.into()
                }
                std::net::IpAddr::V6(v6) if v6.is_unspecified() => {
                    std::net::Ipv6Addr::LOCALHOST.into()
                }
                ip => ip,
            };
            let probe = SocketAddr::new(ip, a.port());
            match std::net::TcpStream::connect_timeout(
                &probe,
                std::time::Duration::from_millis(500),
            ) {
                Ok(_) => Err(std::io::Error::new(
                    std::io::ErrorKind::AddrInUse,
                    "Address already in use (something answers there)",
                )),
                Err(_) => Ok(()),
            }
        }
        Err(e) => Err(e),
    }
}

/// The data directory exists (or can be made), is writable, and has room.
pub fn data_dir(dir: &Path) -> Check {
    let name = "data_dir";
    let fix_perm = format!(
        "make {} writable by the vehicle's user (the service's is neptunus: `sudo chown -R neptunus: {}`), or set data_dir",
        dir.display(),
        dir.display()
    );
    if let Err(e) = std::fs::create_dir_all(dir) {
        return Check::fail(
            name,
            format!("cannot create {}: {e}", dir.display()),
            fix_perm,
        );
    }
    let probe = dir.join(".neptunus-doctor-probe");
    if let Err(e) = std::fs::write(&probe, b"").and_then(|()| std::fs::remove_file(&probe)) {
        return Check::fail(
            name,
            format!("{} is not writable: {e}", dir.display()),
            fix_perm,
        );
    }
    match nix::sys::statvfs::statvfs(dir) {
        Ok(s) => {
            #[allow(
                clippy::useless_conversion,
                reason = "the counts are u32 on 32-bit ARM (the BeagleBone)"
            )]
            let free = u64::from(s.blocks_available()).saturating_mul(u64::from(s.fragment_size()));
            let mib = free / (1024 * 1024);
            if free < MIN_FREE_BYTES {
                Check::fail(
                    name,
                    format!("only {mib} MiB free on {}", dir.display()),
                    "free space (old tlogs are in DATA_DIR/tlogs), or lower [mavlink] tlog_total_mb".to_owned(),
                )
            } else {
                Check::pass(
                    name,
                    format!("{} is writable, {mib} MiB free", dir.display()),
                )
            }
        }
        Err(e) => Check::pass(
            name,
            format!("{} is writable (free space unknown: {e})", dir.display()),
        ),
    }
}

/// The clock is not before this build; whether it is synchronised.
pub fn clock() -> Check {
    clock_at(system_unix_us(), system_sync())
}

pub fn clock_at(unix_us: u64, sync: ClockSync) -> Check {
    let name = "clock";
    let now = crate::eventlog::rfc3339_utc(unix_us);
    let build = crate::eventlog::rfc3339_utc(BUILD_UNIX_S * 1_000_000);
    if unix_us < BUILD_UNIX_S * 1_000_000 {
        return Check::warn(
            name,
            format!("the clock says {now}, before this build ({build})"),
            "harmless at the pool: the ground station in control sets the logs' clock (SYSTEM_TIME, which QGroundControl and Cockpit send); for good: give the ROV network with NTP (`sudo timedatectl set-ntp true`) or set it (`sudo date -s 2026-11-25T12:00Z`)".to_owned(),
        );
    }
    let how = match sync {
        ClockSync::Synced => "synchronised (systemd-timesyncd)",
        ClockSync::Unsynced => {
            "not synchronised (systemd-timesyncd has no time source): the ground station in control will set the logs' clock"
        }
        ClockSync::Unknown => "synchronisation unknown (no systemd-timesyncd)",
    };
    Check::pass(name, format!("{now}, after this build ({build}); {how}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_from_ffmpeg_and_v4l2_ctl() {
        let ffmpeg = "[video4linux2,v4l2 @ 0x5581] Compressed:       mjpeg :          Motion-JPEG : 1280x720 640x480\n\
                      [video4linux2,v4l2 @ 0x5581] Raw       :     yuyv422 :           YUYV 4:2:2 : 640x480\n\
                      /dev/video0: Immediate exit requested";
        assert_eq!(parse_formats(ffmpeg), ["mjpeg", "yuyv422"]);
        let v4l2 = "ioctl: VIDIOC_ENUM_FMT\n\tType: Video Capture\n\n\t[0]: 'MJPG' (Motion-JPEG, compressed)\n\t[1]: 'YUYV' (YUYV 4:2:2)\n";
        assert_eq!(parse_formats(v4l2), ["mjpg", "yuyv"]);
        let h264_only = vec!["h264".to_owned()];
        assert!(usable(&h264_only, SourceKind::Ffmpeg).is_some());
        assert!(usable(&h264_only, SourceKind::MjpgStreamer).is_none());
    }

    #[test]
    fn the_device_comes_from_the_sources_arguments() {
        let mut c = CameraConfig::default();
        assert_eq!(camera_device(&c), Some(PathBuf::from("/dev/video0")));
        c.mjpg_streamer.input = "input_uvc.so -d /dev/video2 -r 800x600".into();
        assert_eq!(camera_device(&c), Some(PathBuf::from("/dev/video2")));
        c.source = SourceKind::Ffmpeg;
        assert_eq!(camera_device(&c), Some(PathBuf::from("/dev/video0")));
    }

    #[test]
    fn a_clock_before_the_build_is_a_warning_with_its_fix() {
        // Harmless at an offline pool: the station in control sets the
        // logs' clock. It must not make doctor fail.
        let c = clock_at(946_684_800_000_000, ClockSync::Unsynced);
        assert!(
            c.ok && c.warning && c.fix.as_deref().unwrap_or("").contains("SYSTEM_TIME"),
            "{c:?}"
        );
        let text = super::super::Report::new(vec![c]).text();
        assert!(text.starts_with("warn  clock"), "{text}");
        assert!(text.contains("all checks passed (1 warning)"), "{text}");
        let c = clock_at(BUILD_UNIX_S * 1_000_000 + 1, ClockSync::Synced);
        assert!(c.ok, "{c:?}");
    }
}
