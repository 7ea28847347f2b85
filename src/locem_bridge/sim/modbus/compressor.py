"""Compressor stand-in model: a first-order pressure model and its Modbus register map (plain Python).

Protocol-independent on purpose: :class:`CompressorModel` holds the physics and the faults,
:class:`CompressorRegisterMap` maps Modbus tables/addresses to the model and raises
:class:`RegisterAccessError` with the Modbus exception code for bad requests. The pymodbus 3.16 server in
:mod:`locem_bridge.sim.modbus.modbus_server` is a thin adapter; the pymodbus 3.6 adapter (the last line for Python 3.8),
:mod:`locem_bridge.sim.modbus.modbus_legacy`, calls the same methods.

Register map (PDU addresses, 0-based; device id from ``robot.compressor.device_id``)

=================  =======  ===========================  =====================================================
table              address  name                         meaning
=================  =======  ===========================  =====================================================
coils (RW)         0        motor_on                     1 = run the compressor motor
coils (RW)         1        spray_valve                  1 = open the spray gun valve
coils (W)          2        fault_reset                  write 1: clear a latched fault (reads 0)
discrete inputs    0        motor_running                motor on and no fault
discrete inputs    1        valve_open                   spray valve open
discrete inputs    2        pressure_in_range            measured pressure within ``pressure_range``
discrete inputs    3        fault_active                 fault code != 0
discrete inputs    4        watchdog_tripped             the communication watchdog stopped the device (latched
                                                         until ``watchdog_timeout`` is written again)
holding (RW)       0        pressure_setpoint            centibar (0.01 bar), 0 .. max_setpoint*100
holding (RW)       1        watchdog_timeout             communication watchdog, ms: 0 = off (power-up value),
                                                         50 .. 60000; writing it (any value) clears
                                                         ``watchdog_tripped`` and restarts the timer
input registers    0        measured_pressure            centibar
input registers    1        motor_current                centiampere (0.01 A)
input registers    2        fault_code                   0 none, 1 overpressure, 2 motor overload
input registers    3        status_bits                  bit0 motor_running, bit1 valve_open, bit2 in range,
                                                         bit3 fault_active, bit4 watchdog_tripped
input registers    4        watchdog_trips               watchdog trips since power-up (saturates at 65535)
=================  =======  ===========================  =====================================================

Any other address -> exception 2 (ILLEGAL DATA ADDRESS); a setpoint outside the range -> exception 3
(ILLEGAL DATA VALUE). Faults: :meth:`CompressorModel.inject_overpressure` makes the regulator stick open so the
pressure climbs to the relief pressure; crossing ``overpressure_limit`` latches fault 1 and stops the motor.
:meth:`CompressorModel.inject_motor_fault` latches fault 2. A fault is cleared by writing ``fault_reset``
(only while the pressure is below the limit). Link drops are a property of the server, not of the model.

Communication watchdog (as industrial controllers have one): once ``watchdog_timeout`` is non-zero, every
request that reaches the device (any table, read or write, any connection) restarts its timer; when no request
arrives for that long (wall clock: the link is the device's real-time behaviour, whatever the sim time scale),
the device closes the spray valve and stops the motor by itself and latches ``watchdog_tripped``. It trips once
per silence: the next request restarts the timer. The server checks it every :data:`WATCHDOG_CHECK_PERIOD`
seconds, so the device is safe at most ``timeout + WATCHDOG_CHECK_PERIOD`` after the last request.

:meth:`CompressorModel.history` is the device's own record of every valve and motor change (wall time
``time.time()``, sim time, new value, cause: ``modbus``, ``watchdog``, ``test``), so a test can measure how long
after an event the device became safe.
"""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Optional, Sequence

from ..errors import DeviceStandInError

FAULT_NONE = 0
FAULT_OVERPRESSURE = 1
FAULT_MOTOR_OVERLOAD = 2

EXC_ILLEGAL_ADDRESS = 2
EXC_ILLEGAL_VALUE = 3

