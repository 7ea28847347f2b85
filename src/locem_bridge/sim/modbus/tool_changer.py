"""Tool changer stand-in: the changer's lock, its rack of tool slots and their Modbus register map (plain Python).

An automatic tool changer couples a tool to the arm's flange: the robot side (on the flange) has a lock driven by
the device, every tool carries the tool-side plate with its id. The tools wait in a rack on the robot, one slot
each; a slot is a named arm pose (``robot.tool_changer.rack.<tool>: {slot: N, pose: [6 joints]}``), and a tool's
plate id is its slot number. The rack rides on the arm's mount, so a slot is the flange position the slot's pose
gives in the arm's ``base_link`` frame, wherever the base (or a lift) is.

:class:`ToolChangerModel` holds the device (lock state, tools in the rack, fault code) over a :class:`ToolRack`,
the physical side: :class:`WorldRack` binds it to the PyBullet world (:class:`~locem_bridge.sim.world.World`),
which mounts the coupled tool on the flange and parks a released one. :class:`ToolChangerRegisterMap` is the
Modbus view; the compressor's server adapters serve it unchanged
(:class:`~locem_bridge.sim.modbus.modbus_server.CompressorServer` with ``register_map=``), so a client sees the same
exceptions and link faults on both pymodbus lines. :func:`tool_changer_server` builds one.

Register map (PDU addresses, 0-based; device id from ``robot.tool_changer.device_id``)

=================  =======  ===========================  =====================================================
table              address  name                         meaning
=================  =======  ===========================  =====================================================
coils (RW)         0        lock                         write 1: lock (couple the tool in the slot the flange
                                                         is at), write 0: unlock (release the coupled tool into
                                                         its slot); reads the state last commanded and accepted
coils (W)          1        fault_reset                  write 1: clear the fault code (reads 0)
discrete inputs    0        locked                       lock closed (confirmed)
discrete inputs    1        unlocked                     lock open (confirmed); both 0 while it moves
discrete inputs    2        busy                         the lock is moving (``sim.lock_time``)
discrete inputs    3        tool_coupled                 a tool is coupled (``coupled_tool_id`` != 0)
discrete inputs    4        fault_active                 ``fault_code`` != 0
discrete inputs    5        at_slot                      the flange is at a rack slot now
discrete inputs    6..13    slot_1_present ..            a tool sits in rack slot 1 .. 8 (slots the rack does
                            slot_8_present               not have read 0)
input registers    0        coupled_tool_id              plate id of the coupled tool = its rack slot; 0 none
input registers    1        fault_code                   0 none, 1 not at a slot, 2 slot empty, 3 not at the
                                                         coupled tool's slot (see below)
input registers    2        status_bits                  bit0 locked, bit1 unlocked, bit2 busy, bit3
                                                         tool_coupled, bit4 fault_active, bit5 at_slot
input registers    3        slots_present                bit n-1 = a tool sits in slot n
input registers    4        flange_slot                  the slot the flange is at now, 0 none
input registers    5        operations                   locks + unlocks completed since power-up (saturates)
=================  =======  ===========================  =====================================================

There are no holding registers. Any other address -> exception 2 (ILLEGAL DATA ADDRESS).

Interlocks (the device refuses, the lock does not move, ``fault_code`` says why; the next lock/unlock command or
``fault_reset`` clears it): lock away from every rack slot -> 1 ``not at a slot``; lock at a slot holding no tool
-> 2 ``slot empty``; unlock while a tool is coupled and the flange is not at that tool's own slot -> 3 ``not at
the tool's slot`` (the tool would drop). A lock or unlock takes ``sim.lock_time`` sim seconds (``busy``); a lock
whose flange left the slot meanwhile ends unlocked with fault 1. The lock never opens by itself: a link loss or a
silent master leaves a coupled tool coupled (no communication watchdog: holding the tool is the safe state).
"""
from __future__ import annotations

import logging
import threading
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .compressor import EXC_ILLEGAL_ADDRESS, RegisterAccessError
from ..errors import DeviceStandInError, SimStateError

log = logging.getLogger(__name__)

