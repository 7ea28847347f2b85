"""The automatic tool change: ``CHANGE_TOOL tool=<name>`` (declared by :func:`specs_for` for a robot whose file has a
``tool_changer`` section, which then offers no MOUNT_TOOL; :class:`ToolChangerCommands` binds it).

The sequence, every arm motion a joint move: process outputs off; clear of the wall (a wall pose first retracts
straight and passes ``robot.arm.home_via``, as HOME does); the safe pose ``robot.tool_changer.safe_pose``; when a
tool is coupled, its rack slot, unlock (the device confirms), TCP back to the flange and no payload, the safe pose
again; the new tool's slot, lock, the coupled tool id checked against the tool's slot; TCP offset and payload of
the new tool set exactly as MOUNT_TOOL sets them; the safe pose. The tool coupled now is what the device reports
(not what LOCEM remembers): a tool already coupled and locked answers OK at once, with no motion, after its TCP and
payload are set again. A failure leaves the arm where it stopped and the lock as the device holds it
(``HARDWARE_ERROR`` naming the device's fault); nothing is retried by itself.
"""

from typing import Any, Dict, Iterable, List, Mapping, Optional, Tuple

from locem_bridge.locem.errors import NotReady
from locem_bridge.locem.registry import Arg, CommandSpec

from .commands_wall import WallCommands
from .errors import BadRequest, DeviceFault
from .interfaces import ToolChanger

CATEGORY = "wall"
JOINT_SPEED = 1.0          # rad/s, moves to and between the rack slots
JOINT_ACCEL = 1.4          # rad/s^2

def change_tool_spec(tools: Tuple[str, ...]) -> CommandSpec:
    """CHANGE_TOOL of a robot whose tool rack (``robot.tool_changer.rack``) holds ``tools``."""
    return CommandSpec(
        "CHANGE_TOOL", "Change the tool with the automatic tool changer: the mounted tool back into its rack slot, "
        "the named one coupled and locked, its TCP offset and payload set (OK at once when it is already coupled).",
        args=(Arg.choice("tool", tools, "the tool to couple (one of the rack's)"),),
        resources=frozenset({"arm", "tool", "tool_changer"}), category=CATEGORY, timeout=120.0,
        capability="sk:cap_ChangeToolAutomatically",
        result=(("tool", "tool coupled now"), ("previous", "tool put back into the rack ('' none)"),
                ("changed", "false when it was already coupled"), ("tcp", "TCP offset"), ("mass", "kg")))


def specs_for(robot: Mapping[str, Any]) -> Tuple[CommandSpec, ...]:
    """CHANGE_TOOL for a robot section with a ``tool_changer`` (choices: its rack's tools); none otherwise."""
    if "tool_changer" not in robot:
        return ()
    return (change_tool_spec(tuple(sorted(robot["tool_changer"]["rack"]))),)


class ToolChangerCommands:
    """CHANGE_TOOL over the arm of ``wall`` (its active tool, TCP and payload) and a :class:`ToolChanger`
    (None: the command answers NOT_READY)."""

    name = "tool_changer"

    def __init__(self, robot_cfg: Mapping[str, Any], wall: WallCommands, changer: Optional[ToolChanger]) -> None:
        cfg = robot_cfg["tool_changer"]
        self._specs = specs_for(robot_cfg)
        self.wall, self.changer = wall, changer
        self.safe_pose = str(cfg["safe_pose"])
        self.rack_poses: Dict[str, List[float]] = {tool: [float(v) for v in slot["pose"]]
                                                   for tool, slot in cfg["rack"].items()}

    def specs(self) -> Iterable[CommandSpec]:
        return self._specs

    def handlers(self) -> Dict[str, Any]:
        return {"CHANGE_TOOL": self.change_tool}

    def stop(self) -> None:
        """The changer holds its tool; the arm is stopped by the arm's command set."""

    def health(self) -> Dict[str, Any]:
        if self.changer is None:
            return {"link": "down", "device": "not configured", "last_error": "no tool changer backend built"}
        return self.changer.health()

    def _need(self) -> ToolChanger:
        if self.changer is None:
            raise NotReady("this robot has no tool_changer backend built")
        return self.changer

    def change_tool(self, ctx: Any, tool: str) -> Dict[str, Any]:
        changer = self._need()
        if tool not in self.rack_poses:
            raise BadRequest("tool %s has no slot in this robot's tool rack (robot.tool_changer.rack: %s)"
                             % (tool, ", ".join(sorted(self.rack_poses))), argument="tool")
        state = changer.read()
        if state["locked"] and state["coupled_tool"] == tool:
            out = self.wall.activate_tool(tool)
            out.update(previous=tool, changed=False, message="%s already coupled" % tool)
            return out
        if not state["present"].get(tool, False):
            raise NotReady("the %s is not in its rack slot %d (taken out of the rack?); put it back first"
                           % (tool, changer.slots[tool]))
        arm = self.wall.arm
        if arm is None:
            raise NotReady("this robot has no arm backend configured")
        safe = arm.named_pose(self.safe_pose)
        self.wall.stop()                                   # process outputs off
        ctx.report(0.05, "clear of the wall")
        self.wall.clear_of_wall(ctx)
        arm.move_joints(ctx, safe, JOINT_SPEED, JOINT_ACCEL)
        previous = state["coupled_tool"]
        if previous:
            ctx.report(0.3, "%s into rack slot %d" % (previous, changer.slots[previous]))
            arm.move_joints(ctx, self.rack_poses[previous], JOINT_SPEED, JOINT_ACCEL)
            changer.unlock(ctx)
            self.wall.activate_tool(None)
            arm.move_joints(ctx, safe, JOINT_SPEED, JOINT_ACCEL)
        elif state["locked"]:                              # closed on nothing: open before a tool can go in
            changer.unlock(ctx)
        ctx.report(0.6, "%s from rack slot %d" % (tool, changer.slots[tool]))
        arm.move_joints(ctx, self.rack_poses[tool], JOINT_SPEED, JOINT_ACCEL)
        locked = changer.lock(ctx)
        if locked["coupled_tool_id"] != changer.slots[tool]:
            raise DeviceFault("tool changer locked on tool id %d (%s), expected %d (%s)"
                              % (locked["coupled_tool_id"], locked["coupled_tool"] or "unknown", changer.slots[tool],
                                 tool), device="tool_changer")
        out = self.wall.activate_tool(tool)
        ctx.report(0.9, "back to %s" % self.safe_pose)
        arm.move_joints(ctx, safe, JOINT_SPEED, JOINT_ACCEL)
        out.update(previous=previous, changed=True,
                   message="%s coupled%s" % (tool, ", %s back in the rack" % previous if previous else ""))
        return out
