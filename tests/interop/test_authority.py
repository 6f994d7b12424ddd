"""Control authority and operator handover, end to end from the ground
stations' side (contract: the user guide's "Control authority and safety",
docs/guide/src/safety.md: the owner and the handover by
MAV_CMD_REQUEST_OPERATOR_CONTROL).

Two pymavlink ground stations talk to one `neptunus --sim` over real UDP,
each on a socket of its own: 255/190 (SYSID_MYGCS, the primary) and 254/190
(allowed through NEPT_GCS_ALLOW2 = 254, preset in params.toml). Both send
HEARTBEAT at 1 Hz. Thruster output is read from SERVO_OUTPUT_RAW (requested
at 10 Hz), ownership from CONTROL_STATUS, and every scenario's events from
DATA_DIR/events/events.jsonl.

"Stays the same" is checked over a window counted in SERVO_OUTPUT_RAW
samples after the input under test has reached the vehicle, never by
sleeping. FS_PILOT_INPUT = 1 (warn) keeps a slow machine's stick pauses
from disarming the vehicle in the middle of a handover.
"""

from __future__ import annotations

import re

import pytest

from mavhelpers import (
    ACCEPTED,
    CAP_ACCEPTS_GCS_CONTROL,
    CENTRED,
    CMD_REQUEST_OPERATOR_CONTROL,
    CONTROL_SYSTEM_MANAGER,
    CONTROL_TAKEOVER_ALLOWED,
    DENIED,
    FAILED,
    FULL_AHEAD,
    FULL_ASTERN,
    NOT_IN_CONTROL,
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

REQ = CMD_REQUEST_OPERATOR_CONTROL
PARAMS = {"NEPT_GCS_ALLOW2": 254, "FS_PILOT_INPUT": 1}
WINDOW = 15  # SERVO_OUTPUT_RAW samples (1.5 s at 10 Hz) for "stays the same"


def assert_result(ack, expected: int, what: str):
    assert ack.result == expected, f"{what}: expected COMMAND_ACK {result_name(expected)}, got {result_name(ack.result)}"


def two_stations(make_vehicle, stations, params=PARAMS):
    v = start_vehicle(make_vehicle, params)
    g255 = stations.gcs(v.udp_port, 255).connect()
    g254 = stations.gcs(v.udp_port, 254).connect()
    # Telemetry requests are open to everyone: 10 Hz thruster samples for the whole endpoint.
    assert_result(g254.set_interval(36, 10), ACCEPTED, "SET_MESSAGE_INTERVAL(SERVO_OUTPUT_RAW) from 254")
    return v, g255, g254


def arm_and_drive(g, position, what):
    """`g` claims the vehicle by stick input and arming, then drives."""
    mark = g.inbox.mark()
    g.sticks(CENTRED)
    assert_result(g.command_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1), ACCEPTED, f"arm from {g.name}")
    heartbeat_where(g.inbox, is_armed, mark, what=f"armed after {g.name}'s arm")
    mark = g.inbox.mark()
    g.sticks(position)
    pred = is_forward if position == FULL_AHEAD else is_reverse
    return g.inbox.wait("SERVO_OUTPUT_RAW", pred, 10, mark, what)


