"""The vehicle's files from the ground station's side, over UDP: the onboard
logs listed and downloaded as QGroundControl does it, the component
metadata COMPONENT_METADATA names fetched with pymavlink's MAVFTP client
and held against MAVLink's own schemas, and what a station that may only
watch, or a bad request, gets."""

from __future__ import annotations

import json
import logging
import re
import struct
from pathlib import Path

import jsonschema
import pytest
from pymavlink import mavutil

from mavhelpers import Deadline, GcsHeartbeat, free_udp_port, from_vehicle, mavlink, mavlink_crate_xml_dir, recv, wait_ack
from transfer_clients import QgcLogs, ftp_get

QGC = (255, 190)
WATCHER = (77, 190)
MSG_COMPONENT_METADATA = 397
FTP_NAK = 129
FTP_ACK = 128


def connect(port: int, station=QGC):
    conn = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=station[0], source_component=station[1]
    )
    conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    assert recv(conn, "HEARTBEAT", 10.0, from_vehicle) is not None, "no HEARTBEAT from the vehicle"
    return conn


def schema(name: str) -> dict:
    """A JSON schema of MAVLink's component metadata, from the mavlink crate's
    package (what the vehicle is built against; not copied here)."""
    path = mavlink_crate_xml_dir().parent.parent / "component_metadata" / name
    return json.loads(path.read_text())


@pytest.fixture
def vehicle_with_a_closed_tlog(make_vehicle):
    """A vehicle that ran once with a station asking for its telemetry at
    50 Hz for a few seconds (a tlog of a few chunks, closed at its stop),
    and runs again."""
    port = free_udp_port()
    v = make_vehicle([f"udpin:127.0.0.1:{port}"])
    v.udp_port = port
    conn = connect(port)
    try:
        with GcsHeartbeat(conn):
            conn.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_ALL, 50, 1)
            seen = 0
            dl = Deadline(30.0)
            while seen < 2500 and not dl.expired():
                if conn.recv_match(blocking=True, timeout=0.5) is not None:
                    seen += 1
            assert seen >= 2500, f"only {seen} messages from the vehicle"
    finally:
        conn.close()
    v.restart()
    return v


def test_qgroundcontrol_lists_the_logs_and_downloads_a_closed_tlog_whole(vehicle_with_a_closed_tlog, tmp_path):
    v = vehicle_with_a_closed_tlog
    tlogs = sorted((v.data_dir / "tlogs").glob("*.tlog"))
    assert len(tlogs) == 2, tlogs
    closed = tlogs[0]
    expected = closed.read_bytes()
    assert len(expected) > 100_000, f"the first run's tlog holds {len(expected)} bytes"

    conn = connect(v.udp_port)
    try:
        with GcsHeartbeat(conn):
            logs = QgcLogs(conn)
            entries = logs.list()
            # The closed log first (ids from 1, oldest first), then the running one.
            assert sorted(entries) == [1, 2], entries
            first = entries[1]
            assert first.size == len(expected)
            first_record_s = struct.unpack(">Q", expected[:8])[0] // 1_000_000
            assert first.time_utc == first_record_s
            data = logs.download(first)
    finally:
        conn.close()
    assert data == expected, "the downloaded log differs from the file"

    # Readable as a tlog by pymavlink, every record a MAVLink message.
    out = tmp_path / "downloaded.tlog"
    out.write_bytes(data)
    mlog = mavutil.mavlink_connection(str(out))
    types: dict[str, int] = {}
    while (m := mlog.recv_match()) is not None:
        types[m.get_type()] = types.get(m.get_type(), 0) + 1
    assert "BAD_DATA" not in types, types
    assert types.get("ATTITUDE", 0) > 50 and types.get("HEARTBEAT", 0) > 2, types


