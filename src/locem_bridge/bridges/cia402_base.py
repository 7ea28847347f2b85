"""Mobile base over CAN: CiA 402 wheel drives (canopen ``BaseNode402``) and the base control loop, for every
kinematics of :data:`locem_bridge.common.base_kinematics.KINEMATICS` (``robot.base.kind``: ``mecanum``, four
wheels; ``differential``, two).

Lifecycle: ``Cia402Base(base_cfg, eds_path)`` -> :meth:`start` (opens the python-can bus named by
``robot.base.drives.can``; a supervisor thread enables every drive: heartbeat seen, NMT OPERATIONAL, PROFILED
VELOCITY, OPERATION ENABLED; then runs the control loop at ``control_rate`` Hz) -> :meth:`close` (zero velocity,
drives disabled, bus closed).

Each control cycle: check every drive's heartbeat (consumer timeout = ``heartbeat_ms`` x
``consumer_timeout_factor``) and statusword; integrate odometry from the wheel positions (TPDO2, 0x6064) through
the base kinematics; compute the body twist (GOTO closed loop, an open-loop ``/cmd_vel`` twist while it is
fresh, or zero); send the wheel targets (RPDO2, 0x60FF). A silent or faulted drive latches a fault: every drive
is commanded to zero in the same cycle (the drives decelerate at ``stop_deceleration``), running motions end
with :class:`~.errors.DeviceFault` (``HARDWARE_ERROR``). When every drive is back (boot-up, heartbeat) the
supervisor enables them again; nothing moves until the next command.

GOTO deadline (:class:`~.errors.MotionTimeout`, ``TIMEOUT``; the base is commanded to zero before the command
answers)::

    deadline = scale x (max(distance / speed, turn / (0.8 max_angular_velocity)) + 2 speed / linear_acceleration
                        + max_angular_velocity / angular_acceleration) + margin

``scale`` and ``margin`` (s) come from ``robot.base.deadline`` (defaults 1.0 and 5 s). A differential base
turns twice: its deadline counts both turns (see below) instead of the larger of drive and turn.

GOTO on a non-holonomic (differential) base: turn, drive, turn. 1. turn in place toward the goal (or away from
it when the goal lies behind: the base then drives backwards, so it never turns more than pi/2 to aim) until
the heading is within ``ALIGN_TOLERANCE`` of the bearing; 2. drive along the bearing with the same speed profile
as the mecanum base (v^2 = 2 a d, at most ``speed`` and ``max_linear_velocity``), steering onto the bearing
while more than ``STEER_DISTANCE`` is left, until within half the position tolerance; 3. turn in place to the
goal heading. Should the position leave the tolerance again meanwhile, it aims again (1). Same limits (wheel,
linear, angular, accelerations), same completion test (within ``tolerance`` / ``angle_tolerance`` and still) as
the mecanum base. A purely lateral request (``MOVE_BASE_REL dy=0.5``) thus becomes a quarter turn, a straight
drive and a quarter turn back. The deadline::

    deadline = scale x (distance / speed + (turn_1 + turn_2) / (0.8 max_angular_velocity)
                        + 2 speed / linear_acceleration + 3 max_angular_velocity / angular_acceleration
                        + one correction) + margin

(one correction, when the base has to move: :data:`REAIM_TURNS` / (0.8 max_angular_velocity) + 2
max_angular_velocity / angular_acceleration + :data:`REAIM_CREEP_S`: a drive that ends out of the tolerance aims
again.)

Heartbeat consumer: a drive is silent when no heartbeat arrived for ``heartbeat_ms`` x ``consumer_timeout_factor``
(the robot YAML: 100 ms x 2 = 200 ms); the cycle that notices it commands every wheel to zero, so the base stands
still at most that timeout + one control period (20 ms at 50 Hz) + the drives' braking at ``stop_deceleration``
after the last heartbeat.

Heartbeat producer (the drives' safety net when LOCEM dies): the master sends its own heartbeat (node
``drives.master_node_id``, default 127, every ``heartbeat_ms``) and, while enabling each drive, makes the drive
consume it (0x1016 sub 1, timeout ``drives.master_timeout_ms``, default :data:`MASTER_TIMEOUT_MS` = 500 ms, five
heartbeats: a busy machine may delay a few). A drive whose master falls silent for that long stops by itself
(quick stop, PRE-OPERATIONAL; see :mod:`locem_bridge.sim.can.drives`). A drive without 0x1016 is enabled anyway, with a
warning that it will not stop by itself. A fresh master (a respawned LOCEM) commands every wheel to zero before it
enables the drive, so nothing a previous LOCEM left running moves on.

Poses: ``[x, y, theta]`` of base_footprint in ``map``; odometry starts at :meth:`set_pose` (initial pose).
"""

