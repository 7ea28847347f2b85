"""Base drive stand-ins: the CiA 402 wheel drives (canopen ``LocalNode``) on a python-can bus, and the lift's
position-mode drive (:class:`Cia402PositionDrive`) on the same bus.

Lifecycle: ``DriveSet(drives_cfg, eds_path, clock)`` -> :meth:`DriveSet.start` (opens the bus, boots every node:
boot-up message, PRE-OPERATIONAL, heartbeat from 0x1017) -> the world calls :meth:`DriveSet.wheel_angles` each
step -> :meth:`DriveSet.stop`. The bus comes from configuration (``robot.base.drives.can``): ``virtual`` (one
process), ``udp_multicast`` (across processes), ``socketcan`` (hardware / vcan); a test can inject its own
``can.BusABC``.

Each :class:`Cia402Drive` implements
- NMT slave with heartbeat producer (canopen ``NmtSlave``); a reset command reboots it (boot-up, PRE-OP);
- the CiA 402 state machine driven by the controlword 0x6040 (shutdown, switch on, enable operation, disable
  voltage, quick stop, fault reset on the rising edge of bit 7) with the statusword 0x6041;
- PROFILED VELOCITY mode (0x6060 = 3): target velocity 0x60FF, ramp 0x6083/0x6084 (velocity units per s),
  feedback 0x6064 position (counts) and 0x606C velocity; units from configuration
  (``velocity_units_per_rad_s``, ``counts_per_rad``; wheel shaft);
- PDOs wired explicitly (a ``LocalNode`` does not apply RPDOs by itself): received RPDOs are decoded with the
  current mapping (0x1600..) and written through the object dictionary, only in OPERATIONAL; TPDOs
  (0x1800../0x1A00..) are sent cyclically with their event timer and at once when the statusword changes.
- heartbeat consumer (0x1016 sub 1 = producer node id << 16 | time ms, written by the master when it enables
  the drive): monitoring starts with the producer's first heartbeat; when the producer falls silent for longer
  than that time (its process died, the cable is cut) the drive stops by itself: OPERATION ENABLED -> QUICK STOP
  ACTIVE (braking at 0x6084), EMCY 0x8130 (heartbeat error), NMT PRE-OPERATIONAL (RPDOs ignored) until a master
  enables it again; :meth:`Cia402Drive.check_consumer` is called every TPDO cycle of the drive set;
- faults: :meth:`inject_fault` (FAULT state, 0x603F error code, EMCY), :meth:`inject_heartbeat_loss` (the node
  drops off the bus: no heartbeat, TPDOs or SDO answers, motor stops) and :meth:`restore` (it reboots).
Malformed frames addressed to a drive (wrong length NMT/SDO/RPDO) are ignored and logged; ``refused`` counts them.

Motion physics is integrated exactly (piecewise constant acceleration) on sim time ``clock()``; every change of
state, mode, target or ramp starts a recorded motion segment, so :meth:`Cia402Drive.angles_at` gives the exact
wheel angle at any recent sim time (the world integrates the base pose through it).

Timing (see docs/protocol_notes.md, "Time scale and the bus"): the bus protocol is the device's real-time
behaviour and runs on the wall clock whatever the time scale: heartbeat producer time 0x1017 (sent by a helper
process, :mod:`.heartbeat`, on ``udp_multicast``/``socketcan``) and TPDO event timer 0x1800 sub 5. The cyclic
TPDOs of all drives are sampled at one sim instant per cycle and sent back to back (as SYNC-synchronised drives
would), so a master's odometry gets four wheel positions of the same instant.
"""
from __future__ import annotations

import logging
import math
import struct
import threading
import time
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Optional, Sequence, Tuple

import can
import canopen
from canopen.sdo import SdoAbortedError

from ...common.can_bus import SHARED_INTERFACES, CanBusError, open_bus
from ..errors import DeviceStandInError
from .heartbeat import HeartbeatProcess

log = logging.getLogger(__name__)

# CiA 402 states and their statusword bits (voltage enabled bit 4, remote bit 9 added separately)
NOT_READY = "NOT READY TO SWITCH ON"
SWITCH_ON_DISABLED = "SWITCH ON DISABLED"
READY = "READY TO SWITCH ON"
SWITCHED_ON = "SWITCHED ON"
ENABLED = "OPERATION ENABLED"
QUICK_STOP = "QUICK STOP ACTIVE"
FAULT_REACTION = "FAULT REACTION ACTIVE"
FAULT = "FAULT"
_SW = {NOT_READY: 0x00, SWITCH_ON_DISABLED: 0x40, READY: 0x21 | 0x10, SWITCHED_ON: 0x23 | 0x10,
       ENABLED: 0x27 | 0x10, QUICK_STOP: 0x07 | 0x10, FAULT_REACTION: 0x0F, FAULT: 0x08}
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
MODE_PROFILED_POSITION = 1
MODE_PROFILED_VELOCITY = 3
SUPPORTED_MODES = (MODE_PROFILED_VELOCITY,)
SW_SETPOINT_ACK = 0x1000
CW_NEW_SETPOINT = 0x10
CW_HALT = 0x100
NMT_OPERATIONAL = 5
NMT_PRE_OPERATIONAL = 127

FAULT_OVERCURRENT = 0x2310
EMCY_HEARTBEAT = 0x8130          # life guard / heartbeat error (CiA 301)


