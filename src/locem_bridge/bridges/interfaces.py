"""The interface of each device kind (the whole surface its callers use), and the health record every backend reports.

A backend owns its link: ``start()`` begins connecting in the background (never blocks on a missing device),
``close()`` ends every thread and link. Long operations take a :class:`Waiter` (LOCEM's ``CommandContext``
is one): the backend sleeps through it, so cancel, ``STOP`` and deadlines reach the device at once, and
registers a device stop with ``on_cancel``. Errors are :mod:`.errors` classes.

Health (``health()``), as ``STATUS``, ``/locem/status`` and ``/diagnostics`` show it::

    {"link": "up" | "down" | "connecting", "device": "ok" | "<state>", "last_error": "", ...details}

:func:`locem_bridge.common.health.grade` grades one record (OK, WARN, ERROR as ``diagnostic_msgs/DiagnosticStatus``).
"""

import abc
import threading
import time
from typing import Any, Callable, ClassVar, Dict, FrozenSet, List, Mapping, NoReturn, Optional, Sequence, Tuple

from .errors import NotSupported

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


class Backend(abc.ABC):
    """What every backend offers, and how an optional capability is declared.

    A concrete backend **must** implement every abstract method of its device kind's interface (:class:`Arm`,
    :class:`Compressor`, :class:`Base`) and set the attributes that interface annotates (in ``__init__``, from its
    ``robot.<kind>`` section). It **may** implement optional capability groups: ``OPTIONAL`` of the interface names
    each group and its methods; a backend lists the groups it implements in ``capabilities`` and overrides every
    method of them. Callers ask :meth:`supports` (or :meth:`require`) before they use a group, never ``hasattr``;
    the interface's own versions of a group's methods raise :class:`~.errors.NotSupported` (``INVALID_COMMAND``),
    so a backend without the group writes nothing for it.
    ``test/bridges/test_device_interfaces.py`` checks every backend of :mod:`.backends` against this.

    Errors of every method are :mod:`.errors` classes: :class:`~.errors.NotConnected` (``NOT_READY``) before the
    link first came up, :class:`~.errors.LinkDown` / :class:`~.errors.DeviceFault` (``HARDWARE_ERROR``) for a
    lost link or a device fault, :class:`~.errors.BadRequest` (``INVALID_ARGUMENT``) for well-formed but
    impossible arguments; a long operation also ends with ``Aborted`` when its waiter is cancelled.
    """

    kind = "device"
    #: optional capability groups of this device kind: group name -> the methods that make it up
    OPTIONAL: ClassVar[Mapping[str, Tuple[str, ...]]] = {}
    #: the optional groups this backend implements (a subset of ``OPTIONAL``)
    capabilities: ClassVar[FrozenSet[str]] = frozenset()

    def supports(self, capability: str) -> bool:
        """Whether this backend implements the optional group ``capability`` (ValueError for an unknown name)."""
        if capability not in self.OPTIONAL:
            raise ValueError("%s has no optional capability '%s'; known: %s"
                             % (self.kind, capability, ", ".join(sorted(self.OPTIONAL)) or "none"))
        return capability in self.capabilities

    def require(self, capability: str) -> None:
        """Raise :class:`~.errors.NotSupported` (``INVALID_COMMAND``) unless :meth:`supports` ``capability``:
        a command that cannot run without the group refuses before anything moves."""
        if not self.supports(capability):
            self._unsupported(capability)

    def _unsupported(self, capability: str) -> NoReturn:
        raise NotSupported("this robot's %s (%s) has no %s capability" % (self.kind, type(self).__name__, capability),
                           device=self.kind)

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
    """A 6-axis arm, UR semantics.

    Units and frames: joint positions in rad (``joint_names`` order), joint speeds rad/s, accelerations rad/s^2;
    poses ``[x, y, z, rx, ry, rz]`` (m, rotation vector in rad) of the TCP in the arm ``base`` frame with the TCP
    offset of :meth:`set_tcp` applied; linear speeds m/s, accelerations m/s^2; forces N.

    Motions (:meth:`move_joints`, :meth:`move_linear`, :meth:`move_path`) block until the arm stands still at the
    target and return ``{"q": [...], "tcp_pose": [...], "duration_s": s}``. They sleep through the ``waiter``
    (cancel, ``STOP`` and deadlines reach the device at once) and stop the arm before they raise:
    ``Aborted`` (cancel, :meth:`stop_motion`), :class:`~.errors.MotionTimeout` (over the backend's own
    path-length deadline), :class:`~.errors.SafetyStop` (protective / emergency stop, latched until
    :meth:`reset`), :class:`~.errors.DeviceFault` (refused, or ended off target), :class:`~.errors.NotConnected`.

    Optional groups: ``path`` (:meth:`move_path`, one blended controller path) and ``force`` (force mode along
    one task-frame axis: :meth:`force_mode_start`, :meth:`wait_for_contact`, :meth:`record_force`,
    :meth:`contact_force`, :meth:`force_mode_stop`).
    """

    kind = "arm"
    PATH = "path"
    FORCE = "force"
    OPTIONAL: ClassVar[Mapping[str, Tuple[str, ...]]] = {
        PATH: ("move_path",),
        FORCE: ("force_mode_start", "wait_for_contact", "record_force", "contact_force", "force_mode_stop")}

    #: s, the margin a motion's deadline adds by default (``robot.arm.deadline.margin``); the registry's
    #: worst-case deadlines add it too
    MOTION_MARGIN_S = 2.0
    #: s, what a path may take before it moves (ur_rtde uploads the control script with the waypoints)
    PATH_UPLOAD_S = 2.0
    #: m per rad: the weight of rotation when a motion's length mixes translation and rotation (deadlines)
    ROTATION_WEIGHT = 0.3

    #: joint names, base to wrist (``robot.arm.joint_names``)
    joint_names: Sequence[str] = ()
    #: named joint poses (rad) of ``robot.arm.named_poses`` (at least ``home``; the wall commands use
    #: ``wall_ready`` and ``robot.arm.home_via``)
    named_poses: Mapping[str, List[float]] = {}

    # -- state -------------------------------------------------------------------------------------------
    @abc.abstractmethod
    def cached_state(self) -> Dict[str, Any]:
        """The latest polled state, never blocking: ``q`` (rad), ``qd`` (rad/s), ``tcp`` (pose), ``stamp`` (wall
        time ``time.time()`` the poll's answer arrived at, s), optionally ``sample_time`` (wall time the sample
        was taken at, from the controller's own clock: :mod:`locem_bridge.common.sample_clock`) and
        ``sample_tick`` (the controller's clock in wall seconds, its origin arbitrary: the time between two samples
        exactly, which ``sample_time`` gives only up to the mapping's offset, renewed as answers come in);
        ``{}`` before the first poll. Read by the TCP-triggered tool switch of the wall commands and by ``joint_states``."""

    @abc.abstractmethod
    def joint_positions(self) -> List[float]:
        """A fresh read of the joint positions (rad)."""

    @abc.abstractmethod
    def tcp_pose(self) -> List[float]:
        """A fresh read of the TCP pose (arm base frame)."""

    @abc.abstractmethod
    def named_pose(self, name: str) -> List[float]:
        """The joint positions of a named pose; BadRequest (``argument="pose"``) naming the known ones."""

    @abc.abstractmethod
    def inverse_kinematics(self, pose: Sequence[float], qnear: Optional[Sequence[float]] = None) -> List[float]:
        """Joint positions that put the TCP at ``pose``, the solution closest to ``qnear`` (default: the current
        joints); BadRequest when the pose is not reachable."""

    # -- motions -----------------------------------------------------------------------------------------
    @abc.abstractmethod
    def move_joints(self, waiter: Waiter, q: Sequence[float], speed: float, accel: float) -> Dict[str, Any]:
        """Synchronised joint move to ``q`` (rad); ``speed`` of the leading joint (rad/s), ``accel`` rad/s^2."""

    @abc.abstractmethod
    def move_linear(self, waiter: Waiter, pose: Sequence[float], speed: float, accel: float) -> Dict[str, Any]:
        """Straight TCP move to ``pose`` (arm base frame), ``speed`` m/s, ``accel`` m/s^2; ends within 1 mm."""

    def move_path(self, waiter: Waiter, poses: Sequence[Sequence[float]], speed: float, accel: float,
                  blends: Sequence[float]) -> Dict[str, Any]:
        """Optional group ``path``: straight segments through ``poses`` as ONE controller motion; interior
        waypoint i is rounded within ``blends[i]`` m without stopping (0 stops there), the last is reached
        exactly and at rest. BadRequest before anything moves for a blend radius larger than half of a
        neighbouring segment or a count of radii other than one per pose. Result as the other motions, plus
        ``waypoints``."""
        self._unsupported(self.PATH)

    @abc.abstractmethod
    def stop_motion(self, reason: str = "") -> None:
        """Decelerate now and end force mode; the running motion ends ``Aborted`` naming ``reason``. Never
        raises."""

    # -- settings and I/O --------------------------------------------------------------------------------
    @abc.abstractmethod
    def set_tcp(self, pose: Sequence[float]) -> None:
        """TCP offset from the flange, ``[x, y, z, rx, ry, rz]`` (m, rad)."""

    @abc.abstractmethod
    def set_payload(self, mass: float, cog: Sequence[float]) -> None:
        """Payload ``mass`` (kg) and centre of gravity ``cog`` (m, flange frame)."""

    @abc.abstractmethod
    def set_digital_output(self, index: int, value: bool) -> None:
        """Switch standard digital output ``index`` (0..7); returns once the controller reports the change
        (DeviceFault when it does not within 1 s)."""

    @abc.abstractmethod
    def digital_outputs(self) -> List[bool]:
        """The standard digital outputs DO0..DO7 as last polled."""

    @abc.abstractmethod
    def reset(self, waiter: Waiter) -> Dict[str, Any]:
        """Operator reset after a safety stop whose cause is gone: ``{"cleared": text, "steps": [...]}``;
        DeviceFault when the arm does not come back."""

    # -- optional group: force -----------------------------------------------------------------------------
    def force_mode_start(self, task_frame: Sequence[float], force: float, speed_limit: float) -> None:
        """Optional group ``force``: push with ``force`` N along the z axis of ``task_frame`` (a pose in the arm
        base frame), compliant along that axis only, at most ``speed_limit`` m/s along it. Motions meanwhile
        run along the other axes; their end check ignores the compliant axis."""
        self._unsupported(self.FORCE)

    def wait_for_contact(self, waiter: Waiter, tolerance: float, max_travel: float, timeout: float) -> float:
        """Optional group ``force``: wait until the force along the axis is within ``tolerance`` N of the
        set-point and return it; DeviceFault when the tool first travels ``max_travel`` m or ``timeout`` s
        pass."""
        self._unsupported(self.FORCE)

    def record_force(self, on: bool) -> None:
        """Optional group ``force``: start / stop recording the contact force (see :meth:`force_mode_stop`)."""
        self._unsupported(self.FORCE)

    def contact_force(self) -> float:
        """Optional group ``force``: the force (N) along the force-mode axis now (0 outside force mode)."""
        self._unsupported(self.FORCE)

    def force_mode_stop(self) -> Dict[str, float]:
        """Optional group ``force``: leave force mode (idempotent, never raises); the recorded force along the
        axis: ``samples`` and, when there are any, ``mean``, ``min``, ``max`` (N)."""
        self._unsupported(self.FORCE)


