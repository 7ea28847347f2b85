"""Heartbeat producers of the simulated CAN drives, in a small helper process on the wall clock.

Why a process: a real drive's heartbeat comes from its communication stack, on time whatever its application
does. In the simulator the drives share one Python interpreter with PyBullet, the UR controller stand-in and the
Modbus server; on a loaded 2-core machine a heartbeat thread there waits for the GIL behind a thread the OS has
preempted, and heartbeats measured 149 ms apart at the producer (against a 100 ms producer time and the base
bridge's consumer timeout (150 ms then, 200 ms now); see docs/protocol_notes.md). The helper process holds nothing but the
heartbeat timers, so it is scheduled as soon as a timer is due.

Semantics are unchanged: canopen's ``NmtSlave`` still decides when the heartbeat starts (boot-up -> PRE-OPERATIONAL,
a write of 0x1017), what it carries (the NMT state, updated on every state change) and when it stops (heartbeat
loss injected, node detached). :meth:`HeartbeatProcess.send_periodic` has the signature of
``canopen.Network.send_periodic`` and returns a task with ``update(data)`` / ``stop()``; the DriveSet routes the
heartbeat COB-IDs (0x701..0x77F) to it. The helper exits when its stdin closes, so a simulator that dies (even by
``kill -9``) takes its heartbeats with it and the master sees the loss, as it should.

Only for buses another process can open: ``udp_multicast`` and ``socketcan``. python-can's ``virtual`` bus lives
inside one process; with it the heartbeats stay on canopen's in-process timer threads.

Lifecycle: ``HeartbeatProcess(can_cfg)`` -> :meth:`start` (spawns ``python -m locem_bridge.sim.can.heartbeat``,
waits until it has opened the bus) -> tasks via :meth:`send_periodic` -> :meth:`close` (stops every heartbeat,
ends the process; idempotent).
"""
from __future__ import annotations

import json
import select
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Dict, List, Optional

from ...common.can_bus import SHARED_INTERFACES, CanBusError, open_bus
from ...common.paths import child_env
from ..errors import DeviceStandInError

HEARTBEAT_COB_RANGE = (0x701, 0x77F)


class RemoteHeartbeatTask:
    """What ``Network.send_periodic`` returns for a heartbeat handled by the helper process."""

    def __init__(self, owner: "HeartbeatProcess", can_id: int, data: bytes, period: float) -> None:
        self._owner = owner
        self.can_id = int(can_id)
        self.period = float(period)
        self.data = bytes(data)
        self._owner._command({"op": "set", "cob": self.can_id, "data": self.data.hex(), "period": self.period})

    def update(self, data: bytes) -> None:
        """New payload from the next period on (the schedule keeps its phase)."""
        data = bytes(bytearray(data))
        if data != self.data:
            self.data = data
            self._owner._command({"op": "set", "cob": self.can_id, "data": self.data.hex(), "period": self.period})

    def stop(self) -> None:
        self._owner._command({"op": "stop", "cob": self.can_id})


