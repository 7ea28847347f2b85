"""Time scale: the simulated worksite runs 10x faster than real time with the real base bridge on it.

The bus protocol keeps its wall-clock behaviour (heartbeats from a helper process, TPDO event timer), the physics
runs on sim time, and the ground-truth base pose is exact however much sim time one world step covers."""
import copy
import math
import os
import random
import signal
import subprocess
import sys
import time

import can
import pytest

from locem_bridge.bridges.cia402_base import Cia402Base
from locem_bridge.bridges.commands_base import BaseCommands
from locem_bridge.bridges.config import load_robot_config, resolve_path
from locem_bridge.locem.core import LocemCore
from locem_bridge.locem.registry import Interface
from locem_bridge.common.base_kinematics import MecanumKinematics
from locem_bridge.sim.arm_source import KinematicArm
from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.config import resolve_relative
from locem_bridge.sim.can.drives import DriveSet
from locem_bridge.sim.world import World
from locem_bridge.sim.worksite import Worksite

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ROBOT_YAML = os.path.join(ROOT, "config", "robots", "rbkairos_ur10e.yaml")
SRC = os.path.join(ROOT, "src")


def _group():
    return "239.74.%d.%d" % (random.randint(171, 250), random.randint(1, 250))


def _wait_until(predicate, timeout, period=0.02):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(period)
    return predicate()


class HeartbeatLog(can.Listener):
    """Heartbeat arrivals per node as the base bridge's notifier delivers them (the consumer's view)."""

    def __init__(self):
        self.seen = {}
        self.states = {}

    def on_message_received(self, msg):
        if 0x701 <= msg.arbitration_id <= 0x77F and len(msg.data) == 1:
            nid = msg.arbitration_id - 0x700
            self.seen[nid] = self.seen.get(nid, 0) + 1
            self.states[nid] = msg.data[0]


@pytest.fixture
def fast_stack(site_cfg, robot_cfg, port, free_port_factory):
    """Worksite at time scale 10 on udp_multicast (drive heartbeats from the helper process) and the real base
    bridge (canopen BaseNode402 master, 2 x 100 ms heartbeat consumer) in LOCEM's dispatcher."""
    group, can_port = _group(), free_port_factory()
    ws = Worksite(site_cfg, robot_cfg, modbus_port=port, can_interface="udp_multicast", can_channel=group,
                  can_port=can_port, time_scale=10.0, with_ur=False)
    ws.start()
    robot = load_robot_config(ROBOT_YAML, {"base": {"drives": {"can": {"interface": "udp_multicast",
                                                                          "channel": group, "port": can_port}}}})
    base = Cia402Base(robot["base"], resolve_path(robot, robot["base"]["eds"]),
                      initial_pose=tuple(ws.world.base_pose()))
    core = LocemCore(grace=0.5)
    core.install(BaseCommands(base))
    base.start()
    log = HeartbeatLog()
    try:
        assert base.wait_ready(20.0), base.health()
        base.network.notifier.add_listener(log)
        yield ws, base, core, log
    finally:
        core.close()
        base.close()
        ws.stop()


def _truth_error(ws, goal):
    x, y, th = ws.world.base_pose()
    return math.hypot(x - goal[0], y - goal[1]), abs((th - goal[2] + math.pi) % (2 * math.pi) - math.pi)


def test_goto_at_time_scale_10_through_the_base_bridge_arrives_without_heartbeat_loss(fast_stack):
    ws, base, core, log = fast_stack
    assert ws.clock.time_scale == 10.0
    helper = ws.drives.heartbeat_process
    assert helper is not None and helper.pid is not None           # heartbeats come from the helper process
    x0, y0, th0 = ws.world.base_pose()
    goals = [(x0 + 0.5, y0 + 0.2, th0 + 0.4), (x0 - 0.3, y0 + 0.4, th0 - 0.3), (x0, y0, th0)]
    t0 = time.monotonic()
    for goal in goals:
        r = core.dispatcher.execute("GOTO %.4f %.4f %.4f speed=0.5" % goal)
        assert r.success, r.message                                   # a heartbeat loss would end it HARDWARE_ERROR
        assert _wait_until(lambda: all(abs(v) < 1e-9 for v in ws.drives.wheel_speeds()), 2.0)
        time.sleep(0.05)                                              # one more world step
        d, a = _truth_error(ws, goal)
        assert d < 0.02 and a < math.radians(1.0), (goal, d, math.degrees(a))
    wall = time.monotonic() - t0
    assert base.health()["fault"] == ""
    # every drive kept beating with its NMT state (OPERATIONAL = 0x05) the whole time
    assert sorted(log.seen) == base.node_ids
    assert all(n >= 0.5 * wall / 0.1 for n in log.seen.values()), (log.seen, wall)
    assert all(s == 0x05 for s in log.states.values())


