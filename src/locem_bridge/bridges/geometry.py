"""Rigid transforms for the bridges (numpy only): rotation vectors, RPY, planar poses and the arm base frame.

Frames (REP 103/105): ``map`` (z up), ``base_footprint`` (the mobile base on the floor), the arm's ``base_link``
at ``robot.arm.mount``, and the UR controller ``base`` frame (RTDE poses), which is ``base_link`` turned by pi
about z. Poses of the arm are ``[x, y, z, rx, ry, rz]`` with a rotation vector.
"""

import math
from typing import List, Sequence, Tuple

import numpy as np


def rotvec_to_matrix(rv: Sequence[float]) -> np.ndarray:
    rv = np.asarray(rv, dtype=float)
    angle = float(np.linalg.norm(rv))
    if angle < 1e-12:
        return np.eye(3)
    k = rv / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * kx.dot(kx)


def matrix_to_rotvec(m: np.ndarray) -> List[float]:
    m = np.asarray(m, dtype=float)
    cos = max(-1.0, min(1.0, (np.trace(m) - 1.0) / 2.0))
    angle = math.acos(cos)
    if angle < 1e-9:
        return [0.0, 0.0, 0.0]
    if math.pi - angle < 1e-6:
        # axis from the symmetric part: R = 2 k k^T - I
        k = np.sqrt(np.maximum((np.diag(m) + 1.0) / 2.0, 0.0))
        i = int(np.argmax(k))
        for j in range(3):
            if j != i:
                k[j] = math.copysign(k[j], m[i, j] + m[j, i])
        return list(k / np.linalg.norm(k) * angle)
    axis = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / (2.0 * math.sin(angle))
    return list(axis * angle)


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def transform(rotation: np.ndarray, translation: Sequence[float]) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rotation
    t[:3, 3] = translation
    return t


def planar(x: float, y: float, yaw: float) -> np.ndarray:
    """``map <- base_footprint`` for a planar pose."""
    return transform(rpy_to_matrix(0.0, 0.0, yaw), [x, y, 0.0])


def invert(t: np.ndarray) -> np.ndarray:
    r = t[:3, :3].T
    return transform(r, -r.dot(t[:3, 3]))


def pose_to_matrix(pose: Sequence[float]) -> np.ndarray:
    return transform(rotvec_to_matrix(pose[3:6]), pose[0:3])


def matrix_to_pose(t: np.ndarray) -> List[float]:
    return [float(v) for v in t[:3, 3]] + [float(v) for v in matrix_to_rotvec(t[:3, :3])]


def wrap_angle(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def arm_base_in_footprint(mount_xyz: Sequence[float], mount_rpy: Sequence[float]) -> np.ndarray:
    """``base_footprint <- UR base``: the mount of ``base_link``, then pi about z."""
    return transform(rpy_to_matrix(*mount_rpy), mount_xyz).dot(transform(rpy_to_matrix(0.0, 0.0, math.pi),
                                                                           [0.0, 0.0, 0.0]))


def tool_frame_facing(point: Sequence[float], normal: Sequence[float]) -> np.ndarray:
    """A TCP frame at ``point`` whose z axis points INTO the surface (against ``normal``), x axis horizontal."""
    n = np.asarray(normal, dtype=float)
    norm = float(np.linalg.norm(n))
    if norm < 1e-9:
        raise ValueError("the surface normal must not be zero")
    z = -n / norm
    x = np.cross([0.0, 0.0, 1.0], z)
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return transform(np.column_stack([x, y, z]), point)


def distance(a: Sequence[float], b: Sequence[float]) -> float:
    return float(np.linalg.norm(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))


def angle_between(pose_a: Sequence[float], pose_b: Sequence[float]) -> float:
    """Rotation angle between the orientations of two rotation-vector poses."""
    r = rotvec_to_matrix(pose_a[3:6]).T.dot(rotvec_to_matrix(pose_b[3:6]))
    return math.acos(max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0)))


def split(points: Tuple[float, ...], n: int) -> List[List[float]]:
    return [list(points[i:i + n]) for i in range(0, len(points), n)]