def advance(v: float, angle: float, vt: float, a_up: float, a_down: float, dt: float) -> Tuple[float, float]:
    """Velocity and angle after ``dt`` of the profiled-velocity ramp from ``v`` toward ``vt``: ``a_up`` while the
    speed grows in the target's direction, ``a_down`` while it falls (through zero when the sign changes, then
    ``a_up``). Exact for any ``dt``, so splitting an interval gives the same result as one step."""
    while dt > 0.0:
        if v == vt:
            return v, angle + v * dt
        if v != 0.0 and (v > 0.0) != (vt > 0.0) and vt != 0.0:
            goal = 0.0                                 # decelerate to zero first, then speed up the other way
        else:
            goal = vt
        a = a_up if abs(goal) > abs(v) else a_down
        if a <= 0.0:
            return vt, angle + vt * dt
        tr = abs(goal - v) / a
        s = math.copysign(a, goal - v)
        if dt < tr:
            return v + s * dt, angle + v * dt + 0.5 * s * dt * dt
        angle += 0.5 * (v + goal) * tr
        v = goal
        dt -= tr
    return v, angle


class _MotionParameter:
    """A drive attribute the wheel motion depends on (state, mode, target, ramps): assigning it, from the drive's
    own handlers or from a test, first advances the motion to ``clock()`` and then starts a new motion segment,
    so :meth:`Cia402Drive.angles_at` stays exact."""

    def __set_name__(self, owner: Any, name: str) -> None:
        self.key = "_p_" + name

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        return self if obj is None else obj.__dict__[self.key]

    def __set__(self, obj: Any, value: Any) -> None:
        if "_events" not in obj.__dict__:            # during __init__
            obj.__dict__[self.key] = value
            return
        with obj._lock:
            obj.update()
            obj.__dict__[self.key] = value
            obj._mark()


