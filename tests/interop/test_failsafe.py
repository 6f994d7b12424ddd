"""Failsafes, end to end (contract: the user guide's "Control authority
and safety", docs/guide/src/safety.md: the failsafes and the owner's signs
of life).

The owner whose process dies is a real separate process: a small pymavlink
script that arms, drives and heartbeats until it is killed with SIGKILL, so
nothing in the test process can keep it "alive" by accident. A second
ground station (254, allowed through NEPT_GCS_ALLOW2) stays connected and
heartbeating: its heartbeats must not count as the owner's life. Bounds are
deadlines (FS_GCS_TIMEOUT 2 s plus generous slack), never measured.
"""

from __future__ import annotations

import os
import re
import selectors
import signal
import subprocess
import sys

import pytest

from mavhelpers import (
    ACCEPTED,
    CENTRED,
    FULL_AHEAD,
    FULL_ASTERN,
    Deadline,
    EventLog,
    assert_all,
    control_status,
    from_vehicle,
    heartbeat_where,
    is_armed,
    is_forward,
    is_neutral,
    is_reverse,
    mavlink,
    result_name,
    servo_samples,
    start_vehicle,
    statustext,
)

CRITICAL = mavlink.MAV_STATE_CRITICAL
FAILSAFE_DEADLINE_S = 15.0  # FS_GCS_TIMEOUT (2 s) + slack for a shared, noisy machine
WINDOW = 15  # SERVO_OUTPUT_RAW samples

# The owner GCS as its own process: sysid 255/190, heartbeat at 1 Hz,
# MANUAL_CONTROL at 20 Hz (centred until its arm is acknowledged, then full
# ahead), forever. Prints "ARM_ACK <result>" once.
OWNER_SCRIPT = r"""
import os, sys, time
os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil
conn = mavutil.mavlink_connection("udpout:127.0.0.1:%s" % sys.argv[1], source_system=255, source_component=190)
m = conn.mav
def beat():
    m.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavutil.mavlink.MAV_STATE_ACTIVE)
beat()
m.manual_control_send(1, 0, 0, 500, 0, 0)
m.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
acked = False
next_beat = time.monotonic() + 1.0
while True:
    now = time.monotonic()
    if now >= next_beat:
        beat()
        next_beat = now + 1.0
    while True:
        msg = conn.recv_match(type="COMMAND_ACK", blocking=False)
        if msg is None:
            break
        if msg.command == 400 and not acked:
            acked = True
            print("ARM_ACK %d" % msg.result, flush=True)
    m.manual_control_send(1, 1000 if acked else 0, 0, 500, 0, 0)
    time.sleep(0.05)  # the stick send rate (20 Hz)
"""


