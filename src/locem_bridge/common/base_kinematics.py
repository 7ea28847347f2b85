"""Wheeled base kinematics, one model per ``robot.base.kind``: the name -> model table :data:`KINEMATICS`.

Wheel speeds are wheel-shaft angular velocities in rad/s, positive when the wheel rolls the robot forward.
Body twist ``(vx, vy, wz)`` is in the base frame (x forward, y left, z up; base_footprint).

``mecanum`` (4 wheels, omnidirectional), wheel order front_left, front_right, rear_left, rear_right,
``k = half_wheelbase + half_track``. Inverse: ``fl = (vx - vy - k wz)/r``, ``fr = (vx + vy + k wz)/r``,
``rl = (vx + vy - k wz)/r``, ``rr = (vx - vy + k wz)/r``; forward is its least-squares inverse.

``differential`` (2 driven wheels on one axle through base_footprint, passive casters), wheel order left, right,
``s = separation`` (distance between the wheel contact points). Inverse: ``left = (vx - wz s/2)/r``,
``right = (vx + wz s/2)/r``; forward: ``vx = r (left + right)/2``, ``vy = 0``, ``wz = r (right - left)/s``.
It cannot move sideways (``holonomic`` is False): the ``vy`` of a twist is dropped; a caller that must reach a
lateral goal turns first (the base bridge's GOTO turns, drives, turns).

One module for the robot's geometry: the base bridge commands wheels with it and the simulated worksite moves
the base with it. :func:`kinematics_for` builds a model from the ``robot.base.wheel`` section; the robot file
checks that section with :data:`WHEEL_KEYS` and the wheel list with :data:`WHEEL_ORDER`.
"""
from __future__ import annotations

from typing import Any, Dict, List, Mapping, Sequence, Tuple


class BaseKinematics:
    """Pure functions of a wheel geometry (the interface every model of :data:`KINEMATICS` implements)."""

    #: the ``robot.base.kind`` naming this model
    kind = ""
    #: True when the base can move in any direction without turning first
    holonomic = True
    #: wheel radius, m
    r = 1.0

    def wheel_speeds(self, vx: float, vy: float, wz: float) -> List[float]:
        """Body twist -> wheel speeds in rad/s, in the model's wheel order (:data:`WHEEL_ORDER`)."""
        raise NotImplementedError

    def twist(self, w: Sequence[float]) -> Tuple[float, float, float]:
        """Wheel speeds (or wheel angle increments) -> body twist (or body displacement)."""
        raise NotImplementedError

    def wheel_positions(self) -> List[Tuple[float, float]]:
        """Each driven wheel's centre ``(x, y)`` in base_footprint, in the model's wheel order."""
        raise NotImplementedError

    def scale_to_limit(self, vx: float, vy: float, wz: float, max_wheel: float) -> Tuple[float, float, float]:
        """The twist scaled down (direction kept) so no wheel exceeds ``max_wheel`` rad/s."""
        peak = max(abs(w) for w in self.wheel_speeds(vx, vy, wz))
        if peak <= max_wheel or peak == 0.0:
            return vx, vy, wz
        s = max_wheel / peak
        return vx * s, vy * s, wz * s


class MecanumKinematics(BaseKinematics):
    """Four mecanum wheels at ``(+-half_wheelbase, +-half_track)`` (see the module docstring)."""

    kind = "mecanum"
    holonomic = True

    def __init__(self, radius: float, half_wheelbase: float, half_track: float) -> None:
        if radius <= 0.0 or half_wheelbase <= 0.0 or half_track <= 0.0:
            raise ValueError("mecanum geometry must be positive: radius=%r half_wheelbase=%r half_track=%r"
                             % (radius, half_wheelbase, half_track))
        self.r = float(radius)
        self.half_wheelbase = float(half_wheelbase)
        self.half_track = float(half_track)
        self.k = self.half_wheelbase + self.half_track

    def wheel_speeds(self, vx: float, vy: float, wz: float) -> List[float]:
        """Body twist -> wheel speeds [fl, fr, rl, rr] in rad/s."""
        r, k = self.r, self.k
        return [(vx - vy - k * wz) / r, (vx + vy + k * wz) / r, (vx + vy - k * wz) / r, (vx - vy + k * wz) / r]

    def twist(self, w: Sequence[float]) -> Tuple[float, float, float]:
        """Wheel speeds (or wheel angle increments) [fl, fr, rl, rr] -> body twist (or body displacement)."""
        fl, fr, rl, rr = w
        r, k = self.r, self.k
        return (r / 4.0 * (fl + fr + rl + rr), r / 4.0 * (-fl + fr + rl - rr), r / (4.0 * k) * (-fl + fr - rl + rr))

    def wheel_positions(self) -> List[Tuple[float, float]]:
        a, b = self.half_wheelbase, self.half_track
        return [(a, b), (a, -b), (-a, b), (-a, -b)]


class DifferentialKinematics(BaseKinematics):
    """Two driven wheels, left and right, ``separation`` apart on the axle through base_footprint."""

    kind = "differential"
    holonomic = False

    def __init__(self, radius: float, separation: float) -> None:
        if radius <= 0.0 or separation <= 0.0:
            raise ValueError("differential geometry must be positive: radius=%r separation=%r" % (radius, separation))
        self.r = float(radius)
        self.separation = float(separation)

    def wheel_speeds(self, vx: float, vy: float, wz: float) -> List[float]:
        """Body twist -> wheel speeds [left, right] in rad/s (``vy`` cannot be produced and is dropped)."""
        h = self.separation / 2.0
        return [(vx - h * wz) / self.r, (vx + h * wz) / self.r]

    def twist(self, w: Sequence[float]) -> Tuple[float, float, float]:
        """Wheel speeds (or wheel angle increments) [left, right] -> body twist (or body displacement)."""
        left, right = w
        return (self.r / 2.0 * (left + right), 0.0, self.r / self.separation * (right - left))

    def wheel_positions(self) -> List[Tuple[float, float]]:
        h = self.separation / 2.0
        return [(0.0, h), (0.0, -h)]


#: ``robot.base.kind`` -> model class
KINEMATICS: Dict[str, type] = {"mecanum": MecanumKinematics, "differential": DifferentialKinematics}
#: ``robot.base.kind`` -> the geometry keys of ``robot.base.wheel`` the model reads (besides ``radius``)
WHEEL_KEYS: Dict[str, Tuple[str, ...]] = {"mecanum": ("half_wheelbase", "half_track"),
                                          "differential": ("separation",)}
#: ``robot.base.kind`` -> the wheels of ``robot.base.drives.wheels``, in the order of the model's equations
WHEEL_ORDER: Dict[str, Tuple[str, ...]] = {"mecanum": ("front_left", "front_right", "rear_left", "rear_right"),
                                           "differential": ("left", "right")}


def kinematics_for(kind: str, wheel: Mapping[str, Any]) -> BaseKinematics:
    """The model of ``kind`` (a key of :data:`KINEMATICS`) built from a ``robot.base.wheel`` section."""
    if kind not in KINEMATICS:
        raise ValueError("unknown base kind %r, allowed: %s" % (kind, ", ".join(sorted(KINEMATICS))))
    return KINEMATICS[kind](float(wheel["radius"]), *(float(wheel[k]) for k in WHEEL_KEYS[kind]))
