"""The worksite with the second robot (config/robots/diffdrive_ur5e.yaml): a differential base with casters, a
lift carrying a UR5e class arm whose controller stand-in runs on the same URDF. The world loads, the lift's
drive stand-in moves the arm mount (and with it the UR base frame and the flange) in the PyBullet world, and the
stand-in's pinocchio model and the PyBullet arm agree at every lift height."""
import os
import socket
import time

import numpy as np
import pybullet as pb
import pytest

from locem_bridge.sim.config import load_robot
from locem_bridge.sim.worksite import Worksite

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DIFF_YAML = os.path.join(REPO, "config", "robots", "diffdrive_ur5e.yaml")


def _address():
    third = 1 + (os.getpid() + 131) % 250
    for last in range(1, 250):
        addr = "127.65.%d.%d" % (third, last)
        try:
            for port in (29999, 30003, 30004):
                with socket.socket() as s:
                    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                    s.bind((addr, port))
            return addr
        except OSError:
            continue
    raise RuntimeError("no free loopback address")


@pytest.fixture
def second(site_cfg, port):
    ws = Worksite(site_cfg, load_robot(DIFF_YAML), host=_address(), modbus_port=port, can_interface="virtual",
                  can_channel="second-%d" % os.getpid(), time_scale=4.0)
    ws.start()
    yield ws
    ws.stop()


def _wait(pred, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.02)
    return False


def _flange_in_map_from_controller(ws):
    pose = ws.ur.get_tcp_pose()                       # no TCP offset set: the flange, in the UR base frame
    p, orn = ws.world.arm_base_pose()
    return np.array(pb.multiplyTransforms(p, orn, pose[:3], [0, 0, 0, 1])[0])


def test_the_second_robot_loads_and_the_lift_carries_the_arm(second):
    ws = second
    robot = ws.robot_cfg["robot"]
    assert ws.world.kinematics.kind == "differential" and len(ws.drives.drives) == 2
    assert "lift_drive_can" in ws.endpoints()
    bottom, top = robot["lift"]["range"]
    assert ws.world.lift_height() == pytest.approx(robot["arm"]["mount"]["xyz"][2])
    q = robot["arm"]["named_poses"]["wall_ready"]
    ws.ur.set_joint_positions(q)
    assert _wait(lambda: np.allclose(ws.world.joint_positions(), q, atol=1e-9))
    flange0 = np.array(ws.world.tcp_pose()[0])
    assert np.allclose(_flange_in_map_from_controller(ws), flange0, atol=1e-3)
    # the lift drive stand-in moves to the top (profile position, as its CAN master would command it)
    drive = ws.lift
    drive.state = "OPERATION ENABLED"
    drive.mode = 1
    with drive._lock:
        drive.setpoint = top - bottom
    assert _wait(lambda: drive.in_position(), timeout=10.0)
    assert _wait(lambda: abs(ws.world.lift_height() - top) < 1e-6)
    flange1 = np.array(ws.world.tcp_pose()[0])
    rise = top - robot["arm"]["mount"]["xyz"][2]
    assert np.allclose(flange1 - flange0, [0.0, 0.0, rise], atol=1e-4)   # the whole arm rose, nothing else moved
    assert ws.world.arm_base_pose()[0][2] == pytest.approx(top, abs=1e-4)
    # the controller's frame moved with it: its model and the PyBullet arm still agree
    assert np.allclose(_flange_in_map_from_controller(ws), flange1, atol=1e-3)


def test_the_ur5e_stand_in_runs_on_the_robot_files_urdf_with_its_limits(second):
    from locem_bridge.sim.ur.kinematics import ArmKinematics
    ws = second
    kin = ws.ur.kinematics
    assert kin.urdf_path.endswith("ur5_robot.urdf")
    reference = ArmKinematics("ur5")
    assert np.allclose(kin.lower, reference.lower) and np.allclose(kin.upper, reference.upper)
    # reach 0.85 m: the flange's farthest point from the shoulder axis with the arm stretched out horizontally
    stretched = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    flange = kin.fk(stretched)
    assert 0.80 < float(np.hypot(flange[0], flange[1])) < 0.95
    world = ws.world
    for name, q in ws.robot_cfg["robot"]["arm"]["named_poses"].items():
        assert np.all(np.asarray(q) >= kin.lower) and np.all(np.asarray(q) <= kin.upper), name
        # every named pose keeps the arm clear of the chassis and the lift column (1 cm), lift at the bottom
        with world._lock:
            world._q = list(q)
            world._place_robot()
            near = pb.getClosestPoints(world.arm_body, world.base_body, 0.01, physicsClientId=world._cid)
        assert not near, "%s: arm within 1 cm of the base/column" % name


def test_with_the_lift_the_ur5e_covers_the_site_joints_heights_from_two_lift_heights():
    """Measured reach (sim/reach.py: stand-in IK + clearance from the chassis and the lift column): the taping tool
    facing a wall 0.55 m ahead of the arm axis spans < 1.9 m from one height, so z 0.10..2.0 m (the default site's
    joints) needs the lift: its bottom reaches down to 0.10 m, its top up to 2.0 m; sideways about +-0.7 m."""
    from locem_bridge.sim.reach import reach_table
    rows = reach_table(load_robot(DIFF_YAML), distances=(0.55,), step=0.05, tools=("taping_tool",))
    by_height = {r["mount_z"]: r for r in rows}
    bottom, top = min(by_height), max(by_height)
    assert by_height[bottom]["z_min"] <= 0.10 and by_height[top]["z_max"] >= 2.0, rows
    for r in rows:
        assert r["z_max"] - r["z_min"] < 1.9, r                  # one height cannot cover 0.10..2.0
        assert r["y_min"] <= -0.7 and r["y_max"] >= 0.7, r
