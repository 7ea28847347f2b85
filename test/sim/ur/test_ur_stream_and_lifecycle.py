"""UR stand-in: the RTDE stream's wall-clock rate, stopScript (command 255) and a controller killed by SIGKILL and
started again as a new process, each checked with the real clients (ur_rtde) or a raw RTDE reader."""
import os
import signal
import socket
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

from ur_client_support import Q_HOME, disconnect_all, eventually

rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")
dashboard_client = pytest.importorskip("dashboard_client")

pytestmark = pytest.mark.slow

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))),
                   "src")
RTDE_PORT = 30004
# RTDE package types
REQUEST_PROTOCOL_VERSION, SETUP_OUTPUTS, START, PAUSE, DATA = 86, 79, 83, 80, 85


class RtdeReader:
    """A raw RTDE output subscriber (protocol 2) that counts the data packages it receives."""

    def __init__(self, addr: str, names: bytes, frequency: float) -> None:
        self.sock = socket.create_connection((addr, RTDE_PORT), timeout=2.0)
        self._send(REQUEST_PROTOCOL_VERSION, struct.pack(">H", 2))
        assert self._recv_type(REQUEST_PROTOCOL_VERSION) == b"\x01"
        self._send(SETUP_OUTPUTS, struct.pack(">d", frequency) + names)
        body = self._recv_type(SETUP_OUTPUTS)
        assert body[0] == 1, "output recipe refused: %r" % body
        self._send(START)
        assert self._recv_type(START) == b"\x01"

    def _send(self, ptype: int, payload: bytes = b"") -> None:
        self.sock.sendall(struct.pack(">HB", len(payload) + 3, ptype) + payload)

    def _exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("the stand-in closed the RTDE connection")
            buf += chunk
        return buf

    def recv(self):
        size, ptype = struct.unpack(">HB", self._exact(3))
        return ptype, self._exact(size - 3)

    def _recv_type(self, ptype: int, limit: int = 2000) -> bytes:
        for _ in range(limit):
            t, body = self.recv()
            if t == ptype:
                return body
        raise AssertionError("no package of type %d" % ptype)

    def count_for(self, seconds: float):
        """Data packages received in ``seconds`` of wall clock, and the controller timestamps they carried."""
        stamps = []
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            ptype, body = self.recv()
            if ptype == DATA:
                stamps.append(struct.unpack_from(">d", body, 1)[0])
        return stamps

    def close(self) -> None:
        if self.sock.fileno() < 0:
            return                                        # already closed
        try:
            self._send(PAUSE)
        except OSError:
            pass
        self.sock.close()


def test_rtde_stream_delivers_about_500_packages_per_wall_second(ur_standin):
    """The stream rate measured on the wall clock, not from the controller's cycle count: a raw subscriber at
    500 Hz counts packages over 2 s while a real RTDEReceiveInterface is streaming too. The bounds are tolerant
    (a busy CI machine); the on-time percentage is measured by bench/bench_ur_standin.py."""
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)          # default: 500 Hz on a 5.x controller
    reader = RtdeReader(addr, b"timestamp,actual_q", 500.0)
    try:
        reader.count_for(0.3)                            # drain what queued during the handshake
        ts0, w0 = r.getTimestamp(), time.monotonic()
        t0 = time.monotonic()
        stamps = reader.count_for(2.0)
        wall = time.monotonic() - t0
        ts1, w1 = r.getTimestamp(), time.monotonic()
        rate = len(stamps) / wall
        assert 400.0 <= rate <= 550.0, "%.1f packages/s over %.2f s of wall clock" % (rate, wall)
        assert all(b > a for a, b in zip(stamps, stamps[1:]))          # fresh packages, never a repeat
        # the controller clock the receive interface sees advances with the wall clock (not a replay)
        assert (ts1 - ts0) == pytest.approx(w1 - w0, abs=0.25)
        reader.close()                                   # not read any more: do not let it build a backlog
        # a 125 Hz subscriber gets a quarter of that rate
        slow = RtdeReader(addr, b"timestamp", 125.0)
        try:
            slow.count_for(0.3)
            t0 = time.monotonic()
            n = len(slow.count_for(2.0))
            slow_rate = n / (time.monotonic() - t0)
        finally:
            slow.close()
        assert 100.0 <= slow_rate <= 140.0, "%.1f packages/s at 125 Hz" % slow_rate
    finally:
        reader.close()
        disconnect_all(r)


def _spawn_standin(addr: str, log_path: str) -> subprocess.Popen:
    """``python -m locem_bridge.sim.ur --address addr`` as its own process (no control pipe)."""
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    log = open(log_path, "ab")
    try:
        return subprocess.Popen([sys.executable, "-m", "locem_bridge.sim.ur", "--address", addr,
                                 "--time-scale", "10", "--log-level", "INFO"],
                                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, env=env)
    finally:
        log.close()


