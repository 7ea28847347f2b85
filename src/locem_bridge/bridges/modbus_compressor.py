"""Spray compressor over Modbus TCP (pymodbus client), register map of ``locem_bridge.sim.modbus.compressor``.

=================  =======  ======================================================================
table              address  meaning
=================  =======  ======================================================================
coils              0, 1     motor_on, spray_valve (write 1 = on / open); coil 2 fault_reset
holding registers  0, 1     pressure set-point (cbar); communication watchdog timeout (ms, 0 = off)
input registers    0..4     measured pressure (cbar), motor current (cA), fault code, status bits
                            (bit0 motor running, bit1 valve open, bit2 pressure in range, bit3 fault,
                            bit4 watchdog tripped), watchdog trips since power-up
=================  =======  ======================================================================

Lifecycle: ``ModbusCompressor(cfg)`` -> :meth:`start` (poll thread at ``poll_rate`` Hz, 10..20) -> :meth:`close`.
Every request has a timeout of at most 500 ms and is retried once on a fresh connection (pymodbus reconnects on
the next request, with its own growing delay). A failed poll marks the link ``down``; commands then fail with
:class:`~.errors.LinkDown` (``HARDWARE_ERROR``).

Communication watchdog: the device closes its spray valve and stops its motor by itself when no request reaches
it for ``robot.compressor.watchdog_timeout`` seconds (default :data:`WATCHDOG_TIMEOUT`, 0.5 s). The bridge writes
that timeout at every (re)connect; its regular polls (two reads every 1 / ``poll_rate`` s) keep the watchdog
refreshed, so a dead LOCEM leaves the compressor safe within the timeout (+ the device's 20 ms check period). The
0.5 s equals ``stale_after``, the gap after which the bridge itself already treats the link as lost and makes the
device safe, so the watchdog adds no new stop on a busy machine. A device found tripped (``watchdog_tripped``) is
reported (a warning, ``health()["watchdog"]``) and re-armed; a device that lost the setting (a power cycle) gets
it written again at the next poll.

Safe state, before any command: the first successful poll after :meth:`start`, and the first after a loss (a
failed poll, a poll answered later than ``stale_after``, a stop that could not reach the device, a watchdog trip
seen by a poll), commands the spray valve closed, then the motor off, then arms the watchdog, before the link is
reported ``up``. Until that first safe state is confirmed every command answers ``NOT_READY`` naming it (a LOCEM
just started does not know what a previous one left running). Whatever was running when the link died (e.g. a
SPRAY_AREA that then failed with ``HARDWARE_ERROR``) is thus left with no spray and no motor; nothing restarts by
itself. A command that needs pressure again switches the motor on itself (SPRAY_AREA does; SET_PRESSURE asks for
COMPRESSOR_ON first).
"""

import logging
import threading
import time
from typing import Any, Callable, Dict, Mapping, Optional

from ..common.rate import FixedRate
from .config import need
from .errors import DeviceFault, LinkDown, NotConnected
from .modbus_link import ModbusLink
from .interfaces import Compressor, Health

log = logging.getLogger(__name__)

COIL_MOTOR, COIL_VALVE, COIL_FAULT_RESET = 0, 1, 2
HOLD_SETPOINT, HOLD_WATCHDOG = 0, 1
IN_PRESSURE = 0
FAULTS = {0: "none", 1: "overpressure", 2: "motor overload"}
MAX_REQUEST_TIMEOUT = 0.5
#: default communication watchdog timeout of the device, s (see the module docstring)
WATCHDOG_TIMEOUT = 0.5


