"""The camera component (1, 100) and the camera tilt as a MAVLink gimbal,
from a pymavlink ground station's side against the real `neptunus --sim`
(whose synthetic camera makes the camera component exist).

Discovery is done as QGroundControl does it: wait for a HEARTBEAT from
component 100 with MAV_TYPE_CAMERA, then MAV_CMD_REQUEST_MESSAGE 259
(CAMERA_INFORMATION) and 269 (VIDEO_STREAM_INFORMATION, stream 0 = all) to
component 100; each answer is a COMMAND_ACK first, then the message.

The gimbal: 255 takes control, sets pitch -30 deg with
MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW; the tilt the vehicle sends the board
shows in SERVO_OUTPUT_RAW.servo8_raw (requested at 10 Hz), and the pitch the
board reports back (its status line's `servo`) in
GIMBAL_DEVICE_ATTITUDE_STATUS. The non-owner 254 is refused and the tilt
stays.
"""

from __future__ import annotations

import math
import socket
import time

from mavhelpers import (
    ACCEPTED,
    CMD_REQUEST_OPERATOR_CONTROL,
    NOT_IN_CONTROL,
    UNSUPPORTED,
    from_vehicle,
    mavlink,
    result_name,
    servo_samples,
    start_vehicle,
)

CAMERA = 100
PARAMS = {"NEPT_GCS_ALLOW2": 254}
CAMERA_INFORMATION, VIDEO_STREAM_INFORMATION = 259, 269
GIMBAL_MANAGER_INFORMATION = 280
DO_GIMBAL_MANAGER_PITCHYAW = 1000
HAS_VIDEO_STREAM = 256
VIDEO_STREAM_TYPE_RTPUDP = 1
VIDEO_STREAM_STATUS_FLAGS_RUNNING = 1
VIDEO_STREAM_ENCODING_H264 = 1
NAN = float("nan")


def expected_video_uri(vehicle) -> str:
    """The uri QGC is told to receive on: with the `auto` default, port 5600
    at the address the (local) ground station is heard from."""
    return "udp://127.0.0.1:5600"


def from_camera(m) -> bool:
    return m.get_srcSystem() == 1 and m.get_srcComponent() == CAMERA


def camera_request(g, cmd: int, *params):
    """COMMAND_LONG to (1, 100); the camera's ACK and the position after it."""
    mark = g.inbox.mark()
    g.command(cmd, *params, target=(1, CAMERA))
    ack = g.inbox.wait("COMMAND_ACK", lambda m: from_camera(m) and m.command == cmd, 10, mark, f"the camera's COMMAND_ACK for {cmd}")
    assert (ack.target_system, ack.target_component) == (g.sysid, g.compid), f"ack addressed to {ack.target_system}/{ack.target_component}"
    return ack, mark


def answered_after_ack(g, mtype: str, ack, mark):
    """The camera's `mtype` answer: after its ACK, none before it."""
    early = g.inbox.select(mtype, from_camera, mark, ack._idx)
    assert not early, f"{mtype} arrived before its COMMAND_ACK: {early}"
    return g.inbox.wait(mtype, from_camera, 10, ack._idx, f"{mtype} after the ACK")


def text(v) -> str:
    """A char[] field (str) or a uint8_t[] one (list of ints) as text."""
    if isinstance(v, str):
        return v.rstrip("\0")
    return bytes(v).split(b"\0", 1)[0].decode()


def test_qgc_camera_discovery(make_vehicle, stations):
    v = start_vehicle(make_vehicle, PARAMS)
    qgc = stations.gcs(v.udp_port, 255, compid=190, name="QGC").connect()

    hb = qgc.inbox.wait("HEARTBEAT", from_camera, 5, 0, "a HEARTBEAT from component 100")
    assert hb.type == mavlink.MAV_TYPE_CAMERA, f"camera heartbeat type {hb.type}"
    assert hb.autopilot == mavlink.MAV_AUTOPILOT_INVALID, f"camera heartbeat autopilot {hb.autopilot}"
    assert hb.system_status == mavlink.MAV_STATE_STANDBY
    # 1 Hz: two more within 3 s.
    qgc.inbox.wait_count("HEARTBEAT", 2, from_camera, 3.5, hb._idx + 1, "the camera's heartbeat at 1 Hz")

    ack, mark = camera_request(qgc, mavlink.MAV_CMD_REQUEST_MESSAGE, CAMERA_INFORMATION)
    assert ack.result == ACCEPTED, f"REQUEST_MESSAGE(259): {result_name(ack.result)}"
    info = answered_after_ack(qgc, "CAMERA_INFORMATION", ack, mark)
    assert info.flags & HAS_VIDEO_STREAM, f"CAMERA_INFORMATION.flags {info.flags} lacks HAS_VIDEO_STREAM (256)"
    assert text(info.cam_definition_uri) == "", f"cam_definition_uri {info.cam_definition_uri!r}: QGC would download it"
    assert text(info.vendor_name) == "Neptunus" and text(info.model_name) == "OpenROV camera"
    assert info.resolution_h > 0 and info.resolution_v > 0

    # The RTP sender starts once a station is heard and its first picture is
    # in the encoder; QGC asks again until the stream runs, and so does this.
    uri = expected_video_uri(v)
    deadline = time.monotonic() + 20
    while True:
        ack, mark = camera_request(qgc, mavlink.MAV_CMD_REQUEST_MESSAGE, VIDEO_STREAM_INFORMATION, 0)
        assert ack.result == ACCEPTED, f"REQUEST_MESSAGE(269): {result_name(ack.result)}"
        vs = answered_after_ack(qgc, "VIDEO_STREAM_INFORMATION", ack, mark)
        assert (vs.stream_id, vs.count) == (1, 1)
        assert vs.type == VIDEO_STREAM_TYPE_RTPUDP, f"stream type {vs.type}"
        assert vs.encoding == VIDEO_STREAM_ENCODING_H264, f"encoding {vs.encoding}"
        if vs.flags & VIDEO_STREAM_STATUS_FLAGS_RUNNING:
            break
        # Not running yet: described, but with no uri.
        assert text(vs.uri) == "", f"uri {vs.uri!r} with no stream"
        assert time.monotonic() < deadline, "the video stream never ran (is ffmpeg installed?)"
        time.sleep(1.0)
    assert text(vs.uri) == uri, f"uri {vs.uri!r}, expected {uri!r}"
    assert vs.resolution_h > 0 and vs.resolution_v > 0 and vs.framerate > 0 and vs.bitrate > 0, str(vs)
    # And the video really arrives there: RTP version 2, payload type 96.
    host, port = uri.removeprefix("udp://").rsplit(":", 1)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.bind((host, int(port)))
        rx.settimeout(10)
        packet, _ = rx.recvfrom(2048)
        assert packet[0] >> 6 == 2 and packet[1] & 0x7F == 96, f"not H.264 RTP: {packet[:12].hex()}"
    finally:
        rx.close()

    # The legacy request QGC 4.x may send instead.
    ack, mark = camera_request(qgc, mavlink.MAV_CMD_REQUEST_CAMERA_INFORMATION, 1)
    assert ack.result == ACCEPTED
    answered_after_ack(qgc, "CAMERA_INFORMATION", ack, mark)

    # A camera command it does not implement.
    ack, _ = camera_request(qgc, mavlink.MAV_CMD_IMAGE_START_CAPTURE, 0, 1, 1)
    assert ack.result == UNSUPPORTED, f"IMAGE_START_CAPTURE: {result_name(ack.result)}"