def _wait_listening(proc: subprocess.Popen, addr: str, log_path: str, timeout: float = 30.0) -> None:
    """Until all three ports accept a connection (bounded); fails with the child's log otherwise."""
    deadline = time.monotonic() + timeout
    pending = [29999, 30003, RTDE_PORT]
    while pending and time.monotonic() < deadline:
        if proc.poll() is not None:
            break
        try:
            with socket.create_connection((addr, pending[0]), timeout=0.5):
                pass
            pending.pop(0)
        except OSError:
            time.sleep(0.1)
    if pending:
        with open(log_path, "rb") as fh:
            out = fh.read().decode(errors="replace")
        pytest.fail("UR stand-in process on %s not listening on %s (exit code %s):\n%s"
                    % (addr, pending, proc.poll(), out[-3000:]))


def _kill(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=10)


def _log_text(log_path: str) -> str:
    with open(log_path, "rb") as fh:
        return fh.read().decode(errors="replace")


def test_stop_script_ends_the_control_program_and_moves_need_a_new_upload(ur_address, tmp_path):
    """stopScript (register command 255): the control script is no longer running (dashboard programState and
    running, RTDE runtime_state and robot_status bit 1 'program running'); a move is refused and leaves the arm
    where it is until the script is uploaded again. The stand-in runs as ``python -m locem_bridge.sim.ur`` with
    its log in a file, which shows that command 255 ended the program (not, say, a dashboard ``stop``)."""
    log_path = str(tmp_path / "standin.log")
    proc = _spawn_standin(ur_address, log_path)
    r = c = db = None
    try:
        _wait_listening(proc, ur_address, log_path)
        r = rtde_receive.RTDEReceiveInterface(ur_address)
        c = rtde_control.RTDEControlInterface(ur_address)
        db = dashboard_client.DashboardClient(ur_address)
        db.connect()
        assert c.isProgramRunning()
        assert db.programState().startswith("PLAYING")
        assert db.running()
        assert r.getRuntimeState() == 2                             # PLAYING
        assert r.getRobotStatus() & 0b10                            # bit 1: program running
        assert "stopped by stopScript" not in _log_text(log_path)
        c.stopScript()
        assert eventually(lambda: r.getRuntimeState() == 1)        # STOPPED
        assert eventually(lambda: "control script stopped by stopScript" in _log_text(log_path))
        assert db.programState().startswith("STOPPED")
        assert not db.running()
        assert eventually(lambda: not (r.getRobotStatus() & 0b10))
        assert r.getRobotStatus() & 0b1                             # still powered on
        assert r.getRobotMode() == 7                                # RUNNING: the robot itself is fine
        assert not c.isProgramRunning()
        q_before = r.getActualQ()
        target = [0.4] + Q_HOME[1:]
        assert c.moveJ(target, 1.0, 1.0) is False                   # nothing runs the command
        time.sleep(0.2)                                             # 2 s of motion time at time scale 10
        assert np.allclose(r.getActualQ(), q_before, atol=1e-9)    # the arm did not move
        assert r.getRuntimeState() == 1
        assert c.reuploadScript()                                   # a new upload starts it again
        assert eventually(c.isProgramRunning)
        assert db.programState().startswith("PLAYING")
        assert c.moveJ(target, 1.0, 1.0) is True
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), target))) < 1e-3)
    finally:
        for client in (c, r, db):
            if client is not None:
                disconnect_all(client)
        _kill(proc)


def test_sigkilled_standin_process_restarted_then_clients_reconnect(ur_address, tmp_path):
    """Issue 3: killing the stand-in's process (SIGKILL: no orderly close) and starting a new one on the same
    address, then reconnect() of the control and receive interfaces: moveJ works and getActualQ agrees."""
    log_path = str(tmp_path / "standin.log")
    procs = []
    r = c = None
    try:
        first = _spawn_standin(ur_address, log_path)
        procs.append(first)
        _wait_listening(first, ur_address, log_path)
        r = rtde_receive.RTDEReceiveInterface(ur_address)
        c = rtde_control.RTDEControlInterface(ur_address)
        target = [0.3, -1.4, 1.4, -1.6, -1.5, 0.2]
        assert c.moveJ(target, 1.0, 1.0)
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), target))) < 1e-3)

        os.kill(first.pid, signal.SIGKILL)
        first.wait(timeout=10)
        assert first.returncode == -signal.SIGKILL
        assert eventually(lambda: not c.isConnected() and not r.isConnected(), timeout=10.0), \
            "the clients did not notice the controller was gone"

        second = _spawn_standin(ur_address, log_path)              # same address, a fresh controller
        procs.append(second)
        _wait_listening(second, ur_address, log_path)
        assert r.reconnect()
        assert c.reconnect()
        assert r.isConnected() and c.isConnected()
        assert eventually(c.isProgramRunning)
        # a new controller process starts from its initial pose (the killed one kept nothing)
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), Q_HOME))) < 1e-3)
        goal = [-0.2, -1.3, 1.3, -1.7, -1.4, 0.5]
        assert c.moveJ(goal, 1.0, 1.0) is True
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), goal))) < 1e-3)
        # and it is the new process that moved: it is alive, the old one is gone
        assert second.poll() is None
    finally:
        for client in (c, r):
            if client is not None:
                disconnect_all(client)
        for p in procs:
            _kill(p)
