"""Lifecycle and link faults of the compressor Modbus TCP stand-in, shared by the pymodbus adapters.

pymodbus-free on purpose: :class:`CompressorServerBase` owns the asyncio thread, the start/stop lifecycle, the
link-drop fault modes and the refusal accounting; an adapter subclass (:mod:`.modbus_server` for pymodbus 3.16,
:mod:`.modbus_legacy` for pymodbus 3.6.x, the last line for Python 3.8 / Noetic) only builds and shuts down its
pymodbus server and routes every request through the one
:class:`~locem_bridge.sim.modbus.compressor.CompressorRegisterMap`, so both lines answer alike.

Lifecycle: ``Adapter(model, host, port, device_id)`` -> :meth:`~CompressorServerBase.start` (binds, serves from its
own asyncio thread; returns once listening, raises :class:`DeviceStandInError` when it cannot bind) ->
:meth:`~CompressorServerBase.stop` (idempotent).

Link faults (:meth:`~CompressorServerBase.drop_link`): ``mode="close"`` closes the listening socket and every
connection (clients get connection errors) and re-opens it after ``duration`` wall seconds; ``mode="silent"``
keeps the connections but answers nothing until the link returns (clients time out; the held requests are
answered late, when the link returns). ``duration=None`` keeps the link down until
:meth:`~CompressorServerBase.restore_link`. Requests held or refused by a dropped link never reach the device, so
its communication watchdog (:class:`~locem_bridge.sim.modbus.compressor.CompressorRegisterMap`), checked by the server
thread every ``WATCHDOG_CHECK_PERIOD`` seconds, trips during a drop as it does when the client dies.

:meth:`~CompressorServerBase.state` is what a test reads: the model, the watchdog and the valve / motor history.

Adapter contract: implement ``async _listen() -> server`` (raise ``OSError`` or any exception when the address
cannot be bound) and ``async _shutdown(server)`` (close the listener and every connection); await :meth:`_gate`
before touching the model for a request; report refused requests through :meth:`_refused`.
"""
from __future__ import annotations

import asyncio
import logging
import re
import socket
import threading
from typing import Any, Dict, List, Optional, Tuple

from .compressor import WATCHDOG_CHECK_PERIOD, CompressorModel, CompressorRegisterMap, RegisterAccessError
from ..errors import DeviceStandInError

log = logging.getLogger("locem_bridge.sim.modbus.modbus_server")

LINK_MODES = ("close", "silent")


def parse_version(text: str) -> Tuple[int, int, int]:
    """``"3.6.9"`` -> ``(3, 6, 9)``; missing or non-numeric parts count as 0 (``"3.7.0.dev1"`` -> (3, 7, 0))."""
    parts = [int(m) if m else 0 for m in (re.match(r"\d*", p).group(0) for p in str(text).split(".")[:3])]
    while len(parts) < 3:
        parts.append(0)
    return parts[0], parts[1], parts[2]