class Cia402Drive:
    """One simulated wheel drive (see the module docstring)."""

    state = _MotionParameter()
    mode = _MotionParameter()
    target_units = _MotionParameter()
    accel_units = _MotionParameter()
    decel_units = _MotionParameter()
    #: the modes of operation (0x6060) this drive accepts
    supported_modes: Tuple[int, ...] = SUPPORTED_MODES

    def __init__(self, node_id: int, name: str, eds_path: str, cfg: Dict[str, Any], clock: Callable[[], float]) -> None:
        self.node_id = int(node_id)
        self.name = name
        self.node = canopen.LocalNode(self.node_id, canopen.import_od(eds_path, self.node_id))
        self.vel_scale = float(cfg["velocity_units_per_rad_s"])
        self.pos_scale = float(cfg["counts_per_rad"])
        self.max_speed = float(cfg.get("max_wheel_speed", 1e9))
        self.heartbeat_ms = int(cfg["heartbeat_ms"])
        self.tpdo_period_ms = int(cfg["tpdo_period_ms"])
        accel_units = int(round(float(cfg["profile_acceleration"]) * self.vel_scale))
        self._clock = clock
        self._lock = threading.RLock()
        self.state = NOT_READY
        self.mode = 0
        self.target_units = 0
        self.accel_units = accel_units
        self.decel_units = accel_units
        self.error_code = 0
        self.velocity = 0.0           # rad/s at the wheel shaft, drive sign
        self.angle = 0.0              # rad, drive sign
        self._t = clock()
        self._events: Deque[Tuple[float, float, float, float, float, float]] = deque(maxlen=4096)
        self._last_cw = 0
        self.online = False
        self.refused = 0
        self.network: Optional[canopen.Network] = None
        self._rpdo_handlers: Dict[int, Any] = {}
        self._rewire_rpdos_later = False
        self._tpdo_last: Dict[int, float] = {}
        self._tpdo_due: Dict[int, float] = {}
        self._last_sw_sent: Optional[int] = None
        self._sample: Optional[Tuple[int, Tuple[float, float]]] = None
        self.consumer: Optional[Tuple[int, float]] = None      # (producer node id, timeout s), from 0x1016 sub 1
        self._consumer_seen: Optional[float] = None            # time.monotonic() of the producer's last heartbeat
        self._consumer_cb: Any = None
        self.consumer_trips = 0
        self.last_consumer_trip: Optional[float] = None        # time.time() of the last trip
        od = self.node.data_store
        od.setdefault(0x1017, {})[0] = struct.pack("<H", self.heartbeat_ms)
        for n in (0, 1):
            od.setdefault(0x1800 + n, {})[5] = struct.pack("<H", self.tpdo_period_ms)
        od.setdefault(0x6083, {})[0] = struct.pack("<I", accel_units)
        od.setdefault(0x6084, {})[0] = struct.pack("<I", accel_units)
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        self._mark()

    # -- physics -------------------------------------------------------------------------------------------
    def _target_rad_s(self) -> float:
        if self.state != ENABLED or self.mode != MODE_PROFILED_VELOCITY:
            return 0.0
        return max(-self.max_speed, min(self.max_speed, self.target_units / self.vel_scale))

    def update(self) -> None:
        """Advance velocity and angle to ``clock()`` (exact for the piecewise constant acceleration)."""
        with self._lock:
            now = self._clock()
            dt = now - self._t
            if dt <= 0.0:
                return
            self._t = now
            self.velocity, self.angle = advance(self.velocity, self.angle, self._target_rad_s(),
                                                self.accel_units / self.vel_scale, self.decel_units / self.vel_scale,
                                                dt)

    def _mark(self) -> None:
        """Record a motion segment start (call with the lock held, right after ``update()``): everything the
        trajectory depends on from now on, for :meth:`angles_at`."""
        self._events.append((self._t, self.angle, self.velocity, self._target_rad_s(),
                             self.accel_units / self.vel_scale, self.decel_units / self.vel_scale))

    def still_since(self, t: float) -> bool:
        """True when the wheel has stood still (velocity and target 0) from sim time ``t`` on."""
        with self._lock:
            e = self._events[-1]
            return e[0] <= t and e[2] == 0.0 and e[3] == 0.0

    def angles_at(self, times: List[float]) -> List[float]:
        """Wheel angle (drive sign) at each of the increasing sim ``times`` (the past since the oldest recorded
        segment, up to now), from the recorded motion segments: exact, whatever the times (the world integrates
        the base pose through them)."""
        return [a for _, a in self.states_at(times)]

    def states_at(self, times: List[float]) -> List[Tuple[float, float]]:
        """``(velocity, angle)`` at each of the increasing sim ``times`` (see :meth:`angles_at`)."""
        with self._lock:
            self.update()
            now_state = (self._t, self.velocity, self.angle)
            events = []                                  # the segments from the one in force at times[0] on
            for e in reversed(self._events):
                events.append(e)
                if times and e[0] <= times[0]:
                    break
            events.reverse()
        out = []
        k = 0
        for t in times:
            while k + 1 < len(events) and events[k + 1][0] <= t:
                k += 1
            if t >= now_state[0]:
                out.append(now_state[1:])
                continue
            t0, angle, v, vt, a_up, a_down = events[k]
            out.append(advance(v, angle, vt, a_up, a_down, max(0.0, t - t0)))
        return out

    # -- object dictionary hooks ---------------------------------------------------------------------------
    def statusword(self) -> int:
        with self._lock:
            sw = _SW[self.state] | SW_REMOTE
            if self.state == ENABLED and abs(self.velocity - self._target_rad_s()) < 1e-6:
                sw |= SW_TARGET_REACHED
            return sw

    def _on_read(self, index: int, subindex: int, od: Any) -> Optional[int]:
        if index == 0x6041:
            return self.statusword()
        if index == 0x6061:
            return self.mode
        if index in (0x6064, 0x606C):
            sample = self._sample
            if sample is not None and sample[0] == threading.get_ident():
                velocity, angle = sample[1]              # cyclic TPDO: the value at the cycle's sample instant
            else:
                with self._lock:
                    self.update()
                    velocity, angle = self.velocity, self.angle
            if index == 0x6064:
                return _i32(angle * self.pos_scale)
            return _i32(velocity * self.vel_scale)
        if index == 0x603F:
            return self.error_code
        if index == 0x1001:
            return 0x01 if self.state in (FAULT, FAULT_REACTION) else 0
        return None

    def _on_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        if index == 0x6040:
            self._controlword(struct.unpack_from("<H", data)[0])
        elif index == 0x6060:
            mode = struct.unpack_from("<b", data)[0]
            if mode not in self.supported_modes:
                log.warning("drive %d: mode of operation %d refused, supported: %s", self.node_id, mode,
                            self.supported_modes)
                raise SdoAbortedError(0x06090030)   # value range of parameter exceeded
            with self._lock:
                self.update()
                self.mode = mode
            self._send_status_tpdo()
        elif index == 0x60FF:
            with self._lock:
                self.update()
                self.target_units = struct.unpack_from("<i", data)[0]
        elif index in (0x6083, 0x6084):
            value = struct.unpack_from("<I", data)[0]
            if value == 0:
                raise SdoAbortedError(0x06090032)   # value too low
            with self._lock:
                self.update()
                if index == 0x6083:
                    self.accel_units = value
                else:
                    self.decel_units = value
        elif 0x1400 <= index <= 0x1403 or 0x1600 <= index <= 0x1603:
            self._rewire_rpdos_later = True
        elif index == 0x1016 and subindex == 1:
            self._set_consumer(struct.unpack_from("<I", data)[0])

    # -- heartbeat consumer ------------------------------------------------------------------------------------
    def _set_consumer(self, value: int) -> None:
        producer, ms = (value >> 16) & 0x7F, value & 0xFFFF
        net = self.network
        if self._consumer_cb is not None and net is not None and self.consumer is not None:
            try:
                net.unsubscribe(0x700 + self.consumer[0], self._consumer_cb)
            except (KeyError, ValueError):
                pass
        self._consumer_cb = None
        self._consumer_seen = None
        self.consumer = None
        if ms == 0 or producer == 0:
            return                                           # consumer off
        self.consumer = (producer, ms / 1000.0)

        def on_heartbeat(can_id: int, data: bytes, timestamp: float) -> None:
            if self.online and len(data) == 1:
                self._consumer_seen = time.monotonic()
        self._consumer_cb = on_heartbeat
        if net is not None:
            net.subscribe(0x700 + producer, on_heartbeat)
        log.info("drive %d (%s): consumes the heartbeat of node %d, timeout %d ms", self.node_id, self.name,
                 producer, ms)

    def check_consumer(self, now: float) -> bool:
        """Stop the drive when the monitored producer fell silent (see the module docstring); True on a trip."""
        consumer, seen = self.consumer, self._consumer_seen
        if consumer is None or seen is None or not self.online or now - seen <= consumer[1]:
            return False
        self._consumer_seen = None                           # monitoring restarts with the next heartbeat
        with self._lock:
            self.update()
            prev = self.state
            if self.state == ENABLED:
                self.state = QUICK_STOP
            self.target_units = 0
            self._mark()
        self.consumer_trips += 1
        self.last_consumer_trip = time.time()
        log.warning("drive %d (%s): heartbeat of node %d silent for %.0f ms (timeout %.0f ms): %s -> %s, "
                    "PRE-OPERATIONAL", self.node_id, self.name, consumer[0], (now - seen) * 1000.0,
                    consumer[1] * 1000.0, prev, self.state)
        self._send_status_tpdo()
        try:
            self.node.emcy.send(EMCY_HEARTBEAT, 0x11)         # error register: generic + communication
            self.node.nmt.send_command(0x80)                 # PRE-OPERATIONAL
        except Exception as exc:  # the bus may be gone while shutting down
            log.warning("drive %d: heartbeat-loss reaction not sent: %s", self.node_id, exc)
        return True

    # -- CiA 402 state machine -----------------------------------------------------------------------------
    def _controlword(self, cw: int) -> None:
        with self._lock:
            self.update()
            prev = self.state
            rising_reset = bool(cw & 0x80) and not (self._last_cw & 0x80)
            self._last_cw = cw
            s = self.state
            if s == FAULT:
                if rising_reset:
                    self.state = SWITCH_ON_DISABLED
                    self.error_code = 0
            elif cw & 0x80:
                pass                                             # fault reset bit outside FAULT: no command
            elif cw & 0x02 == 0:                                 # disable voltage
                if s in (READY, SWITCHED_ON, ENABLED, QUICK_STOP):
                    self.state = SWITCH_ON_DISABLED
            elif cw & 0x06 == 0x02:                              # quick stop
                if s == ENABLED:
                    self.state = QUICK_STOP
                elif s in (READY, SWITCHED_ON):
                    self.state = SWITCH_ON_DISABLED
            elif cw & 0x0F == 0x06 or cw & 0x0F == 0x0E:         # shutdown
                if s in (SWITCH_ON_DISABLED, SWITCHED_ON, ENABLED):
                    self.state = READY
            elif cw & 0x0F == 0x07:                              # switch on / disable operation
                if s in (READY, ENABLED):
                    self.state = SWITCHED_ON
            elif cw & 0x0F == 0x0F:                              # enable operation (switch on + enable)
                if s == SWITCHED_ON or s == QUICK_STOP:
                    self.state = ENABLED
                elif s == READY:
                    self.state = ENABLED                         # transitions 3 + 4 at once
            if prev == ENABLED and self.state != ENABLED:
                self.target_units = 0                            # leaving OPERATION ENABLED drops the target
            changed = self.state != prev
        if changed:
            log.info("drive %d (%s): %s -> %s", self.node_id, self.name, prev, self.state)
            self._send_status_tpdo()

    def inject_fault(self, error_code: int = FAULT_OVERCURRENT) -> None:
        """Drive fault: FAULT state, 0x603F = ``error_code``, EMCY sent, motor stops at once."""
        with self._lock:
            self.update()
            self.state = FAULT
            self.error_code = int(error_code)
            self.velocity = 0.0
            self.target_units = 0
            self._mark()
        log.warning("drive %d (%s): fault 0x%04X injected", self.node_id, self.name, error_code)
        if self.online and self.network is not None:
            try:
                self.node.emcy.send(self.error_code, 0x01)
            except Exception as exc:  # the bus may be gone while shutting down
                log.warning("drive %d: EMCY not sent: %s", self.node_id, exc)
        self._send_status_tpdo()

    # -- network -------------------------------------------------------------------------------------------
    def attach(self, network: canopen.Network) -> None:
        """Join ``network`` and boot (boot-up message, PRE-OPERATIONAL, heartbeat)."""
        self.network = network
        network.add_node(self.node)
        self._guard_handlers()
        self._rewire_rpdos()
        self._boot()

    def _guard_handlers(self) -> None:
        """Put length checks in front of canopen's NMT and SDO handlers (malformed frames never reach them)."""
        net = self.network
        net.unsubscribe(0, self.node.nmt.on_command)
        net.unsubscribe(0x600 + self.node_id, self.node.sdo.on_request)
        net.subscribe(0, self._on_nmt)
        net.subscribe(0x600 + self.node_id, self._on_sdo)

    def _unguard_handlers(self) -> None:
        for cob, cb in ((0, self._on_nmt), (0x600 + self.node_id, self._on_sdo)):
            try:
                self.network.unsubscribe(cob, cb)
            except (KeyError, ValueError):
                pass

    def _boot(self) -> None:
        with self._lock:
            self.update()
            self.state = SWITCH_ON_DISABLED        # NOT READY TO SWITCH ON passes on its own after the self test
            self.mode = 0
            self.target_units = 0
            self.velocity = 0.0
            self._last_cw = 0
            self._mark()
        self._set_consumer(0)                      # a reset restores the default: no consumer
        self.node.nmt.send_command(0x81)           # INITIALISING: boot-up message
        self.node.nmt.send_command(0x80)           # PRE-OPERATIONAL: starts the heartbeat from 0x1017
        self.online = True
        self._last_sw_sent = None

    def detach(self) -> None:
        if self.network is None:
            return
        self.node.nmt.stop_heartbeat()
        self._unwire_rpdos()
        self._unguard_handlers()
        self.network.nodes.pop(self.node_id, None)
        self.online = False
        self.network = None

    def inject_heartbeat_loss(self) -> None:
        """The node drops off the bus: no heartbeat, TPDO, SDO or NMT handling; the motor stops."""
        with self._lock:
            self.update()
            self.online = False
            self.state = NOT_READY
            self.target_units = 0
            self.velocity = 0.0
            self._mark()
        self.node.nmt.stop_heartbeat()
        self._unwire_rpdos()
        self._unguard_handlers()
        log.warning("drive %d (%s): heartbeat loss injected (node off the bus)", self.node_id, self.name)

    def restore(self) -> None:
        """Undo a heartbeat loss: the node reboots and must be enabled again by the master."""
        net = self.network
        if net is None:
            raise DeviceStandInError("drive %d was never attached to a network" % self.node_id)
        self._unguard_handlers()
        self.network.subscribe(0, self._on_nmt)
        self.network.subscribe(0x600 + self.node_id, self._on_sdo)
        self._rewire_rpdos()
        self._boot()
        log.warning("drive %d (%s): back on the bus (rebooted)", self.node_id, self.name)

    def _on_nmt(self, can_id: int, data: bytes, timestamp: float) -> None:
        if not self.online:
            return
        if len(data) != 2:
            self._refuse("NMT frame with %d data bytes, allowed 2" % len(data))
            return
        cmd, nid = data[0], data[1]
        if nid not in (0, self.node_id):
            return
        if cmd not in (0x01, 0x02, 0x80, 0x81, 0x82):
            self._refuse("unknown NMT command 0x%02X, allowed 0x01 0x02 0x80 0x81 0x82" % cmd)
            return
        self.node.nmt.on_command(can_id, data, timestamp)
        if cmd == 0x81:
            self._boot()                                   # reset node: application and communication
        elif cmd == 0x82:
            self.node.nmt.send_command(0x81)               # reset communication: boot-up, then PRE-OPERATIONAL
            self.node.nmt.send_command(0x80)

    def _on_sdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        if not self.online:
            return
        if len(data) != 8:
            self._refuse("SDO request with %d data bytes, allowed 8" % len(data))
            return
        self.node.sdo.on_request(can_id, data, timestamp)
        if self._rewire_rpdos_later:                   # an RPDO COB-ID or mapping was written: apply it now
            self._rewire_rpdos()

    def _refuse(self, why: str) -> None:
        self.refused += 1
        log.warning("drive %d (%s): ignored malformed frame: %s", self.node_id, self.name, why)

    # -- PDO wiring ----------------------------------------------------------------------------------------
    def _raw(self, index: int, sub: int) -> int:
        obj = self.node.object_dictionary[index][sub]
        return obj.decode_raw(self.node.get_data(index, sub))

    def _mapping(self, map_index: int) -> List[Any]:
        out = []
        for sub in range(1, self._raw(map_index, 0) + 1):
            value = self._raw(map_index, sub)
            index, subindex, bits = value >> 16, (value >> 8) & 0xFF, value & 0xFF
            if index:
                out.append((index, subindex, bits))
        return out

    def _unwire_rpdos(self) -> None:
        if self.network is None:
            return
        for cob, cb in list(self._rpdo_handlers.items()):
            try:
                self.network.unsubscribe(cob, cb)
            except Exception:
                pass
        self._rpdo_handlers = {}

    def _rewire_rpdos(self) -> None:
        self._unwire_rpdos()
        self._rewire_rpdos_later = False
        for n in range(4):
            comm = 0x1400 + n
            if comm not in self.node.object_dictionary:
                continue
            cob = self._raw(comm, 1)
            if cob & 0x80000000:
                continue
            cob &= 0x7FF

            def handler(can_id: int, data: bytes, timestamp: float, _map: int = 0x1600 + n) -> None:
                self._on_rpdo(_map, data)
            self._rpdo_handlers[cob] = handler
            self.network.subscribe(cob, handler)

    def _on_rpdo(self, map_index: int, data: bytes) -> None:
        if not self.online:
            return
        if self.node.nmt.state != "OPERATIONAL":
            return                                            # PDOs are only processed in OPERATIONAL
        mapping = self._mapping(map_index)
        total = sum(bits for _, _, bits in mapping) // 8
        if len(data) != total:
            self._refuse("RPDO (map 0x%04X) with %d data bytes, mapping needs %d" % (map_index, len(data), total))
            return
        offset = 0
        for index, subindex, bits in mapping:
            n = bits // 8
            try:
                self.node.set_data(index, subindex, bytes(data[offset:offset + n]))
            except SdoAbortedError as exc:
                self._refuse("RPDO value for 0x%04X refused (abort 0x%08X)" % (index, exc.code))
            offset += n
        if self._rewire_rpdos_later:
            self._rewire_rpdos()

    def _tpdo_data(self, map_index: int) -> bytes:
        return b"".join(self.node.get_data(index, sub) for index, sub, _ in self._mapping(map_index))

    def _send_status_tpdo(self) -> None:
        """Event-driven transmission of every TPDO that maps the statusword (on a state change)."""
        if not self.online or self.network is None or self.node.nmt.state != "OPERATIONAL":
            return
        for n in range(4):
            if 0x1A00 + n in self.node.object_dictionary and any(
                    i == 0x6041 for i, _, _ in self._mapping(0x1A00 + n)):
                self._send_tpdo(n, time.monotonic())

    def _send_tpdo(self, n: int, now: float) -> None:
        frame = self._tpdo_frame(n, now)
        if frame is not None:
            self._transmit([frame])

    def _tpdo_frame(self, n: int, now: float) -> Optional[Tuple[int, bytes, int]]:
        cob = self._raw(0x1800 + n, 1)
        if cob & 0x80000000:
            return None
        self._tpdo_last[n] = now
        return cob & 0x7FF, self._tpdo_data(0x1A00 + n), n

    def _transmit(self, frames: List[Tuple[int, bytes, int]]) -> None:
        for cob, data, n in frames:
            try:
                self.network.send_message(cob, data)
            except Exception as exc:
                log.warning("drive %d: TPDO%d not sent: %s", self.node_id, n + 1, exc)

    def send_cyclic_tpdos(self, now: float, sample_time: Optional[float] = None) -> None:
        """Send every enabled TPDO whose event timer (wall clock ``now``) has expired."""
        self._transmit(self.due_tpdo_frames(now, sample_time))

    def due_tpdo_frames(self, now: float, sample_time: Optional[float] = None) -> List[Tuple[int, bytes, int]]:
        """The ``(cob_id, data, tpdo index)`` of every enabled TPDO whose event timer (wall clock ``now``) has
        expired, with position and velocity at sim time ``sample_time`` (default: now). The DriveSet samples all
        four drives at one instant per cycle and sends their frames back to back, as drives synchronised by a
        SYNC object would: a master's odometry then gets four wheel positions of the same instant."""
        if not self.online or self.network is None or self.node.nmt.state != "OPERATIONAL":
            return []
        if sample_time is not None:
            self._sample = (threading.get_ident(), self.states_at([sample_time])[0])
        try:
            return self._due_tpdos(now)
        finally:
            self._sample = None

    def _due_tpdos(self, now: float) -> List[Tuple[int, bytes, int]]:
        frames = []
        for n in range(4):
            comm = 0x1800 + n
            if comm not in self.node.object_dictionary:
                continue
            period = self._raw(comm, 5) / 1000.0
            if period <= 0.0:
                continue
            due = self._tpdo_due.get(n, 0.0)
            if now >= due - 0.002:                     # tolerate a loop that wakes up a little early
                frame = self._tpdo_frame(n, now)
                if frame is not None:
                    frames.append(frame)
                self._tpdo_due[n] = now + period if now - due > period else due + period
        return frames

    def snapshot(self) -> Dict[str, Any]:
        with self._lock:
            self.update()
            return {"node_id": self.node_id, "name": self.name, "state": self.state, "mode": self.mode,
                    "nmt": self.node.nmt.state, "online": self.online, "velocity": self.velocity,
                    "angle": self.angle, "error_code": self.error_code, "refused": self.refused}


