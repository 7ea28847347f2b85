"""LOCEM commands of the mobile base and of the lift carrying the arm (declarations in ``SPECS``;
:class:`BaseCommands` binds the base's, :class:`LiftCommands` the lift's: registered only on a robot with a
``robot.lift`` section).

Poses ``x y theta`` are base_footprint in the ``map`` frame (m, rad, REP 103); odometry starts at the initial
pose (``SET_POSE`` or the node's ``~initial_pose``). GOTO runs closed loop on odometry until within
``tolerance`` / ``angle_tolerance`` and standing still, with a deadline from distance and speed.
"""

import math
from typing import Any, Dict, Iterable

from locem_bridge.locem.registry import Arg, CommandSpec

from locem_bridge.common.geometry import wrap_angle
from .interfaces import Base, Lift
from .suspension import Resumable, base_settle, lift_settle

CATEGORY = "base"
_BASE = frozenset({"base"})
MAP_EXTENT = 100.0
PI = math.pi


def _goal_args() -> tuple:
    return (Arg.number("tolerance", "m", 0.002, 0.5, "position tolerance", default=0.01, keyword_only=True),
            Arg.number("angle_tolerance", "rad", 0.002, 0.5, "heading tolerance", default=0.01, keyword_only=True),
            Arg.number("speed", "m/s", 0.01, 1.0, "travel speed", default=0.4, keyword_only=True))


def _goto_deadline(v: Any) -> float:
    return 2.0 * MAP_EXTENT / v["speed"] + 30.0


_POSE_RESULT = (("pose", "[x, y, theta] reached (odometry), m and rad"), ("error_xy", "m from the goal"),
                ("error_theta", "rad from the goal heading"), ("duration_s", "seconds"))

GOTO = CommandSpec(
    "GOTO", "Drive the base to a pose in the map frame (closed loop on odometry).",
    args=(Arg.number("x", "m", -MAP_EXTENT, MAP_EXTENT, "goal x in map"),
          Arg.number("y", "m", -MAP_EXTENT, MAP_EXTENT, "goal y in map"),
          Arg.number("theta", "rad", -2 * PI, 2 * PI, "goal heading in map")) + _goal_args(),
    resources=_BASE, category=CATEGORY, result=_POSE_RESULT, pausable=True, timeout=_goto_deadline({"speed": 0.01}),
    deadline=_goto_deadline, capability="sk:cap_DriveBase")
GOTO_TAG = CommandSpec(
    "GOTO_TAG", "Drive the base to a named pose of the configuration (robot.base.named_poses / ~named_poses).",
    args=(Arg.word("name", "named base pose"),) + _goal_args(), resources=_BASE, category=CATEGORY,
    result=_POSE_RESULT, pausable=True, timeout=_goto_deadline({"speed": 0.01}), deadline=_goto_deadline,
    capability="sk:cap_DriveBaseToNamedPose")
MOVE_BASE_REL = CommandSpec(
    "MOVE_BASE_REL", "Move the base relative to its current pose (dx, dy in the base frame, dtheta).",
    args=(Arg.number("dx", "m", -10.0, 10.0, "forward"), Arg.number("dy", "m", -10.0, 10.0, "to the left"),
          Arg.number("dtheta", "rad", -2 * PI, 2 * PI, "turn, counter-clockwise")) + _goal_args(),
    resources=_BASE, category=CATEGORY, result=_POSE_RESULT, pausable=True,
    deadline=lambda v: (abs(v["dx"]) + abs(v["dy"])) / v["speed"] + abs(v["dtheta"]) / 0.5 + 15.0,
    capability="sk:cap_MoveBaseRelative")
STOP_BASE = CommandSpec(
    "STOP_BASE", "Stop the base now (the running base command ends ABORTED); never BUSY.", category=CATEGORY,
    timeout=2.0, preemptive=True, inline=True, result=(("stopped", "true"),))
GET_POSE = CommandSpec(
    "GET_POSE", "Read the base pose (odometry in map) and its measured velocity.", category=CATEGORY, timeout=1.0,
    inline=True, query=True, result=(("pose", "[x, y, theta], m and rad"), ("twist", "[vx, vy, wz] in base frame")))
SET_POSE = CommandSpec(
    "SET_POSE", "Tell the base where it is in the map (resets odometry; e.g. after localisation).",
    args=(Arg.number("x", "m", -MAP_EXTENT, MAP_EXTENT, "x in map"),
          Arg.number("y", "m", -MAP_EXTENT, MAP_EXTENT, "y in map"),
          Arg.number("theta", "rad", -2 * PI, 2 * PI, "heading in map")),
    resources=_BASE, category=CATEGORY, timeout=1.0, result=(("pose", "the pose set"),),
    capability="sk:cap_SetBasePose")

RESET_BASE = CommandSpec(
    "RESET_BASE", "Operator reset after a drive fault: fault reset and enable the drives again (nothing moves).",
    resources=_BASE, category=CATEGORY, timeout=20.0, result=(("cleared", "the latched fault"),),
    capability="sk:cap_ResetBase")

