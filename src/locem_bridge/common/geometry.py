"""Angles and rotations, defined once (numpy only): the bridges, the simulated worksite and HICEM's nodes use these.

Conventions: angles in rad; :func:`wrap_angle` maps to [-pi, pi). A pose is ``[x, y, z, rx, ry, rz]`` with a
rotation vector (UR's convention, the RTDE poses); a quaternion is ``(x, y, z, w)`` (PyBullet's order); a
transform is a 4x4 homogeneous matrix; ``rpy`` is roll, pitch, yaw about the fixed x, y, z axes (URDF).
"""

import math
from typing import Any, List, Sequence, Tuple

import numpy as np

Quaternion = Tuple[float, float, float, float]


def wrap_angle(a: Any) -> Any:
    """``a`` (a number or a numpy array) wrapped to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def rotvec_to_matrix(rv: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis times angle), Rodrigues' formula."""
    rv = np.asarray(rv, dtype=float)
    angle = float(np.linalg.norm(rv))
    if angle < 1e-12:
        return np.eye(3)
    k = rv / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * kx.dot(kx)


def matrix_to_rotvec(m: np.ndarray) -> List[float]:
    """Rotation vector of a rotation matrix, angle in [0, pi]."""
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
    """Rotation matrix of roll, pitch, yaw (about the fixed x, then y, then z axis)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def rotvec_to_quat(rv: Sequence[float]) -> Quaternion:
    """Quaternion ``(x, y, z, w)`` of a rotation vector."""
    rv = np.asarray(rv, dtype=float)
    angle = float(np.linalg.norm(rv))
    if angle < 1e-12:
        return (0.0, 0.0, 0.0, 1.0)
    axis = rv / angle
    s = math.sin(angle / 2.0)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2.0))


def quat_to_rotvec(q: Sequence[float]) -> List[float]:
    """Rotation vector (angle in [0, pi]) of a unit quaternion ``(x, y, z, w)``."""
    x, y, z, w = q
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(max(0.0, 1.0 - w * w))
    angle = 2.0 * math.atan2(s, w)
    if s < 1e-12:
        return [0.0, 0.0, 0.0]
    return [x / s * angle, y / s * angle, z / s * angle]


def matrix_to_quat(m: np.ndarray) -> Quaternion:
    """Quaternion ``(x, y, z, w)`` of a rotation matrix."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k]) * 2
    q = [0.0, 0.0, 0.0, 0.0]
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    q[3] = (m[k, j] - m[j, k]) / s
    return (q[0], q[1], q[2], q[3])


def rotation_z_along(z_axis: Sequence[float]) -> np.ndarray:
    """Rotation matrix whose z axis points along ``z_axis`` and whose x axis is horizontal (the TCP frame a tool
    takes against a wall; x along the world x axis when ``z_axis`` is vertical). A zero ``z_axis`` raises
    ``ValueError``."""
    z = np.asarray(z_axis, dtype=float)
    norm = float(np.linalg.norm(z))
    if norm < 1e-9:
        raise ValueError("the z axis must not be zero, got %r" % (list(z_axis),))
    z = z / norm
    x = np.cross([0.0, 0.0, 1.0], z)
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x = x / np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def transform(rotation: np.ndarray, translation: Sequence[float]) -> np.ndarray:
    """4x4 transform of a rotation matrix and a translation."""
    t = np.eye(4)
    t[:3, :3] = rotation
    t[:3, 3] = translation
    return t


def invert(t: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform."""
    r = t[:3, :3].T
    return transform(r, -r.dot(t[:3, 3]))


def pose_to_matrix(pose: Sequence[float]) -> np.ndarray:
    """4x4 transform of a rotation-vector pose ``[x, y, z, rx, ry, rz]``."""
    return transform(rotvec_to_matrix(pose[3:6]), pose[0:3])


def matrix_to_pose(t: np.ndarray) -> List[float]:
    """Rotation-vector pose ``[x, y, z, rx, ry, rz]`` of a 4x4 transform."""
    return [float(v) for v in t[:3, 3]] + [float(v) for v in matrix_to_rotvec(t[:3, :3])]


def angle_between(pose_a: Sequence[float], pose_b: Sequence[float]) -> float:
    """Rotation angle (rad, 0..pi) between the orientations of two rotation-vector poses."""
    r = rotvec_to_matrix(pose_a[3:6]).T.dot(rotvec_to_matrix(pose_b[3:6]))
    return math.acos(max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0)))