def test_heartbeat_loss_at_time_scale_10_stops_the_base_and_it_recovers(fast_stack):
    ws, base, core, log = fast_stack
    x0, y0, th0 = ws.world.base_pose()
    execution = core.dispatcher.submit("GOTO %.4f %.4f %.4f speed=0.3" % (x0 + 0.6, y0 + 0.3, th0), Interface.SERVICE)
    assert _wait_until(lambda: any(abs(v) > 0.1 for v in ws.drives.wheel_speeds()), 5.0)
    ws.inject_fault("drive_heartbeat_loss", node_id=2)       # node 2 drops off the bus: the helper stops its beat
    response = execution.wait(10.0)
    assert not response.success and "heartbeat lost" in response.message and "drive 2" in response.message
    assert _wait_until(lambda: all(abs(v) < 1e-9 for v in ws.drives.wheel_speeds()), 2.0)
    ws.clear_fault("drive_heartbeat_loss", node_id=2)         # node reboots; the bridge enables it again
    assert _wait_until(lambda: base.health()["fault"] == "" and base.health()["link"] == "up", 15.0), base.health()
    goal = (x0, y0, th0)
    r = core.dispatcher.execute("GOTO %.4f %.4f %.4f speed=0.5" % goal)
    assert r.success, r.message
    assert _wait_until(lambda: all(abs(v) < 1e-9 for v in ws.drives.wheel_speeds()), 2.0)


HELPER_PARENT = r"""
import sys, time
from locem_bridge.sim.can.heartbeat import HeartbeatProcess
hp = HeartbeatProcess({"interface": "udp_multicast", "channel": sys.argv[1], "port": int(sys.argv[2])})
hp.start()
hp.send_periodic(0x77E, bytes([0x7F]), 0.05)
print(hp.pid, flush=True)
time.sleep(60)
"""


def test_drive_heartbeats_stop_when_the_simulator_process_is_killed(free_port_factory):
    group, can_port = _group(), free_port_factory()
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    parent = subprocess.Popen([sys.executable, "-c", HELPER_PARENT, group, str(can_port)], stdout=subprocess.PIPE,
                              env=env, text=True)
    listener = can.Bus(interface="udp_multicast", channel=group, port=can_port, fd=False)
    try:
        helper_pid = int(parent.stdout.readline())

        def beats(window):
            end, n = time.monotonic() + window, 0
            while time.monotonic() < end:
                msg = listener.recv(0.05)
                if msg is not None and msg.arbitration_id == 0x77E:
                    assert bytes(msg.data) == b"\x7f"             # PRE-OPERATIONAL
                    n += 1
            return n

        assert beats(0.5) >= 3
        parent.send_signal(signal.SIGKILL)                      # the simulator dies without cleaning up
        parent.wait(5)
        assert _wait_until(lambda: not os.path.exists("/proc/%d" % helper_pid)
                           or open("/proc/%d/stat" % helper_pid).read().split()[2] == "Z", 5.0)
        beats(0.2)                                             # frames already in flight
        assert beats(0.5) == 0
    finally:
        listener.shutdown()
        if parent.poll() is None:
            parent.kill()
            parent.wait()


