"""LOCEM commands of the UR arm (declarations from :func:`arm_specs`; :class:`ArmCommands` binds them to an arm
backend).

The bound of TCP coordinates (and of TCP offsets) is a fact of the robot: ``tcp_bound`` (m) = the arm's reach
plus its longest tool (:func:`locem_bridge.robot_facts.tcp_bound`, from ``robot.arm.reach`` and
``robot.tools``); the registry of a robot is built from its file (:func:`specs_for`).

Joint positions in rad; poses ``[x, y, z, rx, ry, rz]`` (m, rotation vector in rad) in the UR ``base`` frame,
TCP offset applied. Motions have a registry deadline computed from the arguments (worst case) and a tighter one
from the actual path length once the start is known; a safety stop answers ``HARDWARE_ERROR`` until
``RESET_ARM``.
"""

import math
from functools import lru_cache
from typing import Any, Dict, Iterable, List, Mapping, Optional, Tuple

from locem_bridge.locem.registry import Arg, CommandSpec

from .errors import BadRequest
from locem_bridge.common.geometry import angle_between
from locem_bridge.robot_facts import shipped_tcp_bound, tcp_bound
from .interfaces import Arm
from .suspension import Resumable, arm_settle

CATEGORY = "arm"
_ARM = frozenset({"arm"})
TWO_PI = 2.0 * math.pi
MAX_PATH_POINTS = 50
MAX_BLEND = 0.5                 # m, largest blend radius accepted (ur_rtde allows up to 2 m)
MOTION_MARGIN_S, PATH_UPLOAD_S, ROTATION_WEIGHT = Arm.MOTION_MARGIN_S, Arm.PATH_UPLOAD_S, Arm.ROTATION_WEIGHT


def joint_travel_bound(speed: float, accel: float) -> float:
    """Registry deadline of a joint move before the start is known: a full turn of the farthest joint."""
    return 2.0 * math.pi / speed + 2.0 * speed / accel + MOTION_MARGIN_S + 1.0


def _joints() -> tuple:
    return tuple(Arg.number("q%d" % (i + 1), "rad", -TWO_PI, TWO_PI, "joint %d position" % (i + 1)) for i in range(6))


def _pose(doc: str, bound: float) -> tuple:
    return (Arg.number("x", "m", -bound, bound, doc + " x"), Arg.number("y", "m", -bound, bound, doc + " y"),
            Arg.number("z", "m", -bound, bound, doc + " z"),
            Arg.number("rx", "rad", -TWO_PI, TWO_PI, doc + " rotation vector x"),
            Arg.number("ry", "rad", -TWO_PI, TWO_PI, doc + " rotation vector y"),
            Arg.number("rz", "rad", -TWO_PI, TWO_PI, doc + " rotation vector z"))


def _speed_j(default: float = 1.05) -> tuple:
    return (Arg.number("speed", "rad/s", 0.01, 3.14, "joint speed of the leading joint", default=default,
                       keyword_only=True),
            Arg.number("accel", "rad/s^2", 0.01, 40.0, "joint acceleration", default=1.4, keyword_only=True))


def _speed_l(default: float = 0.25) -> tuple:
    return (Arg.number("speed", "m/s", 0.001, 1.0, "TCP speed", default=default, keyword_only=True),
            Arg.number("accel", "m/s^2", 0.01, 10.0, "TCP acceleration", default=1.2, keyword_only=True))


_MOTION_RESULT = (("q", "joint positions at the end, rad"), ("tcp_pose", "TCP pose at the end"),
                  ("duration_s", "seconds from start to standstill"))

MOVE_J = CommandSpec(
    "MOVE_J", "Move the arm to joint positions (synchronised joint motion).", args=_joints() + _speed_j(),
    resources=_ARM, category=CATEGORY, pausable=True, result=_MOTION_RESULT,
    deadline=lambda v: joint_travel_bound(v["speed"], v["accel"]), capability="sk:cap_MoveArm")
MOVE_HOME = CommandSpec(
    "MOVE_HOME", "Move the arm to a named joint pose of the robot configuration (default home).",
    args=(Arg.word("pose", "named pose of robot.arm.named_poses", default="home"),) + _speed_j(),
    resources=_ARM, category=CATEGORY, result=_MOTION_RESULT, pausable=True,
    deadline=lambda v: joint_travel_bound(v["speed"], v["accel"]), capability="sk:cap_ArmToNamedPose")
