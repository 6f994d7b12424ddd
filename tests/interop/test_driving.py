"""Driving end to end with the real clients: stick in, thrusters and motion out.

The board emulator and simulator run inside `neptunus --sim`; what the board
received shows in SERVO_OUTPUT_RAW (the µs really commanded: 1 starboard,
2 port, 3 vertical) and the simulated motion in NEPTUNUS_SIM_STATE, our
dialect's ground-truth message. An observer socket decodes both with a
pymavlink module generated from dialect/neptunus.xml (no global dialect
switch, so the other tests are unaffected)."""

from __future__ import annotations

import asyncio
import math
import socket
import time

import pytest

from mavhelpers import Deadline, free_tcp_port, free_udp_port, from_vehicle, generate_dialect, mavlink, recv


@pytest.fixture(scope="session")
def neptunus_dialect(tmp_path_factory):
    """pymavlink bindings of our dialect, generated with pymavlink's own mavgen
    from dialect/neptunus.xml over the upstream XML the binary is built from."""
    return generate_dialect(tmp_path_factory.mktemp("dialect"))


class Observer:
    """A UDP socket the vehicle sends to (`--mavlink udpout:`), decoded with our dialect."""

    def __init__(self, dialect):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.mav = dialect.MAVLink(None)
        self.mav.robust_parsing = True
        self.latest = {}

    def pump(self, seconds: float):
        dl = Deadline(seconds)
        while not dl.expired():
            try:
                data = self.sock.recv(4096)
            except socket.timeout:
                continue
            for m in self.mav.parse_buffer(data) or []:
                # The autopilot's own (the camera, component 100, sends a
                # HEARTBEAT of its own right after the autopilot's).
                if from_vehicle(m):
                    self.latest[m.get_type()] = m

    def wait(self, mtype: str, cond, timeout: float, what: str):
        dl = Deadline(timeout)
        while not dl.expired():
            self.pump(0.2)
            m = self.latest.get(mtype)
            if m is not None and cond(m):
                return m
        pytest.fail(f"{what}: last {mtype} was {self.latest.get(mtype)}")

    def close(self):
        self.sock.close()


def servos(m):
    return (m.servo1_raw, m.servo2_raw, m.servo3_raw)


@pytest.fixture
def observer(neptunus_dialect):
    o = Observer(neptunus_dialect)
    yield o
    o.close()


def test_pymavlink_manual_control_drives_forward_yaws_and_disarm_stops(make_vehicle, observer):
    from pymavlink import mavutil

    port = free_udp_port()
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190)
    try:
        make_vehicle([f"udpout:127.0.0.1:{port}", f"udpout:127.0.0.1:{observer.port}"])
        assert conn.wait_heartbeat(timeout=10)
        conn.arducopter_arm()
        observer.wait("HEARTBEAT", lambda m: m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 10, "armed")

        def stick(x, z, r, seconds):
            dl = Deadline(seconds)
            while not dl.expired():
                conn.mav.manual_control_send(1, x, 0, z, r, 0)
                observer.pump(0.04)  # 25 Hz

        start = observer.wait("NEPTUNUS_SIM_STATE", lambda m: True, 5, "sim state")
        stick(1000, 500, 0, 4.0)
        # Full forward at the default pilot gain 0.5; the port thruster is wired reversed.
        observer.wait("SERVO_OUTPUT_RAW", lambda m: servos(m) == (1700, 1300, 1500), 3, "forward go()")
        s = observer.wait("NEPTUNUS_SIM_STATE", lambda m: m.u > 0.4, 3, "surge speed")
        assert math.hypot(s.x - start.x, s.y - start.y) > 0.5

        psi0 = s.psi
        stick(0, 500, 1000, 3.0)
        s = observer.wait("NEPTUNUS_SIM_STATE", lambda m: m.r > 0.05, 3, "turning to starboard")
        turned = (s.psi - psi0) % (2 * math.pi)
        assert 0.1 < turned < math.pi, f"heading increased by {turned} rad"

        conn.arducopter_disarm()
        stick(1000, 500, 0, 0.5)  # the pilot keeps pushing: no effect once disarmed
        observer.wait("SERVO_OUTPUT_RAW", lambda m: servos(m) == (1500, 1500, 1500), 3, "neutral after disarm")
    finally:
        conn.close()


def test_mavproxy_rc_override_drives_forward(make_vehicle, observer, tmp_path):
    from test_mavproxy import MavProxy

    port = free_tcp_port()
    make_vehicle([f"tcpin:127.0.0.1:{port}", f"udpout:127.0.0.1:{observer.port}"])
    workdir = tmp_path / "mavproxy"
    workdir.mkdir()
    mp = MavProxy(f"tcp:127.0.0.1:{port}", workdir)
    try:
        mp.expect(r"online system 1", 60, "connect")
        mp.send("arm throttle")
        mp.expect(r"\bARMED", 30, "armed")
        mp.send("rc 5 1700")
        # (1700 − 1500)/400 = half forward, × gain 0.5: a quarter of full thrust.
        observer.wait("SERVO_OUTPUT_RAW", lambda m: servos(m) == (1600, 1400, 1500), 10, "rc 5 1700 → go()")
        observer.wait("NEPTUNUS_SIM_STATE", lambda m: m.u > 0.2, 10, "moving forward")
        mp.send("rc 5 1500")
        observer.wait("SERVO_OUTPUT_RAW", lambda m: servos(m) == (1500, 1500, 1500), 10, "rc 5 1500 → neutral")
    finally:
        mp.close()


def test_mavsdk_manual_control_drives_forward(make_vehicle, observer):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.manual_control import ManualControlAsync

    port = free_udp_port()
    make_vehicle([f"udpout:127.0.0.1:{port}", f"udpout:127.0.0.1:{observer.port}"])

    async def session():
        config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(config) as sdk:
            await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
            drone = await sdk.first_autopilot(timeout_s=15.0)
            assert drone is not None
            await ActionAsync(drone).arm()
            manual = ManualControlAsync(drone)
            end = time.monotonic() + 4.0
            while time.monotonic() < end:
                # MAVSDK: x, y, r in −1..1, z in 0..1 (0.5 = hold depth); sysid 245.
                await manual.set_manual_control_input(0.5, 0.0, 0.5, 0.0)
                await asyncio.sleep(0.05)  # the send rate, 20 Hz
                observer.pump(0.0)

    asyncio.run(asyncio.wait_for(session(), 60))
    observer.wait("SERVO_OUTPUT_RAW", lambda m: servos(m) == (1600, 1400, 1500), 3, "MAVSDK forward go()")
    observer.wait("NEPTUNUS_SIM_STATE", lambda m: m.u > 0.2, 3, "moving forward")
