"""The small abstract interface of each device kind, and the health record every backend reports.

A backend owns its link: ``start()`` begins connecting in the background (never blocks on a missing device),
``close()`` ends every thread and link. Long operations take a :class:`Waiter` (LOCEM's ``CommandContext``
is one): the backend sleeps through it, so cancel, ``STOP`` and deadlines reach the device at once, and
registers a device stop with ``on_cancel``. Errors are :mod:`.errors` classes.

Health (``health()``), as ``STATUS``, ``/locem/status`` and ``/diagnostics`` show it::

    {"link": "up" | "down" | "connecting", "device": "ok" | "<state>", "last_error": "", ...details}

:func:`health_level` grades one record as ``diagnostic_msgs/DiagnosticStatus`` does (OK 0, WARN 1, ERROR 2): ERROR
when the link is not up, the device state starts with ``fault`` or ``safety``, or a ``fault`` is latched.
"""

import abc
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence

try:  # typing.Protocol is 3.8+
    from typing import Protocol
except ImportError:  # pragma: no cover
    Protocol = object  # type: ignore


class Waiter(Protocol):
    """What a long device operation needs from its caller (satisfied by LOCEM's ``CommandContext``)."""

    def sleep(self, seconds: float) -> None: ...

    def check(self) -> None: ...

    def on_cancel(self, callback: Callable[[], None]) -> None: ...

    def report(self, progress: float, text: str = "") -> None: ...


class PlainWaiter:
    """A :class:`Waiter` for scripts and benchmarks: plain sleeping, ``cancel()`` from another thread."""

    def __init__(self) -> None:
        self._cancelled = threading.Event()
        self._callbacks: List[Callable[[], None]] = []

    def sleep(self, seconds: float) -> None:
        self.check()
        if self._cancelled.wait(max(0.0, seconds)):
            self.check()

    def check(self) -> None:
        if self._cancelled.is_set():
            from locem_bridge.locem.errors import Aborted
            raise Aborted("cancelled")

    def on_cancel(self, callback: Callable[[], None]) -> None:
        self._callbacks.append(callback)

    def report(self, progress: float, text: str = "") -> None:
        pass

    def cancel(self) -> None:
        self._cancelled.set()
        for cb in self._callbacks:
            cb()


class Health:
    """Thread-safe health record of one backend (link, device state, last error, details)."""

    def __init__(self, link: str = "connecting") -> None:
        self._lock = threading.Lock()
        self.link = link
        self.device = "unknown"
        self.last_error = ""
        self.since = time.time()
        self.details: Dict[str, Any] = {}

    def set(self, link: Optional[str] = None, device: Optional[str] = None, error: Optional[str] = None,
            **details: Any) -> None:
        with self._lock:
            if link is not None and link != self.link:
                self.link = link
                self.since = time.time()
            if device is not None:
                self.device = device
            if error is not None:
                self.last_error = error
            self.details.update(details)

    def report(self) -> Dict[str, Any]:
        with self._lock:
            out = {"link": self.link, "device": self.device, "last_error": self.last_error,
                   "link_since": round(self.since, 3)}
            out.update(self.details)
            return out


HEALTH_OK, HEALTH_WARN, HEALTH_ERROR = 0, 1, 2


def health_level(health: Dict[str, Any]) -> int:
    """The diagnostic level of one health record (see the module docstring)."""
    if health.get("link") != "up":
        return HEALTH_ERROR
    device = str(health.get("device", "ok"))
    if device.startswith("fault") or device.startswith("safety") or health.get("fault"):
        return HEALTH_ERROR
    return HEALTH_OK if device in ("ok", "unknown") else HEALTH_WARN


class Backend(abc.ABC):
    """What every backend offers."""

    kind = "device"

    @abc.abstractmethod
    def start(self) -> None:
        """Begin connecting (in the background); returns at once."""

    @abc.abstractmethod
    def close(self) -> None:
        """Stop the device, end threads and links (idempotent)."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Device-wide stop (LOCEM ``STOP``): no motion, process outputs off. Never raises for a down link."""

    @abc.abstractmethod
    def health(self) -> Dict[str, Any]:
        """The health record (see the module docstring)."""

    def wait_ready(self, timeout: float) -> bool:
        """Block until the link is up (True) or ``timeout`` passes (False)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.health().get("link") == "up":
                return True
            time.sleep(0.02)
        return self.health().get("link") == "up"


class Arm(Backend):
    """A 6-axis arm (UR semantics: joint positions in rad, poses ``[x, y, z, rx, ry, rz]`` in the arm base)."""

    kind = "arm"
    joint_names: Sequence[str] = ()

    @abc.abstractmethod
    def joint_positions(self) -> List[float]: ...

    @abc.abstractmethod
    def tcp_pose(self) -> List[float]: ...

    @abc.abstractmethod
    def move_joints(self, waiter: Waiter, q: Sequence[float], speed: float, accel: float) -> Dict[str, Any]: ...

    @abc.abstractmethod
    def move_linear(self, waiter: Waiter, pose: Sequence[float], speed: float, accel: float) -> Dict[str, Any]: ...

    @abc.abstractmethod
    def stop_motion(self, reason: str = "") -> None: ...

    @abc.abstractmethod
    def set_tcp(self, pose: Sequence[float]) -> None: ...

    @abc.abstractmethod
    def set_payload(self, mass: float, cog: Sequence[float]) -> None: ...

    @abc.abstractmethod
    def set_digital_output(self, index: int, value: bool) -> None: ...

    @abc.abstractmethod
    def reset(self, waiter: Waiter) -> Dict[str, Any]:
        """Operator reset after a safety stop whose cause is gone."""


class Compressor(Backend):
    """A spray compressor: motor, pressure set-point, measured pressure, spray valve."""

    kind = "compressor"

    @abc.abstractmethod
    def read(self) -> Dict[str, Any]:
        """A fresh reading: pressure, setpoint (bar), motor_running, valve_open, in_range, fault_code."""

    @abc.abstractmethod
    def set_motor(self, on: bool) -> None: ...

    @abc.abstractmethod
    def set_setpoint(self, bar: float) -> None: ...

    @abc.abstractmethod
    def set_valve(self, open_: bool) -> None: ...

    @abc.abstractmethod
    def check_link(self) -> None:
        """Raise :class:`~.errors.LinkDown` unless a poll succeeded recently."""


class Base(Backend):
    """An omnidirectional mobile base with odometry in the ``map`` frame."""

    kind = "base"

    @abc.abstractmethod
    def pose(self) -> List[float]:
        """``[x, y, theta]`` of base_footprint in map (odometry from the initial pose)."""

    @abc.abstractmethod
    def set_pose(self, x: float, y: float, theta: float) -> None: ...

    @abc.abstractmethod
    def twist(self) -> List[float]:
        """Measured body twist ``[vx, vy, wz]``."""

    @abc.abstractmethod
    def set_velocity(self, vx: float, vy: float, wz: float, hold: float = 0.5) -> None:
        """Open-loop body twist for ``hold`` seconds (``/cmd_vel``); later calls replace it."""

    @abc.abstractmethod
    def goto(self, waiter: Waiter, x: float, y: float, theta: float, tolerance: float, angle_tolerance: float,
             speed: float) -> Dict[str, Any]: ...


class Scanner(abc.ABC):
    """Wall feature detection behind SCAN (result shape: docs/contracts.md)."""

    @abc.abstractmethod
    def scan(self, base_pose: Sequence[float]) -> Dict[str, Any]: ...
