"""The one definition of angles and rotations: wrapping, rotation vector <-> matrix <-> quaternion, RPY, rigid
transforms, checked against independent constructions (axis-angle by hand, numpy's own algebra)."""
import math

import numpy as np
import pytest

from locem_bridge.common.geometry import (angle_between, invert, matrix_to_pose, matrix_to_quat, matrix_to_rotvec,
                                          pose_to_matrix, quat_to_rotvec, rotvec_to_matrix, rotvec_to_quat,
                                          rotation_z_along, rpy_to_matrix, wrap_angle)

ROTVECS = [[0, 0, 0], [0.1, -0.2, 0.3], [0, math.pi, 0], [2.2214, -2.2214, 0], [0, 0, -3.1], [1e-13, 0, 0]]


@pytest.mark.parametrize("a, wrapped", [(0.0, 0.0), (math.pi / 2, math.pi / 2), (3 * math.pi / 2, -math.pi / 2),
                                        (-3 * math.pi / 2, math.pi / 2), (7.0, 7.0 - 2 * math.pi),
                                        (math.pi, -math.pi), (-math.pi, -math.pi), (20 * math.pi + 0.25, 0.25)])
def test_wrap_angle_maps_into_minus_pi_to_pi(a, wrapped):
    assert wrap_angle(a) == pytest.approx(wrapped, abs=1e-9)


def test_wrap_angle_works_on_arrays_as_on_numbers():
    angles = np.array([-7.0, -math.pi, 0.3, math.pi, 9.0])
    assert np.allclose(wrap_angle(angles), [wrap_angle(float(a)) for a in angles])
    assert np.all((wrap_angle(angles) >= -math.pi) & (wrap_angle(angles) < math.pi))


@pytest.mark.parametrize("rv", ROTVECS)
def test_rotation_vector_matrix_and_quaternion_agree(rv):
    m = rotvec_to_matrix(rv)
    assert np.allclose(m.T.dot(m), np.eye(3), atol=1e-9) and np.linalg.det(m) == pytest.approx(1.0)
    assert np.allclose(rotvec_to_matrix(matrix_to_rotvec(m)), m, atol=1e-6)
    q = rotvec_to_quat(rv)
    assert sum(c * c for c in q) == pytest.approx(1.0)
    assert np.allclose(rotvec_to_matrix(quat_to_rotvec(q)), m, atol=1e-6)
    q2 = matrix_to_quat(m)
    assert np.allclose(q2, q, atol=1e-6) or np.allclose(q2, [-c for c in q], atol=1e-6)   # q and -q: one rotation


def test_a_rotation_vector_turns_about_its_axis_by_its_length():
    m = rotvec_to_matrix([0.0, 0.0, math.pi / 2])
    assert np.allclose(m.dot([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-12)
    assert np.allclose(rpy_to_matrix(0.0, 0.0, math.pi / 2), m, atol=1e-12)
    assert np.allclose(rpy_to_matrix(0.3, -0.2, 1.1),                     # z(yaw) . y(pitch) . x(roll)
                       rotvec_to_matrix([0, 0, 1.1]).dot(rotvec_to_matrix([0, -0.2, 0])).dot(
                           rotvec_to_matrix([0.3, 0, 0])), atol=1e-12)


def test_poses_transforms_and_the_angle_between_two_orientations():
    pose = [0.1, -0.2, 0.3, 0.0, 3.0, 0.0]
    t = pose_to_matrix(pose)
    assert np.allclose(invert(t).dot(t), np.eye(4), atol=1e-12)
    assert np.allclose(matrix_to_pose(t), pose, atol=1e-9)
    assert angle_between(pose, [0, 0, 0, 0.0, 3.0, 0.0]) == pytest.approx(0.0, abs=1e-6)
    assert angle_between([0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0.4]) == pytest.approx(0.4)


@pytest.mark.parametrize("z_axis", [[0, 1, 0], [0.3, -0.8, 0.2], [0, 0, 1], [0, 0, -2.0], [-1, 0, 0]])
def test_a_frame_along_an_axis_keeps_its_x_axis_horizontal(z_axis):
    r = rotation_z_along(z_axis)
    assert np.allclose(r.T.dot(r), np.eye(3), atol=1e-12) and np.linalg.det(r) == pytest.approx(1.0)
    assert np.allclose(r[:, 2], np.asarray(z_axis, float) / np.linalg.norm(z_axis))
    assert abs(r[2, 0]) < 1e-12                                        # x horizontal
    with pytest.raises(ValueError, match="must not be zero"):
        rotation_z_along([0, 0, 0])


def test_no_module_outside_common_wraps_angles_or_converts_rotations_again():
    """The angle and rotation helpers have one definition: a function of that name elsewhere, or the wrapping
    idiom written out, fails here."""
    import ast
    import os
    import re
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")
    names = {"wrap_angle", "rotvec_to_matrix", "matrix_to_rotvec", "rpy_to_matrix", "rotvec_to_quat",
             "quat_to_rotvec", "matrix_to_quat", "rotation_z_along", "pose_to_matrix", "matrix_to_pose", "invert"}
    idiom = re.compile(r"%\s*\(?\s*2(\.0)?\s*\*\s*(math|np)\.pi|atan2\((math|np)\.sin\(")
    offenders = []
    for folder, _, files in os.walk(os.path.join(src, "locem_bridge")):
        for name in files:
            path = os.path.join(folder, name)
            if not name.endswith(".py") or path.endswith(os.path.join("common", "geometry.py")):
                continue
            text = open(path, encoding="utf-8").read()
            offenders += ["%s:%d def %s" % (os.path.relpath(path, src), n.lineno, n.name)
                          for n in ast.walk(ast.parse(text, path))
                          if isinstance(n, ast.FunctionDef) and n.name.lstrip("_") in names]
            offenders += ["%s: %s" % (os.path.relpath(path, src), m.group(0)) for m in idiom.finditer(text)]
    assert not offenders, "angle / rotation helpers defined outside locem_bridge.common.geometry: %s" % offenders
