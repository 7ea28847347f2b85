"""The plasterboard commands, composed from the atomic device operations ("multiple atomic actions using a single
ROS action call"): SCAN, MOUNT_TOOL, APPLY_TAPE_START, APPLY_TAPE, SPRAY_AREA, SAND_AREA, HOME.

Every number comes from HICEM (line endpoints, area rectangle, wall normal, offsets, speeds) in the ``map``
frame; LOCEM never knows feature ids. Geometry: the map point is expressed in the UR ``base`` frame through the
base odometry pose and ``robot.arm.mount``; the TCP faces the wall (tool z axis against the inward wall
normal, tool x axis horizontal). Approaches to a wall use a joint move to the controller's IK solution, the
work itself straight moves (MOVE_L semantics, 1 mm accuracy).

Process outputs are switched from ``robot.tools.<tool>.switch``: a UR standard digital output (taping tool,
sander) or the compressor's spray valve. Whatever ends a command (success, error, cancel, STOP, deadline), the
process output is switched off before the command answers; a compressor link lost mid SPRAY_AREA ends the
command with ``HARDWARE_ERROR`` within one second (the valve is closed when the link returns).
"""

import math
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence

import numpy as np

from locem_bridge.locem.errors import NotReady
from locem_bridge.locem.registry import Arg, CommandSpec

from .commands_compressor import wait_for_pressure
from .errors import BadRequest, BridgeError
from .geometry import arm_base_in_footprint, invert, matrix_to_pose, planar, tool_frame_facing

CATEGORY = "wall"
TOOLS = ("taping_tool", "spray_gun", "sander")
EXT = 100.0
APPROACH_SPEED = 0.25          # m/s, free moves near the wall
CONTACT_SPEED = 0.05           # m/s, the last centimetres to the wall


def _point(prefix: str, doc: str, suffix: str = "") -> tuple:
    return tuple(Arg.number("%s%s%s" % (prefix, c, suffix), "m", -EXT, EXT, "%s %s (map)" % (doc, c)) for c in "xyz")


def _normal() -> tuple:
    return tuple(Arg.number("n%s" % c, "", -1.0, 1.0, "inward wall normal %s (map; normalised by LOCEM)" % c)
                 for c in "xyz")


def _line_len(v: Mapping[str, Any]) -> float:
    return math.sqrt((v["x1"] - v["x0"]) ** 2 + (v["y1"] - v["y0"]) ** 2 + (v["z1"] - v["z0"]) ** 2)


def _raster_len(v: Mapping[str, Any]) -> float:
    lanes = math.ceil(v["height"] / v["spacing"]) + 1
    return lanes * (v["width"] + v["spacing"] + 0.4)


_LINE_ARGS = _point("", "line start", "0") + _point("", "line end", "1")
_WORK_RESULT = (("length_m", "length worked"), ("duration_s", "seconds"))

SCAN = CommandSpec(
    "SCAN", "Detect the wall joints and areas visible from the current base pose (docs/contracts.md shape).",
    resources=frozenset({"scanner"}), category=CATEGORY, timeout=10.0,
    result=(("stamp", "time of the scan"), ("walls", "walls seen"), ("joints", "joint lines: start, end, kind"),
            ("areas", "wall areas: origin, u, width, height")))
MOUNT_TOOL = CommandSpec(
    "MOUNT_TOOL", "Make the operator-mounted tool active: TCP offset and payload from the robot configuration.",
    args=(Arg.choice("tool", TOOLS, "the tool the operator mounted"),), resources=frozenset({"arm", "tool"}),
    category=CATEGORY, timeout=5.0, result=(("tool", "active tool"), ("tcp", "TCP offset"), ("mass", "kg")))
APPLY_TAPE_START = CommandSpec(
    "APPLY_TAPE_START", "Bring the taping tool in front of a line's start for the operator to judge (tool off).",
    args=_LINE_ARGS + _normal() + (Arg.number("approach", "m", 0.0, 0.5, "distance in front of the wall", default=0.05,
                              keyword_only=True),),
    resources=frozenset({"arm", "tool"}), category=CATEGORY, timeout=60.0, result=(("tcp_pose", "arm base frame"),))
APPLY_TAPE = CommandSpec(
    "APPLY_TAPE", "Tape a joint line: approach its start, taping tool on, follow the line, tool off, retract.",
    args=APPLY_TAPE_START.args[:9] + (
        Arg.number("speed", "m/s", 0.01, 0.5, "speed along the line", default=0.1, keyword_only=True),
        Arg.number("offset", "m", -0.01, 0.05, "TCP distance from the wall surface while taping", default=0.0,
                   keyword_only=True),
        Arg.number("approach", "m", 0.01, 0.5, "approach / retract distance", default=0.05, keyword_only=True)),
    resources=frozenset({"arm", "tool"}), category=CATEGORY, timeout=120.0, result=_WORK_RESULT,
    deadline=lambda v: _line_len(v) / v["speed"] + 60.0)
