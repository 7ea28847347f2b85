"""The name -> backend table. Modules are imported only when a backend is built, so a robot without, say, a
compressor never loads pymodbus, and the API documentation never loads a device library.

The robot YAML picks each backend: ``robot.arm.backend`` (default ``ur_rtde``), ``robot.compressor.protocol``
(``modbus_tcp``), ``robot.tool_changer.protocol`` (``modbus_tcp``), ``robot.base.drives.profile`` (``cia402``), the
lift (``robot.lift``) ``cia402``, ``robot.scanner.backend`` (default ``sim``).
A new device type is a new module plus one line here.
"""

import importlib
from typing import Any, Dict

from .errors import BridgeConfigError

BACKENDS: Dict[str, Dict[str, str]] = {
    "arm": {"ur_rtde": "locem_bridge.bridges.ur_arm:UrRtdeArm"},
    "compressor": {"modbus_tcp": "locem_bridge.bridges.modbus_compressor:ModbusCompressor"},
    "tool_changer": {"modbus_tcp": "locem_bridge.bridges.modbus_tool_changer:ModbusToolChanger"},
    "base": {"cia402": "locem_bridge.bridges.cia402_base:Cia402Base"},
    "lift": {"cia402": "locem_bridge.bridges.cia402_lift:Cia402Lift"},
    "scanner": {"sim": "locem_bridge.bridges.sim_scanner:SiteScanner"},
}


def backend_class(kind: str, name: str) -> Any:
    """The class registered as ``name`` for device ``kind`` (imported now)."""
    table = BACKENDS.get(kind)
    if table is None:
        raise BridgeConfigError("unknown device kind '%s'; known: %s" % (kind, ", ".join(sorted(BACKENDS))))
    target = table.get(name)
    if target is None:
        raise BridgeConfigError("no %s backend named '%s'; known: %s" % (kind, name, ", ".join(sorted(table))))
    module_name, _, attr = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise BridgeConfigError("%s backend '%s' needs a library that is not installed: %s" % (kind, name, error))
    return getattr(module, attr)
