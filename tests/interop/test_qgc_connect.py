"""QGroundControl's connect sequence over UDP, replayed with pymavlink as
(255, 190): every request answered, none left to time out."""

from __future__ import annotations

import struct

import pytest
from pymavlink import mavutil

from mavhelpers import Deadline, GcsHeartbeat, from_vehicle, mavlink

QGC_SYSID, QGC_COMPID = 255, 190
MSG_AUTOPILOT_VERSION = 148
MSG_AVAILABLE_MODES = 435
MSG_COMPONENT_INFORMATION = 395
MSG_COMPONENT_METADATA = 397
FTP_TERMINATE_SESSION = 1
FTP_OPEN_FILE_RO = 4
FTP_BURST_READ_FILE = 15
FTP_ACK = 128
FTP_NAK = 129
FTP_ERR_FILE_NOT_FOUND = 10


class Qgc:
    """A QGC-shaped client: records everything it receives from the vehicle,
    so that duplicates and strays are visible at the end."""

    def ftp(self, opcode: int, seq: int, path: bytes = b"", session: int = 0, offset: int = 0, size: int | None = None, timeout: float = 3.0):
        """One FTP request (QGC's FTPManager framing); the reply to it."""
        n = len(path) if size is None else size
        payload = struct.pack("<HBBBBBBI", seq, session, opcode, n, 0, 0, 0, offset) + path
        self.conn.mav.file_transfer_protocol_send(0, 1, 1, list(payload.ljust(251, b"\0")))
        return self.wait(
            lambda m: m.get_type() == "FILE_TRANSFER_PROTOCOL"
            and struct.unpack_from("<H", bytes(m.payload))[0] == (seq + 1) % 65536,
            timeout,
        )

    def ftp_get(self, path: str) -> bytes:
        """A file as QGC's FTPManager downloads it: OpenFileRO, then
        BurstReadFile until the burst that ends short, then TerminateSession."""
        ack = self.ftp(FTP_OPEN_FILE_RO, 100, path=path.encode())
        assert ack is not None, f"no reply to OpenFileRO {path}"
        data = bytes(ack.payload)
        _seq, session, opcode, size = struct.unpack_from("<HBBB", data)
        assert opcode == FTP_ACK and size == 4, f"OpenFileRO {path}: opcode {opcode}"
        length = struct.unpack_from("<I", data, 12)[0]
        out = bytearray()
        seq = 200
        while len(out) < length:
            payload = struct.pack("<HBBBBBBI", seq, session, FTP_BURST_READ_FILE, 0, 0, 0, 0, len(out))
            self.conn.mav.file_transfer_protocol_send(0, 1, 1, list(payload.ljust(251, b"\0")))
            dl = Deadline(3.0)
            complete = False
            while not complete and not dl.expired():
                m = self.wait(lambda m: m.get_type() == "FILE_TRANSFER_PROTOCOL", dl.left())
                if m is None:
                    break
                d = bytes(m.payload)
                r_seq, _s, opcode, size, _req, burst_complete, _pad, offset = struct.unpack_from("<HBBBBBBI", d)
                assert opcode == FTP_ACK, f"burst read NAK {d[12]}"
                assert offset == len(out), "a burst packet out of order on loopback"
                out += d[12 : 12 + size]
                complete = burst_complete == 1
                seq = r_seq + 1
            assert complete, "a burst that never completed"
        assert self.ftp(FTP_TERMINATE_SESSION, seq, session=session) is not None
        return bytes(out)

    def __init__(self, conn):
        self.conn = conn
        self.received = []
        self.commands_sent = []

    def pump(self, timeout: float):
        m = self.conn.recv_match(blocking=True, timeout=timeout)
        # A message pymavlink's dialect lacks comes without its header
        # (UNKNOWN_<id>, the frame in `data`): its sender is read there.
        unknown = m is not None and m.get_type().startswith("UNKNOWN_") and bytes(m.data)[5:7] == b"\x01\x01"
        if m is not None and m.get_type() != "BAD_DATA" and (unknown or from_vehicle(m)):
            self.received.append(m)
            return m
        return None

    def wait(self, cond, timeout: float):
        dl = Deadline(timeout)
        while not dl.expired():
            m = self.pump(min(dl.left(), 0.5))
            if m is not None and cond(m):
                return m
        return None

    def command_long(self, command: int, *params: float):
        p = list(params) + [0.0] * (7 - len(params))
        self.commands_sent.append(command)
        self.conn.mav.command_long_send(1, 1, command, 0, *p)

    def acks(self, command: int | None = None):
        return [m for m in self.received if m.get_type() == "COMMAND_ACK" and (command is None or m.command == command)]

    def request_message(self, msg_id: int, param2: float = 0.0, timeout: float = 3.0):
        """REQUEST_MESSAGE; returns the ACK (waiting for it)."""
        before = len(self.acks(mavlink.MAV_CMD_REQUEST_MESSAGE))
        self.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, msg_id, param2)
        dl = Deadline(timeout)
        while not dl.expired() and len(self.acks(mavlink.MAV_CMD_REQUEST_MESSAGE)) == before:
            self.pump(min(dl.left(), 0.5))
        acks = self.acks(mavlink.MAV_CMD_REQUEST_MESSAGE)
        assert len(acks) > before, f"no COMMAND_ACK for REQUEST_MESSAGE({msg_id}) within {timeout} s"
        return acks[before]


