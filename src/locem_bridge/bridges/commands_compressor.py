"""LOCEM commands of the spray compressor (declarations in ``SPECS``; :class:`CompressorCommands` binds them).

Pressures are in bar. ``SET_PRESSURE`` waits (by default) until the measured pressure is within ``tolerance``
of the set-point; ``SPRAY_ON`` opens the valve only while the pressure is inside the working band of the
robot YAML (``robot.compressor.pressure_range``). A lost link answers ``HARDWARE_ERROR``.
"""

import time
from typing import Any, Dict, Iterable

from locem_bridge.locem.errors import NotReady
from locem_bridge.locem.registry import Arg, CommandSpec

from .errors import DeviceFault
from .interfaces import Compressor, Waiter

CATEGORY = "compressor"
_RES = frozenset({"compressor"})
MAX_SETPOINT_BAR = 10.0

COMPRESSOR_ON = CommandSpec(
    "COMPRESSOR_ON", "Start the compressor motor (checks that it runs).", resources=_RES, category=CATEGORY,
    timeout=5.0, result=(("motor_running", "true once the motor runs"), ("pressure", "measured pressure, bar")),
    capability="sk:cap_RunCompressor")
COMPRESSOR_OFF = CommandSpec(
    "COMPRESSOR_OFF", "Close the spray valve and stop the compressor motor.", resources=_RES, category=CATEGORY,
    timeout=5.0, result=(("motor_running", "false"),), capability="sk:cap_StopCompressor")
SET_PRESSURE = CommandSpec(
    "SET_PRESSURE", "Set the pressure set-point; by default wait until the pressure is within tolerance.",
    args=(Arg.number("pressure", "bar", 0.0, MAX_SETPOINT_BAR, "pressure set-point"),
          Arg.flag("wait", "wait for the pressure to reach the set-point", default=True, keyword_only=True),
          Arg.number("tolerance", "bar", 0.01, 2.0, "allowed |measured - set-point| when waiting", default=0.2,
                     keyword_only=True)),
    resources=_RES, category=CATEGORY, timeout=60.0,
    result=(("pressure", "measured pressure at the end, bar"), ("setpoint", "set-point, bar"),
            ("waited_s", "seconds until within tolerance")), capability="sk:cap_SetPressure")
GET_PRESSURE = CommandSpec(
    "GET_PRESSURE", "Read the compressor now: pressure, set-point, motor, valve, fault.", category=CATEGORY,
    timeout=2.0, inline=True, query=True,
    result=(("pressure", "measured pressure, bar"), ("setpoint", "set-point, bar"),
            ("motor_running", "motor on and no fault"), ("valve_open", "spray valve open"),
            ("in_range", "pressure inside the working band"), ("fault", "none, overpressure, motor overload")))
SPRAY_ON = CommandSpec(
    "SPRAY_ON", "Open the spray valve (only while the pressure is inside the working band).",
    resources=_RES, category=CATEGORY, timeout=3.0, result=(("valve_open", "true"), ("pressure", "bar")),
    capability="sk:cap_SwitchSpray")
SPRAY_OFF = CommandSpec(
    "SPRAY_OFF", "Close the spray valve.", resources=_RES, category=CATEGORY, timeout=3.0,
    result=(("valve_open", "false"),), capability="sk:cap_SwitchSpray")

SPECS = (COMPRESSOR_ON, COMPRESSOR_OFF, SET_PRESSURE, GET_PRESSURE, SPRAY_ON, SPRAY_OFF)


def _public(state: Dict[str, Any]) -> Dict[str, Any]:
    keys = ("pressure", "setpoint", "motor_running", "valve_open", "in_range", "fault", "motor_current")
    return {k: state[k] for k in keys if k in state}


