"""MAVSDK (Python `mavsdk` 4.1.0: the native binding, MAVSDK's C++ core in
process, no mavsdk_server). The vehicle sends to MAVSDK's default-style
`udpin://` socket (`--mavlink udpout:`), as in MAVSDK's examples.

4.x replaced the gRPC API (`System().connect(system_address=...)`) with
`Mavsdk(Configuration)` + `add_any_connection(url)` + `first_autopilot()`;
plugins are constructed on the System."""

from __future__ import annotations

import asyncio
import math

import pytest

mavsdk_asyncio = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk, Vehicle  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402

from mavhelpers import free_udp_port  # noqa: E402

TEST_TIMEOUT_S = 60.0


async def first(gen, cond=lambda _: True, timeout: float = 10.0, what: str = "value"):
    """The first item of an async generator satisfying `cond`, within `timeout`."""

    async def take():
        async for x in gen:
            if cond(x):
                return x

    try:
        return await asyncio.wait_for(take(), timeout)
    except asyncio.TimeoutError:
        pytest.fail(f"no {what} within {timeout} s")
    finally:
        await gen.aclose()


async def session(port: int):
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        drone = await sdk.first_autopilot(timeout_s=15.0)
        assert drone is not None, "MAVSDK found no autopilot within 15 s"
        assert await drone.is_connected()
        assert await drone.has_autopilot()
        assert await drone.get_system_id() == 1
        assert 1 in await drone.component_ids()
        # MAVSDK knows the autopilot's kind from its HEARTBEAT, which comes
        # once a second: the system may be found from another message first.
        kind = await drone.autopilot_type()
        for _ in range(50):
            if kind == Autopilot.ARDUPILOT:
                break
            await asyncio.sleep(0.1)
            kind = await drone.autopilot_type()
        assert kind == Autopilot.ARDUPILOT
        assert await drone.vehicle_type() == Vehicle.SUBMARINE

        telemetry = TelemetryAsync(drone)
        action = ActionAsync(drone)

        att = await first(telemetry.subscribe_attitude_euler(), what="attitude_euler sample")
        for v in (att.roll_deg, att.pitch_deg, att.yaw_deg):
            assert math.isfinite(v) and -180.0 <= v <= 360.0, att

        # The vehicle is "ready" (fresh board telemetry), so the voltage is known.
        bat = await first(
            telemetry.subscribe_battery(), lambda b: b.voltage_v > 0, what="battery sample with a voltage"
        )
        assert 9.0 < bat.voltage_v < 14.0, bat
        assert 0.0 <= bat.remaining_percent <= 100.0, bat

        await action.arm()  # raises ActionError unless ACCEPTED
        await first(telemetry.subscribe_armed(), lambda a: a, what="armed=True")
        await action.disarm()
        await first(telemetry.subscribe_armed(), lambda a: not a, what="armed=False")


def test_mavsdk_connect_arm_telemetry(make_vehicle):
    port = free_udp_port()
    # The vehicle first, then the ground station (the usual order in the field).
    make_vehicle([f"udpout:127.0.0.1:{port}"])
    asyncio.run(asyncio.wait_for(session(port), TEST_TIMEOUT_S))
