"""The mavlink2rest API on the HMI's port, used from the client's side as
Cockpit uses it: REST reads of the vehicle's last messages, the WebSocket
`ws/mavlink` for the live telemetry, and the same WebSocket to act as a
ground station with Cockpit's header (system 255 = SYSID_MYGCS, component
240) — HEARTBEAT at 1 Hz, MANUAL_CONTROL all the time, COMMAND_LONG to arm
and disarm.

The vehicle is the real binary started by conftest's `make_vehicle`: with the
board emulator (`--sim`) or the genuine firmware in simavr (`--hil`, when
NEPTUNUS_HIL_FIRMWARE names its .elf); the HMI listens on 127.0.0.1:0 and
writes its address to DATA_DIR/http.addr. On loopback a simulated vehicle
lets a client pilot without the pilot password (`[hmi] open_control`
defaults to "loopback" with --sim and --hil).

Waits are conditions with generous deadlines (a slow, shared machine);
nothing sleeps to let time pass.
"""

from __future__ import annotations

import json
import queue
import re
import socket
import threading
import time
import urllib.parse
import urllib.request

import websocket  # websocket-client

from mavhelpers import Deadline

COCKPIT_SYSID, COCKPIT_COMPID = 255, 240
GENEROUS_S = 30.0
# Diving takes the thrusters and the simulated ROV's inertia; with the
# genuine firmware the depth sensor is read once a second.
MOVE_S = 90.0
NAMED_VALUES = {"Lights1", "PilotGain", "CamTilt", "Laser", "InputHold"}
ARMED = 128  # MAV_MODE_FLAG_SAFETY_ARMED


def http_addr(vehicle, timeout: float = GENEROUS_S) -> str:
    """host:port of the vehicle's HMI, from the file it writes once bound."""
    path = vehicle.data_dir / "http.addr"
    dl = Deadline(timeout)
    while not dl.expired():
        try:
            addr = path.read_text().strip()
            if addr:
                return addr
        except OSError:
            pass  # not written yet
        time.sleep(0.05)  # poll interval, not a timing assumption
    raise TimeoutError(f"no HMI address in {path} within {timeout} s")


def get_json(addr: str, path: str):
    with urllib.request.urlopen(f"http://{addr}{path}", timeout=GENEROUS_S) as r:
        assert r.status == 200, f"GET {path}: {r.status}"
        return json.loads(r.read())


def post_json(addr: str, path: str, body) -> tuple[int, str]:
    req = urllib.request.Request(
        f"http://{addr}{path}", data=json.dumps(body).encode(), method="POST", headers={"Content-Type": "application/json"}
    )
    with urllib.request.urlopen(req, timeout=GENEROUS_S) as r:
        return r.status, r.read().decode()


def chars(v) -> str:
    """A MAVLink char array as mavlink2rest gives it (one-character strings, NUL-padded)."""
    return "".join(v).rstrip("\0")


def gcs_heartbeat() -> dict:
    return {
        "type": "HEARTBEAT",
        "custom_mode": 0,
        "mavtype": {"type": "MAV_TYPE_GCS"},
        "autopilot": {"type": "MAV_AUTOPILOT_INVALID"},
        "base_mode": {"bits": 192},
        "system_status": {"type": "MAV_STATE_ACTIVE"},
        "mavlink_version": 2,
    }


def manual_control(x: int = 0, y: int = 0, z: int = 500, r: int = 0) -> dict:
    """Cockpit's MANUAL_CONTROL: z 500 is neutral, the extensions present."""
    return {
        "type": "MANUAL_CONTROL",
        "target": 1,
        "x": x,
        "y": y,
        "z": z,
        "r": r,
        "s": 0,
        "t": 0,
        "buttons": 0,
        "buttons2": 0,
        "enabled_extensions": 0,
    }


def command_long(command: str, *params: float) -> dict:
    p = list(params) + [0.0] * (7 - len(params))
    return {
        "type": "COMMAND_LONG",
        **{f"param{i + 1}": float(v) for i, v in enumerate(p)},
        "command": {"type": command},
        "target_system": 1,
        "target_component": 1,
        "confirmation": 0,
    }


