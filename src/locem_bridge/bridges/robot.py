"""Build every configured backend and command set of one robot from its YAML (the composition root of the
bridges; ``locem_node`` calls it, tests and benchmarks may too).

::

    robot = build_robot(load_robot_config(path), site=site_yaml_path, initial_pose=(2.4, 1.6, 1.5708))
    robot.start()                       # every backend starts connecting in the background
    for command_set in robot.command_sets:
        core.install(command_set)
    ...
    robot.close()

Command sets are built base first, then arm, compressor and the wall commands: ``STOP`` runs the device stops in
that order, so motion stops before process outputs are switched off. ``devices`` limits what is built (e.g. ``("compressor",)`` for a compressor-only bench); a section missing from
the YAML is skipped, its commands then answer ``NOT_READY``. The wall (plasterboard) commands are built when an
arm is.
"""

from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from locem_bridge.common.config_errors import ConfigError

from .backends import backend_class
from .config import need, resolve_path
from .interfaces import Backend

ALL_DEVICES = ("arm", "compressor", "base", "lift", "scanner", "tool_changer")


class Robot:
    """The backends (``arm``, ``compressor``, ``base``, ``lift``, ``scanner``, ``tool_changer``) and command sets of
    one robot."""

    def __init__(self) -> None:
        self.backends: Dict[str, Any] = {}
        self.command_sets: List[Any] = []

    def get(self, kind: str) -> Any:
        return self.backends.get(kind)

    def start(self) -> None:
        for backend in self.backends.values():
            if isinstance(backend, Backend):          # a scanner has no link to start
                backend.start()

    def close(self) -> None:
        for kind in ("base", "lift", "arm", "compressor", "tool_changer"):
            backend = self.backends.get(kind)
            if backend is not None:
                try:
                    backend.close()
                except Exception:  # close every backend, whatever one of them does
                    pass


def build_robot(robot_cfg: Mapping[str, Any], devices: Sequence[str] = ALL_DEVICES, site: Any = None,
                initial_pose: Optional[Tuple[float, float, float]] = None,
                named_base_poses: Optional[Mapping[str, Sequence[float]]] = None) -> Robot:
    """Every configured backend and command set; a configuration problem a backend finds names the robot file."""
    try:
        return _build_robot(robot_cfg, devices, site, initial_pose, named_base_poses)
    except ConfigError as error:
        raise error.in_file(str(robot_cfg.get("_path", "")))


def _build_robot(robot_cfg: Mapping[str, Any], devices: Sequence[str], site: Any,
                 initial_pose: Optional[Tuple[float, float, float]],
                 named_base_poses: Optional[Mapping[str, Sequence[float]]]) -> Robot:
    from .commands_arm import ArmCommands
    from .commands_base import BaseCommands, LiftCommands
    from .commands_changer import ToolChangerCommands
    from .commands_compressor import CompressorCommands
    from .commands_wall import WallCommands
    from ..robot_facts import tcp_bound

    robot = Robot()
    if "base" in devices and "base" in robot_cfg:
        base_cfg = dict(robot_cfg["base"])
        if named_base_poses:
            base_cfg["named_poses"] = dict(base_cfg.get("named_poses", {}) or {}, **dict(named_base_poses))
        cls = backend_class("base", str(need(base_cfg, "drives.profile", str, default="cia402", where="robot.base")))
        eds = resolve_path(robot_cfg, need(base_cfg, "eds", str, where="robot.base"))
        robot.backends["base"] = cls(base_cfg, eds, initial_pose=tuple(initial_pose or (0.0, 0.0, 0.0)))
        robot.command_sets.append(BaseCommands(robot.backends["base"]))
    if "lift" in devices and "lift" in robot_cfg and "base" in robot_cfg:     # a node on the base's CAN bus
        cls = backend_class("lift", "cia402")
        robot.backends["lift"] = cls(robot_cfg["lift"], robot_cfg["base"]["drives"]["can"],
                                     resolve_path(robot_cfg, need(robot_cfg["lift"], "eds", str, where="robot.lift")))
        robot.command_sets.append(LiftCommands(robot.backends["lift"]))
    if "arm" in devices and "arm" in robot_cfg:
        cls = backend_class("arm", str(robot_cfg["arm"].get("backend", "ur_rtde")))
        robot.backends["arm"] = cls(robot_cfg["arm"])
        robot.command_sets.append(ArmCommands(robot.backends["arm"], tcp_bound=tcp_bound(robot_cfg)))
    if "compressor" in devices and "compressor" in robot_cfg:
        cls = backend_class("compressor", str(robot_cfg["compressor"].get("protocol", "modbus_tcp")))
        robot.backends["compressor"] = cls(robot_cfg["compressor"])
        robot.command_sets.append(CompressorCommands(robot.backends["compressor"]))
    if "scanner" in devices and "scanner" in robot_cfg and site:
        cls = backend_class("scanner", str(robot_cfg["scanner"].get("backend", "sim")))
        robot.backends["scanner"] = cls(robot_cfg["scanner"], site)
    if "tool_changer" in devices and "tool_changer" in robot_cfg:
        cls = backend_class("tool_changer", str(robot_cfg["tool_changer"].get("protocol", "modbus_tcp")))
        robot.backends["tool_changer"] = cls(robot_cfg["tool_changer"])
    if "arm" in robot.backends:
        wall = WallCommands(robot_cfg, arm=robot.backends.get("arm"), base=robot.backends.get("base"),
                            compressor=robot.backends.get("compressor"), scanner=robot.backends.get("scanner"),
                            lift=robot.backends.get("lift"))
        robot.command_sets.append(wall)
        if "tool_changer" in robot_cfg:            # CHANGE_TOOL instead of MOUNT_TOOL (NOT_READY without a backend)
            robot.command_sets.append(ToolChangerCommands(robot_cfg, wall, robot.backends.get("tool_changer")))
    return robot
