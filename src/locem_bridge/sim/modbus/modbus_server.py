"""Modbus TCP server of the compressor stand-in, for the installed pymodbus line (chosen at import time).

``CompressorServer`` is the public class (the worksite and the bridge tests use it); it is

* :class:`Pymodbus316CompressorServer` (below) with pymodbus >= 3.16 (Python >= 3.10), built on the 3.16
  ``SimDevice`` datastore whose ``action`` callback sees every read and write;
* :class:`~locem_bridge.sim.modbus.modbus_legacy.LegacyCompressorServer` with pymodbus 3.6.x, the last line for
  Python 3.8 (ROS Noetic on Ubuntu 20.04), built on a custom ``ModbusBaseSlaveContext``.

Both call the same :class:`~locem_bridge.sim.modbus.compressor.CompressorRegisterMap` and share lifecycle, link faults
and refusal accounting (:class:`~locem_bridge.sim.modbus.modbus_base.CompressorServerBase`), so a client sees the same
device on both lines: same values, exception 2 for addresses outside the map, exception 3 for set-points out of
range, exception 4 for any other unit id, same ``close`` / ``silent`` link drops. Other pymodbus versions are
refused at import with an ImportError naming the supported ranges.

Lifecycle: ``CompressorServer(model, host, port, device_id)`` -> :meth:`start` (binds, serves from its own asyncio
thread; returns once listening) -> :meth:`stop`. Link faults: :meth:`drop_link` (``close`` / ``silent``,
optional ``duration``), :meth:`restore_link`; see :mod:`.modbus_base`.

Bit reads that start inside the map but run past its end return 0 for the missing bits (pymodbus 3.16 packs bits
into 16-bit words and does not pass the bit count to the device; the 3.6 adapter answers the same way); every other
address outside the map is refused with exception 2.
"""
from __future__ import annotations

from typing import Any, List, Optional

import pymodbus

from .compressor import CompressorModel, RegisterAccessError
from ..errors import DeviceStandInError
from .modbus_base import CompressorServerBase, parse_version

#: installed pymodbus version as (major, minor, patch)
PYMODBUS_VERSION = parse_version(getattr(pymodbus, "__version__", "0"))
#: True when the installed pymodbus has the 3.6 datastore API (slave contexts, ``slave=`` on clients)
LEGACY_API = (3, 6) <= PYMODBUS_VERSION[:2] < (3, 7)

if not LEGACY_API and PYMODBUS_VERSION[:2] < (3, 16):
    raise ImportError("locem_bridge.sim.modbus.modbus_server: pymodbus %s is not supported; install pymodbus>=3.6.9,<3.7 "
                      "(Python 3.8) or pymodbus>=3.16,<3.17 (Python >= 3.10), see requirements.txt"
                      % getattr(pymodbus, "__version__", "?"))

if not LEGACY_API:
    from pymodbus.constants import ExcCodes
    from pymodbus.server import ModbusTcpServer
    from pymodbus.simulator import DataType, SimData, SimDevice


def _exc(code: int) -> Any:
    return ExcCodes.ILLEGAL_VALUE if code == 3 else ExcCodes.ILLEGAL_ADDRESS


class Pymodbus316CompressorServer(CompressorServerBase):
    """pymodbus 3.16 TCP server bound to a :class:`CompressorModel` (``SimDevice`` action callback)."""

    pymodbus_line = "3.16"

    def __init__(self, model: CompressorModel, host: str = "127.0.0.1", port: int = 5020, device_id: int = 1,
                 register_map: Any = None, name: str = "compressor") -> None:
        if LEGACY_API:
            raise DeviceStandInError("the pymodbus 3.16 adapter cannot run on the installed pymodbus %s; use "
                                     "locem_bridge.sim.modbus.modbus_server.CompressorServer" % pymodbus.__version__)
        super().__init__(model, host, port, device_id, register_map, name)

    # -- pymodbus glue -------------------------------------------------------------------------------------
    def _device(self) -> SimDevice:
        return SimDevice(
            id=self.device_id,
            # blocks span addresses 0..4095 so those requests reach _action (which refuses and logs); pymodbus
            # itself answers exception 2 above that
            simdata=([SimData(0, count=0x100, values=0, datatype=DataType.BITS)],
                     [SimData(0, count=0x100, values=0, datatype=DataType.BITS)],
                     [SimData(0, count=0x1000, values=0, datatype=DataType.REGISTERS)],
                     [SimData(0, count=0x1000, values=0, datatype=DataType.REGISTERS)]),
            action=self._action)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      current_registers: List[int], set_values: Optional[List[Any]]) -> Any:
        await self._gate()                      # silent link drop: hold the answer
        self.requests += 1
        try:
            if set_values is not None:
                if function_code in (5, 15):
                    self.map.write_bits(address, [bool(v) for v in set_values])
                elif function_code in (6, 16, 23):
                    self.map.write_registers(address, [int(v) for v in set_values])
                else:
                    raise RegisterAccessError(2, "function code %d cannot write" % function_code)
            if function_code in (1, 5, 15):
                table, names = "coils", self.map.COILS
            elif function_code == 2:
                table, names = "discrete_inputs", self.map.DISCRETE_INPUTS
            else:
                table = "holding" if function_code in (3, 6, 16, 23) else "input"
                if set_values is None:
                    self.map.read_registers(table, address, count)          # refuses addresses not in the map
                size = len(self.map.HOLDING_REGISTERS if table == "holding" else self.map.INPUT_REGISTERS)
                regs = self.map.read_registers(table, 0, size) if size else []
                current_registers[:len(regs)] = regs
                return None
            if set_values is None and address >= len(names):
                raise RegisterAccessError(2, "%s address %d not in map, allowed 0..%d" % (table, address, len(names) - 1))
            bits = self.map.read_bits(table, 0, len(names))
            current_registers[0] = sum(1 << i for i, b in enumerate(bits) if b)
            return None
        except RegisterAccessError as exc:
            return _exc(self._refused(function_code, address, exc))

    async def _listen(self) -> Any:
        server = ModbusTcpServer(self._device(), address=(self.host, self.port))
        await server.serve_forever(background=True)
        return server

    async def _shutdown(self, server: Any) -> None:
        await server.shutdown()


if LEGACY_API:
    from .modbus_legacy import LegacyCompressorServer as CompressorServer
else:
    CompressorServer = Pymodbus316CompressorServer  # type: ignore[misc]

__all__ = ["CompressorServer", "LEGACY_API", "PYMODBUS_VERSION", "Pymodbus316CompressorServer"]