@pytest.fixture
def qgc(udp_vehicle):
    conn = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{udp_vehicle.udp_port}", source_system=QGC_SYSID, source_component=QGC_COMPID
    )
    with GcsHeartbeat(conn):
        client = Qgc(conn)
        hb = client.wait(lambda m: m.get_type() == "HEARTBEAT", 5.0)
        assert hb is not None, "no HEARTBEAT from (1, 1) after our first GCS heartbeat"
        assert hb.type == mavlink.MAV_TYPE_SUBMARINE
        assert hb.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        yield client
    conn.close()


def test_qgc_connect_sequence(qgc):
    # 1. AUTOPILOT_VERSION
    ack = qgc.request_message(MSG_AUTOPILOT_VERSION)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    av = qgc.wait(lambda m: m.get_type() == "AUTOPILOT_VERSION", 3.0)
    assert av is not None, "REQUEST_MESSAGE(AUTOPILOT_VERSION) accepted but no AUTOPILOT_VERSION"
    assert av.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert av.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
    assert not av.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    assert not av.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY

    # 2. AVAILABLE_MODES by index, as QGC does: index 1 says how many there are.
    ack = qgc.request_message(MSG_AVAILABLE_MODES, 1)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    first = qgc.wait(lambda m: m.get_type() == "AVAILABLE_MODES", 3.0)
    assert first is not None and first.mode_index == 1
    modes = {1: first}
    for i in range(2, first.number_modes + 1):
        ack = qgc.request_message(MSG_AVAILABLE_MODES, i)
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED, f"AVAILABLE_MODES index {i}"
        m = qgc.wait(lambda m: m.get_type() == "AVAILABLE_MODES" and m.mode_index == i, 3.0)
        assert m is not None, f"no AVAILABLE_MODES with mode_index {i}"
        modes[i] = m
    by_name = {m.mode_name: m for m in modes.values()}
    assert by_name["MANUAL"].custom_mode == 19
    assert not by_name["MANUAL"].properties & mavlink.MAV_MODE_PROPERTY_NOT_USER_SELECTABLE
    assert "ALT_HOLD" in by_name

    # 3. Component metadata (and the older component information): each
    #    answered, naming the general metadata file, which QGC fetches over
    #    MAVLink FTP. pymavlink 2.4.50's dialect lacks both messages: they
    #    arrive as UNKNOWN_397/395, the URI read from the payload.
    uris = []
    for msg_id in (MSG_COMPONENT_METADATA, MSG_COMPONENT_INFORMATION):
        ack = qgc.request_message(msg_id)
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED, f"REQUEST_MESSAGE({msg_id})"
        m = qgc.wait(lambda m: m.get_type() == f"UNKNOWN_{msg_id}", 3.0)
        assert m is not None, f"REQUEST_MESSAGE({msg_id}) accepted, no message {msg_id}"
        frame = bytes(m.data)
        payload = frame[10 : 10 + frame[1]].ljust(320, b"\0")
        # COMPONENT_METADATA: u32, u32, uri[100]; COMPONENT_INFORMATION: three u32, then the URI.
        at = 8 if msg_id == MSG_COMPONENT_METADATA else 12
        uris.append(payload[at : at + 100].split(b"\0")[0].decode())
    assert uris[0] == uris[1] and uris[0].startswith("mftp://"), uris
    # QGC keeps one slash of the scheme's and asks for the rest.
    general = qgc.ftp_get("/" + uris[0][len("mftp://") :])
    assert b'"metadataTypes"' in general

    # 4. MAVLink FTP for the parameter file: NAK FileNotFound within 1 s
    #    (QGC's FTP ack timeout), so QGC falls back to the parameter protocol.
    ftp_before = len([m for m in qgc.received if m.get_type() == "FILE_TRANSFER_PROTOCOL"])
    nak = qgc.ftp(FTP_OPEN_FILE_RO, 7, path=b"@PARAM/param.pck", timeout=1.0)
    assert nak is not None, "no FTP reply within 1 s"
    assert (nak.target_system, nak.target_component) == (QGC_SYSID, QGC_COMPID)
    data = bytes(nak.payload)
    _seq, _session, opcode, size, req_opcode = struct.unpack_from("<HBBBB", data)
    assert opcode == FTP_NAK and req_opcode == FTP_OPEN_FILE_RO
    assert size >= 1 and data[12] == FTP_ERR_FILE_NOT_FOUND

    # 5. PARAM_REQUEST_LIST; gaps re-read by index (QGC's retry).
    qgc.conn.mav.param_request_list_send(1, 1)
    values: dict[int, object] = {}
    count = None
    retried = 0
    dl = Deadline(40.0)
    while not dl.expired():
        m = qgc.wait(lambda m: m.get_type() == "PARAM_VALUE", min(dl.left(), 1.0))
        if m is not None:
            count = m.param_count
            values[m.param_index] = m
            if len(values) == count:
                break
            continue
        # Quiet for 1 s: ask for the missing ones by index, as QGC does.
        assert count is not None, "no PARAM_VALUE at all after PARAM_REQUEST_LIST"
        for i in sorted(set(range(count)) - values.keys())[:10]:
            retried += 1
            qgc.conn.mav.param_request_read_send(1, 1, b"", i)
    assert count is not None and count > 0
    missing = sorted(set(range(count)) - values.keys())
    assert not missing, f"parameters never arrived (even by index): {missing[:20]}"
    assert {v.param_count for v in values.values()} == {count}
    names = {v.param_id for v in values.values()}
    assert len(names) == count, "duplicate parameter names"
    for name in ("SYSID_MYGCS", "JS_GAIN_DEFAULT", "FS_GCS_ENABLE"):
        assert name in names
    gain = next(v for v in values.values() if v.param_id == "JS_GAIN_DEFAULT")
    assert gain.param_type == mavlink.MAV_PARAM_TYPE_REAL32 and abs(gain.param_value - 0.5) < 1e-6

    # 6. Missions, rally, fence: each an empty list of the type asked for.
    for mission_type in (0, 1, 2):
        qgc.conn.mav.mission_request_list_send(1, 1, mission_type)
        mc = qgc.wait(lambda m: m.get_type() == "MISSION_COUNT", 3.0)
        assert mc is not None, f"no MISSION_COUNT for mission_type {mission_type}"
        assert mc.count == 0 and mc.mission_type == mission_type
        assert (mc.target_system, mc.target_component) == (QGC_SYSID, QGC_COMPID)

    # Drain one more heartbeat period so any duplicate or late ACK shows up.
    qgc.wait(lambda m: False, 1.5)

    # Every command answered exactly once, each ACK addressed to us.
    acks = qgc.acks()
    assert len(acks) == len(qgc.commands_sent), (
        f"{len(qgc.commands_sent)} commands sent, {len(acks)} COMMAND_ACKs received"
    )
    for a in acks:
        assert (a.target_system, a.target_component) == (QGC_SYSID, QGC_COMPID), a
    # Each metadata message came once.
    for msg_id in (MSG_COMPONENT_METADATA, MSG_COMPONENT_INFORMATION):
        assert len([m for m in qgc.received if m.get_type() == f"UNKNOWN_{msg_id}"]) == 1
    # The parameter file's FTP request answered once (no duplicate NAK to
    # time out on later).
    assert len([m for m in qgc.received if m.get_type() == "FILE_TRANSFER_PROTOCOL"]) == ftp_before + 1
    print(f"{count} parameters, {retried} re-read by index")