def wait_for_pressure(compressor: Compressor, waiter: Waiter, setpoint: float, tolerance: float,
                      timeout: float) -> Dict[str, Any]:
    """Poll until |pressure - setpoint| <= tolerance; raises on link loss, fault or ``timeout``."""
    start = time.monotonic()
    while True:
        compressor.check_link()
        state = compressor.cached()
        if state.get("fault_active"):
            raise DeviceFault("compressor fault: %s" % state.get("fault"), device="compressor")
        if abs(state.get("pressure", -1e9) - setpoint) <= tolerance:
            state["waited_s"] = round(time.monotonic() - start, 3)
            return state
        if time.monotonic() - start > timeout:
            raise DeviceFault("pressure %.2f bar did not reach %.2f +- %.2f bar within %.0f s"
                              % (state.get("pressure", float("nan")), setpoint, tolerance, timeout), device="compressor")
        waiter.report(min(0.99, state.get("pressure", 0.0) / setpoint if setpoint > 0 else 0.0),
                      "pressure %.2f bar" % state.get("pressure", 0.0))
        waiter.sleep(1.0 / compressor.poll_rate)


class CompressorCommands:
    """The compressor command set for :meth:`LocemCore.install`."""

    name = "compressor"

    def __init__(self, compressor: Compressor) -> None:
        self.compressor = compressor

    def specs(self) -> Iterable[CommandSpec]:
        return SPECS

    def handlers(self) -> Dict[str, Any]:
        return {"COMPRESSOR_ON": self.on, "COMPRESSOR_OFF": self.off, "SET_PRESSURE": self.set_pressure,
                "GET_PRESSURE": self.get_pressure, "SPRAY_ON": self.spray_on, "SPRAY_OFF": self.spray_off}

    def stop(self) -> None:
        self.compressor.stop()

    def health(self) -> Dict[str, Any]:
        return self.compressor.health()

    # -- handlers ----------------------------------------------------------------------------------------
    def on(self, ctx: Any) -> Dict[str, Any]:
        comp = self.compressor
        comp.set_motor(True)
        end = time.monotonic() + 2.0
        while True:
            state = comp.read()
            if state["motor_running"]:
                return _public(state)
            if state["fault_active"] or time.monotonic() > end:
                raise DeviceFault("compressor motor does not run (fault: %s)" % state["fault"], device="compressor")
            ctx.sleep(0.05)

    def off(self, ctx: Any) -> Dict[str, Any]:
        self.compressor.set_motor(False)
        return _public(self.compressor.read())

    def set_pressure(self, ctx: Any, pressure: float, wait: bool, tolerance: float) -> Dict[str, Any]:
        comp = self.compressor
        if pressure > comp.max_setpoint:
            from .errors import BadRequest
            raise BadRequest("SET_PRESSURE: pressure %.2f bar exceeds this compressor's max_setpoint %.2f bar"
                             % (pressure, comp.max_setpoint), device="compressor", argument="pressure")
        comp.set_setpoint(pressure)
        if not wait:
            return _public(comp.read())
        if not comp.read()["motor_running"] and pressure > tolerance:
            raise NotReady("SET_PRESSURE: the motor is off, the pressure cannot rise; send COMPRESSOR_ON first")
        state = wait_for_pressure(comp, ctx, pressure, tolerance, timeout=max(1.0, ctx.remaining() - 0.5)
                                  if hasattr(ctx, "remaining") else 55.0)
        out = _public(state)
        out["waited_s"] = state["waited_s"]
        return out

    def get_pressure(self, ctx: Any) -> Dict[str, Any]:
        state = self.compressor.read()
        out = _public(state)
        out["message"] = "%.2f bar (set-point %.2f bar)" % (state["pressure"], state["setpoint"])
        return out

    def spray_on(self, ctx: Any) -> Dict[str, Any]:
        comp = self.compressor
        state = comp.read()
        lo, hi = comp.pressure_range
        if not lo <= state["pressure"] <= hi:
            raise NotReady("SPRAY_ON: pressure %.2f bar is outside the working band %.2f..%.2f bar; "
                           "SET_PRESSURE first" % (state["pressure"], lo, hi))
        comp.set_valve(True)
        return _public(comp.read())

    def spray_off(self, ctx: Any) -> Dict[str, Any]:
        self.compressor.set_valve(False)
        return _public(self.compressor.read())
