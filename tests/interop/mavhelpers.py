"""Small helpers shared by the interoperability tests (no fixtures here)."""

from __future__ import annotations

import os
import socket
import threading
import time

os.environ.setdefault("MAVLINK20", "1")  # MAVLink 2 from the first frame

from pymavlink import mavutil  # noqa: E402

mavlink = mavutil.mavlink


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port the OS considers free right now (bind port 0 on loopback)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_udp_port() -> int:
    return free_port(socket.SOCK_DGRAM)


def free_tcp_port() -> int:
    return free_port(socket.SOCK_STREAM)


class Deadline:
    """Polling helper: `while dl.left() > 0: ...` and no sleeps for timing."""

    def __init__(self, seconds: float):
        self.end = time.monotonic() + seconds

    def left(self) -> float:
        return max(0.0, self.end - time.monotonic())

    def expired(self) -> bool:
        return time.monotonic() >= self.end


def recv(conn, types, timeout: float, cond=None):
    """The first message of `types` (str or list) satisfying `cond`, or None
    once `timeout` seconds have passed."""
    dl = Deadline(timeout)
    while not dl.expired():
        m = conn.recv_match(type=types, blocking=True, timeout=min(dl.left(), 0.5))
        if m is None:
            continue
        if m.get_type() == "BAD_DATA":
            continue
        if cond is None or cond(m):
            return m
    return None


def from_vehicle(m) -> bool:
    return m.get_srcSystem() == 1 and m.get_srcComponent() == 1



class GcsHeartbeat:
    """Sends a GCS HEARTBEAT (type GCS, autopilot INVALID) at 1 Hz from a
    background thread, as QGroundControl does. Makes the connection's send
    path thread-safe (pymavlink's is not: sequence numbers, socket writes)."""

    def __init__(self, conn, period_s: float = 1.0):
        self.conn = conn
        self.period_s = period_s
        self.lock = threading.Lock()
        self.stop_event = threading.Event()
        self.sent = 0
        orig_send = conn.mav.send

        def locked_send(msg, force_mavlink1=False):
            with self.lock:
                orig_send(msg, force_mavlink1=force_mavlink1)

        conn.mav.send = locked_send
        self.thread = threading.Thread(target=self._run, name="gcs-heartbeat", daemon=True)

    def beat(self):
        self.conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
        self.sent += 1

    def _run(self):
        while not self.stop_event.is_set():
            try:
                self.beat()
            except OSError:
                pass  # the vehicle may be restarting; keep beating
            self.stop_event.wait(self.period_s)  # the heartbeat period itself

    def __enter__(self):
        self.beat()  # a UDP vehicle learns about us from our first frame
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop_event.set()
        self.thread.join(timeout=5)


def bounded(fn, timeout: float, what: str):
    """Run a blocking library call that has no timeout of its own (e.g.
    pymavlink's motors_armed_wait) in a daemon thread; fail after `timeout`."""
    result: dict = {}

    def run():
        try:
            result["value"] = fn()
        except BaseException as e:  # re-raised in the test thread
            result["error"] = e

    t = threading.Thread(target=run, name=f"bounded:{what}", daemon=True)
    t.start()
    t.join(timeout)
    if t.is_alive():
        raise AssertionError(f"{what} did not return within {timeout} s")
    if "error" in result:
        raise result["error"]
    return result.get("value")


def wait_ack(conn, command: int, timeout: float = 5.0, texts: list | None = None):
    """The COMMAND_ACK for `command` from the vehicle; STATUSTEXTs seen on
    the way are appended to `texts`."""
    dl = Deadline(timeout)
    while not dl.expired():
        m = conn.recv_match(type=["COMMAND_ACK", "STATUSTEXT"], blocking=True, timeout=min(dl.left(), 0.5))
        if m is None or not from_vehicle(m):
            continue
        if m.get_type() == "STATUSTEXT":
            if texts is not None:
                texts.append(m.text)
        elif m.command == command:
            return m
    raise AssertionError(f"no COMMAND_ACK for command {command} within {timeout} s")