class OwnerProcess:
    def __init__(self, vehicle_port: int, log_path):
        self.log = open(log_path, "wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-c", OWNER_SCRIPT, str(vehicle_port)],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self.log,
            env=dict(os.environ, MAVLINK20="1"),
        )
        self.log_path = log_path

    def read_line(self, timeout: float, what: str) -> str:
        dl = Deadline(timeout)
        buf = b""
        with selectors.DefaultSelector() as sel:
            sel.register(self.proc.stdout, selectors.EVENT_READ)
            while not dl.expired():
                if not sel.select(min(dl.left(), 0.5)):
                    continue
                chunk = os.read(self.proc.stdout.fileno(), 4096)
                if not chunk:
                    break  # the process exited
                buf += chunk
                if b"\n" in buf:
                    return buf.split(b"\n", 1)[0].decode()
        self.log.flush()
        raise AssertionError(
            f"owner process: expected {what} within {timeout} s; stdout {buf!r}, exit code {self.proc.poll()}, "
            f"stderr: {self.log_path.read_text(errors='replace')[-2000:]}"
        )

    def kill(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
        if not self.log.closed:
            self.log.close()


@pytest.fixture
def owner_process(tmp_path):
    """Starts the owner GCS process for a vehicle port; killed at teardown whatever happened."""
    started: list[OwnerProcess] = []

    def start(vehicle_port: int) -> OwnerProcess:
        p = OwnerProcess(vehicle_port, tmp_path / f"owner-gcs-{len(started) + 1}-stderr.txt")
        started.append(p)
        return p

    yield start
    for p in started:
        p.kill()


def owner_arms_and_drives(v, watcher, owner_process) -> OwnerProcess:
    mark = watcher.inbox.mark()
    owner = owner_process(v.udp_port)
    line = owner.read_line(20, "the arm acknowledged")
    assert line == f"ARM_ACK {ACCEPTED}", f"the owner's arm: expected ARM_ACK {ACCEPTED} (ACCEPTED), got {line!r}"
    heartbeat_where(watcher.inbox, is_armed, mark, what="armed by the owner process")
    watcher.inbox.wait("SERVO_OUTPUT_RAW", is_forward, 10, mark, "the owner process drives ahead")
    control_status(watcher.inbox, 255, mark, what="CONTROL_STATUS naming the owner process 255")
    return owner


def gcs_lost_event(e) -> bool:
    return (e["sysid"] == 255 or "255" in (e["detail"] or "")) and re.search(r"gcs|heartbeat", e["detail"] or "", re.I) is not None


def test_owner_process_killed_gcs_failsafe_disarms(make_vehicle, stations, owner_process):
    """Scenario 5: the owner's process dies (SIGKILL) → within FS_GCS_TIMEOUT
    plus slack: disarmed, thrusters neutral, a failsafe STATUSTEXT, no owner
    in CONTROL_STATUS; the event log has failsafe_raised then disarmed.
    FS_PILOT_INPUT 0 so that only the GCS failsafe can act."""
    v = start_vehicle(make_vehicle, {"NEPT_GCS_ALLOW2": 254, "FS_GCS_TIMEOUT": 2.0, "FS_PILOT_INPUT": 0})
    events = EventLog(v.data_dir)
    watcher = stations.gcs(v.udp_port, 254, name="watcher 254").connect()  # alive throughout
    assert watcher.set_interval(36, 10).result == ACCEPTED
    owner = owner_arms_and_drives(v, watcher, owner_process)

    mark = watcher.inbox.mark()
    owner.kill()
    hb = heartbeat_where(watcher.inbox, lambda m: not is_armed(m), mark, FAILSAFE_DEADLINE_S, "disarmed by the GCS failsafe")
    text = statustext(watcher.inbox, r"failsafe: GCS 255 heartbeat lost", mark, FAILSAFE_DEADLINE_S, what="the GCS failsafe announced")
    watcher.inbox.wait("SERVO_OUTPUT_RAW", is_neutral, FAILSAFE_DEADLINE_S, mark, "thrusters neutral after the owner died")
    servo_samples(watcher.inbox, WINDOW, hb._idx)
    assert_all(watcher.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, hb._idx), is_neutral, "neutral once disarmed")
    control_status(watcher.inbox, 0, mark, FAILSAFE_DEADLINE_S, "CONTROL_STATUS with no owner after the owner died")
    assert text.severity <= mavlink.MAV_SEVERITY_WARNING, f"the failsafe STATUSTEXT should be WARNING or worse: {text}"

    armed = events.wait("armed", {255})
    raised = events.wait("failsafe_raised", {255, None}, after=armed, cond=gcs_lost_event, what="(the GCS failsafe for 255)")
    events.wait("disarmed", None, after=raised)
    events.wait("control_lost", {255}, after=armed)


