"""Recording on the vehicle, from a pymavlink ground station against the real
`neptunus --sim`: its synthetic camera (the one H.264 encode), and a
camera's own H.264 (copied by ffmpeg, or read as a V4L2 camera's stream).

1. The power cut: MAV_CMD_VIDEO_START_CAPTURE to the camera (1, 100), and
   once the vehicle's CAMERA_CAPTURE_STATUS says it has recorded 6 s, the
   vehicle is killed (SIGKILL: no shutdown, no last write). The MPEG-TS it
   left decodes with ffmpeg over at least 5 s, and the telemetry beside it
   (CSV and WebVTT) covers the same seconds.
2. The floor: the data directory on a small tmpfs of its own (root only:
   the test mounts it), `[storage] min_free_mb` a little under its free
   space; the pilot dives (armed, ALT_HOLD at 1 m, driving ahead) and
   records; another file then takes the room. The recording stops with a
   STATUSTEXT that says why, and the dive goes on: still armed, still in
   ALT_HOLD at its depth, the thrusters still answer the sticks, and a
   parameter change is still saved to disk.
3. Home over MAVLink FTP: a recording stopped by the pilot is listed in
   `/recordings` and fetched, video and telemetry, byte for byte, by
   pymavlink's MAVFTP client.

Every wait is a condition with a generous deadline (the machine is shared).
"""

from __future__ import annotations

import csv
import os
import re
import subprocess
import time
from pathlib import Path

import pytest

from mavhelpers import ACCEPTED, Deadline, GcsHeartbeat, from_vehicle, mavlink, recv, servos, start_vehicle, statustext
from test_depth_hold import IGNORE_ALL_BUT_Z, TOLERANCE_M

CAMERA = 100
MIB = 1024 * 1024
# The encoder starts with the first recording (nothing else wants video
# here) and the recording with its first keyframe: generous on a busy machine.
START_DEADLINE_S = 60.0


def from_camera(m) -> bool:
    return m.get_srcSystem() == 1 and m.get_srcComponent() == CAMERA


def record(gcs, on: bool) -> None:
    cmd = mavlink.MAV_CMD_VIDEO_START_CAPTURE if on else mavlink.MAV_CMD_VIDEO_STOP_CAPTURE
    mark = gcs.inbox.mark()
    gcs.command(cmd, 0, 0, target=(1, CAMERA))
    ack = gcs.inbox.wait("COMMAND_ACK", lambda m: from_camera(m) and m.command == cmd, 10, mark, f"the camera's ack for {cmd}")
    assert ack.result == ACCEPTED, f"{cmd}: result {ack.result}"


def recorded_ms(gcs, at_least_ms: int, since: int, timeout: float):
    """The camera's CAMERA_CAPTURE_STATUS once it says it has recorded `at_least_ms`."""
    return gcs.inbox.wait(
        "CAMERA_CAPTURE_STATUS",
        lambda m: from_camera(m) and m.video_status == 1 and m.recording_time_ms >= at_least_ms,
        timeout,
        since,
        f"CAMERA_CAPTURE_STATUS with {at_least_ms} ms recorded",
    )