class HeartbeatProcess:
    """The helper process and its command pipe (see the module docstring). Thread-safe."""

    def __init__(self, can_cfg: Dict[str, Any]) -> None:
        if can_cfg.get("interface") not in SHARED_INTERFACES:
            raise DeviceStandInError("heartbeat process needs a bus other processes can open (%s), got %r"
                                     % (", ".join(SHARED_INTERFACES), can_cfg.get("interface")))
        self.can_cfg = dict(can_cfg)
        self._proc: Optional[subprocess.Popen] = None
        self._lock = threading.Lock()

    @staticmethod
    def handles(can_id: int) -> bool:
        return HEARTBEAT_COB_RANGE[0] <= can_id <= HEARTBEAT_COB_RANGE[1]

    def start(self, timeout: float = 20.0) -> None:
        if self._proc is not None:
            raise DeviceStandInError("heartbeat process already started")
        env = child_env()
        cfg = {k: self.can_cfg[k] for k in ("interface", "channel", "port") if k in self.can_cfg}
        self._proc = subprocess.Popen([sys.executable, "-m", "locem_bridge.sim.can.heartbeat", json.dumps(cfg)],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, text=True, bufsize=1)
        ready, _, _ = select.select([self._proc.stdout], [], [], timeout)
        line = self._proc.stdout.readline() if ready else ""
        if not line.startswith("ready"):
            self.close()
            raise DeviceStandInError("heartbeat process did not start on CAN %s: %s"
                                     % (cfg, line.strip() or "no answer within %.0f s" % timeout))

    @property
    def pid(self) -> Optional[int]:
        return self._proc.pid if self._proc is not None else None

    def send_periodic(self, can_id: int, data: bytes, period: float, remote: bool = False) -> RemoteHeartbeatTask:
        """``canopen.Network.send_periodic`` for heartbeat COB-IDs."""
        if remote or not self.handles(can_id):
            raise DeviceStandInError("heartbeat process only sends heartbeats (COB-ID 0x701..0x77F), got 0x%X"
                                     % can_id)
        return RemoteHeartbeatTask(self, can_id, data, period)

    def _command(self, cmd: Dict[str, Any]) -> None:
        with self._lock:
            proc = self._proc
            if proc is None or proc.poll() is not None:
                if cmd["op"] == "stop":
                    return                         # nothing is sending anyway
                raise DeviceStandInError("heartbeat process is not running (exit code %s)"
                                         % (proc.returncode if proc is not None else "never started"))
            try:
                proc.stdin.write(json.dumps(cmd) + "\n")
                proc.stdin.flush()
            except (BrokenPipeError, OSError) as exc:
                if cmd["op"] != "stop":
                    raise DeviceStandInError("heartbeat process pipe broken: %s" % exc)

    def close(self) -> None:
        with self._lock:
            proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            proc.stdin.close()                     # EOF: the helper stops every heartbeat and exits
        except OSError:
            pass
        try:
            proc.wait(3.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()


# -- the helper process --------------------------------------------------------------------------------------------
def _serve(can_cfg: Dict[str, Any]) -> int:
    import can

    try:
        bus = open_bus(can_cfg)                # the drives' own bus, opened the same way
    except CanBusError as exc:
        print("error: %s" % exc, flush=True)
        return 2
    tasks: Dict[int, List[Any]] = {}           # cob -> [message, period, next due]
    stdin = sys.stdin
    print("ready", flush=True)
    try:
        while True:
            now = time.monotonic()
            for cob, task in list(tasks.items()):
                msg, period, due = task
                if now >= due:
                    try:
                        bus.send(msg)
                    except Exception as exc:       # keep the other heartbeats going
                        print("error: heartbeat 0x%X not sent: %s" % (cob, exc), file=sys.stderr, flush=True)
                    due += period
                    task[2] = due if due > now else now + period   # after a stall: restart, no burst
            wait = min((t[2] for t in tasks.values()), default=now + 1.0) - time.monotonic()
            ready, _, _ = select.select([stdin], [], [], max(0.0, wait))
            if not ready:
                continue
            line = stdin.readline()
            if not line:
                return 0                           # parent gone or closed the pipe: stop sending
            try:
                cmd = json.loads(line)
                cob = int(cmd["cob"])
                if cmd["op"] == "stop":
                    tasks.pop(cob, None)
                elif cmd["op"] == "set":
                    msg = can.Message(arbitration_id=cob, data=bytes.fromhex(cmd["data"]), is_extended_id=False)
                    period = float(cmd["period"])
                    if period <= 0.0:
                        tasks.pop(cob, None)
                    elif cob in tasks and abs(tasks[cob][1] - period) < 1e-9:
                        tasks[cob][0] = msg        # new state, same schedule
                    else:
                        tasks[cob] = [msg, period, time.monotonic()]   # first heartbeat at once
            except (ValueError, KeyError, TypeError) as exc:
                print("error: bad command %r: %s" % (line.strip(), exc), file=sys.stderr, flush=True)
    finally:
        bus.shutdown()


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m locem_bridge.sim.can.heartbeat '{\"interface\": ..., \"channel\": ..., \"port\": ...}'",
              file=sys.stderr)
        return 2
    # Ctrl-C or roslaunch's SIGINT reaches the whole process group: the helper's lifetime is its parent's
    # (it stops when its stdin closes), so it ends quietly with the parent instead of with a traceback
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return _serve(json.loads(argv[0]))


if __name__ == "__main__":
    sys.exit(main())
