"""Depth hold end to end over UDP with the board emulator, driven the way
ArduSub's documented pymavlink example drives a BlueROV2: arm, switch to
ALT_HOLD, then send SET_POSITION_TARGET_GLOBAL_INT with only z (alt =
-depth) a few times a second. The held depth shows in GLOBAL_POSITION_INT
(relative_alt, mm, negative below the surface) and in our
NEPTUNUS_AUTOPILOT; the run mode switch is checked on the same vehicle.
Bounds are deadlines for a shared machine, never measured times."""

from __future__ import annotations

import time

from mavhelpers import Deadline, bounded, from_vehicle, mavlink, recv, wait_ack

# POSITION_TARGET_TYPEMASK: everything ignored except z (ArduSub's example).
IGNORE_ALL_BUT_Z = (
    mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)
HOLD_DEADLINE_S = 60.0  # 1 m at 0.4 m/s is a few seconds; slack for a noisy machine
TOLERANCE_M = 0.15


def set_target_depth(conn, boot: float, depth_m: float) -> None:
    conn.mav.set_position_target_global_int_send(
        int(1e3 * (time.time() - boot)),
        conn.target_system,
        conn.target_component,
        coordinate_frame=mavlink.MAV_FRAME_GLOBAL_INT,
        type_mask=IGNORE_ALL_BUT_Z,
        lat_int=0,
        lon_int=0,
        alt=-depth_m,
        vx=0,
        vy=0,
        vz=0,
        afx=0,
        afy=0,
        afz=0,
        yaw=0,
        yaw_rate=0,
    )


def hold_until(conn, boot: float, depth_m: float, what: str) -> float:
    """Sends the target at 4 Hz until the reported depth has stayed within
    TOLERANCE_M of it for 3 s; returns the last reported depth."""
    dl = Deadline(HOLD_DEADLINE_S)
    inside_since = None
    last_send = 0.0
    depth = float("nan")
    seen = []  # (time, depth) for the failure's message
    while not dl.expired():
        now = time.monotonic()
        if now - last_send >= 0.25:
            set_target_depth(conn, boot, depth_m)
            conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
            last_send = now
        m = recv(conn, "GLOBAL_POSITION_INT", 0.3, from_vehicle)
        if m is None:
            continue
        depth = -m.relative_alt / 1000.0
        seen.append((now, depth))
        if abs(depth - depth_m) <= TOLERANCE_M:
            inside_since = inside_since or now
            if now - inside_since >= 3.0:
                return depth
        else:
            inside_since = None
    end = time.monotonic()
    last = [d for t, d in seen if end - t <= 10.0]
    span = f"; last 10 s: {min(last):.2f}..{max(last):.2f} m over {len(last)} reports" if last else "; no reports in the last 10 s"
    raise AssertionError(f"{what}{span}: depth {depth:.2f} m never held within {TOLERANCE_M} m of {depth_m} m for 3 s in {HOLD_DEADLINE_S} s")


def test_set_position_target_global_int_moves_the_held_depth(pymav):
    _, conn = pymav
    boot = time.time()
    conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
    conn.arducopter_arm()
    assert wait_ack(conn, mavlink.MAV_CMD_COMPONENT_ARM_DISARM).result == mavlink.MAV_RESULT_ACCEPTED
    bounded(conn.motors_armed_wait, 10, "motors_armed_wait")

    mode = conn.mode_mapping()["ALT_HOLD"]
    conn.set_mode(mode)
    assert wait_ack(conn, mavlink.MAV_CMD_DO_SET_MODE).result == mavlink.MAV_RESULT_ACCEPTED
    hb = recv(conn, "HEARTBEAT", 5.0, lambda m: from_vehicle(m) and m.custom_mode == mode)
    assert hb is not None, "the vehicle never reported ALT_HOLD"

    hold_until(conn, boot, 1.0, "target 1.0 m")
    hold_until(conn, boot, 0.4, "target moved to 0.4 m")

    # NAV_CONTROLLER_OUTPUT carries the depth error (ArduPilot's alt_error).
    conn.mav.command_long_send(1, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 62, 200_000, 0, 0, 0, 0, 0)
    nav = recv(conn, "NAV_CONTROLLER_OUTPUT", 5.0, from_vehicle)
    assert nav is not None, "no NAV_CONTROLLER_OUTPUT"
    assert abs(nav.alt_error) < 0.5, f"alt_error {nav.alt_error} while holding"
    conn.arducopter_disarm()


def test_run_mode_switch_stops_the_thrusters_and_flags_simulated(pymav):
    _, conn = pymav
    conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
    conn.arducopter_arm()
    assert wait_ack(conn, mavlink.MAV_CMD_COMPONENT_ARM_DISARM).result == mavlink.MAV_RESULT_ACCEPTED
    # Drive ahead, then switch to the built-in simulator (our dialect's command 44200).
    dl = Deadline(10)
    moving = None
    while not dl.expired() and moving is None:
        conn.mav.manual_control_send(1, 800, 0, 500, 0, 0)
        s = recv(conn, "SERVO_OUTPUT_RAW", 0.2, from_vehicle)
        if s is not None and s.servo1_raw != 1500:
            moving = s
    assert moving is not None, "the thrusters never moved ahead"
    texts: list[str] = []
    conn.mav.command_long_send(1, 1, 44200, 0, 1, 0, 0, 0, 0, 0, 0)
    ack = wait_ack(conn, 44200, texts=texts)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED, f"run mode ack {ack}"
    # The STATUSTEXT comes with the switch, before or after the ack.
    if not any("simulated" in t for t in texts):
        st = recv(conn, "STATUSTEXT", 5.0, lambda m: from_vehicle(m) and "simulated" in m.text)
        assert st is not None, f"no STATUSTEXT saying telemetry is simulated; saw {texts}"
    hb = recv(conn, "HEARTBEAT", 5.0, lambda m: from_vehicle(m) and m.base_mode & mavlink.MAV_MODE_FLAG_HIL_ENABLED)
    assert hb is not None, "HEARTBEAT does not carry MAV_MODE_FLAG_HIL_ENABLED in simulator run mode"
    # A safety stop: the sticks must come back to centre before anything moves again.
    s = recv(conn, "SERVO_OUTPUT_RAW", 5.0, lambda m: from_vehicle(m) and (m.servo1_raw, m.servo2_raw, m.servo3_raw) == (1500, 1500, 1500))
    assert s is not None, "the thrusters did not stop at the run mode switch"
    conn.mav.command_long_send(1, 1, 44200, 0, 0, 0, 0, 0, 0, 0, 0)
    assert wait_ack(conn, 44200).result == mavlink.MAV_RESULT_ACCEPTED
    hb = recv(conn, "HEARTBEAT", 5.0, lambda m: from_vehicle(m) and not m.base_mode & mavlink.MAV_MODE_FLAG_HIL_ENABLED)
    assert hb is not None, "HIL flag still set after returning to normal run mode"
    conn.arducopter_disarm()
