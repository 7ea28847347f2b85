"""Simulation time with a time scale: sim seconds advance ``time_scale`` times faster than wall seconds.

Models (pressure, drives, base, arm motion) advance on :meth:`SimClock.now`; protocol streams (TPDOs,
heartbeats, RTDE, Modbus answers) keep wall-clock rates: they are the devices' real-time behaviour, and the
clients' timeouts (e.g. the base bridge's 2 x 100 ms heartbeat consumer) are wall-clock facts of the real robot
(docs/protocol_notes.md, "Time scale and the bus"). ``time_scale = 1.0`` is hardware-like. The scale can
be changed while running; sim time stays continuous. Thread-safe.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Optional

from .errors import SimConfigError


class SimClock:
    """Monotonic simulation clock: ``now()`` in sim seconds since construction (or ``start``)."""

    def __init__(self, time_scale: float = 1.0, start: float = 0.0,
                 wall: Optional[Callable[[], float]] = None) -> None:
        self._wall = wall or time.monotonic
        self._lock = threading.Lock()
        self._check(time_scale)
        self._scale = float(time_scale)
        self._sim0 = float(start)
        self._wall0 = self._wall()

    @staticmethod
    def _check(scale: float) -> None:
        if not (isinstance(scale, (int, float)) and 0.0 < scale <= 1000.0):
            raise SimConfigError("time_scale = %r is out of range, allowed (0, 1000]" % (scale,))

    @property
    def time_scale(self) -> float:
        return self._scale

    @time_scale.setter
    def time_scale(self, scale: float) -> None:
        self._check(scale)
        with self._lock:
            now_w = self._wall()
            self._sim0 += (now_w - self._wall0) * self._scale
            self._wall0 = now_w
            self._scale = float(scale)

    def now(self) -> float:
        """Current sim time in seconds."""
        with self._lock:
            return self._sim0 + (self._wall() - self._wall0) * self._scale

    def wall_to_sim(self, wall_seconds: float) -> float:
        return wall_seconds * self._scale

    def sim_to_wall(self, sim_seconds: float) -> float:
        return sim_seconds / self._scale