class Compressor(Backend):
    """A spray compressor: motor, pressure set-point, measured pressure, spray valve. Pressures in bar.

    Reading: :meth:`read` (a fresh request) and :meth:`cached` (the latest poll) return ``pressure``,
    ``setpoint`` (bar), ``motor_running``, ``valve_open``, ``in_range`` (pressure inside ``pressure_range``),
    ``fault`` (text, ``none`` when there is none) and ``fault_active``. Writes check the link first
    (:class:`~.errors.LinkDown` when no poll succeeded recently, :class:`~.errors.NotConnected` until the safe
    state after start, valve closed and motor off, is confirmed).
    """

    kind = "compressor"

    #: (low, high) bar: the working band the spray valve may open in (``robot.compressor.pressure_range``)
    pressure_range: Tuple[float, float]
    #: bar, the highest set-point this compressor accepts (``robot.compressor.max_setpoint``)
    max_setpoint: float
    #: Hz, how often the backend polls the device (the period :meth:`cached` is refreshed at)
    poll_rate: float
    #: s, the device's communication watchdog: with no request for this long it closes the valve and stops the
    #: motor by itself (``robot.compressor.watchdog_timeout``; 0 = none)
    watchdog_timeout: float

    @abc.abstractmethod
    def read(self) -> Dict[str, Any]:
        """A fresh reading (see the class docstring)."""

    @abc.abstractmethod
    def cached(self) -> Dict[str, Any]:
        """The latest polled reading, never blocking (``{}`` before the first poll)."""

    @abc.abstractmethod
    def set_motor(self, on: bool) -> None:
        """Motor on / off (off closes the valve first)."""

    @abc.abstractmethod
    def set_setpoint(self, bar: float) -> None:
        """Pressure set-point, bar."""

    @abc.abstractmethod
    def set_valve(self, open_: bool) -> None:
        """Spray valve open / closed."""

    @abc.abstractmethod
    def check_link(self) -> None:
        """Raise :class:`~.errors.LinkDown` unless a poll succeeded recently."""


