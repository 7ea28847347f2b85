"""pymodbus 3.6 adapter of the compressor Modbus TCP stand-in (the last pymodbus line for Python 3.8 / Noetic).

Import :class:`~locem_bridge.sim.modbus.modbus_server.CompressorServer` rather than this module: it picks this adapter
when pymodbus 3.6.x is installed. Lifecycle, link faults and refusal accounting are those of
:class:`~locem_bridge.sim.modbus.modbus_base.CompressorServerBase`; register semantics are those of
:class:`~locem_bridge.sim.modbus.compressor.CompressorRegisterMap`.

How the 3.6 datastore API is used

* The server context holds one :class:`_DeviceContext` (a ``ModbusBaseSlaveContext``) for ``device_id``; every
  other unit id gets a context that refuses with exception 4, as pymodbus 3.16 answers unknown device ids.
* pymodbus 3.6 runs each request as its own asyncio task: ``validate`` -> ``async_setValues`` (writes) ->
  ``async_getValues``. ``validate`` accepts everything so that the link gate (silent drops) holds refused
  requests too and the register map alone decides; ``async_getValues`` / ``async_setValues`` wait at the gate
  and call the map.
* A refusal found in the map is recorded in a context variable of that request's task; the server's
  ``response_manipulator`` (called in the same task right before the answer is sent) replaces the normal answer
  by an exception response with the map's code (2 ILLEGAL DATA ADDRESS, 3 ILLEGAL DATA VALUE). pymodbus 3.6
  itself would only answer 4 (SLAVE FAILURE) for an error raised in the datastore.
"""
from __future__ import annotations

import contextvars
from typing import Any, List, Optional, Sequence, Tuple

import pymodbus

from .compressor import CompressorModel, RegisterAccessError
from ..errors import DeviceStandInError
from .modbus_base import CompressorServerBase, log, parse_version

if parse_version(getattr(pymodbus, "__version__", "0"))[:2] != (3, 6):
    raise ImportError("locem_bridge.sim.modbus.modbus_legacy needs pymodbus 3.6.x (installed: %s); import "
                      "locem_bridge.sim.modbus.modbus_server.CompressorServer, which picks the adapter for the installed "
                      "version" % getattr(pymodbus, "__version__", "?"))

from pymodbus.datastore import ModbusBaseSlaveContext, ModbusServerContext  # noqa: E402 (after the version check)
from pymodbus.pdu import ExceptionResponse  # noqa: E402
from pymodbus.server import ModbusTcpServer  # noqa: E402

EXC_DEVICE_FAILURE = 4

_TABLES = {1: "coils", 5: "coils", 15: "coils", 2: "discrete_inputs",
           3: "holding", 6: "holding", 16: "holding", 22: "holding", 23: "holding", 4: "input"}

# exception code of the first refusal met while executing the current request (one asyncio task per request)
_refusal: contextvars.ContextVar = contextvars.ContextVar("locem_compressor_modbus_refusal", default=None)


def _note_refusal(code: int) -> None:
    if _refusal.get() is None:
        _refusal.set(code)


def _refused_already() -> bool:
    """True once the current request has been refused (a write's read-back must not count it twice)."""
    return _refusal.get() is not None


class _DeviceContext(ModbusBaseSlaveContext):
    """The compressor as a pymodbus 3.6 slave context: every access goes to the register map."""

    def __init__(self, server: "LegacyCompressorServer") -> None:
        self._server = server

    def __str__(self) -> str:
        return "%s stand-in (device id %d)" % (self._server.name, self._server.device_id)

    def reset(self) -> None:
        """Nothing to reset: the values live in the model."""

    def validate(self, fc_as_hex: int, address: int, count: int = 1) -> bool:
        return True                         # the map decides, after the link gate (see the module docstring)

    def getValues(self, fc_as_hex: int, address: int, count: int = 1) -> List[Any]:
        return self._server._read(fc_as_hex, address, count)

    def setValues(self, fc_as_hex: int, address: int, values: Sequence[Any]) -> None:
        self._server._write(fc_as_hex, address, values)

    async def async_getValues(self, fc_as_hex: int, address: int, count: int = 1) -> List[Any]:
        await self._server._gate()
        return self._server._read(fc_as_hex, address, count)

    async def async_setValues(self, fc_as_hex: int, address: int, values: Sequence[Any]) -> None:
        await self._server._gate()
        self._server._write(fc_as_hex, address, values)