_AREA_ARGS = _point("o", "area origin") + (
    Arg.number("ux", "", -1.0, 1.0, "along-wall unit vector x"), Arg.number("uy", "", -1.0, 1.0, "along-wall unit vector y"),
    Arg.number("uz", "", -1.0, 1.0, "along-wall unit vector z"),
    Arg.number("width", "m", 0.01, 10.0, "extent along u"), Arg.number("height", "m", 0.01, 5.0, "extent upwards"))
SPRAY_AREA = CommandSpec(
    "SPRAY_AREA", "Spray an area in horizontal raster lanes: compressor on, pressure reached, valve open only on "
    "the lanes, closed at the end and on any error.",
    args=_AREA_ARGS + _normal() + (
        Arg.number("spacing", "m", 0.02, 1.0, "distance between lanes", default=0.2, keyword_only=True),
        Arg.number("standoff", "m", 0.05, 1.0, "nozzle to wall", default=0.3, keyword_only=True),
        Arg.number("speed", "m/s", 0.01, 1.0, "speed along a lane", default=0.4, keyword_only=True),
        Arg.number("pressure", "bar", 0.5, 10.0, "spray pressure", default=2.5, keyword_only=True)),
    resources=frozenset({"arm", "tool", "compressor"}), category=CATEGORY, timeout=600.0, result=_WORK_RESULT
    + (("lanes", "lanes sprayed"),), deadline=lambda v: _raster_len(v) / v["speed"] * 2.0 + 90.0)
SAND_AREA = CommandSpec(
    "SAND_AREA", "Sand an area in horizontal raster lanes in contact with the wall, sander on only on the lanes.",
    args=_AREA_ARGS + _normal() + (
        Arg.number("spacing", "m", 0.02, 1.0, "distance between lanes", default=0.1, keyword_only=True),
        Arg.number("speed", "m/s", 0.01, 0.5, "speed along a lane", default=0.15, keyword_only=True),
        Arg.number("force", "N", 0.0, 100.0, "contact force set-point (position-controlled contact: the UR "
                   "stand-in has no force mode)", default=20.0, keyword_only=True)),
    resources=frozenset({"arm", "tool"}), category=CATEGORY, timeout=600.0, result=_WORK_RESULT
    + (("lanes", "lanes sanded"),), deadline=lambda v: _raster_len(v) / v["speed"] * 2.0 + 90.0)
HOME = CommandSpec(
    "HOME", "Process outputs off, arm to its home pose.", resources=frozenset({"arm", "tool"}), category=CATEGORY,
    timeout=60.0, result=(("q", "joint positions"),))

SPECS = (SCAN, MOUNT_TOOL, APPLY_TAPE_START, APPLY_TAPE, SPRAY_AREA, SAND_AREA, HOME)


class GuardedWaiter:
    """A waiter that also runs ``guard()`` (e.g. the compressor link check) whenever it sleeps or checks."""

    def __init__(self, ctx: Any, guard: Callable[[], None]) -> None:
        self._ctx = ctx
        self._guard = guard

    def sleep(self, seconds: float) -> None:
        self._ctx.sleep(seconds)
        self._guard()

    def check(self) -> None:
        self._ctx.check()
        self._guard()

    def on_cancel(self, callback: Callable[[], None]) -> None:
        self._ctx.on_cancel(callback)

    def report(self, progress: float, text: str = "") -> None:
        self._ctx.report(progress, text)


