"""Mecanum kinematics of the four-wheel omnidirectional base (wheel order front_left, front_right, rear_left,
rear_right; wheel speeds in rad/s at the shaft, positive when the wheel rolls the robot forward).

Body twist ``(vx, vy, wz)`` in ``base_footprint`` (x forward, y left). With ``k = half_wheelbase + half_track``
and wheel radius ``r``: ``fl = (vx - vy - k wz)/r``, ``fr = (vx + vy + k wz)/r``, ``rl = (vx + vy - k wz)/r``,
``rr = (vx - vy + k wz)/r``; :meth:`Mecanum.body` is the least-squares inverse (also for angle increments).
"""

from typing import List, Sequence, Tuple


class Mecanum:
    def __init__(self, radius: float, half_wheelbase: float, half_track: float) -> None:
        if radius <= 0 or half_wheelbase <= 0 or half_track <= 0:
            raise ValueError("mecanum geometry must be positive (radius %r, half_wheelbase %r, half_track %r)"
                             % (radius, half_wheelbase, half_track))
        self.r = float(radius)
        self.k = float(half_wheelbase) + float(half_track)

    def wheels(self, vx: float, vy: float, wz: float) -> List[float]:
        r, k = self.r, self.k
        return [(vx - vy - k * wz) / r, (vx + vy + k * wz) / r, (vx + vy - k * wz) / r, (vx - vy + k * wz) / r]

    def body(self, w: Sequence[float]) -> Tuple[float, float, float]:
        fl, fr, rl, rr = w
        r, k = self.r, self.k
        return (r / 4.0 * (fl + fr + rl + rr), r / 4.0 * (-fl + fr + rl - rr), r / (4.0 * k) * (-fl + fr - rl + rr))

    def scale_to_limit(self, vx: float, vy: float, wz: float, max_wheel: float) -> Tuple[float, float, float]:
        """The twist scaled down (direction kept) so no wheel exceeds ``max_wheel`` rad/s."""
        peak = max(abs(w) for w in self.wheels(vx, vy, wz))
        if peak <= max_wheel or peak == 0.0:
            return vx, vy, wz
        s = max_wheel / peak
        return vx * s, vy * s, wz * s