STOP_ARM = CommandSpec(
    "STOP_ARM", "Stop the arm now (the running arm command ends ABORTED); never BUSY.", category=CATEGORY,
    timeout=3.0, preemptive=True, inline=True, result=(("stopped", "true"),))
GET_JOINTS = CommandSpec(
    "GET_JOINTS", "Read the joint positions now.", category=CATEGORY, timeout=2.0, inline=True, query=True,
    result=(("q", "joint positions, rad"), ("names", "joint names")))
GET_TCP_POSE = CommandSpec(
    "GET_TCP_POSE", "Read the TCP pose now (arm base frame, TCP offset applied).", category=CATEGORY, timeout=2.0,
    inline=True, query=True, result=(("pose", "[x, y, z, rx, ry, rz], m and rad"),))
SET_PAYLOAD = CommandSpec(
    "SET_PAYLOAD", "Set the payload mass and centre of gravity (flange frame).",
    args=(Arg.number("mass", "kg", 0.0, 12.5, "payload mass"), Arg.number("cx", "m", -0.5, 0.5, "centre of gravity x"),
          Arg.number("cy", "m", -0.5, 0.5, "centre of gravity y"), Arg.number("cz", "m", -0.5, 0.5, "centre of gravity z")),
    resources=_ARM, category=CATEGORY, timeout=3.0, result=(("mass", "kg"), ("cog", "m")),
    capability="sk:cap_SetPayload")
TOOL_OUTPUT = CommandSpec(
    "TOOL_OUTPUT", "Switch a standard digital output of the arm controller (tool power, taping, sander).",
    args=(Arg.integer("index", 0, 7, "standard digital output DO0..DO7"), Arg.flag("state", "on (true) or off")),
    resources=frozenset({"tool"}), category=CATEGORY, timeout=3.0, result=(("outputs", "DO0..DO7 after the change"),),
    capability="sk:cap_SwitchToolOutput")
RESET_ARM = CommandSpec(
    "RESET_ARM", "Operator reset after a protective or emergency stop whose cause is removed.", resources=_ARM,
    category=CATEGORY, timeout=30.0, result=(("cleared", "the latched safety stop"), ("steps", "recovery steps")),
    capability="sk:cap_ResetArm")

def _path_deadline(v: Mapping[str, Any], bound: float) -> float:
    """Registry deadline of MOVE_PATH: the waypoint-to-waypoint length plus a first leg across the whole reach
    (``bound``: the TCP coordinate bound), one acceleration and stop per waypoint, the script upload and the
    margin."""
    speed, accel = v["speed"], v["accel"]
    try:
        points = parse_waypoints(v["waypoints"], bound)
    except BadRequest:           # refused by the handler anyway; any finite deadline will do
        return 2.0 * bound / speed + MOTION_MARGIN_S + 1.0
    length = 2.0 * bound + sum(math.dist(points[i][:3], points[i + 1][:3])
                               + ROTATION_WEIGHT * angle_between(points[i], points[i + 1])
                               for i in range(len(points) - 1))
    return length / speed + len(points) * 2.0 * speed / accel + MOTION_MARGIN_S + PATH_UPLOAD_S + 1.0


@lru_cache(maxsize=16)
def arm_specs(bound: float) -> Tuple[CommandSpec, ...]:
    """The arm commands of a robot whose TCP coordinates are bounded by ``bound`` (m, :func:`tcp_bound`): the
    pose arguments' ranges and the motion deadlines depend on it."""
    move_l = CommandSpec(
        "MOVE_L", "Move the TCP in a straight line to a pose in the arm base frame.",
        args=_pose("target", bound) + _speed_l(), resources=_ARM, category=CATEGORY, result=_MOTION_RESULT,
        pausable=True,
        deadline=lambda v: 2.0 * bound / v["speed"] + 2.0 * v["speed"] / v["accel"] + MOTION_MARGIN_S + 1.0,
        capability="sk:cap_MoveArmLinear")
    move_path = CommandSpec(
        "MOVE_PATH", "Move the TCP through waypoints as one controller path: straight segments, each interior "
        "waypoint rounded on an arc within its blend radius without stopping (blend 0 stops there); the last "
        "waypoint is reached exactly. Waypoints: x:y:z:rx:ry:rz[:blend] joined by '/', e.g. "
        "0.5:0.2:0.4:0:3.14:0/0.5:0.3:0.4:0:3.14:0 blend=0.02. A blend radius may be at most half of either "
        "neighbouring segment.",
        args=(Arg.word("waypoints", "up to %d poses x:y:z:rx:ry:rz (m, rad), each optionally :blend (m, 0..%g, "
                                    "overrides blend), joined by '/'" % (MAX_PATH_POINTS, MAX_BLEND),
                       max_length=1000),)
        + _speed_l() + (Arg.number("blend", "m", 0.0, MAX_BLEND, "blend radius at the interior waypoints (0 = stop "
                                                                  "at each)", default=0.0, keyword_only=True),),
        resources=_ARM, category=CATEGORY, result=_MOTION_RESULT + (("waypoints", "waypoints in the path"),),
        pausable=True,
        deadline=lambda v: _path_deadline(v, bound), capability="sk:cap_MoveArmPath")
    set_tcp = CommandSpec(
        "SET_TCP", "Set the TCP offset from the flange.", args=_pose("TCP offset", bound), resources=_ARM,
        category=CATEGORY, timeout=3.0, result=(("tcp", "the offset set"),), capability="sk:cap_SetTcp")
    return (MOVE_J, move_l, move_path, MOVE_HOME, STOP_ARM, GET_JOINTS, GET_TCP_POSE, set_tcp, SET_PAYLOAD,
            TOOL_OUTPUT, RESET_ARM)


