"""Motion generators with UR semantics, stepped by the controller with motion-time increments.

Every generator has ``step(dt, q, qd) -> (q, qd)`` (numpy arrays, rad and rad/s) and a ``done`` flag; the
controller holds at most one active generator. Lifecycle: created by a command, stepped each control cycle, dropped
when ``done`` or replaced by the next command (as ``kill move_thrd`` in the URScript control program).

- :class:`JointMove` — ``movej``: one trapezoidal profile shared by all joints (they start and stop together); the
  slowest joint under ``v`` / ``a`` sets the duration.
- :class:`LinearMove` — ``movel``: the TCP follows the straight segment between start and goal with a trapezoidal
  profile of the path parameter; the orientation is interpolated along the geodesic (SLERP); joints come from IK
  seeded with the previous sample.
- :class:`JointSpeed` / :class:`CartesianSpeed` — ``speedj`` / ``speedl``: ramp to a target velocity with the
  given acceleration and hold it until replaced or stopped.
- :class:`JointStop` / :class:`CartesianStop` — ``stopj`` / ``stopl``: linear deceleration to rest (stopl keeps the
  TCP on its current straight line).
- :class:`ServoJ` — ``servoj``: reach the streamed target within ``time`` (velocity limited).
"""
import math
from typing import Optional, Tuple

import numpy as np
import pinocchio as pin

from .errors import KinematicsError
from .kinematics import ArmKinematics

Arr = np.ndarray


class Trapezoid:
    """Time-optimal trapezoidal (or triangular) profile covering ``distance`` >= 0 with limits ``v``, ``a``."""

    __slots__ = ("d", "v", "a", "ta", "tc", "duration")

    def __init__(self, distance: float, v: float, a: float) -> None:
        if v <= 0 or a <= 0 or not math.isfinite(v) or not math.isfinite(a):
            raise ValueError("speed and acceleration must be positive and finite (v=%r, a=%r)" % (v, a))
        self.d = max(0.0, float(distance))
        if self.d * a < v * v:          # never reaches v: triangular
            self.ta = math.sqrt(self.d / a)
            self.v = a * self.ta
            self.tc = 0.0
        else:
            self.ta = v / a
            self.v = v
            self.tc = self.d / v - self.ta
        self.a = a
        self.duration = 2 * self.ta + self.tc

    def sample(self, t: float) -> Tuple[float, float]:
        """(position, velocity) at time t, clamped to [0, duration]."""
        if t <= 0:
            return 0.0, 0.0
        if t >= self.duration:
            return self.d, 0.0
        if t < self.ta:
            return 0.5 * self.a * t * t, self.a * t
        if t < self.ta + self.tc:
            return 0.5 * self.a * self.ta * self.ta + self.v * (t - self.ta), self.v
        r = self.duration - t
        return self.d - 0.5 * self.a * r * r, self.a * r


class Motion:
    """Base class: ``done`` turns True when the generator has nothing left to do."""

    kind = "motion"
    done = False

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:  # pragma: no cover - interface
        raise NotImplementedError


class JointMove(Motion):
    kind = "movej"

    def __init__(self, q0: Arr, q1: Arr, v: float, a: float) -> None:
        self.q0 = np.array(q0, dtype=float)
        self.delta = np.array(q1, dtype=float) - self.q0
        dist = float(np.max(np.abs(self.delta)))
        self.profile = Trapezoid(dist, v, a)
        self.scale = self.delta / dist if dist > 0 else np.zeros(6)
        self.t = 0.0
        self.done = dist == 0.0

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        self.t += dt
        s, sd = self.profile.sample(self.t)
        if self.t >= self.profile.duration:
            self.done = True
        return self.q0 + self.scale * s, self.scale * sd


class _CartesianPath(Motion):
    """Shared IK tracking for Cartesian generators: keeps a reference SE3 and solves IK from the last q."""

    def __init__(self, kin: ArmKinematics) -> None:
        self.kin = kin

    def _solve(self, target: pin.SE3, q: Arr) -> Arr:
        sol = self.kin.ik_se3(target, q, max_iter=50, tol=1e-11)
        if sol is None:
            raise KinematicsError("TCP target not reachable on the straight path (singularity or workspace limit)")
        return sol