def from_autopilot(f: dict) -> bool:
    return f["header"]["system_id"] == 1 and f["header"]["component_id"] == 1


def depth_of(f: dict) -> float | None:
    """Depth in metres from the vehicle's VFR_HUD (alt = -depth)."""
    m = f["message"]
    if m["type"] == "VFR_HUD" and from_autopilot(f):
        return -m["alt"]
    return None


class M2rClient:
    """One mavlink2rest WebSocket. A reader thread queues the vehicle's frames
    (and, apart, the answers to ours: `Ok(N)`, `Err(…)`); the test sends from
    its own thread (websocket-client locks its send path)."""

    def __init__(self, addr: str, query: str = "", sysid: int = COCKPIT_SYSID, compid: int = COCKPIT_COMPID):
        self.sysid, self.compid = sysid, compid
        self.ws = websocket.create_connection(f"ws://{addr}/mavlink2rest/ws/mavlink{query}", timeout=GENEROUS_S)
        self.ws.settimeout(None)  # the reader blocks; closing wakes it
        self.frames: queue.Queue = queue.Queue()
        self.replies: queue.Queue = queue.Queue()
        self.closed = threading.Event()
        self.sent = 0
        self.last_beat = None
        self.reader = threading.Thread(target=self._read, name="m2r-reader", daemon=True)
        self.reader.start()

    def _read(self):
        try:
            while True:
                text = self.ws.recv()
                if not text:
                    return
                try:
                    v = json.loads(text)
                except ValueError:
                    v = None
                if isinstance(v, dict) and "header" in v:
                    self.frames.put(v)
                else:
                    self.replies.put(text)
        except (websocket.WebSocketException, OSError):
            return
        finally:
            self.closed.set()

    def close(self):
        try:
            self.ws.sock.shutdown(socket.SHUT_RDWR)  # wakes the blocked reader
        except OSError:
            pass
        self.reader.join(timeout=5)
        self.ws.shutdown()

    def send(self, message: dict):
        frame = {"header": {"system_id": self.sysid, "component_id": self.compid, "sequence": self.sent % 256}, "message": message}
        self.sent += 1
        self.ws.send(json.dumps(frame))

    def beat(self):
        """Cockpit's HEARTBEAT, once a second."""
        now = time.monotonic()
        if self.last_beat is None or now - self.last_beat >= 1.0:
            self.last_beat = now
            self.send(gcs_heartbeat())

    def next_frame(self, timeout: float):
        assert not self.closed.is_set() or not self.frames.empty(), "the vehicle closed the WebSocket"
        try:
            return self.frames.get(timeout=timeout)
        except queue.Empty:
            return None

    def wait(self, name: str, pred=lambda f: True, timeout: float = GENEROUS_S, sticks: dict | None = None, seen=None):
        """The next vehicle frame of type `name` satisfying `pred`; meanwhile
        Cockpit's HEARTBEAT, and `sticks` every 40 ms when given (an armed
        vehicle that hears no pilot input disarms). `seen` collects what
        arrived, for the failure message."""
        dl = Deadline(timeout)
        last = None
        while not dl.expired():
            self.beat()
            if sticks is not None:
                self.send(sticks)
            f = self.next_frame(0.04 if sticks is not None else 0.2)
            if f is None:
                continue
            if seen is not None:
                seen.append(f)
            if f["message"]["type"] == name:
                last = f
                if pred(f):
                    return f
        raise AssertionError(f"no {name} as expected within {timeout} s (last: {json.dumps(last)[:600]})")

    def reply(self, timeout: float = GENEROUS_S) -> str:
        """The next answer to one of our frames."""
        try:
            return self.replies.get(timeout=timeout)
        except queue.Empty:
            raise AssertionError(f"no answer to our frames within {timeout} s") from None

    def command(self, command: str, *params: float, sticks: dict | None = None) -> str:
        """Sends a COMMAND_LONG and returns its COMMAND_ACK's result."""
        self.send(command_long(command, *params))
        ack = self.wait("COMMAND_ACK", lambda f: f["message"]["command"]["type"] == command, sticks=sticks)
        return ack["message"]["result"]["type"]