def specs_for(robot: Mapping[str, Any]) -> Tuple[CommandSpec, ...]:
    """The arm commands of the robot section ``robot`` (a loaded robot file's ``robot``)."""
    return arm_specs(tcp_bound(robot))


def parse_waypoints(text: str, bound: Optional[float] = None) -> List[List[float]]:
    """``x:y:z:rx:ry:rz[:blend]/...`` -> the poses; BadRequest naming the bad waypoint (see :func:`parse_path`)."""
    return parse_path(text, bound)[0]


def parse_path(text: str, bound: Optional[float] = None) -> Tuple[List[List[float]], List[Optional[float]]]:
    """``x:y:z:rx:ry:rz[:blend]/...`` -> (poses, per-waypoint blend or None); BadRequest naming the bad waypoint
    and what is allowed. ``bound``: the TCP coordinate bound (m; None: the shipped robot's)."""
    bound = shipped_tcp_bound() if bound is None else bound
    chunks = text.split("/")
    if len(chunks) > MAX_PATH_POINTS:
        raise BadRequest("MOVE_PATH: %d waypoints, allowed at most %d" % (len(chunks), MAX_PATH_POINTS),
                         argument="waypoints")
    points: List[List[float]] = []
    blends: List[Optional[float]] = []
    for i, chunk in enumerate(chunks):
        parts = chunk.split(":")
        try:
            values = [float(p) for p in parts]
        except ValueError:
            values = []
        if len(values) not in (6, 7) or not all(math.isfinite(v) for v in values):
            raise BadRequest("MOVE_PATH: waypoint %d '%s' must be 6 numbers x:y:z:rx:ry:rz, optionally :blend"
                             % (i + 1, chunk[:60]), argument="waypoints")
        if any(abs(v) > bound for v in values[:3]):
            raise BadRequest("MOVE_PATH: waypoint %d position out of range; allowed -%g to %g m" % (i + 1, bound, bound),
                             argument="waypoints")
        if any(abs(v) > TWO_PI for v in values[3:6]):
            raise BadRequest("MOVE_PATH: waypoint %d rotation vector out of range; allowed -%.4f to %.4f rad"
                             % (i + 1, TWO_PI, TWO_PI), argument="waypoints")
        if len(values) == 7 and not 0.0 <= values[6] <= MAX_BLEND:
            raise BadRequest("MOVE_PATH: waypoint %d blend radius %g m out of range; allowed 0 to %g m"
                             % (i + 1, values[6], MAX_BLEND), argument="waypoints")
        points.append(values[:6])
        blends.append(values[6] if len(values) == 7 else None)
    return points, blends