def test_mavftp_fetches_the_component_metadata_and_every_parameter_is_described(udp_vehicle, tmp_path, caplog):
    conn = connect(udp_vehicle.udp_port)
    try:
        with GcsHeartbeat(conn):
            conn.mav.command_long_send(1, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0, MSG_COMPONENT_METADATA, 0, 0, 0, 0, 0, 0)
            assert wait_ack(conn, mavlink.MAV_CMD_REQUEST_MESSAGE).result == mavlink.MAV_RESULT_ACCEPTED
            cm = component_metadata(conn)
            m = re.fullmatch(r"mftp://(\[;comp=\d+\])?(.+)", cm["uri"])
            assert m, cm["uri"]
            general_path = m.group(2)

            ftp, ret = ftp_get(conn, general_path, str(tmp_path / "general.json"))
            assert ret.error_code == 0, ret.error_code
            general_bytes = (tmp_path / "general.json").read_bytes()
            general = json.loads(general_bytes)
            jsonschema.validate(general, schema("general.schema.json"))

            # The CRC COMPONENT_METADATA gives is the file's, as CalcFileCRC32 says.
            caplog.set_level(logging.INFO)
            ret = ftp.cmd_crc([general_path])
            assert ret.error_code == 0
            crcs = re.findall(r"crc: \S+ 0x([0-9a-f]{8})", caplog.text)
            assert crcs and int(crcs[-1], 16) == cm["file_crc"]

            types = {t["type"]: t for t in general["metadataTypes"]}
            params_meta = types[1]
            params_path = re.fullmatch(r"mftp://(\[;comp=\d+\])?(.+)", params_meta["uri"]).group(2)
            ftp, ret = ftp_get(conn, params_path, str(tmp_path / "parameters.json"), burst=239)
            assert ret.error_code == 0, ret.error_code
            meta = json.loads((tmp_path / "parameters.json").read_text())
            jsonschema.validate(meta, schema("parameter.schema.json"))

            # Every parameter the vehicle lists is described, with its type.
            conn.param_fetch_all()
            values: dict[str, object] = {}
            count = None
            dl = Deadline(30.0)
            while (count is None or len(values) < count) and not dl.expired():
                p = recv(conn, "PARAM_VALUE", 2.0, from_vehicle)
                if p is not None:
                    count = p.param_count
                    values[p.param_id] = p
    finally:
        conn.close()
    assert count and len(values) == count, f"{len(values)} of {count} parameters"
    described = {p["name"]: p for p in meta["parameters"]}
    type_names = {
        mavlink.MAV_PARAM_TYPE_INT8: "Int8",
        mavlink.MAV_PARAM_TYPE_INT16: "Int16",
        mavlink.MAV_PARAM_TYPE_INT32: "Int32",
        mavlink.MAV_PARAM_TYPE_REAL32: "Float",
    }
    for name, p in values.items():
        d = described.get(name)
        assert d is not None, f"{name} is listed but not described"
        assert d["shortDesc"] and d["longDesc"], name
        assert d["type"] == type_names[p.param_type], name
    assert set(described) == set(values)
    assert described["FS_GCS_ENABLE"]["values"][0] == {"value": 0, "description": "Disabled"}


def component_metadata(conn) -> dict:
    """The COMPONENT_METADATA the vehicle sent: pymavlink 2.4.50's bundled
    dialects lack message 397 (it hands the frame over as UNKNOWN_397), so
    its payload is read as the message definition lays it out
    (time_boot_ms, file_crc, uri[100])."""
    dl = Deadline(5.0)
    while not dl.expired():
        m = conn.recv_match(blocking=True, timeout=dl.left())
        if m is not None and m.get_type() == f"UNKNOWN_{MSG_COMPONENT_METADATA}":
            # The whole frame: a MAVLink 2 header of 10 bytes, then the payload.
            frame = bytes(m.data)
            payload = frame[10 : 10 + frame[1]].ljust(108, b"\0")
            time_boot_ms, file_crc, uri = struct.unpack("<II100s", payload[:108])
            return {"file_crc": file_crc, "uri": uri.split(b"\0")[0].decode()}
    pytest.fail("REQUEST_MESSAGE(COMPONENT_METADATA) accepted, no COMPONENT_METADATA")


