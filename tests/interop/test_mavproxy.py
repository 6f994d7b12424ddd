"""MAVProxy 1.8.75 against the vehicle's tcpin endpoint, driven through a
pseudo-terminal (pexpect) exactly as a user types: connect, `param fetch`,
`arm throttle`, `disarm`; `log list`, `log download`."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

import pexpect
import pytest

from mavhelpers import free_tcp_port

MAVPROXY = Path(sys.executable).parent / "mavproxy.py"


class MavProxy:
    def __init__(self, master: str, workdir: Path):
        self.log_path = workdir / "mavproxy-output.txt"
        self.log = open(self.log_path, "w")
        env = dict(os.environ, HOME=str(workdir), TERM="dumb")
        env["PATH"] = f"{MAVPROXY.parent}{os.pathsep}{env.get('PATH', '')}"
        self.child = pexpect.spawn(
            sys.executable,
            [str(MAVPROXY), f"--master={master}", f"--state-basedir={workdir / 'state'}"],
            cwd=str(workdir),
            env=env,
            encoding="utf-8",
            codec_errors="replace",
        )
        self.child.logfile_read = self.log

    def expect(self, pattern: str, timeout: float, what: str) -> re.Match:
        i = self.child.expect([pattern, pexpect.TIMEOUT, pexpect.EOF], timeout=timeout)
        if i != 0:
            self.log.flush()
            why = "timed out" if i == 1 else "MAVProxy exited"
            pytest.fail(f"{what}: {why} waiting for {pattern!r}; MAVProxy said:\n{self.log_path.read_text()[-4000:]}")
        return self.child.match

    def send(self, line: str):
        self.child.sendline(line)

    def close(self):
        # `exit` is only honoured with `set requireexit`, and even then MAVProxy
        # lingers; a hang-up, then SIGINT, then SIGKILL (pexpect's terminate).
        self.child.terminate(force=True)
        self.child.close(force=True)
        self.log.close()


@pytest.fixture
def mavproxy(make_vehicle, tmp_path):
    port = free_tcp_port()
    vehicle = make_vehicle([f"tcpin:127.0.0.1:{port}"])
    workdir = tmp_path / "mavproxy"
    workdir.mkdir()
    mp = MavProxy(f"tcp:127.0.0.1:{port}", workdir)
    try:
        yield vehicle, mp
    finally:
        mp.close()


def test_mavproxy_params_arm_disarm(mavproxy):
    _, mp = mavproxy
    mp.expect(r"Detected vehicle 1:1", 60, "connect")
    mp.expect(r"online system 1", 30, "connect")

    mp.send("param fetch")
    n = int(mp.expect(r"Received (\d+) parameters", 90, "param fetch").group(1))
    assert n > 0
    # MAVProxy saves what it received; every parameter must be in it.
    mp.expect(r"Saved (\d+) parameters to (\S+)", 30, "param save")
    saved = int(mp.child.match.group(1))
    assert saved == n
    parm_file = Path(mp.child.match.group(2).strip())
    rows = dict(line.split()[:2] for line in parm_file.read_text().splitlines() if line.strip())
    assert len(rows) == n
    assert float(rows["JS_GAIN_DEFAULT"]) == pytest.approx(0.5)
    assert float(rows["SYSID_MYGCS"]) == 255

    mp.send("arm throttle")
    mp.expect(r"COMPONENT_ARM_DISARM: ACCEPTED", 30, "arm ack")
    mp.expect(r"\bARMED", 30, "armed heartbeat")

    mp.send("disarm")
    mp.expect(r"COMPONENT_ARM_DISARM: ACCEPTED", 30, "disarm ack")
    mp.expect(r"DISARMED", 30, "disarmed heartbeat")

    # MAVProxy's fence module reads a clear GEOFENCE health bit as a breach.
    mp.log.flush()
    assert "fence breach" not in mp.log_path.read_text()


def test_mavproxy_lists_and_downloads_the_log(mavproxy):
    vehicle, mp = mavproxy
    mp.expect(r"Detected vehicle 1:1", 60, "connect")
    mp.expect(r"online system 1", 30, "connect")
    mp.send("log list")
    size = int(mp.expect(r"Log 1\s+numLogs 1 lastLog 1 size (\d+)", 30, "log list").group(1))
    assert size > 0
    out = Path(mp.log_path).parent / "log1.bin"
    mp.send(f"log download 1 {out}")
    got = int(mp.expect(r"Finished downloading \S+ \((\d+) bytes", 120, "log download").group(1))
    # The log being written: what its entry said, as it was on the disk.
    assert got == size
    tlog = next((vehicle.data_dir / "tlogs").glob("*.tlog"))
    assert out.read_bytes() == tlog.read_bytes()[:size]