def test_rest_reads_the_live_attitude_and_the_vehicle_heartbeat(make_vehicle):
    v = make_vehicle()
    addr = http_addr(v)
    base = "/mavlink2rest/mavlink/vehicles/1/components/1/messages"

    hb = get_json(addr, f"{base}/HEARTBEAT")
    assert hb["message"]["type"] == "HEARTBEAT"
    assert hb["message"]["mavtype"]["type"] == "MAV_TYPE_SUBMARINE", hb
    assert hb["message"]["autopilot"]["type"] == "MAV_AUTOPILOT_ARDUPILOTMEGA", hb
    assert hb["message"]["system_status"]["type"] == "MAV_STATE_STANDBY", hb
    assert not hb["message"]["base_mode"]["bits"] & ARMED, hb

    # Live: the counter and the time of the last update move on, and the
    # attitude is a real one (radians within range).
    first = get_json(addr, f"{base}/ATTITUDE")
    assert first["message"]["type"] == "ATTITUDE"
    n0 = first["status"]["time"]["counter"]
    assert n0 >= 1, first
    assert "T" in first["status"]["time"]["last_update"], first
    for k in ("roll", "pitch", "yaw"):
        assert isinstance(first["message"][k], (int, float)) and abs(first["message"][k]) <= 3.2, first
    dl = Deadline(GENEROUS_S)
    later = first
    while later["status"]["time"]["counter"] <= n0 + 2:
        assert not dl.expired(), f"ATTITUDE not updated in the REST view: {later}"
        time.sleep(0.2)  # poll interval, not a timing assumption
        later = get_json(addr, f"{base}/ATTITUDE")
    assert later["status"]["time"]["last_update"] != first["status"]["time"]["last_update"]
    yaw = get_json(addr, f"{base}/ATTITUDE/message/yaw")
    assert isinstance(yaw, (int, float)), yaw
    # The vehicle's HEARTBEAT keeps coming too (1 Hz).
    n_hb = hb["status"]["time"]["counter"]
    while get_json(addr, f"{base}/HEARTBEAT/status/time/counter") <= n_hb:
        assert not dl.expired(), "the vehicle's HEARTBEAT not updated in the REST view"
        time.sleep(0.2)  # poll interval, not a timing assumption

    # A frame POSTed is handed on and shows in the view under its header.
    status, body = post_json(
        addr, "/mavlink2rest/mavlink", {"header": {"system_id": COCKPIT_SYSID, "component_id": COCKPIT_COMPID, "sequence": 0}, "message": gcs_heartbeat()}
    )
    assert status == 200 and json.loads(body) == "Ok.", body
    mine = get_json(addr, f"/mavlink2rest/mavlink/vehicles/{COCKPIT_SYSID}/components/{COCKPIT_COMPID}/messages/HEARTBEAT")
    assert mine["message"]["mavtype"]["type"] == "MAV_TYPE_GCS", mine
    info = get_json(addr, "/mavlink2rest/info")
    assert info["service"]["name"] == "neptunus", info


def test_websocket_streams_what_cockpit_shows(make_vehicle):
    v = make_vehicle()
    addr = http_addr(v)
    wanted = ["HEARTBEAT", "ATTITUDE", "VFR_HUD", "SCALED_PRESSURE", "NAMED_VALUE_FLOAT"]
    # Only watching: the filter keeps the stream to these message types.
    c = M2rClient(addr, "?filter=" + urllib.parse.quote("^(" + "|".join(wanted) + ")$"))
    try:
        types: set[str] = set()
        names: set[str] = set()
        frames = []
        dl = Deadline(GENEROUS_S)
        while not (types >= set(wanted) and names >= NAMED_VALUES):
            assert not dl.expired(), f"within {GENEROUS_S} s: types {sorted(types)}, NAMED_VALUE_FLOAT names {sorted(names)}"
            f = c.next_frame(0.5)
            if f is None:
                continue
            frames.append(f)
            m = f["message"]
            assert f["header"]["system_id"] == 1, f
            types.add(m["type"])
            if m["type"] == "NAMED_VALUE_FLOAT" and from_autopilot(f):
                names.add(chars(m["name"]))
        assert types == set(wanted), f"the filter let through {sorted(types - set(wanted))}"

        def last(name):
            return next(f["message"] for f in reversed(frames) if f["message"]["type"] == name and from_autopilot(f))

        hb = last("HEARTBEAT")
        assert hb["mavtype"]["type"] == "MAV_TYPE_SUBMARINE", hb
        att = last("ATTITUDE")
        assert all(abs(att[k]) <= 3.2 for k in ("roll", "pitch", "yaw")), att
        # At the surface: a depth near 0 m, and the water's pressure is about
        # an atmosphere (hPa) — the board's depth sensor read through.
        hud = last("VFR_HUD")
        assert -0.5 < -hud["alt"] < 0.5, hud
        assert 0 <= hud["heading"] < 360, hud
        sp = last("SCALED_PRESSURE")
        assert 900 < sp["press_abs"] < 1200, sp
    finally:
        c.close()