class Base(Backend):
    """An omnidirectional mobile base with odometry in the ``map`` frame.

    Poses ``[x, y, theta]`` of base_footprint in ``map`` (m, rad, REP 103), twists ``[vx, vy, wz]`` in the base
    frame (m/s, rad/s). Optional group ``localisation``: :meth:`correct_pose` takes external pose fixes.
    """

    kind = "base"
    LOCALISATION = "localisation"
    OPTIONAL: ClassVar[Mapping[str, Tuple[str, ...]]] = {LOCALISATION: ("correct_pose",)}

    #: a localisation source is configured (optional group ``localisation``; see :meth:`wait_localised`)
    localisation_expected: bool = False

    #: named poses ``[x, y, theta]`` of ``robot.base.named_poses`` (plus the node's ``~named_poses``)
    named_poses: Mapping[str, List[float]] = {}

    @abc.abstractmethod
    def pose(self) -> List[float]:
        """``[x, y, theta]`` of base_footprint in map (odometry from the initial pose)."""

    @abc.abstractmethod
    def set_pose(self, x: float, y: float, theta: float) -> None:
        """Where the base is in the map now (resets odometry)."""

    @abc.abstractmethod
    def named_pose(self, name: str) -> List[float]:
        """The pose of a named place; BadRequest (``argument="name"``) naming the known ones."""

    @abc.abstractmethod
    def twist(self) -> List[float]:
        """Measured body twist ``[vx, vy, wz]``."""

    @abc.abstractmethod
    def set_velocity(self, vx: float, vy: float, wz: float, hold: float = 0.5) -> None:
        """Open-loop body twist for ``hold`` seconds (``/cmd_vel``); later calls replace it."""

    @abc.abstractmethod
    def goto(self, waiter: Waiter, x: float, y: float, theta: float, tolerance: float, angle_tolerance: float,
             speed: float) -> Dict[str, Any]:
        """Drive closed loop to ``(x, y, theta)`` in map until within ``tolerance`` m / ``angle_tolerance`` rad
        and still; ``speed`` m/s. Returns ``pose``, ``error_xy``, ``error_theta``, ``duration_s``; raises
        ``Aborted`` (:meth:`halt`, cancel), :class:`~.errors.MotionTimeout`, :class:`~.errors.DeviceFault`."""

    @abc.abstractmethod
    def halt(self) -> None:
        """Zero velocity now; a running :meth:`goto` ends ``Aborted``. Never raises."""

    @abc.abstractmethod
    def reset(self, waiter: Waiter) -> Dict[str, Any]:
        """Operator reset after a drive fault (nothing moves): ``{"cleared": text}``."""

    def correct_pose(self, x: float, y: float, theta: float) -> bool:
        """Optional group ``localisation``: a pose fix in map (m, rad); returns whether it was taken (a base
        may ignore fixes while it moves)."""
        self._unsupported(self.LOCALISATION)

    def wait_localised(self, waiter: Waiter, timeout: float) -> Optional[str]:
        """Optional group ``localisation``: wait, at most ``timeout`` s, until the pose holds a fix taken since
        the base last stopped, while fixes come at all (or before the first one, when
        :attr:`localisation_expected`). None once it does (or without localisation: at once); otherwise why
        not, for the log. A base without the group has nothing to wait for."""
        return None


