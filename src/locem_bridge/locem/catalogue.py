"""Every command LOCEM can declare, with or without hardware: the source of the API documentation.

Each entry names a module with a ``SPECS`` tuple; modules are imported lazily so the catalogue never pulls in
a device library. Bridges append their declaration modules here.
"""

import importlib
from typing import List, Tuple

from .registry import CommandSpec

DECLARATION_MODULES: Tuple[str, ...] = (
    "locem_bridge.locem.system_commands",
    "locem_bridge.bridges.commands_arm",
    "locem_bridge.bridges.commands_compressor",
    "locem_bridge.bridges.commands_base",
    "locem_bridge.bridges.commands_wall",
)


def all_specs() -> List[CommandSpec]:
    specs: List[CommandSpec] = []
    for module_name in DECLARATION_MODULES:
        specs.extend(importlib.import_module(module_name).SPECS)
    return specs