def test_non_owner_cannot_move_thrusters_or_change_state_but_may_watch(make_vehicle, stations):
    """Scenario 1: 255 arms and drives (a claim); 254's sticks and state
    changing commands are refused, its reads and telemetry requests work."""
    v, g255, g254 = two_stations(make_vehicle, stations)
    events = EventLog(v.data_dir)

    arm_and_drive(g255, FULL_AHEAD, "255 drives ahead")
    cs = control_status(g254.inbox, 255, what="CONTROL_STATUS naming the claimer 255")
    assert cs.flags & CONTROL_SYSTEM_MANAGER, f"CONTROL_STATUS.flags {cs.flags} lacks SYSTEM_MANAGER (1)"
    assert list(cs.gcs_secondary) == [0] * 10, f"single owner: gcs_secondary should be all zero, got {list(cs.gcs_secondary)}"

    # State-changing commands from the non-owner: NOT_IN_CONTROL plus a STATUSTEXT.
    mark = g254.inbox.mark()
    refused = {
        "arm": (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1),
        "DO_SET_MODE MANUAL_THRUSTERS": (mavlink.MAV_CMD_DO_SET_MODE, 1, 100),
        "motor test": (mavlink.MAV_CMD_DO_MOTOR_TEST, 1, 1, 1600, 1, 1),
        "lights on (ILLUMINATOR_ON_OFF)": (405, 1),
        "lights 50 % (DO_ILLUMINATOR_CONFIGURE)": (406, 0, 50),
        "lights servo 7 (DO_SET_SERVO)": (mavlink.MAV_CMD_DO_SET_SERVO, 7, 1700),
        "camera tilt (DO_MOUNT_CONTROL)": (mavlink.MAV_CMD_DO_MOUNT_CONTROL, 3000),
    }
    for what, (cmd, *params) in refused.items():
        assert_result(g254.command_ack(cmd, *params), NOT_IN_CONTROL, f"{what} from the non-owner 254")
    statustext(g254.inbox, r"\b254\b", mark, what="a STATUSTEXT about refusing 254's commands")
    hb = heartbeat_where(g254.inbox, lambda m: True, g254.inbox.mark(), what="a heartbeat after the refused commands")
    assert is_armed(hb) and hb.custom_mode == 19, f"still armed in MANUAL (19) after 254's refused commands; heartbeat {hb}"

    # PARAM_SET from a non-owner: answered with the unchanged value.
    before = g254.param_read("FS_GCS_TIMEOUT").param_value
    mark = g254.inbox.mark()
    g254.mav.param_set_send(1, 1, b"FS_GCS_TIMEOUT", before + 7, mavlink.MAV_PARAM_TYPE_REAL32)
    pv = g254.inbox.wait("PARAM_VALUE", lambda m: m.param_id == "FS_GCS_TIMEOUT", 10, mark, "PARAM_VALUE answering 254's PARAM_SET")
    assert pv.param_value == before, f"254's PARAM_SET FS_GCS_TIMEOUT={before + 7}: expected the unchanged {before}, got {pv.param_value}"

    # Anyone may watch: parameters, REQUEST_MESSAGE, SET_MESSAGE_INTERVAL.
    assert g254.param_read("NEPT_GCS_ALLOW2").param_value == 254
    mark = g254.inbox.mark()
    assert_result(g254.command_ack(mavlink.MAV_CMD_REQUEST_MESSAGE, 148), ACCEPTED, "REQUEST_MESSAGE(AUTOPILOT_VERSION) from 254")
    av = g254.inbox.wait("AUTOPILOT_VERSION", from_vehicle, 10, mark)
    assert av.capabilities & CAP_ACCEPTS_GCS_CONTROL, f"AUTOPILOT_VERSION.capabilities {av.capabilities:#x} lacks COMPONENT_ACCEPTS_GCS_CONTROL (524288)"
    assert_result(g254.set_interval(36, 10), ACCEPTED, "SET_MESSAGE_INTERVAL from the non-owner 254")

    # 254's sticks (full astern) change nothing while 255 drives ahead.
    mark = g254.inbox.mark()
    g254.sticks(FULL_ASTERN)
    hint = statustext(g254.inbox, r"ignoring manual_control from sysid 254", mark, timeout=15, what="the rate-limited report of 254's refused sticks")
    window = servo_samples(g254.inbox, WINDOW, hint._idx)
    assert_all(g254.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, mark), is_forward, "ahead, as 255 commands (254's sticks are astern)")
    control_status(g254.inbox, 255, window[-1]._idx, what="control still with 255 after 254's sticks")

    # Disarm is accepted from anyone: stopping is never wrong.
    g254.sticks(None)
    mark = g254.inbox.mark()
    assert_result(g254.command_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0), ACCEPTED, "disarm from the non-owner 254")
    heartbeat_where(g254.inbox, lambda m: not is_armed(m), mark, what="disarmed by 254")

    armed = events.wait("armed", {255})
    events.wait("control_claimed", {255})
    events.wait("command_rejected", {254}, after=armed)
    events.wait("disarmed", {254}, after=armed)


