"""Contact and force mode of the UR stand-in: a contact-surface provider, a stiff-spring contact force, and the
admittance control that ``force_mode`` (ur_rtde ``forceMode``, command 6) applies along the selected axes.

Contact provider (injected, e.g. by the worksite world, which knows the walls): a callable
``provider(tcp_pose) -> None | (depth, normal)`` taking the TCP pose ``[x, y, z, rx, ry, rz]`` in the UR base frame and
returning the penetration depth (m, > 0 inside the surface) and the surface's outward unit normal (base frame), or
None when the TCP touches nothing. :class:`PlaneContact` is one made of flat surfaces (usable across a process
pipe). The contact force on the tool is ``stiffness * depth * normal`` (N); ``actual_TCP_force`` reports it (base
frame axes, torques 0) minus the offset stored by ``zero_ftsensor()``: pressing the tool against a wall whose
outward normal is +x reads a positive Fx.

Force mode (type 2 only: the task frame is used as given): along every selected translational axis of the task
frame the TCP moves with the admittance velocity ``gain * (wrench_i - applied_i)``, limited by ``limits[i]`` (m/s),
where ``applied`` is the force the robot exerts on its environment (minus the contact force); ``gain`` is
``ADMITTANCE`` but never more than ``STABILITY / (stiffness * dt)``, so a stiff contact settles without ringing.
Along the other axes the running motion (movel, path, speedl ...) is followed unchanged. Lifecycle: created by
command 6 (re-sent parameters update it), ended by command 7 (``end_force_mode(); stopl(10)``), a protective or
emergency stop, or the end of the program.
"""
import math
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np

from .errors import ConfigurationError, ScriptRuntimeError
from .kinematics import pose_to_se3

ContactProvider = Callable[[Sequence[float]], Optional[Tuple[float, Sequence[float]]]]

DEFAULT_STIFFNESS = 20000.0      # N/m, a plasterboard wall against a sanding pad
ADMITTANCE = 0.01                # (m/s)/N in free space
STABILITY = 0.5                  # gain * stiffness * dt never above this
MAX_PLANES = 64


class PlaneContact:
    """Contact provider made of flat surfaces in the UR base frame: ``[{"point": [x, y, z], "normal": [nx, ny, nz]},
    ...]`` (normal pointing out of the solid, towards the robot). Optional ``"radius"`` (m) bounds a surface to a
    disc around its point. The deepest penetration wins."""

    def __init__(self, planes: Sequence[dict]) -> None:
        if len(planes) > MAX_PLANES:
            raise ConfigurationError("at most %d contact planes, got %d" % (MAX_PLANES, len(planes)))
        self.planes: List[Tuple[np.ndarray, np.ndarray, float]] = []
        for i, pl in enumerate(planes):
            try:
                point = np.asarray(pl["point"], dtype=float)
                normal = np.asarray(pl["normal"], dtype=float)
                radius = float(pl.get("radius", math.inf))
            except (KeyError, TypeError, ValueError):
                raise ConfigurationError("contact plane %d must be {'point': [x, y, z], 'normal': [nx, ny, nz]}, "
                                         "got %r" % (i + 1, pl))
            if point.shape != (3,) or normal.shape != (3,) or not (np.all(np.isfinite(point))
                                                                    and np.all(np.isfinite(normal))):
                raise ConfigurationError("contact plane %d: point and normal must be 3 finite numbers" % (i + 1))
            norm = float(np.linalg.norm(normal))
            if norm < 1e-9:
                raise ConfigurationError("contact plane %d: the normal must not be the zero vector" % (i + 1))
            if not radius > 0:
                raise ConfigurationError("contact plane %d: radius must be > 0 m" % (i + 1))
            self.planes.append((point, normal / norm, radius))

    def __call__(self, tcp_pose: Sequence[float]) -> Optional[Tuple[float, Sequence[float]]]:
        p = np.asarray(tcp_pose[:3], dtype=float)
        best: Optional[Tuple[float, Sequence[float]]] = None
        for point, normal, radius in self.planes:
            depth = float(np.dot(point - p, normal))
            if depth <= 0:
                continue
            lateral = (p - point) + depth * normal
            if float(np.linalg.norm(lateral)) > radius:
                continue
            if best is None or depth > best[0]:
                best = (depth, normal.tolist())
        return best


def contact_force(provider: Optional[ContactProvider], tcp_pose: Sequence[float], stiffness: float) -> np.ndarray:
    """Force (N, base frame) the environment exerts on the tool at ``tcp_pose``; zeros without contact."""
    if provider is None:
        return np.zeros(3)
    hit = provider(tcp_pose)
    if not hit:
        return np.zeros(3)
    depth, normal = hit
    n = np.asarray(normal, dtype=float)
    norm = float(np.linalg.norm(n))
    if not (depth > 0 and math.isfinite(depth) and norm > 1e-9):
        return np.zeros(3)
    return stiffness * float(depth) * n / norm


class ForceMode:
    """Parameters of one ``force_mode`` call and its admittance step (see the module docstring)."""

    def __init__(self, task_frame: Sequence[float], selection: Sequence[int], wrench: Sequence[float],
                 mode_type: int, limits: Sequence[float]) -> None:
        if mode_type not in (1, 2, 3):
            raise ScriptRuntimeError("force_mode: type must be 1, 2 or 3, got %r" % (mode_type,))
        if mode_type != 2:
            raise ScriptRuntimeError("force_mode: type %d is not emulated by the UR stand-in (type 2 only: the "
                                     "task frame is used as given)" % mode_type)
        sel = [int(s) for s in selection]
        if any(s not in (0, 1) for s in sel):
            raise ScriptRuntimeError("force_mode: selection vector entries must be 0 or 1, got %r" % (sel,))
        if any(sel[3:]):
            raise ScriptRuntimeError("force_mode: compliance about rotation axes (selection %r) is not emulated by "
                                     "the UR stand-in; select translation axes only" % (sel,))
        w = np.asarray(wrench, dtype=float)
        lim = np.asarray(limits, dtype=float)
        frame = np.asarray(task_frame, dtype=float)
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(lim)) and np.all(np.isfinite(frame))):
            raise ScriptRuntimeError("force_mode: task frame, wrench and limits must be finite numbers")
        self.sel = np.array(sel[:3], dtype=float)
        if np.any((lim[:3] <= 0) & (self.sel > 0)):
            raise ScriptRuntimeError("force_mode: the speed limit of a compliant axis must be > 0 m/s, got %r"
                                     % (lim[:3].tolist(),))
        self.rotation = pose_to_se3(frame).rotation
        self.force = w[:3]
        self.limits = lim[:3]
        self.selection = sel
        self.task_frame = frame.tolist()

    def step(self, applied: np.ndarray, dt: float, stiffness: float) -> np.ndarray:
        """TCP displacement (m, base frame) for one cycle of ``dt`` s, given the force the robot applies now."""
        applied_task = self.rotation.T @ applied
        gain = ADMITTANCE
        if stiffness > 0 and dt > 0:
            gain = min(gain, STABILITY / (stiffness * dt))
        v = np.clip(gain * (self.force - applied_task), -self.limits, self.limits) * self.sel
        return self.rotation @ (v * dt)

    def describe(self) -> dict:
        return {"task_frame": self.task_frame, "selection": self.selection, "wrench": self.force.tolist(),
                "limits": self.limits.tolist()}
