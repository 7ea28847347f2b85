"""Every command LOCEM can declare, with or without hardware: the source of the API documentation.

Each entry names a module with a ``SPECS`` tuple, or, when the commands depend on the robot (argument ranges,
tool names), a ``specs_for(robot)`` function taking the robot file's ``robot`` section; modules are imported
lazily so the catalogue never pulls in a device library. Bridges append their declaration modules here.
"""

import importlib
from typing import Any, List, Mapping, Optional, Tuple

from .registry import CommandSpec

DECLARATION_MODULES: Tuple[str, ...] = (
    "locem_bridge.locem.system_commands",
    "locem_bridge.bridges.commands_arm",
    "locem_bridge.bridges.commands_compressor",
    "locem_bridge.bridges.commands_base",
    "locem_bridge.bridges.commands_wall",
    "locem_bridge.bridges.commands_changer",
)


def all_specs(robot: Optional[Mapping[str, Any]] = None) -> List[CommandSpec]:
    """Every command a LOCEM of ``robot`` (a loaded robot file's ``robot`` section; default: the shipped robot
    file's) can declare, with that robot's ranges and tool names."""
    if robot is None:
        from ..robot_file import load_robot
        robot = load_robot()["robot"]
    specs: List[CommandSpec] = []
    for module_name in DECLARATION_MODULES:
        module = importlib.import_module(module_name)
        specs.extend(module.specs_for(robot) if hasattr(module, "specs_for") else module.SPECS)
    return specs
