"""Path moves with blends (URScript ``movel``/``movej``/``movep`` sequences with ``r``), as the UR controller runs them.

Semantics (UR): the move toward waypoint *i* uses that waypoint's ``v`` and ``a``; a blend radius ``r > 0`` at an
interior waypoint means the TCP leaves the straight segment ``r`` before the waypoint and joins the next one ``r``
after it, without stopping; ``r = 0`` stops at the waypoint; the last waypoint is always reached exactly and at
rest. The stand-in draws the blend as the circular arc tangent to both segments at those two points, so the TCP
passes the waypoint at ``r * tan(turn / 4)`` (< ``r``). A blend radius larger than half of either neighbouring
segment is a runtime error (overlapping blends), found before anything moves.

Structure: :class:`PathMove` (the ``Motion`` for command 45) checks and plans the whole path, then runs it as a
sequence of *runs* split at the stop waypoints. A run of one segment is an ordinary :class:`~.motion.LinearMove` /
:class:`~.motion.JointMove`; a run of several blended segments is a :class:`BlendedLinearRun` (TCP path in the base
frame, orientation interpolated per segment and across each blend, joints from IK) or a :class:`BlendedJointRun`
(the same construction in joint space; the blend radius is converted to the joint distance at which the TCP is
``r`` from the waypoint). Both follow a :class:`BlendedCurve`: the geometry plus a time-optimal speed profile under
the per-segment speed / acceleration limits and the centripetal limit ``v <= sqrt(a * R)`` on each arc.
"""
import math
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np
import pinocchio as pin

from .errors import KinematicsError, ScriptRuntimeError
from .kinematics import ArmKinematics, pose_to_se3
from .motion import JointMove, LinearMove, Motion, _CartesianPath
from .script_path import PathEntry

Arr = np.ndarray

SAMPLE_STEP = 0.0005          # path units (m or rad) between speed-profile samples
MAX_SAMPLES = 20000
MIN_SPEED = 1e-6
LINEAR_KINDS = ("movel", "movep")