LIFT_EXTENT = 5.0          # m: the grammar's bound; the robot's own range (robot.lift.range) is checked by the lift
LIFT = CommandSpec(
    "LIFT", "Move the lift carrying the arm to a height (the arm mount above base_footprint; the arm's base frame "
    "moves with it) and wait until in position. Allowed: robot.lift.range (HELP LIFT on a robot with a lift: "
    "STATUS health.lift.range).",
    args=(Arg.number("z", "m", 0.0, LIFT_EXTENT, "arm mount height above the floor (base_footprint)"),),
    resources=frozenset({"lift"}), category="lift", pausable=True, result=(("height", "m reached"), ("error", "m from the goal"),
                                                            ("duration_s", "seconds")),
    timeout=120.0, capability="sk:cap_Lift")

BASE_SPECS = (GOTO, GOTO_TAG, MOVE_BASE_REL, STOP_BASE, GET_POSE, SET_POSE, RESET_BASE)
LIFT_SPECS = (LIFT,)
SPECS = BASE_SPECS + LIFT_SPECS


class BaseCommands:
    """The base command set for :meth:`LocemCore.install`."""

    name = "base"

    def __init__(self, base: Base) -> None:
        self.base = base

    def specs(self) -> Iterable[CommandSpec]:
        return BASE_SPECS

    def handlers(self) -> Dict[str, Any]:
        return {"GOTO": self.goto, "GOTO_TAG": self.goto_tag, "MOVE_BASE_REL": self.move_rel,
                "STOP_BASE": self.stop_base, "GET_POSE": self.get_pose, "SET_POSE": self.set_pose,
                "RESET_BASE": self.reset_base}

    def stop(self) -> None:
        self.base.stop()

    def health(self) -> Dict[str, Any]:
        return self.base.health()

    def _goto(self, ctx: Any, x: float, y: float, theta: float, tolerance: float, angle_tolerance: float,
              speed: float) -> Dict[str, Any]:
        """Suspend: the base brakes to zero velocity (its drives' quick-stop deceleration) and stands; Resume:
        it drives on to the same goal from where it stopped."""
        base = self.base
        return Resumable(ctx, base.halt, settle=base_settle(base)).run(
            lambda: base.goto(ctx, x, y, theta, tolerance, angle_tolerance, speed))

    def goto(self, ctx: Any, x: float, y: float, theta: float, tolerance: float, angle_tolerance: float,
             speed: float) -> Dict[str, Any]:
        return self._goto(ctx, x, y, theta, tolerance, angle_tolerance, speed)

    def goto_tag(self, ctx: Any, name: str, tolerance: float, angle_tolerance: float, speed: float) -> Dict[str, Any]:
        x, y, theta = self.base.named_pose(name)
        out = self._goto(ctx, x, y, theta, tolerance, angle_tolerance, speed)
        out["goal"] = [x, y, theta]
        return out

    def move_rel(self, ctx: Any, dx: float, dy: float, dtheta: float, tolerance: float, angle_tolerance: float,
                 speed: float) -> Dict[str, Any]:
        x, y, th = self.base.pose()
        gx = x + math.cos(th) * dx - math.sin(th) * dy
        gy = y + math.sin(th) * dx + math.cos(th) * dy
        out = self._goto(ctx, gx, gy, wrap_angle(th + dtheta), tolerance, angle_tolerance, speed)
        out["goal"] = [gx, gy, wrap_angle(th + dtheta)]
        return out

    def stop_base(self, ctx: Any) -> Dict[str, Any]:
        self.base.halt()
        return {"stopped": True}

    def get_pose(self, ctx: Any) -> Dict[str, Any]:
        p = self.base.pose()
        return {"pose": p, "twist": self.base.twist(), "message": "%.4f %.4f %.4f" % tuple(p)}

    def set_pose(self, ctx: Any, x: float, y: float, theta: float) -> Dict[str, Any]:
        self.base.set_pose(x, y, theta)
        return {"pose": self.base.pose()}

    def reset_base(self, ctx: Any) -> Dict[str, Any]:
        return self.base.reset(ctx)


class LiftCommands:
    """The lift's command set (``LIFT``) for :meth:`LocemCore.install`; its health (``STATUS`` ``health.lift``)
    carries ``height`` and ``range``."""

    name = "lift"

    def __init__(self, lift: Lift) -> None:
        self.lift = lift

    def specs(self) -> Iterable[CommandSpec]:
        return LIFT_SPECS

    def handlers(self) -> Dict[str, Any]:
        return {"LIFT": self.lift_to}

    def stop(self) -> None:
        self.lift.stop()

    def health(self) -> Dict[str, Any]:
        return self.lift.health()

    def lift_to(self, ctx: Any, z: float) -> Dict[str, Any]:
        """Suspend: the lift halts (brakes at its deceleration and holds); Resume: on to the same height."""
        lift = self.lift
        return Resumable(ctx, lift.halt, settle=lift_settle(lift)).run(lambda: lift.move_to(ctx, z))