class Cia402PositionDrive(Cia402Drive):
    """A linear axis drive (the lift) in PROFILED POSITION mode (0x6060 = 1): target position 0x607A (counts),
    profile velocity 0x6081, acceleration 0x6083 and deceleration 0x6084 (velocity units [per s]); a new set-point
    is taken on the rising edge of controlword bit 4 (acknowledged in statusword bit 12 while bit 4 stays set),
    controlword bit 8 (halt) brakes the axis at the deceleration and holds it where it stops,
    statusword bit 10 (target reached) is set once the axis stands at the set-point. Positions are ``angle`` (m of
    axis travel from its zero), counts = ``counts_per_rad`` x m, velocity units = ``velocity_units_per_rad_s`` x
    m/s (the wheel drive's keys, read per metre). Outside OPERATION ENABLED + position mode the axis brakes at
    the deceleration and keeps its position (a lift holds its load: brake). The travel is limited to
    ``[0, travel]`` (software limits); a set-point outside is clamped.

    ``cfg`` adds ``travel`` (m) and ``start`` (m) to the wheel drive's keys; ``profile_velocity`` (m/s) is the
    default of 0x6081."""

    supported_modes = (MODE_PROFILED_POSITION,)
    SUBSTEP = 0.0005          # s of sim time per integration step of the position profile

    def __init__(self, node_id: int, name: str, eds_path: str, cfg: Dict[str, Any], clock: Callable[[], float]) -> None:
        super().__init__(node_id, name, eds_path, cfg, clock)
        self.travel = float(cfg["travel"])
        self.profile_velocity_units = int(round(float(cfg["profile_velocity"]) * self.vel_scale))
        self.target_counts = 0
        self.setpoint = min(max(float(cfg.get("start", 0.0)), 0.0), self.travel)
        self.angle = self.setpoint
        self._ack = False
        od = self.node.data_store
        od.setdefault(0x6081, {})[0] = struct.pack("<I", self.profile_velocity_units)
        self._mark()

    def update(self) -> None:
        with self._lock:
            now = self._clock()
            dt = now - self._t
            if dt <= 0.0:
                return
            self._t = now
            a = self.accel_units / self.vel_scale
            d = self.decel_units / self.vel_scale
            vmax = max(1e-6, self.profile_velocity_units / self.vel_scale)
            active = self.state == ENABLED and self.mode == MODE_PROFILED_POSITION and self.online
            x, v = self.angle, self.velocity
            while dt > 1e-12:
                h = min(self.SUBSTEP, dt)
                dt -= h
                if not active:                      # brake to a stand and hold
                    dv = min(abs(v), d * h)
                    v_new = v - math.copysign(dv, v) if v else 0.0
                    x += 0.5 * (v + v_new) * h
                    v = v_new
                    continue
                err = self.setpoint - x
                if abs(err) < 1e-7 and abs(v) <= d * h:
                    x, v = self.setpoint, 0.0
                    continue
                s = 1.0 if err > 0 else -1.0
                if v * s < 0.0 or v * v / (2.0 * d) >= abs(err):
                    v_new = v - math.copysign(min(abs(v), d * h), v)       # brake (toward the set-point)
                    if v_new == 0.0 and abs(err) > 1e-7 and v * s >= 0.0:
                        v_new = s * min(a * h, math.sqrt(2.0 * d * abs(err)))
                else:
                    v_new = s * min(vmax, abs(v) + a * h)
                step = 0.5 * (v + v_new) * h
                if (err - step) * err < 0.0 and abs(v_new) <= 2.0 * d * h + 1e-9:
                    x, v = self.setpoint, 0.0                                # lands on it
                    continue
                x += step
                v = v_new
            self.angle = min(max(x, -0.01), self.travel + 0.01)
            self.velocity = v

    def states_at(self, times: List[float]) -> List[Tuple[float, float]]:
        """``(velocity, position)`` now for every time asked (the position profile keeps no segment history; the
        TPDO sampler asks for the current instant)."""
        with self._lock:
            self.update()
            return [(self.velocity, self.angle) for _ in times]

    def still_since(self, t: float) -> bool:
        with self._lock:
            return self.velocity == 0.0 and self.in_position()

    def in_position(self) -> bool:
        with self._lock:
            return self.mode == MODE_PROFILED_POSITION and self.velocity == 0.0 and abs(self.angle - self.setpoint) < 1e-6

    def statusword(self) -> int:
        with self._lock:
            self.update()
            sw = _SW[self.state] | SW_REMOTE
            if self.state == ENABLED and self.in_position():
                sw |= SW_TARGET_REACHED
            if self._ack:
                sw |= SW_SETPOINT_ACK
            return sw

    def _on_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        if index == 0x607A:
            with self._lock:
                self.target_counts = struct.unpack_from("<i", data)[0]
            return
        if index == 0x6081:
            value = struct.unpack_from("<I", data)[0]
            if value == 0:
                raise SdoAbortedError(0x06090032)   # value too low
            with self._lock:
                self.update()
                self.profile_velocity_units = value
            return
        if index == 0x60FF:
            return
        prev_cw = self._last_cw
        super()._on_write(index, subindex, od, data)
        if index == 0x6040:
            cw = struct.unpack_from("<H", data)[0]
            with self._lock:
                if cw & CW_HALT and self.state == ENABLED and self.mode == MODE_PROFILED_POSITION:
                    self.update()                    # halt: brake at the deceleration, hold where it stops
                    d = self.decel_units / self.vel_scale
                    stop_at = self.angle + math.copysign(self.velocity * self.velocity / (2.0 * d), self.velocity)
                    self.setpoint = min(max(stop_at, 0.0), self.travel)
                elif cw & CW_NEW_SETPOINT and not prev_cw & CW_NEW_SETPOINT and self.state == ENABLED \
                        and self.mode == MODE_PROFILED_POSITION:
                    self.update()
                    self.setpoint = min(max(self.target_counts / self.pos_scale, 0.0), self.travel)
                    self._ack = True
                    log.info("drive %d (%s): new set-point %.4f m", self.node_id, self.name, self.setpoint)
                elif not cw & CW_NEW_SETPOINT:
                    self._ack = False
            self._send_status_tpdo()

    def _controlword(self, cw: int) -> None:
        with self._lock:
            self.update()
            was = self.state
        super()._controlword(cw)
        with self._lock:
            if was != ENABLED and self.state == ENABLED:
                self.setpoint = self.angle           # enabling holds the axis where it stands

    def _boot(self) -> None:
        with self._lock:
            self.update()
            keep = self.angle
        super()._boot()
        with self._lock:
            self.angle = keep                        # an absolute encoder: a reboot keeps the position
            self.setpoint = keep
            self._ack = False


