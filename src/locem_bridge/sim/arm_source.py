"""Where the world gets the arm's joint state and digital outputs from.

The world mirrors the arm; it never moves it. Any object with the :class:`ArmStateSource` shape works:
``joint_positions() -> 6 floats (rad)`` and ``digital_output(index) -> bool``; ``add_step_listener(fn)`` is
optional (``fn(q, motion_time)`` called by the source at every motion step, so fast motions are sampled densely;
``motion_time`` is the source's own motion clock in sim seconds, or None when it has none: a controller that moves
its arm in bursts on a busy machine says by it how long each step took).

- :class:`KinematicArm` is a settable source for scripts and tests (no controller, no protocol): set joint
  positions or interpolate a Cartesian line through a solver the world provides.
- :func:`ur_stand_in_source` adapts the UR controller stand-in (:mod:`locem_bridge.sim.ur`) when present.
"""
from __future__ import annotations

import threading
from typing import Any, Callable, List, Optional, Sequence

try:  # typing.Protocol is 3.8+
    from typing import Protocol
except ImportError:  # pragma: no cover
    Protocol = object  # type: ignore


class ArmStateSource(Protocol):
    def joint_positions(self) -> Sequence[float]: ...

    def digital_output(self, index: int) -> bool: ...


class KinematicArm:
    """A settable arm state (joint positions and 8 standard digital outputs), thread-safe.

    Setting ``q`` calls the step listeners like a controller's motion loop would.
    """

    def __init__(self, q: Optional[Sequence[float]] = None) -> None:
        self._lock = threading.Lock()
        self._q: List[float] = list(q) if q is not None else [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
        self._do = [False] * 8
        self._listeners: List[Callable[[Sequence[float], Optional[float]], None]] = []

    def joint_positions(self) -> List[float]:
        with self._lock:
            return list(self._q)

    def set_joint_positions(self, q: Sequence[float], motion_time: Optional[float] = None) -> None:
        """Set the joint positions (rad) and call the step listeners; ``motion_time`` (sim s) is this step's time on
        the arm's own motion clock, as a controller reports it, or None (the world then times the step itself)."""
        if len(q) != 6:
            raise ValueError("q must have 6 joint positions, found %d" % len(q))
        with self._lock:
            self._q = [float(x) for x in q]
            listeners = list(self._listeners)
        for fn in listeners:
            fn(list(q), motion_time)

    def digital_output(self, index: int) -> bool:
        with self._lock:
            return self._do[index]

    def set_digital_output(self, index: int, value: bool) -> None:
        if not 0 <= index < 8:
            raise ValueError("digital output index %r out of range, allowed 0..7" % (index,))
        with self._lock:
            self._do[index] = bool(value)

    def add_step_listener(self, fn: Callable[[Sequence[float], Optional[float]], None]) -> None:
        with self._lock:
            self._listeners.append(fn)

    def remove_step_listener(self, fn: Callable[[Sequence[float], Optional[float]], None]) -> None:
        with self._lock:
            if fn in self._listeners:
                self._listeners.remove(fn)


class UrArmSource:
    """Adapter: the UR controller stand-in (:class:`locem_bridge.sim.ur.UrControllerStandIn`) as an arm source.

    Joint positions and standard digital outputs come from the stand-in; its per-control-cycle listener
    (``ArmSnapshot``) feeds the world's step listener with ``snapshot.q`` and ``snapshot.motion_time``.
    """

    def __init__(self, ur: Any) -> None:
        self.ur = ur
        self._wrapped: dict = {}

    def joint_positions(self) -> List[float]:
        return [float(x) for x in self.ur.get_joint_positions()]

    def digital_output(self, index: int) -> bool:
        return bool(self.ur.get_standard_digital_outputs()[index])

    def add_step_listener(self, fn: Callable[[Sequence[float], Optional[float]], None]) -> None:
        def on_snapshot(snapshot: Any) -> None:
            fn(snapshot.q, snapshot.motion_time)
        self._wrapped[fn] = on_snapshot
        self.ur.add_step_listener(on_snapshot)

    def remove_step_listener(self, fn: Callable[[Sequence[float], Optional[float]], None]) -> None:
        cb = self._wrapped.pop(fn, None)
        if cb is not None:
            self.ur.remove_step_listener(cb)