class BlendedCurve:
    """Straight segments through ``points`` (rows, Euclidean space of any dimension) joined by circular arcs.

    ``radii[k-1]`` is the blend radius at interior point k (1 .. m-1, where m = number of segments); the arc is
    tangent to both segments at distance ``radii`` from the point. ``vmax[k-1]`` / ``amax[k-1]`` limit path speed
    and acceleration on segment k; an arc takes the smaller limits of its two segments, the centripetal limit
    ``sqrt(a R)`` and ``arc_cap(k, arc_length)`` when given. The profile starts and ends at rest.
    """

    def __init__(self, points: Arr, radii: Sequence[float], vmax: Sequence[float], amax: Sequence[float],
                 arc_cap: Optional[Callable[[int, float], float]] = None) -> None:
        p = np.asarray(points, dtype=float)
        m = len(p) - 1
        self.points = p
        seg = p[1:] - p[:-1]
        self.lengths = np.linalg.norm(seg, axis=1)
        if np.any(self.lengths <= 0):
            raise ValueError("blended curve: zero-length segment")
        self.dirs = seg / self.lengths[:, None]
        r = [0.0] + [float(x) for x in radii] + [0.0]      # r[k] at point k (0 and m are the ends)
        self.radii = r
        pieces = []          # (kind, s0, length, k, data, vlim, alim)
        s = 0.0
        for k in range(1, m + 1):
            L = self.lengths[k - 1]
            f0, f1 = r[k - 1] / L, 1.0 - r[k] / L
            length = max(0.0, (f1 - f0) * L)
            if length > 0:
                pieces.append(("line", s, length, k, (f0, f1), vmax[k - 1], amax[k - 1]))
                s += length
            if k < m and r[k] > 0:
                d1, d2 = self.dirs[k - 1], self.dirs[k]
                cos_phi = float(np.clip(np.dot(d1, d2), -1.0, 1.0))
                phi = math.acos(cos_phi)
                a_lim = min(amax[k - 1], amax[k])
                v_lim = min(vmax[k - 1], vmax[k])
                if phi < 1e-9:                       # collinear: a straight blend
                    length, data = 2.0 * r[k], None
                else:
                    radius = r[k] / math.tan(phi / 2.0)
                    nvec = d2 - cos_phi * d1
                    nvec = nvec / np.linalg.norm(nvec)
                    centre = p[k] - r[k] * d1 + radius * nvec
                    length, data = radius * phi, (centre, radius, nvec, d1, phi)
                    v_lim = min(v_lim, math.sqrt(a_lim * radius))
                if arc_cap is not None:
                    v_lim = min(v_lim, arc_cap(k, length))
                if length > 0:
                    pieces.append(("arc", s, length, k, data, max(v_lim, MIN_SPEED), a_lim))
                    s += length
        self.pieces = pieces
        self.starts = np.array([pc[1] for pc in pieces])
        self.length = s
        self._profile()

    # -- geometry -----------------------------------------------------------------------------------------------
    def locate(self, s: float) -> Tuple[Arr, str, int, float]:
        """Point at arc length ``s``: (position, 'line' | 'arc', segment / waypoint index k, local fraction)."""
        j = int(np.searchsorted(self.starts, s, side="right")) - 1
        j = min(max(j, 0), len(self.pieces) - 1)
        kind, s0, length, k, data, _v, _a = self.pieces[j]
        u = min(1.0, max(0.0, (s - s0) / length))
        if kind == "line":
            f0, f1 = data
            f = f0 + (f1 - f0) * u
            if s >= self.length:
                f = 1.0
            pos = self.points[k - 1] + (self.points[k] - self.points[k - 1]) * f
            if f == 1.0:
                pos = self.points[k].copy()
            return pos, "line", k, f
        if data is None:
            d1 = self.dirs[k - 1]
            pos = self.points[k] + d1 * (self.radii[k] * (2.0 * u - 1.0))
            return pos, "arc", k, u
        centre, radius, nvec, d1, phi = data
        th = phi * u
        return centre - radius * nvec * math.cos(th) + radius * d1 * math.sin(th), "arc", k, u

    # -- speed profile --------------------------------------------------------------------------------------------
    def _profile(self) -> None:
        total = self.length
        n = int(min(MAX_SAMPLES, max(2, math.ceil(total / SAMPLE_STEP))))
        ds = total / n
        cell_v = np.full(n, np.inf)
        cell_a = np.full(n, np.inf)
        for _kind, s0, length, _k, _d, vl, al in self.pieces:
            i0 = int(math.floor(s0 / ds))
            i1 = int(math.ceil((s0 + length) / ds))
            i0, i1 = max(0, min(i0, n - 1)), max(1, min(i1, n))
            if i1 <= i0:
                i1 = i0 + 1
            cell_v[i0:i1] = np.minimum(cell_v[i0:i1], vl)
            cell_a[i0:i1] = np.minimum(cell_a[i0:i1], al)
        vertex = np.empty(n + 1)
        vertex[0] = vertex[n] = 0.0
        vertex[1:n] = np.minimum(cell_v[:-1], cell_v[1:])
        vmax = vertex.tolist()
        acc = cell_a.tolist()
        v = [0.0] * (n + 1)
        for i in range(n):
            v[i + 1] = min(vmax[i + 1], math.sqrt(v[i] * v[i] + 2.0 * acc[i] * ds))
        for i in range(n - 1, -1, -1):
            v[i] = min(v[i], math.sqrt(v[i + 1] * v[i + 1] + 2.0 * acc[i] * ds))
        vel = np.array(v)
        dt = 2.0 * ds / np.maximum(vel[:-1] + vel[1:], MIN_SPEED)
        self.ds = ds
        self.vel = vel
        self.cell_dt = dt
        self.times = np.concatenate([[0.0], np.cumsum(dt)])
        self.duration = float(self.times[-1])

    def sample(self, t: float) -> Tuple[float, float]:
        """(arc length, path speed) at time ``t`` (clamped to [0, duration])."""
        if t <= 0:
            return 0.0, 0.0
        if t >= self.duration:
            return self.length, 0.0
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        i = min(max(i, 0), len(self.cell_dt) - 1)
        tau = t - self.times[i]
        v0, v1, dt = self.vel[i], self.vel[i + 1], self.cell_dt[i]
        alpha = (v1 - v0) / dt
        s = i * self.ds + v0 * tau + 0.5 * alpha * tau * tau
        return min(s, (i + 1) * self.ds), v0 + alpha * tau