def pitch_deg(q) -> float:
    w, x, y, z = q
    return math.degrees(math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x)))))


def test_gimbal_pitch_by_owner_moves_the_tilt_and_not_by_others(make_vehicle, stations):
    v = start_vehicle(make_vehicle, PARAMS)
    g255 = stations.gcs(v.udp_port, 255).connect()
    g254 = stations.gcs(v.udp_port, 254).connect()
    ack = g255.command_ack(CMD_REQUEST_OPERATOR_CONTROL, 1, 0, 10, 255)
    assert ack.result == ACCEPTED, f"255's control request: {result_name(ack.result)}"
    assert g255.set_interval(36, 10).result == ACCEPTED  # SERVO_OUTPUT_RAW at 10 Hz

    # What QGC's gimbal controller asks the manager (component 1).
    mark = g255.inbox.mark()
    assert g255.command_ack(mavlink.MAV_CMD_REQUEST_MESSAGE, GIMBAL_MANAGER_INFORMATION).result == ACCEPTED
    gi = g255.inbox.wait("GIMBAL_MANAGER_INFORMATION", from_vehicle, 10, mark)
    assert gi.gimbal_device_id == 1
    assert gi.cap_flags & mavlink.GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_AXIS
    assert math.isclose(math.degrees(gi.pitch_min), -90, abs_tol=0.1) and math.isclose(math.degrees(gi.pitch_max), 90, abs_tol=0.1)
    st = g255.inbox.wait("GIMBAL_MANAGER_STATUS", from_vehicle, 5, mark, "GIMBAL_MANAGER_STATUS streamed")
    assert (st.gimbal_device_id, st.primary_control_sysid) == (1, 255), f"{st}"

    # -30 deg = 1500 - 30 * 500 / 90 us.
    mark = g255.inbox.mark()
    ack = g255.command_ack(DO_GIMBAL_MANAGER_PITCHYAW, -30, NAN, NAN, NAN, 0, 0, 0)
    assert ack.result == ACCEPTED, f"owner's pitch -30: {result_name(ack.result)}"
    g255.inbox.wait("SERVO_OUTPUT_RAW", lambda m: from_vehicle(m) and m.servo8_raw == 1333, 10, mark, "tilt 1333 us sent to the board")
    # The board slews and reports its servo: the device attitude follows it.
    att = g255.inbox.wait(
        "GIMBAL_DEVICE_ATTITUDE_STATUS",
        lambda m: from_vehicle(m) and abs(pitch_deg(m.q) + 30) < 0.5,
        10,
        mark,
        "GIMBAL_DEVICE_ATTITUDE_STATUS at about -30 deg",
    )
    assert att.gimbal_device_id == 1

    # The non-owner: refused, and the tilt stays where the owner put it.
    mark = g254.inbox.mark()
    ack = g254.command_ack(DO_GIMBAL_MANAGER_PITCHYAW, 20, NAN, NAN, NAN, 0, 0, 0)
    assert ack.result == NOT_IN_CONTROL, f"non-owner's pitch: {result_name(ack.result)}"
    g254.mav.gimbal_manager_set_pitchyaw_send(1, 1, 0, 0, math.radians(20), NAN, NAN, NAN)
    window = servo_samples(g254.inbox, 15, ack._idx)
    moved = [m.servo8_raw for m in window if m.servo8_raw != 1333]
    assert not moved, f"the tilt moved after 254's refused command and message: {moved}"
    atts = g254.inbox.select("GIMBAL_DEVICE_ATTITUDE_STATUS", from_vehicle, window[-1]._idx)
    last = atts[-1] if atts else g254.inbox.wait("GIMBAL_DEVICE_ATTITUDE_STATUS", from_vehicle, 5, window[-1]._idx)
    assert abs(pitch_deg(last.q) + 30) < 0.5, f"attitude {pitch_deg(last.q):.1f} deg after the refused requests"
