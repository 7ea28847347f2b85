"""UR arm backend over RTDE (ur_rtde in a supervised child process, see :mod:`.ur_worker`).

Lifecycle: ``UrRtdeArm(arm_cfg)`` -> :meth:`start` (a supervisor thread starts the worker, polls the arm state at
``poll_rate`` Hz, and restarts the worker with exponential backoff, 0.5 s doubling to 5 s, whenever the link is
lost: a reconnect redoes the whole handshake including the script upload) -> :meth:`close`.

Motions: every move is started asynchronously and watched: it ends when the controller reports the async
operation finished and the arm stands still at the target; it is stopped (``stopJ`` / ``stopL``) on cancel,
STOP, STOP_ARM and when it overruns its deadline (:class:`~.errors.MotionTimeout`, ``TIMEOUT``; the arm is stopped
before the command answers)::

    deadline = scale x (path / speed + stops x 2 speed / accel) + margin      [+ the script upload of a path]

``scale`` and ``margin`` (s) come from ``robot.arm.deadline`` (defaults 1.0 and ``MOTION_MARGIN_S`` = 2 s): a
slower controller (speed slider, reduced mode) needs a larger scale; a scale below 1 makes every motion overrun
(used by the tests). Before each command the link and the safety state are checked.

Paths (:meth:`UrRtdeArm.move_path`): one ``moveL(path)`` of ur_rtde, i.e. the control script is re-uploaded with
the waypoints (speed, acceleration, blend radius each) injected and run as one blended motion; the async progress
word names the waypoint being approached. The blend radii are checked here first (at most half of either
neighbouring segment, the first segment starting at the current TCP), so a bad path is refused before anything
moves; should the controller still refuse it (its control script halts), the script is uploaded again.

Force mode (:meth:`UrRtdeArm.force_mode_start` / :meth:`~UrRtdeArm.force_mode_stop`): ur_rtde ``forceMode`` with
one compliant axis, the z axis of a task frame (the tool axis for SAND_AREA): the controller pushes with the
requested force along it, speed-limited, while moves run along the other axes. Meanwhile a move's end check ignores
the compliant axis, the force along it is recorded (``actual_TCP_force``), and STOP / cancel / any stop of the arm
end force mode first.

Watchdog and safe state: the worker stops the arm (``stopJ``) and sets the controller's RTDE watchdog
(``robot.arm.controller.watchdog_frequency``, default :data:`WATCHDOG_HZ` = 1 Hz) before the link is reported up,
so commands answer ``NOT_READY`` until then; the 50 Hz state polls kick it, so when LOCEM dies the controller
stops the program and the arm within 1 s (see :mod:`.ur_worker`). 1 Hz leaves a busy machine 20 missed polls.

Safety: a protective stop, an emergency stop or any safety mode other than NORMAL / REDUCED is latched as
:class:`~.errors.SafetyStop` (``HARDWARE_ERROR``) and refuses every motion until :meth:`reset` (``RESET_ARM``),
which an operator sends after removing the cause; nothing clears it automatically.
"""

import json
import logging
import math
import queue
import subprocess
import sys
import threading
import time
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from locem_bridge.locem.errors import Aborted

from .config import need
from .errors import BadRequest, DeviceFault, LinkDown, MotionTimeout, NotConnected, SafetyStop
from locem_bridge.common.geometry import angle_between, rotvec_to_matrix
from locem_bridge.common.paths import child_env
from locem_bridge.common.sample_clock import SampleClock
from .geometry import distance
from .interfaces import Arm, Health, Waiter

log = logging.getLogger(__name__)