class Lift(Backend):
    """A vertical axis carrying the arm (``robot.lift``): heights ``z`` (m) of the arm mount above base_footprint,
    within :attr:`range`. The arm's ``base`` frame moves with it."""

    kind = "lift"

    #: ``[bottom, top]`` heights the axis reaches (``robot.lift.range``), m
    range: Tuple[float, float] = (0.0, 0.0)

    @abc.abstractmethod
    def height(self) -> float:
        """The arm mount's height now (m above base_footprint, from the drive's position)."""

    @abc.abstractmethod
    def move_to(self, waiter: Waiter, z: float) -> Dict[str, Any]:
        """Move to ``z`` (m) and wait until in position (drive's target reached, within the tolerance): returns
        ``height``, ``error``, ``duration_s``; :class:`~.errors.BadRequest` naming :attr:`range` (nothing moves)
        for a height outside it; ``Aborted`` (:meth:`halt`, cancel), :class:`~.errors.MotionTimeout`,
        :class:`~.errors.DeviceFault`."""

    @abc.abstractmethod
    def halt(self) -> None:
        """Brake to a stand now (a running :meth:`move_to` ends ``Aborted``). Never raises."""


class ToolChanger(Backend):
    """An automatic tool changer: a lock on the flange that couples the tool waiting in the rack slot the flange is
    at, and releases the coupled tool into its own slot. Every tool carries a plate whose id is its rack slot
    (``robot.tool_changer.rack.<tool>.slot``); the rack slots are named arm poses the commands drive to.

    Reading: :meth:`read` (a fresh request) and :meth:`cached` (the latest poll) return ``locked``, ``unlocked``
    (both false while the lock moves), ``busy``, ``coupled_tool_id`` (0 none), ``coupled_tool`` (its name, ""
    none), ``fault_code``, ``fault`` (text, ``none``), ``fault_active``, ``present`` (tool -> it sits in its
    slot) and ``flange_slot`` (the slot the flange is at, 0 none).

    :meth:`lock` and :meth:`unlock` block until the device confirms (``locked`` / ``unlocked`` and not busy) and
    return the reading; the device's interlocks (lock away from a slot or at an empty one, unlock away from the
    coupled tool's slot) answer :class:`~.errors.DeviceFault` naming the fault, and so does no confirmation
    within :attr:`lock_timeout`. Link handling as the compressor's: :class:`~.errors.NotConnected` until the
    safe state after start is confirmed, :class:`~.errors.LinkDown` when no poll succeeded recently. The safe
    state holds what is coupled: the lock is commanded to the state the device reports (a coupled tool stays
    locked; a lock or unlock cut off by a link loss is not repeated).
    """

    kind = "tool_changer"

    #: tool name -> its rack slot (= its plate id), ``robot.tool_changer.rack``
    slots: Mapping[str, int]
    #: s, how long a lock or unlock may take before it fails (``robot.tool_changer.lock_timeout``)
    lock_timeout: float

    @abc.abstractmethod
    def read(self) -> Dict[str, Any]:
        """A fresh reading (see the class docstring)."""

    @abc.abstractmethod
    def cached(self) -> Dict[str, Any]:
        """The latest polled reading, never blocking (``{}`` before the first poll)."""

    @abc.abstractmethod
    def lock(self, waiter: Waiter) -> Dict[str, Any]:
        """Lock on the tool of the slot the flange is at; the reading once locked."""

    @abc.abstractmethod
    def unlock(self, waiter: Waiter) -> Dict[str, Any]:
        """Release the coupled tool into its slot (the flange must be at it); the reading once unlocked."""

    @abc.abstractmethod
    def check_link(self) -> None:
        """Raise :class:`~.errors.LinkDown` unless a poll succeeded recently."""


class Scanner(abc.ABC):
    """Wall feature detection behind SCAN (no link of its own: built, never started)."""

    kind = "scanner"

    @abc.abstractmethod
    def scan(self, base_pose: Sequence[float]) -> Dict[str, Any]:
        """The wall features visible from ``base_pose`` (``[x, y, theta]`` in map): ``stamp``, ``walls``,
        ``joints``, ``areas`` in the map frame (shape: docs/contracts.md)."""


#: the interface of each device kind of :data:`.backends.BACKENDS`
INTERFACES: Dict[str, type] = {"arm": Arm, "compressor": Compressor, "base": Base, "lift": Lift, "scanner": Scanner,
                               "tool_changer": ToolChanger}