class _UnknownDeviceContext(ModbusBaseSlaveContext):
    """Any unit id other than the compressor's: refused with exception 4 (as pymodbus 3.16 answers)."""

    def __init__(self, server: "LegacyCompressorServer", unit: int) -> None:
        self._server, self._unit = server, unit

    def reset(self) -> None:
        """Nothing to reset."""

    def validate(self, fc_as_hex: int, address: int, count: int = 1) -> bool:
        return True

    def _refuse(self, fc_as_hex: int) -> None:
        if _refused_already():
            return
        log.warning("%s %s:%d refused fc=%d for unit id %d: this stand-in is unit id %d (exception %d)",
                    self._server.name, self._server.host, self._server.port, fc_as_hex, self._unit, self._server.device_id,
                    EXC_DEVICE_FAILURE)
        _note_refusal(EXC_DEVICE_FAILURE)

    async def async_getValues(self, fc_as_hex: int, address: int, count: int = 1) -> List[Any]:
        await self._server._gate()
        self._refuse(fc_as_hex)
        return [0] * max(0, count)

    async def async_setValues(self, fc_as_hex: int, address: int, values: Sequence[Any]) -> None:
        await self._server._gate()
        self._refuse(fc_as_hex)


class _ServerContext(ModbusServerContext):
    """Routes the compressor's unit id to the device and every other id to a refusing context."""

    def __init__(self, server: "LegacyCompressorServer") -> None:
        # single=True: the 3.6 framer then passes frames for every unit id on to __getitem__ (with single=False
        # it silently drops frames for unknown ids and the client only sees a timeout)
        self._device = _DeviceContext(server)
        super().__init__(slaves=self._device, single=True)
        self._server = server

    def __getitem__(self, slave: int) -> Any:
        if slave == self._server.device_id:
            return self._device
        return _UnknownDeviceContext(self._server, slave)


class LegacyCompressorServer(CompressorServerBase):
    """pymodbus 3.6 TCP server bound to a :class:`CompressorModel` (custom slave context, see the module doc)."""

    pymodbus_line = "3.6"

    def __init__(self, model: CompressorModel, host: str = "127.0.0.1", port: int = 5020, device_id: int = 1,
                 register_map: Any = None, name: str = "compressor") -> None:
        super().__init__(model, host, port, device_id, register_map, name)

    # -- register map access (called by _DeviceContext inside the request's task) --------------------------
    def _read(self, function_code: int, address: int, count: int) -> List[Any]:
        table = _TABLES.get(function_code)
        try:
            if table is None:
                raise RegisterAccessError(2, "function code %d has no table in this device" % function_code)
            names = {"coils": self.map.COILS, "discrete_inputs": self.map.DISCRETE_INPUTS}.get(table)
            if names is None:
                return list(self.map.read_registers(table, address, count))
            if address < 0 or address >= len(names):
                raise RegisterAccessError(2, "%s address %d not in map, allowed 0..%d"
                                          % (table, address, len(names) - 1))
            # bits past the end of the map read 0, as on the 3.16 line (see modbus_server)
            inside = min(count, len(names) - address)
            return list(self.map.read_bits(table, address, inside)) + [False] * max(0, count - inside)
        except RegisterAccessError as exc:
            if not _refused_already():
                _note_refusal(self._refused(function_code, address, exc))
            return [0] * max(0, count)

    def _write(self, function_code: int, address: int, values: Sequence[Any]) -> None:
        try:
            if function_code in (5, 15):
                self.map.write_bits(address, [bool(v) for v in values])
            elif function_code in (6, 16, 22, 23):
                self.map.write_registers(address, [int(v) for v in values])
            else:
                raise RegisterAccessError(2, "function code %d cannot write" % function_code)
        except RegisterAccessError as exc:
            _note_refusal(self._refused(function_code, address, exc))

    def _answer(self, response: Any) -> Tuple[Any, bool]:
        """``response_manipulator``: count the request, turn a recorded refusal into its exception response."""
        self.requests += 1
        code: Optional[int] = _refusal.get()
        if code is None:
            return response, False
        _refusal.set(None)
        refusal = ExceptionResponse(response.function_code & 0x7F, code)
        refusal.transaction_id = response.transaction_id
        refusal.slave_id = response.slave_id
        return refusal, False

    # -- pymodbus glue -------------------------------------------------------------------------------------
    async def _listen(self) -> Any:
        server = ModbusTcpServer(_ServerContext(self), address=(self.host, self.port),
                                 response_manipulator=self._answer)
        if not await server.listen():       # pymodbus 3.6 logs the OSError and returns False
            raise DeviceStandInError("cannot be bound (in use or not local)")
        return server

    async def _shutdown(self, server: Any) -> None:
        await server.shutdown()
