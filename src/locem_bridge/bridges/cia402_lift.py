"""The lift carrying the arm, over CAN: one CiA 402 drive in PROFILED POSITION mode (canopen ``BaseNode402``) on
the base's bus (``robot.base.drives.can``; its own node id ``robot.lift.drive.node_id``).

Lifecycle: ``Cia402Lift(lift_cfg, can_cfg, eds_path)`` -> :meth:`start` (opens its own python-can bus on the
configured channel; a supervisor thread enables the drive: heartbeat seen, NMT OPERATIONAL, PROFILED POSITION,
profile velocity / acceleration / deceleration from ``robot.lift``, OPERATION ENABLED; then watches heartbeat
and statusword at 20 Hz) -> :meth:`close` (halt, drive disabled, bus closed).

Heights ``z`` are the arm mount's (the arm's base_link origin) above base_footprint; the axis position (drive
counts, 0x6064 / 0x607A) is ``(z - range[0]) x counts_per_m``. A move: target position 0x607A (SDO), controlword
new set-point (bit 4, change immediately bit 5; SDO, so it is ordered after the target), the drive acknowledges
(statusword bit 12), the bit is cleared; done when the drive reports target reached (bit 10) and the position is
within ``tolerance`` of the goal (a LIFT to where the axis already stands so is answered at once, no set-point
sent). Halt (STOP, cancel): controlword bit 8 (the drive brakes at its deceleration and holds). Deadline
(:class:`~.errors.MotionTimeout`, the lift halted first)::

    deadline = scale x (trapezoid time of the move at max_velocity / acceleration) + margin

(``robot.lift.deadline``, defaults 1.0 and 5 s). A silent drive (no heartbeat for ``heartbeat_ms`` x 3) or a
FAULT statusword latches a fault: moves end with :class:`~.errors.DeviceFault` (``HARDWARE_ERROR``); the supervisor
enables the drive again once its heartbeat is back (a drive FAULT needs the fault reset of a new enable: the next
LIFT after the heartbeat returns, or a restart of LOCEM).
"""

import logging
import math
import threading
import time
from typing import Any, Dict, Mapping, Optional, Tuple

from .can_link import open_device_bus
from .config import need
from .errors import BadRequest, DeviceFault, MotionTimeout, NotConnected
from .interfaces import Health, Lift, Waiter

log = logging.getLogger(__name__)

SW_FAULT = 0x08
SW_TARGET_REACHED = 0x0400
SW_SETPOINT_ACK = 0x1000
CW_ENABLE = 0x0F
CW_NEW_SETPOINT = 0x10 | 0x20          # new set-point + change set immediately (absolute target)
CW_HALT = 0x100
HEARTBEAT_FACTOR = 3.0          # a position-mode axis finishes its move by itself: no need to trip early


