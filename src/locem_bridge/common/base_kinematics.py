"""Mecanum (4-wheel omnidirectional) kinematics, wheel order front_left, front_right, rear_left, rear_right.

Wheel speeds are wheel-shaft angular velocities in rad/s, positive when the wheel rolls the robot forward.
Body twist ``(vx, vy, wz)`` is in the base frame (x forward, y left, z up). ``k = half_wheelbase + half_track``.
Inverse: ``fl = (vx - vy - k wz)/r``, ``fr = (vx + vy + k wz)/r``, ``rl = (vx + vy - k wz)/r``,
``rr = (vx - vy + k wz)/r``; forward is its least-squares inverse.

One module for the robot's geometry: the base bridge commands wheels with it and the simulated worksite moves
the base with it.
"""
from __future__ import annotations

from typing import List, Sequence, Tuple


class MecanumKinematics:
    """Pure functions of the wheel geometry (radius, half wheelbase, half track)."""

    def __init__(self, radius: float, half_wheelbase: float, half_track: float) -> None:
        if radius <= 0.0 or half_wheelbase <= 0.0 or half_track <= 0.0:
            raise ValueError("mecanum geometry must be positive: radius=%r half_wheelbase=%r half_track=%r"
                             % (radius, half_wheelbase, half_track))
        self.r = float(radius)
        self.k = float(half_wheelbase) + float(half_track)

    def wheel_speeds(self, vx: float, vy: float, wz: float) -> List[float]:
        """Body twist -> wheel speeds [fl, fr, rl, rr] in rad/s."""
        r, k = self.r, self.k
        return [(vx - vy - k * wz) / r, (vx + vy + k * wz) / r, (vx + vy - k * wz) / r, (vx - vy + k * wz) / r]

    def twist(self, w: Sequence[float]) -> Tuple[float, float, float]:
        """Wheel speeds (or wheel angle increments) [fl, fr, rl, rr] -> body twist (or body displacement)."""
        fl, fr, rl, rr = w
        r, k = self.r, self.k
        return (r / 4.0 * (fl + fr + rl + rr), r / 4.0 * (-fl + fr + rl - rr), r / (4.0 * k) * (-fl + fr - rl + rr))

    def scale_to_limit(self, vx: float, vy: float, wz: float, max_wheel: float) -> Tuple[float, float, float]:
        """The twist scaled down (direction kept) so no wheel exceeds ``max_wheel`` rad/s."""
        peak = max(abs(w) for w in self.wheel_speeds(vx, vy, wz))
        if peak <= max_wheel or peak == 0.0:
            return vx, vy, wz
        s = max_wheel / peak
        return vx * s, vy * s, wz * s
