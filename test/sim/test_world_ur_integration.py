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


def test_the_arm_feels_the_walls_force_reading_and_contact_depth(site_with_ur):
    """The worksite gives the UR stand-in the world's walls as contact surfaces: a flange pressed 3 mm into
    wall_1 reads 20 kN/m x 3 mm = 60 N along the wall's normal (UR base axes); 5 mm in front of it, nothing."""
    ws = site_with_ur
    wall = next(w for w in ws.world.site.walls if w.id == "wall_1")
    face = wall.from_wall_coords(2.4, 1.0, 0.0)                     # map point on wall_1's face, 1 m high
    ws.world.set_base_pose(face[0] + 0.95 * wall.n[0], face[1] + 0.95 * wall.n[1],
                           math.atan2(-wall.n[1], -wall.n[0]))      # 0.95 m in front, facing the wall
    normal_in_base = np.subtract(ws.world.map_to_arm_base(face + wall.n), ws.world.map_to_arm_base(face))

    def press(depth):
        q = ws.world.ik_tcp(face - depth * wall.n, -wall.n, seed=ws.ur.get_joint_positions())
        # pressing the flange into the wall is also a collision: the protective stop it raises brakes the arm
        # for a moment, and a teleport is refused while the arm moves
        assert _wait(lambda: not ws.ur.arm.is_moving())
        ws.ur.set_joint_positions(q)
        assert _wait(lambda: np.allclose(ws.world.joint_positions(), q, atol=1e-9))
        return ws.world.wall_contact(ws.ur.get_tcp_pose())

    depth, normal = press(0.003)
    assert depth == pytest.approx(0.003, abs=2e-4) and np.allclose(normal, normal_in_base, atol=1e-6)
    assert _wait(lambda: np.allclose(ws.ur.get_tcp_force()[:3], 20000.0 * depth * normal_in_base, atol=1.0))
    assert press(-0.005) is None                                     # in front of the wall: no contact
    assert _wait(lambda: np.allclose(ws.ur.get_tcp_force(), 0.0, atol=1e-9))
