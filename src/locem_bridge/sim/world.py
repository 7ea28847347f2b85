"""The PyBullet worksite: room, plasterboard walls, the mobile manipulator and its tools.

Lifecycle: ``World(site_cfg, robot_cfg, clock, arm=..., drives=..., compressor=...)`` builds the scene
(``gui=False`` -> DIRECT) -> :meth:`step` advances it to ``clock()`` (called by :meth:`start`'s loop at
``simulation.world_rate`` wall Hz, or by hand in tests) -> :meth:`close`. All PyBullet calls happen under one
lock, so public methods are safe from any thread.

What one step does:
1. base: wheel angle increments of the CAN drives (:class:`~locem_bridge.sim.can.drives.DriveSet`) through the
   base kinematics (``robot.base.kind``: mecanum or differential, :mod:`locem_bridge.common.base_kinematics`) move ``base_footprint`` in the map frame (kinematic body, no slip); the increments are
   taken from the drives' exact motion segments every ``BASE_SUBSTEP`` of sim time since the last step, so the
   ground truth does not depend on the time scale or on a late step (one world step at time scale 20 covers
   0.4 s of sim time, and the midpoint rule over such steps drifted by millimetres per GOTO);
   With a lift (``robot.lift``), the arm's mount follows the lift drive's position (``lift=``, a
   :class:`~locem_bridge.sim.can.drives.Cia402PositionDrive`): mount z = ``robot.lift.range[0]`` + axis position;
   :meth:`lift_height` reports it;
2. arm: joint positions mirrored from the arm source (:mod:`.arm_source`; the UR stand-in when running),
   including every intermediate controller step delivered to the step listener since the last step;
3. tool: the mounted tool follows ``tool0``; its process state comes from the configured switch (UR standard
   digital output, or the compressor's spray valve + pressure in range);
4. outcome: TCP samples go to :class:`~locem_bridge.sim.outcome.OutcomeRecorder` (tape, spray, sand maps);
5. collisions: base/pedestal and arm links against walls (tools may touch walls: that is their job); a new
   contact increments ``collisions`` and is logged; ``on_collision`` callbacks run (e.g. protective stop).

Arm geometry: the URDF of the ``example-robot-data`` package (UR description meshes), placed at
``robot.arm.mount`` on the base. The UR controller ``base`` frame (RTDE poses) is ``base_link`` turned by pi
about z; :meth:`arm_base_pose` returns it.
"""
from __future__ import annotations

import logging
import math
import os
import shutil
import tempfile
import threading
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Optional, Sequence, Tuple

import numpy as np
import pybullet as pb

from .clock import SimClock
from ..robot_file import TOOL_NAMES
from .config import find_example_robot_data, resolve_arm_urdf  # noqa: F401 (re-exported)
from .errors import SimConfigError, SimStateError
from ..common.geometry import matrix_to_quat, quat_to_rotvec, rotation_z_along, rotvec_to_quat
from ..common.base_kinematics import kinematics_for
from ..common.rate import FixedRate
from .outcome import OutcomeRecorder
from .perception import WallScanner
from .site import Site, Wall

log = logging.getLogger(__name__)

BASE_SUBSTEP = 0.01    # sim s: the base pose is integrated through wheel angles at most this far apart
SAMPLE_QUEUE = 30000   # arm controller samples waiting for the world's step, at most (60 s wall at 500 Hz)



def wall_boxes(wall: Wall) -> List[Tuple[float, float, float, float]]:
    """``(s0, s1, t0, t1)`` rectangles (wall coordinates) that make up ``wall`` around its clear door and window
    openings (frames are wall): full-height strips between the openings, and below / above each opening."""
    cuts = sorted(wall.openings, key=lambda o: o.s0)
    out: List[Tuple[float, float, float, float]] = []
    s = 0.0
    for o in cuts:
        if o.s0 > s + 1e-9:
            out.append((s, o.s0, 0.0, wall.height))
        if o.t0 > 1e-9:
            out.append((o.s0, o.s1, 0.0, o.t0))
        if o.t1 < wall.height - 1e-9:
            out.append((o.s0, o.s1, o.t1, wall.height))
        s = o.s1
    if wall.length > s + 1e-9:
        out.append((s, wall.length, 0.0, wall.height))
    return out