@pytest.mark.parametrize("accept_by", ["release", "rerequest"])
def test_request_forwarded_to_owner_who_hands_over(make_vehicle, stations, accept_by):
    """Scenarios 2 and 2b: 254 asks, 255 is asked and gives control away
    (by releasing, or by re-requesting with takeover allowed). Thrusters go
    neutral at the transfer; 254 picks up only after centring its sticks;
    from then on 255's sticks are ignored."""
    v, g255, g254 = two_stations(make_vehicle, stations)
    events = EventLog(v.data_dir)
    arm_and_drive(g255, FULL_AHEAD, "255 drives ahead")
    control_status(g254.inbox, 255)

    m254, m255 = g254.inbox.mark(), g255.inbox.mark()
    assert_result(g254.command_ack(REQ, 1, 0, 10, 254), FAILED, "254's control request while 255 owns (takeover not allowed)")
    fwd = g255.inbox.wait("COMMAND_LONG", lambda m: from_vehicle(m) and m.command == REQ, 10, m255, "the request forwarded to the owner 255")
    assert (fwd.param1, fwd.param2, fwd.param3, fwd.param4) == (1, 0, 10, 254), f"forwarded 32100 params (p1 1, p2 0, p3 10, p4 254) expected, got {fwd}"
    assert (fwd.target_system, fwd.target_component) == (255, 190), f"forwarded to 255/190 expected, got {fwd.target_system}/{fwd.target_component}"
    statustext(g255.inbox, r"GCS 254 requests control", m255, what="the owner told who asks")

    # An ACCEPTED ack from the owner only acknowledges receipt.
    g255.ack_forwarded(REQ, ACCEPTED)
    m_give = g254.inbox.mark()
    if accept_by == "release":
        assert_result(g255.command_ack(REQ, 0), ACCEPTED, "255's release")
    else:
        assert_result(g255.command_ack(REQ, 1, 1, 10, 255), ACCEPTED, "255's re-request allowing takeover")
    early = g254.inbox.select("CONTROL_STATUS", lambda m: from_vehicle(m) and m.gcs_main != 255, m254, m_give)
    assert not early, f"control moved before the owner gave it (its ACCEPTED ack only acknowledges receipt): {early}"
    control_status(g254.inbox, 254, m_give, what="CONTROL_STATUS naming 254 after 255 gave control")

    # Neutral at the transfer, although 255 still pushes ahead; 254's
    # non-centred sticks are ignored until it has centred them once.
    first_neutral = g254.inbox.wait("SERVO_OUTPUT_RAW", is_neutral, 10, m_give, "thrusters neutral at the transfer")
    g254.sticks(FULL_ASTERN)
    statustext(g254.inbox, r"centre the sticks", first_neutral._idx, what="the pick-up hint to 254")
    servo_samples(g254.inbox, WINDOW, g254.inbox.mark(), what="samples while 254 has not centred")
    assert_all(g254.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, first_neutral._idx), is_neutral, "neutral until 254 centres its sticks")
    assert is_armed(g254.inbox.select("HEARTBEAT", from_vehicle)[-1]), "the armed state is kept across the transfer"

    g254.sticks(CENTRED, repeat_now=3)  # pick-up
    m_drive = g254.inbox.mark()
    g254.sticks(FULL_ASTERN)
    first = g254.inbox.wait("SERVO_OUTPUT_RAW", is_reverse, 10, m_drive, "254 drives astern after pick-up")
    servo_samples(g254.inbox, WINDOW, first._idx)
    assert_all(g254.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, first._idx), is_reverse, "astern as 254 commands (255's sticks, ahead, are ignored)")
    g254.inbox.wait("NEPTUNUS_SIM_STATE", lambda m: m.u < -0.1, 15, m_drive, "the simulated vehicle moving astern")
    statustext(g255.inbox, r"ignoring manual_control from sysid 255", m_give, timeout=15, what="the report of 255's ignored sticks")

    events.wait("control_claimed", {255})
    req = events.wait("control_requested", {254})
    events.wait("control_forwarded", {254, 255}, after=req)
    if accept_by == "release":
        events.wait("control_released", {255}, after=req)
    granted = ("control_granted",) if accept_by == "release" else ("control_granted", "control_takeover")
    events.wait(granted, {254, 255}, after=req, cond=lambda e: e["sysid"] == 254 or "254" in e["detail"])