class ArmCommands:
    """The arm command set for :meth:`LocemCore.install`; ``tcp_bound`` (m): the robot's TCP coordinate bound
    (:func:`locem_bridge.robot_facts.tcp_bound`; None: the shipped robot's)."""

    name = "arm"

    def __init__(self, arm: Arm, tcp_bound: Optional[float] = None) -> None:
        self.arm = arm
        self.tcp_bound = shipped_tcp_bound() if tcp_bound is None else float(tcp_bound)

    def specs(self) -> Iterable[CommandSpec]:
        return arm_specs(self.tcp_bound)

    def handlers(self) -> Dict[str, Any]:
        return {"MOVE_J": self.move_j, "MOVE_L": self.move_l, "MOVE_PATH": self.move_path,
                "MOVE_HOME": self.move_home, "STOP_ARM": self.stop_arm, "GET_JOINTS": self.get_joints,
                "GET_TCP_POSE": self.get_tcp_pose, "SET_TCP": self.set_tcp, "SET_PAYLOAD": self.set_payload,
                "TOOL_OUTPUT": self.tool_output, "RESET_ARM": self.reset_arm}

    def stop(self) -> None:
        self.arm.stop()

    def health(self) -> Dict[str, Any]:
        return self.arm.health()

    def resumable(self, ctx: Any) -> Resumable:
        """Suspend: the arm decelerates along its path (``stopL`` / ``stopJ``, not a protective stop) and waits
        at rest; Resume: the motion is issued again from there to the same target."""
        return Resumable(ctx, lambda: self.arm.stop_motion("suspended"), settle=arm_settle(self.arm))

    def move_j(self, ctx: Any, q1: float, q2: float, q3: float, q4: float, q5: float, q6: float, speed: float,
               accel: float) -> Dict[str, Any]:
        q = [q1, q2, q3, q4, q5, q6]
        return self.resumable(ctx).run(lambda: self.arm.move_joints(ctx, q, speed, accel))

    def move_l(self, ctx: Any, x: float, y: float, z: float, rx: float, ry: float, rz: float, speed: float,
               accel: float) -> Dict[str, Any]:
        pose = [x, y, z, rx, ry, rz]
        return self.resumable(ctx).run(lambda: self.arm.move_linear(ctx, pose, speed, accel))

    def move_path(self, ctx: Any, waypoints: str, speed: float, accel: float, blend: float) -> Dict[str, Any]:
        """Resumed after a suspension with the waypoints not yet reached (the controller's path progress when it
        was suspended); the first one's blend shrinks to half of its now shorter segment if need be."""
        self.arm.require(Arm.PATH)
        points, own = parse_path(waypoints, self.tcp_bound)
        radii = [blend if b is None else b for b in own]
        left = {"from": 0}
        arm = self.arm

        def stop() -> None:
            progress = arm.cached_state().get("progress")
            if isinstance(progress, int) and progress >= 0:
                left["from"] = max(left["from"], min(left["from"] + progress, len(points) - 1))
            arm.stop_motion("suspended")

        def attempt() -> Dict[str, Any]:
            rest, blends = points[left["from"]:], list(radii[left["from"]:])
            if left["from"] and len(rest) > 1:
                here = arm.tcp_pose()
                first = math.dist(here[:3], rest[0][:3])
                blends[0] = min(blends[0], first / 2.0, math.dist(rest[0][:3], rest[1][:3]) / 2.0)
            out = arm.move_path(ctx, rest, speed, accel, blends)
            out["waypoints"] = len(points)
            return out
        return Resumable(ctx, stop, settle=arm_settle(arm)).run(attempt)

    def move_home(self, ctx: Any, pose: str, speed: float, accel: float) -> Dict[str, Any]:
        q = self.arm.named_pose(pose)
        return self.resumable(ctx).run(lambda: self.arm.move_joints(ctx, q, speed, accel))

    def stop_arm(self, ctx: Any) -> Dict[str, Any]:
        self.arm.stop_motion("STOP_ARM")
        return {"stopped": True}

    def get_joints(self, ctx: Any) -> Dict[str, Any]:
        q = self.arm.joint_positions()
        return {"q": q, "names": list(self.arm.joint_names),
                "message": " ".join("%.4f" % v for v in q)}

    def get_tcp_pose(self, ctx: Any) -> Dict[str, Any]:
        pose = self.arm.tcp_pose()
        return {"pose": pose, "message": " ".join("%.4f" % v for v in pose)}

    def set_tcp(self, ctx: Any, x: float, y: float, z: float, rx: float, ry: float, rz: float) -> Dict[str, Any]:
        self.arm.set_tcp([x, y, z, rx, ry, rz])
        return {"tcp": [x, y, z, rx, ry, rz]}

    def set_payload(self, ctx: Any, mass: float, cx: float, cy: float, cz: float) -> Dict[str, Any]:
        self.arm.set_payload(mass, [cx, cy, cz])
        return {"mass": mass, "cog": [cx, cy, cz]}

    def tool_output(self, ctx: Any, index: int, state: bool) -> Dict[str, Any]:
        self.arm.set_digital_output(index, state)
        return {"outputs": self.arm.digital_outputs()}

    def reset_arm(self, ctx: Any) -> Dict[str, Any]:
        return self.arm.reset(ctx)
