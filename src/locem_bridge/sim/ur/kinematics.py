"""Forward and inverse kinematics of the emulated arm, with pinocchio, in UR conventions.

Poses are UR poses ``[x, y, z, rx, ry, rz]`` (metres, rotation vector) of the TCP in the UR *base* frame (the URDF
link ``base``, rotated by pi about z with respect to ``base_link``), the flange is the URDF link ``tool0`` and the
TCP is the flange composed with the TCP offset set by ``set_tcp`` (also a UR pose).

The model comes from the ``example-robot-data`` package: ``ur10``, ``ur5``, ``ur3`` as shipped, and ``ur10e`` /
``ur5e`` (default ``ur10e``), which the package does not ship, derived from the CB-series URDF of the same size with
the e-Series DH geometry and joint limits (:func:`e_series_urdf_xml`); or from any URDF path with ``base`` and
``tool0`` links.
Instances are not thread-safe (one pinocchio ``Data`` each); the controller uses its own instance from its control
thread.
"""
import os
from typing import List, Optional, Sequence

import numpy as np
import pinocchio as pin

from .errors import ConfigurationError, KinematicsError

_ERD_MODELS = {
    "ur10": "robots/ur_description/urdf/ur10_robot.urdf",
    "ur5": "robots/ur_description/urdf/ur5_robot.urdf",
    "ur3": "robots/ur_description/urdf/ur3_robot.urdf",
}


def _erd_share_dirs() -> List[str]:
    """Candidate ``share/example-robot-data`` folders (pip/cmeel wheel, then system installs)."""
    dirs = []
    env = os.environ.get("EXAMPLE_ROBOT_DATA_DIR")
    if env:
        dirs.append(env)
    for p in (os.path.dirname(pin.__file__),):
        # pip wheels: <site-packages>/cmeel.prefix/share/example-robot-data
        site = p
        for _ in range(6):
            cand = os.path.join(site, "cmeel.prefix", "share", "example-robot-data")
            if os.path.isdir(cand):
                dirs.append(cand)
                break
            site = os.path.dirname(site)
    dirs += ["/opt/openrobots/share/example-robot-data", "/usr/share/example-robot-data",
             "/opt/ros/noetic/share/example-robot-data"]
    return dirs


#: e-Series geometry (UR DH parameters d1, a2, a3, d4, d5, d6 in m) and joint limits, applied to the example-robot-data
#: CB-series URDF of the same size (whose meshes stay: they are visual only).
E_SERIES = {
    "ur10e": {"base": "ur10", "d1": 0.1807, "a2": 0.6127, "a3": 0.57155, "d4": 0.17415, "d5": 0.11985,
              "d6": 0.11655, "shoulder_offset": 0.176, "elbow_offset": 0.137,
              "velocity": (2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416),
              "effort": (330.0, 330.0, 150.0, 56.0, 56.0, 56.0)},
    "ur5e": {"base": "ur5", "d1": 0.1625, "a2": 0.425, "a3": 0.3922, "d4": 0.1333, "d5": 0.0997, "d6": 0.0996,
             "shoulder_offset": 0.138, "elbow_offset": 0.131,
             "velocity": (3.1416,) * 6, "effort": (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)},
}


def e_series_urdf_xml(model: str) -> str:
    """URDF text of an e-Series arm (``ur10e``, ``ur5e``): the CB-series URDF with e-Series joint origins/limits.

    The UR base frame, ``tool0`` and the joint axes are those of the UR description; the world can load the same
    text so that the PyBullet arm and the stand-in's kinematics agree.
    """
    import xml.etree.ElementTree as ET
    g = E_SERIES[model]
    root = ET.parse(resolve_model_path(g["base"])).getroot()
    wrist2_y = g["d4"] - g["shoulder_offset"] + g["elbow_offset"]
    origins = {
        "shoulder_pan_joint": (0.0, 0.0, g["d1"]),
        "shoulder_lift_joint": (0.0, g["shoulder_offset"], 0.0),
        "elbow_joint": (0.0, -g["elbow_offset"], g["a2"]),
        "wrist_1_joint": (0.0, 0.0, g["a3"]),
        "wrist_2_joint": (0.0, wrist2_y, 0.0),
        "wrist_3_joint": (0.0, 0.0, g["d5"]),
        "ee_fixed_joint": (0.0, g["d6"], 0.0),
        "wrist_3_link-tool0_fixed_joint": (0.0, g["d6"], 0.0),
    }
    order = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
             "wrist_3_joint"]
    for joint in root.findall("joint"):          # not the <transmission><joint> references
        name = joint.get("name")
        if name in origins:
            joint.find("origin").set("xyz", "%r %r %r" % origins[name])
        if name in order:
            lim = joint.find("limit")
            if lim is not None:
                i = order.index(name)
                lim.set("velocity", repr(g["velocity"][i]))
                lim.set("effort", repr(g["effort"][i]))
    root.set("name", model)
    return ET.tostring(root, encoding="unicode")