def lift_drive(robot: Dict[str, Any], eds_path: str, clock: Callable[[], float]) -> Cia402PositionDrive:
    """The lift's drive stand-in from the robot file's ``robot`` section (``robot.lift``): axis zero at the bottom of
    ``lift.range``, starting where ``arm.mount.xyz`` puts the arm."""
    lift = robot["lift"]
    drv = lift["drive"]
    bottom, top = lift["range"]
    cfg = {"velocity_units_per_rad_s": drv["velocity_units_per_m_s"], "counts_per_rad": drv["counts_per_m"],
           "heartbeat_ms": drv["heartbeat_ms"], "tpdo_period_ms": drv["tpdo_period_ms"],
           "profile_acceleration": lift["acceleration"], "profile_velocity": lift["max_velocity"],
           "travel": top - bottom, "start": float(robot["arm"]["mount"]["xyz"][2]) - bottom}
    return Cia402PositionDrive(drv["node_id"], "lift", eds_path, cfg, clock)


def _i32(value: float) -> int:
    v = int(round(value))
    return max(-(2 ** 31), min(2 ** 31 - 1, v))


class DriveSet:
    """The wheel drives of the base on one bus (``others``: further drives on it, e.g. the lift), plus the cyclic
    TPDO thread.

    :param drives_cfg: ``robot.base.drives`` section (with ``max_wheel_speed`` from ``robot.base.limits``).
    :param eds_path: object dictionary of the drives.
    :param clock: sim time (``SimClock.now``).
    :param bus: an open python-can bus to use instead of opening one from ``drives_cfg['can']``.
    :param heartbeat_process: send the heartbeats from a helper process (:mod:`.heartbeat`): ``None`` (default)
        = when the bus comes from configuration and other processes can open it (``udp_multicast``,
        ``socketcan``); ``False`` = canopen's in-process timer threads; ``True`` = required.

    Timing: the bus protocol runs on the wall clock, as on a real drive (heartbeat producer time 0x1017, TPDO
    event timer 0x1800 sub 5), the motion on sim time; the CAN frame rate does not change with the time scale.
    """

    def __init__(self, drives_cfg: Dict[str, Any], eds_path: str, clock: Callable[[], float],
                 bus: Optional[can.BusABC] = None, max_wheel_speed: float = 1e9,
                 heartbeat_process: Optional[bool] = None, others: Sequence[Cia402Drive] = ()) -> None:
        self.cfg = drives_cfg
        self.clock = clock
        self._bus = bus
        self._own_bus = bus is None
        cfg = dict(drives_cfg)
        cfg["max_wheel_speed"] = max_wheel_speed
        self.drives = [Cia402Drive(w["node_id"], w["name"], eds_path, cfg, clock) for w in drives_cfg["wheels"]]
        self.polarity = [int(w["polarity"]) for w in drives_cfg["wheels"]]
        self.others: List[Cia402Drive] = list(others)    # further drives on the bus (the lift), not wheels
        self.network: Optional[canopen.Network] = None
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self.period = max(0.001, min(d.tpdo_period_ms for d in self.drives) / 1000.0)
        iface = drives_cfg["can"]["interface"]
        if heartbeat_process is None:
            heartbeat_process = bus is None and iface in SHARED_INTERFACES
        if heartbeat_process and iface not in SHARED_INTERFACES:
            raise DeviceStandInError("robot.base.drives.can.interface = %r: heartbeats from a helper process need "
                                     "a bus other processes can open (%s)" % (iface, ", ".join(SHARED_INTERFACES)))
        self.use_heartbeat_process = bool(heartbeat_process)
        self.sync_sampling = True      # cyclic TPDOs of all drives sampled at one sim instant per cycle
        self.heartbeat_process: Optional[HeartbeatProcess] = None

    def start(self) -> None:
        if self.network is not None:
            raise DeviceStandInError("drive set already started")
        if self._bus is None:              # the base bridge opens its bus the same way
            try:
                self._bus = open_bus(self.cfg["can"])
            except CanBusError as exc:
                raise DeviceStandInError(str(exc))
        self.network = canopen.Network(self._bus)
        self.network.NOTIFIER_CYCLE = 0.1      # short receive timeout: quick, clean shutdown
        if self.use_heartbeat_process:
            try:
                self.heartbeat_process = HeartbeatProcess(self.cfg["can"])
                self.heartbeat_process.start()
            except DeviceStandInError:
                if self._own_bus:
                    self._bus.shutdown()
                    self._bus = None
                self.network = None
                raise
            self.network.send_periodic = self._send_periodic    # type: ignore[assignment]
        self.network.connect()                 # bus given: only starts the notifier
        for d in self.drives + self.others:
            d.attach(self.network)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="cia402-tpdo", daemon=True)
        self._thread.start()
        log.info("base drives (CiA 402, node ids %s) on CAN %s/%s", [d.node_id for d in self.drives],
                 self.cfg["can"]["interface"], self.cfg["can"]["channel"])

    def _send_periodic(self, can_id: int, data: bytes, period: float, remote: bool = False) -> Any:
        """``Network.send_periodic`` of the drives' network: heartbeats go to the helper process."""
        if self.heartbeat_process is not None and not remote and HeartbeatProcess.handles(can_id):
            return self.heartbeat_process.send_periodic(can_id, data, period)
        return canopen.network.PeriodicMessageTask(can_id, data, period, self._bus, remote)

    def _run(self) -> None:
        nxt = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            sample_time = self.clock() if self.sync_sampling else None   # one instant for every drive
            burst = []
            for d in self.drives + self.others:
                try:
                    d.check_consumer(now)
                    burst.append((d, d.due_tpdo_frames(now, sample_time)))
                except Exception as exc:           # keep the loop alive, say what went wrong
                    log.warning("drive %d: cyclic TPDO failed: %s", d.node_id, exc)
            for d, frames in burst:                # back to back: the burst is short on the wire
                d._transmit(frames)
            nxt += self.period
            delay = nxt - time.monotonic()
            if delay < -self.period:
                nxt = time.monotonic()
                delay = 0.0
            self._stop.wait(max(0.0, delay))

    def stop(self) -> None:
        if self.network is None:
            return
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        for d in self.drives + self.others:
            d.detach()
        if self.heartbeat_process is not None:
            self.heartbeat_process.close()
            self.heartbeat_process = None
        if self.network.notifier is not None:
            self.network.notifier.stop(2.0)
            self.network.notifier = None
        if self._own_bus and self._bus is not None:
            self._bus.shutdown()
        self._bus = None if self._own_bus else self._bus
        self.network = None

    def drive(self, node_id: int) -> Cia402Drive:
        for d in self.drives + self.others:
            if d.node_id == node_id:
                return d
        raise KeyError("no drive with node id %d, known: %s" % (node_id, [d.node_id for d in self.drives + self.others]))

    def wheel_angles(self) -> List[float]:
        """Wheel angles in the kinematics' wheel order (mecanum [fl, fr, rl, rr], differential [left, right]) in rad, positive = rolling forward (polarity applied)."""
        out = []
        for d, p in zip(self.drives, self.polarity):
            with d._lock:
                d.update()
                out.append(p * d.angle)
        return out

    def wheel_angle_samples(self, t0: float, t1: float, max_step: float) -> List[List[float]]:
        """Wheel angles [fl, fr, rl, rr] (polarity applied) at sim times evenly spaced in ``(t0, t1]``, at most
        ``max_step`` apart (at most 4000 samples), computed exactly from each drive's motion segments: the world
        integrates the base pose through them, so its accuracy does not depend on how often it steps (a higher
        time scale or a stalled loop means more sim time per step)."""
        if t1 <= t0:
            return []
        if all(d.still_since(t0) for d in self.drives):
            n = 1                                      # nothing moved: one sample is exact
        else:
            n = max(1, min(4000, int(math.ceil((t1 - t0) / max(max_step, 1e-6)))))
        times = [t0 + (t1 - t0) * k / n for k in range(1, n + 1)]
        per_drive = [[p * a for a in d.angles_at(times)] for d, p in zip(self.drives, self.polarity)]
        return [list(row) for row in zip(*per_drive)]

    def wheel_speeds(self) -> List[float]:
        out = []
        for d, p in zip(self.drives, self.polarity):
            with d._lock:
                d.update()
                out.append(p * d.velocity)
        return out
