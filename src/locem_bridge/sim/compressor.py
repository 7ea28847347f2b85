"""Compressor stand-in model: a first-order pressure model and its Modbus register map (plain Python).

Protocol-independent on purpose: :class:`CompressorModel` holds the physics and the faults,
:class:`CompressorRegisterMap` maps Modbus tables/addresses to the model and raises
:class:`RegisterAccessError` with the Modbus exception code for bad requests. The pymodbus 3.16 server in
:mod:`locem_bridge.sim.modbus_server` is a thin adapter; the pymodbus 3.6 adapter (the last line for Python 3.8),
:mod:`locem_bridge.sim.modbus_legacy`, calls the same methods.

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
holding (RW)       0        pressure_setpoint            centibar (0.01 bar), 0 .. max_setpoint*100
input registers    0        measured_pressure            centibar
input registers    1        motor_current                centiampere (0.01 A)
input registers    2        fault_code                   0 none, 1 overpressure, 2 motor overload
input registers    3        status_bits                  bit0 motor_running, bit1 valve_open, bit2 in range,
                                                         bit3 fault_active
=================  =======  ===========================  =====================================================

Any other address -> exception 2 (ILLEGAL DATA ADDRESS); a setpoint outside the range -> exception 3
(ILLEGAL DATA VALUE). Faults: :meth:`CompressorModel.inject_overpressure` makes the regulator stick open so the
pressure climbs to the relief pressure; crossing ``overpressure_limit`` latches fault 1 and stops the motor.
:meth:`CompressorModel.inject_motor_fault` latches fault 2. A fault is cleared by writing ``fault_reset``
(only while the pressure is below the limit). Link drops are a property of the server, not of the model.
"""
from __future__ import annotations

import math
import threading
from typing import Any, Callable, Dict, List, Sequence

from .errors import DeviceStandInError

FAULT_NONE = 0
FAULT_OVERPRESSURE = 1
FAULT_MOTOR_OVERLOAD = 2

EXC_ILLEGAL_ADDRESS = 2
EXC_ILLEGAL_VALUE = 3

COILS = ("motor_on", "spray_valve", "fault_reset")
DISCRETE_INPUTS = ("motor_running", "valve_open", "pressure_in_range", "fault_active")
HOLDING_REGISTERS = ("pressure_setpoint",)
INPUT_REGISTERS = ("measured_pressure", "motor_current", "fault_code", "status_bits")


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
    def set_motor(self, on: bool) -> None:
        with self._lock:
            self.update()
            self.motor_on = bool(on)

    def set_valve(self, open_: bool) -> None:
        with self._lock:
            self.update()
            self.valve_open = bool(open_)

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
    """Modbus view of a :class:`CompressorModel` (see the module docstring for the map)."""

    def __init__(self, model: CompressorModel) -> None:
        self.model = model

    @staticmethod
    def _check(names: Sequence[str], table: str, address: int, count: int, writable: bool = True) -> None:
        if count < 1 or address < 0 or address + count > len(names):
            raise RegisterAccessError(EXC_ILLEGAL_ADDRESS, "%s %d..%d not in map, allowed 0..%d" % (
                table, address, address + count - 1, len(names) - 1))

    def read_bits(self, table: str, address: int, count: int) -> List[bool]:
        """``table`` is ``coils`` or ``discrete_inputs``."""
        m = self.model
        with m._lock:
            m.update()
            if table == "coils":
                self._check(COILS, table, address, count)
                values = [m.motor_on, m.valve_open, False]
            elif table == "discrete_inputs":
                self._check(DISCRETE_INPUTS, table, address, count)
                values = [m.motor_running, m.valve_open, m.pressure_in_range, m.fault_code != FAULT_NONE]
            else:
                raise RegisterAccessError(EXC_ILLEGAL_ADDRESS, "unknown bit table %r" % table)
        return values[address:address + count]

    def read_registers(self, table: str, address: int, count: int) -> List[int]:
        """``table`` is ``holding`` or ``input``; values are raw 16-bit integers."""
        m = self.model
        with m._lock:
            m.update()
            if table == "holding":
                self._check(HOLDING_REGISTERS, table, address, count)
                values = [_u16(m.setpoint * 100.0)]
            elif table == "input":
                self._check(INPUT_REGISTERS, table, address, count)
                status = (int(m.motor_running) | int(m.valve_open) << 1 | int(m.pressure_in_range) << 2
                          | int(m.fault_code != FAULT_NONE) << 3)
                values = [_u16(m.pressure * 100.0), _u16(m.motor_current * 100.0), m.fault_code, status]
            else:
                raise RegisterAccessError(EXC_ILLEGAL_ADDRESS, "unknown register table %r" % table)
        return values[address:address + count]

    def write_bits(self, address: int, values: Sequence[bool]) -> None:
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
        self._check(HOLDING_REGISTERS, "holding", address, len(values))
        for i, v in enumerate(values):
            if address + i == 0:
                if not 0 <= v <= int(round(self.model.max_setpoint * 100)):
                    raise RegisterAccessError(EXC_ILLEGAL_VALUE, "pressure_setpoint %d cbar out of range, allowed 0..%d"
                                              % (v, int(round(self.model.max_setpoint * 100))))
                self.model.set_setpoint(v / 100.0)