def test_ctrl_c_to_the_process_group_leaves_the_helper_to_its_parent(free_port_factory):
    """roslaunch's SIGINT (or Ctrl-C) reaches the helper with its parent: it keeps sending until the parent
    closes it, then ends with exit code 0 (no KeyboardInterrupt traceback in the launch output)."""
    from locem_bridge.sim.can.heartbeat import HeartbeatProcess
    group, can_port = _group(), free_port_factory()
    hp = HeartbeatProcess({"interface": "udp_multicast", "channel": group, "port": can_port})
    listener = can.Bus(interface="udp_multicast", channel=group, port=can_port, fd=False)
    try:
        hp.start()
        hp.send_periodic(0x77D, bytes([0x05]), 0.05)
        proc = hp._proc

        def beats(window):
            end, n = time.monotonic() + window, 0
            while time.monotonic() < end:
                msg = listener.recv(0.05)
                n += msg is not None and msg.arbitration_id == 0x77D
            return n
        assert beats(0.5) >= 3
        os.kill(hp.pid, signal.SIGINT)
        beats(0.1)
        assert proc.poll() is None and beats(0.5) >= 3          # still beating: its parent decides
        hp.close()
        assert proc.returncode == 0
    finally:
        listener.shutdown()
        hp.close()


def _reference_pose(kin, start, wheel_targets, accel, t_end, h=1e-4):
    """Pose after ``t_end`` s of every wheel ramping from rest to its target at ``accel`` (fine integration)."""
    x, y, th = start
    t = 0.0
    while t < t_end - 1e-12:
        step = min(h, t_end - t)
        tm = t + step / 2
        speeds = [math.copysign(min(accel * tm, abs(v)), v) for v in wheel_targets]
        vx, vy, w = kin.twist(speeds)                      # body twist of the wheel speeds (per second)
        thm = th + w * step / 2
        x += (math.cos(thm) * vx - math.sin(thm) * vy) * step
        y += (math.sin(thm) * vx + math.cos(thm) * vy) * step
        th += w * step
        t += step
    return x, y, th


class ManualWall:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


@pytest.mark.parametrize("wall_steps", [[0.02] * 50, [0.02, 0.1, 0.02, 0.25, 0.02, 0.02, 0.3, 0.27]],
                         ids=["regular", "stalled"])
def test_ground_truth_base_pose_is_exact_whatever_sim_time_a_world_step_covers(site_cfg, robot_cfg, wall_steps):
    wall = ManualWall()
    clock = SimClock(20.0, wall=wall)                  # one 20 ms world step = 0.4 s of sim time
    cfg = copy.deepcopy(robot_cfg["robot"]["base"]["drives"])
    cfg["can"] = {"interface": "virtual", "channel": "exact-%d-%d" % (os.getpid(), random.randint(0, 10 ** 6))}
    eds = resolve_relative(robot_cfg, robot_cfg["robot"]["base"]["eds"])
    drives = DriveSet(cfg, eds, clock.now)
    drives.start()
    world = World(copy.deepcopy(site_cfg), robot_cfg, clock, arm=KinematicArm(), drives=drives, gui=False)
    try:
        world.set_base_pose(1.5, 1.5, 0.3)
        wh = robot_cfg["robot"]["base"]["wheel"]
        kin = MecanumKinematics(wh["radius"], wh["half_wheelbase"], wh["half_track"])
        wheel_targets = kin.wheel_speeds(0.05, 0.02, 0.6)     # a slow arc with a fast turn: 0.24 rad per step
        for d, p, v in zip(drives.drives, drives.polarity, wheel_targets):
            d._controlword(0x06)
            d._controlword(0x0F)
            d.mode = 3
            d.target_units = int(round(p * v * d.vel_scale))
        exact_targets = [p * d.target_units / d.vel_scale for d, p in zip(drives.drives, drives.polarity)]
        for step in wall_steps:
            wall.t += step
            world.step()
        accel = cfg["profile_acceleration"]
        ref = _reference_pose(kin, (1.5, 1.5, 0.3), exact_targets, accel, clock.now())
        x, y, th = world.base_pose()
        assert abs(th - ref[2]) < 1e-6
        assert math.hypot(x - ref[0], y - ref[1]) < 2e-4, (x - ref[0], y - ref[1])
    finally:
        world.close()
        drives.stop()
