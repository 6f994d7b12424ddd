"""Fixtures for the interoperability suite: the real `neptunus --sim` binary
driven by the real ground-station libraries.

Every vehicle gets a fresh data directory and ports picked by the OS (bind
port 0, read the port back). Readiness is a condition polled with a deadline:
a HEARTBEAT from (1, 1) with system_status STANDBY and a SYS_STATUS with
PREARM_CHECK healthy, on the vehicle's control TCP endpoint. Nothing sleeps to wait for timing.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")  # speak MAVLink 2 from the first frame

from pymavlink import mavutil  # noqa: E402

from mavhelpers import Deadline, Stations, free_tcp_port, free_udp_port, from_vehicle, generate_dialect, recv  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
BIN = Path(os.environ.get("NEPTUNUS_BIN", REPO / "target" / "debug" / "neptunus"))
STANDBY = mavutil.mavlink.MAV_STATE_STANDBY
PREARM_CHECK = mavutil.mavlink.MAV_SYS_STATUS_PREARM_CHECK
READY_TIMEOUT_S = 20.0
# With the genuine firmware in the loop (`neptunus --hil`): the firmware's
# built .elf (`neptunus genuine-board --build-only`), else the emulator.
HIL_FIRMWARE = os.environ.get("NEPTUNUS_HIL_FIRMWARE") or None
STOP_TIMEOUT_S = 10.0


def wait_connect_tcp(port: int, timeout: float) -> None:
    """Poll until something accepts on 127.0.0.1:port."""
    dl = Deadline(timeout)
    last = None
    while not dl.expired():
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
            return
        except OSError as e:  # not listening yet
            last = e
            time.sleep(0.05)  # poll interval, not a timing assumption
    raise TimeoutError(f"nothing accepted on tcp 127.0.0.1:{port} within {timeout} s: {last}")


class Vehicle:
    """One `neptunus --sim` process. `endpoints` are extra --mavlink URLs; a
    `tcpin` control endpoint is always added for the readiness check."""

    def __init__(self, data_dir: Path, endpoints: list[str], log_dir: Path):
        self.data_dir = data_dir
        self.endpoints = list(endpoints)
        self.control_port = free_tcp_port()
        self.log_dir = log_dir
        self.proc: subprocess.Popen | None = None
        self.starts = 0
        self.stderr_paths: list[Path] = []
        # More command-line arguments (a --config FILE).
        self.extra_args: list[str] = []

    @property
    def control_url(self) -> str:
        return f"tcp:127.0.0.1:{self.control_port}"

    def start(self, wait: bool = True) -> "Vehicle":
        assert self.proc is None, "already running"
        if not BIN.exists():
            pytest.fail(f"vehicle binary {BIN} does not exist — run `cargo build` or set NEPTUNUS_BIN")
        self.starts += 1
        err_path = self.log_dir / f"neptunus-stderr-{self.starts}.txt"
        self.stderr_paths.append(err_path)
        # The browser HMI on a free loopback port: parallel tests never share 8080.
        # The board: the emulator (--sim), or the genuine firmware in simavr
        # (--hil) when NEPTUNUS_HIL_FIRMWARE names its built .elf.
        board = ["--hil", HIL_FIRMWARE] if HIL_FIRMWARE else ["--sim"]
        args = [str(BIN), *board, "--data-dir", str(self.data_dir), "--http", "127.0.0.1:0", *self.extra_args]
        for url in self.endpoints + [f"tcpin:127.0.0.1:{self.control_port}"]:
            args += ["--mavlink", url]
        env = dict(os.environ, NO_COLOR="1", RUST_LOG=os.environ.get("RUST_LOG", "info"))
        with open(err_path, "wb") as err:
            self.proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=err, stderr=err, env=env)
        if wait:
            self.wait_ready()
        return self

    def wait_ready(self, timeout: float = READY_TIMEOUT_S) -> None:
        """Ready = a HEARTBEAT with system_status STANDBY (board link up) and a
        SYS_STATUS whose health has PREARM_CHECK (fresh telemetry: QGC's
        "Ready"), both from (1, 1)."""
        dl = Deadline(timeout)
        wait_connect_tcp(self.control_port, timeout)
        conn = mavutil.mavlink_connection(self.control_url, source_system=254, source_component=191, retries=0)
        standby = prearm = False
        try:
            while not (standby and prearm):
                if dl.expired():
                    raise TimeoutError(
                        f"vehicle not ready within {timeout} s (STANDBY heartbeat: {standby}, PREARM_CHECK healthy: {prearm})"
                    )
                if self.proc.poll() is not None:
                    raise RuntimeError(f"neptunus exited with {self.proc.returncode} before it was ready")
                m = recv(conn, ["HEARTBEAT", "SYS_STATUS"], min(dl.left(), 1.0), from_vehicle)
                if m is None:
                    continue
                if m.get_type() == "HEARTBEAT":
                    standby = m.system_status == STANDBY
                else:
                    prearm = bool(m.onboard_control_sensors_health & PREARM_CHECK)
        finally:
            conn.close()

    def stop(self) -> int | None:
        """SIGTERM, wait, then SIGKILL. Returns the exit code."""
        p, self.proc = self.proc, None
        if p is None:
            return None
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=STOP_TIMEOUT_S)
        return p.returncode

    def restart(self) -> "Vehicle":
        """Stop and start again on the same data directory and ports."""
        self.stop()
        return self.start()

    def stderr_text(self) -> str:
        out = []
        for p in self.stderr_paths:
            try:
                out.append(f"--- {p.name} ---\n" + p.read_text(errors="replace"))
            except OSError:
                pass
        return "\n".join(out)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """On failure, attach every vehicle's stderr to the report."""
    outcome = yield
    rep = outcome.get_result()
    if rep.failed:
        for i, v in enumerate(getattr(item, "_neptunus_vehicles", []), 1):
            rep.sections.append((f"neptunus #{i} stderr ({v.data_dir})", v.stderr_text()[-20000:]))