class BlendedLinearRun(_CartesianPath):
    """``movel`` through several poses with blends (one run: at rest only at its ends)."""

    kind = "movel"

    def __init__(self, kin: ArmKinematics, start: pin.SE3, goals: Sequence[pin.SE3], v: Sequence[float],
                 a: Sequence[float], radii: Sequence[float]) -> None:
        super().__init__(kin)
        frames = [start] + list(goals)
        self.rot = [f.rotation.copy() for f in frames]
        self.drot = [pin.log3(self.rot[k - 1].T @ self.rot[k]) for k in range(1, len(frames))]
        pts = np.array([f.translation for f in frames])
        lin = np.linalg.norm(pts[1:] - pts[:-1], axis=1)
        ang = np.array([float(np.linalg.norm(d)) for d in self.drot])
        # as movel: the slower of translation (v m/s) and rotation (v rad/s) sets the pace of a segment
        scale = lin / np.maximum(lin, ang)
        vmax = [float(v[k] * scale[k]) for k in range(len(lin))]
        amax = [float(a[k] * scale[k]) for k in range(len(lin))]
        self.lin = lin

        def arc_cap(k: int, arc_length: float) -> float:
            turn = self._blend_rotation(k)[1]
            return min(v[k - 1], v[k]) * arc_length / turn if turn > 1e-12 else float("inf")
        self.radii = [0.0] + list(radii) + [0.0]
        self.curve = BlendedCurve(pts, radii, vmax, amax, arc_cap)
        self.goal = goals[-1]
        self.t = 0.0
        self.segment = 1
        self.path_speed = 0.0

    def _segment_rotation(self, k: int, f: float) -> Arr:
        return self.rot[k - 1] @ pin.exp3(self.drot[k - 1] * f)

    def _blend_rotation(self, k: int) -> Tuple[Arr, float, Arr]:
        r_in = self._segment_rotation(k, 1.0 - self.radii[k] / self.lin[k - 1])
        r_out = self._segment_rotation(k + 1, self.radii[k] / self.lin[k])
        delta = pin.log3(r_in.T @ r_out)
        return r_in, float(np.linalg.norm(delta)), delta

    def pose_at(self, s: float) -> pin.SE3:
        pos, kind, k, f = self.curve.locate(s)
        if kind == "line":
            self.segment = k
            rot = self._segment_rotation(k, f)
        else:
            self.segment = k + 1
            r_in, _turn, delta = self._blend_rotation(k)
            rot = r_in @ pin.exp3(delta * f)
        return pin.SE3(rot, np.asarray(pos, dtype=float))

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        self.t += dt
        s, self.path_speed = self.curve.sample(self.t)
        if self.t >= self.curve.duration:
            self.done = True
            target = self.goal
            self.segment = len(self.lin)
        else:
            target = self.pose_at(s)
        qn = self._solve(target, q)
        return qn, (qn - q) / dt if dt > 0 else np.zeros(6)


class BlendedJointRun(Motion):
    """``movej`` through several joint positions with blends (radii already converted to joint space)."""

    kind = "movej"

    def __init__(self, q0: Arr, targets: Sequence[Arr], v: Sequence[float], a: Sequence[float],
                 joint_radii: Sequence[float]) -> None:
        pts = np.array([np.asarray(q0, dtype=float)] + [np.asarray(t, dtype=float) for t in targets])
        seg = pts[1:] - pts[:-1]
        lead = np.max(np.abs(seg), axis=1) / np.linalg.norm(seg, axis=1)   # leading joint per unit path length
        vmax = [float(v[k] / lead[k]) for k in range(len(seg))]
        amax = [float(a[k] / lead[k]) for k in range(len(seg))]
        self.curve = BlendedCurve(pts, joint_radii, vmax, amax)
        self.goal = pts[-1]
        self.t = 0.0
        self.segment = 1
        self.nseg = len(seg)

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        self.t += dt
        s, _v = self.curve.sample(self.t)
        if self.t >= self.curve.duration:
            self.done = True
            qn = self.goal.copy()
            self.segment = self.nseg
        else:
            qn, kind, k, _f = self.curve.locate(s)
            self.segment = k if kind == "line" else k + 1
        return qn, (qn - q) / dt if dt > 0 else np.zeros(6)