def frame_times(ts: Path) -> list[float]:
    """The decoded pictures' times (s), as ffmpeg decodes them; ffmpeg must
    decode the file without an error."""
    run = subprocess.run(
        ["ffmpeg", "-hide_banner", "-nostdin", "-v", "error", "-i", str(ts), "-f", "null", "-"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, f"ffmpeg could not decode {ts.name}: {run.stderr[-2000:]}"
    probe = subprocess.run(
        ["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries", "frame=best_effort_timestamp_time",
         "-of", "csv=p=0", str(ts)],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    fields = (line.split(",", 1)[0].strip() for line in probe.stdout.splitlines())
    return [float(x) for x in fields if x and x != "N/A"]


def vtt_starts(vtt: Path) -> list[float]:
    out = []
    for m in re.finditer(r"^(\d\d):(\d\d):(\d\d)\.(\d\d\d) --> ", vtt.read_text(), re.MULTILINE):
        h, mi, s, ms = (int(g) for g in m.groups())
        out.append(h * 3600 + mi * 60 + s + ms / 1000)
    return out


def test_a_recording_survives_sigkill(make_vehicle, stations):
    v = start_vehicle(make_vehicle, {})
    gcs = stations.gcs(v.udp_port, 255, name="pilot").connect()
    mark = gcs.inbox.mark()
    record(gcs, True)
    started = statustext(gcs.inbox, r"Recording on the vehicle: rec-", mark, START_DEADLINE_S)
    name = started.text.split(": ", 1)[1].strip()
    recorded_ms(gcs, 6000, started._idx, 30)

    # The power cut.
    v.proc.kill()
    v.proc.wait(timeout=10)
    v.proc = None

    rec = v.data_dir / "recordings"
    segments = sorted(rec.glob(f"{name}-*.ts"))
    assert segments, f"no video of {name} in {sorted(p.name for p in rec.iterdir())}"
    ts = segments[0]
    times = frame_times(ts)
    assert len(times) >= 5, f"{ts.name}: {len(times)} pictures decoded"
    span = times[-1] - times[0]
    assert span >= 5.0, f"{ts.name} decodes over {span:.2f} s only ({len(times)} pictures)"

    # The telemetry beside it, on the same clock: the CSV and the subtitles
    # cover the seconds the video covers.
    with (rec / f"{name}.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows, "the CSV has no row"
    assert {"depth_m", "heading_deg", "roll_deg", "pitch_deg", "mode", "armed", "lights_pct", "tilt_deg"} <= set(rows[0])
    t = [float(r["segment_time_s"]) for r in rows if r["segment"] == ts.name]
    assert t and t[0] <= 1.0 and t[-1] >= span - 1.0, f"CSV covers {t[:1]}..{t[-1:]} s, the video {span:.2f} s"
    assert any(r["depth_m"] != "" for r in rows), "no depth in the CSV"
    cues = vtt_starts(ts.with_suffix(".vtt"))
    assert cues and cues[0] <= 1.0 and cues[-1] >= span - 1.5, f"subtitles at {cues[:1]}..{cues[-1:]} s, the video {span:.2f} s"


@pytest.mark.skipif(os.geteuid() != 0, reason="mounting the small tmpfs that stands for a full SD card needs root (CI runs as root)")
def test_at_the_storage_floor_the_recording_stops_and_the_dive_goes_on(make_vehicle, stations, tmp_path):
    v = start_vehicle(make_vehicle, {}, start=False)
    # The data directory on a file system of its own: 48 MiB, so the floor
    # is reached by filling it, never the machine's disk.
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=48m,mode=0755", "tmpfs", str(v.data_dir)], check=True)
    try:
        (v.data_dir / "params.toml").write_text("")
        config = tmp_path / "storage.toml"
        config.write_text("[storage]\nmin_free_mb = 24\ntotal_mb = 4096\n")
        v.extra_args = ["--config", str(config)]
        v.start()
        dive_and_fill(v, stations)
    finally:
        v.stop()
        subprocess.run(["umount", str(v.data_dir)], check=False)


def dive_and_fill(v, stations):
    pilot = stations.gcs(v.udp_port, 255, name="pilot").connect()
    pilot.set_interval(mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, 10)
    pilot.sticks((0, 0, 500, 0))
    ack = pilot.command_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arm")
    assert ack.result == ACCEPTED, f"arm: {ack.result}"
    alt_hold = 2
    ack = pilot.command_ack(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, alt_hold, what="ALT_HOLD")
    assert ack.result == ACCEPTED, f"ALT_HOLD: {ack.result}"
    hold_depth(pilot, 1.0, "diving to 1 m")

    mark = pilot.inbox.mark()
    record(pilot, True)
    started = statustext(pilot.inbox, r"Recording on the vehicle: rec-", mark, START_DEADLINE_S)
    recorded_ms(pilot, 2000, started._idx, 30)
    # Driving ahead while it records.
    pilot.sticks((600, 0, 500, 0))
    pilot.inbox.wait("SERVO_OUTPUT_RAW", lambda m: from_vehicle(m) and servos(m)[0] > 1500, 10, pilot.inbox.mark(), "driving ahead")

    # Another writer takes the room: below the 24 MiB floor.
    mark = pilot.inbox.mark()
    free = os.statvfs(v.data_dir).f_bavail * os.statvfs(v.data_dir).f_frsize
    ballast = free - 20 * MIB
    assert ballast > 0, f"only {free / MIB:.1f} MiB free on the tmpfs"
    with open(v.data_dir / "ballast", "wb") as f:
        f.write(b"\0" * ballast)
    stopped = statustext(pilot.inbox, r"^Recording stopped: free space", mark, 20, max_severity=mavlink.MAV_SEVERITY_WARNING)
    # A long text comes in chunks with the same id.
    pilot.inbox.wait("STATUSTEXT", lambda m: from_vehicle(m) and m.id == stopped.id and "min_free_mb" in m.text, 5, stopped._idx)
    whole = "".join(m.text for m in pilot.inbox.select("STATUSTEXT", lambda m: from_vehicle(m) and m.id == stopped.id, stopped._idx))
    assert re.search(r"free space \d+ MiB is at the floor of 24 MiB \(\[storage\] min_free_mb\)", whole), whole
    pilot.inbox.wait("CAMERA_CAPTURE_STATUS", lambda m: from_camera(m) and m.video_status == 0, 10, mark, "not recording any more")
    # A new recording is refused while the floor is reached.
    mark = pilot.inbox.mark()
    pilot.command(mavlink.MAV_CMD_VIDEO_START_CAPTURE, 0, 0, target=(1, CAMERA))
    ack = pilot.inbox.wait("COMMAND_ACK", lambda m: from_camera(m) and m.command == mavlink.MAV_CMD_VIDEO_START_CAPTURE, 10, mark)
    assert ack.result == mavlink.MAV_RESULT_DENIED, f"start at the floor: {ack.result}"

    # The dive goes on: armed, in ALT_HOLD, at its depth, driving.
    after = pilot.inbox.mark()
    hb = pilot.inbox.wait("HEARTBEAT", from_vehicle, 5, after, "a heartbeat after the stop")
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED, "disarmed"
    assert hb.custom_mode == alt_hold, f"mode {hb.custom_mode}"
    pilot.inbox.wait("SERVO_OUTPUT_RAW", lambda m: from_vehicle(m) and servos(m)[0] > 1500, 10, after, "still driving ahead")
    pilot.sticks((0, 0, 500, 0))
    hold_depth(pilot, 1.0, "the held depth after the recording stopped")
    # What the vehicle needs to run is still written at the floor.
    ack_mark = pilot.inbox.mark()
    pilot.mav.param_set_send(1, 1, b"JS_GAIN_DEFAULT", 0.6, mavlink.MAV_PARAM_TYPE_REAL32)
    pilot.inbox.wait("PARAM_VALUE", lambda m: from_vehicle(m) and m.param_id == "JS_GAIN_DEFAULT", 10, ack_mark)
    saved = Deadline(15)
    while "JS_GAIN_DEFAULT" not in (v.data_dir / "params.toml").read_text():
        assert not saved.expired(), "the parameter change was not saved at the storage floor"
        pilot.inbox.wait("HEARTBEAT", from_vehicle, 5, pilot.inbox.mark())
    pilot.command_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, what="disarm")


def hold_depth(pilot, depth_m: float, what: str) -> None:
    """Sends the depth target (ArduSub's way) until GLOBAL_POSITION_INT has
    stayed within TOLERANCE_M of it for 3 s."""
    dl = Deadline(60)
    inside_since = None
    while not dl.expired():
        pilot.mav.set_position_target_global_int_send(
            0, 1, 1, mavlink.MAV_FRAME_GLOBAL_INT, IGNORE_ALL_BUT_Z, 0, 0, -depth_m, 0, 0, 0, 0, 0, 0, 0, 0
        )
        m = pilot.inbox.wait("GLOBAL_POSITION_INT", from_vehicle, 5, pilot.inbox.mark(), what)
        now = time.monotonic()
        if abs(-m.relative_alt / 1000.0 - depth_m) <= TOLERANCE_M:
            inside_since = inside_since or now
            if now - inside_since >= 3.0:
                return
        else:
            inside_since = None
    raise AssertionError(f"{what}: the depth never held within {TOLERANCE_M} m of {depth_m} m for 3 s")


def ffmpeg_children(pid: int) -> list[str]:
    """The command lines of the vehicle's ffmpeg children."""
    out = []
    for child in Path(f"/proc/{pid}/task").glob("*/children"):
        for c in child.read_text().split():
            try:
                line = Path(f"/proc/{c}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if "ffmpeg" in line.split(" ", 1)[0]:
                out.append(line)
    return out


def test_a_camera_giving_h264_is_recorded_as_it_gives_it(make_vehicle, stations, tmp_path):
    """`[camera.h264] passthrough`: the camera's own H.264 (here an MP4 clip
    played in real time, the SPS/PPS only in its header) is what the
    recording holds — one ffmpeg copying it, no encoder anywhere."""
    clip = tmp_path / "camera.mp4"
    subprocess.run(
        ["ffmpeg", "-hide_banner", "-loglevel", "error", "-y", "-f", "lavfi", "-i", "testsrc2=size=320x240:rate=15",
         "-t", "60", "-c:v", "libx264", "-preset", "veryfast", "-profile:v", "main", "-bf", "0", "-g", "15", "-pix_fmt", "yuv420p",
         str(clip)],
        check=True,
        timeout=120,
    )
    v = start_vehicle(make_vehicle, {}, start=False)
    config = tmp_path / "passthrough.toml"
    config.write_text(f'[camera]\nsource = "synthetic"\nrtp = ["off"]\n[camera.h264]\npassthrough = ["-re", "-i", "{clip}"]\n')
    v.extra_args = ["--config", str(config)]
    v.start()
    gcs = stations.gcs(v.udp_port, 255, name="pilot").connect()
    mark = gcs.inbox.mark()
    record(gcs, True)
    started = statustext(gcs.inbox, r"Recording on the vehicle: rec-", mark, START_DEADLINE_S)
    name = started.text.split(": ", 1)[1].strip()
    recorded_ms(gcs, 3000, started._idx, 30)
    children = ffmpeg_children(v.proc.pid)
    assert len(children) == 1 and "-c:v copy" in children[0] and "libx264" not in children[0], children
    mark = gcs.inbox.mark()
    record(gcs, False)
    statustext(gcs.inbox, r"^Recording stopped: rec-", mark, 15)
    ts = sorted((v.data_dir / "recordings").glob(f"{name}-*.ts"))[0]
    times = frame_times(ts)
    assert len(times) >= 15 and times[-1] - times[0] >= 2.0, f"{len(times)} pictures over {times[-1] - times[0]:.2f} s"
    # The camera's Main profile (CABAC), which the vehicle's own encoder
    # (constrained baseline) never makes.
    assert stream_of(ts) == stream_of(clip) == "h264,Main,320,240", f"the recording {stream_of(ts)!r}, the camera {stream_of(clip)!r}"


def test_a_v4l2_camera_giving_h264_is_recorded_as_it_gives_it(make_vehicle, stations, tmp_path):
    """`source = "v4l2"` on a camera that gives H.264 (here its recorded
    stream in the device's place: a raw H.264 clip, the SPS/PPS only at
    its start, read at the camera's rate): the recording holds the camera's
    own pictures, and nothing is encoded — not one ffmpeg runs."""
    clip = tmp_path / "camera.h264"
    subprocess.run(
        ["ffmpeg", "-hide_banner", "-loglevel", "error", "-y", "-f", "lavfi", "-i", "testsrc2=size=320x240:rate=15",
         "-t", "60", "-c:v", "libx264", "-preset", "veryfast", "-profile:v", "main", "-bf", "0", "-g", "15", "-pix_fmt", "yuv420p",
         "-f", "h264", str(clip)],
        check=True,
        timeout=120,
    )
    v = start_vehicle(make_vehicle, {}, start=False)
    config = tmp_path / "v4l2.toml"
    config.write_text(f'[camera]\nsource = "v4l2"\nfps = 15\nrtp = ["off"]\n[camera.v4l2]\ndevice = "{clip}"\nformat = "h264"\n')
    v.extra_args = ["--config", str(config)]
    v.start()
    gcs = stations.gcs(v.udp_port, 255, name="pilot").connect()
    mark = gcs.inbox.mark()
    record(gcs, True)
    started = statustext(gcs.inbox, r"Recording on the vehicle: rec-", mark, START_DEADLINE_S)
    name = started.text.split(": ", 1)[1].strip()
    recorded_ms(gcs, 3000, started._idx, 30)
    assert ffmpeg_children(v.proc.pid) == [], ffmpeg_children(v.proc.pid)
    mark = gcs.inbox.mark()
    record(gcs, False)
    statustext(gcs.inbox, r"^Recording stopped: rec-", mark, 15)
    ts = sorted((v.data_dir / "recordings").glob(f"{name}-*.ts"))[0]
    times = frame_times(ts)
    assert len(times) >= 15 and times[-1] - times[0] >= 2.0, f"{len(times)} pictures over {times[-1] - times[0]:.2f} s"
    assert stream_of(ts) == "h264,Main,320,240", f"the recording {stream_of(ts)!r}"


def stream_of(path: Path) -> str:
    probe = subprocess.run(
        ["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries", "stream=codec_name,profile,width,height",
         "-of", "csv=p=0", str(path)],
        capture_output=True, text=True, timeout=60, check=True,
    )
    return next(line.strip() for line in probe.stdout.splitlines() if line.strip())


def test_a_recording_is_listed_and_fetched_over_mavftp(make_vehicle, tmp_path):
    """The pilot records three seconds, stops, and fetches the recording's
    first segment and its telemetry with pymavlink's MAVFTP client (as
    MAVProxy does): what comes home is the file on the vehicle, byte for byte,
    and the /recordings listing names it."""
    from pymavlink import mavftp

    from test_transfers import connect
    from transfer_clients import ftp_get

    v = start_vehicle(make_vehicle, {})
    conn = connect(v.udp_port)
    rec = v.data_dir / "recordings"
    with GcsHeartbeat(conn):
        for cmd in (mavlink.MAV_CMD_VIDEO_START_CAPTURE, None, mavlink.MAV_CMD_VIDEO_STOP_CAPTURE):
            if cmd is None:
                status = recv(
                    conn,
                    "CAMERA_CAPTURE_STATUS",
                    START_DEADLINE_S,
                    lambda m: from_camera(m) and m.video_status == 1 and m.recording_time_ms >= 3000,
                )
                assert status is not None, "the camera never reported 3 s recorded"
                continue
            conn.mav.command_long_send(1, CAMERA, cmd, 0, 0, 0, 0, 0, 0, 0, 0)
            ack = recv(conn, "COMMAND_ACK", 10, lambda m: from_camera(m) and m.command == cmd)
            assert ack is not None and ack.result == ACCEPTED, f"{cmd}: {ack}"
        # Stopped: asked, the camera says it no longer records (the recorder
        # has closed the files).
        dl = Deadline(20.0)
        idle = None
        while idle is None and not dl.expired():
            conn.mav.command_long_send(1, CAMERA, mavlink.MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS, 0, 1, 0, 0, 0, 0, 0, 0)
            idle = recv(conn, "CAMERA_CAPTURE_STATUS", 1.0, lambda m: from_camera(m) and m.video_status == 0)
        assert idle is not None, "the camera still records after the stop"

        segments = sorted(rec.glob("rec-*.ts"))
        assert segments, f"nothing recorded: {sorted(p.name for p in rec.iterdir())}"
        ts = segments[0]
        csv_file = rec / (ts.name.rsplit("-", 1)[0] + ".csv")
        assert csv_file.exists(), f"no telemetry beside {ts.name}"

        ftp = None
        for f in (ts, csv_file):
            out = tmp_path / f.name
            ftp, ret = ftp_get(conn, f"/recordings/{f.name}", str(out))
            assert ret.error_code == mavftp.FtpError.Success, f"{f.name}: {ret}"
            assert out.read_bytes() == f.read_bytes(), f"{f.name}: what came home differs from the vehicle's file"
        listing = ftp.cmd_list(["/recordings"])
        assert listing.error_code == mavftp.FtpError.Success, listing
        names = {e.name for e in ftp.list_result}
        assert {ts.name, csv_file.name} <= names, f"/recordings lists {sorted(names)}"