@pytest.fixture
def make_vehicle(request, tmp_path):
    """Factory: make_vehicle(endpoints=[...], start=True) -> Vehicle. All
    vehicles are stopped at teardown; their stderr is printed if the test failed."""
    made: list[Vehicle] = []
    request.node._neptunus_vehicles = made

    def make(endpoints: list[str] | None = None, start: bool = True) -> Vehicle:
        n = len(made) + 1
        data_dir = tmp_path / f"data{n}"
        data_dir.mkdir()
        v = Vehicle(data_dir, endpoints or [], tmp_path)
        made.append(v)
        if start:
            v.start()
        return v

    yield make
    codes = [v.stop() for v in made]
    # A vehicle that crashed (a panic exits 101) fails the test even if the
    # client side looked fine.
    bad = [(i, c) for i, c in enumerate(codes, 1) if c not in (None, 0, -signal.SIGTERM)]
    assert not bad, f"neptunus exited abnormally (vehicle #, exit code): {bad}"


@pytest.fixture
def udp_vehicle(make_vehicle):
    """A vehicle listening on udpin (clients connect with `udpout:`)."""
    port = free_udp_port()
    v = make_vehicle([f"udpin:127.0.0.1:{port}"])
    v.udp_port = port
    return v


@pytest.fixture
def pymav(make_vehicle):
    """(vehicle, connection): the ArduSub-script way — pymavlink listens with
    `udpin:` and the vehicle sends to it (`--mavlink udpout:`). The client
    socket is bound before the vehicle starts."""
    port = free_udp_port()
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
    try:
        v = make_vehicle([f"udpout:127.0.0.1:{port}"])
        hb = conn.wait_heartbeat(timeout=10)
        assert hb is not None, "no HEARTBEAT on the udpin socket the vehicle sends to"
        yield v, conn
    finally:
        conn.close()


@pytest.fixture(scope="session")
def vehicle_dialect(tmp_path_factory):
    """pymavlink bindings generated from the vehicle's own dialect (our XML
    over the mavlink crate's upstream XML): CONTROL_STATUS, REQUEST_OPERATOR_CONTROL,
    NEPTUNUS_SIM_STATE decode."""
    return generate_dialect(tmp_path_factory.mktemp("vehicle-dialect"))


@pytest.fixture
def stations(vehicle_dialect):
    """Factory of ground stations and observers (`stations.gcs(port, sysid)`,
    `stations.observer()`), all closed at teardown."""
    s = Stations(vehicle_dialect)
    yield s
    s.close()
