"""The bridges' frames (numpy only): planar poses, the arm base frame, the wall-facing TCP frame.

Angles, rotations and rigid transforms every layer uses live in :mod:`locem_bridge.common.geometry`.

Frames (REP 103/105): ``map`` (z up), ``base_footprint`` (the mobile base on the floor), the arm's ``base_link``
at ``robot.arm.mount``, and the UR controller ``base`` frame (RTDE poses), which is ``base_link`` turned by pi
about z. Poses of the arm are ``[x, y, z, rx, ry, rz]`` with a rotation vector.
"""

import math
from typing import List, Sequence, Tuple

import numpy as np

from locem_bridge.common.geometry import rotation_z_along, rpy_to_matrix, transform


def planar(x: float, y: float, yaw: float) -> np.ndarray:
    """``map <- base_footprint`` for a planar pose."""
    return transform(rpy_to_matrix(0.0, 0.0, yaw), [x, y, 0.0])


def arm_base_in_footprint(mount_xyz: Sequence[float], mount_rpy: Sequence[float]) -> np.ndarray:
    """``base_footprint <- UR base``: the mount of ``base_link``, then pi about z."""
    return transform(rpy_to_matrix(*mount_rpy), mount_xyz).dot(transform(rpy_to_matrix(0.0, 0.0, math.pi),
                                                                           [0.0, 0.0, 0.0]))


def tool_frame_facing(point: Sequence[float], normal: Sequence[float]) -> np.ndarray:
    """A TCP frame at ``point`` whose z axis points INTO the surface (against ``normal``), x axis horizontal."""
    n = np.asarray(normal, dtype=float)
    if float(np.linalg.norm(n)) < 1e-9:
        raise ValueError("the surface normal must not be zero")
    return transform(rotation_z_along(-n), point)


def distance(a: Sequence[float], b: Sequence[float]) -> float:
    return float(np.linalg.norm(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))


def split(points: Tuple[float, ...], n: int) -> List[List[float]]:
    return [list(points[i:i + n]) for i in range(0, len(points), n)]