class World:
    """The simulated worksite in PyBullet (see the module docstring)."""

    def __init__(self, site_cfg: Dict[str, Any], robot_cfg: Dict[str, Any], clock: Optional[SimClock] = None,
                 arm: Any = None, drives: Any = None, compressor: Any = None, gui: Optional[bool] = None,
                 lift: Any = None) -> None:
        self.site_cfg, self.robot_cfg = site_cfg, robot_cfg
        sim = site_cfg["simulation"]
        robot = robot_cfg["robot"]
        self.clock = clock or SimClock(sim["time_scale"])
        self.site = Site(site_cfg)
        self.arm_source = arm
        self.drives = drives
        self.compressor = compressor
        self.rate = float(sim["world_rate"])
        self.robot = robot
        self.tools_cfg = robot["tools"]
        self.kinematics = kinematics_for(robot["base"].get("kind", "mecanum"), robot["base"]["wheel"])
        self.lift = lift
        self._lift_bottom = float(robot["lift"]["range"][0]) if "lift" in robot else 0.0
        self._mount_z = float(robot["arm"]["mount"]["xyz"][2])      # arm mount height now (moves with a lift)
        if lift is not None:
            self._mount_z = self._lift_bottom + float(lift.angle)
        self.outcome = OutcomeRecorder(self.site, self.tools_cfg, sim["outcome"], clock=self.clock.now)
        # the scanner reports each area's finish (bare / sprayed / sanded) from what the outcome recorded
        self.scanner = WallScanner(self.site, robot["scanner"], sim["perception"]["position_noise"], sim["seed"],
                                   outcome=self.outcome)
        self._lock = threading.RLock()
        self._gui = sim["gui"] if gui is None else bool(gui)
        self._cid = pb.connect(pb.GUI if self._gui else pb.DIRECT)
        self._tmp = tempfile.mkdtemp(prefix="locem_world_")
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self.collisions = 0
        self.collision_log: List[Dict[str, Any]] = []
        self._contacts: set = set()
        self.on_collision: List[Callable[[Dict[str, Any]], None]] = []
        self.mounted_tool: Optional[str] = None
        self.steps = 0
        # arm samples (joint positions, tool process on at that moment) from the controller's step listener
        # and their numbers in the state journal (None: not journaled)
        # (at most SAMPLE_QUEUE: a minute of a 500 Hz controller; should the world's thread fall that far behind,
        # the oldest are dropped and the drop is logged with how many)
        self._samples: Deque[Tuple[List[float], bool, float, Optional[int]]] = deque(maxlen=SAMPLE_QUEUE)
        self.samples_dropped = 0
        #: journals the samples while a tool is mounted and what the world recorded of them (a
        #: :class:`~locem_bridge.sim.world_state.WorldState`; set by the worksite), None: not kept
        self.sample_journal: Any = None
        self._last_sample: Optional[List[float]] = None
        self._motion_anchor: Optional[float] = None      # world time - controller motion time (_sample_time)
        self._arm_clock: Optional[float] = None          # the latest sample's time on that line (every tick)
        # map <- UR controller base as (rotation, origin), set by _place_robot (from _build on), read by
        # arm_base_pose and, on the controller's thread, wall_contact
        self._ur_base_in_map: Optional[Tuple[np.ndarray, np.ndarray]] = None
        self._t = self.clock.now()
        x, y, yaw = self.site.robot_start
        self._pose = [float(x), float(y), float(yaw)]
        self._q = list(arm.joint_positions()) if arm is not None else list(
            robot["arm"]["named_poses"].get("home", [0.0] * 6))
        self._wheel_prev = list(drives.wheel_angles()) if drives is not None else None
        self._tcp_prev: Optional[np.ndarray] = None
        self._tcp_prev_t = 0.0                           # sim time of _tcp_prev
        self._dirty = True
        try:
            self._build()
        except Exception:
            self.close()
            raise
        if arm is not None and hasattr(arm, "add_step_listener"):
            arm.add_step_listener(self._on_arm_step)

    # -- scene -----------------------------------------------------------------------------------------------
    def _build(self) -> None:
        c = self._cid
        pb.setGravity(0, 0, -9.81, physicsClientId=c)
        fx, fy = self.site.floor_size
        floor = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[fx / 2, fy / 2, 0.01], physicsClientId=c)
        fvis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=[fx / 2, fy / 2, 0.01], rgbaColor=[0.6, 0.6, 0.6, 1],
                                    physicsClientId=c)
        inside = np.mean([(w.p0 + w.p1) / 2 for w in self.site.walls], axis=0)
        self.floor = pb.createMultiBody(0, floor, fvis, [inside[0], inside[1], -0.01], physicsClientId=c)
        self.wall_bodies: Dict[int, str] = {}
        for wall in self.site.walls:
            color = [0.93, 0.93, 0.88, 1] if wall.material == "plasterboard" else [0.55, 0.55, 0.55, 1]
            yaw = math.atan2(wall.u[1], wall.u[0])
            for s0, s1, t0, t1 in wall_boxes(wall):      # the wall around its door and window openings
                half = [(s1 - s0) / 2, wall.thickness / 2, (t1 - t0) / 2]
                col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=c)
                vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=color, physicsClientId=c)
                mid = wall.p0 + wall.u[:2] * (s0 + s1) / 2 - wall.n[:2] * wall.thickness / 2  # behind the face
                body = pb.createMultiBody(0, col, vis, [mid[0], mid[1], (t0 + t1) / 2],
                                          pb.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=c)
                self.wall_bodies[body] = wall.id
        # mobile base: chassis + driven wheels (+ casters for a differential base) + pedestal, one kinematic multibody
        base = self.robot["base"]
        ch, wh, ped = base["chassis"], base["wheel"], self.robot["pedestal"]
        body_h = ch["height"] - ch["clearance"]
        chassis_col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[ch["length"] / 2, ch["width"] / 2, body_h / 2],
                                              physicsClientId=c)
        chassis_vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=[ch["length"] / 2, ch["width"] / 2, body_h / 2],
                                           rgbaColor=[0.85, 0.2, 0.1, 1], physicsClientId=c)
        link_masses, link_cols, link_vis, link_pos, link_orn = [], [], [], [], []
        wheel_col = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=wh["radius"], height=wh["width"],
                                            physicsClientId=c)
        wheel_vis = pb.createVisualShape(pb.GEOM_CYLINDER, radius=wh["radius"], length=wh["width"],
                                         rgbaColor=[0.1, 0.1, 0.1, 1], physicsClientId=c)
        zc = ch["clearance"] + body_h / 2
        for wx, wy in self.kinematics.wheel_positions():
            link_masses.append(1.0)
            link_cols.append(wheel_col)
            link_vis.append(wheel_vis)
            link_pos.append([wx, wy, wh["radius"] - zc])
            link_orn.append(pb.getQuaternionFromEuler([math.pi / 2, 0, 0]))
        self._n_wheel_links = len(link_pos)
        if not self.kinematics.holonomic:       # passive casters, front and rear (visual: they carry no motion)
            cr = max(0.02, min(ch["clearance"] + 0.02, wh["radius"] / 2))
            caster_vis = pb.createVisualShape(pb.GEOM_SPHERE, radius=cr, rgbaColor=[0.2, 0.2, 0.2, 1],
                                              physicsClientId=c)
            for sx in (1, -1):
                link_masses.append(0.5)
                link_cols.append(-1)
                link_vis.append(caster_vis)
                link_pos.append([sx * (ch["length"] / 2 - cr - 0.02), 0.0, cr - zc])
                link_orn.append([0, 0, 0, 1])
        ph = max(ped["height"], 0.001)
        ped_col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[ped["size"][0] / 2, ped["size"][1] / 2, ph / 2],
                                          physicsClientId=c)
        ped_vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=[ped["size"][0] / 2, ped["size"][1] / 2, ph / 2],
                                       rgbaColor=[0.3, 0.3, 0.35, 1], physicsClientId=c)
        link_masses.append(5.0)
        link_cols.append(ped_col)
        link_vis.append(ped_vis)
        link_pos.append([ped["xy"][0], ped["xy"][1], ch["height"] + ph / 2 - zc])
        link_orn.append([0, 0, 0, 1])
        n = len(link_masses)
        self._base_z = zc
        self.base_body = pb.createMultiBody(
            ch["mass"], chassis_col, chassis_vis, [0, 0, zc], [0, 0, 0, 1],
            linkMasses=link_masses, linkCollisionShapeIndices=link_cols, linkVisualShapeIndices=link_vis,
            linkPositions=link_pos, linkOrientations=link_orn, linkInertialFramePositions=[[0, 0, 0]] * n,
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * n, linkParentIndices=[0] * n,
            linkJointTypes=[pb.JOINT_FIXED] * n, linkJointAxis=[[0, 0, 1]] * n, physicsClientId=c)
        # arm
        urdf, share = resolve_arm_urdf(self.robot["arm"])
        with open(urdf) as fh:
            text = fh.read().replace("package://example-robot-data/", share.rstrip("/") + "/")
        patched = os.path.join(self._tmp, "arm.urdf")
        with open(patched, "w") as fh:
            fh.write(text)
        self.arm_body = pb.loadURDF(patched, useFixedBase=True, flags=pb.URDF_USE_INERTIA_FROM_FILE,
                                    physicsClientId=c)
        names = self.robot["arm"]["joint_names"]
        self.arm_joints: List[int] = []
        self.tool0_link = -1
        by_name = {}
        for j in range(pb.getNumJoints(self.arm_body, physicsClientId=c)):
            info = pb.getJointInfo(self.arm_body, j, physicsClientId=c)
            by_name[info[1].decode()] = j
            if info[12].decode() == "tool0":
                self.tool0_link = j
        missing = [nm for nm in names if nm not in by_name]
        if missing or self.tool0_link < 0:
            raise SimConfigError("arm URDF %s lacks joints %s or the tool0 link" % (urdf, missing))
        self.arm_joints = [by_name[nm] for nm in names]
        for j in range(-1, pb.getNumJoints(self.arm_body, physicsClientId=c)):
            pb.setCollisionFilterGroupMask(self.arm_body, j, 1, 1, physicsClientId=c)
        # tools (one body each, parked out of the room until mounted)
        self.tool_bodies: Dict[str, int] = {}
        colors = {"taping_tool": [0.1, 0.5, 0.9, 1], "spray_gun": [0.9, 0.8, 0.1, 1], "sander": [0.2, 0.8, 0.3, 1]}
        for i, name in enumerate(TOOL_NAMES):
            b = self.tools_cfg[name]["body"]
            col = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=b["radius"], height=b["length"], physicsClientId=c)
            vis = pb.createVisualShape(pb.GEOM_CYLINDER, radius=b["radius"], length=b["length"],
                                       rgbaColor=colors[name], physicsClientId=c)
            self.tool_bodies[name] = pb.createMultiBody(0, col, vis, self._parking(i), physicsClientId=c)
        self._place_robot()

    def _parking(self, i: int) -> List[float]:
        return [-50.0 - 2.0 * i, -50.0, 0.5]

    # -- kinematic placement -----------------------------------------------------------------------------------
    def _base_tf(self) -> Tuple[List[float], Tuple[float, ...]]:
        x, y, yaw = self._pose
        return [x, y, 0.0], pb.getQuaternionFromEuler([0, 0, yaw])

    def _place_robot(self) -> None:
        c = self._cid
        pos, orn = self._base_tf()
        pb.resetBasePositionAndOrientation(self.base_body, [pos[0], pos[1], self._base_z], orn, physicsClientId=c)
        mount = self.robot["arm"]["mount"]
        mxyz = [mount["xyz"][0], mount["xyz"][1], self._mount_z]
        mpos, morn = pb.multiplyTransforms(pos, orn, mxyz, pb.getQuaternionFromEuler(mount["rpy"]))
        pb.resetBasePositionAndOrientation(self.arm_body, mpos, morn, physicsClientId=c)
        # map <- UR controller base (base_link turned by pi about z)
        rot = np.asarray(pb.getMatrixFromQuaternion(morn), dtype=float).reshape(3, 3).dot(
            np.diag([-1.0, -1.0, 1.0]))
        self._ur_base_in_map = (rot, np.asarray(mpos, dtype=float))
        for j, qv in zip(self.arm_joints, self._q):
            pb.resetJointState(self.arm_body, j, qv, physicsClientId=c)
        if self.mounted_tool is not None:
            self._place_tool()

    def _tool_frame(self) -> Tuple[Tuple[float, ...], Tuple[float, ...]]:
        st = pb.getLinkState(self.arm_body, self.tool0_link, computeForwardKinematics=True, physicsClientId=self._cid)
        return st[4], st[5]

    def _place_tool(self) -> None:
        fpos, forn = self._tool_frame()
        length = self.tools_cfg[self.mounted_tool]["body"]["length"]
        pos, orn = pb.multiplyTransforms(fpos, forn, [0, 0, length / 2], [0, 0, 0, 1])
        pb.resetBasePositionAndOrientation(self.tool_bodies[self.mounted_tool], pos, orn, physicsClientId=self._cid)

    def _tcp(self) -> Tuple[np.ndarray, np.ndarray]:
        """TCP position and its z axis (unit) in map, for the mounted tool (flange when none)."""
        fpos, forn = self._tool_frame()
        if self.mounted_tool is None:
            off, orn = [0, 0, 0], (0, 0, 0, 1)
        else:
            tcp = self.tools_cfg[self.mounted_tool]["tcp"]
            off, orn = tcp[:3], rotvec_to_quat(tcp[3:])
        pos, q = pb.multiplyTransforms(fpos, forn, off, orn)
        m = np.array(pb.getMatrixFromQuaternion(q)).reshape(3, 3)
        return np.array(pos), m[:, 2]

    # -- public state ------------------------------------------------------------------------------------------
    def base_pose(self) -> List[float]:
        """``[x, y, yaw]`` of base_footprint in map (ground truth)."""
        with self._lock:
            return list(self._pose)

    def set_base_pose(self, x: float, y: float, yaw: float) -> None:
        """Teleport the base (scene setup, operator pushing the robot)."""
        with self._lock:
            self._pose = [float(x), float(y), float(yaw)]
            self._place_robot()
            self._tcp_prev = None
            self._dirty = True

    def lift_height(self) -> Optional[float]:
        """Height (m) of the arm mount above base_footprint: the lift's (ground truth), None without a lift."""
        with self._lock:
            return self._mount_z if self.lift is not None else None

    def arm_pose_clear(self, q: Sequence[float], mount_z: Optional[float] = None, clearance: float = 0.01,
                       floor: float = 0.05, wall_x: Optional[float] = None) -> bool:
        """Whether joint positions ``q`` (with the arm mount at height ``mount_z``, default: where it is) keep every
        arm link ``clearance`` m away from the base body (chassis, wheels, pedestal / lift column), every arm link
        origin ``floor`` m above the floor and, with ``wall_x``, every arm link's bounding box ``clearance`` m short
        of a wall at map x = ``wall_x`` (perpendicular to x, ahead). The scene is put back as it was (for reach
        studies, :mod:`.reach`)."""
        c = self._cid
        with self._lock:
            keep_q, keep_z = list(self._q), self._mount_z
            try:
                self._q = [float(v) for v in q]
                if mount_z is not None:
                    self._mount_z = float(mount_z)
                self._place_robot()
                if pb.getClosestPoints(self.arm_body, self.base_body, clearance, physicsClientId=c):
                    return False
                if wall_x is not None and any(
                        pb.getAABB(self.arm_body, j, physicsClientId=c)[1][0] > wall_x - clearance
                        for j in range(pb.getNumJoints(self.arm_body, physicsClientId=c))):
                    return False
                return all(pb.getLinkState(self.arm_body, j, physicsClientId=c)[4][2] >= floor
                           for j in range(pb.getNumJoints(self.arm_body, physicsClientId=c)))
            finally:
                self._q, self._mount_z = keep_q, keep_z
                self._place_robot()

    def arm_base_pose(self) -> Tuple[List[float], List[float]]:
        """Position and quaternion (x, y, z, w) of the UR controller ``base`` frame in map (the placement the
        last :meth:`_place_robot` cached)."""
        rot, origin = self._ur_base_in_map
        return origin.tolist(), list(matrix_to_quat(rot))

    def touching(self, q: Sequence[float], clearance: float = 0.0) -> List[Tuple[str, str]]:
        """``(part, wall)`` pairs -- part ``base``, ``arm`` or ``tool`` -- that come within ``clearance`` m of a
        wall with the arm at joint positions ``q`` and the mounted tool on it (for checking planned poses before
        the robot moves; the scene is put back as it was)."""
        c = self._cid
        with self._lock:
            keep_q = list(self._q)
            try:
                self._q = [float(v) for v in q]
                self._place_robot()
                if self.mounted_tool is not None:
                    self._place_tool()
                bodies = [(self.base_body, "base"), (self.arm_body, "arm")]
                if self.mounted_tool is not None:
                    bodies.append((self.tool_bodies[self.mounted_tool], "tool"))
                out = set()
                for body, part in bodies:
                    for wb, wid in self.wall_bodies.items():
                        if pb.getClosestPoints(body, wb, clearance, physicsClientId=c):
                            out.add((part, wid))
                return sorted(out)
            finally:
                self._q = keep_q
                self._place_robot()
                if self.mounted_tool is not None:
                    self._place_tool()

    def wall_contact(self, tcp_pose: Sequence[float]) -> Optional[Tuple[float, List[float]]]:
        """Contact provider for the UR stand-in (``set_contact_provider``): how deep the TCP (a pose in the UR
        base frame, as the controller reports it) is inside a wall of the site, and that wall's normal out of
        the wall (into the room) in the UR base frame; None when the TCP touches no wall. A tool with a pad
        (``pad_radius``) touches the wall while any of its pad does: its centre may be up to the pad's radius past
        the wall's edge (a sander centred on the top edge presses with its lower half). Called on the
        controller's thread: it reads the robot placement cached by the last world step, no PyBullet call."""
        placed = self._ur_base_in_map
        if placed is None:
            return None
        rot, origin = placed
        p = rot.dot(np.asarray(tcp_pose[:3], dtype=float)) + origin
        tool = self.mounted_tool
        r = float(self.tools_cfg[tool].get("pad_radius", 0.0)) if tool is not None else 0.0
        best: Optional[Tuple[float, List[float]]] = None
        for wall in self.site.walls:
            s, t, d = wall.to_wall_coords(p)
            if d >= 0.0 or d < -wall.thickness or not (-r <= s <= wall.length + r and -r <= t <= wall.height + r):
                continue
            if wall.in_opening(s, t, r):
                continue        # in a door or window opening: no wall under the tool
            if best is None or -d > best[0]:
                best = (-d, rot.T.dot(wall.n).tolist())
        return best

    def tcp_pose(self) -> Tuple[List[float], List[float]]:
        """TCP position and its z axis in map (mounted tool's TCP offset applied)."""
        with self._lock:
            pos, z = self._tcp()
            return list(pos), list(z)

    def joint_positions(self) -> List[float]:
        with self._lock:
            return list(self._q)

    def tcp_target_in_arm_base(self, position: Sequence[float], z_axis: Sequence[float]) -> List[float]:
        """UR pose ``[x, y, z, rx, ry, rz]`` (arm ``base`` frame) that puts the TCP at ``position`` (map) with its
        z axis along ``z_axis`` (map) and its x axis horizontal; for scripted passes through the UR stand-in."""
        rot = rotation_z_along(z_axis)
        p, q = self.arm_base_pose()
        ip, iq = pb.invertTransform(p, q)
        out_p, out_q = pb.multiplyTransforms(ip, iq, list(position), matrix_to_quat(rot))
        return list(out_p) + quat_to_rotvec(out_q)

    def map_to_arm_base(self, point: Sequence[float]) -> List[float]:
        """A map-frame point expressed in the UR ``base`` frame."""
        p, q = self.arm_base_pose()
        ip, iq = pb.invertTransform(p, q)
        out, _ = pb.multiplyTransforms(ip, iq, list(point), [0, 0, 0, 1])
        return list(out)

    def ik_tcp(self, position: Sequence[float], z_axis: Sequence[float], seed: Optional[Sequence[float]] = None,
               iterations: int = 8, tol: float = 1e-4) -> List[float]:
        """Joint positions that put the TCP (mounted tool) at ``position`` (map) with its z axis along ``z_axis``
        (x axis kept horizontal). For scripted passes and tests; the arm source still decides what happens."""
        rot = rotation_z_along(z_axis)
        if self.mounted_tool is None:
            off, oq = [0.0, 0.0, 0.0], (0, 0, 0, 1)
        else:
            tcp = self.tools_cfg[self.mounted_tool]["tcp"]
            off, oq = tcp[:3], rotvec_to_quat(tcp[3:])
        tq = matrix_to_quat(rot)
        ioff, ioq = pb.invertTransform(off, oq)
        fpos, forn = pb.multiplyTransforms(list(position), tq, ioff, ioq)
        c = self._cid
        with self._lock:
            keep = list(self._q)
            q = list(seed) if seed is not None else list(self._q)
            try:
                for _ in range(iterations):
                    for j, qv in zip(self.arm_joints, q):
                        pb.resetJointState(self.arm_body, j, qv, physicsClientId=c)
                    sol = pb.calculateInverseKinematics(self.arm_body, self.tool0_link, fpos, forn,
                                                        maxNumIterations=200, residualThreshold=1e-7,
                                                        physicsClientId=c)
                    q = list(sol[:6])
                    for j, qv in zip(self.arm_joints, q):
                        pb.resetJointState(self.arm_body, j, qv, physicsClientId=c)
                    p, _ = self._tool_frame()
                    if np.linalg.norm(np.array(p) - np.array(fpos)) < tol:
                        break
            finally:
                for j, qv in zip(self.arm_joints, keep):
                    pb.resetJointState(self.arm_body, j, qv, physicsClientId=c)
        return q

    # -- tools (operator) --------------------------------------------------------------------------------------
    def mount_tool(self, name: str, by: str = "operator") -> None:
        """The operator (or the tool changer, ``by``) mounts ``name`` on the flange (exactly one tool at a time)."""
        if name not in TOOL_NAMES:
            raise SimStateError("unknown tool %r, allowed: %s" % (name, ", ".join(TOOL_NAMES)))
        with self._lock:
            if self.mounted_tool is not None:
                raise SimStateError("tool %r is mounted; remove it before mounting %r" % (self.mounted_tool, name))
            self.mounted_tool = name
            self._place_tool()
            self._tcp_prev = None
            self._dirty = True
        log.info("%s mounted %s", by, name)

    def remove_tool(self, by: str = "operator") -> Optional[str]:
        """The operator (or the tool changer, ``by``) removes the mounted tool; returns its name (None when nothing
        was mounted)."""
        with self._lock:
            name = self.mounted_tool
            if name is None:
                return None
            pb.resetBasePositionAndOrientation(self.tool_bodies[name], self._parking(TOOL_NAMES.index(name)),
                                               [0, 0, 0, 1], physicsClientId=self._cid)
            self.mounted_tool = None
            self._tcp_prev = None
        log.info("%s removed %s", by, name)
        return name

    def flange_in_mount(self, q: Optional[Sequence[float]] = None) -> List[float]:
        """Where the flange (``tool0``) is in the arm's ``base_link`` frame for joint positions ``q`` (default: the
        arm source's current ones): the tool changer stand-in's rack slots (:mod:`.modbus.tool_changer`)."""
        if q is None:
            q = self.arm_source.joint_positions() if self.arm_source is not None else self._q
        c = self._cid
        with self._lock:
            for j, qv in zip(self.arm_joints, q):
                pb.resetJointState(self.arm_body, j, float(qv), physicsClientId=c)
            fpos, _ = self._tool_frame()
            for j, qv in zip(self.arm_joints, self._q):
                pb.resetJointState(self.arm_body, j, qv, physicsClientId=c)
            bpos, born = pb.getBasePositionAndOrientation(self.arm_body, physicsClientId=c)
            ipos, iorn = pb.invertTransform(bpos, born)
            pos, _ = pb.multiplyTransforms(ipos, iorn, fpos, [0, 0, 0, 1])
        return [float(v) for v in pos]

    def tool_active(self) -> bool:
        """Whether the mounted tool's process is on (digital output / valve + pressure in range)."""
        name = self.mounted_tool
        if name is None:
            return False
        sw = self.tools_cfg[name]["switch"]
        if sw["source"] == "ur_digital_out":
            return bool(self.arm_source is not None and self.arm_source.digital_output(sw["index"]))
        return bool(self.compressor is not None and self.compressor.spraying())

    # -- perception --------------------------------------------------------------------------------------------
    def scan(self) -> Dict[str, Any]:
        """SCAN result (contract JSON shape) from the current base pose (under the world's lock: the scanner reads
        the outcome recorder, which the stepping thread writes)."""
        with self._lock:
            return self.scanner.scan(self.base_pose(), stamp=self.clock.now())

    # -- stepping ----------------------------------------------------------------------------------------------
    def _on_arm_step(self, q: Sequence[float], motion_time: Optional[float] = None) -> None:
        """Controller step listener (the controller's thread): queue the joint sample together with whether the
        tool's process is on at this moment and its sim time, so a valve or output switched between two world steps
        takes effect at the right place along the path (a world step spans many controller cycles, the more so when
        time-scaled) and each stretch of the path gets the time the tool took over it (a busy machine's controller
        cycles are not evenly spread over a world step: a stretch passed in one late cycle got only its share of
        the step, a thin stripe of spray across the lane).

        A sample's time is the controller's own ``motion_time`` when it gives one (see :meth:`_sample_time`): a
        controller that woke up late moves the arm on by the cycles it missed, in a burst of steps that all come in
        at nearly one wall time; timed by the world clock, that stretch got no coat at all."""
        q = [float(x) for x in q]
        last = self._samples[-1][0] if self._samples else self._last_sample
        t = self._sample_time(motion_time)
        if last is not None and max(abs(a - b) for a, b in zip(last, q)) <= 1e-9:
            return                                       # controller idling: nothing new
        self._last_sample = q
        try:
            on = self.tool_active()
        except Exception:                                # a stand-in shutting down: judged at the step instead
            on = False
        journal, n = self.sample_journal, None
        if journal is not None and self.mounted_tool is not None:
            n = journal.note_sample(q, on, t)
        if len(self._samples) == SAMPLE_QUEUE:
            self.samples_dropped += 1
            if self.samples_dropped in (1, 10, 100, 1000) or self.samples_dropped % 10000 == 0:
                log.warning("world: %d arm samples dropped (the world's step fell %d samples behind): the outcome "
                            "maps miss that stretch of the arm's path", self.samples_dropped, SAMPLE_QUEUE)
        self._samples.append((q, on, t, n))

    def resume_samples(self, samples: Sequence[Tuple[List[float], bool, float, int]],
                       pen: Optional[Tuple[Sequence[float], float]]) -> None:
        """A restored world goes on with the arm samples its maps did not hold yet (the saved state's ``pending``),
        the tool at ``pen`` (TCP, sim time; None: the first sample only places it) before them: the next step
        records them as it would have. Without a tool mounted there is nothing to record: they are dropped."""
        with self._lock:
            if not samples or self.mounted_tool is None:
                return
            if pen is not None:
                self._tcp_prev, self._tcp_prev_t = np.asarray(pen[0], dtype=float), float(pen[1])
            newer = list(self._samples)                  # the new controller's, at most where the arm stood
            self._samples.clear()
            self._samples.extend([(list(q), bool(on), float(t), n) for q, on, t, n in samples] + newer)
            if not newer:
                self._last_sample = list(samples[-1][0])

    def _sample_time(self, motion_time: Optional[float]) -> float:
        """Sim time of a controller sample: the world clock, or, given the controller's ``motion_time``, that
        clock on the world's time line, anchored where the controller was least behind the world clock (a sample
        is never timed in the future; a controller that falls behind -- a stall, a restart -- keeps its own
        spacing, so the steps of a catch-up burst get their true durations). The world then times what it does
        without a sample (an arm at rest, a trailing pose) on the same line (:attr:`_arm_clock`)."""
        now = self.clock.now()
        if motion_time is None:
            self._arm_clock = None                       # a source without a motion clock: the world's own
            return now
        offset = now - float(motion_time)
        if self._motion_anchor is None or offset < self._motion_anchor:
            self._motion_anchor = offset
        t = self._motion_anchor + float(motion_time)
        self._arm_clock = t
        return t

    def step(self) -> None:
        """Advance the world to ``clock()`` (see the module docstring)."""
        with self._lock:
            now = self.clock.now()
            t_prev = self._t
            self._t = now
            self.steps += 1
            moved = False
            if self.drives is not None:
                if hasattr(self.drives, "wheel_angle_samples"):
                    samples = self.drives.wheel_angle_samples(t_prev, now, BASE_SUBSTEP)
                else:
                    samples = [self.drives.wheel_angles()]
                for ang in samples:
                    d = [a - b for a, b in zip(ang, self._wheel_prev)]
                    self._wheel_prev = ang
                    if any(abs(x) > 1e-12 for x in d):
                        dx, dy, dth = self.kinematics.twist(d)
                        x, y, yaw = self._pose
                        ym = yaw + dth / 2.0
                        self._pose = [x + math.cos(ym) * dx - math.sin(ym) * dy,
                                      y + math.sin(ym) * dx + math.cos(ym) * dy, yaw + dth]
                        moved = True
            if self.lift is not None:
                with self.lift._lock:
                    self.lift.update()
                    z = self._lift_bottom + float(self.lift.angle)
                if abs(z - self._mount_z) > 1e-7:
                    self._mount_z = z
                    self._tcp_prev = None            # the TCP moved with the mount: no painting along that jump
                    moved = True
            active = self.tool_active()
            # what has no sample of its own is timed on the samples' line (the controller's motion clock, when it
            # gives one): mixed with the world clock, a segment after it would get no time (read before the queue
            # is drained: a sample queued meanwhile is later than it)
            t_now = now if self._arm_clock is None else self._arm_clock
            qs: List[Tuple[List[float], bool, float, Optional[int]]] = []
            while self._samples:
                qs.append(self._samples.popleft())
            numbers = [n for _q, _on, _t, n in qs if n is not None]
            try:
                self._record_samples(qs, moved, active, t_now)
            finally:
                if self.sample_journal is not None:      # where the next sample's segment starts
                    self.sample_journal.note_drained(max(numbers) if numbers else None, None if self._tcp_prev is
                                                     None else [float(x) for x in self._tcp_prev], self._tcp_prev_t)

    def _record_samples(self, qs: List[Tuple[List[float], bool, float, Optional[int]]], moved: bool, active: bool,
                        t_now: float) -> None:
        """The arm's part of :meth:`step` (under the lock): the samples ``qs`` (and the arm's joints now) into the
        outcome maps, then the collision check."""
        if self.arm_source is not None:
            q_now = [float(x) for x in self.arm_source.joint_positions()]
            if not qs or max(abs(a - b) for a, b in zip(qs[-1][0], q_now)) > 1e-9:
                qs.append((q_now, active, max(t_now, qs[-1][2]) if qs else t_now, None))
        if qs and max(abs(a - b) for a, b in zip(qs[-1][0], self._q)) <= 1e-9 and len(qs) == 1:
            qs = []
        if not (moved or qs or self._dirty or active):
            self._tcp_prev_t = t_now                 # idle: nothing changed, nothing to measure
            return
        self._dirty = False
        if moved:
            self._place_robot()
        if not qs:
            qs = [(self._q, active, t_now, None)]
        elif self.mounted_tool is None:
            qs = [qs[-1]]                            # nothing to measure along the way
        # thin out dense controller steps: keep every sample that moved the TCP >= 2 mm; a segment lasts from
        # the previous kept sample's time to its own (thinned-out samples' time goes to the next segment)
        n = len(qs)
        journal, upto = self.sample_journal, None
        for i, (q, on, t, number) in enumerate(qs):
            if number is not None:
                upto = number if upto is None else max(upto, number)
            self._q = q
            for j, qv in zip(self.arm_joints, q):
                pb.resetJointState(self.arm_body, j, qv, physicsClientId=self._cid)
            if self.mounted_tool is not None:
                pos, z = self._tcp()
                if i < n - 1 and self._tcp_prev is not None and np.linalg.norm(pos - self._tcp_prev) < 0.002:
                    continue
                if self._tcp_prev is not None:
                    if journal is not None:      # the segment's record says which samples it holds
                        journal.segment_ends(upto, t)
                    self.outcome.record(self.mounted_tool, on, self._tcp_prev, pos, z,
                                        max(0.0, t - self._tcp_prev_t))
                self._tcp_prev, self._tcp_prev_t = pos, t
        if self.mounted_tool is not None:
            self._place_tool()
        self._check_collisions()

    def _check_collisions(self) -> None:
        c = self._cid
        current = set()
        for body, part in ((self.base_body, "base"), (self.arm_body, "arm")):
            for wb, wid in self.wall_bodies.items():
                pts = pb.getClosestPoints(body, wb, 0.0, physicsClientId=c)
                for p in pts:
                    link = p[3]
                    if part == "arm":
                        name = "arm:" + (pb.getJointInfo(body, link, physicsClientId=c)[12].decode()
                                         if link >= 0 else "root")
                    else:
                        name = "base" if link < 0 else ("base:wheel_%d" % link if link < self._n_wheel_links
                                                        else "base:pedestal")
                    current.add((name, wid))
        new = current - self._contacts
        self._contacts = current
        for name, wid in sorted(new):
            self.collisions += 1
            event = {"stamp": self.clock.now(), "part": name, "wall": wid, "base_pose": list(self._pose)}
            self.collision_log.append(event)
            log.warning("collision: %s touches %s", name, wid)
            for fn in list(self.on_collision):
                try:
                    fn(event)
                except Exception as exc:
                    log.warning("collision callback failed: %s", exc)

    @property
    def in_contact(self) -> List[Tuple[str, str]]:
        return sorted(self._contacts)

    # -- loop --------------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Run :meth:`step` at ``world_rate`` (wall clock) in a thread."""
        if self._thread is not None:
            raise SimStateError("world loop already running")
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="world", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        rate = FixedRate(1.0 / self.rate, self._stop)
        while rate.running():
            try:
                self.step()
            except Exception:
                log.exception("world step failed")
            rate.sleep()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None

    def close(self) -> None:
        """Stop the loop and disconnect PyBullet (idempotent)."""
        self.stop()
        if self.arm_source is not None and hasattr(self.arm_source, "remove_step_listener"):
            try:
                self.arm_source.remove_step_listener(self._on_arm_step)
            except Exception:
                pass
        with self._lock:
            if self._cid is not None and self._cid >= 0:
                try:
                    pb.disconnect(physicsClientId=self._cid)
                except pb.error:
                    pass
                self._cid = -1
        shutil.rmtree(self._tmp, ignore_errors=True)
