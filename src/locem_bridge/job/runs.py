"""Separate runs on one machine: each run of the main job gets its own device addresses, and a small registry of
the runs under way says what is taken and by which run.

The simulated devices listen where real ones would: the UR stand-in on one address at the fixed UR ports
29999/30003/30004 (ur_rtde always dials those), the compressor on a Modbus TCP port, the base drives on a
``udp_multicast`` CAN channel (group and UDP port). Two runs on the same addresses reach each other's devices, so
run ``n`` (slot ``n``) takes the robot file's addresses shifted by ``n``: loopback ``127.0.0.(1+n)`` (every
127.0.0.0/8 address works on Linux without setup) with the same ports, CAN group ``.(2+n)`` and UDP port
``43113+n`` (python-can binds the port on every address, so a group alone would not separate two runs).

:class:`RunRegistry` keeps one JSON file per run under way (run id, pid, slot, addresses, ROS ports) in a folder
shared by every checkout on the machine (``$LOCEM_RUNS_DIR``, default ``<tmp>/locem_bridge_runs``); an entry
whose process is gone is ignored. :meth:`RunRegistry.claim` takes the first slot no live run holds and whose
addresses are free right now (:func:`probe` binds them as the stand-ins will), under a file lock so two runs
started at the same moment get different slots; when no slot is left it raises :class:`NoFreeAddresses` with one
line naming what is taken and by which run. ROS-free.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import ipaddress
import json
import os
import socket
import tempfile
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

from ..common.can_bus import bus_name

#: the UR controller's fixed port names in the order of :attr:`DeviceAddresses.ur_ports`
UR_PORT_NAMES = ("dashboard", "script", "rtde")


class RunsError(Exception):
    """Base class of this module's errors."""


class NoFreeAddresses(RunsError):
    """No slot of device addresses is free; the message (one line) names what is taken and by which run."""


@dataclass(frozen=True)
class DeviceAddresses:
    """Where one run's devices listen."""

    host: str                              # UR stand-in and compressor (IPv4)
    ur_ports: Tuple[int, int, int]         # dashboard, script, RTDE
    modbus_port: int
    can_interface: str                     # udp_multicast | virtual | socketcan
    can_channel: str                       # multicast group, socketcan device or virtual bus name
    can_port: int                          # UDP port of the udp_multicast group (0 when not udp_multicast)

    def overrides(self) -> Dict[str, Any]:
        """The robot-section overrides that put a robot file on these addresses (``robot_overrides``)."""
        can: Dict[str, Any] = {"interface": self.can_interface, "channel": self.can_channel}
        if self.can_interface == "udp_multicast":
            can["port"] = self.can_port
        return {"arm": {"controller": {"host": self.host}}, "compressor": {"host": self.host, "port": self.modbus_port},
                "base": {"drives": {"can": can}}}

    def as_dict(self) -> Dict[str, Any]:
        """Plain JSON data for the registry and the run report."""
        return {"ur": "%s:%s" % (self.host, "/".join(str(p) for p in self.ur_ports)),
                "modbus": "%s:%d" % (self.host, self.modbus_port),
                "can": self.can_text()}

    def can_text(self) -> str:
        return bus_name(self.overrides()["base"]["drives"]["can"])     # as the bus's own errors name it

    def describe(self) -> str:
        """``UR 127.0.0.2:29999/30003/30004, Modbus 127.0.0.2:5020, CAN udp_multicast 239.74.163.3:43114``."""
        d = self.as_dict()
        return "UR %s, Modbus %s, CAN %s" % (d["ur"], d["modbus"], d["can"])

    @classmethod
    def from_registry(cls, data: Mapping[str, Any]) -> "DeviceAddresses":
        return cls(host=str(data["host"]), ur_ports=tuple(int(p) for p in data["ur_ports"]),  # type: ignore[arg-type]
                   modbus_port=int(data["modbus_port"]), can_interface=str(data["can_interface"]),
                   can_channel=str(data["can_channel"]), can_port=int(data["can_port"]))


