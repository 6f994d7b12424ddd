"""Commands our dialect does not define still get exactly one COMMAND_ACK
UNSUPPORTED, at once (rule 4 of reference/gcs-clients.md): pymavlink's
ArduPilot dialect knows commands that development.xml does not."""

from __future__ import annotations

from mavhelpers import Deadline, mavlink, recv


def test_unknown_command_number_is_unsupported_at_once(udp_vehicle):
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{udp_vehicle.udp_port}", source_system=255, source_component=190)
    try:
        conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert conn.wait_heartbeat(timeout=10)
        for command in (42428, 31010, 65000):  # DO_SEND_BANNER (ardupilotmega), a USER command, nothing at all
            conn.mav.command_long_send(1, 1, command, 0, 0, 0, 0, 0, 0, 0, 0)
            acks = []
            dl = Deadline(1.5)
            while not dl.expired():
                m = recv(conn, "COMMAND_ACK", dl.left(), lambda m: m.command == command)
                if m is not None:
                    acks.append(m)
            assert len(acks) == 1, f"command {command}: {acks}"
            a = acks[0]
            assert a.result == mavlink.MAV_RESULT_UNSUPPORTED
            assert (a.target_system, a.target_component) == (255, 190)
    finally:
        conn.close()
