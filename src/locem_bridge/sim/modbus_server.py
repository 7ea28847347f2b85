"""Modbus TCP server of the compressor stand-in (pymodbus 3.16 adapter around :mod:`.compressor`).

Lifecycle: ``CompressorServer(model, host, port, device_id)`` -> :meth:`start` (binds, serves from its own
asyncio thread; returns once listening) -> :meth:`stop`. Every request passes through a ``SimDevice`` action
callback that reads/writes the :class:`~locem_bridge.sim.compressor.CompressorRegisterMap`; refused requests are
answered with the Modbus exception code and logged (``refused`` counts them).

Link faults (:meth:`drop_link`): ``mode="close"`` closes the listening socket and every connection (clients get
connection errors) and re-opens it after ``duration`` wall seconds; ``mode="silent"`` keeps the connections but
answers nothing until the link returns (clients time out). ``duration=None`` keeps the link down until
:meth:`restore_link`.

Bit reads that start inside the map but run past its end return 0 for the missing bits (pymodbus packs bits
into 16-bit words and does not pass the bit count to the device); every other address outside the map is
refused with exception 2.
"""
from __future__ import annotations

import asyncio
import logging
import threading
from typing import Any, List, Optional

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from .compressor import (COILS, DISCRETE_INPUTS, HOLDING_REGISTERS, INPUT_REGISTERS, CompressorModel,
                         CompressorRegisterMap, RegisterAccessError)
from .errors import DeviceStandInError

log = logging.getLogger(__name__)

_BIT_READ = {1: "coils", 2: "discrete_inputs"}
_REG_READ = {3: "holding", 4: "input"}


def _exc(code: int) -> Any:
    return ExcCodes.ILLEGAL_VALUE if code == 3 else ExcCodes.ILLEGAL_ADDRESS


class CompressorServer:
    """pymodbus TCP server bound to a :class:`CompressorModel`."""

    def __init__(self, model: CompressorModel, host: str = "127.0.0.1", port: int = 5020, device_id: int = 1) -> None:
        self.model = model
        self.map = CompressorRegisterMap(model)
        self.host, self.port, self.device_id = host, int(port), int(device_id)
        self.refused = 0
        self.requests = 0
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._thread: Optional[threading.Thread] = None
        self._server: Optional[ModbusTcpServer] = None
        self._link_up: Optional[asyncio.Event] = None
        self._restore_handle: Optional[asyncio.TimerHandle] = None
        self.link_state = "down"

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
        if self._link_up is not None and not self._link_up.is_set():
            await self._link_up.wait()          # silent link drop: hold the answer
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
                table, names = "coils", COILS
            elif function_code == 2:
                table, names = "discrete_inputs", DISCRETE_INPUTS
            else:
                table = "holding" if function_code in (3, 6, 16, 23) else "input"
                if set_values is None:
                    self.map.read_registers(table, address, count)          # refuses addresses not in the map
                regs = self.map.read_registers(table, 0, len(HOLDING_REGISTERS if table == "holding"
                                                             else INPUT_REGISTERS))
                current_registers[:len(regs)] = regs
                return None
            if set_values is None and address >= len(names):
                raise RegisterAccessError(2, "%s address %d not in map, allowed 0..%d" % (table, address, len(names) - 1))
            bits = self.map.read_bits(table, 0, len(names))
            current_registers[0] = sum(1 << i for i, b in enumerate(bits) if b)
            return None
        except RegisterAccessError as exc:
            self.refused += 1
            log.warning("compressor %s:%d refused fc=%d address=%d: %s (exception %d)",
                        self.host, self.port, function_code, address, exc, exc.exception_code)
            return _exc(exc.exception_code)

    async def _open(self) -> None:
        self._server = ModbusTcpServer(self._device(), address=(self.host, self.port))
        await self._server.serve_forever(background=True)
        self.link_state = "up"

    async def _close(self) -> None:
        if self._server is not None:
            await self._server.shutdown()
            self._server = None

    # -- lifecycle -----------------------------------------------------------------------------------------
    def _run(self, started: threading.Event, box: List[BaseException]) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._link_up = asyncio.Event()
            self._link_up.set()
            self._loop.run_until_complete(self._open())
        except BaseException as exc:  # report bind errors to start()
            box.append(exc)
            started.set()
            return
        started.set()
        self._loop.run_forever()
        self._loop.run_until_complete(self._close())
        self._loop.close()

    def start(self, timeout: float = 5.0) -> None:
        """Bind and serve; raises DeviceStandInError when the address cannot be bound."""
        if self._thread is not None:
            raise DeviceStandInError("compressor server already started")
        self._loop = asyncio.new_event_loop()
        started = threading.Event()
        box: List[BaseException] = []
        self._thread = threading.Thread(target=self._run, args=(started, box), name="compressor-modbus", daemon=True)
        self._thread.start()
        if not started.wait(timeout) or box:
            self._thread.join(1.0)
            self._thread = None
            raise DeviceStandInError("compressor Modbus server could not listen on %s:%d: %s"
                                     % (self.host, self.port, box[0] if box else "timeout"))
        log.info("compressor Modbus TCP stand-in listening on %s:%d (device id %d)", self.host, self.port,
                 self.device_id)

    def stop(self) -> None:
        """Close all connections and stop the thread (idempotent)."""
        if self._thread is None:
            return
        loop = self._loop

        def _halt() -> None:
            if self._link_up is not None:
                self._link_up.set()
            loop.stop()
        loop.call_soon_threadsafe(_halt)
        self._thread.join(5.0)
        self._thread = None
        self.link_state = "down"

    # -- link faults ---------------------------------------------------------------------------------------
    def _call(self, coro_fn: Any) -> None:
        if self._loop is None or self._thread is None:
            raise DeviceStandInError("compressor server is not running")
        fut = asyncio.run_coroutine_threadsafe(coro_fn(), self._loop)
        fut.result(5.0)

    def drop_link(self, duration: Optional[float] = None, mode: str = "close") -> None:
        """Take the link down (``close`` or ``silent``) for ``duration`` wall seconds (None = until restored)."""
        if mode not in ("close", "silent"):
            raise DeviceStandInError("drop_link mode %r not allowed, allowed: close, silent" % mode)

        async def _drop() -> None:
            if mode == "close":
                await self._close()
            else:
                self._link_up.clear()
            self.link_state = "dropped_" + mode
            log.warning("compressor link dropped (%s)%s", mode, "" if duration is None else " for %.2f s" % duration)
            if duration is not None:
                self._restore_handle = self._loop.call_later(duration, lambda: self._loop.create_task(self._restore()))
        self._call(_drop)

    async def _restore(self) -> None:
        if self._restore_handle is not None:
            self._restore_handle.cancel()
            self._restore_handle = None
        if self._server is None:
            await self._open()
        self._link_up.set()
        self.link_state = "up"
        log.warning("compressor link restored")

    def restore_link(self) -> None:
        """Bring a dropped link back now."""
        self._call(self._restore)
