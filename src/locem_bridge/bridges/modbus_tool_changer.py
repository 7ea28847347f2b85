"""Tool changer backend over Modbus TCP (pymodbus sync client), the pattern of :mod:`.modbus_compressor`.

Register map: the device's, documented in :mod:`locem_bridge.sim.modbus.tool_changer` (its stand-in) and
docs/protocol_notes.md: coil 0 ``lock`` (1 lock, 0 unlock), coil 1 ``fault_reset``; input registers 0..5
``coupled_tool_id``, ``fault_code``, ``status_bits`` (bit0 locked, bit1 unlocked, bit2 busy, bit3 tool_coupled,
bit4 fault_active, bit5 at_slot), ``slots_present`` (bit n-1 = slot n), ``flange_slot``, ``operations``.

A poll thread reads the six input registers every 1 / ``poll_rate`` s (10 Hz) into :meth:`cached` and the
health record (``coupled_tool``, ``locked``, ``fault``). Link loss: a failed poll, or none answered within
``stale_after`` (0.5 s), reports the link ``down`` and every command answers ``HARDWARE_ERROR``
(:class:`~.errors.LinkDown`); a lock or unlock waiting for its confirmation ends with it.

Safe state, before any command: the first successful poll after :meth:`start` and the first after a loss
command the lock coil to what the device reports (locked when a tool is coupled or the lock is closed, open
otherwise), so a coupled tool is held and a lock or unlock cut off by the loss is not repeated; only then is the
link reported ``up``. Until the first safe state every command answers ``NOT_READY``. The changer never moves
by itself; nothing else is needed to make it safe (no communication watchdog: holding the tool is safe).
"""

import logging
import threading
import time
from typing import Any, Callable, Dict, Mapping, Optional

from ..common.rate import FixedRate
from .config import need
from .errors import DeviceFault, LinkDown, NotConnected
from .modbus_link import ModbusLink
from .interfaces import Health, ToolChanger, Waiter

log = logging.getLogger(__name__)

COIL_LOCK, COIL_FAULT_RESET = 0, 1
IN_COUPLED, IN_COUNT = 0, 6
FAULTS = {0: "none", 1: "not at a slot", 2: "slot empty", 3: "not at the tool's slot"}
MAX_REQUEST_TIMEOUT = 0.5
WAIT_PERIOD = 0.02                 # s between two reads while a lock / unlock is confirmed