COILS = ("motor_on", "spray_valve", "fault_reset")
DISCRETE_INPUTS = ("motor_running", "valve_open", "pressure_in_range", "fault_active", "watchdog_tripped")
HOLDING_REGISTERS = ("pressure_setpoint", "watchdog_timeout")
INPUT_REGISTERS = ("measured_pressure", "motor_current", "fault_code", "status_bits", "watchdog_trips")

#: allowed non-zero values of the ``watchdog_timeout`` holding register, ms
WATCHDOG_MIN_MS, WATCHDOG_MAX_MS = 50, 60000
#: wall seconds between two checks of the watchdog by the server
WATCHDOG_CHECK_PERIOD = 0.02
#: entries kept in the valve / motor history
HISTORY_LENGTH = 256


class RegisterAccessError(DeviceStandInError):
    """A Modbus request the device refuses; ``exception_code`` is the Modbus exception code to answer."""

    def __init__(self, exception_code: int, message: str) -> None:
        super().__init__(message)
        self.exception_code = exception_code


class CompressorModel:
    """First-order pressure model of a spray compressor, advanced lazily on ``clock()`` (sim seconds).

    :param cfg: ``robot.compressor`` section (``pressure_range``, ``max_setpoint``, ``sim`` parameters).
    :param clock: callable returning sim time in seconds (e.g. :meth:`SimClock.now`).
    """

    def __init__(self, cfg: Dict[str, Any], clock: Callable[[], float]) -> None:
        sim = cfg["sim"]
        self.tau = float(sim["time_constant"])
        self.max_pressure = float(sim["max_pressure"])
        self.valve_drop = float(sim["valve_drop"])
        self.idle_current = float(sim["idle_current"])
        self.current_per_bar = float(sim["current_per_bar"])
        self.overpressure_limit = float(sim["overpressure_limit"])
        self.pressure_range = (float(cfg["pressure_range"][0]), float(cfg["pressure_range"][1]))
        self.max_setpoint = float(cfg["max_setpoint"])
        self._clock = clock
        self._lock = threading.RLock()
        self._t = clock()
        self.motor_on = False
        self.valve_open = False
        self.setpoint = 0.0
        self.pressure = 0.0
        self.fault_code = FAULT_NONE
        self._regulator_stuck = False
        self._history: Deque[Dict[str, Any]] = deque(maxlen=HISTORY_LENGTH)

    # -- physics -------------------------------------------------------------------------------------------
    def update(self) -> None:
        """Advance the model to ``clock()``."""
        with self._lock:
            now = self._clock()
            dt = now - self._t
            self._t = now
            if dt <= 0.0:
                return
            # integrate in slices so a fault trips at the right moment even for large dt
            steps = max(1, int(math.ceil(dt / (self.tau / 20.0))))
            h = dt / steps
            for _ in range(steps):
                running = self.motor_on and self.fault_code == FAULT_NONE
                if running:
                    target = self.max_pressure if self._regulator_stuck else min(self.setpoint, self.max_pressure)
                    if self.valve_open:
                        target = max(0.0, target - self.valve_drop)
                else:
                    target = 0.0
                tau = self.tau if running or not self.valve_open else self.tau / 4.0
                self.pressure += (target - self.pressure) * (1.0 - math.exp(-h / tau))
                if self.pressure > self.overpressure_limit and self.fault_code == FAULT_NONE:
                    self.fault_code = FAULT_OVERPRESSURE

    @property
    def motor_running(self) -> bool:
        return self.motor_on and self.fault_code == FAULT_NONE

    @property
    def motor_current(self) -> float:
        return self.idle_current + self.current_per_bar * self.pressure if self.motor_running else 0.0

    @property
    def pressure_in_range(self) -> bool:
        return self.pressure_range[0] <= self.pressure <= self.pressure_range[1]

    def spraying(self) -> bool:
        """True while the valve is open and the pressure is in the working range (compound comes out)."""
        with self._lock:
            self.update()
            return self.valve_open and self.pressure_in_range

    # -- commands ------------------------------------------------------------------------------------------
    def set_motor(self, on: bool, cause: str = "modbus") -> None:
        with self._lock:
            self.update()
            if self.motor_on != bool(on):
                self._note("motor_on", bool(on), cause)
            self.motor_on = bool(on)

    def set_valve(self, open_: bool, cause: str = "modbus") -> None:
        with self._lock:
            self.update()
            if self.valve_open != bool(open_):
                self._note("valve_open", bool(open_), cause)
            self.valve_open = bool(open_)

    def safe_stop(self, cause: str) -> None:
        """Valve closed, then motor off (what the watchdog does)."""
        with self._lock:
            self.set_valve(False, cause)
            self.set_motor(False, cause)

    def _note(self, what: str, value: bool, cause: str) -> None:
        self._history.append({"wall": time.time(), "sim": self._clock(), "what": what, "value": value,
                              "cause": cause})

    def history(self) -> List[Dict[str, Any]]:
        """Every valve / motor change, oldest first: ``{wall, sim, what, value, cause}`` (see the module doc)."""
        with self._lock:
            return [dict(e) for e in self._history]

    def set_setpoint(self, bar: float) -> None:
        if not (isinstance(bar, (int, float)) and math.isfinite(bar) and 0.0 <= bar <= self.max_setpoint):
            raise RegisterAccessError(EXC_ILLEGAL_VALUE, "pressure setpoint %r bar out of range, allowed 0 .. %g bar"
                                      % (bar, self.max_setpoint))
        with self._lock:
            self.update()
            self.setpoint = float(bar)

    def reset_fault(self) -> bool:
        """Clear a latched fault if the cause is gone; returns True when cleared."""
        with self._lock:
            self.update()
            if self.fault_code == FAULT_OVERPRESSURE and self.pressure > self.overpressure_limit:
                return False
            self.fault_code = FAULT_NONE
            self._regulator_stuck = False
            return True

    # -- fault injection -----------------------------------------------------------------------------------
    def inject_overpressure(self) -> None:
        """Make the regulator stick open: pressure rises towards ``max_pressure`` and trips fault 1."""
        with self._lock:
            self.update()
            self._regulator_stuck = True

    def inject_motor_fault(self) -> None:
        with self._lock:
            self.update()
            self.fault_code = FAULT_MOTOR_OVERLOAD

    def snapshot(self) -> Dict[str, Any]:
        with self._lock:
            self.update()
            return {"motor_on": self.motor_on, "motor_running": self.motor_running, "valve_open": self.valve_open,
                    "setpoint": self.setpoint, "pressure": self.pressure, "motor_current": self.motor_current,
                    "fault_code": self.fault_code, "pressure_in_range": self.pressure_in_range}