def resolve_model_path(model: str) -> str:
    """Turn a model name (``ur10``, ``ur5``, ``ur3``) or a URDF path into an existing URDF path."""
    if model.endswith(".urdf"):
        if not os.path.isfile(model):
            raise ConfigurationError("URDF file %r does not exist" % model)
        return model
    key = model.lower()
    if key not in _ERD_MODELS:
        raise ConfigurationError("unknown arm model %r: use one of %s or a path to a URDF file"
                                 % (model, sorted(list(_ERD_MODELS) + list(E_SERIES))))
    for d in _erd_share_dirs():
        path = os.path.join(d, _ERD_MODELS[key])
        if os.path.isfile(path):
            return path
    raise ConfigurationError("URDF for %r not found: install the example-robot-data package or set "
                             "EXAMPLE_ROBOT_DATA_DIR" % model)


def pose_to_se3(pose: Sequence[float]) -> pin.SE3:
    """UR pose [x, y, z, rx, ry, rz] -> pinocchio SE3."""
    p = np.asarray(pose, dtype=float)
    return pin.SE3(pin.exp3(p[3:6]), p[0:3].copy())


def se3_to_pose(m: pin.SE3) -> List[float]:
    """pinocchio SE3 -> UR pose with the rotation vector angle in [0, pi]."""
    r = pin.log3(m.rotation)
    return [float(m.translation[0]), float(m.translation[1]), float(m.translation[2]),
            float(r[0]), float(r[1]), float(r[2])]