def addresses_of(robot: Mapping[str, Any]) -> DeviceAddresses:
    """The device addresses of a robot section (the ``robot:`` mapping of a robot YAML, overrides merged)."""
    try:
        ctl = robot["arm"]["controller"]
        comp = robot["compressor"]
        can = robot["base"]["drives"]["can"]
        interface = str(can["interface"])
        return DeviceAddresses(
            host=str(ctl["host"]),
            ur_ports=(int(ctl.get("dashboard_port", 29999)), int(ctl.get("script_port", 30003)),
                      int(ctl.get("rtde_port", 30004))),
            modbus_port=int(comp["port"]), can_interface=interface, can_channel=str(can["channel"]),
            can_port=int(can.get("port", 43113)) if interface == "udp_multicast" else 0)
    except (KeyError, TypeError, ValueError) as exc:
        raise RunsError("robot config has no usable device addresses (robot.arm.controller.host, "
                        "robot.compressor.port, robot.base.drives.can): %s" % exc)


def slot_addresses(base: DeviceAddresses, slot: int) -> Optional[DeviceAddresses]:
    """The addresses of run slot ``slot`` (0 = the robot file's own); None when ``base`` cannot be shifted that
    far (a host outside 127.0.0.0/8 or a CAN interface other than udp_multicast has slot 0 only)."""
    if slot == 0:
        return base
    host = ipaddress.IPv4Address(base.host)
    shifted = host + slot
    if not host.is_loopback or not shifted.is_loopback or int(shifted) & 0xFF in (0, 255):
        return None
    if base.can_interface != "udp_multicast":
        return None
    group = ipaddress.IPv4Address(base.can_channel) + slot
    if not group.is_multicast or base.can_port + slot > 65535:
        return None
    return DeviceAddresses(host=str(shifted), ur_ports=base.ur_ports, modbus_port=base.modbus_port,
                           can_interface=base.can_interface, can_channel=str(group), can_port=base.can_port + slot)


def probe(addresses: DeviceAddresses) -> List[str]:
    """What of ``addresses`` is in use right now, as ``"UR dashboard 127.0.0.1:29999"`` items (empty: all free).

    TCP ports are bound as the stand-ins bind them (``SO_REUSEADDR``, so a port in TIME_WAIT counts as free and a
    listener as taken); the CAN channel's UDP port is bound without ``SO_REUSEADDR``, which fails while any
    process (a stand-in, a bridge, a heartbeat helper) has the bus open."""
    taken: List[str] = []
    tcp = [("UR %s" % n, p) for n, p in zip(UR_PORT_NAMES, addresses.ur_ports)] + [("Modbus", addresses.modbus_port)]
    for what, port in tcp:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((addresses.host, port))
            except OSError as exc:
                taken.append("%s %s:%d%s" % (what, addresses.host, port, _why(exc)))
    if addresses.can_interface == "udp_multicast":
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.bind(("", addresses.can_port))
            except OSError as exc:
                taken.append("CAN %s%s" % (addresses.can_text(), _why(exc)))
    return taken


def _why(exc: OSError) -> str:
    return "" if exc.errno == errno.EADDRINUSE else " (%s)" % (exc.strerror or exc)


@dataclass
class RunEntry:
    """One run under way, as the registry keeps it."""

    run: str
    pid: int
    slot: int
    addresses: DeviceAddresses
    ports: List[int] = field(default_factory=list)       # ROS master, operator page
    started: float = 0.0
    pid_start: str = ""                                   # /proc start time of pid (guards against pid reuse)

    def to_json(self) -> Dict[str, Any]:
        data = asdict(self)
        data["addresses"] = asdict(self.addresses)
        data["devices"] = self.addresses.as_dict()
        return data

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "RunEntry":
        return cls(run=str(data["run"]), pid=int(data["pid"]), slot=int(data["slot"]),
                   addresses=DeviceAddresses.from_registry(data["addresses"]),
                   ports=[int(p) for p in data.get("ports", [])], started=float(data.get("started", 0.0)),
                   pid_start=str(data.get("pid_start", "")))

    def label(self) -> str:
        return "run %s (pid %d)" % (self.run, self.pid)


def process_start(pid: int) -> str:
    """The start time of process ``pid`` from /proc (clock ticks since boot), "" when unknown or gone."""
    try:
        with open("/proc/%d/stat" % pid, encoding="ascii", errors="replace") as handle:
            text = handle.read()
    except OSError:
        return ""
    fields = text.rsplit(")", 1)[-1].split()
    return fields[19] if len(fields) > 19 else ""