def _u16(value: float) -> int:
    return max(0, min(0xFFFF, int(round(value))))


class CompressorRegisterMap:
    """Modbus view of a :class:`CompressorModel` and its communication watchdog (see the module docstring).

    :param wall: monotonic wall clock of the watchdog (seconds).
    """

    #: the names of each table's addresses, 0-based (the server adapters serve exactly these)
    COILS, DISCRETE_INPUTS, HOLDING_REGISTERS, INPUT_REGISTERS = COILS, DISCRETE_INPUTS, HOLDING_REGISTERS, INPUT_REGISTERS

    def __init__(self, model: CompressorModel, wall: Callable[[], float] = time.monotonic) -> None:
        self.model = model
        self._wall = wall
        self._wd_lock = threading.Lock()
        self.watchdog_ms = 0
        self.watchdog_tripped = False
        self.watchdog_trips = 0
        self.last_trip: Optional[Dict[str, float]] = None
        self._last_traffic = wall()
        self._expired = False

    # -- communication watchdog ----------------------------------------------------------------------------
    def _traffic(self) -> None:
        """A request reached the device: restart the watchdog timer."""
        with self._wd_lock:
            self._last_traffic = self._wall()
            self._expired = False

    def check_watchdog(self) -> bool:
        """Trip the watchdog if it is armed and no request came for its timeout; True when it tripped now."""
        with self._wd_lock:
            if self.watchdog_ms <= 0 or self._expired:
                return False
            silent = self._wall() - self._last_traffic
            if silent * 1000.0 < self.watchdog_ms:
                return False
            self._expired = True
            self.watchdog_tripped = True
            self.watchdog_trips += 1
            self.last_trip = {"wall": time.time(), "silent_s": round(silent, 4)}
        self.model.safe_stop("watchdog")
        return True

    def watchdog_state(self) -> Dict[str, Any]:
        with self._wd_lock:
            return {"timeout_ms": self.watchdog_ms, "tripped": self.watchdog_tripped, "trips": self.watchdog_trips,
                    "last_trip": dict(self.last_trip) if self.last_trip else None,
                    "silent_s": round(self._wall() - self._last_traffic, 4)}

    def _set_watchdog(self, value: int) -> None:
        with self._wd_lock:
            self.watchdog_ms = int(value)
            self.watchdog_tripped = False
            self._last_traffic = self._wall()
            self._expired = False

    @staticmethod
    def _check(names: Sequence[str], table: str, address: int, count: int, writable: bool = True) -> None:
        if count < 1 or address < 0 or address + count > len(names):
            raise RegisterAccessError(EXC_ILLEGAL_ADDRESS, "%s %d..%d not in map, allowed 0..%d" % (
                table, address, address + count - 1, len(names) - 1))

    def read_bits(self, table: str, address: int, count: int) -> List[bool]:
        """``table`` is ``coils`` or ``discrete_inputs``."""
        self._traffic()
        m = self.model
        with m._lock:
            m.update()
            if table == "coils":
                self._check(COILS, table, address, count)
                values = [m.motor_on, m.valve_open, False]
            elif table == "discrete_inputs":
                self._check(DISCRETE_INPUTS, table, address, count)
                values = [m.motor_running, m.valve_open, m.pressure_in_range, m.fault_code != FAULT_NONE,
                          self.watchdog_tripped]
            else:
                raise RegisterAccessError(EXC_ILLEGAL_ADDRESS, "unknown bit table %r" % table)
        return values[address:address + count]

    def read_registers(self, table: str, address: int, count: int) -> List[int]:
        """``table`` is ``holding`` or ``input``; values are raw 16-bit integers."""
        self._traffic()
        m = self.model
        with m._lock:
            m.update()
            if table == "holding":
                self._check(HOLDING_REGISTERS, table, address, count)
                values = [_u16(m.setpoint * 100.0), self.watchdog_ms]
            elif table == "input":
                self._check(INPUT_REGISTERS, table, address, count)
                status = (int(m.motor_running) | int(m.valve_open) << 1 | int(m.pressure_in_range) << 2
                          | int(m.fault_code != FAULT_NONE) << 3 | int(self.watchdog_tripped) << 4)
                values = [_u16(m.pressure * 100.0), _u16(m.motor_current * 100.0), m.fault_code, status,
                          _u16(self.watchdog_trips)]
            else:
                raise RegisterAccessError(EXC_ILLEGAL_ADDRESS, "unknown register table %r" % table)
        return values[address:address + count]

    def write_bits(self, address: int, values: Sequence[bool]) -> None:
        self._traffic()
        self._check(COILS, "coils", address, len(values))
        for i, v in enumerate(values):
            a = address + i
            if a == 0:
                self.model.set_motor(bool(v))
            elif a == 1:
                self.model.set_valve(bool(v))
            elif a == 2 and v:
                self.model.reset_fault()

    def write_registers(self, address: int, values: Sequence[int]) -> None:
        self._traffic()
        self._check(HOLDING_REGISTERS, "holding", address, len(values))
        limit = int(round(self.model.max_setpoint * 100))
        for i, v in enumerate(values):        # check every value first: nothing half-applied
            if address + i == 0 and not 0 <= v <= limit:
                raise RegisterAccessError(EXC_ILLEGAL_VALUE, "pressure_setpoint %d cbar out of range, allowed 0..%d"
                                          % (v, limit))
            if address + i == 1 and v != 0 and not WATCHDOG_MIN_MS <= v <= WATCHDOG_MAX_MS:
                raise RegisterAccessError(EXC_ILLEGAL_VALUE, "watchdog_timeout %d ms out of range, allowed 0 (off) "
                                          "or %d..%d" % (v, WATCHDOG_MIN_MS, WATCHDOG_MAX_MS))
        for i, v in enumerate(values):
            if address + i == 0:
                self.model.set_setpoint(v / 100.0)
            elif address + i == 1:
                self._set_watchdog(v)