def bind_problem(host: str, port: int) -> str:
    """Why ``host:port`` cannot be bound now (e.g. ``Address already in use``), "" when it can: the adapters'
    own bind errors are vague (pymodbus 3.16: "Could not start listen, please check address")."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            return str(exc.strerror or exc)
    return ""


class CompressorServerBase:
    """Modbus TCP stand-in of the compressor: lifecycle and link faults (see the module docstring).

    :param model: the pressure model served.
    :param host: address to bind (e.g. ``127.0.0.1``).
    :param port: TCP port to bind.
    :param device_id: Modbus unit id answered; requests to any other id are refused with exception 4.
    :param register_map: the device's register map (default: the compressor's, :class:`CompressorRegisterMap`
        of ``model``); any map with the same methods and table names (``COILS``, ``DISCRETE_INPUTS``,
        ``HOLDING_REGISTERS``, ``INPUT_REGISTERS``) is served alike, e.g. the tool changer's
        (:mod:`.tool_changer`).
    :param name: the device's name in log lines, errors and the thread's name.
    """

    #: which pymodbus line the adapter talks to, e.g. ``"3.16"`` (set by subclasses)
    pymodbus_line = ""

    def __init__(self, model: CompressorModel, host: str = "127.0.0.1", port: int = 5020,
                 device_id: int = 1, register_map: Any = None, name: str = "compressor") -> None:
        self.name = name
        if not 0 <= int(device_id) <= 247:
            raise DeviceStandInError("%s device_id %r not allowed, allowed 0..247" % (name, device_id))
        if not 0 <= int(port) <= 65535:
            raise DeviceStandInError("%s port %r not allowed, allowed 0..65535" % (name, port))
        self.model = model
        self.map = register_map if register_map is not None else CompressorRegisterMap(model)
        self.host, self.port, self.device_id = host, int(port), int(device_id)
        self.refused = 0
        self.requests = 0
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._thread: Optional[threading.Thread] = None
        self._server: Any = None
        self._link_up: Optional[asyncio.Event] = None
        self._restore_handle: Optional[asyncio.TimerHandle] = None
        self._watchdog_handle: Optional[asyncio.TimerHandle] = None
        self.link_state = "down"

    def state(self) -> Dict[str, Any]:
        """The device as a test sees it: model snapshot, link, watchdog and the valve / motor history."""
        out = self.model.snapshot()
        out.update(link=self.link_state, watchdog=self.map.watchdog_state(), history=self.model.history(),
                   requests=self.requests, refused=self.refused)
        return out

    # -- adapter hooks -------------------------------------------------------------------------------------
    async def _listen(self) -> Any:
        """Build the pymodbus server and start listening; return it."""
        raise NotImplementedError

    async def _shutdown(self, server: Any) -> None:
        """Close the listener and every connection of ``server``."""
        raise NotImplementedError

    # -- shared request helpers ----------------------------------------------------------------------------
    async def _gate(self) -> None:
        """Hold the request while the link is dropped in ``silent`` mode."""
        if self._link_up is not None and not self._link_up.is_set():
            await self._link_up.wait()

    def _refused(self, function_code: int, address: int, exc: RegisterAccessError) -> int:
        """Count and log a refused request; returns its Modbus exception code."""
        self.refused += 1
        log.warning("%s %s:%d refused fc=%d address=%d: %s (exception %d)", self.name,
                    self.host, self.port, function_code, address, exc, exc.exception_code)
        return exc.exception_code

    # -- lifecycle -----------------------------------------------------------------------------------------
    def _watch(self) -> None:
        """Check the device's communication watchdog, then again in ``WATCHDOG_CHECK_PERIOD`` (server thread)."""
        try:
            if self.map.check_watchdog():
                log.warning("compressor %s:%d: communication watchdog tripped (no request for %d ms): spray valve "
                            "closed, motor off", self.host, self.port, self.map.watchdog_ms)
        finally:
            if self._loop is not None and not self._loop.is_closed():
                self._watchdog_handle = self._loop.call_later(WATCHDOG_CHECK_PERIOD, self._watch)

    async def _open(self) -> None:
        self._server = await self._listen()
        self.link_state = "up"

    async def _close(self) -> None:
        if self._server is not None:
            server, self._server = self._server, None
            await self._shutdown(server)

    def _run(self, started: threading.Event, box: List[BaseException]) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._link_up = asyncio.Event()
            self._link_up.set()
            self._loop.run_until_complete(self._open())
        except BaseException as exc:  # report bind errors to start()
            box.append(exc)
            self._loop.close()
            started.set()
            return
        started.set()
        self._watch()
        self._loop.run_forever()
        try:
            self._loop.run_until_complete(self._close())
        finally:
            self._loop.close()

    def start(self, timeout: float = 5.0) -> None:
        """Bind and serve; raises DeviceStandInError when the address cannot be bound."""
        if self._thread is not None:
            raise DeviceStandInError("%s server already started" % self.name)
        self._loop = asyncio.new_event_loop()
        started = threading.Event()
        box: List[BaseException] = []
        self._thread = threading.Thread(target=self._run, args=(started, box), name="%s-modbus" % self.name,
                                        daemon=True)
        self._thread.start()
        if not started.wait(timeout) or box:
            self._thread.join(1.0)
            self._thread = None
            raise DeviceStandInError("%s Modbus stand-in cannot listen on %s:%d: %s"
                                     % (self.name, self.host, self.port, bind_problem(self.host, self.port)
                                        or (box[0] if box else "timeout")))
        log.info("%s Modbus TCP stand-in listening on %s:%d (device id %d, pymodbus %s line)", self.name, self.host,
                 self.port, self.device_id, self.pymodbus_line)

    def stop(self) -> None:
        """Close all connections and stop the thread (idempotent)."""
        if self._thread is None:
            return
        loop = self._loop

        def _halt() -> None:
            if self._watchdog_handle is not None:
                self._watchdog_handle.cancel()
            if self._link_up is not None:
                self._link_up.set()             # release requests held by a silent drop
            loop.stop()
        loop.call_soon_threadsafe(_halt)
        self._thread.join(5.0)
        self._thread = None
        self.link_state = "down"

    # -- link faults ---------------------------------------------------------------------------------------
    def _call(self, coro_fn: Any) -> None:
        if self._loop is None or self._thread is None:
            raise DeviceStandInError("%s server is not running" % self.name)
        fut = asyncio.run_coroutine_threadsafe(coro_fn(), self._loop)
        fut.result(5.0)

    def drop_link(self, duration: Optional[float] = None, mode: str = "close") -> None:
        """Take the link down (``close`` or ``silent``) for ``duration`` wall seconds (None = until restored)."""
        if mode not in LINK_MODES:
            raise DeviceStandInError("drop_link mode %r not allowed, allowed: %s" % (mode, ", ".join(LINK_MODES)))
        if duration is not None and not (isinstance(duration, (int, float)) and duration >= 0.0):
            raise DeviceStandInError("drop_link duration %r not allowed, allowed: None or seconds >= 0" % (duration,))

        async def _drop() -> None:
            if mode == "close":
                await self._close()
            else:
                self._link_up.clear()
            self.link_state = "dropped_" + mode
            log.warning("%s link dropped (%s)%s", self.name, mode, "" if duration is None else " for %.2f s" % duration)
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
        log.warning("%s link restored", self.name)

    def restore_link(self) -> None:
        """Bring a dropped link back now."""
        self._call(self._restore)