def alive(pid: int, pid_start: str = "") -> bool:
    """True when process ``pid`` exists (and, when ``pid_start`` is known, is still the same process)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass                                  # another user's process: it exists
    if pid_start:
        now = process_start(pid)
        return not now or now == pid_start
    return True


def default_folder() -> str:
    return os.environ.get("LOCEM_RUNS_DIR") or os.path.join(tempfile.gettempdir(), "locem_bridge_runs")


class RunRegistry:
    """The runs under way on this machine: one ``<run>.json`` per run in ``folder`` (see the module docstring)."""

    def __init__(self, folder: Optional[str] = None) -> None:
        self.folder = folder or default_folder()

    @contextlib.contextmanager
    def _locked(self) -> Iterator[None]:
        os.makedirs(self.folder, exist_ok=True)
        with open(os.path.join(self.folder, ".lock"), "a") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(handle, fcntl.LOCK_UN)

    def _path(self, run: str) -> str:
        return os.path.join(self.folder, run + ".json")

    def _read(self) -> List[RunEntry]:
        entries: List[RunEntry] = []
        try:
            names = sorted(os.listdir(self.folder))
        except OSError:
            return entries
        for name in names:
            if not name.endswith(".json"):
                continue
            try:
                with open(os.path.join(self.folder, name), encoding="utf-8") as handle:
                    entries.append(RunEntry.from_json(json.load(handle)))
            except (OSError, ValueError, KeyError, TypeError):
                continue                       # half-written or foreign file: not a run
        return entries

    def live(self) -> List[RunEntry]:
        """The runs whose process is still there (entries of dead processes are ignored)."""
        return [e for e in self._read() if alive(e.pid, e.pid_start)]

    def claim(self, run: str, base: DeviceAddresses, pid: Optional[int] = None, max_slots: int = 8,
              ports: Sequence[int] = (), taken_names: Callable[[str], bool] = lambda name: False,
              check: Callable[[DeviceAddresses], List[str]] = probe) -> RunEntry:
        """Register a run on the first free slot of ``base`` (see the module docstring); returns its entry.

        ``run`` is made unique among the live runs and where ``taken_names(run)`` says so (``-2``, ``-3`` ...
        appended). Raises :class:`NoFreeAddresses` (one line: what is taken, by which run) when every one of
        ``max_slots`` slots is held by a live run or in use by another program."""
        pid = os.getpid() if pid is None else pid
        with self._locked():
            live = self.live()
            for entry in self._read():       # forget the dead
                if entry not in live:
                    with contextlib.suppress(OSError):
                        os.remove(self._path(entry.run))
            names = {e.run for e in live}
            unique, n = run, 1
            while unique in names or taken_names(unique):
                n += 1
                unique = "%s-%d" % (run, n)
            reasons: List[str] = []
            for slot in range(max(1, max_slots)):
                addresses = slot_addresses(base, slot)
                if addresses is None:
                    reasons.append("slot %d: %s cannot be shifted to another loopback address / CAN channel"
                                   % (slot, base.describe()))
                    break
                holders = [e for e in live if e.slot == slot or _overlap(e.addresses, addresses)]
                if holders:
                    reasons.append("%s taken by %s" % (addresses.host, ", ".join(e.label() for e in holders)))
                    continue
                busy = check(addresses)
                if busy:
                    reasons.append("%s in use by a program outside the run registry (%s)"
                                   % (addresses.host, ", ".join(busy)))
                    continue
                entry = RunEntry(run=unique, pid=pid, slot=slot, addresses=addresses, ports=list(ports),
                                 started=time.time(), pid_start=process_start(pid))
                tmp = self._path(unique) + ".tmp"
                with open(tmp, "w", encoding="utf-8") as handle:
                    json.dump(entry.to_json(), handle, indent=1, sort_keys=True)
                os.replace(tmp, self._path(unique))
                return entry
            raise NoFreeAddresses("no free device addresses for a new run (%d slot%s tried): %s"
                                  % (max(1, max_slots), "" if max_slots == 1 else "s", "; ".join(reasons)))

    def used_ports(self) -> List[int]:
        """The ROS master and page ports of the live runs (a new run picks others)."""
        return sorted({p for e in self.live() for p in e.ports})

    def release(self, run: str) -> None:
        """Forget ``run`` (the run ended); a missing entry is fine."""
        with self._locked():
            with contextlib.suppress(OSError):
                os.remove(self._path(run))


def _overlap(a: DeviceAddresses, b: DeviceAddresses) -> bool:
    """True when two runs on these addresses would reach each other's devices."""
    same_host = a.host == b.host and (set(a.ur_ports) | {a.modbus_port}) & (set(b.ur_ports) | {b.modbus_port})
    same_can = a.can_interface == b.can_interface and (
        a.can_port == b.can_port if a.can_interface == "udp_multicast" else a.can_channel == b.can_channel)
    return bool(same_host) or same_can