class ModbusToolChanger(ToolChanger):
    """The tool changer backend (see the module docstring). ``cfg`` is ``robot.tool_changer``."""

    def __init__(self, cfg: Mapping[str, Any], poll_rate: float = 10.0, stale_after: float = 0.5) -> None:
        where = "robot.tool_changer"
        self.host = need(cfg, "host", str, where=where)
        self.port = need(cfg, "port", int, lo=1, hi=65535, where=where)
        self.device_id = need(cfg, "device_id", int, lo=0, hi=247, where=where)
        self.timeout = min(MAX_REQUEST_TIMEOUT, need(cfg, "timeout", float, default=0.5, lo=0.01, where=where))
        self.lock_timeout = need(cfg, "lock_timeout", float, default=3.0, lo=0.1, where=where)
        rack = need(cfg, "rack", dict, where=where)
        self.slots: Dict[str, int] = {tool: int(slot["slot"]) for tool, slot in rack.items()}
        self._tool_of = {n: tool for tool, n in self.slots.items()}
        self.poll_rate = poll_rate
        self.stale_after = stale_after
        self._health = Health("connecting")
        self._link = ModbusLink("tool_changer", self.host, self.port, self.device_id, self.timeout)
        self._lock = self._link.lock            # one request at a time on the client
        self._state: Dict[str, Any] = {}
        self._last_ok = 0.0
        self._was_down = False
        self._safe = False
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.polls = 0
        self.safe_state_writes = 0

    # -- lifecycle ---------------------------------------------------------------------------------------
    def start(self) -> None:
        self._link.open()
        self._stop.clear()
        self._thread = threading.Thread(target=self._poll_loop, name="tool-changer-poll", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        if self._link.is_open:
            self._link.close()
        self._health.set(link="down", device="closed")

    def stop(self) -> None:
        """Nothing to stop: the lock moves for a fraction of a second and holds its tool (never opens it)."""

    # -- requests ----------------------------------------------------------------------------------------
    def _request(self, call: Callable[[Any, Dict[str, Any]], Any], attempts: int = 2) -> Any:
        """One Modbus request with a bounded timeout, retried; raises LinkDown / DeviceFault."""
        return self._link.request(call, attempts)

    def _read_state(self) -> Dict[str, Any]:
        regs = self._request(lambda c, kw: c.read_input_registers(IN_COUPLED, count=IN_COUNT, **kw)).registers
        bits = regs[2]
        return {"coupled_tool_id": regs[0], "coupled_tool": self._tool_of.get(regs[0], ""),
                "fault_code": regs[1], "fault": FAULTS.get(regs[1], "code %d" % regs[1]),
                "locked": bool(bits & 1), "unlocked": bool(bits & 2), "busy": bool(bits & 4),
                "fault_active": bool(bits & 16), "at_slot": bool(bits & 32),
                "present": {tool: bool(regs[3] >> (n - 1) & 1) for tool, n in self.slots.items()},
                "flange_slot": regs[4], "operations": regs[5], "stamp": time.time()}

    def _make_safe(self, state: Dict[str, Any], why: str) -> None:
        hold = bool(state["coupled_tool_id"]) or state["locked"]
        self._request(lambda c, kw: c.write_coil(COIL_LOCK, hold, **kw))
        self.safe_state_writes += 1
        log.warning("tool changer %s: lock commanded %s (%s)", why, "closed" if hold else "open",
                    "holds %s" % state["coupled_tool"] if state["coupled_tool"] else "no tool coupled")

    def _poll_loop(self) -> None:
        rate = FixedRate(1.0 / self.poll_rate, self._stop)
        while not self._stop.is_set():
            try:
                state = self._read_state()
                silent = self._last_ok > 0.0 and time.monotonic() - self._last_ok > self.stale_after
                if not self._safe or self._was_down or silent:
                    self._make_safe(state, "link back" if self._safe else "connected")
                    self._was_down = False
                    self._safe = True
                self._store(state)
                self.polls += 1
                self._health.set(link="up", device="fault: %s" % state["fault"] if state["fault_active"] else "ok",
                                 coupled_tool=state["coupled_tool"], locked=state["locked"],
                                 flange_slot=state["flange_slot"])
            except LinkDown as exc:
                if not self._was_down:
                    log.warning("%s", exc)
                self._was_down = True
                self._health.set(link="down", device="unknown", error=exc.message)
            except DeviceFault as exc:
                self._health.set(error=exc.message)
            rate.sleep()

    def _store(self, state: Dict[str, Any]) -> None:
        with self._lock:
            self._state = state
        self._last_ok = time.monotonic()

    # -- interface ---------------------------------------------------------------------------------------
    def check_link(self) -> None:
        if not self._safe:
            raise NotConnected("tool changer %s:%d is not in its safe state yet (lock commanded to what the "
                               "device holds: done at the first answer after LOCEM starts): %s"
                               % (self.host, self.port, self._health.last_error or "no answer yet"),
                               device="tool_changer")
        age = time.monotonic() - self._last_ok
        if self._was_down or age > self.stale_after:
            raise LinkDown("tool changer link is down (no answer for %.2f s): %s"
                           % (age, self._health.last_error or "not connected"), device="tool_changer")

    def cached(self) -> Dict[str, Any]:
        with self._lock:
            return dict(self._state)

    def read(self) -> Dict[str, Any]:
        self.check_link()
        state = self._read_state()
        self._store(state)
        return dict(state)

    def lock(self, waiter: Waiter) -> Dict[str, Any]:
        return self._move(waiter, True)

    def unlock(self, waiter: Waiter) -> Dict[str, Any]:
        return self._move(waiter, False)

    def _move(self, waiter: Waiter, lock: bool) -> Dict[str, Any]:
        what = "lock" if lock else "unlock"
        self.check_link()
        before = self.read()
        self._request(lambda c, kw: c.write_coil(COIL_LOCK, lock, **kw))
        end = time.monotonic() + self.lock_timeout
        while True:
            waiter.sleep(WAIT_PERIOD)
            self.check_link()
            state = self.read()
            if state["fault_active"]:
                raise DeviceFault("tool changer refused to %s: fault %d (%s), flange at %s" % (
                    what, state["fault_code"], state["fault"],
                    "slot %d" % state["flange_slot"] if state["flange_slot"] else "no rack slot"),
                    device="tool_changer")
            if not state["busy"] and (state["locked"] if lock else state["unlocked"]):
                state["duration_s"] = round(self.lock_timeout - (end - time.monotonic()), 3)
                return state
            if time.monotonic() > end:
                raise DeviceFault("tool changer did not confirm the %s within %.1f s (before: %s; now: locked %s, "
                                  "unlocked %s, busy %s)" % (what, self.lock_timeout, before["coupled_tool"] or
                                                             "no tool", state["locked"], state["unlocked"],
                                                             state["busy"]), device="tool_changer")

    def health(self) -> Dict[str, Any]:
        report = self._health.report()
        age = time.monotonic() - self._last_ok if self._last_ok else None
        report["age_s"] = round(age, 3) if age is not None else None
        if report["link"] == "up" and age is not None and age > self.stale_after:
            report["link"] = "down"
            report["last_error"] = "no answer from the tool changer for %.2f s" % age
        return report