MAX_SLOTS = 8
FAULT_NONE, FAULT_NOT_AT_SLOT, FAULT_SLOT_EMPTY, FAULT_WRONG_SLOT = 0, 1, 2, 3
FAULTS = {FAULT_NONE: "none", FAULT_NOT_AT_SLOT: "not at a slot", FAULT_SLOT_EMPTY: "slot empty",
          FAULT_WRONG_SLOT: "not at the tool's slot"}

COILS = ("lock", "fault_reset")
DISCRETE_INPUTS = ("locked", "unlocked", "busy", "tool_coupled", "fault_active", "at_slot") + tuple(
    "slot_%d_present" % n for n in range(1, MAX_SLOTS + 1))
HOLDING_REGISTERS: Tuple[str, ...] = ()
INPUT_REGISTERS = ("coupled_tool_id", "fault_code", "status_bits", "slots_present", "flange_slot", "operations")


class ToolRack:
    """The physical side of the changer: where the flange is and what the flange carries (an interface)."""

    def slot_at(self) -> int:
        """The rack slot the flange is at now (1..), 0 when none."""
        raise NotImplementedError

    def mounted(self) -> Optional[str]:
        """The tool on the flange now, None when none."""
        raise NotImplementedError

    def couple(self, tool: str) -> None:
        """The lock closed on ``tool``: it is on the flange now."""
        raise NotImplementedError

    def release(self, tool: str) -> None:
        """The lock opened: ``tool`` stays in its slot."""
        raise NotImplementedError


class WorldRack(ToolRack):
    """The rack of ``robot.tool_changer`` in a :class:`~locem_bridge.sim.world.World`: a slot is where its pose puts
    the flange in the arm's ``base_link`` frame (computed once), the flange is at it within ``sim.slot_tolerance``."""

    def __init__(self, world: Any, changer_cfg: Mapping[str, Any]) -> None:
        self.world = world
        self.tolerance = float(changer_cfg["sim"]["slot_tolerance"])
        self.slots: Dict[int, np.ndarray] = {}
        for tool, slot in changer_cfg["rack"].items():
            self.slots[int(slot["slot"])] = np.asarray(world.flange_in_mount(slot["pose"]), dtype=float)

    def slot_at(self) -> int:
        here = np.asarray(self.world.flange_in_mount(), dtype=float)
        for number, where in sorted(self.slots.items()):
            if float(np.linalg.norm(here - where)) <= self.tolerance:
                return number
        return 0

    def mounted(self) -> Optional[str]:
        return self.world.mounted_tool

    def couple(self, tool: str) -> None:
        self.world.mount_tool(tool, by="tool changer")

    def release(self, tool: str) -> None:
        self.world.remove_tool(by="tool changer")


