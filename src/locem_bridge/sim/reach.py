"""The arm's reach with each tool facing a wall ahead of the base, measured on a robot file in the PyBullet world:
the numbers the trees and the robot facts need (how high and how far sideways a tool reaches from one base pose,
per lift height).

For each tool, each distance ``D`` (TCP ahead of the arm's vertical axis, along +x of base_footprint; the tool axis
horizontal, pointing at a wall whose surface is perpendicular to x) and each arm mount height (the lift's bottom,
middle and top; the fixed mount without a lift), a grid point counts as reachable when the UR stand-in's IK
(pinocchio on the robot file's URDF, joint limits, the branch nearest ``wall_ready`` as the wall commands use)
reaches it AND the arm keeps 1 cm from the base body (chassis, wheels, pedestal / lift column) AND every arm link
origin stays 5 cm above the floor AND no arm link's bounding box comes within 1 cm of the wall the tool works on
(at the TCP for a contact tool, ``standoff`` ahead of it for the spray gun)
(:meth:`~locem_bridge.sim.world.World.arm_pose_clear`). Reported: the TCP's lowest and highest reachable z above
the floor (at y = 0) and its lateral band (y at the mount's height); ``flange_distance`` = flange ahead of
base_footprint (the robot file's ``wall_work.flange_distance``).

    python3 -m locem_bridge.sim.reach --robot config/robots/diffdrive_ur5e.yaml [--distance 0.55 ...] [--step 0.025]
"""
import argparse
import sys
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from ..bridges.geometry import tool_frame_facing
from ..common.geometry import matrix_to_rotvec
from .config import load_robot, load_site, resolve_arm_urdf
from .world import World

UR_BASE = np.diag([-1.0, -1.0, 1.0])       # the UR controller's base frame: base_link turned by pi about z


def _ur_pose(point: Sequence[float]) -> List[float]:
    """UR pose (arm base frame) of a TCP at ``point`` (mount frame), tool axis along +x of base_footprint."""
    frame = tool_frame_facing(point, (-1.0, 0.0, 0.0))
    return list(UR_BASE.dot(frame[:3, 3])) + list(matrix_to_rotvec(UR_BASE.dot(frame[:3, :3])))


def mount_heights(robot: Dict[str, Any]) -> List[float]:
    """The lift's bottom, middle and top; the fixed mount's height without a lift."""
    if "lift" in robot:
        lo, hi = robot["lift"]["range"]
        return [lo, round((lo + hi) / 2.0, 4), hi]
    return [float(robot["arm"]["mount"]["xyz"][2])]


def reach_table(robot_cfg: Dict[str, Any], distances: Sequence[float] = (0.45, 0.55, 0.65), step: float = 0.025,
                heights: Optional[Sequence[float]] = None, tools: Optional[Sequence[str]] = None) -> List[Dict[str, Any]]:
    """One row per tool x distance x mount height: ``tool``, ``distance``, ``mount_z``, ``z_min``/``z_max`` (TCP
    above the floor, None when nothing is reachable), ``y_min``/``y_max`` (at the mount's height)."""
    from .ur.kinematics import ArmKinematics, KinematicsError
    robot = robot_cfg["robot"]
    arm = robot["arm"]
    kin = ArmKinematics(resolve_arm_urdf(arm)[0])
    seed = arm["named_poses"].get("wall_ready", arm["named_poses"].get("home", [0.0, -1.5708, 1.5708, -1.5708,
                                                                            -1.5708, 0.0]))
    world = World(load_site(), robot_cfg, gui=False)
    rows = []
    try:
        world.set_base_pose(0.0, 0.0, 0.0)

        mount_x = float(arm["mount"]["xyz"][0])

        def reachable(point: List[float], length: float, mount_z: float, wall_x: float) -> bool:
            try:
                q = kin.ik(_ur_pose(point), seed, tcp_pose=[0.0, 0.0, length, 0.0, 0.0, 0.0])
            except KinematicsError:
                return False
            return world.arm_pose_clear(q, mount_z, wall_x=wall_x)

        for tool in tools or sorted(robot["tools"]):
            length = float(robot["tools"][tool]["tcp"][2])
            wall_x = mount_x + float(robot["tools"][tool].get("standoff", 0.0))
            for d in distances:
                for h in heights or mount_heights(robot):
                    zs = [z for z in np.arange(-h, 1.2, step) if reachable([d, 0.0, z], length, h, wall_x + d)]
                    ys = [y for y in np.arange(-1.0, 1.0 + 1e-9, step)
                          if reachable([d, y, 0.0], length, h, wall_x + d)]
                    rows.append({"tool": tool, "distance": d, "mount_z": h,
                                 "flange_distance": round(mount_x + d - length, 3),
                                 "z_min": round(h + zs[0], 3) if zs else None,
                                 "z_max": round(h + zs[-1], 3) if zs else None,
                                 "y_min": round(ys[0], 3) if ys else None, "y_max": round(ys[-1], 3) if ys else None})
    finally:
        world.close()
    return rows


def main(argv: Optional[Sequence[str]] = None) -> int:
    from ..robot_file import default_robot_path
    ap = argparse.ArgumentParser(prog="python3 -m locem_bridge.sim.reach", description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default=default_robot_path(), help="robot YAML (default: %(default)s)")
    ap.add_argument("--distance", type=float, nargs="+", default=[0.45, 0.55, 0.65],
                    help="TCP distances ahead of the arm's axis, m")
    ap.add_argument("--step", type=float, default=0.025, help="grid step, m")
    args = ap.parse_args(argv)
    cfg = load_robot(args.robot)
    mount_x = cfg["robot"]["arm"]["mount"]["xyz"][0]
    print("%s: TCP D m ahead of the arm axis (arm axis %.2f m ahead of base_footprint), tool facing +x"
          % (cfg["robot"]["name"], mount_x))
    print("%-12s %5s %8s %8s %15s %15s" % ("tool", "D", "flange", "mount z", "TCP z (floor)", "y at mount z"))
    for r in reach_table(cfg, args.distance, args.step):
        fmt = lambda a, b: "unreachable" if a is None else "%.2f..%.2f" % (a, b)   # noqa: E731
        print("%-12s %5.2f %8.2f %8.2f %15s %15s" % (r["tool"], r["distance"], r["flange_distance"], r["mount_z"],
                                                     fmt(r["z_min"], r["z_max"]), fmt(r["y_min"], r["y_max"])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