def test_cockpit_arms_dives_and_disarms_over_the_websocket(make_vehicle):
    v = make_vehicle()
    addr = http_addr(v)
    c = M2rClient(addr)
    neutral = manual_control()
    try:
        hb = c.wait("HEARTBEAT", from_autopilot)
        assert not hb["message"]["base_mode"]["bits"] & ARMED, hb
        assert c.reply().startswith("Ok("), "our HEARTBEAT answered Ok(N)"

        # Neutral sticks first (arming starts from them), then arm, asking
        # again while the pre-arm checks still fail.
        c.wait("SERVO_OUTPUT_RAW", from_autopilot, sticks=neutral)
        dl = Deadline(GENEROUS_S)
        while (r := c.command("MAV_CMD_COMPONENT_ARM_DISARM", 1.0, sticks=neutral)) != "MAV_RESULT_ACCEPTED":
            assert not dl.expired(), f"arming refused: {r}"
            c.wait("HEARTBEAT", from_autopilot, sticks=neutral)
        c.wait("HEARTBEAT", lambda f: from_autopilot(f) and f["message"]["base_mode"]["bits"] & ARMED, sticks=neutral)

        # Dive: the vertical thruster (SERVO_OUTPUT_RAW servo3, ArduSub's
        # MOT_3) leaves neutral and the depth the vehicle reports grows.
        start = c.wait("VFR_HUD", from_autopilot, sticks=neutral)
        start_m = depth_of(start)
        down = manual_control(z=100)
        c.wait("SERVO_OUTPUT_RAW", lambda f: from_autopilot(f) and f["message"]["servo3_raw"] != 1500, sticks=down)
        seen: list = []
        try:
            c.wait("VFR_HUD", lambda f: from_autopilot(f) and depth_of(f) > start_m + 0.3, timeout=MOVE_S, sticks=down, seen=seen)
        except AssertionError as e:
            depths = [round(d, 2) for f in seen if (d := depth_of(f)) is not None]
            raise AssertionError(f"{e}; from {start_m:.2f} m, reported depths {depths[-40:]}") from None
        # Still armed and still ours throughout.
        hb = c.wait("HEARTBEAT", from_autopilot, sticks=down)
        assert hb["message"]["base_mode"]["bits"] & ARMED, hb

        # Sticks back, disarm: the HEARTBEAT says so and the thrusters stop.
        assert c.command("MAV_CMD_COMPONENT_ARM_DISARM", 0.0, sticks=neutral) == "MAV_RESULT_ACCEPTED"
        c.wait("HEARTBEAT", lambda f: from_autopilot(f) and not f["message"]["base_mode"]["bits"] & ARMED)
        c.wait(
            "SERVO_OUTPUT_RAW",
            lambda f: from_autopilot(f) and (f["message"]["servo1_raw"], f["message"]["servo2_raw"], f["message"]["servo3_raw"]) == (1500, 1500, 1500),
        )
        # Every frame we sent converted: none answered `Could not convert…` or `Err(…)`.
        answers = []
        while True:
            try:
                answers.append(c.replies.get_nowait())
            except queue.Empty:
                break
        bad = [a for a in answers if not re.fullmatch(r"Ok\(\d+\)", a)]
        assert not bad, f"answers other than Ok(N): {bad[:5]}"
    finally:
        c.close()