class ToolChangerModel:
    """The changer device over a :class:`ToolRack` (see the module docstring), advanced lazily on ``clock()``.

    :param cfg: ``robot.tool_changer`` (``rack``, ``sim.lock_time``).
    :param clock: sim time, s.
    """

    def __init__(self, cfg: Mapping[str, Any], clock: Callable[[], float], rack: ToolRack) -> None:
        self.rack = rack
        self._clock = clock
        self.lock_time = float(cfg["sim"]["lock_time"])
        self.tool_of: Dict[int, str] = {int(s["slot"]): tool for tool, s in cfg["rack"].items()}
        self.slot_of: Dict[str, int] = {tool: n for n, tool in self.tool_of.items()}
        self._lock = threading.RLock()
        on_flange = rack.mounted()
        if on_flange is not None and on_flange not in self.slot_of:
            raise DeviceStandInError("tool %r is on the flange but has no rack slot (robot.tool_changer.rack: %s)"
                                     % (on_flange, ", ".join(sorted(self.slot_of))))
        self.coupled = self.slot_of[on_flange] if on_flange else 0
        self.locked = bool(self.coupled)         # a tool on the flange at power-up is held
        self.commanded = self.locked
        self.present = {n: n != self.coupled for n in self.tool_of}
        self.fault_code = FAULT_NONE
        self.operations = 0
        self._pending: Optional[Tuple[str, int, float]] = None   # (lock|unlock, slot, done at sim time)
        self._history: List[Dict[str, Any]] = []

    # -- the device ------------------------------------------------------------------------------------------
    def update(self) -> None:
        """Finish a lock / unlock whose ``lock_time`` has passed."""
        with self._lock:
            if self._pending is None or self._clock() < self._pending[2]:
                return
            what, slot, _ = self._pending
            self._pending = None
            if what == "lock":
                if self.rack.slot_at() != slot:          # the flange left the slot while the lock closed
                    self._fault(FAULT_NOT_AT_SLOT, "the flange left slot %d while locking" % slot)
                    self.commanded = False
                    return
                self.rack.couple(self.tool_of[slot])
                self.present[slot] = False
                self.coupled, self.locked = slot, True
            else:
                if self.coupled:
                    self.rack.release(self.tool_of[self.coupled])
                    self.present[self.coupled] = True
                self.coupled, self.locked = 0, False
            self.operations += 1
            self._note(what, slot)

    @property
    def busy(self) -> bool:
        return self._pending is not None

    def command_lock(self, lock: bool) -> None:
        """The lock coil written: lock (1) or unlock (0), with the interlocks of the module docstring."""
        with self._lock:
            self.update()
            if not self.busy:
                self.fault_code = FAULT_NONE         # every command clears the last one's refusal
            if self.busy or lock == self.commanded:
                return
            here = self.rack.slot_at()
            if lock:
                if here == 0:
                    return self._fault(FAULT_NOT_AT_SLOT, "lock refused: the flange is at no rack slot")
                if not self.present.get(here, False):
                    return self._fault(FAULT_SLOT_EMPTY, "lock refused: slot %d holds no tool" % here)
                self.commanded = True
                self._pending = ("lock", here, self._clock() + self.lock_time)
            else:
                if self.coupled and here != self.coupled:
                    return self._fault(FAULT_WRONG_SLOT, "unlock refused: %s is coupled and the flange is at %s, "
                                       "not at its slot %d" % (self.tool_of[self.coupled],
                                                               "slot %d" % here if here else "no slot", self.coupled))
                self.commanded = False
                self._pending = ("unlock", self.coupled, self._clock() + self.lock_time)
            self.update()

    def take_from_rack(self, tool: str) -> None:
        """The operator takes ``tool`` out of its rack slot (maintenance): the slot reads empty until
        :meth:`put_in_rack`. SimStateError when the tool is not in its slot."""
        with self._lock:
            slot = self._rack_slot(tool)
            if not self.present[slot]:
                raise SimStateError("%s is not in its rack slot %d" % (tool, slot))
            self.present[slot] = False

    def put_in_rack(self, tool: str) -> None:
        """The operator puts ``tool`` back into its rack slot."""
        with self._lock:
            slot = self._rack_slot(tool)
            if slot == self.coupled or self.present[slot]:
                raise SimStateError("%s is %s" % (tool, "on the flange" if slot == self.coupled else "in its slot"))
            self.present[slot] = True

    def _rack_slot(self, tool: str) -> int:
        if tool not in self.slot_of:
            raise SimStateError("%r has no rack slot, allowed: %s" % (tool, ", ".join(sorted(self.slot_of))))
        return self.slot_of[tool]

    def reset_fault(self) -> None:
        with self._lock:
            self.fault_code = FAULT_NONE

    def _fault(self, code: int, text: str) -> None:
        self.fault_code = code
        log.warning("tool changer: %s (fault %d)", text, code)
        self._note("fault", code)

    def _note(self, what: str, value: int) -> None:
        self._history.append({"sim": self._clock(), "what": what, "value": value})
        del self._history[:-256]

    def history(self) -> List[Dict[str, Any]]:
        """Every completed lock / unlock (value: the slot) and refusal (value: the fault code), oldest first."""
        with self._lock:
            return [dict(e) for e in self._history]

    def snapshot(self) -> Dict[str, Any]:
        with self._lock:
            self.update()
            return {"locked": self.locked, "unlocked": not self.locked and not self.busy, "busy": self.busy,
                    "coupled_tool_id": self.coupled, "coupled_tool": self.tool_of.get(self.coupled),
                    "fault_code": self.fault_code, "fault": FAULTS[self.fault_code],
                    "slots_present": dict(self.present), "flange_slot": self.rack.slot_at(),
                    "operations": self.operations}


