"""Small helpers shared by the interoperability tests (no fixtures here):
waits with deadlines, and for the multi-station tests (control authority,
failsafes, signing) ground stations with a background inbox, the event log
and signed-frame parsing."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import re
import select
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

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


# ---------------------------------------------------------------------------
# Several ground stations at once (control authority, failsafes, signing).
# ---------------------------------------------------------------------------

REPO = Path(__file__).resolve().parents[2]

ARMED = 128  # MAV_MODE_FLAG_SAFETY_ARMED
NEUTRAL_US = 1500
# MAV_RESULT values by number: pymavlink 2.4.50's bundled dialects predate
# MAV_RESULT_NOT_IN_CONTROL.
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED, NOT_IN_CONTROL = 0, 1, 2, 3, 4, 10
RESULT_NAMES = {0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED", 4: "FAILED", 5: "IN_PROGRESS", 10: "NOT_IN_CONTROL"}
CMD_REQUEST_OPERATOR_CONTROL = 32100
CONTROL_SYSTEM_MANAGER, CONTROL_TAKEOVER_ALLOWED = 1, 2
CAP_ACCEPTS_GCS_CONTROL = 524288
# MAVLink signing timestamps count 10 µs units since 2015-01-01 00:00 UTC.
SIGNING_EPOCH_UNIX = 1420070400


def result_name(r: int) -> str:
    return f"{RESULT_NAMES.get(r, '?')} ({r})"


def mavlink_crate_xml_dir() -> Path:
    """The upstream MAVLink XML the vehicle is built from: the
    `mavlink/message_definitions/v1.0` folder of the mavlink crate package,
    found as build.rs finds it (NEPTUNUS_MAVLINK_XML_DIR, else cargo)."""
    env = os.environ.get("NEPTUNUS_MAVLINK_XML_DIR")
    if env:
        return Path(env)
    out = subprocess.run(
        ["cargo", "metadata", "--format-version", "1", "--offline", "--manifest-path", str(REPO / "Cargo.toml")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if out.returncode != 0:
        raise RuntimeError(f"cargo metadata failed: {out.stderr[-2000:]}")
    for pkg in json.loads(out.stdout)["packages"]:
        if pkg["name"] == "mavlink":
            d = Path(pkg["manifest_path"]).parent / "mavlink" / "message_definitions" / "v1.0"
            if (d / "development.xml").is_file():
                return d
    raise RuntimeError("the mavlink crate's message_definitions/v1.0 not found; set NEPTUNUS_MAVLINK_XML_DIR")


def generate_dialect(out: Path):
    """pymavlink bindings of the vehicle's own dialect: dialect/neptunus.xml
    over the upstream XML of the mavlink crate (what the binary is built
    from). pymavlink 2.4.50's bundled development.xml has neither
    CONTROL_STATUS (512) nor MAV_CMD_REQUEST_OPERATOR_CONTROL."""
    upstream = mavlink_crate_xml_dir()
    for name in (
        "minimal.xml",
        "standard.xml",
        "common.xml",
        "development.xml",
        # ardupilotmega.xml and its includes (the dialect includes it too).
        "ardupilotmega.xml",
        "uAvionix.xml",
        "icarous.xml",
        "loweheiser.xml",
        "cubepilot.xml",
        "csAirLink.xml",
    ):
        shutil.copy(upstream / name, out / name)
    shutil.copy(REPO / "dialect" / "neptunus.xml", out / "neptunus.xml")
    py = out / "neptunus_vehicle_dialect.py"
    subprocess.run(
        [sys.executable, "-m", "pymavlink.tools.mavgen", "--lang=Python3", "--wire-protocol=2.0", f"--output={py}", str(out / "neptunus.xml")],
        check=True,
        capture_output=True,
        timeout=300,
    )
    spec = importlib.util.spec_from_file_location("neptunus_vehicle_dialect", py)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert hasattr(mod, "MAVLink_control_status_message"), "generated dialect lacks CONTROL_STATUS (512)"
    return mod


def write_params(data_dir: Path, params: dict) -> None:
    """Preset parameters: DATA_DIR/params.toml, a flat TOML table, before the vehicle starts."""
    lines = [f"{name} = {value!r}" for name, value in params.items()]
    (data_dir / "params.toml").write_text("\n".join(lines) + "\n")


def start_vehicle(make_vehicle, params: dict, extra_endpoints=(), start: bool = True):
    """A vehicle with a `udpin:` endpoint for the ground stations (its port
    in `v.udp_port`) plus `extra_endpoints`, with `params` preset."""
    port = free_udp_port()
    v = make_vehicle([f"udpin:127.0.0.1:{port}", *extra_endpoints], start=False)
    v.udp_port = port
    write_params(v.data_dir, params)
    if start:
        v.start()
    return v


# ---- thruster output (SERVO_OUTPUT_RAW: 1 starboard, 2 port, 3 vertical) ----

def servos(m) -> tuple:
    return (m.servo1_raw, m.servo2_raw, m.servo3_raw)


def is_neutral(m) -> bool:
    return servos(m) == (NEUTRAL_US, NEUTRAL_US, NEUTRAL_US)


def is_forward(m) -> bool:
    """Surge ahead: starboard above neutral, port (wired reversed) below."""
    return m.servo1_raw > NEUTRAL_US + 50 and m.servo2_raw < NEUTRAL_US - 50


def is_reverse(m) -> bool:
    return m.servo1_raw < NEUTRAL_US - 50 and m.servo2_raw > NEUTRAL_US + 50


def is_armed(m) -> bool:
    return bool(m.base_mode & ARMED)


# Stick positions for MANUAL_CONTROL (x, y, z, r): z = 500 is the centre.
CENTRED = (0, 0, 500, 0)
FULL_AHEAD = (1000, 0, 500, 0)
FULL_ASTERN = (-1000, 0, 500, 0)


class Inbox:
    """Every MAVLink frame arriving on a UDP socket, decoded by a reader
    thread and kept in arrival order. Nothing is consumed, so several waits
    can look at the same traffic, and order between messages can be checked
    (each message gets `_idx`, its position). The parser has no signing key:
    signed frames decode, and their raw bytes stay in `get_msgbuf()`."""

    def __init__(self, sock: socket.socket, dialect, name: str):
        self.sock = sock
        self.name = name
        self.parser = dialect.MAVLink(None)
        self.parser.robust_parsing = True
        self.msgs: list = []
        self.cond = threading.Condition()
        self.stop_event = threading.Event()
        self.thread = threading.Thread(target=self._run, name=f"inbox:{name}", daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop_event.is_set():
            try:
                ready, _, _ = select.select([self.sock], [], [], 0.2)
                if not ready:
                    continue
                data, _addr = self.sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError, ConnectionRefusedError):
                continue
            except (OSError, ValueError):
                return  # socket closed
            try:
                msgs = self.parser.parse_buffer(data) or []
            except Exception:  # a frame pymavlink cannot decode: not ours to judge here
                continue
            with self.cond:
                for m in msgs:
                    if m.get_type() == "BAD_DATA":
                        continue
                    m._idx = len(self.msgs)
                    self.msgs.append(m)
                self.cond.notify_all()

    def close(self):
        self.stop_event.set()
        self.thread.join(timeout=5)

    def mark(self) -> int:
        """The position of the next message to arrive."""
        with self.cond:
            return len(self.msgs)

    def select(self, types=None, cond=None, since: int = 0, until: int | None = None) -> list:
        """Messages already received at positions since..until, of `types` and satisfying `cond`."""
        if isinstance(types, str):
            types = [types]
        with self.cond:
            window = self.msgs[since:until]
        return [m for m in window if (types is None or m.get_type() in types) and (cond is None or cond(m))]

    def last(self, mtype: str, since: int = 0):
        found = self.select(mtype, since=since)
        return found[-1] if found else None

    def wait(self, types, cond=None, timeout: float = 10.0, since: int = 0, what: str = ""):
        """The first message at or after `since` of `types` satisfying `cond`;
        fails the test (saying what was expected and what was last seen) after `timeout` s."""
        return self.wait_count(types, 1, cond, timeout, since, what)[0]

    def wait_count(self, types, n: int, cond=None, timeout: float = 10.0, since: int = 0, what: str = "") -> list:
        """The first `n` such messages at or after `since` (`types` None: any type)."""
        if isinstance(types, str):
            types = [types]
        dl = Deadline(timeout)
        pos = since
        found: list = []
        with self.cond:
            while True:
                while pos < len(self.msgs):
                    m = self.msgs[pos]
                    pos += 1
                    if (types is None or m.get_type() in types) and (cond is None or cond(m)):
                        found.append(m)
                        if len(found) >= n:
                            return found
                if dl.expired():
                    break
                self.cond.wait(min(dl.left(), 0.5))
        last = {t: str(self.last(t, since)) for t in types} if types else [str(m) for m in self.select(since=max(since, len(self.msgs) - 3))]
        raise AssertionError(
            f"{self.name}: expected {n} × {'/'.join(types or ['any message'])} — {what or 'matching'} — within {timeout} s "
            f"after position {since}; got {len(found)}; last seen: {last}"
        )

    def texts(self, since: int = 0, until: int | None = None) -> list[str]:
        return [m.text for m in self.select("STATUSTEXT", since=since, until=until)]


class Gcs:
    """A pymavlink ground station (sysid, compid) on its own UDP socket
    (`udpout:` to the vehicle's `udpin:` port, bound to a port of its own),
    speaking the vehicle's dialect. Background threads: an Inbox reader,
    HEARTBEAT at 1 Hz (type GCS, autopilot INVALID) while `alive`, and
    MANUAL_CONTROL at 20 Hz while sticks are set. The send path is locked:
    pymavlink's is not thread-safe (sequence numbers, signing timestamps)."""

    STICK_PERIOD_S = 0.05  # the stick send rate (20 Hz), like a joystick
    HEARTBEAT_PERIOD_S = 1.0

    def __init__(self, dialect, vehicle_port: int, sysid: int, compid: int = 190, name: str | None = None):
        self.sysid, self.compid = sysid, compid
        self.name = name or f"GCS {sysid}"
        self.dialect = dialect
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{vehicle_port}", source_system=sysid, source_component=compid)
        self.conn.port.bind(("127.0.0.1", 0))  # a peer of its own, receiving before its first send
        self.conn.mav = dialect.MAVLink(self.conn, srcSystem=sysid, srcComponent=compid)
        self.conn.mav.robust_parsing = True
        self.mav = self.conn.mav
        self.lock = threading.RLock()
        orig_send = self.mav.send

        def locked_send(msg, force_mavlink1=False):
            with self.lock:
                orig_send(msg, force_mavlink1=force_mavlink1)

        self.mav.send = locked_send
        self.inbox = Inbox(self.conn.port, dialect, self.name)
        self.stop_event = threading.Event()
        self.alive = False
        self.heartbeats_sent = 0
        self._sticks: tuple | None = None
        self.thread = threading.Thread(target=self._run, name=f"gcs:{self.name}", daemon=True)
        self.thread.start()

    # -- background traffic --
    def _run(self):
        next_beat = time.monotonic()
        while not self.stop_event.is_set():
            now = time.monotonic()
            try:
                if self.alive and now >= next_beat:
                    self.heartbeat()
                    next_beat = now + self.HEARTBEAT_PERIOD_S
                sticks = self._sticks
                if sticks is not None:
                    self.manual_control(*sticks)
            except OSError:
                pass  # the vehicle may be restarting
            self.stop_event.wait(self.STICK_PERIOD_S)

    def heartbeat(self):
        self.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
        self.heartbeats_sent += 1

    def manual_control(self, x, y, z, r, buttons=0):
        self.mav.manual_control_send(1, x, y, z, r, buttons)

    def start_heartbeat(self):
        self.heartbeat()
        self.alive = True

    def stop_heartbeat(self):
        self.alive = False

    def sticks(self, position: tuple | None, repeat_now: int = 1):
        """From now on send `position` (x, y, z, r) at 20 Hz (None: stop
        sending). The first `repeat_now` frames go out at once, so frames
        sent afterwards by this thread are known to follow them."""
        if position is not None:
            for _ in range(repeat_now):
                self.manual_control(*position)
        self._sticks = position

    def connect(self, timeout: float = 10.0, heartbeat: bool = True):
        """Say hello (our HEARTBEAT makes us a UDP peer) and wait for the vehicle's."""
        if heartbeat:
            self.start_heartbeat()
        else:
            self.heartbeat()
        self.inbox.wait("HEARTBEAT", from_vehicle, timeout, what=f"the vehicle's HEARTBEAT on {self.name}'s socket")
        return self

    # -- requests --
    def command(self, cmd: int, *params, target=(1, 1)):
        p = list(params) + [0.0] * (7 - len(params))
        msg = self.mav.command_long_encode(target[0], target[1], cmd, 0, *p)
        self.mav.send(msg)
        return msg

    def command_ack(self, cmd: int, *params, timeout: float = 10.0, what: str = ""):
        """Send COMMAND_LONG and return the vehicle's COMMAND_ACK for it."""
        mark = self.inbox.mark()
        self.command(cmd, *params)
        return self.inbox.wait(
            "COMMAND_ACK",
            lambda m: from_vehicle(m) and m.command == cmd,
            timeout,
            mark,
            what or f"COMMAND_ACK for command {cmd} sent by {self.name}",
        )

    def ack_forwarded(self, cmd: int, result: int):
        """Answer a command the vehicle sent us."""
        self.mav.command_ack_send(cmd, result, 0, 0, 1, 1)

    def param_read(self, name: str, timeout: float = 10.0):
        mark = self.inbox.mark()
        self.mav.param_request_read_send(1, 1, name.encode(), -1)
        return self.inbox.wait("PARAM_VALUE", lambda m: m.param_id == name, timeout, mark, f"PARAM_VALUE {name}")

    def set_interval(self, msg_id: int, hz: float):
        return self.command_ack(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def send_raw(self, buf: bytes):
        with self.lock:
            self.conn.write(buf)

    def close(self):
        self._sticks = None
        self.alive = False
        self.stop_event.set()
        self.thread.join(timeout=5)
        self.inbox.close()
        self.conn.close()


class Observer:
    """A bound UDP socket the vehicle sends to (`--mavlink udpout:`): sees
    everything the vehicle broadcasts, sends nothing."""

    def __init__(self, dialect, name: str = "observer"):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.url = f"udpout:127.0.0.1:{self.port}"
        self.inbox = Inbox(self.sock, dialect, name)

    def close(self):
        self.inbox.close()
        self.sock.close()


class Stations:
    """Everything a test opened, closed at teardown (see conftest's `stations`)."""

    def __init__(self, dialect):
        self.dialect = dialect
        self.opened: list = []

    def gcs(self, vehicle_port: int, sysid: int, compid: int = 190, name: str | None = None) -> Gcs:
        g = Gcs(self.dialect, vehicle_port, sysid, compid, name)
        self.opened.append(g)
        return g

    def observer(self, name: str = "observer") -> Observer:
        o = Observer(self.dialect, name)
        self.opened.append(o)
        return o

    def close(self):
        for s in reversed(self.opened):
            try:
                s.close()
            except OSError:
                pass


def control_status(inbox: Inbox, gcs_main: int, since: int = 0, timeout: float = 10.0, what: str = ""):
    """The first CONTROL_STATUS since `since` naming `gcs_main` as the owner."""
    return inbox.wait(
        "CONTROL_STATUS",
        lambda m: from_vehicle(m) and m.gcs_main == gcs_main,
        timeout,
        since,
        what or f"CONTROL_STATUS with gcs_main {gcs_main}",
    )


def heartbeat_where(inbox: Inbox, cond, since: int = 0, timeout: float = 10.0, what: str = ""):
    return inbox.wait("HEARTBEAT", lambda m: from_vehicle(m) and cond(m), timeout, since, what)


def servo_samples(inbox: Inbox, n: int, since: int, timeout: float = 15.0, what: str = "") -> list:
    """`n` SERVO_OUTPUT_RAW samples from position `since` on: a window of
    observation measured in samples, not seconds."""
    return inbox.wait_count("SERVO_OUTPUT_RAW", n, from_vehicle, timeout, since, what or f"{n} SERVO_OUTPUT_RAW samples")


def assert_all(msgs: list, pred, expected: str):
    bad = [(m._idx, servos(m) if m.get_type() == "SERVO_OUTPUT_RAW" else str(m)) for m in msgs if not pred(m)]
    assert not bad, f"expected every sample {expected}; {len(bad)} of {len(msgs)} were not: {bad[:10]}"


def statustext(inbox: Inbox, pattern: str, since: int = 0, timeout: float = 10.0, max_severity: int = 7, what: str = ""):
    """The first STATUSTEXT since `since` whose text matches the regex
    `pattern` (case-insensitive) with severity <= `max_severity` (0 is worst)."""
    rx = re.compile(pattern, re.IGNORECASE)
    try:
        return inbox.wait(
            "STATUSTEXT",
            lambda m: from_vehicle(m) and rx.search(m.text) is not None and m.severity <= max_severity,
            timeout,
            since,
            what or f"STATUSTEXT /{pattern}/",
        )
    except AssertionError as e:
        raise AssertionError(f"{e}\n  STATUSTEXTs seen since {since}: {inbox.texts(since)}") from None


# ---- event log: DATA_DIR/events/events.jsonl ----

class EventLog:
    """DATA_DIR/events/events.jsonl (and rotated events.N.jsonl), read as
    the vehicle writes it: one JSON object per complete line."""

    def __init__(self, data_dir: Path):
        self.dir = data_dir / "events"

    def read(self) -> list[dict]:
        files = sorted(self.dir.glob("events.*.jsonl"), key=lambda p: -int(p.name.split(".")[1]) if p.name.split(".")[1].isdigit() else 0)
        files.append(self.dir / "events.jsonl")
        out: list[dict] = []
        for f in files:
            try:
                text = f.read_text(errors="replace")
            except FileNotFoundError:
                continue
            for line in text.split("\n")[:-1]:  # the last piece is an unfinished line (or empty)
                line = line.strip()
                if line:
                    e = json.loads(line)
                    e["_pos"] = len(out)
                    out.append(e)
        return out

    def summary(self) -> list:
        return [(e.get("event"), e.get("sysid")) for e in self.read()]

    def wait(self, event, sysids=None, timeout: float = 15.0, after: dict | None = None, cond=None, what: str = "") -> dict:
        """The first `event` (a name, or a tuple of acceptable names) after
        the event `after` (if given) whose sysid is in `sysids` (None: any)
        and that satisfies `cond`."""
        names = (event,) if isinstance(event, str) else tuple(event)
        dl = Deadline(timeout)
        while True:
            events = self.read()
            for e in events[after["_pos"] + 1 if after else 0:]:
                if e.get("event") in names and (sysids is None or e.get("sysid") in sysids) and (cond is None or cond(e)):
                    for key in ("time", "unix_us", "mono_s", "event", "sysid", "detail"):
                        assert key in e, f"event {e} lacks the field {key!r}"
                    return e
            if dl.expired():
                raise AssertionError(
                    f"expected event {event!r} with sysid in {sysids} {what} in {self.dir / 'events.jsonl'} within {timeout} s"
                    + (f" after {after.get('event')} #{after['_pos']}" if after else "")
                    + f"; the log has (event, sysid): {[(x.get('event'), x.get('sysid')) for x in events]}"
                )
            time.sleep(0.1)  # poll interval for a file, not a timing assumption


# ---- MAVLink 2 signing, read from the raw frame ----

def signing_timestamp(ahead_s: float = 0.0) -> int:
    """A signing timestamp (10 µs units since 2015-01-01) `ahead_s` seconds from now."""
    return int((time.time() - SIGNING_EPOCH_UNIX + ahead_s) * 100_000)


def is_signed(m) -> bool:
    buf = m.get_msgbuf()
    return buf[0] == 0xFD and bool(buf[2] & 0x01)


def signature_timestamp(m) -> int | None:
    """The 48-bit timestamp of a signed frame (None if unsigned)."""
    if not is_signed(m):
        return None
    return int.from_bytes(bytes(m.get_msgbuf()[-12:-6]), "little")


def signature_valid(m, key: bytes) -> bool:
    """Signature = first 6 bytes of SHA-256(key ‖ frame up to and including the timestamp)."""
    buf = bytes(m.get_msgbuf())
    return is_signed(m) and hashlib.sha256(key + buf[:-6]).digest()[:6] == buf[-6:]


def wait_for(pred, timeout: float, what: str):
    """Poll `pred()` until it is true; fail saying `what` was expected."""
    dl = Deadline(timeout)
    while not pred():
        if dl.expired():
            raise AssertionError(f"expected {what} within {timeout} s")
        time.sleep(0.05)  # poll interval, not a timing assumption