class ModbusCompressor(Compressor):
    """The compressor backend (see the module docstring). ``cfg`` is ``robot.compressor``."""

    def __init__(self, cfg: Mapping[str, Any], poll_rate: float = 15.0, stale_after: float = 0.5) -> None:
        self.host = need(cfg, "host", str, where="robot.compressor")
        self.port = need(cfg, "port", int, lo=1, hi=65535, where="robot.compressor")
        self.device_id = need(cfg, "device_id", int, lo=0, hi=247, where="robot.compressor")
        self.timeout = min(MAX_REQUEST_TIMEOUT, need(cfg, "timeout", float, default=0.5, lo=0.01,
                                                     where="robot.compressor"))
        band = need(cfg, "pressure_range", list, where="robot.compressor")
        self.pressure_range = (float(band[0]), float(band[1]))
        self.max_setpoint = need(cfg, "max_setpoint", float, lo=0.1, where="robot.compressor")
        self.watchdog_timeout = need(cfg, "watchdog_timeout", float, default=WATCHDOG_TIMEOUT, lo=0.05, hi=60.0,
                                     where="robot.compressor")
        self.watchdog_ms = int(round(self.watchdog_timeout * 1000.0))
        if not 10.0 <= poll_rate <= 20.0:
            raise ValueError("poll_rate must be 10..20 Hz, got %r" % poll_rate)
        self.poll_rate = poll_rate
        self.stale_after = stale_after
        self._health = Health("connecting")
        self._link = ModbusLink("compressor", self.host, self.port, self.device_id, self.timeout)
        self._lock = self._link.lock            # one request at a time on the client
        self._state: Dict[str, Any] = {}
        self._last_ok = 0.0
        self._was_down = False
        self._safe = False                      # the safe state was confirmed since start()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.polls = 0
        self.safe_state_writes = 0              # times the safe state was commanded (start, after a link loss)
        self.watchdog_trips_seen = 0            # trips found on the device at a (re)connect or poll

    # -- lifecycle ---------------------------------------------------------------------------------------
    def start(self) -> None:
        self._link.open()
        self._stop.clear()
        self._thread = threading.Thread(target=self._poll_loop, name="compressor-poll", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        if self._link.is_open:
            for coil in (COIL_VALVE, COIL_MOTOR):
                try:
                    self._request(lambda c, kw, coil=coil: c.write_coil(coil, False, **kw), attempts=1)
                except (LinkDown, DeviceFault):
                    break
            self._link.close()
        self._health.set(link="down", device="closed")

    # -- requests ----------------------------------------------------------------------------------------
    def _request(self, call: Callable[[Any, Dict[str, Any]], Any], attempts: int = 2) -> Any:
        """One Modbus request with a bounded timeout, retried; raises LinkDown / DeviceFault."""
        return self._link.request(call, attempts)

    def _read_state(self) -> Dict[str, Any]:
        regs = self._request(lambda c, kw: c.read_input_registers(IN_PRESSURE, count=5, **kw)).registers
        hold = self._request(lambda c, kw: c.read_holding_registers(HOLD_SETPOINT, count=2, **kw)).registers
        bits = regs[3]
        state = {"pressure": regs[0] / 100.0, "motor_current": regs[1] / 100.0, "fault_code": regs[2],
                 "fault": FAULTS.get(regs[2], "code %d" % regs[2]), "motor_running": bool(bits & 1),
                 "valve_open": bool(bits & 2), "in_range": bool(bits & 4), "fault_active": bool(bits & 8),
                 "watchdog_tripped": bool(bits & 16), "watchdog_trips": regs[4], "watchdog_ms": hold[1],
                 "setpoint": hold[0] / 100.0, "stamp": time.time()}
        return state

    def _make_safe(self, state: Dict[str, Any], why: str) -> None:
        """Valve closed, motor off, watchdog armed (see the module docstring); updates ``state``."""
        self._request(lambda c, kw: c.write_coil(COIL_VALVE, False, **kw))
        self._request(lambda c, kw: c.write_coil(COIL_MOTOR, False, **kw))
        self._request(lambda c, kw: c.write_register(HOLD_WATCHDOG, self.watchdog_ms, **kw))
        state.update(valve_open=False, motor_running=False, watchdog_ms=self.watchdog_ms)
        if state.get("watchdog_tripped"):
            self.watchdog_trips_seen += 1
            log.warning("compressor %s:%d had been stopped by its communication watchdog (%d trips since power-up; "
                        "no request for %.2f s)", self.host, self.port, state.get("watchdog_trips", 0),
                        self.watchdog_timeout)
        state["watchdog_tripped"] = False
        self.safe_state_writes += 1
        log.warning("compressor %s: spray valve closed, motor off, watchdog %.2f s armed (safe state)", why,
                    self.watchdog_timeout)

    def _poll_loop(self) -> None:
        rate = FixedRate(1.0 / self.poll_rate, self._stop)
        while not self._stop.is_set():
            try:
                state = self._read_state()
                silent = self._last_ok > 0.0 and time.monotonic() - self._last_ok > self.stale_after
                if not self._safe or self._was_down or silent or state["watchdog_tripped"]:
                    # (re)connected, or the device stopped itself: safe state before anything else happens
                    self._make_safe(state, "link back" if self._safe else "connected")
                    self._was_down = False
                    self._safe = True
                elif state["watchdog_ms"] != self.watchdog_ms:
                    log.warning("compressor watchdog reads %d ms, expected %d ms (device restarted?): written again",
                                state["watchdog_ms"], self.watchdog_ms)
                    self._request(lambda c, kw: c.write_register(HOLD_WATCHDOG, self.watchdog_ms, **kw))
                with self._lock:
                    self._state = state
                self._last_ok = time.monotonic()
                self.polls += 1
                self._health.set(link="up", device="fault: %s" % state["fault"] if state["fault_active"] else "ok",
                                 pressure=state["pressure"], setpoint=state["setpoint"],
                                 motor_running=state["motor_running"], valve_open=state["valve_open"],
                                 watchdog={"timeout_s": self.watchdog_timeout, "device_trips": state["watchdog_trips"],
                                           "trips_seen": self.watchdog_trips_seen})
            except LinkDown as exc:
                if not self._was_down:
                    log.warning("%s", exc)
                self._was_down = True
                self._health.set(link="down", device="unknown", error=exc.message)
            except DeviceFault as exc:
                self._health.set(error=exc.message)
            rate.sleep()

    # -- interface ---------------------------------------------------------------------------------------
    def check_link(self) -> None:
        self._check_safe()
        age = time.monotonic() - self._last_ok
        if self._was_down or self._last_ok == 0.0 or age > self.stale_after:
            raise LinkDown("compressor link is down (no answer for %.2f s): %s"
                           % (age if self._last_ok else float("inf"), self._health.last_error or "not connected yet"),
                           device="compressor")

    def _check_safe(self) -> None:
        """Raise :class:`NotConnected` (``NOT_READY``) until the safe state at start is confirmed."""
        if not self._safe:
            raise NotConnected("compressor %s:%d is not in its safe state yet (valve closed, motor off, watchdog "
                               "armed: done at the first answer after LOCEM starts): %s"
                               % (self.host, self.port, self._health.last_error or "no answer yet"),
                               device="compressor")

    def cached(self) -> Dict[str, Any]:
        with self._lock:
            return dict(self._state)

    def read(self) -> Dict[str, Any]:
        self._check_safe()
        state = self._read_state()
        with self._lock:
            self._state = state
        return dict(state)

    def read_pressure(self) -> float:
        """One fresh read of the measured pressure register (bar)."""
        regs = self._request(lambda c, kw: c.read_input_registers(IN_PRESSURE, count=1, **kw)).registers
        return regs[0] / 100.0

    def set_motor(self, on: bool) -> None:
        self.check_link()
        if not on:
            self._request(lambda c, kw: c.write_coil(COIL_VALVE, False, **kw))
        self._request(lambda c, kw: c.write_coil(COIL_MOTOR, bool(on), **kw))

    def set_setpoint(self, bar: float) -> None:
        self.check_link()
        value = int(round(bar * 100.0))
        self._request(lambda c, kw: c.write_register(HOLD_SETPOINT, value, **kw))

    def set_valve(self, open_: bool) -> None:
        self.check_link()
        self._request(lambda c, kw: c.write_coil(COIL_VALVE, bool(open_), **kw))

    def reset_fault(self) -> None:
        self.check_link()
        self._request(lambda c, kw: c.write_coil(COIL_FAULT_RESET, True, **kw))

    def stop(self) -> None:
        """Valve closed, motor off; never blocks on a link known to be down (the valve closes when it returns)."""
        try:
            self.check_link()
        except (LinkDown, NotConnected) as exc:
            self._was_down = True
            log.warning("compressor stop deferred until the link returns: %s", exc.message)
            return
        for coil in (COIL_VALVE, COIL_MOTOR):
            try:
                self._request(lambda c, kw, coil=coil: c.write_coil(coil, False, **kw), attempts=1)
            except (LinkDown, DeviceFault) as exc:
                self._was_down = True       # forces the valve-closed write on the next good poll
                log.warning("compressor stop: %s", exc)

    def health(self) -> Dict[str, Any]:
        report = self._health.report()
        age = time.monotonic() - self._last_ok if self._last_ok else None
        report["age_s"] = round(age, 3) if age is not None else None
        if report["link"] == "up" and age is not None and age > self.stale_after:
            report["link"] = "down"        # a request is hanging: no answer within stale_after
            report["last_error"] = "no answer from the compressor for %.2f s" % age
        return report