class ToolChangerRegisterMap:
    """Modbus view of a :class:`ToolChangerModel` (see the module docstring); served by the compressor's adapters."""

    COILS, DISCRETE_INPUTS, HOLDING_REGISTERS, INPUT_REGISTERS = COILS, DISCRETE_INPUTS, HOLDING_REGISTERS, \
        INPUT_REGISTERS

    def __init__(self, model: ToolChangerModel) -> None:
        self.model = model

    @staticmethod
    def _check(names: Sequence[str], table: str, address: int, count: int) -> None:
        if count < 1 or address < 0 or address + count > len(names):
            raise RegisterAccessError(EXC_ILLEGAL_ADDRESS, "%s %d..%d not in map%s" % (
                table, address, address + count - 1,
                ", allowed 0..%d" % (len(names) - 1) if names else ": this device has no %s" % table))

    def _state(self) -> Dict[str, Any]:
        s = self.model.snapshot()
        s["status_bits"] = (int(s["locked"]) | int(s["unlocked"]) << 1 | int(s["busy"]) << 2
                            | int(bool(s["coupled_tool_id"])) << 3 | int(bool(s["fault_code"])) << 4
                            | int(bool(s["flange_slot"])) << 5)
        s["present_bits"] = sum(1 << (n - 1) for n, here in s["slots_present"].items() if here)
        return s

    def read_bits(self, table: str, address: int, count: int) -> List[bool]:
        """``table`` is ``coils`` or ``discrete_inputs``."""
        s = self._state()
        if table == "coils":
            self._check(COILS, table, address, count)
            values = [self.model.commanded, False]
        elif table == "discrete_inputs":
            self._check(DISCRETE_INPUTS, table, address, count)
            values = [bool(s["status_bits"] >> i & 1) for i in range(6)] + [
                bool(s["present_bits"] >> (n - 1) & 1) for n in range(1, MAX_SLOTS + 1)]
        else:
            raise RegisterAccessError(EXC_ILLEGAL_ADDRESS, "unknown bit table %r" % table)
        return values[address:address + count]

    def read_registers(self, table: str, address: int, count: int) -> List[int]:
        """``table`` is ``holding`` (none: refused) or ``input``."""
        if table != "input":
            self._check(HOLDING_REGISTERS, table, address, count)
        self._check(INPUT_REGISTERS, table, address, count)
        s = self._state()
        values = [s["coupled_tool_id"], s["fault_code"], s["status_bits"], s["present_bits"], s["flange_slot"],
                  min(0xFFFF, s["operations"])]
        return values[address:address + count]

    def write_bits(self, address: int, values: Sequence[bool]) -> None:
        self._check(COILS, "coils", address, len(values))
        for i, v in enumerate(values):
            if address + i == 0:
                self.model.command_lock(bool(v))
            elif v:
                self.model.reset_fault()

    def write_registers(self, address: int, values: Sequence[int]) -> None:
        self._check(HOLDING_REGISTERS, "holding", address, len(values))

    # -- what the server calls periodically / for its state() ---------------------------------------------------
    def check_watchdog(self) -> bool:
        """Called by the server every few ms: finishes a lock / unlock on time even when nobody reads. The changer
        has no communication watchdog (it holds its tool): never trips."""
        self.model.update()
        return False

    def watchdog_state(self) -> Dict[str, Any]:
        return {"timeout_ms": 0, "tripped": False, "trips": 0, "last_trip": None}


def tool_changer_server(model: ToolChangerModel, host: str, port: int, device_id: int) -> Any:
    """The Modbus TCP server of ``model`` for the installed pymodbus line (not started)."""
    from .modbus_server import CompressorServer
    return CompressorServer(model, host, port, device_id, register_map=ToolChangerRegisterMap(model),
                            name="tool changer")