import logging
import math
import threading
import time
from typing import Any, Dict, List, Mapping, Optional, Tuple

from .can_link import open_device_bus
from .config import need
from .errors import BadRequest, DeviceFault, LinkDown, MotionTimeout, NotConnected
from locem_bridge.common.geometry import wrap_angle
from .interfaces import Base, Health, Waiter
from ..common.base_kinematics import WHEEL_ORDER, kinematics_for
from ..common.rate import FixedRate

log = logging.getLogger(__name__)

SW_FAULT = 0x08
MASTER_TIMEOUT_MS = 500
ALIGN_TOLERANCE = 0.02      # rad: a differential base aims at the goal this closely before it drives
# A differential GOTO's deadline allows one correction: a drive that ends out of the position tolerance across its
# heading (a few mm past the tolerance on a busy machine, whose control cycles come late) aims again, at most a
# quarter turn, creeps the rest and makes the last turn from there, up to a half turn more than planned (rad, s).
REAIM_TURNS = 1.5 * math.pi
REAIM_CREEP_S = 1.0
STEER_DISTANCE = 0.05       # m: it steers onto the bearing while farther than this from the goal
LOCALISATION_SILENT_S = 2.0  # s without a localisation fix: none is running (wait_localised does not wait)
FIX_INTERVALS = 2.5          # wait_localised waits at most this many of the fixes' mean interval