class LinearMove(_CartesianPath):
    kind = "movel"

    def __init__(self, kin: ArmKinematics, q0: Arr, goal: pin.SE3, v: float, a: float) -> None:
        super().__init__(kin)
        self.start = kin.fk_se3(q0)
        self.goal = goal
        self.dp = goal.translation - self.start.translation
        self.dr = pin.log3(self.start.rotation.T @ goal.rotation)
        lin = float(np.linalg.norm(self.dp))
        ang = float(np.linalg.norm(self.dr))
        # The path parameter s in [0, 1]; the slower of translation (v m/s) and rotation (v rad/s) sets the time.
        self.length = max(lin, ang)
        self.profile = Trapezoid(self.length, v, a)
        self.t = 0.0
        self.done = self.length == 0.0

    def pose_at(self, s: float) -> pin.SE3:
        return pin.SE3(self.start.rotation @ pin.exp3(self.dr * s), self.start.translation + self.dp * s)

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        self.t += dt
        d, _ = self.profile.sample(self.t)
        s = d / self.length if self.length > 0 else 1.0
        if self.t >= self.profile.duration:
            self.done = True
            s = 1.0
        qn = self._solve(self.pose_at(s), q)
        return qn, (qn - q) / dt if dt > 0 else np.zeros(6)


class JointSpeed(Motion):
    kind = "speedj"

    def __init__(self, qd_target: Arr, a: float, t: float = 0.0) -> None:
        self.target = np.array(qd_target, dtype=float)
        self.a = float(a)

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        diff = self.target - qd
        m = float(np.max(np.abs(diff)))
        lim = self.a * dt
        nqd = self.target.copy() if m <= lim else qd + diff * (lim / m)
        return q + 0.5 * (qd + nqd) * dt, nqd


class CartesianSpeed(_CartesianPath):
    kind = "speedl"

    def __init__(self, kin: ArmKinematics, q0: Arr, twist0: Arr, xd_target: Arr, a: float) -> None:
        super().__init__(kin)
        self.ref = kin.fk_se3(q0)
        self.twist = np.array(twist0, dtype=float)
        self.target = np.array(xd_target, dtype=float)
        self.a = float(a)

    def retarget(self, xd_target: Arr, a: float) -> None:
        self.target = np.array(xd_target, dtype=float)
        self.a = float(a)

    def _advance_twist(self, dt: float) -> None:
        diff = self.target - self.twist
        m = max(float(np.linalg.norm(diff[:3])), float(np.linalg.norm(diff[3:])))
        lim = self.a * dt
        self.twist = self.target.copy() if m <= lim else self.twist + diff * (lim / m)

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        old = self.twist
        self._advance_twist(dt)
        mean = 0.5 * (old + self.twist)
        self.ref = pin.SE3(pin.exp3(mean[3:] * dt) @ self.ref.rotation, self.ref.translation + mean[:3] * dt)
        qn = self._solve(self.ref, q)
        return qn, (qn - q) / dt if dt > 0 else np.zeros(6)


class CartesianStop(CartesianSpeed):
    kind = "stopl"

    def __init__(self, kin: ArmKinematics, q0: Arr, twist0: Arr, a: float) -> None:
        super().__init__(kin, q0, twist0, np.zeros(6), a)
        self.done = not np.any(np.abs(self.twist) > 1e-12)

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        qn, nqd = super().step(dt, q, qd)
        if not np.any(np.abs(self.twist) > 1e-12):
            self.done = True
            nqd = np.zeros(6)
        return qn, nqd


class JointStop(Motion):
    kind = "stopj"

    def __init__(self, qd0: Arr, a: float) -> None:
        self.a = float(a)
        self.done = not np.any(np.abs(qd0) > 1e-12)

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        m = float(np.max(np.abs(qd)))
        lim = self.a * dt
        if m <= lim:
            self.done = True
            # remaining distance of the linear ramp: m/a * m/2 scaled per joint
            frac = m / self.a if self.a > 0 else 0.0
            return q + 0.5 * qd * frac, np.zeros(6)
        nqd = qd * (1.0 - lim / m)
        return q + 0.5 * (qd + nqd) * dt, nqd


class ServoJ(Motion):
    kind = "servoj"

    def __init__(self, target: Arr, time: float, vmax: Arr) -> None:
        self.vmax = np.array(vmax, dtype=float)
        self.retarget(target, time)

    def retarget(self, target: Arr, time: float) -> None:
        self.target = np.array(target, dtype=float)
        self.time = max(float(time), 1e-4)
        self.remaining = self.time

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        horizon = max(self.remaining, dt)
        v = (self.target - q) / horizon
        v = np.clip(v, -self.vmax, self.vmax)
        self.remaining = max(0.0, self.remaining - dt)
        return q + v * dt, v


def tcp_twist(prev: Optional[pin.SE3], cur: pin.SE3, dt: float) -> Arr:
    """Finite-difference TCP twist [v, w] in the base frame between two samples ``dt`` apart."""
    if prev is None or dt <= 0:
        return np.zeros(6)
    v = (cur.translation - prev.translation) / dt
    w = pin.log3(cur.rotation @ prev.rotation.T) / dt
    return np.concatenate([v, w])
