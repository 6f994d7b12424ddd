"""MAVLink 2 message signing, end to end (contract: the user guide's
docs/guide/src/security.md, "Message signing").

The key is set the way ground stations do it: SETUP_SIGNING (key =
SHA-256 of a passphrase, as QGroundControl and MAVProxy derive it), sent
over an endpoint marked trusted (`tcpin:…?trusted`). Signed stations use
pymavlink's own signing (`setup_signing(key, sign_outgoing=True)`); the
vehicle's signatures and timestamps are read from the raw frames.
"""

from __future__ import annotations

import base64
import hashlib
import socket
import stat

from pymavlink import mavutil

from mavhelpers import (
    ACCEPTED,
    CENTRED,
    DENIED,
    FULL_AHEAD,
    FULL_ASTERN,
    Deadline,
    EventLog,
    assert_all,
    free_tcp_port,
    from_vehicle,
    heartbeat_where,
    is_armed,
    is_forward,
    is_signed,
    mavlink,
    result_name,
    servo_samples,
    signature_timestamp,
    signature_valid,
    signing_timestamp,
    start_vehicle,
    statustext,
    wait_for,
)

KEY = hashlib.sha256(b"neptunus interop passphrase").digest()
OTHER_KEY = hashlib.sha256(b"somebody else's passphrase").digest()
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
ONE_DAY_S = 86400


def assert_result(ack, expected: int, what: str):
    assert ack.result == expected, f"{what}: expected COMMAND_ACK {result_name(expected)}, got {result_name(ack.result)}"


def send_setup_signing(conn, key: bytes, initial_timestamp: int) -> None:
    """SETUP_SIGNING to the vehicle (1/1) as QGroundControl sends it: twice, unacknowledged."""
    for _ in range(2):
        conn.mav.setup_signing_send(1, 1, key, initial_timestamp)


def tcp_gcs(tcp_port: int):
    """A pymavlink GCS 255/190 on a TCP endpoint of the vehicle (the caller closes it)."""
    conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{tcp_port}", source_system=255, source_component=190, retries=3)
    conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
    return conn


def set_key_over_trusted_link(v, tcp_port: int, key: bytes, initial_timestamp: int) -> None:
    conn = tcp_gcs(tcp_port)
    try:
        send_setup_signing(conn, key, initial_timestamp)
        key_file = v.data_dir / "signing.key"
        wait_for(key_file.exists, 15, f"{key_file} written after SETUP_SIGNING on the trusted endpoint")
    finally:
        conn.close()


def signed_gcs(stations, port: int, sysid: int = 255, name: str | None = None):
    g = stations.gcs(port, sysid, name=name or f"signed {sysid}")
    g.conn.setup_signing(KEY, sign_outgoing=True, initial_timestamp=signing_timestamp(), link_id=1)
    return g


def assert_vehicle_signs(inbox, key: bytes, since: int, what: str, n: int = 10):
    frames = inbox.wait_count(None, n, from_vehicle, 15, since, f"{n} frames from the vehicle ({what})")
    bad = [(m._idx, m.get_type(), "unsigned" if not is_signed(m) else "bad signature") for m in frames if not signature_valid(m, key)]
    assert not bad, f"{what}: every frame from the vehicle should carry a valid signature with the key; not so: {bad}"


def secret_forms(key: bytes) -> dict:
    return {
        "raw bytes": key,
        "hex": key.hex().encode(),
        "HEX": key.hex().upper().encode(),
        "base64": base64.b64encode(key),
        "byte list": str(list(key)).encode(),
    }


def assert_key_absent(paths, key: bytes):
    for path in paths:
        data = path.read_bytes()
        for form, needle in secret_forms(key).items():
            assert needle not in data, f"the signing key ({form}) appears in {path}"