@pytest.mark.parametrize("refusal", ["denied", "silent"])
def test_owner_refusing_or_ignoring_a_request_keeps_control(make_vehicle, stations, refusal):
    """Scenario 3: the owner refuses (COMMAND_ACK DENIED to the forwarded
    command), or says nothing until the requester's timeout (p3 = 3 s):
    control stays with 255, which still drives; a STATUSTEXT says so. A
    release afterwards leaves the vehicle unowned: the request is over."""
    v, g255, g254 = two_stations(make_vehicle, stations)
    events = EventLog(v.data_dir)
    arm_and_drive(g255, FULL_AHEAD, "255 drives ahead")
    control_status(g254.inbox, 255)

    timeout_s = 10 if refusal == "denied" else 3
    m254, m255 = g254.inbox.mark(), g255.inbox.mark()
    assert_result(g254.command_ack(REQ, 1, 0, timeout_s, 254), FAILED, "254's control request while 255 owns")
    fwd = g255.inbox.wait("COMMAND_LONG", lambda m: from_vehicle(m) and m.command == REQ, 10, m255, "the request forwarded to 255")
    assert fwd.param4 == 254 and fwd.param3 == timeout_s, f"forwarded request should carry p3 {timeout_s}, p4 254: {fwd}"

    if refusal == "denied":
        m_refuse = g254.inbox.mark()
        g255.ack_forwarded(REQ, DENIED)
        text = g254.inbox.wait(
            "STATUSTEXT",
            lambda m: from_vehicle(m) and re.search(r"refus|denied|declin|reject|254", m.text, re.I) and "answer within" not in m.text,
            10,
            m_refuse,
            "a STATUSTEXT saying 254's request was refused",
        )
    else:
        text = statustext(g254.inbox, r"timed? ?out", m254, timeout=20, what="a STATUSTEXT saying 254's request timed out")
    refused = events.wait("control_refused", {254, 255}, timeout=20)

    after = text._idx
    cs = g254.inbox.wait("CONTROL_STATUS", from_vehicle, 10, after, "CONTROL_STATUS after the refusal")
    assert cs.gcs_main == 255, f"control stays with 255 after the {refusal} refusal; CONTROL_STATUS.gcs_main {cs.gcs_main}"
    servo_samples(g254.inbox, WINDOW, after)
    assert_all(g254.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, m254), is_forward, "ahead as 255 commands, throughout")

    m = g254.inbox.mark()
    assert_result(g255.command_ack(REQ, 0), ACCEPTED, "255's release after the request ended")
    cs = g254.inbox.wait("CONTROL_STATUS", lambda m: from_vehicle(m) and m.gcs_main != 255, 10, m, "CONTROL_STATUS after the release")
    assert cs.gcs_main == 0, f"the refused request is over: a release leaves the vehicle unowned, not 254's; gcs_main {cs.gcs_main}"

    req = events.wait("control_requested", {254})
    events.wait("control_forwarded", {254, 255}, after=req)
    assert refused["_pos"] > req["_pos"], f"control_refused should follow control_requested: {events.summary()}"
    granted = [e for e in events.read() if e["event"] in ("control_granted", "control_takeover") and e["sysid"] == 254]
    assert not granted, f"no grant to 254 expected: {granted}"


def test_primary_takes_over_with_a_warning_first(make_vehicle, stations):
    """Scenario 4: 254 owns; the primary 255 (SYSID_MYGCS) requests and is
    ACCEPTED at once. 254 is warned before CONTROL_STATUS names 255; the
    thrusters go neutral and 255 picks up after centring."""
    v, g255, g254 = two_stations(make_vehicle, stations)
    events = EventLog(v.data_dir)
    assert g255.param_read("SYSID_MYGCS").param_value == 255
    arm_and_drive(g254, FULL_ASTERN, "254 drives astern")
    control_status(g255.inbox, 254)

    m254, m255 = g254.inbox.mark(), g255.inbox.mark()
    assert_result(g255.command_ack(REQ, 1, 0, 10, 255), ACCEPTED, "the primary's request while 254 owns")
    warning = statustext(
        g254.inbox, r"taken over by primary GCS 255", m254, max_severity=mavlink.MAV_SEVERITY_WARNING,
        what="a WARNING-or-worse STATUSTEXT to 254 about the takeover",
    )
    cs = control_status(g254.inbox, 255, m254, what="CONTROL_STATUS naming the primary")
    assert warning._idx < cs._idx, (
        f"254 should be warned before control changes: STATUSTEXT at #{warning._idx}, CONTROL_STATUS gcs_main 255 at #{cs._idx}"
    )
    fwd = g254.inbox.select("COMMAND_LONG", lambda m: m.command == REQ, m254)
    assert not fwd, f"a primary takeover does not ask the owner: {fwd}"

    first_neutral = g254.inbox.wait("SERVO_OUTPUT_RAW", is_neutral, 10, m254, "thrusters neutral at the takeover")
    g255.sticks(FULL_AHEAD)  # not centred yet: ignored
    statustext(g255.inbox, r"centre the sticks", m255, what="the pick-up hint to 255")
    servo_samples(g254.inbox, WINDOW, g254.inbox.mark())
    assert_all(g254.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, first_neutral._idx), is_neutral, "neutral until 255 centres (254 still pushes astern)")
    g255.sticks(CENTRED, repeat_now=3)
    m = g254.inbox.mark()
    g255.sticks(FULL_AHEAD)
    first = g254.inbox.wait("SERVO_OUTPUT_RAW", is_forward, 10, m, "the primary drives ahead after pick-up")
    servo_samples(g254.inbox, WINDOW, first._idx)
    assert_all(g254.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, first._idx), is_forward, "ahead as 255 commands (254's astern ignored)")

    claimed = events.wait("control_claimed", {254})
    events.wait("control_takeover", {255, 254}, after=claimed, cond=lambda e: e["sysid"] == 255 or "255" in e["detail"])


