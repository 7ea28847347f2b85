"""The bridges against the worksite composition of the simulator (``locem_bridge.sim.worksite.Worksite``, what
``python3 -m locem_bridge.sim`` / ``sim_worksite`` run): both sides read the SAME robot YAML and differ only in
the addresses this test overrides, which is the one-YAML claim of the bridges."""
import math
import os
import random

import pytest

from locem_bridge.bridges.config import load_robot_config
from locem_bridge.bridges.robot import build_robot
from locem_bridge.locem.core import LocemCore

from bridge_rigs import ROBOT_YAML, free_port, next_ur_address, wait_until

pytest.importorskip("rtde_control")
worksite_mod = pytest.importorskip("locem_bridge.sim.worksite")
pytestmark = pytest.mark.slow

SITE = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                    "config", "sites", "default.yaml")


@pytest.fixture
def stack():
    host = next_ur_address()
    port = free_port()
    group = "239.74.167.%d" % random.randint(1, 250)
    can_port = 44000 + random.randint(0, 999)
    ws = worksite_mod.Worksite(host=host, modbus_port=port, can_interface="udp_multicast", can_channel=group,
                               can_port=can_port, time_scale=4.0)
    ws.start()
    overrides = {"arm": {"controller": {"host": host}}, "compressor": {"host": host, "port": port},
                 "base": {"drives": {"can": {"interface": "udp_multicast", "channel": group, "port": can_port}}}}
    robot_cfg = load_robot_config(ROBOT_YAML, overrides)
    robot = build_robot(robot_cfg, site=SITE, initial_pose=tuple(ws.world.base_pose()))
    core = LocemCore(grace=0.5)
    for command_set in robot.command_sets:
        core.install(command_set)
    robot.start()
    for kind in ("arm", "compressor", "base"):
        assert robot.get(kind).wait_ready(30.0), (kind, robot.get(kind).health())
    yield ws, robot, core
    core.close()
    robot.close()
    ws.stop()


def test_one_yaml_drives_the_simulated_worksite(stack):
    ws, robot, core = stack
    goal = (1.7, 1.5, 1.3)
    r = core.dispatcher.execute("GOTO %g %g %g" % goal)
    assert r.success, r.message
    x, y, th = ws.world.base_pose()
    assert math.hypot(x - goal[0], y - goal[1]) < 0.02 and abs(th - goal[2]) < math.radians(1.0)
    r = core.dispatcher.execute("MOVE_HOME scan")
    assert r.success, r.message
    # the controller said the arm is there; the world's copy of the arm follows at its own step rate
    scan_q = robot.get("arm").named_pose("scan")

    def world_error():
        return max(abs(a - b) for a, b in zip(ws.world.joint_positions(), scan_q))
    assert wait_until(lambda: world_error() < 2e-3, timeout=1.0), "world arm %.4f rad from 'scan'" % world_error()
    assert core.dispatcher.execute("COMPRESSOR_ON").success
    assert core.dispatcher.execute("SET_PRESSURE 3").success
    assert abs(ws.compressor.snapshot()["pressure"] - 3.0) < 0.25
    scan = core.dispatcher.execute("SCAN")
    assert scan.success
    truth = ws.scan()
    assert {j["id"] for j in scan.result["joints"]} == {j["id"] for j in truth["joints"]}
    assert core.dispatcher.execute("STOP").success
    assert wait_until(lambda: not ws.compressor.snapshot()["motor_on"], timeout=2.0)