def test_signed_station_drives_unsigned_and_replayed_frames_are_refused(make_vehicle, stations):
    """Key set over the trusted TCP endpoint → the vehicle signs everything;
    a signed 255 arms and drives; unsigned stations (254, and 255 itself on
    another socket) get DENIED and their sticks move nothing; a replayed
    signed arm does not re-arm; SETUP_SIGNING over UDP (untrusted) leaves the
    key unchanged; the key file is 0600 and the key is in no log."""
    tcp_port = free_tcp_port()
    v = start_vehicle(make_vehicle, {"NEPT_GCS_ALLOW2": 254, "FS_PILOT_INPUT": 1}, [f"tcpin:127.0.0.1:{tcp_port}?trusted"])
    events = EventLog(v.data_dir)
    unsigned254 = stations.gcs(v.udp_port, 254, name="unsigned 254").connect()
    unsigned255 = stations.gcs(v.udp_port, 255, name="unsigned 255").connect()

    mark = unsigned254.inbox.mark()
    set_key_over_trusted_link(v, tcp_port, KEY, signing_timestamp())
    key_file = v.data_dir / "signing.key"
    mode = stat.S_IMODE(key_file.stat().st_mode)
    assert mode == 0o600, f"{key_file} should have mode 0600, has {mode:o}"
    set_event = events.wait("signing_key_set", {255})
    first_signed = unsigned254.inbox.wait(None, lambda m: from_vehicle(m) and is_signed(m), 15, mark, "the vehicle signing its frames")
    assert_vehicle_signs(unsigned254.inbox, KEY, first_signed._idx, "after SETUP_SIGNING")

    # Unsigned stations may watch, not control.
    for g in (unsigned254, unsigned255):
        assert_result(g.command_ack(ARM, 1), DENIED, f"unsigned arm from {g.name}")
    assert unsigned255.param_read("NEPT_GCS_ALLOW2").param_value == 254, "unsigned stations may still read parameters"
    hb = heartbeat_where(unsigned254.inbox, lambda m: True, unsigned254.inbox.mark())
    assert not is_armed(hb), f"unsigned arms must not arm: {hb}"

    # The signed 255 arms and drives.
    s255 = signed_gcs(stations, v.udp_port).connect()
    assert_result(s255.set_interval(36, 10), ACCEPTED, "signed SET_MESSAGE_INTERVAL")
    s255.sticks(CENTRED)
    assert_result(s255.command_ack(ARM, 1), ACCEPTED, "signed arm from 255")
    m = s255.inbox.mark()
    s255.sticks(FULL_AHEAD)
    s255.inbox.wait("SERVO_OUTPUT_RAW", is_forward, 10, m, "the signed 255 drives ahead")

    # Unsigned sticks (same sysid 255, another socket) move nothing; an unsigned disarm is refused too.
    m = s255.inbox.mark()
    unsigned255.sticks(FULL_ASTERN)
    servo_samples(s255.inbox, 2 * 15, m, what="samples while unsigned sticks push astern")
    assert_all(s255.inbox.select("SERVO_OUTPUT_RAW", from_vehicle, m), is_forward, "ahead as the signed 255 commands")
    unsigned255.sticks(None)
    assert_result(unsigned255.command_ack(ARM, 0), DENIED, "unsigned disarm while signing is on")
    hb = heartbeat_where(s255.inbox, lambda m: True, s255.inbox.mark())
    assert is_armed(hb), f"an unsigned disarm must not disarm: {hb}"

    # SETUP_SIGNING on an untrusted endpoint (UDP), even signed: ignored with a STATUSTEXT.
    key_before = key_file.read_bytes()
    m = s255.inbox.mark()
    send_setup_signing(s255.conn, OTHER_KEY, signing_timestamp())
    note = statustext(s255.inbox, r"signing", m, what="a STATUSTEXT saying SETUP_SIGNING was ignored on an untrusted endpoint")
    assert key_file.read_bytes() == key_before, "SETUP_SIGNING on an untrusted endpoint changed the key file"
    events.wait("signing_refused", {255}, after=set_event)
    assert_vehicle_signs(s255.inbox, KEY, note._idx, "after the refused SETUP_SIGNING (still the first key)")

    # Replay: the bytes of a signed arm, sent again after a disarm, do not re-arm.
    s255.sticks(None)
    m = s255.inbox.mark()
    assert_result(s255.command_ack(ARM, 0), ACCEPTED, "signed disarm")
    heartbeat_where(s255.inbox, lambda m: not is_armed(m), m, what="disarmed")
    m = s255.inbox.mark()
    arm_msg = s255.mav.command_long_encode(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    s255.mav.send(arm_msg)
    replay = bytes(arm_msg.get_msgbuf())
    assert replay[0] == 0xFD and replay[2] & 1, "the captured arm frame should be a signed MAVLink 2 frame"
    ack = s255.inbox.wait("COMMAND_ACK", lambda a: from_vehicle(a) and a.command == ARM, 10, m, "ACK of the genuine signed arm")
    assert_result(ack, ACCEPTED, "the genuine signed arm")
    heartbeat_where(s255.inbox, is_armed, m, what="armed by the genuine frame")
    m = s255.inbox.mark()
    assert_result(s255.command_ack(ARM, 0), ACCEPTED, "signed disarm before the replay")
    heartbeat_where(s255.inbox, lambda m: not is_armed(m), m, what="disarmed before the replay")

    m_replay = s255.inbox.mark()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as attacker:
        attacker.sendto(replay, ("127.0.0.1", v.udp_port))
    # A later genuine command is answered (the replay neither armed nor broke the stream);
    # the heartbeat after its answer shows the vehicle still disarmed.
    later = s255.command_ack(mavlink.MAV_CMD_REQUEST_MESSAGE, 148)
    assert_result(later, ACCEPTED, "a signed REQUEST_MESSAGE after the replay")
    hb = heartbeat_where(s255.inbox, lambda m: True, later._idx, what="a heartbeat after the replay was processed")
    armed_again = s255.inbox.select("HEARTBEAT", lambda m: from_vehicle(m) and is_armed(m), m_replay)
    assert not armed_again and not is_armed(hb), f"the replayed arm re-armed the vehicle: {armed_again or hb}"
    events.wait("signature_rejected", {255, None}, after=set_event)

    v.stop()  # flush the logs
    tlogs = sorted((v.data_dir / "tlogs").glob("*"))
    assert tlogs and any(p.stat().st_size > 0 for p in tlogs), f"expected a non-empty tlog in {v.data_dir / 'tlogs'}"
    logs = tlogs + sorted((v.data_dir / "events").glob("*")) + [v.data_dir / "params.toml"]
    assert_key_absent([p for p in logs if p.is_file()] + v.stderr_paths, KEY)


def test_setup_signing_on_untrusted_endpoints_is_ignored(make_vehicle, stations):
    """Without a trusted endpoint, SETUP_SIGNING over UDP or plain TCP is
    ignored with a STATUSTEXT: no key file, the vehicle does not sign, and
    unsigned control still works."""
    tcp_port = free_tcp_port()
    v = start_vehicle(make_vehicle, {}, [f"tcpin:127.0.0.1:{tcp_port}"])
    events = EventLog(v.data_dir)
    g = stations.gcs(v.udp_port, 255).connect()

    m = g.inbox.mark()
    send_setup_signing(g.conn, KEY, signing_timestamp())
    note = statustext(g.inbox, r"signing", m, what="a STATUSTEXT saying SETUP_SIGNING over UDP was ignored")
    first = events.wait("signing_refused", {255})
    conn = tcp_gcs(tcp_port)
    try:
        send_setup_signing(conn, KEY, signing_timestamp())
        events.wait("signing_refused", {255}, after=first, what="(SETUP_SIGNING over plain TCP)")
    finally:
        conn.close()

    assert not (v.data_dir / "signing.key").exists(), "SETUP_SIGNING on an untrusted endpoint wrote a key"
    frames = g.inbox.wait_count(None, 10, from_vehicle, 15, note._idx)
    signed = [(x._idx, x.get_type()) for x in frames if is_signed(x)]
    assert not signed, f"signing must stay off: signed frames {signed}"
    assert_result(g.command_ack(ARM, 1), ACCEPTED, "unsigned arm with signing off")
    keys = [e for e in events.read() if e["event"] == "signing_key_set"]
    assert not keys, f"no key was set: {keys}"


def test_unsigned_heartbeats_do_not_keep_a_signed_owner_alive(make_vehicle, stations):
    """With signing on, the owner's life is its signed frames: an unsigned
    station with the same sysid heartbeating and pushing sticks does not
    stop the GCS failsafe when the signed owner goes silent."""
    tcp_port = free_tcp_port()
    v = start_vehicle(
        make_vehicle, {"FS_GCS_TIMEOUT": 2.0, "FS_PILOT_INPUT": 0}, [f"tcpin:127.0.0.1:{tcp_port}?trusted"]
    )
    events = EventLog(v.data_dir)
    set_key_over_trusted_link(v, tcp_port, KEY, signing_timestamp())
    s255 = signed_gcs(stations, v.udp_port).connect()
    assert_result(s255.set_interval(36, 10), ACCEPTED, "signed SET_MESSAGE_INTERVAL")
    s255.sticks(CENTRED)
    assert_result(s255.command_ack(ARM, 1), ACCEPTED, "signed arm")
    m = s255.inbox.mark()
    s255.sticks(FULL_AHEAD)
    s255.inbox.wait("SERVO_OUTPUT_RAW", is_forward, 10, m, "the signed owner drives")
    impostor = stations.gcs(v.udp_port, 255, name="unsigned 255").connect()
    impostor.sticks(FULL_AHEAD)

    mark = impostor.inbox.mark()
    s255.sticks(None)
    s255.stop_heartbeat()
    statustext(impostor.inbox, r"failsafe: GCS 255 heartbeat lost", mark, 15, what="the GCS failsafe despite unsigned heartbeats from 255")
    heartbeat_where(impostor.inbox, lambda m: not is_armed(m), mark, 15, "disarmed by the GCS failsafe")
    events.wait("failsafe_raised", {255, None}, cond=lambda e: e["sysid"] == 255 or "255" in (e["detail"] or ""))


class RawObserver:
    """A UDP socket the vehicle sends to, read synchronously: after the
    vehicle has stopped, `drain()` returns everything it sent before."""

    def __init__(self, dialect):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.url = f"udpout:127.0.0.1:{self.sock.getsockname()[1]}"
        self.parser = dialect.MAVLink(None)
        self.parser.robust_parsing = True

    def _parse(self, data: bytes) -> list:
        return [m for m in (self.parser.parse_buffer(data) or []) if m.get_type() != "BAD_DATA" and from_vehicle(m)]

    def read_until(self, enough, timeout: float, what: str) -> list:
        dl = Deadline(timeout)
        got: list = []
        while not enough(got):
            if dl.expired():
                raise AssertionError(f"expected {what} within {timeout} s; got {len(got)} frames, signed: {sum(map(is_signed, got))}")
            self.sock.settimeout(max(0.01, min(dl.left(), 0.5)))
            try:
                got += self._parse(self.sock.recv(65536))
            except socket.timeout:
                pass
        return got

    def drain(self) -> list:
        got: list = []
        self.sock.setblocking(False)
        try:
            while True:
                got += self._parse(self.sock.recv(65536))
        except BlockingIOError:
            pass
        finally:
            self.sock.setblocking(True)
        return got

    def close(self):
        self.sock.close()


def test_signing_timestamps_never_go_backwards_across_restart(make_vehicle, vehicle_dialect):
    """SETUP_SIGNING sets initial_timestamp one day ahead of the wall clock;
    the vehicle's timestamps follow it, strictly increasing; after a restart
    the first signed frames carry timestamps beyond the last one sent before
    (the persisted reservation), not the wall clock's."""
    obs = RawObserver(vehicle_dialect)
    try:
        tcp_port = free_tcp_port()
        v = start_vehicle(make_vehicle, {}, [f"tcpin:127.0.0.1:{tcp_port}?trusted", obs.url])
        ahead = signing_timestamp(ONE_DAY_S)
        set_key_over_trusted_link(v, tcp_port, KEY, ahead)

        def n_signed(n):
            return lambda frames: sum(map(is_signed, frames)) >= n

        before = obs.read_until(n_signed(30), 20, "30 signed frames after SETUP_SIGNING")
        v.stop()
        before += obs.drain()
        stamps = [signature_timestamp(m) for m in before if is_signed(m)]
        bad = [(m.get_type(), "unsigned" if not is_signed(m) else "bad signature") for m in before if is_signed(m) and not signature_valid(m, KEY)]
        assert not bad, f"frames before the restart not validly signed: {bad}"
        assert all(t >= ahead for t in stamps), f"timestamps should follow initial_timestamp {ahead} (one day ahead); got min {min(stamps)}"
        assert all(b > a for a, b in zip(stamps, stamps[1:])), f"timestamps should strictly increase: {stamps}"
        assert (v.data_dir / "signing.timestamp").exists(), "the signing timestamp reservation file DATA_DIR/signing.timestamp"
        last_before = stamps[-1]

        v.start()
        after = obs.read_until(n_signed(10), 20, "10 signed frames after the restart")
        unsigned = [m.get_type() for m in after if not is_signed(m)]
        assert not unsigned, f"after the restart every frame should be signed (the key persists); unsigned: {unsigned}"
        invalid = [m.get_type() for m in after if not signature_valid(m, KEY)]
        assert not invalid, f"after the restart frames should be signed with the same key; invalid: {invalid}"
        stamps_after = [signature_timestamp(m) for m in after]
        assert stamps_after[0] > last_before, (
            f"the first signed frame after the restart has timestamp {stamps_after[0]}, not beyond the last one before "
            f"({last_before}); the wall clock is at {signing_timestamp()}"
        )
        assert all(b > a for a, b in zip(stamps_after, stamps_after[1:])), f"timestamps after the restart should strictly increase: {stamps_after}"
    finally:
        obs.close()
