"""The telemetry log in DATA_DIR/tlogs is a standard tlog: pymavlink's
mavlogdump.py reads it, and it holds frames in both directions."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

from pymavlink import mavutil

from mavhelpers import Deadline, GcsHeartbeat, from_vehicle, mavlink, recv, wait_ack

MAVLOGDUMP = Path(sys.executable).parent / "mavlogdump.py"
GCS = (255, 190)


def test_tlog_readable_by_mavlogdump(udp_vehicle):
    conn = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{udp_vehicle.udp_port}", source_system=GCS[0], source_component=GCS[1]
    )
    try:
        with GcsHeartbeat(conn) as hb:
            assert recv(conn, "HEARTBEAT", 5.0, from_vehicle) is not None
            conn.mav.command_long_send(1, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0)
            assert wait_ack(conn, mavlink.MAV_CMD_REQUEST_MESSAGE).result == mavlink.MAV_RESULT_ACCEPTED
            conn.mav.param_request_read_send(1, 1, b"JS_GAIN_DEFAULT", -1)
            assert recv(conn, "PARAM_VALUE", 5.0, from_vehicle) is not None
            assert recv(conn, "ATTITUDE", 5.0, from_vehicle) is not None
            assert recv(conn, "SYS_STATUS", 5.0, from_vehicle) is not None
            # At least two of our heartbeats on the wire (the thread beats at 1 Hz).
            dl = Deadline(5.0)
            while hb.sent < 2 and not dl.expired():
                conn.recv_match(blocking=True, timeout=0.2)
            assert hb.sent >= 2
            # One more vehicle heartbeat after our last command, so everything
            # above has been through the vehicle's loop and logger.
            assert recv(conn, "HEARTBEAT", 5.0, from_vehicle) is not None
    finally:
        conn.close()
    # A clean stop flushes and closes the log.
    assert udp_vehicle.stop() in (0, -15)

    tlogs = sorted((udp_vehicle.data_dir / "tlogs").glob("*.tlog"))
    assert len(tlogs) == 1, tlogs
    dump = subprocess.run(
        [sys.executable, str(MAVLOGDUMP), "--format", "json", "--show-source", str(tlogs[0])],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert dump.returncode == 0, dump.stderr[-2000:]
    seen: dict[tuple[int, int], set[str]] = defaultdict(set)
    bad = 0
    for line in dump.stdout.splitlines():
        try:
            meta = json.loads(line)["meta"]
        except (ValueError, KeyError):
            continue
        if meta["type"] == "BAD_DATA":
            bad += 1
        seen[(meta["srcSystem"], meta["srcComponent"])].add(meta["type"])
    assert bad == 0, f"{bad} BAD_DATA records in the tlog"
    out = seen[(1, 1)]
    for t in ("HEARTBEAT", "ATTITUDE", "SYS_STATUS", "PARAM_VALUE", "COMMAND_ACK", "AUTOPILOT_VERSION"):
        assert t in out, f"{t} from the vehicle missing from the tlog; saw {sorted(out)}"
    into = seen[GCS]
    for t in ("HEARTBEAT", "COMMAND_LONG", "PARAM_REQUEST_READ"):
        assert t in into, f"the GCS's {t} missing from the tlog; saw {sorted(into)}"