class Cia402Base(Base):
    """The base backend (see the module docstring). ``cfg`` is ``robot.base``."""

    capabilities = frozenset({Base.LOCALISATION})

    def __init__(self, cfg: Mapping[str, Any], eds_path: str, initial_pose: Tuple[float, float, float] = (0.0, 0.0, 0.0),
                 bus: Any = None) -> None:
        w = "robot.base"
        drives = need(cfg, "drives", dict, where=w)
        self.can_cfg = dict(need(drives, "can", dict, where=w + ".drives"))
        self.wheels = list(need(drives, "wheels", list, where=w + ".drives"))
        self.base_kind = str(cfg.get("kind", "mecanum"))
        if self.base_kind not in WHEEL_ORDER:
            raise BadRequest("robot.base.kind %r is not known, allowed: %s" % (self.base_kind, ", ".join(WHEEL_ORDER)))
        order = WHEEL_ORDER[self.base_kind]
        if len(self.wheels) != len(order):
            raise BadRequest("robot.base.drives.wheels must list %d wheels (%s) for a %s base, got %d"
                             % (len(order), ", ".join(order), self.base_kind, len(self.wheels)))
        self.node_ids = [int(x["node_id"]) for x in self.wheels]
        self.names = [str(x["name"]) for x in self.wheels]
        self.polarity = [int(x["polarity"]) for x in self.wheels]
        self.vel_scale = need(drives, "velocity_units_per_rad_s", float, lo=1e-6, where=w + ".drives")
        self.pos_scale = need(drives, "counts_per_rad", float, lo=1e-6, where=w + ".drives")
        self.heartbeat_s = need(drives, "heartbeat_ms", float, lo=1.0, where=w + ".drives") / 1000.0
        self.hb_timeout = self.heartbeat_s * need(drives, "consumer_timeout_factor", float, default=1.5, lo=1.0,
                                                  where=w + ".drives")
        self.master_id = need(drives, "master_node_id", int, default=127, lo=1, hi=127, where=w + ".drives")
        self.master_timeout_ms = need(drives, "master_timeout_ms", int, default=MASTER_TIMEOUT_MS, lo=10, hi=65535,
                                      where=w + ".drives")
        self._hb_task: Any = None
        self.accel_units = int(need(drives, "profile_acceleration", float, lo=0.1, where=w + ".drives") * self.vel_scale)
        self.stop_decel_units = int(need(drives, "stop_deceleration", float, default=200.0, lo=1.0,
                                         where=w + ".drives") * self.vel_scale)
        wheel = need(cfg, "wheel", dict, where=w)
        try:
            self.kin = kinematics_for(self.base_kind, wheel)
        except (KeyError, ValueError) as exc:
            raise BadRequest("robot.base.wheel: %s" % exc)
        self.holonomic = self.kin.holonomic
        limits = need(cfg, "limits", dict, where=w)
        self.max_wheel = need(limits, "max_wheel_speed", float, lo=0.1, where=w + ".limits")
        self.max_lin = need(limits, "max_linear_velocity", float, lo=0.01, where=w + ".limits")
        self.max_ang = need(limits, "max_angular_velocity", float, lo=0.01, where=w + ".limits")
        self.lin_accel = need(limits, "linear_acceleration", float, default=0.6, lo=0.01, where=w + ".limits")
        self.ang_accel = need(limits, "angular_acceleration", float, default=1.2, lo=0.01, where=w + ".limits")
        self.rate = need(cfg, "control_rate", float, default=50.0, lo=5.0, hi=1000.0, where=w)
        self.fix_window = int(need(cfg, "localisation_window", float, default=10.0, lo=1.0, hi=1000.0, where=w))
        self.named_poses = {k: [float(x) for x in v] for k, v in dict(cfg.get("named_poses", {}) or {}).items()}
        self.deadline_scale = need(cfg, "deadline.scale", float, default=1.0, lo=0.01, hi=100.0, where=w)
        self.deadline_margin = need(cfg, "deadline.margin", float, default=5.0, lo=0.0, hi=600.0, where=w)
        self.eds_path = eds_path
        self._bus_given = bus
        self._bus: Any = None
        self.network: Any = None
        self.nodes: List[Any] = []
        self._health = Health("connecting")
        self._lock = threading.RLock()
        self._pose = [float(v) for v in initial_pose]
        self._twist = [0.0, 0.0, 0.0]          # measured body twist
        self._cmd = [0.0, 0.0, 0.0]            # commanded body twist (after ramps)
        self._open_loop: Optional[Tuple[List[float], float]] = None
        self._goal: Optional[Dict[str, Any]] = None
        self._last_pos: Optional[List[float]] = None
        self._fixes: List[Tuple[float, float, float]] = []   # localisation fixes taken since the base stopped
        self._fix_offered_at: Optional[float] = None         # when the last fix came (taken or not), monotonic
        self._fix_interval: Optional[float] = None           # the fixes' mean interval (s, while they come)
        #: a localisation source is configured (LOCEM's localisation_topic): before its first fix, wait_localised
        #: waits for one too (a restarted LOCEM's pose is the configured start until then)
        self.localisation_expected = False
        self._last_hb = [0.0] * len(self.wheels)
        self._enabled = False
        self._fault: Optional[str] = None
        self._fault_kind = ""
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.cycles = 0
        self.loop_started = 0.0
        self._loop_rate: Optional[FixedRate] = None
        self.stop_latency: Optional[float] = None

    # -- lifecycle ---------------------------------------------------------------------------------------
    def _open_bus(self) -> Any:
        return open_device_bus(self.can_cfg, "base")

    def start(self) -> None:
        import canopen

        self._bus = self._bus_given or self._open_bus()
        self.network = canopen.Network(self._bus)
        self.network.connect()
        for node_id in self.node_ids:
            node = canopen.BaseNode402(node_id, self.eds_path)
            self.network.add_node(node)
            self.nodes.append(node)
        for i, node_id in enumerate(self.node_ids):
            self.network.subscribe(0x700 + node_id, self._heartbeat_cb(i))
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="base-control", daemon=True)
        self._thread.start()

    def _heartbeat_cb(self, i: int) -> Any:
        def on_heartbeat(can_id: int, data: bytes, timestamp: float) -> None:
            self._last_hb[i] = time.monotonic()
        return on_heartbeat

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(3.0)
            self._thread = None
        if self._hb_task is not None:
            try:
                self._hb_task.stop()
            except Exception:
                pass
            self._hb_task = None
        if self.network is not None:
            try:
                self._send_wheels([0.0] * len(self.nodes))
            except Exception:
                pass
            for node in self.nodes:
                try:
                    node.rpdo[1]["Controlword"].raw = 0x06
                    node.rpdo[1].transmit()
                except Exception:
                    pass
            try:
                self.network.disconnect() if self._bus_given is None else self.network.notifier.stop(1.0)
            except Exception:
                pass
            self.network = None
        self._health.set(link="down", device="closed")

    # -- enabling ----------------------------------------------------------------------------------------
    def _enable_all(self) -> None:
        if self._hb_task is None:               # heartbeat producer first: the drives' monitoring starts with it
            self._hb_task = self.network.send_periodic(0x700 + self.master_id, b"\x05", self.heartbeat_s)
        for i, node in enumerate(self.nodes):
            node.nmt.wait_for_heartbeat(max(1.0, 3 * self.heartbeat_s))
            try:
                node.sdo[0x1016][1].raw = (self.master_id << 16) | self.master_timeout_ms
            except Exception as exc:  # SdoAbortedError / KeyError: the drive has no heartbeat consumer
                log.warning("base: drive %d has no heartbeat consumer (0x1016: %s): it will not stop by itself when "
                            "LOCEM dies", self.node_ids[i], exc)
            node.setup_402_state_machine()
            node.nmt.state = "OPERATIONAL"
            node.op_mode = "PROFILED VELOCITY"
            node.sdo[0x6083].raw = self.accel_units
            node.sdo[0x6084].raw = self.stop_decel_units
            node.rpdo[2]["Target velocity"].raw = 0
            node.rpdo[2].transmit()
            node.state = "OPERATION ENABLED"
            node.tpdo_values.pop(0x6041, None)     # a statusword cached before the enable (e.g. FAULT) is stale
            self._last_hb[i] = time.monotonic()
        with self._lock:
            self._last_pos = None
            self._enabled = True
            self._fault = None
            self._cmd = [0.0, 0.0, 0.0]

    def _run(self) -> None:
        backoff = 0.5
        while not self._stop.is_set():
            if not self._enabled:
                self._health.set(link="connecting")
                try:
                    self._enable_all()
                    backoff = 0.5
                    self._health.set(link="up", device="ok")
                    log.info("base: drives %s enabled", self.node_ids)
                except Exception as exc:  # canopen raises several kinds (SdoCommunicationError, RuntimeError, ...)
                    self._health.set(link="down", error="enabling the drives failed: %s: %s" % (type(exc).__name__, exc))
                    self._stop.wait(backoff)
                    backoff = min(5.0, backoff * 2.0)
                    continue
            self._control_loop()

    def _control_loop(self) -> None:
        period = 1.0 / self.rate
        self.loop_started = time.monotonic()
        self.cycles = 0
        rate = self._loop_rate = FixedRate(period, self._stop)
        while rate.running() and self._enabled:
            try:
                self._cycle(time.monotonic(), period)
            except Exception as exc:
                log.exception("base control cycle failed")
                self._latch("control cycle failed: %s" % exc)
            self.cycles += 1
            rate.sleep()

    def loop_rate(self) -> Dict[str, float]:
        elapsed = time.monotonic() - self.loop_started if self.loop_started else 0.0
        achieved = self.cycles / elapsed if elapsed > 0 else 0.0
        return {"configured_hz": self.rate, "achieved_hz": achieved, "cycles": self.cycles,
                "late": self._loop_rate.late if self._loop_rate is not None else 0}

    # -- one cycle ---------------------------------------------------------------------------------------
    def _latch(self, why: str, kind: str = "other") -> None:
        with self._lock:
            first = self._fault is None
            self._fault = why
            if first:
                self._fault_kind = kind
            self._cmd = [0.0, 0.0, 0.0]
            self._open_loop = None
        try:
            self._send_wheels([0.0] * len(self.nodes))
        except Exception:
            pass
        if first:
            log.error("base stopped: %s", why)
            self._health.set(device="fault: %s" % why, error=why)

    def _cycle(self, now: float, period: float) -> None:
        # 1. heartbeat consumer and drive state
        for i, node in enumerate(self.nodes):
            silent = now - self._last_hb[i]
            if silent > self.hb_timeout:
                self._latch("drive %d (%s) heartbeat lost (silent %.0f ms, timeout %.0f ms)"
                            % (self.node_ids[i], self.names[i], silent * 1000, self.hb_timeout * 1000), "heartbeat")
            sw = node.tpdo_values.get(0x6041)
            if sw is not None and sw & SW_FAULT:
                self._latch("drive %d (%s) reports FAULT (statusword 0x%04X)" % (self.node_ids[i], self.names[i], sw),
                            "drive")
        # 2. odometry, also while the base brakes after a fault (that motion is real)
        self._odometry()
        if self._fault is not None:
            self._send_wheels([0.0] * len(self.nodes))
            self._maybe_recover(now)
            return
        # 3. command
        twist = self._command(period)
        self._send_wheels(self.kin.wheel_speeds(*twist))

    def _maybe_recover(self, now: float) -> None:
        """After a heartbeat loss: re-enable once every drive's heartbeat is back (a rebooted drive must be enabled
        again). A drive FAULT stays latched until :meth:`reset` (RESET_BASE, an operator's decision)."""
        if self._fault_kind == "heartbeat" and all(now - t < self.hb_timeout for t in self._last_hb):
            with self._lock:
                self._enabled = False              # the supervisor enables the drives again
            self._health.set(link="connecting")

    def _odometry(self) -> None:
        pos = []
        for node, pol in zip(self.nodes, self.polarity):
            counts = node.tpdo_values.get(0x6064)
            if counts is None:
                return
            pos.append(pol * counts / self.pos_scale)
        with self._lock:
            if self._last_pos is not None:
                d = [a - b for a, b in zip(pos, self._last_pos)]
                dx, dy, dth = self.kin.twist(d)
                x, y, yaw = self._pose
                if abs(dth) > 1e-9:                 # along the arc of a constant twist over the cycle
                    s, c = math.sin(dth) / dth, (1.0 - math.cos(dth)) / dth
                    dx, dy = dx * s - dy * c, dx * c + dy * s
                self._pose = [x + math.cos(yaw) * dx - math.sin(yaw) * dy, y + math.sin(yaw) * dx + math.cos(yaw) * dy,
                              wrap_angle(yaw + dth)]
            self._last_pos = pos
            speeds = []
            for node, pol in zip(self.nodes, self.polarity):
                v = node.tpdo_values.get(0x606C)
                speeds.append(pol * (v or 0) / self.vel_scale)
            self._twist = list(self.kin.twist(speeds))

    def _command(self, period: float) -> List[float]:
        with self._lock:
            goal = self._goal
            if goal is not None:
                target = self._goal_twist(goal)
            elif self._open_loop is not None and time.monotonic() < self._open_loop[1]:
                target = list(self._open_loop[0])
            else:
                self._open_loop = None
                target = [0.0, 0.0, 0.0]
            # acceleration ramps, speeding up only: a slower command is passed on at once and the drives brake
            # at their own profile deceleration (0x6084/0x6083, on the device's clock). A ramp on this loop's
            # clock would also stretch braking whenever the devices run faster than it (a time-scaled
            # simulation, a stalled cycle) and overshoot the goal.
            cmd = list(self._cmd)
            if (math.hypot(target[0], target[1]) <= math.hypot(cmd[0], cmd[1])
                    and target[0] * cmd[0] + target[1] * cmd[1] >= 0.0):
                cmd[0], cmd[1] = target[0], target[1]
            else:
                dv = [target[0] - cmd[0], target[1] - cmd[1]]
                norm = math.hypot(*dv)
                step = self.lin_accel * period
                if norm > step:
                    dv = [dv[0] * step / norm, dv[1] * step / norm]
                cmd[0] += dv[0]
                cmd[1] += dv[1]
            dw = target[2] - cmd[2]
            if abs(target[2]) <= abs(cmd[2]) and target[2] * cmd[2] >= 0.0:
                cmd[2] = target[2]
            else:
                cmd[2] += max(-self.ang_accel * period, min(self.ang_accel * period, dw))
            cmd = list(self.kin.scale_to_limit(cmd[0], cmd[1], cmd[2], self.max_wheel))
            self._cmd = cmd
            return cmd

    def _goal_twist(self, goal: Dict[str, Any]) -> List[float]:
        if not self.holonomic:
            return self._goal_twist_turn_drive_turn(goal)
        x, y, yaw = self._pose
        ex, ey = goal["x"] - x, goal["y"] - y
        eth = wrap_angle(goal["theta"] - yaw)
        dist = math.hypot(ex, ey)
        if dist <= goal["tolerance"] and abs(eth) <= goal["angle_tolerance"]:
            if math.hypot(self._twist[0], self._twist[1]) < 0.01 and abs(self._twist[2]) < 0.02:
                goal["reached"].set()
            return [0.0, 0.0, 0.0]
        # linear: toward the goal, slowing down so it can stop (v^2 = 2 a d) and proportionally near it
        v = 0.0
        if dist > 0.3 * goal["tolerance"]:
            v = min(goal["speed"], math.sqrt(2.0 * self.lin_accel * 0.8 * dist), 1.5 * dist)
            v = max(v, 0.01)
        w = 0.0
        if abs(eth) > 0.3 * goal["angle_tolerance"]:
            w = min(self.max_ang, math.sqrt(2.0 * self.ang_accel * 0.8 * abs(eth)), 2.0 * abs(eth))
            w = math.copysign(max(w, 0.01), eth)
        if dist > 1e-9:
            c, s = math.cos(-yaw), math.sin(-yaw)
            bx, by = (c * ex - s * ey) / dist, (s * ex + c * ey) / dist
        else:
            bx = by = 0.0
        return [v * bx, v * by, w]

    def _linear_speed(self, goal: Dict[str, Any], dist: float) -> float:
        """Speed toward a goal ``dist`` away: slowing down so it can stop (v^2 = 2 a d), proportional near it."""
        return max(min(goal["speed"], math.sqrt(2.0 * self.lin_accel * 0.8 * dist), 1.5 * dist), 0.01)

    def _turn_rate(self, err: float, tolerance: float) -> float:
        """Angular speed toward a heading ``err`` rad away (same profile as the mecanum base)."""
        if abs(err) <= 0.3 * tolerance:
            return 0.0
        w = min(self.max_ang, math.sqrt(2.0 * self.ang_accel * 0.8 * abs(err)), 2.0 * abs(err))
        return math.copysign(max(w, 0.01), err)

    def _goal_twist_turn_drive_turn(self, goal: Dict[str, Any]) -> List[float]:
        """A differential base's GOTO cycle (see the module docstring): aim, drive, turn to the goal heading."""
        x, y, yaw = self._pose
        ex, ey = goal["x"] - x, goal["y"] - y
        dist = math.hypot(ex, ey)
        eth = wrap_angle(goal["theta"] - yaw)
        tol = goal["tolerance"]
        still = math.hypot(self._twist[0], self._twist[1]) < 0.01 and abs(self._twist[2]) < 0.02
        phase = goal.setdefault("phase", "aim" if dist > tol else "turn")
        if phase == "turn" and dist > tol:
            phase = "aim"                          # pushed out of the tolerance: aim again
        if phase in ("aim", "drive"):
            bearing = math.atan2(ey, ex)
            err = wrap_angle(bearing - yaw)
            if phase == "aim":
                goal["reverse"] = abs(err) > math.pi / 2.0      # goal behind: drive backwards
            if goal.get("reverse"):
                err = wrap_angle(err + math.pi)
            if phase == "aim":
                if abs(err) <= ALIGN_TOLERANCE and still:
                    phase = "drive"
                else:
                    goal["phase"] = phase
                    return [0.0, 0.0, self._turn_rate(err, ALIGN_TOLERANCE) if abs(err) > ALIGN_TOLERANCE else 0.0]
            along = ex * math.cos(yaw) + ey * math.sin(yaw)
            if goal.get("reverse"):
                along = -along
            if along <= 0.3 * tol or dist <= 0.5 * tol:
                phase = "turn" if dist <= tol else "aim"   # passed it, or close enough: stop driving
                goal["phase"] = phase
                return [0.0, 0.0, 0.0]
            v = self._linear_speed(goal, along) * max(0.0, math.cos(err))
            w = 0.0
            if dist > STEER_DISTANCE:
                w = max(-self.max_ang, min(self.max_ang, 2.0 * err))
            goal["phase"] = "drive"
            return [-v if goal.get("reverse") else v, 0.0, w]
        goal["phase"] = "turn"
        if dist <= tol and abs(eth) <= goal["angle_tolerance"]:
            if still:
                goal["reached"].set()
            return [0.0, 0.0, 0.0]
        return [0.0, 0.0, self._turn_rate(eth, goal["angle_tolerance"])]

    def _send_wheels(self, wheels: List[float]) -> None:
        for node, pol, speed in zip(self.nodes, self.polarity, wheels):
            node.rpdo[2]["Target velocity"].raw = int(round(pol * speed * self.vel_scale))
            node.rpdo[2].transmit()

    # -- interface ---------------------------------------------------------------------------------------
    def _ready(self) -> None:
        if self._fault is not None:
            raise DeviceFault("base stopped: %s" % self._fault, device="base")
        if not self._enabled:
            raise NotConnected("base drives are not enabled yet (%s)" % (self._health.last_error or "enabling"),
                               device="base")

    def pose(self) -> List[float]:
        with self._lock:
            return list(self._pose)

    def set_pose(self, x: float, y: float, theta: float) -> None:
        with self._lock:
            self._pose = [float(x), float(y), wrap_angle(float(theta))]
            self._fixes = []

    def correct_pose(self, x: float, y: float, theta: float, still_speed: float = 0.005,
                     still_rate: float = 0.01) -> bool:
        """A localisation fix (map frame, e.g. AMCL's pose or the simulator's), used while the base stands
        still and runs no GOTO, so wheel odometry drift does not add up over a job: the first fix after the
        base stopped replaces the odometry pose, and from then on the pose is the mean of the last
        ``robot.base.localisation_window`` fixes since it stopped (independent fix noise shrinks with their
        number instead of jumping the pose by it on every fix: a wall command's targets, computed one after the
        other, then agree). Ignored while the base moves (the fix would be late by its latency); moving clears
        the fixes. Returns whether it was taken."""
        with self._lock:
            now = time.monotonic()
            if self._fix_offered_at is not None and now - self._fix_offered_at <= LOCALISATION_SILENT_S:
                gap = now - self._fix_offered_at
                self._fix_interval = gap if self._fix_interval is None else 0.8 * self._fix_interval + 0.2 * gap
            self._fix_offered_at = now
            vx, vy, wz = self._twist
            if self._goal is not None or math.hypot(vx, vy) > still_speed or abs(wz) > still_rate:
                self._fixes = []
                return False
            self._fixes.append((float(x), float(y), float(theta)))
            del self._fixes[:-self.fix_window]
            n = float(len(self._fixes))
            mean_yaw = math.atan2(sum(math.sin(f[2]) for f in self._fixes), sum(math.cos(f[2]) for f in self._fixes))
            self._pose = [sum(f[0] for f in self._fixes) / n, sum(f[1] for f in self._fixes) / n,
                          wrap_angle(mean_yaw)]
            return True

    def wait_localised(self, waiter: Waiter, timeout: float) -> Optional[str]:
        """The first fix after the base stopped replaces the odometry pose, by the odometry's drift over the drive
        (a centimetre after a long drive on a busy machine): a wall command whose targets were computed partly
        before that fix and partly after it would run its tool off the line by as much (a taping piece that
        started 1 cm off the wall left 10 cm of its joint bare). Waits for that fix while fixes come (one within
        LOCALISATION_SILENT_S), at most ``timeout`` and FIX_INTERVALS of their mean interval (a source that
        publishes only while the base moves, as AMCL does, costs that long); before the first fix of a
        :attr:`localisation_expected` source, at most ``timeout``. Later fixes move the pose by their averaged
        noise only."""
        start = time.monotonic()
        while True:
            with self._lock:
                if self._fixes:
                    return None
                offered, interval = self._fix_offered_at, self._fix_interval
            now = time.monotonic()
            if offered is None:
                if not self.localisation_expected:
                    return None                              # no localisation: odometry it is
                limit = timeout
            elif now - offered > LOCALISATION_SILENT_S:
                return None                                  # fixes stopped coming: odometry it is
            else:
                limit = timeout if interval is None else min(timeout, max(FIX_INTERVALS * interval, 0.05))
            if now - start >= limit:
                return ("base: no localisation fix taken within %.2f s of a wall command's start, the base standing "
                        "still (%s); its targets come from odometry" % (
                            now - start, "no fix yet" if offered is None else "the last came %.2f s ago"
                            % (now - offered)))
            waiter.sleep(0.01)

    def twist(self) -> List[float]:
        with self._lock:
            return list(self._twist)

    def set_velocity(self, vx: float, vy: float, wz: float, hold: float = 0.5) -> None:
        if self._fault is not None or not self._enabled:
            return
        vx = max(-self.max_lin, min(self.max_lin, vx))
        vy = max(-self.max_lin, min(self.max_lin, vy)) if self.holonomic else 0.0   # a differential base: no vy
        wz = max(-self.max_ang, min(self.max_ang, wz))
        with self._lock:
            if self._goal is None:
                self._open_loop = ([vx, vy, wz], time.monotonic() + hold)
                if vx or vy or wz:
                    self._fixes = []               # the base will move: fixes from before no longer apply

    def goto(self, waiter: Waiter, x: float, y: float, theta: float, tolerance: float, angle_tolerance: float,
             speed: float) -> Dict[str, Any]:
        self._ready()
        start = self.pose()
        dist = math.hypot(x - start[0], y - start[1])
        turn = abs(wrap_angle(theta - start[2]))
        speed = min(speed, self.max_lin)
        if self.holonomic:
            budget = self.deadline_scale * (max(dist / speed, turn / (0.8 * self.max_ang))
                                            + 2.0 * speed / self.lin_accel + self.max_ang / self.ang_accel)
        else:                                   # turn, drive, turn (each aim turn at most pi/2: it may reverse)
            bearing = math.atan2(y - start[1], x - start[0])
            aim = abs(wrap_angle(bearing - start[2]))
            heading = start[2] if dist <= tolerance else (bearing if aim <= math.pi / 2.0 else bearing + math.pi)
            aim = min(aim, math.pi - aim)
            last = abs(wrap_angle(theta - heading))
            budget = self.deadline_scale * (dist / speed + (aim + last) / (0.8 * self.max_ang)
                                            + 2.0 * speed / self.lin_accel + 3.0 * self.max_ang / self.ang_accel)
            if dist > tolerance:                # one correction: ended out of the tolerance across its heading, it
                budget += self.deadline_scale * (REAIM_TURNS / (0.8 * self.max_ang)       # aims again (at most
                                                 + 2.0 * self.max_ang / self.ang_accel + REAIM_CREEP_S)   # pi/2)
        budget += self.deadline_margin
        goal = {"x": x, "y": y, "theta": wrap_angle(theta), "tolerance": tolerance,
                "angle_tolerance": angle_tolerance, "speed": speed, "reached": threading.Event()}
        t0 = time.monotonic()
        with self._lock:
            self._goal = goal
            self._open_loop = None
            self._fixes = []
        waiter.on_cancel(self.halt)
        try:
            while not goal["reached"].is_set():
                waiter.sleep(0.02)
                if self._fault is not None:
                    raise DeviceFault("base stopped during GOTO: %s" % self._fault, device="base")
                if not self._enabled:
                    raise LinkDown("base drives were disabled during GOTO", device="base")
                if self._goal is not goal:
                    from locem_bridge.locem.errors import Aborted
                    raise Aborted("GOTO stopped by STOP_BASE")
                p = self.pose()
                left = math.hypot(x - p[0], y - p[1])
                waiter.report(1.0 - min(1.0, left / dist) if dist > 1e-6 else 0.5, "%.3f m to go" % left)
                if time.monotonic() - t0 > budget:
                    raise MotionTimeout("GOTO did not reach (%.3f, %.3f, %.3f) within %.1f s (at %s)"
                                        % (x, y, theta, budget, ", ".join("%.3f" % v for v in p)), device="base")
        finally:
            with self._lock:
                if self._goal is goal:
                    self._goal = None
        p = self.pose()
        return {"pose": p, "error_xy": math.hypot(x - p[0], y - p[1]), "error_theta": abs(wrap_angle(theta - p[2])),
                "duration_s": round(time.monotonic() - t0, 3)}

    def halt(self) -> None:
        """Zero velocity now (drives decelerate at stop_deceleration); ends a GOTO."""
        with self._lock:
            self._goal = None
            self._open_loop = None
            self._cmd = [0.0, 0.0, 0.0]
        if self.network is not None and self._enabled:
            try:
                self._send_wheels([0.0] * len(self.nodes))
            except Exception as exc:
                log.warning("base halt: %s", exc)

    def stop(self) -> None:
        self.halt()

    def reset(self, waiter: Waiter, timeout: float = 15.0) -> Dict[str, Any]:
        """Operator reset after a drive fault: fault reset and enable every drive again (the base stays still)."""
        cleared = self._fault or ""
        with self._lock:
            self._enabled = False           # the supervisor runs the enable sequence (fault reset included)
            self._fault = None
            self._fault_kind = ""
        end = time.monotonic() + timeout
        while not (self._enabled and self._fault is None):
            if time.monotonic() > end:
                raise DeviceFault("RESET_BASE: drives not enabled within %.0f s (%s)"
                                  % (timeout, self._fault or self._health.last_error), device="base")
            waiter.sleep(0.05)
        waiter.sleep(3.0 / self.rate)              # a few control cycles with fresh drive states
        if self._fault is not None:
            raise DeviceFault("RESET_BASE: the drives fault again: %s" % self._fault, device="base")
        return {"cleared": cleared}

    def named_pose(self, name: str) -> List[float]:
        if name not in self.named_poses:
            raise BadRequest("no named base pose '%s'; known: %s" % (name, ", ".join(sorted(self.named_poses))
                                                                     or "none configured (robot.base.named_poses)"),
                             device="base", argument="name")
        return list(self.named_poses[name])

    def health(self) -> Dict[str, Any]:
        report = self._health.report()
        report["fault"] = self._fault or ""
        report["pose"] = [round(v, 4) for v in self.pose()]
        report.update({k: round(v, 2) if isinstance(v, float) else v for k, v in self.loop_rate().items()})
        return report