class PathMove(Motion):
    """Command 45: the injected path, checked and planned at construction (raises ScriptRuntimeError naming the
    waypoint, before anything moves), then executed run after run. ``progress`` is the ``signal_async_progress``
    value of the waypoint being approached (-1 before the start)."""

    kind = "path"

    def __init__(self, kin: ArmKinematics, q0: Arr, entries: Sequence[PathEntry]) -> None:
        self.kin = kin
        self.entries = list(entries)
        self.progress = -1
        self.reported_progress = -1
        self.q_targets: List[Arr] = []
        self.poses: List[pin.SE3] = []
        self.runs: List[List[int]] = []
        self._current: Optional[Motion] = None
        self._run_index = 0
        self._run_start_q = np.asarray(q0, dtype=float).copy()
        self._plan(np.asarray(q0, dtype=float))
        self.done = not self.entries

    # -- planning -----------------------------------------------------------------------------------------------
    def _plan(self, q0: Arr) -> None:
        kin = self.kin
        prev_q = q0.copy()
        n = len(self.entries)
        for i, e in enumerate(self.entries):
            where = "path waypoint %d (%s)" % (i + 1, e.line[:70])
            for name, val in (("v", e.v), ("a", e.a)):
                if not (math.isfinite(val) and val > 0):
                    raise ScriptRuntimeError("%s: %s=%r must be a positive number" % (where, name, val))
            if not (math.isfinite(e.r) and e.r >= 0):
                raise ScriptRuntimeError("%s: blend radius r=%r must be >= 0" % (where, e.r))
            target = np.asarray(e.target, dtype=float)
            try:
                if e.is_pose:
                    pose = pose_to_se3(target)
                    q = np.asarray(kin.ik(target.tolist(), prev_q.tolist()))
                else:
                    q = target
                    if np.any(q < kin.lower) or np.any(q > kin.upper):
                        raise ScriptRuntimeError("%s: joint target %s outside the joint limits"
                                                 % (where, np.round(q, 4).tolist()))
                    pose = kin.fk_se3(q)
            except KinematicsError as exc:
                raise ScriptRuntimeError("%s: %s" % (where, exc))
            self.q_targets.append(q.copy())
            self.poses.append(pose)
            prev_q = q
        # blend radii against the TCP distances between consecutive waypoints (first: from the current TCP)
        tcp = [kin.fk_se3(q0).translation] + [p.translation for p in self.poses]
        seg = [float(np.linalg.norm(tcp[i + 1] - tcp[i])) for i in range(n)]
        run: List[int] = []
        for i, e in enumerate(self.entries):
            run.append(i)
            last = i == n - 1
            if not last and e.r > 0:
                half = min(seg[i], seg[i + 1]) / 2.0
                if e.r > half + 1e-12:
                    raise ScriptRuntimeError(
                        "path waypoint %d: blend radius %.4g m is larger than half of a neighbouring segment "
                        "(%.4g m and %.4g m long; allowed at most %.4g m)" % (i + 1, e.r, seg[i], seg[i + 1], half))
                if (e.kind in LINEAR_KINDS) != (self.entries[i + 1].kind in LINEAR_KINDS):
                    raise ScriptRuntimeError("path waypoint %d: blending from %s into %s is not emulated by the UR "
                                             "stand-in (use r=0 there)" % (i + 1, e.kind, self.entries[i + 1].kind))
            if last or e.r <= 0:
                self.runs.append(run)
                run = []
        self._joint_radii = {}
        for run in self.runs:
            if len(run) > 1 and self.entries[run[0]].kind == "movej":
                for i in run[:-1]:
                    self._joint_radii[i] = self._joint_blend(i, q0)

    def _joint_blend(self, i: int, q0: Arr) -> float:
        """Joint-space distance from waypoint i at which the TCP is r away from the waypoint's TCP (both sides)."""
        r = self.entries[i].r
        w = self.q_targets[i]
        before = self.q_targets[i - 1] if i > 0 else q0
        after = self.q_targets[i + 1]
        tcp_w = self.kin.fk_se3(w).translation
        out = []
        for other in (before, after):
            d = other - w

            def dist(f: float) -> float:
                return float(np.linalg.norm(self.kin.fk_se3(w + d * f).translation - tcp_w))
            lo, hi = 0.0, None
            for f in np.linspace(0.0, 0.5, 33)[1:]:
                if dist(f) >= r:
                    hi = float(f)
                    break
                lo = float(f)
            if hi is None:
                raise ScriptRuntimeError("path waypoint %d: blend radius %.4g m is larger than the TCP gets from the "
                                         "waypoint within half of a neighbouring joint move" % (i + 1, r))
            for _ in range(30):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if dist(mid) < r else (lo, mid)
            out.append(hi * float(np.linalg.norm(d)))
        return min(out)

    # -- execution ----------------------------------------------------------------------------------------------
    def _start_run(self, q: Arr) -> Motion:
        run = self.runs[self._run_index]
        es = [self.entries[i] for i in run]
        if len(run) == 1:
            e, i = es[0], run[0]
            if e.kind == "movej":
                return JointMove(q, self.q_targets[i], e.v, e.a)
            return LinearMove(self.kin, q, self.poses[i], e.v, e.a)
        v = [e.v for e in es]
        a = [e.a for e in es]
        if es[0].kind == "movej":
            radii = [self._joint_radii[i] for i in run[:-1]]
            return BlendedJointRun(q, [self.q_targets[i] for i in run], v, a, radii)
        start = self.kin.fk_se3(q)
        return BlendedLinearRun(self.kin, start, [self.poses[i] for i in run], v, a, [e.r for e in es[:-1]])

    def step(self, dt: float, q: Arr, qd: Arr) -> Tuple[Arr, Arr]:
        if self.done:
            return q, np.zeros(6)
        if self._current is None:
            self._current = self._start_run(q)
        cur = self._current
        qn, qdn = cur.step(dt, q, qd)
        run = self.runs[self._run_index]
        seg = getattr(cur, "segment", 1)
        self.progress = self.entries[run[min(seg, len(run)) - 1]].progress
        if cur.done:
            self._current = None
            self._run_index += 1
            if self._run_index >= len(self.runs):
                self.done = True
                qdn = np.zeros(6)
            elif self.entries[run[-1]].r <= 0:
                qdn = np.zeros(6)           # stopped at the waypoint
        return qn, qdn