def test_stations_not_allowed_never_control(make_vehicle, stations):
    """A station that is neither SYSID_MYGCS nor NEPT_GCS_ALLOWn: its control
    request is DENIED, its arm NOT_IN_CONTROL, its sticks claim nothing."""
    v = start_vehicle(make_vehicle, PARAMS)
    stranger = stations.gcs(v.udp_port, 77).connect()
    assert_result(stranger.command_ack(REQ, 1, 0, 10, 77), DENIED, "control request from the stranger 77")
    assert_result(stranger.command_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1), NOT_IN_CONTROL, "arm from the stranger 77")
    mark = stranger.inbox.mark()
    stranger.sticks(FULL_AHEAD)
    statustext(stranger.inbox, r"\b77\b", mark, timeout=15, what="a STATUSTEXT about 77's refused sticks")
    cs = stranger.inbox.wait("CONTROL_STATUS", from_vehicle, 10, stranger.inbox.mark())
    assert cs.gcs_main == 0, f"a stranger's sticks claim nothing: gcs_main {cs.gcs_main}"
    hb = heartbeat_where(stranger.inbox, lambda m: True, stranger.inbox.mark())
    assert not is_armed(hb)


def test_explicit_claim_mode_and_takeover_allowed(make_vehicle, stations):
    """NEPT_CTRL_CLAIM = 1: arming and sticks are refused until a station
    requests control. A request with p2 = 1 sets TAKEOVER_ALLOWED, and then
    another allowed station's request is granted at once."""
    v, g255, g254 = two_stations(make_vehicle, stations, dict(PARAMS, NEPT_CTRL_CLAIM=1))
    events = EventLog(v.data_dir)
    assert_result(g255.command_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1), NOT_IN_CONTROL, "arm before any request (NEPT_CTRL_CLAIM 1)")
    mark = g255.inbox.mark()
    g255.sticks(CENTRED)
    servo_samples(g255.inbox, 5, mark)
    cs = g255.inbox.wait("CONTROL_STATUS", from_vehicle, 10, g255.inbox.mark())
    assert cs.gcs_main == 0, f"sticks do not claim with NEPT_CTRL_CLAIM 1: gcs_main {cs.gcs_main}"

    mark = g254.inbox.mark()
    assert_result(g255.command_ack(REQ, 1, 1, 10, 255), ACCEPTED, "255's request (takeover allowed) while unowned")
    cs = control_status(g254.inbox, 255, mark)
    assert cs.flags & CONTROL_TAKEOVER_ALLOWED, f"CONTROL_STATUS.flags {cs.flags} should have TAKEOVER_ALLOWED (2)"
    assert_result(g255.command_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1), ACCEPTED, "arm by the owner")

    mark = g254.inbox.mark()
    assert_result(g254.command_ack(REQ, 1, 0, 10, 254), ACCEPTED, "254's request while takeover is allowed")
    control_status(g254.inbox, 254, mark)
    granted = events.wait("control_granted", {255})
    events.wait(("control_granted", "control_takeover"), {254, 255}, after=granted, cond=lambda e: e["sysid"] == 254 or "254" in e["detail"])