class Cia402Lift(Lift):
    """The lift backend (see the module docstring). ``cfg`` is ``robot.lift``, ``can_cfg`` the base's bus."""

    def __init__(self, cfg: Mapping[str, Any], can_cfg: Mapping[str, Any], eds_path: str, bus: Any = None) -> None:
        w = "robot.lift"
        rng = list(need(cfg, "range", list, where=w))
        self.range: Tuple[float, float] = (float(rng[0]), float(rng[1]))
        self.max_velocity = need(cfg, "max_velocity", float, lo=0.001, where=w)
        self.acceleration = need(cfg, "acceleration", float, lo=0.001, where=w)
        self.tolerance = need(cfg, "tolerance", float, default=0.001, lo=0.0001, where=w)
        drv = need(cfg, "drive", dict, where=w)
        self.node_id = need(drv, "node_id", int, lo=1, hi=127, where=w + ".drive")
        self.counts_per_m = need(drv, "counts_per_m", float, lo=1.0, where=w + ".drive")
        self.vel_units = need(drv, "velocity_units_per_m_s", float, lo=1.0, where=w + ".drive")
        self.hb_timeout = need(drv, "heartbeat_ms", float, default=100.0, lo=1.0, where=w + ".drive") / 1000.0 \
            * HEARTBEAT_FACTOR
        self.deadline_scale = need(cfg, "deadline.scale", float, default=1.0, lo=0.01, hi=100.0, where=w)
        self.deadline_margin = need(cfg, "deadline.margin", float, default=5.0, lo=0.0, hi=600.0, where=w)
        self.can_cfg = dict(can_cfg)
        self.eds_path = eds_path
        self._bus_given = bus
        self._bus: Any = None
        self.network: Any = None
        self.node: Any = None
        self._health = Health("connecting")
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._enabled = False
        self._fault: Optional[str] = None
        self._last_hb = 0.0
        self._moving: Optional[Dict[str, Any]] = None

    # -- lifecycle ---------------------------------------------------------------------------------------
    def _open_bus(self) -> Any:
        return open_device_bus(self.can_cfg, "lift")

    def start(self) -> None:
        import canopen

        self._bus = self._bus_given or self._open_bus()
        self.network = canopen.Network(self._bus)
        self.network.connect()
        self.node = canopen.BaseNode402(self.node_id, self.eds_path)
        self.network.add_node(self.node)
        self.network.subscribe(0x700 + self.node_id, self._on_heartbeat)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="lift-supervisor", daemon=True)
        self._thread.start()

    def _on_heartbeat(self, can_id: int, data: bytes, timestamp: float) -> None:
        self._last_hb = time.monotonic()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(3.0)
            self._thread = None
        if self.network is not None:
            if self._enabled:
                try:
                    self.node.sdo[0x6040].raw = 0x06            # shutdown: the axis brake holds it
                except Exception:
                    pass
            try:
                self.network.disconnect() if self._bus_given is None else self.network.notifier.stop(1.0)
            except Exception:
                pass
            self.network = None
        self._enabled = False
        self._health.set(link="down", device="closed")

    def _enable(self) -> None:
        node = self.node
        node.nmt.wait_for_heartbeat(max(1.0, 3 * self.hb_timeout))
        self._last_hb = time.monotonic()
        node.setup_402_state_machine()
        node.nmt.state = "OPERATIONAL"
        node.op_mode = "PROFILED POSITION"
        node.sdo[0x6081].raw = int(round(self.max_velocity * self.vel_units))
        node.sdo[0x6083].raw = int(round(self.acceleration * self.vel_units))
        node.sdo[0x6084].raw = int(round(self.acceleration * self.vel_units))
        node.sdo[0x6040].raw = 0x80                    # fault reset (no effect outside FAULT)
        node.state = "OPERATION ENABLED"
        node.tpdo_values.pop(0x6041, None)
        with self._lock:
            self._enabled = True
            self._fault = None

    def _run(self) -> None:
        backoff = 0.5
        while not self._stop.is_set():
            if not self._enabled:
                self._health.set(link="connecting")
                try:
                    self._enable()
                    backoff = 0.5
                    self._health.set(link="up", device="ok", error="")
                    log.info("lift: drive %d enabled (profile position)", self.node_id)
                except Exception as exc:  # canopen raises several kinds (SdoCommunicationError, RuntimeError, ...)
                    self._health.set(link="down", error="enabling the lift drive failed: %s: %s"
                                     % (type(exc).__name__, exc))
                    self._stop.wait(backoff)
                    backoff = min(5.0, backoff * 2.0)
                    continue
            self._watch()
            self._stop.wait(0.05)

    def _watch(self) -> None:
        silent = time.monotonic() - self._last_hb
        why = ""
        if silent > self.hb_timeout:
            why = "lift drive %d heartbeat lost (silent %.0f ms)" % (self.node_id, silent * 1000)
        sw = self.node.tpdo_values.get(0x6041)
        if sw is not None and sw & SW_FAULT:
            why = "lift drive %d reports FAULT (statusword 0x%04X)" % (self.node_id, sw)
        if why and self._fault is None:
            log.error("lift: %s", why)
            with self._lock:
                self._fault = why
            self._health.set(device="fault: %s" % why, error=why)
        if self._fault is not None and silent < self.hb_timeout and "heartbeat" in self._fault:
            with self._lock:
                self._enabled = False                  # back on the bus: enable it again

    # -- interface ---------------------------------------------------------------------------------------
    def _ready(self) -> None:
        if self._fault is not None:
            raise DeviceFault("lift stopped: %s" % self._fault, device="lift")
        if not self._enabled:
            raise NotConnected("lift drive is not enabled yet (%s)" % (self._health.last_error or "enabling"),
                               device="lift")

    def height_or_nan(self) -> float:
        counts = self.node.tpdo_values.get(0x6064) if self.node is not None else None
        return float("nan") if counts is None else self.range[0] + counts / self.counts_per_m

    def height(self) -> float:
        z = self.height_or_nan()
        if math.isnan(z):
            raise NotConnected("lift position not received yet", device="lift")
        return z

    def _travel_time(self, d: float) -> float:
        v, a = self.max_velocity, self.acceleration
        return d / v + v / a if d > v * v / a else 2.0 * math.sqrt(d / a)

    def move_to(self, waiter: Waiter, z: float) -> Dict[str, Any]:
        lo, hi = self.range
        if not lo <= z <= hi:
            raise BadRequest("lift height %.4f m is outside the lift's range [%g, %g] m (robot.lift.range)"
                             % (z, lo, hi), device="lift", argument="z")
        self._ready()
        start = self.height()
        t0 = time.monotonic()
        node = self.node
        if abs(z - start) <= self.tolerance and (node.tpdo_values.get(0x6041) or 0) & SW_TARGET_REACHED:
            # at rest where it is asked to go (the next band of a section, a piece at the same height): no set-point
            return {"height": round(start, 4), "error": round(abs(start - z), 4), "duration_s": 0.0}
        budget = self.deadline_scale * self._travel_time(abs(z - start)) + self.deadline_margin
        move = {"z": z}
        with self._lock:
            self._moving = move
        waiter.on_cancel(self.halt)
        try:
            node.sdo[0x6040].raw = CW_ENABLE                          # halt bit and set-point bit cleared
            node.sdo[0x607A].raw = int(round((z - lo) * self.counts_per_m))
            node.sdo[0x6040].raw = CW_ENABLE | CW_NEW_SETPOINT
            ack_end = time.monotonic() + 1.0
            while not int(node.sdo[0x6041].raw) & SW_SETPOINT_ACK:
                if time.monotonic() > ack_end:
                    raise DeviceFault("lift drive did not acknowledge the set-point (statusword 0x%04X)"
                                      % int(node.sdo[0x6041].raw), device="lift")
                waiter.sleep(0.01)
            node.sdo[0x6040].raw = CW_ENABLE
            while True:
                waiter.sleep(0.02)
                if self._fault is not None:
                    raise DeviceFault("lift stopped during LIFT: %s" % self._fault, device="lift")
                if self._moving is not move:
                    from locem_bridge.locem.errors import Aborted
                    raise Aborted("LIFT stopped")
                h = self.height()
                sw = node.tpdo_values.get(0x6041) or 0
                if sw & SW_TARGET_REACHED and abs(h - z) <= self.tolerance:
                    break
                span = abs(z - start)
                waiter.report(1.0 - min(1.0, abs(z - h) / span) if span > 1e-6 else 0.5, "%.3f m to go" % abs(z - h))
                if time.monotonic() - t0 > budget:
                    self.halt()
                    raise MotionTimeout("LIFT did not reach %.3f m within %.1f s (at %.3f m)" % (z, budget, h),
                                        device="lift")
        finally:
            with self._lock:
                if self._moving is move:
                    self._moving = None
        h = self.height()
        return {"height": round(h, 4), "error": round(abs(h - z), 4), "duration_s": round(time.monotonic() - t0, 3)}

    def halt(self) -> None:
        with self._lock:
            self._moving = None
        if self.network is not None and self._enabled:
            try:
                self.node.sdo[0x6040].raw = CW_ENABLE | CW_HALT
            except Exception as exc:
                log.warning("lift halt: %s", exc)

    def stop(self) -> None:
        self.halt()

    def health(self) -> Dict[str, Any]:
        report = self._health.report()
        report["fault"] = self._fault or ""
        z = self.height_or_nan()
        report["height"] = None if math.isnan(z) else round(z, 4)
        report["range"] = list(self.range)
        return report