def ftp_request(conn, opcode: int, path: bytes = b"", session: int = 0, offset: int = 0, size: int | None = None, seq: int = 1):
    payload = struct.pack("<HBBBBBBI", seq, session, opcode, len(path) if size is None else size, 0, 0, 0, offset) + path
    conn.mav.file_transfer_protocol_send(0, 1, 1, list(payload.ljust(251, b"\0")))
    m = recv(conn, "FILE_TRANSFER_PROTOCOL", 5.0, from_vehicle)
    assert m is not None, f"no FTP reply to opcode {opcode} {path!r}"
    data = bytes(m.payload)
    r_seq, r_session, r_opcode, r_size, req_opcode = struct.unpack_from("<HBBBB", data)
    assert r_seq == (seq + 1) % 65536 and req_opcode == opcode
    return r_opcode, r_session, data[12 : 12 + r_size]


def test_bad_ftp_requests_get_naks_and_a_watcher_gets_no_records(vehicle_with_a_closed_tlog):
    v = vehicle_with_a_closed_tlog
    tlogs = sorted((v.data_dir / "tlogs").glob("*.tlog"))
    name = tlogs[0].name.encode()
    before = {p.name: p.stat().st_size for p in tlogs}

    pilot = connect(v.udp_port)
    try:
        for path in (b"/../params.toml", b"/logs/tlogs/../../params.toml", b"/logs/tlogs/" + name + b"\0x", b"/signing.key", b"@PARAM/param.pck"):
            assert ftp_request(pilot, 4, path)[::2] == (FTP_NAK, bytes([10])), path
        for opcode in (6, 7, 8, 9, 10, 11, 12, 13):
            assert ftp_request(pilot, opcode, b"/logs/tlogs/" + name)[::2] == (FTP_NAK, bytes([9])), opcode
        assert ftp_request(pilot, 99)[::2] == (FTP_NAK, bytes([7]))
        assert ftp_request(pilot, 5, session=200, size=10)[::2] == (FTP_NAK, bytes([4]))
        opcode, session, data = ftp_request(pilot, 4, b"/logs/tlogs/" + name)
        assert opcode == FTP_ACK
        size = struct.unpack("<I", data)[0]
        assert size == tlogs[0].stat().st_size
        assert ftp_request(pilot, 5, session=session, offset=size, size=100)[::2] == (FTP_NAK, bytes([6]))
        assert ftp_request(pilot, 1, session=session)[0] == FTP_ACK
    finally:
        pilot.close()

    watcher = connect(v.udp_port, WATCHER)
    try:
        # Records are for stations that may control: EACCES.
        assert ftp_request(watcher, 3, b"/logs/tlogs")[::2] == (FTP_NAK, bytes([2, 13]))
        assert ftp_request(watcher, 4, b"/logs/tlogs/" + name)[::2] == (FTP_NAK, bytes([2, 13]))
        # The log list is empty for it, and it may not erase.
        watcher.mav.log_request_list_send(1, 1, 0, 0xFFFF)
        entry = recv(watcher, "LOG_ENTRY", 5.0, from_vehicle)
        assert entry is not None and entry.num_logs == 0
        watcher.mav.log_erase_send(1, 1)
        text = recv(watcher, "STATUSTEXT", 5.0, lambda m: from_vehicle(m) and "log erase" in m.text)
        assert text is not None and "Refused" in text.text
    finally:
        watcher.close()
    after = {p.name: p.stat().st_size for p in sorted((v.data_dir / "tlogs").glob("*.tlog"))}
    assert set(after) == set(before)
    assert after[tlogs[0].name] == before[tlogs[0].name]
