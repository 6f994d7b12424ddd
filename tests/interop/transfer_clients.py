"""Ground-station clients for the vehicle's files, with pymavlink:

- `QgcLogs`: onboard log list and download the way QGroundControl's
  LogDownloadController asks (LOG_REQUEST_LIST 0..0xffff, the first
  entry making `num_logs` slots, entries of size 0 skipped with an
  ArduPilot vehicle, missing entries asked again by id range after 500 ms;
  data in chunks of 512 × 90 bytes, the next chunk asked for when one is
  complete, the first missing run of the chunk asked again after 500 ms of
  silence, misaligned or out-of-chunk LOG_DATA ignored, LOG_REQUEST_END at
  the end).
- `ftp_get`: a file with pymavlink's own MAVFTP client (`pymavlink.mavftp`,
  what MAVProxy's `ftp` module uses).

Used by the interoperability tests and, as a script, by the transfer
benchmark (`benches/transfer.rs`), which runs it as a separate process:

    python transfer_clients.py log  PORT SYSID OUT   # the oldest log
    python transfer_clients.py ftp  PORT SYSID PATH OUT [BURST]

Each prints one JSON line: bytes, seconds, retries."""

from __future__ import annotations

import json
import os
import sys
import time

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

DATA_LEN = 90
CHUNK_BINS = 512
CHUNK = CHUNK_BINS * DATA_LEN
TIMEOUT_S = 0.5
ENTRY_RETRIES = 2
DATA_RETRIES = 5


class TransferError(Exception):
    pass


class QgcLogs:
    def __init__(self, conn, target=(1, 1), ardupilot: bool = True):
        self.conn = conn
        self.target = target
        # QGroundControl counts ArduPilot's log ids from 1.
        self.one_based = 1 if ardupilot else 0
        self.ardupilot = ardupilot
        self.retries = 0

    def _recv(self, types, timeout: float):
        return self.conn.recv_match(type=types, blocking=True, timeout=timeout)

    def list(self) -> dict[int, object]:
        """id -> LOG_ENTRY, as QGroundControl builds its table."""
        self.conn.mav.log_request_list_send(*self.target, 0, 0xFFFF)
        slots: list[object | None] | None = None
        retries = 0
        while True:
            m = self._recv("LOG_ENTRY", TIMEOUT_S)
            if m is None:
                if slots is None:
                    if retries >= ENTRY_RETRIES:
                        raise TransferError("no LOG_ENTRY at all")
                    retries += 1
                    self.conn.mav.log_request_list_send(*self.target, 0, 0xFFFF)
                    continue
                missing = [i for i, e in enumerate(slots) if e is None]
                if not missing:
                    break
                if retries >= ENTRY_RETRIES:
                    raise TransferError(f"log entries {missing} never came")
                retries += 1
                self.retries += 1
                start = missing[0]
                end = start
                while end + 1 < len(slots) and slots[end + 1] is None:
                    end += 1
                self.conn.mav.log_request_list_send(
                    *self.target, start + self.one_based, end + self.one_based
                )
                continue
            if m.num_logs == 0:
                return {}
            if slots is None:
                slots = [None] * m.num_logs
            if m.size or not self.ardupilot:
                i = m.id - self.one_based
                if 0 <= i < len(slots):
                    slots[i] = m
            retries = 0
            if all(e is not None for e in slots):
                break
        return {e.id: e for e in slots}

    def download(self, entry) -> bytes:
        """The log whole, chunk by chunk."""
        size = entry.size
        data = bytearray(size)
        chunk = 0
        chunks = (size + CHUNK - 1) // CHUNK

        def bins_of(c: int) -> int:
            return min(CHUNK_BINS, (size - c * CHUNK + DATA_LEN - 1) // DATA_LEN)

        have = [False] * bins_of(0) if size else []
        self.conn.mav.log_request_data_send(*self.target, entry.id, 0, len(have) * DATA_LEN)
        retries = 0
        while chunk < chunks:
            m = self._recv("LOG_DATA", TIMEOUT_S)
            if m is None:
                if retries >= DATA_RETRIES:
                    raise TransferError(f"log {entry.id}: chunk {chunk} never completed")
                retries += 1
                self.retries += 1
                start = have.index(False)
                end = start
                while end + 1 < len(have) and not have[end + 1]:
                    end += 1
                self.conn.mav.log_request_data_send(
                    *self.target,
                    entry.id,
                    chunk * CHUNK + start * DATA_LEN,
                    (end + 1 - start) * DATA_LEN,
                )
                continue
            if m.id != entry.id or m.ofs % DATA_LEN != 0 or m.ofs > size:
                continue
            if m.ofs // CHUNK != chunk:
                continue
            b = (m.ofs - chunk * CHUNK) // DATA_LEN
            if b >= len(have) or have[b]:
                continue
            data[m.ofs : m.ofs + m.count] = bytes(m.data[: m.count])
            have[b] = True
            retries = 0
            if all(have):
                chunk += 1
                if chunk < chunks:
                    have = [False] * bins_of(chunk)
                    self.conn.mav.log_request_data_send(
                        *self.target, entry.id, chunk * CHUNK, len(have) * DATA_LEN
                    )
        self.conn.mav.log_request_end_send(*self.target)
        return bytes(data)


def ftp_get(conn, path: str, out: str, burst: int = 80, target=(1, 1)):
    """`path` fetched into `out` by pymavlink's MAVFTP client; its result."""
    from pymavlink import mavftp

    settings = mavftp.MAVFTPSettings(
        [
            ("debug", int, 0),
            ("pkt_loss_tx", int, 0),
            ("pkt_loss_rx", int, 0),
            ("max_backlog", int, 5),
            ("burst_read_size", int, burst),
            ("write_size", int, 80),
            ("write_qsize", int, 5),
            ("idle_detection_time", float, 3.7),
            ("read_retry_time", float, 1.0),
            ("retry_time", float, 0.5),
        ]
    )
    ftp = mavftp.MAVFTP(conn, target[0], target[1], settings)
    ret = ftp.cmd_get([path, out])
    if ret.error_code == mavftp.FtpError.Success:
        ret = ftp.process_ftp_reply("get", timeout=120)
    return ftp, ret


def _connect(port: int, sysid: int):
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=sysid, source_component=190)
    # A first frame makes us the vehicle's peer; then its heartbeat.
    conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    if conn.recv_match(type="HEARTBEAT", blocking=True, timeout=10) is None:
        raise TransferError("no HEARTBEAT from the vehicle")
    return conn


def main(argv: list[str]) -> int:
    kind, port, sysid = argv[0], int(argv[1]), int(argv[2])
    conn = _connect(port, sysid)
    try:
        if kind == "log":
            out = argv[3]
            logs = QgcLogs(conn)
            entries = logs.list()
            oldest = entries[min(entries)]
            t0 = time.monotonic()
            data = logs.download(oldest)
            dt = time.monotonic() - t0
            with open(out, "wb") as f:
                f.write(data)
            print(json.dumps({"bytes": len(data), "seconds": dt, "retries": logs.retries, "id": oldest.id}))
        elif kind == "ftp":
            path, out = argv[3], argv[4]
            burst = int(argv[5]) if len(argv) > 5 else 80
            t0 = time.monotonic()
            ftp, ret = ftp_get(conn, path, out, burst)
            dt = time.monotonic() - t0
            if ret.error_code != 0:
                raise TransferError(f"ftp get {path}: error {ret.error_code}")
            print(json.dumps({"bytes": os.path.getsize(out), "seconds": dt, "retries": ftp.read_retries}))
        else:
            raise TransferError(f"unknown kind {kind}")
    finally:
        conn.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