def test_gcs_failsafe_warn_shows_critical_until_another_station_takes_control(make_vehicle, stations, owner_process):
    """FS_GCS_ENABLE 1 (warn): the raised failsafe stays visible — HEARTBEAT
    system_status CRITICAL, still armed, no owner — until an allowed station
    owns the vehicle with fresh life. Taking an armed unowned vehicle needs
    pick-up (centred sticks once); then the failsafe clears."""
    v = start_vehicle(make_vehicle, {"NEPT_GCS_ALLOW2": 254, "FS_GCS_TIMEOUT": 2.0, "FS_GCS_ENABLE": 1, "FS_PILOT_INPUT": 0})
    events = EventLog(v.data_dir)
    g254 = stations.gcs(v.udp_port, 254).connect()
    assert g254.set_interval(36, 10).result == ACCEPTED
    owner = owner_arms_and_drives(v, g254, owner_process)

    mark = g254.inbox.mark()
    owner.kill()
    hb = heartbeat_where(g254.inbox, lambda m: m.system_status == CRITICAL, mark, FAILSAFE_DEADLINE_S, "HEARTBEAT MAV_STATE_CRITICAL after the owner died")
    assert is_armed(hb), f"FS_GCS_ENABLE 1 only warns: still armed expected, heartbeat {hb}"
    statustext(g254.inbox, r"failsafe: GCS 255 heartbeat lost", mark, FAILSAFE_DEADLINE_S)
    control_status(g254.inbox, 0, mark, FAILSAFE_DEADLINE_S)
    g254.inbox.wait("SERVO_OUTPUT_RAW", is_neutral, FAILSAFE_DEADLINE_S, mark, "thrusters neutral without the owner's input")
    later = heartbeat_where(g254.inbox, lambda m: True, g254.inbox.mark(), what="a later heartbeat")
    assert later.system_status == CRITICAL and is_armed(later), f"the failsafe stays raised while nobody owns the vehicle: {later}"

    # 254 takes the armed, unowned vehicle: its sticks count only after centring.
    m = g254.inbox.mark()
    g254.sticks(FULL_ASTERN)
    statustext(g254.inbox, r"centre the sticks", m, what="the pick-up hint for an armed vehicle")
    servo_samples(g254.inbox, WINDOW, g254.inbox.mark())
    assert_all(g254.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, m), is_neutral, "neutral until 254 centres its sticks")
    g254.sticks(CENTRED, repeat_now=3)
    m = g254.inbox.mark()
    g254.sticks(FULL_ASTERN)
    g254.inbox.wait("SERVO_OUTPUT_RAW", is_reverse, 10, m, "254 drives astern after pick-up")
    control_status(g254.inbox, 254, m)
    statustext(g254.inbox, r"failsafe cleared", mark, what="the failsafe cleared once 254 owns the vehicle")
    hb = heartbeat_where(g254.inbox, lambda m: m.system_status != CRITICAL, m, what="a heartbeat no longer CRITICAL")
    assert is_armed(hb), f"still armed after the clear: {hb}"

    raised = events.wait("failsafe_raised", {255, None}, cond=gcs_lost_event)
    events.wait("failsafe_cleared", None, after=raised)
    events.wait("control_claimed", {254}, after=raised)
    disarms = [e for e in events.read() if e["event"] == "disarmed"]
    assert not disarms, f"FS_GCS_ENABLE 1 never disarms: {disarms}"


def test_pilot_input_lost_neutral_then_disarm(make_vehicle, stations):
    """Scenario 6: the owner keeps heartbeating but its sticks stop →
    thrusters neutral and, with FS_PILOT_INPUT 2, disarm after
    FS_PILOT_TIMEOUT (1 s). The GCS failsafe does not act: the owner is alive
    and keeps control."""
    v = start_vehicle(make_vehicle, {"NEPT_GCS_ALLOW2": 254, "FS_PILOT_INPUT": 2, "FS_PILOT_TIMEOUT": 1.0})
    events = EventLog(v.data_dir)
    g255 = stations.gcs(v.udp_port, 255).connect()
    assert g255.set_interval(36, 10).result == ACCEPTED
    g255.sticks(CENTRED)
    ack = g255.command_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == ACCEPTED, f"arm: expected ACCEPTED, got {result_name(ack.result)}"
    m = g255.inbox.mark()
    g255.sticks(FULL_AHEAD)
    g255.inbox.wait("SERVO_OUTPUT_RAW", is_forward, 10, m, "255 drives ahead")

    mark = g255.inbox.mark()
    g255.sticks(None)  # the joystick goes quiet; heartbeats go on
    g255.inbox.wait("SERVO_OUTPUT_RAW", is_neutral, FAILSAFE_DEADLINE_S, mark, "thrusters neutral when pilot input stops")
    hb = heartbeat_where(g255.inbox, lambda m: not is_armed(m), mark, FAILSAFE_DEADLINE_S, "disarmed by the pilot-input failsafe")
    statustext(g255.inbox, r"failsafe: lost manual control", mark, FAILSAFE_DEADLINE_S)
    cs = g255.inbox.wait("CONTROL_STATUS", from_vehicle, 10, hb._idx, "CONTROL_STATUS after the disarm")
    assert cs.gcs_main == 255, f"the owner is alive: it keeps control after a pilot-input failsafe; gcs_main {cs.gcs_main}"
    gcs_texts = [t for t in g255.inbox.texts(mark) if re.search(r"heartbeat lost", t, re.I)]
    assert not gcs_texts, f"the GCS failsafe must not act while the owner heartbeats: {gcs_texts}"

    armed = events.wait("armed", {255})
    raised = events.wait(
        "failsafe_raised", {255, None}, after=armed, cond=lambda e: re.search(r"pilot|manual", e["detail"] or "", re.I) is not None,
        what="(the pilot-input failsafe)",
    )
    events.wait("disarmed", None, after=raised)