class ArmKinematics:
    """FK / IK of one arm model. ``tcp`` is the current TCP offset (UR pose) used when none is given."""

    def __init__(self, model: str = "ur10e") -> None:
        try:
            if model.lower() in E_SERIES:
                self.urdf_path = "%s (e-Series geometry on %s)" % (model, resolve_model_path(
                    E_SERIES[model.lower()]["base"]))
                self.model = pin.buildModelFromXML(e_series_urdf_xml(model.lower()))
            else:
                self.urdf_path = resolve_model_path(model)
                self.model = pin.buildModelFromUrdf(self.urdf_path)
        except ConfigurationError:
            raise
        except Exception as exc:  # pinocchio raises plain RuntimeError/ValueError
            raise ConfigurationError("cannot load arm model %r: %s" % (model, exc))
        if self.model.nq != 6 or self.model.nv != 6:
            raise ConfigurationError("arm model %r must have 6 revolute joints (nq=%d, nv=%d)"
                                     % (self.urdf_path, self.model.nq, self.model.nv))
        self.data = self.model.createData()
        for frame in ("base", "tool0"):
            if not self.model.existFrame(frame):
                raise ConfigurationError("URDF %r has no %r link" % (self.urdf_path, frame))
        self._fid_base = self.model.getFrameId("base")
        self._fid_tool = self.model.getFrameId("tool0")
        self.joint_names = [self.model.names[i] for i in range(1, self.model.njoints)]
        self.lower = np.array(self.model.lowerPositionLimit, dtype=float)
        self.upper = np.array(self.model.upperPositionLimit, dtype=float)
        self.velocity_limit = np.array(self.model.velocityLimit, dtype=float)
        pin.framesForwardKinematics(self.model, self.data, pin.neutral(self.model))
        self._base_inv = self.data.oMf[self._fid_base].inverse()
        self.tcp = pin.SE3.Identity()

    # --- TCP offset --------------------------------------------------------------------------------------------
    def set_tcp(self, pose: Sequence[float]) -> None:
        self.tcp = pose_to_se3(pose)

    def tcp_pose(self) -> List[float]:
        return se3_to_pose(self.tcp)

    # --- forward kinematics ------------------------------------------------------------------------------------
    def flange_se3(self, q: Sequence[float]) -> pin.SE3:
        """Placement of ``tool0`` in the UR base frame."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self._base_inv * self.data.oMf[self._fid_tool]

    def fk_se3(self, q: Sequence[float], tcp: Optional[pin.SE3] = None) -> pin.SE3:
        return self.flange_se3(q) * (self.tcp if tcp is None else tcp)

    def fk(self, q: Sequence[float], tcp_pose: Optional[Sequence[float]] = None) -> List[float]:
        """TCP pose for joint positions ``q`` (TCP offset ``tcp_pose`` or the current one)."""
        tcp = None if tcp_pose is None else pose_to_se3(tcp_pose)
        return se3_to_pose(self.fk_se3(q, tcp))

    def elbow_position(self) -> List[float]:
        """Position of the elbow joint (forearm origin) in the base frame, from the last FK call."""
        m = self._base_inv * self.data.oMi[3]
        return [float(v) for v in m.translation]

    # --- inverse kinematics ------------------------------------------------------------------------------------
    def ik_se3(self, target: pin.SE3, seed: Sequence[float], tcp: Optional[pin.SE3] = None,
               max_iter: int = 200, tol: float = 1e-10) -> Optional[np.ndarray]:
        """Damped least-squares IK from ``seed``; returns q or None when it does not converge."""
        tcp = self.tcp if tcp is None else tcp
        q = np.array(seed, dtype=float)
        model, data = self.model, self.data
        target_flange = target * tcp.inverse()
        for _ in range(max_iter):
            cur = self.flange_se3(q)
            err_m = cur.inverse() * target_flange
            err = pin.log6(err_m).vector
            if float(err.dot(err)) < tol * tol:
                return q
            jac = pin.computeFrameJacobian(model, data, q, self._fid_tool, pin.LOCAL)
            lam = 1e-10 if float(err.dot(err)) < 1e-4 else 1e-6
            dq = np.linalg.solve(jac.T @ jac + lam * np.eye(6), jac.T @ err)
            step = float(np.max(np.abs(dq)))
            if step > 0.5:
                dq *= 0.5 / step
            q = q + dq
        return None

    def ik(self, pose: Sequence[float], qnear: Sequence[float], tcp_pose: Optional[Sequence[float]] = None,
           max_position_error: float = 1e-10, max_orientation_error: float = 1e-10) -> List[float]:
        """Joint positions reaching ``pose`` nearest to ``qnear`` (tries several seeds, keeps the closest).

        Raises :class:`KinematicsError` when no solution exists within joint limits.
        """
        tcp = None if tcp_pose is None else pose_to_se3(tcp_pose)
        target = pose_to_se3(pose)
        qn = np.asarray(qnear, dtype=float)
        seeds = [qn]
        for d in ((0, 0, 0, 0, 0, 0.0), (0, 0.4, -0.4, 0, 0, 0), (0, -0.4, 0.4, 0, 0, 0)):
            seeds.append(qn + np.asarray(d))
        for base in ((0.0, -1.57, 1.57, -1.57, -1.57, 0.0), (0.0, -1.57, -1.57, -1.57, 1.57, 0.0),
                     (3.14, -1.57, 1.57, -1.57, -1.57, 0.0), (0.0, -0.5, 1.0, -2.0, -1.57, 0.0)):
            seeds.append(np.asarray(base))
        best = None
        best_dist = float("inf")
        for s in seeds:
            q = self.ik_se3(target, s, tcp)
            if q is None:
                continue
            # bring each joint to the 2*pi branch nearest to qnear, within limits
            q = qn + np.remainder(q - qn + np.pi, 2 * np.pi) - np.pi
            if np.any(q < self.lower - 1e-9) or np.any(q > self.upper + 1e-9):
                continue
            d = float(np.max(np.abs(q - qn)))
            if d < best_dist:
                best, best_dist = q, d
            if d < 1e-3 or s is seeds[0]:
                break
        if best is None:
            raise KinematicsError("no inverse kinematics solution for pose %s" % ([round(v, 6) for v in pose],))
        return [float(v) for v in best]
