"""Run the stand-in in its own process and drive it over a JSON-lines pipe.

Why: ur_rtde's Python bindings keep the GIL while a client blocks in C++ (e.g. during the connection handshake),
so a stand-in living in the same interpreter as a ur_rtde client starves and the handshake never completes. Tests
and any process that also holds ur_rtde clients therefore start the stand-in with :class:`StandInProcess`.

Protocol (child side, :func:`serve_stdio`): one JSON object per line on stdin, ``{"op": name, "args": [...]}``;
one JSON line answered on stdout, ``{"ok": true, "result": ...}`` or ``{"ok": false, "error": "..."}``.
``{"op": "later", "args": [delay_s, op, [args]]}`` runs ``op`` in the child after ``delay_s`` seconds (to inject a
fault while the parent is blocked in a ur_rtde call, which holds the GIL). The child
prints ``{"ready": true}`` after binding, or ``{"ready": false, "error": "..."}``. EOF on stdin stops it.
"""
import json
import os
import subprocess
import sys
import threading
from typing import Any, List, Optional, Sequence

from ...common.paths import child_env
from .errors import UrStandInError

#: methods of UrControllerStandIn callable through the pipe
ALLOWED_OPS = frozenset((
    "start", "stop", "get_joint_positions", "get_joint_velocities", "get_tcp_pose", "get_tcp_offset",
    "get_standard_digital_outputs", "get_configurable_digital_outputs", "get_tool_digital_outputs",
    "set_standard_digital_input", "set_tool_digital_input", "get_state", "set_joint_positions",
    "inject_protective_stop", "inject_emergency_stop", "release_emergency_stop", "refused", "stats", "later",
    "set_contact_planes", "get_tcp_force", "get_force_mode",
))


def serve_stdio(ctl, stdin=None, stdout=None) -> None:
    """Child side: answer JSON-lines requests for ``ctl`` (a UrControllerStandIn) until EOF or ``exit``."""
    stdin = stdin or sys.stdin
    stdout = stdout or sys.stdout
    for line in stdin:
        line = line.strip()
        if not line:
            continue
        try:
            req = json.loads(line)
            op = req.get("op")
            args = req.get("args", [])
            if op == "exit":
                stdout.write(json.dumps({"ok": True, "result": None}) + "\n")
                stdout.flush()
                break
            if op not in ALLOWED_OPS:
                raise ValueError("unknown op %r (allowed: %s)" % (op, ", ".join(sorted(ALLOWED_OPS))))
            if op == "later":
                # ["later", delay_s, op, args]: run op on a timer thread (e.g. a fault during a blocking call)
                delay, sub, sub_args = float(args[0]), args[1], list(args[2]) if len(args) > 2 else []
                if sub not in ALLOWED_OPS or sub in ("refused", "stats", "later"):
                    raise ValueError("op %r cannot be scheduled" % (sub,))
                timer = threading.Timer(delay, getattr(ctl, sub), sub_args)
                timer.daemon = True
                timer.start()
                result = None
            elif op == "refused":
                result: Any = ctl.refused
            elif op == "stats":
                result = {"cycles": ctl.cycle_count, "overruns": ctl.overruns, "skipped_cycles": ctl.skipped_cycles,
                          "pid": os.getpid()}
            else:
                result = getattr(ctl, op)(*args)
                if op == "start":
                    result = None
            reply = {"ok": True, "result": result}
        except Exception as exc:  # report every failure to the parent, keep serving
            reply = {"ok": False, "error": "%s: %s" % (type(exc).__name__, exc)}
        stdout.write(json.dumps(reply) + "\n")
        stdout.flush()
    ctl.stop()


class StandInProcess:
    """Parent side: a UrControllerStandIn in a child process, with the same method names (proxied).

    Lifecycle: ``start()`` spawns the child and waits until its ports are bound (raises UrStandInError with the
    child's reason otherwise); ``close()`` ends the child (EOF, then kill after ``timeout``). Methods such as
    ``inject_protective_stop()`` or ``get_joint_positions()`` are forwarded; ``stop()``/``start_server()`` stop and
    restart the servers inside the same child (a controller restart).
    """

    def __init__(self, address: str = "127.0.0.1", time_scale: float = 1.0, model: str = "ur10e",
                 q0: Optional[Sequence[float]] = None, log_level: str = "WARNING", timeout: float = 20.0) -> None:
        self.address = address
        self.time_scale = time_scale
        self.model = model
        self.q0 = q0
        self.log_level = log_level
        self.timeout = timeout
        self.proc: Optional[subprocess.Popen] = None
        self._lock = threading.Lock()

    def start(self) -> "StandInProcess":
        env = child_env()
        cmd = [sys.executable, "-m", "locem_bridge.sim.ur", "--address", self.address, "--time-scale",
               repr(float(self.time_scale)), "--model", self.model, "--stdio", "--log-level", self.log_level]
        if self.q0 is not None:
            cmd.append("--q0=" + ",".join(repr(float(v)) for v in self.q0))  # "=": a value may start with "-"
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env,
                                     universal_newlines=True, bufsize=1)
        line = self._readline()
        try:
            msg = json.loads(line)
        except ValueError:
            msg = {"ready": False, "error": "unexpected output %r" % line[:200]}
        if not msg.get("ready"):
            self.close()
            raise UrStandInError("UR stand-in process on %s did not start: %s" % (self.address, msg.get("error")))
        return self

    def _readline(self) -> str:
        assert self.proc is not None and self.proc.stdout is not None
        result: List[str] = []
        t = threading.Thread(target=lambda: result.append(self.proc.stdout.readline()), daemon=True)
        t.start()
        t.join(self.timeout)
        if not result:
            raise UrStandInError("UR stand-in process on %s did not answer within %.0f s"
                                 % (self.address, self.timeout))
        if not result[0]:
            raise UrStandInError("UR stand-in process on %s exited (code %s)" % (self.address, self.proc.poll()))
        return result[0]

    def call(self, op: str, *args: Any) -> Any:
        """Invoke ``op(*args)`` in the child; raises UrStandInError with the child's error text."""
        with self._lock:
            if self.proc is None or self.proc.poll() is not None:
                raise UrStandInError("UR stand-in process on %s is not running" % self.address)
            self.proc.stdin.write(json.dumps({"op": op, "args": list(args)}) + "\n")
            self.proc.stdin.flush()
            reply = json.loads(self._readline())
        if not reply.get("ok"):
            raise UrStandInError(reply.get("error", "unknown error"))
        return reply.get("result")

    def __getattr__(self, name: str):
        if name in ALLOWED_OPS:
            return lambda *args: self.call(name, *args)
        raise AttributeError(name)

    def start_server(self) -> None:
        """Restart the servers in the child after ``stop()``."""
        self.call("start")

    def close(self) -> None:
        proc, self.proc = self.proc, None
        if proc is None:
            return
        try:
            if proc.poll() is None:
                proc.stdin.close()
                proc.wait(timeout=self.timeout)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait(timeout=5)
        finally:
            if proc.stdout is not None:
                proc.stdout.close()

    def __enter__(self) -> "StandInProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()
