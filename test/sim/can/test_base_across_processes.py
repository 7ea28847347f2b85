"""The base over udp_multicast across processes: canopen's BaseNode402 master in this process drives the four
drives of a worksite running in another process (base_worksite_child.py: the Worksite of ``python3 -m
locem_bridge.sim`` without the UR stand-in), and the base in that process's PyBullet world moves the commanded
distance (ground truth read from the child)."""
import json
import math
import os
import subprocess
import sys
import threading
import time

import canopen
import pytest

from locem_bridge.common.base_kinematics import MecanumKinematics
from locem_bridge.sim.config import resolve_relative
from locem_bridge.common.can_bus import open_bus

HERE = os.path.dirname(os.path.abspath(__file__))
SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(HERE))), "src")
CHANNEL = "239.74.163.7"


class Child:
    """The worksite process; every read is bounded."""

    def __init__(self, args, timeout=40.0):
        env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.proc = subprocess.Popen([sys.executable, os.path.join(HERE, "base_worksite_child.py")] + args,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env,
                                     universal_newlines=True, bufsize=1)
        msg = json.loads(self._readline(timeout) or '{"ready": false, "error": "exited"}')
        if not msg.get("ready"):
            self.close()
            pytest.fail("worksite child did not start: %s" % msg.get("error"))

    def _readline(self, timeout):
        out = []
        t = threading.Thread(target=lambda: out.append(self.proc.stdout.readline()), daemon=True)
        t.start()
        t.join(timeout)
        if not out:
            raise AssertionError("worksite child did not answer within %.0f s" % timeout)
        return out[0]

    def ask(self, cmd, timeout=10.0):
        self.proc.stdin.write(cmd + "\n")
        self.proc.stdin.flush()
        line = self._readline(timeout)
        if not line:
            raise AssertionError("worksite child exited (code %s)" % self.proc.poll())
        return json.loads(line)

    def close(self):
        if self.proc.poll() is None:
            try:
                self.proc.stdin.write("exit\n")
                self.proc.stdin.flush()
                self.proc.wait(timeout=15)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(timeout=10)
        for f in (self.proc.stdin, self.proc.stdout):
            try:
                f.close()
            except OSError:
                pass


def _wait_still(child, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(abs(v) < 1e-9 for v in child.ask("wheels")):
            time.sleep(0.2)              # a few more world steps (50 Hz)
            return True
        time.sleep(0.05)
    return False


def test_master_in_this_process_moves_the_base_of_a_worksite_in_another(robot_cfg, test_site_path,
                                                                        free_port_factory):
    modbus_port, can_port = free_port_factory(), free_port_factory()
    child = Child([test_site_path, "127.0.0.1", str(modbus_port), CHANNEL, str(can_port)])
    cfg = robot_cfg["robot"]["base"]["drives"]
    eds = resolve_relative(robot_cfg, robot_cfg["robot"]["base"]["eds"])
    net = canopen.Network(open_bus({"interface": "udp_multicast", "channel": CHANNEL, "port": can_port}))
    net.NOTIFIER_CYCLE = 0.1
    try:
        net.connect()
        nodes = []
        for w in cfg["wheels"]:
            node = canopen.BaseNode402(w["node_id"], eds)
            net.add_node(node)
            nodes.append(node)
        for node in nodes:
            assert node.nmt.wait_for_heartbeat(2.0) == "PRE-OPERATIONAL"
            node.setup_402_state_machine()
            node.nmt.state = "OPERATIONAL"
            node.op_mode = "PROFILED VELOCITY"
            node.state = "OPERATION ENABLED"
            assert node.state == "OPERATION ENABLED"
        wh = robot_cfg["robot"]["base"]["wheel"]
        kin = MecanumKinematics(wh["radius"], wh["half_wheelbase"], wh["half_track"])
        scale = cfg["velocity_units_per_rad_s"]

        def command(speeds):
            for node, w, s in zip(nodes, cfg["wheels"], speeds):
                node.rpdo[2]["Target velocity"].raw = int(round(w["polarity"] * s * scale))
                node.rpdo[2].transmit()

        start = child.ask("pose")
        for vx, vy, duration in ((0.1, 0.0, 2.0), (0.0, -0.1, 1.5)):
            x0, y0, yaw0 = child.ask("pose")
            t0 = time.monotonic()
            command(kin.wheel_speeds(vx, vy, 0.0))
            time.sleep(duration)
            t1 = time.monotonic()
            command([0.0] * 4)
            commanded = math.hypot(vx, vy) * (t1 - t0)       # speed x the time between start and stop command
            assert _wait_still(child), "the wheels of the other process did not stop"
            x1, y1, yaw1 = child.ask("pose")
            moved_fwd = (x1 - x0) * math.cos(yaw0) + (y1 - y0) * math.sin(yaw0)
            moved_left = -(x1 - x0) * math.sin(yaw0) + (y1 - y0) * math.cos(yaw0)
            assert commanded > 0.14
            assert moved_fwd == pytest.approx(math.copysign(commanded, vx) if vx else 0.0, abs=0.01)
            assert moved_left == pytest.approx(math.copysign(commanded, vy) if vy else 0.0, abs=0.01)
            assert yaw1 == pytest.approx(yaw0, abs=0.01)
        # the feedback the master receives (TPDO2: position 0x6064, velocity 0x606C) agrees with the ground
        # truth: wheel odometry from the four positions gives the base's total travel; every wheel is at rest
        angles = []
        for node, w in zip(nodes, cfg["wheels"]):
            assert node.tpdo[2].wait_for_reception(1.0) is not None
            assert node.tpdo_values[0x606C] == 0
            angles.append(w["polarity"] * node.tpdo_values[0x6064] / cfg["counts_per_rad"])
        odo_fwd, odo_left, odo_yaw = kin.twist(angles)       # wheel angles -> body displacement (linear map)
        x, y, yaw = child.ask("pose")
        true_fwd = (x - start[0]) * math.cos(start[2]) + (y - start[1]) * math.sin(start[2])
        true_left = -(x - start[0]) * math.sin(start[2]) + (y - start[1]) * math.cos(start[2])
        assert odo_fwd == pytest.approx(true_fwd, abs=0.002)
        assert odo_left == pytest.approx(true_left, abs=0.002)
        assert odo_yaw == pytest.approx(yaw - start[2], abs=0.005)
        for node in nodes:
            node.state = "SWITCH ON DISABLED"
    finally:
        net.disconnect()
        child.close()
