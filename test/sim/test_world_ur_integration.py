"""The world mirrors the UR controller stand-in (in process, API only: no ur_rtde client here): joint state and
TCP agree between the stand-in's pinocchio model and the PyBullet arm, and an arm collision with a wall puts
the arm in a protective stop."""
import math
import os
import socket
import time

import numpy as np
import pybullet as pb
import pytest

from locem_bridge.sim.worksite import Worksite


def _address():
    third = 1 + (os.getpid() + 97) % 250
    for last in range(1, 250):
        addr = "127.64.%d.%d" % (third, last)
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
def site_with_ur(site_cfg, robot_cfg, port):
    ws = Worksite(site_cfg, robot_cfg, host=_address(), modbus_port=port, can_interface="virtual",
                  can_channel="ur-int-%d" % os.getpid(), time_scale=2.0)
    ws.start()
    yield ws
    ws.stop()


def _wait(pred, timeout=3.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.02)
    return False


def test_world_follows_ur_joint_state_and_tcp_models_agree(site_with_ur, robot_cfg):
    ws = site_with_ur
    q = robot_cfg["robot"]["arm"]["named_poses"]["wall_ready"]
    ws.ur.set_joint_positions(q)
    assert _wait(lambda: np.allclose(ws.world.joint_positions(), q, atol=1e-9))
    # flange (no tool, no TCP offset) from pinocchio (UR base frame) vs PyBullet (map): same point
    ur_pose = ws.ur.get_tcp_pose()
    p, orn = ws.world.arm_base_pose()
    ur_in_map, _ = pb.multiplyTransforms(p, orn, ur_pose[:3], [0, 0, 0, 1])
    world_tcp, _ = ws.world.tcp_pose()
    assert np.allclose(ur_in_map, world_tcp, atol=1e-3)


def test_arm_collision_with_wall_triggers_protective_stop(site_with_ur, robot_cfg):
    ws = site_with_ur
    assert ws.ur.get_state()["safety_mode_name"].upper() == "NORMAL"
    ws.ur.set_joint_positions([0.0, -1.5708, 1.5708, 0.0, 1.5708, 0.0])   # forearm stretched forward
    ws.world.set_base_pose(2.4, 2.9, math.pi / 2)          # stretched arm reaches through wall_1
    assert _wait(lambda: ws.world.collisions > 0)
    assert any(part.startswith("arm:") for part, _ in ws.world.in_contact)
    assert _wait(lambda: "PROTECTIVE" in str(ws.ur.get_state()["safety_mode_name"]).upper())
    assert ws.outcome()["collisions"] >= 1