class WallCommands:
    """Composed plasterboard commands over an arm, a base (pose), a compressor and a scanner (any may be None:
    the commands that need a missing one answer NOT_READY)."""

    name = "wall"

    def __init__(self, robot_cfg: Mapping[str, Any], arm: Any = None, base: Any = None, compressor: Any = None,
                 scanner: Any = None) -> None:
        self.tools = dict(robot_cfg.get("tools", {}))
        mount = robot_cfg.get("arm", {}).get("mount", {})
        self.mount = arm_base_in_footprint(mount.get("xyz", [0.0, 0.0, 0.0]), mount.get("rpy", [0.0, 0.0, 0.0]))
        self.arm, self.base, self.compressor, self.scanner = arm, base, compressor, scanner
        self.active_tool: Optional[str] = None

    def specs(self) -> Iterable[CommandSpec]:
        return SPECS

    def handlers(self) -> Dict[str, Any]:
        return {"SCAN": self.scan, "MOUNT_TOOL": self.mount_tool, "APPLY_TAPE_START": self.apply_tape_start,
                "APPLY_TAPE": self.apply_tape, "SPRAY_AREA": self.spray_area, "SAND_AREA": self.sand_area,
                "HOME": self.home}

    def stop(self) -> None:
        self._outputs_off()

    def health(self) -> Dict[str, Any]:
        return {"link": "up", "device": "ok", "last_error": "", "active_tool": self.active_tool or ""}

    # -- helpers -----------------------------------------------------------------------------------------
    def _need(self, what: str) -> Any:
        dev = getattr(self, what)
        if dev is None:
            raise NotReady("this robot has no %s backend configured" % what)
        return dev

    def _need_tool(self, tool: str) -> None:
        if self.active_tool != tool:
            raise NotReady("the %s is needed but the active tool is %s; mount it and send MOUNT_TOOL %s"
                           % (tool, self.active_tool or "none", tool))

    def to_arm(self, point: Sequence[float], normal: Sequence[float]) -> List[float]:
        """TCP pose (arm base frame) at a map ``point`` facing the wall with inward ``normal``."""
        x, y, th = self._need("base").pose()
        t_map_arm = planar(x, y, th).dot(self.mount)
        try:
            frame = tool_frame_facing(point, normal)
        except ValueError as error:
            raise BadRequest(str(error), argument="nx")
        return matrix_to_pose(invert(t_map_arm).dot(frame))

    def _switch(self, tool: str, on: bool) -> None:
        sw = self.tools.get(tool, {}).get("switch", {})
        if sw.get("source") == "ur_digital_out":
            self._need("arm").set_digital_output(int(sw["index"]), on)
        elif sw.get("source") == "compressor_valve":
            self._need("compressor").set_valve(on)

    def _outputs_off(self) -> None:
        for tool in TOOLS:
            try:
                self._switch(tool, False)
            except (BridgeError, NotReady):
                pass

    def _approach(self, ctx: Any, pose: Sequence[float]) -> None:
        """Joint move to the IK solution of ``pose`` (robust for large re-orientations), then exact MOVE_L."""
        arm = self._need("arm")
        q = arm.inverse_kinematics(pose)
        arm.move_joints(ctx, q, 1.0, 2.0)
        arm.move_linear(ctx, pose, APPROACH_SPEED, 1.2)

    @staticmethod
    def _unit(v: Sequence[float], name: str) -> np.ndarray:
        a = np.asarray(v, dtype=float)
        n = float(np.linalg.norm(a))
        if n < 1e-6:
            raise BadRequest("%s must not be the zero vector" % name, argument=name)
        return a / n

    # -- handlers ----------------------------------------------------------------------------------------
    def scan(self, ctx: Any) -> Dict[str, Any]:
        result = self._need("scanner").scan(self._need("base").pose())
        result["message"] = "%d walls, %d joints, %d areas" % (len(result.get("walls", [])),
                                                               len(result.get("joints", [])),
                                                               len(result.get("areas", [])))
        return result

    def mount_tool(self, ctx: Any, tool: str) -> Dict[str, Any]:
        if tool not in self.tools:
            raise BadRequest("tool %s is not in robot.tools (%s)" % (tool, ", ".join(sorted(self.tools))),
                             argument="tool")
        arm = self._need("arm")
        self._outputs_off()
        cfg = self.tools[tool]
        arm.set_tcp([float(v) for v in cfg["tcp"]])
        arm.set_payload(float(cfg["mass"]), [float(v) for v in cfg["cog"]])
        self.active_tool = tool
        return {"tool": tool, "tcp": cfg["tcp"], "mass": cfg["mass"]}

    def apply_tape_start(self, ctx: Any, x0: float, y0: float, z0: float, x1: float, y1: float, z1: float,
                         nx: float, ny: float, nz: float, approach: float) -> Dict[str, Any]:
        self._need_tool("taping_tool")
        n = self._unit([nx, ny, nz], "normal")
        p0 = np.array([x0, y0, z0])
        pose = self.to_arm(p0 + n * approach, n)
        self._approach(ctx, pose)
        return {"tcp_pose": pose}

    def apply_tape(self, ctx: Any, x0: float, y0: float, z0: float, x1: float, y1: float, z1: float, nx: float,
                   ny: float, nz: float, speed: float, offset: float, approach: float) -> Dict[str, Any]:
        import time
        self._need_tool("taping_tool")
        arm = self._need("arm")
        n = self._unit([nx, ny, nz], "normal")
        p0, p1 = np.array([x0, y0, z0]), np.array([x1, y1, z1])
        length = float(np.linalg.norm(p1 - p0))
        if length < 1e-3:
            raise BadRequest("APPLY_TAPE: the line is shorter than 1 mm", argument="x1")
        start = time.monotonic()
        self._approach(ctx, self.to_arm(p0 + n * approach, n))
        try:
            arm.move_linear(ctx, self.to_arm(p0 + n * offset, n), CONTACT_SPEED, 1.0)
            self._switch("taping_tool", True)
            ctx.report(0.1, "taping")
            arm.move_linear(ctx, self.to_arm(p1 + n * offset, n), speed, 1.0)
        finally:
            self._switch_off_safely("taping_tool")
        arm.move_linear(ctx, self.to_arm(p1 + n * approach, n), APPROACH_SPEED, 1.2)
        return {"length_m": length, "duration_s": round(time.monotonic() - start, 3)}

    def _switch_off_safely(self, tool: str) -> None:
        try:
            self._switch(tool, False)
        except (BridgeError, NotReady):
            pass

    def _raster(self, ctx: Any, tool: str, origin: Sequence[float], u: Sequence[float], width: float,
                height: float, normal: Sequence[float], spacing: float, speed: float, offset: float,
                run_in: float) -> Dict[str, Any]:
        import time
        arm = self._need("arm")
        n = self._unit(normal, "normal")
        uu = self._unit(u, "u")
        up = np.array([0.0, 0.0, 1.0])
        o = np.asarray(origin, dtype=float)
        lanes = max(1, int(math.ceil(height / spacing - 1e-9))) + 1
        heights = [height * k / (lanes - 1) for k in range(lanes)] if lanes > 1 else [height / 2.0]
        start = time.monotonic()
        total = 0.0
        for k, t in enumerate(heights):
            forward = k % 2 == 0
            s0, s1 = (-run_in, width + run_in) if forward else (width + run_in, -run_in)
            a = o + uu * s0 + up * t + n * offset
            b = o + uu * s1 + up * t + n * offset
            if k == 0:
                self._approach(ctx, self.to_arm(a + n * 0.05, n))
            arm.move_linear(ctx, self.to_arm(a, n), APPROACH_SPEED, 1.2)
            try:
                self._switch(tool, True)
                arm.move_linear(ctx, self.to_arm(b, n), speed, 1.2)
            finally:
                self._switch_off_safely(tool)
            total += float(np.linalg.norm(b - a))
            ctx.report((k + 1) / len(heights), "lane %d of %d" % (k + 1, len(heights)))
        last = o + uu * (s1) + up * heights[-1] + n * (offset + 0.05)
        arm.move_linear(ctx, self.to_arm(last, n), APPROACH_SPEED, 1.2)
        return {"length_m": round(total, 4), "lanes": len(heights), "duration_s": round(time.monotonic() - start, 3)}

    def spray_area(self, ctx: Any, ox: float, oy: float, oz: float, ux: float, uy: float, uz: float, width: float,
                   height: float, nx: float, ny: float, nz: float, spacing: float, standoff: float, speed: float,
                   pressure: float) -> Dict[str, Any]:
        self._need_tool("spray_gun")
        comp = self._need("compressor")
        lo, hi = comp.pressure_range
        if not lo <= pressure <= hi:
            raise BadRequest("SPRAY_AREA: pressure %.2f bar is outside the working band %.2f..%.2f bar"
                             % (pressure, lo, hi), argument="pressure")
        guarded = GuardedWaiter(ctx, comp.check_link)
        try:
            comp.check_link()
            comp.set_valve(False)
            comp.set_motor(True)
            comp.set_setpoint(pressure)
            wait_for_pressure(comp, guarded, pressure, 0.2, timeout=30.0)
            out = self._raster(guarded, "spray_gun", [ox, oy, oz], [ux, uy, uz], width, height, [nx, ny, nz],
                               spacing, speed, standoff, run_in=0.1)
        finally:
            self._switch_off_safely("spray_gun")
        return out

    def sand_area(self, ctx: Any, ox: float, oy: float, oz: float, ux: float, uy: float, uz: float, width: float,
                  height: float, nx: float, ny: float, nz: float, spacing: float, speed: float,
                  force: float) -> Dict[str, Any]:
        self._need_tool("sander")
        try:
            out = self._raster(ctx, "sander", [ox, oy, oz], [ux, uy, uz], width, height, [nx, ny, nz], spacing,
                               speed, 0.0, run_in=0.0)
        finally:
            self._switch_off_safely("sander")
        out["force_n"] = force
        return out

    def home(self, ctx: Any) -> Dict[str, Any]:
        self._outputs_off()
        arm = self._need("arm")
        return arm.move_joints(ctx, arm.named_pose("home"), 1.0, 1.4)