SAFETY_OK = (1, 2)                       # NORMAL, REDUCED
SAFETY_NAMES = {1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY", 5: "SAFEGUARD_STOP",
                6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP", 8: "VIOLATION", 9: "FAULT"}
ROBOT_RUNNING = 7
STOP_DECEL_J = 10.0                      # rad/s^2 used by stopJ (1 rad/s stops in 0.1 s)
STOP_DECEL_L = 5.0                       # m/s^2 used by stopL
MOTION_MARGIN_S = Arm.MOTION_MARGIN_S    # s, default deadline margin (the three from :class:`~.interfaces.Arm`)
JOINT_TOL = 2e-3                         # rad, "at the target" for joint moves
LINEAR_TOL = 1e-3                        # m, "at the target" for linear moves
ALREADY_THERE = 0.25                     # of the tolerances: a move this close to its target is not sent
REQUEST_TIMEOUT = 3.0
PATH_UPLOAD_S = Arm.PATH_UPLOAD_S    # s, budget for ur_rtde's script re-upload before a path starts
PATH_CALL_TIMEOUT = 10.0                 # s, the movePath request (stop script, upload, wait until it runs)
ROTATION_WEIGHT = Arm.ROTATION_WEIGHT    # m per rad when a path length mixes translation and rotation
WATCHDOG_HZ = 1.0                        # min frequency of the controller's RTDE watchdog (see the docstring)
FORCE_FREE_SPEED = 2.0                   # m/s, force-mode limit entry of the non-compliant axes (unused by type 2)


class UrRtdeArm(Arm):
    """The UR arm backend (see the module docstring). ``cfg`` is ``robot.arm``."""

    capabilities = frozenset({Arm.PATH, Arm.FORCE})

    def __init__(self, cfg: Mapping[str, Any], poll_rate: float = 50.0, connect_timeout: float = 20.0) -> None:
        self.host = need(cfg, "controller.host", str, where="robot.arm")
        self.frequency = need(cfg, "controller.rtde_frequency", float, default=500.0, lo=1.0, hi=500.0,
                              where="robot.arm")
        self.joint_names = list(need(cfg, "joint_names", list, where="robot.arm"))
        self.named_poses = {k: [float(x) for x in v] for k, v in need(cfg, "named_poses", dict, where="robot.arm").items()}
        self.watchdog_hz = need(cfg, "controller.watchdog_frequency", float, default=WATCHDOG_HZ, lo=0.0, hi=100.0,
                                where="robot.arm")
        self.poll_rate = poll_rate
        self.connect_timeout = connect_timeout
        self.deadline_scale = need(cfg, "deadline.scale", float, default=1.0, lo=0.01, hi=100.0, where="robot.arm")
        self.deadline_margin = need(cfg, "deadline.margin", float, default=MOTION_MARGIN_S, lo=0.0, hi=600.0,
                                    where="robot.arm")
        self._health = Health("connecting")
        self._io_lock = threading.Lock()
        self._proc: Optional[subprocess.Popen] = None
        self._replies: "queue.Queue[Dict[str, Any]]" = queue.Queue()
        self._ids = 0
        self._state: Dict[str, Any] = {}
        self._sample_clock = SampleClock()
        self._last_tick: Optional[Tuple[float, float]] = None       # (controller time, tick) of the last sample
        self._state_lock = threading.Lock()
        self._safety: Optional[str] = None           # latched safety stop (text), cleared only by reset()
        self._link_up = threading.Event()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._motion_kind = ""
        self._stop_requested: Optional[str] = None
        self._force: Optional[Dict[str, Any]] = None    # active force mode: axis (base frame), force, samples
        self.reconnects = 0
        self.connections = 0

    # -- worker process ----------------------------------------------------------------------------------
    def _spawn(self) -> None:
        env = child_env()
        proc = subprocess.Popen([sys.executable, "-u", "-m", "locem_bridge.bridges.ur_worker", "--host", self.host,
                                 "--frequency", repr(self.frequency), "--watchdog", repr(self.watchdog_hz)], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
                                universal_newlines=True, bufsize=1)
        replies: "queue.Queue[Dict[str, Any]]" = queue.Queue()

        def reader() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:
                try:
                    replies.put(json.loads(line))
                except ValueError:
                    continue
            replies.put({"eof": True})
        threading.Thread(target=reader, name="ur-worker-reader", daemon=True).start()
        try:
            first = replies.get(timeout=self.connect_timeout)
        except queue.Empty:
            first = {"ready": False, "error": "no answer within %.0f s" % self.connect_timeout}
        if not first.get("ready"):
            _kill(proc)
            raise LinkDown("UR controller %s: connection failed: %s" % (self.host, first.get("error", "worker ended")),
                           device="arm")
        with self._io_lock:
            self._proc, self._replies = proc, replies

    def _call(self, op: str, *args: Any, timeout: float = REQUEST_TIMEOUT) -> Any:
        with self._io_lock:
            proc = self._proc
            if proc is None or proc.poll() is not None:
                if self.connections == 0:       # never connected since start: NOT_READY, the arm is stopped first
                    raise NotConnected("UR controller %s is not connected yet (the arm is stopped and its watchdog "
                                       "set before it accepts commands): %s" % (
                                           self.host, self._health.last_error or "connecting"), device="arm")
                raise LinkDown("UR controller %s is not connected (%s)" % (self.host, self._health.last_error
                                                                             or "reconnecting"), device="arm")
            self._ids += 1
            rid = self._ids
            try:
                assert proc.stdin is not None
                proc.stdin.write(json.dumps({"id": rid, "op": op, "args": list(args)}) + "\n")
                proc.stdin.flush()
                while True:
                    reply = self._replies.get(timeout=timeout)
                    if reply.get("eof"):
                        raise LinkDown("UR worker for %s ended during %s" % (self.host, op), device="arm")
                    if reply.get("id") == rid:
                        break
            except (OSError, queue.Empty) as exc:
                self._drop_locked("no answer to %s: %s" % (op, type(exc).__name__))
                raise LinkDown("UR controller %s: no answer to %s" % (self.host, op), device="arm")
        if not reply.get("ok"):
            raise DeviceFault("UR controller %s refused %s: %s" % (self.host, op, reply.get("error")), device="arm")
        return reply.get("result")

    def _drop_locked(self, why: str) -> None:
        proc, self._proc = self._proc, None
        self._link_up.clear()
        self._health.set(link="down", error=why)
        if proc is not None:
            threading.Thread(target=_kill, args=(proc,), daemon=True).start()

    # -- supervisor ----------------------------------------------------------------------------------------
    def start(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._supervise, name="ur-supervisor", daemon=True)
        self._thread.start()

    def _supervise(self) -> None:
        backoff = 0.5
        while not self._stop.is_set():
            if self._proc is None:
                self._health.set(link="connecting")
                try:
                    self._spawn()
                except LinkDown as exc:
                    self._health.set(link="down", error=exc.message)
                    self._stop.wait(backoff)
                    backoff = min(5.0, backoff * 2.0)
                    continue
                self.connections += 1
                if self.connections > 1:
                    self.reconnects += 1
                    log.warning("UR controller %s: reconnected (%d)", self.host, self.reconnects)
                backoff = 0.5
            try:
                self._poll()
            except (LinkDown, DeviceFault) as exc:
                with self._io_lock:
                    self._drop_locked(exc.message)
                log.warning("UR controller %s: link lost: %s", self.host, exc.message)
                continue
            self._stop.wait(1.0 / self.poll_rate)

    def _tick(self, device_t: float, wall_t: Optional[float]) -> Optional[float]:
        """The sample's ``sample_tick``: the previous one plus the controller's time since it (at the sample clock's
        rate, wall seconds per controller second); when the controller's clock went back (a new connection) the
        sample's wall time, at least a second after the previous tick (no speed across the restart)."""
        last = self._last_tick
        if last is None or device_t < last[0] or wall_t is None:
            tick = wall_t if last is None or wall_t is None else max(wall_t, last[1] + 1.0)
        else:
            tick = last[1] + self._sample_clock.rate * (device_t - last[0])
        self._last_tick = None if tick is None else (device_t, tick)
        return tick

    def _poll(self) -> Dict[str, Any]:
        st = self._call("state")
        if not (st["receive_connected"] and st["control_connected"]):
            raise LinkDown("UR controller %s: RTDE connection lost" % self.host, device="arm")
        with self._state_lock:
            self._state = st
            self._state["stamp"] = now = time.time()
            if "timestamp" in st:                 # the controller's clock: when the sample was taken
                self._sample_clock.add(st["timestamp"], now)
                self._state["sample_time"] = self._sample_clock.wall(st["timestamp"])
                self._state["sample_tick"] = self._tick(float(st["timestamp"]), self._state["sample_time"])
        fm = self._force
        if fm is not None and fm.get("recording"):
            fm["samples"].append(-float(sum(a * b for a, b in zip(st["tcp_force"][:3], fm["axis"]))))
        mode = st["safety_mode"]
        if mode not in SAFETY_OK and self._safety is None:
            self._safety = "%s (safety mode %d)" % (SAFETY_NAMES.get(mode, "UNKNOWN").lower().replace("_", " "), mode)
            log.error("UR controller %s: %s latched; RESET_ARM after the cause is removed", self.host, self._safety)
            self._health.set(error="%s latched; RESET_ARM after the cause is removed" % self._safety)
        self._link_up.set()
        device = "safety stop: %s" % self._safety if self._safety else (
            "ok" if st["robot_mode"] == ROBOT_RUNNING and st["program_running"] else
            "robot mode %d, program %s" % (st["robot_mode"], "running" if st["program_running"] else "stopped"))
        self._health.set(link="up", device=device, safety_mode=SAFETY_NAMES.get(mode, str(mode)),
                         reconnects=self.reconnects)
        return st

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(3.0)
            self._thread = None
        with self._io_lock:
            proc, self._proc = self._proc, None
        if proc is not None:
            try:
                assert proc.stdin is not None
                proc.stdin.write(json.dumps({"op": "exit"}) + "\n")
                proc.stdin.flush()
                proc.wait(3.0)
            except Exception:
                pass
            _kill(proc)
        self._link_up.clear()
        self._health.set(link="down", device="closed")

    # -- state -----------------------------------------------------------------------------------------------
    def cached_state(self) -> Dict[str, Any]:
        with self._state_lock:
            return dict(self._state)

    def joint_positions(self) -> List[float]:
        return list(self._call("q"))

    def tcp_pose(self) -> List[float]:
        return list(self._call("tcp"))

    def health(self) -> Dict[str, Any]:
        return self._health.report()

    @property
    def safety_latched(self) -> Optional[str]:
        return self._safety

    def _ready(self) -> Dict[str, Any]:
        """Connection and safety check before a command; returns a fresh state."""
        if not self._link_up.is_set():
            raise NotConnected("UR controller %s is not connected yet (%s)" % (
                self.host, self._health.last_error or "connecting"), device="arm")
        st = self._poll()
        if self._safety:
            raise SafetyStop("arm %s is latched; remove the cause and send RESET_ARM" % self._safety, device="arm")
        if st["robot_mode"] != ROBOT_RUNNING or not st["program_running"]:
            raise DeviceFault("arm not ready: robot mode %d, control program %s" % (
                st["robot_mode"], "running" if st["program_running"] else "not running"), device="arm")
        return st

    # -- motions ---------------------------------------------------------------------------------------------
    def move_joints(self, waiter: Waiter, q: Sequence[float], speed: float, accel: float) -> Dict[str, Any]:
        st = self._ready()
        travel = max(abs(a - b) for a, b in zip(q, st["q"]))
        if travel <= ALREADY_THERE * JOINT_TOL and self._at_rest(st):
            return self._already_there(st)
        return self._motion(waiter, "moveJ", list(q), speed, accel, travel, target_q=list(q))

    def move_linear(self, waiter: Waiter, pose: Sequence[float], speed: float, accel: float) -> Dict[str, Any]:
        st = self._ready()
        travel = distance(pose[:3], st["tcp"][:3]) + ROTATION_WEIGHT * angle_between(pose, st["tcp"])
        if travel <= ALREADY_THERE * LINEAR_TOL and self._at_rest(st):
            return self._already_there(st)
        return self._motion(waiter, "moveL", list(pose), speed, accel, travel, target_pose=list(pose))

    def _at_rest(self, st: Dict[str, Any]) -> bool:
        """The arm stands still outside force mode (a move to where it is then has nothing to do)."""
        return self._force is None and max(abs(v) for v in st["qd"]) < 1e-4

    @staticmethod
    def _already_there(st: Dict[str, Any]) -> Dict[str, Any]:
        """The result of a move whose target is where the arm stands: nothing is sent to the controller (a
        motion of no length shows no movement, and telling it from one that has not started cost 0.2 s)."""
        return {"q": st["q"], "tcp_pose": st["tcp"], "duration_s": 0.0}

    def move_path(self, waiter: Waiter, poses: Sequence[Sequence[float]], speed: float, accel: float,
                  blends: Sequence[float]) -> Dict[str, Any]:
        """Straight segments through ``poses`` as ONE controller path: ``blends[i]`` (m) rounds interior waypoint
        i without stopping (0 stops there); the last waypoint is reached exactly and at rest.

        Raises BadRequest (nothing moves) when a blend radius exceeds half of a neighbouring segment.
        """
        if not poses or len(blends) != len(poses):
            raise BadRequest("MOVE_PATH needs one blend radius per waypoint (%d waypoints, %d radii)"
                             % (len(poses), len(blends)), device="arm", argument="waypoints")
        st = self._ready()
        points = [list(st["tcp"])] + [list(p) for p in poses]
        seg = [distance(points[i][:3], points[i + 1][:3]) for i in range(len(poses))]
        radii = [float(b) for b in blends[:-1]] + [0.0]          # the path ends at rest on its last waypoint
        for i, b in enumerate(radii[:-1]):
            half = min(seg[i], seg[i + 1]) / 2.0
            if b > half + 1e-9:
                raise BadRequest("MOVE_PATH: waypoint %d: blend radius %.4g m is larger than half of a neighbouring "
                                 "segment (%.4g m %s, %.4g m after); allowed at most %.4g m"
                                 % (i + 1, b, seg[i], "from the current TCP" if i == 0 else "before", seg[i + 1],
                                    half), device="arm", argument="waypoints")
        travel = sum(seg) + ROTATION_WEIGHT * sum(angle_between(points[i], points[i + 1])
                                                  for i in range(len(poses)))
        stops = 1 + sum(1 for b in radii[:-1] if b <= 0)
        rows = [list(p) + [speed, accel, b] for p, b in zip(poses, radii)]
        return self._motion(waiter, "movePath", [rows], speed, accel, travel, target_pose=list(poses[-1]),
                            stops=stops, kind="moveL", extra_s=PATH_UPLOAD_S, call_timeout=PATH_CALL_TIMEOUT,
                            waypoints=len(poses))

    def _motion(self, waiter: Waiter, op: str, target: List[Any], speed: float, accel: float, travel: float,
                target_q: Optional[List[float]] = None, target_pose: Optional[List[float]] = None,
                stops: int = 1, kind: Optional[str] = None, extra_s: float = 0.0,
                call_timeout: float = REQUEST_TIMEOUT, waypoints: int = 0) -> Dict[str, Any]:
        budget = self.deadline_scale * (travel / speed + stops * 2.0 * speed / accel) + self.deadline_margin + extra_s
        self._stop_requested = None
        self._motion_kind = kind or op
        waiter.on_cancel(lambda: self.stop_motion("cancelled"))
        start = time.monotonic()
        args = list(target) if waypoints else [target, speed, accel]     # a path: target = [rows]
        if not self._call(op, *args, timeout=call_timeout):
            self._raise_if_safety(fresh=True)
            if waypoints:
                self._restart_script()
                raise DeviceFault("UR controller refused the %d-waypoint path and halted its control script "
                                  "(uploaded again); check reachability and blend radii" % waypoints, device="arm")
            raise DeviceFault("UR controller refused %s to %s" % (op, _fmt(target)), device="arm")
        moving_seen = False
        try:
            while True:
                waiter.sleep(0.01)
                if self._stop_requested:
                    raise Aborted("%s stopped: %s" % (op, self._stop_requested))
                st = self._poll()
                self._raise_if_safety()
                elapsed = time.monotonic() - start
                still = max(abs(v) for v in st["qd"]) < 1e-4
                moving_seen = moving_seen or not still or st["progress"] >= 0
                if st["progress"] < 0 and still and (moving_seen or elapsed > 0.2):
                    break
                if waypoints and st["progress"] >= 0:
                    waiter.report(min(0.99, st["progress"] / float(waypoints)),
                                  "waypoint %d of %d" % (st["progress"] + 1, waypoints))
                elif travel > 0:
                    waiter.report(min(0.99, elapsed / max(budget - self.deadline_margin, 1e-3)), "%s running" % op)
                if elapsed > budget:
                    self.stop_motion("deadline")
                    raise MotionTimeout("%s did not finish within %.2f s (path %.3f, speed %.3f, accel %.3f, "
                                        "stops %d)" % (op, budget, travel, speed, accel, stops), device="arm")
        except BaseException:
            if not self._safety and self._link_up.is_set():
                self.stop_motion("aborted")
            raise
        finally:
            self._motion_kind = ""
        if target_q is not None:
            err = max(abs(a - b) for a, b in zip(st["q"], target_q))
            if err > JOINT_TOL:
                raise DeviceFault("moveJ ended %.4f rad from the target" % err, device="arm")
        if target_pose is not None:
            err = distance(st["tcp"][:3], target_pose[:3])
            fm = self._force
            if fm is not None:      # compliant along the force axis: only the error across it counts
                d = [a - b for a, b in zip(st["tcp"][:3], target_pose[:3])]
                along = sum(a * b for a, b in zip(d, fm["axis"]))
                err = math.sqrt(max(0.0, err * err - along * along))
            if err > LINEAR_TOL:
                raise DeviceFault("%s ended %.4f m from the target" % (op, err), device="arm")
        out = {"q": st["q"], "tcp_pose": st["tcp"], "duration_s": round(time.monotonic() - start, 3)}
        if waypoints:
            out["waypoints"] = waypoints
        return out

    def _restart_script(self) -> None:
        """Upload the control script again after the controller halted it (e.g. a refused path)."""
        try:
            self._call("reupload", timeout=PATH_CALL_TIMEOUT)
            end = time.monotonic() + 5.0
            while not self._poll()["program_running"] and time.monotonic() < end:
                time.sleep(0.02)
        except (LinkDown, DeviceFault) as exc:
            log.warning("UR controller %s: control script not restarted: %s", self.host, exc.message)

    def _raise_if_safety(self, fresh: bool = False) -> None:
        """SafetyStop when a safety stop is latched; ``fresh``: after a state read of its own (a motion refused
        because a protective stop came between two of the 50 Hz polls is reported as that stop, not as a
        refusal the operator cannot act on)."""
        if fresh and not self._safety:
            try:
                self._poll()
            except (LinkDown, DeviceFault):
                pass                          # the refusal is the news; the poll thread handles the link
        if self._safety:
            raise SafetyStop("arm %s; the motion was stopped by the controller; remove the cause and send RESET_ARM"
                             % self._safety, device="arm")

    def inverse_kinematics(self, pose: Sequence[float], qnear: Optional[Sequence[float]] = None) -> List[float]:
        """Joint positions for a TCP pose (controller's IK, closest to ``qnear`` / the current joints)."""
        q = qnear if qnear is not None else self.cached_state().get("q") or self.joint_positions()
        try:
            return [float(v) for v in self._call("ik", list(pose), list(q))]
        except DeviceFault as exc:
            raise BadRequest("pose %s is not reachable by the arm: %s" % (_fmt(pose), exc.message), device="arm")

    def stop_motion(self, reason: str = "") -> None:
        """End force mode, decelerate now (stopL for a linear move, stopJ otherwise); never raises."""
        self._stop_requested = reason or "stop requested"
        if self._force is not None:
            self.force_mode_stop()
        try:
            if self._motion_kind == "moveL":
                self._call("stopL", STOP_DECEL_L, timeout=1.0)
            else:
                self._call("stopJ", STOP_DECEL_J, timeout=1.0)
        except (LinkDown, DeviceFault, NotConnected) as exc:
            log.warning("arm stop: %s", exc.message)

    def stop(self) -> None:
        self.stop_motion("STOP")

    # -- force mode ----------------------------------------------------------------------------------------
    def force_mode_start(self, task_frame: Sequence[float], force: float, speed_limit: float) -> None:
        """Zero the force sensor, then push with ``force`` N along the z axis of ``task_frame`` (a pose in the arm
        base frame), compliant along that axis only, at most ``speed_limit`` m/s along it."""
        self._ready()
        if not self._call("zeroFt"):
            raise DeviceFault("zeroFtSensor refused", device="arm")
        axis = rotvec_to_matrix(task_frame[3:6])[:, 2].tolist()
        self._force = {"axis": axis, "force": float(force), "samples": [], "recording": False}
        ok = self._call("forceMode", list(task_frame), [0, 0, 1, 0, 0, 0], [0.0, 0.0, float(force), 0.0, 0.0, 0.0],
                        2, [FORCE_FREE_SPEED, FORCE_FREE_SPEED, float(speed_limit), 1.0, 1.0, 1.0])
        if not ok:
            self._force = None
            self._raise_if_safety()
            raise DeviceFault("UR controller refused forceMode", device="arm")

    def contact_force(self) -> float:
        """Force (N) the tool applies along the force-mode axis now (0 outside force mode)."""
        fm = self._force
        if fm is None:
            return 0.0
        f = self._poll()["tcp_force"]
        return -float(sum(a * b for a, b in zip(f[:3], fm["axis"])))

    def wait_for_contact(self, waiter: Waiter, tolerance: float, max_travel: float, timeout: float) -> float:
        """Wait until the force along the axis is within ``tolerance`` N of the set-point; DeviceFault naming
        what happened when the tool travels ``max_travel`` m along the axis first or ``timeout`` s pass."""
        fm = self._force
        if fm is None:
            raise DeviceFault("wait_for_contact outside force mode", device="arm")
        start = self._poll()["tcp"]
        end = time.monotonic() + timeout
        while True:
            st = self._poll()
            self._raise_if_safety()
            f = -float(sum(a * b for a, b in zip(st["tcp_force"][:3], fm["axis"])))
            if abs(f - fm["force"]) <= tolerance:
                return f
            travel = sum((a - b) * c for a, b, c in zip(st["tcp"][:3], start[:3], fm["axis"]))
            if travel > max_travel:
                raise DeviceFault("no contact: the tool moved %.1f mm along its axis and feels %.1f N of %.1f N"
                                  % (travel * 1e3, f, fm["force"]), device="arm")
            if time.monotonic() > end:
                raise DeviceFault("contact force %.1f N did not reach %.1f +- %.1f N within %.0f s"
                                  % (f, fm["force"], tolerance, timeout), device="arm")
            waiter.sleep(0.01)

    def record_force(self, on: bool) -> None:
        """Start / stop recording the contact force at every state poll (see :meth:`force_mode_stop`)."""
        if self._force is not None:
            self._force["recording"] = bool(on)

    def force_mode_stop(self) -> Dict[str, float]:
        """Leave force mode (the controller also decelerates any motion); never raises. Returns the recorded
        force (N) along the axis: samples, mean, min, max."""
        fm, self._force = self._force, None
        if fm is not None and not self._safety and self._link_up.is_set():
            try:
                self._call("forceModeStop", timeout=2.0)
            except (LinkDown, DeviceFault, NotConnected) as exc:
                log.warning("force mode stop: %s", exc.message)
        samples = fm["samples"] if fm else []
        if not samples:
            return {"samples": 0}
        return {"samples": len(samples), "mean": sum(samples) / len(samples), "min": min(samples),
                "max": max(samples)}

    def named_pose(self, name: str) -> List[float]:
        if name not in self.named_poses:
            raise BadRequest("no named arm pose '%s'; known: %s" % (name, ", ".join(sorted(self.named_poses))),
                             device="arm", argument="pose")
        return list(self.named_poses[name])

    # -- settings --------------------------------------------------------------------------------------------
    def set_tcp(self, pose: Sequence[float]) -> None:
        self._ready()
        if not self._call("setTcp", list(pose)):
            raise DeviceFault("setTcp refused", device="arm")

    def set_payload(self, mass: float, cog: Sequence[float]) -> None:
        self._ready()
        if not self._call("setPayload", float(mass), list(cog)):
            raise DeviceFault("setPayload refused", device="arm")

    def set_digital_output(self, index: int, value: bool) -> None:
        if not self._link_up.is_set():
            raise NotConnected("UR controller %s is not connected yet" % self.host, device="arm")
        if not self._call("setDO", int(index), bool(value)):
            raise DeviceFault("setStandardDigitalOut(%d) refused" % index, device="arm")
        end = time.monotonic() + 1.0          # confirmed when the controller reports the output
        while bool(self._poll()["do_bits"] >> index & 1) != bool(value):
            if time.monotonic() > end:
                raise DeviceFault("digital output %d did not change to %s within 1 s" % (index, value), device="arm")
            time.sleep(0.005)

    def digital_outputs(self) -> List[bool]:
        bits = self.cached_state().get("do_bits", 0)
        return [bool(bits >> i & 1) for i in range(8)]

    # -- operator reset ------------------------------------------------------------------------------------
    def reset(self, waiter: Waiter) -> Dict[str, Any]:
        if not self._link_up.is_set():
            raise NotConnected("UR controller %s is not connected" % self.host, device="arm")
        st = self._poll()
        steps = []
        mode = st["safety_mode"]
        if mode == 3:                                  # protective stop: unlock (allowed 5 s after the stop)
            end = time.monotonic() + 8.0
            refusal = ""
            while True:
                try:
                    self._call("dash", "unlock_protective_stop")
                except DeviceFault as exc:        # e.g. "Cannot unlock protective stop until 5s after occurrence"
                    refusal = exc.message
                waiter.sleep(0.1)
                st = self._poll()
                if st["safety_mode"] in SAFETY_OK:
                    steps.append("protective stop unlocked")
                    break
                if time.monotonic() > end:
                    raise DeviceFault("RESET_ARM: the protective stop cannot be unlocked (safety mode %s) %s"
                                      % (SAFETY_NAMES.get(st["safety_mode"]), refusal), device="arm")
                waiter.sleep(0.25)
        elif mode in (6, 7) or st["robot_mode"] != ROBOT_RUNNING:
            for cmd in ("close_safety_popup", "power_on", "brake_release"):
                self._call("dash", cmd)
                steps.append(cmd.replace("_", " "))
            with self._io_lock:
                self._drop_locked("restarting the control script after an emergency stop")
        end = time.monotonic() + 15.0
        while True:
            try:
                st = self._poll() if self._link_up.is_set() else None
            except (LinkDown, DeviceFault):
                st = None
            if st and st["safety_mode"] in SAFETY_OK and st["robot_mode"] == ROBOT_RUNNING and st["program_running"]:
                break
            if time.monotonic() > end:
                raise DeviceFault("RESET_ARM: the arm did not come back (safety %s); is the cause removed?"
                                  % (SAFETY_NAMES.get(st["safety_mode"]) if st else "unknown"), device="arm")
            waiter.sleep(0.1)
        cleared, self._safety = self._safety, None
        self._health.set(device="ok")
        return {"cleared": cleared or "", "steps": steps, "safety_mode": SAFETY_NAMES.get(st["safety_mode"])}


def _kill(proc: subprocess.Popen) -> None:
    try:
        if proc.poll() is None:
            proc.kill()
        proc.wait(5.0)
    except Exception:
        pass


def _fmt(values: Sequence[float]) -> str:
    return "[" + ", ".join("%.4f" % v for v in values) + "]"

