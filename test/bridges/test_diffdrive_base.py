"""The second robot's motion hardware (config/robots/diffdrive_ur5e.yaml) through the real clients: the base bridge
(python-can + canopen BaseNode402) on a DIFFERENTIAL base against its two CiA 402 drive stand-ins, and the lift
(a CiA 402 drive in profile position mode on the same bus) through LOCEM's LIFT, with the PyBullet world as the
ground truth of the base pose and of the arm mount's height."""
import copy
import math
import os
import threading
import time
import uuid

import pytest

from locem_bridge.bridges.cia402_base import Cia402Base
from locem_bridge.bridges.cia402_lift import Cia402Lift
from locem_bridge.bridges.commands_base import BaseCommands, LiftCommands
from locem_bridge.bridges.config import load_robot_config, resolve_path

from bridge_rigs import REPO, wait_until

pytestmark = pytest.mark.slow

DIFF_YAML = os.path.join(REPO, "config", "robots", "diffdrive_ur5e.yaml")


class DiffRig:
    """Two wheel drives + the lift drive on a fresh ``virtual`` CAN channel, the world with the second robot, and
    the base and lift bridges installed in a LOCEM core."""

    def __init__(self, core, time_scale=1.0):
        from locem_bridge.sim.arm_source import KinematicArm
        from locem_bridge.sim.can.drives import DriveSet, lift_drive
        from locem_bridge.sim.clock import SimClock
        from locem_bridge.sim.config import load_site
        from locem_bridge.sim.world import World
        self.robot = load_robot_config(DIFF_YAML)
        self.cfg = copy.deepcopy(self.robot["base"])
        self.cfg["drives"]["can"] = {"interface": "virtual", "channel": "diff-%s" % uuid.uuid4().hex[:8]}
        # stand-ins and bridges share this process: a long pytest session's pauses (~0.35 s seen) must not read as
        # a silent drive, so the consumers here wait 0.6 s (the robot file's 0.2 s / 0.3 s are for the real bus)
        self.cfg["drives"]["consumer_timeout_factor"] = 6.0
        lift_cfg = copy.deepcopy(self.robot["lift"])
        lift_cfg["drive"]["heartbeat_ms"] = 200
        self.clock = SimClock(time_scale)
        self.lift_drive = lift_drive(self.robot, resolve_path(self.robot, self.robot["lift"]["eds"]), self.clock.now)
        self.drives = DriveSet(self.cfg["drives"], resolve_path(self.robot, self.cfg["eds"]), self.clock.now,
                               max_wheel_speed=self.cfg["limits"]["max_wheel_speed"], others=[self.lift_drive])
        self.drives.start()
        self.world = World(load_site(), {"robot": self.robot}, self.clock,
                           arm=KinematicArm(self.robot["arm"]["named_poses"]["stow"]), drives=self.drives,
                           lift=self.lift_drive, gui=False)
        self.world.start()
        self.base = Cia402Base(self.cfg, resolve_path(self.robot, self.cfg["eds"]),
                               initial_pose=tuple(self.world.base_pose()))
        self.lift = Cia402Lift(lift_cfg, self.cfg["drives"]["can"],
                               resolve_path(self.robot, self.robot["lift"]["eds"]))
        self.base.start()
        self.lift.start()
        core.install(BaseCommands(self.base))
        core.install(LiftCommands(self.lift))
        assert self.base.wait_ready(10.0), self.base.health()
        assert self.lift.wait_ready(10.0), self.lift.health()

    def still(self):
        return all(abs(v) < 1e-9 for v in self.drives.wheel_speeds())

    def close(self):
        self.base.close()
        self.lift.close()
        self.world.close()
        self.drives.stop()


@pytest.fixture
def diff(core):
    rig = DiffRig(core)
    yield rig
    rig.close()


def run(core, text):
    return core.dispatcher.execute(text)


def truth_error(world, goal):
    x, y, th = world.base_pose()
    return math.hypot(x - goal[0], y - goal[1]), abs((th - goal[2] + math.pi) % (2 * math.pi) - math.pi)


class Sampler:
    """Ground truth while a command runs: wheel speeds of the drives and the world's base pose, every 10 ms."""

    def __init__(self, rig):
        self.rig = rig
        self.wheels, self.poses = [], []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            self.wheels.append(self.rig.drives.wheel_speeds())
            self.poses.append((self.rig.clock.now(), self.rig.world.base_pose()))
            time.sleep(0.01)

    def close(self):
        self._stop.set()
        self._thread.join(1.0)


def test_the_differential_base_drives_to_a_pose_within_the_completion_tolerance_and_its_limits(diff, core):
    limits = diff.cfg["limits"]
    x0, y0, th0 = diff.world.base_pose()
    goal = (x0 + 0.9 * math.cos(th0) + 0.3 * math.sin(th0), y0 + 0.9 * math.sin(th0) - 0.3 * math.cos(th0),
            th0 - 0.6)
    probe = Sampler(diff)
    try:
        r = run(core, "GOTO %g %g %g speed=0.5" % goal)
    finally:
        probe.close()
    assert r.success, r.message
    time.sleep(0.1)
    d, a = truth_error(diff.world, goal)
    assert d < 0.02 and a < math.radians(1.0), (d, math.degrees(a))
    assert diff.still()
    # limits: no wheel above max_wheel_speed, body speed and turn rate within the robot file's limits
    peak_wheel = max(abs(w) for ws in probe.wheels for w in ws)
    assert peak_wheel <= limits["max_wheel_speed"] + 1e-6, peak_wheel
    kin = diff.world.kinematics
    twists = [kin.twist(ws) for ws in probe.wheels]
    assert max(abs(t[0]) for t in twists) <= limits["max_linear_velocity"] * 1.02
    assert max(abs(t[2]) for t in twists) <= limits["max_angular_velocity"] * 1.02
    # the ground truth never moved sideways: a differential base rolls along its heading
    assert all(abs(t[1]) < 1e-9 for t in twists)


def test_a_purely_lateral_request_turns_drives_and_turns_back(diff, core):
    x0, y0, th0 = diff.world.base_pose()
    probe = Sampler(diff)
    try:
        r = run(core, "MOVE_BASE_REL 0 0.5 0")
    finally:
        probe.close()
    assert r.success, r.message
    goal = (x0 - 0.5 * math.sin(th0), y0 + 0.5 * math.cos(th0), th0)
    time.sleep(0.1)
    d, a = truth_error(diff.world, goal)
    assert d < 0.02 and a < math.radians(1.0), (d, math.degrees(a))
    # on its way it faced the side (a quarter turn, either way: forward or reversing), then turned back
    turned = max(abs((p[2] - th0 + math.pi) % (2 * math.pi) - math.pi) for _, p in probe.poses)
    assert turned > math.radians(80), math.degrees(turned)
    print("lateral 0.5 m: %.1f s, max heading change %.0f deg, error %.1f mm / %.2f deg"
          % (r.result["duration_s"], math.degrees(turned), d * 1000, math.degrees(a)))


def test_goto_behind_the_base_reverses_instead_of_turning_around(diff, core):
    x0, y0, th0 = diff.world.base_pose()
    goal = (x0 - 0.6 * math.cos(th0), y0 - 0.6 * math.sin(th0), th0)
    probe = Sampler(diff)
    try:
        r = run(core, "GOTO %g %g %g" % goal)
    finally:
        probe.close()
    assert r.success, r.message
    d, a = truth_error(diff.world, goal)
    assert d < 0.02 and a < math.radians(1.0), (d, math.degrees(a))
    turned = max(abs((p[2] - th0 + math.pi) % (2 * math.pi) - math.pi) for _, p in probe.poses)
    assert turned < math.radians(10), math.degrees(turned)


def test_lift_reaches_the_height_and_the_arm_mount_moves_with_it(diff, core):
    lo, hi = diff.robot["lift"]["range"]
    z0 = diff.world.lift_height()
    arm_z0 = diff.world.arm_base_pose()[0][2]
    r = run(core, "LIFT z=1.3")
    assert r.success, r.message
    assert abs(r.result["height"] - 1.3) <= diff.robot["lift"]["tolerance"]
    assert abs(diff.world.lift_height() - 1.3) < 1e-3          # ground truth: the drive stand-in's axis
    assert abs(diff.world.arm_base_pose()[0][2] - arm_z0 - (1.3 - z0)) < 2e-3   # the arm's base frame rose with it
    status = run(core, "STATUS").result["health"]["lift"]
    assert abs(status["height"] - 1.3) < 1e-3 and status["range"] == [lo, hi]
    # travel time of a trapezoid profile at the configured speed and acceleration (sim time scale 1)
    v, acc = diff.robot["lift"]["max_velocity"], diff.robot["lift"]["acceleration"]
    nominal = (1.3 - z0) / v + v / acc
    assert r.result["duration_s"] < nominal + 1.0, (r.result["duration_s"], nominal)
    assert run(core, "LIFT z=%g" % lo).success
    assert abs(diff.world.lift_height() - lo) < 1e-3
    again = run(core, "LIFT z=%g" % lo)                   # already there: answered at once, no set-point
    assert again.success and again.result["duration_s"] == 0.0 and again.result["error"] < 1e-3, again.result


def test_lift_refuses_a_height_outside_its_range_naming_the_range_and_nothing_moves(diff, core):
    lo, hi = diff.robot["lift"]["range"]
    before = diff.world.lift_height()
    setpoint = diff.lift_drive.setpoint
    for z in (hi + 0.2, lo - 0.1):
        r = run(core, "LIFT z=%g" % z)
        assert r.code.value == "INVALID_ARGUMENT", r
        assert "[%g, %g]" % (lo, hi) in r.message and "robot.lift.range" in r.message, r.message
    grammar = run(core, "LIFT z=7")                           # beyond the grammar's own bound
    assert grammar.code.value == "INVALID_ARGUMENT" and "z" in grammar.message
    time.sleep(0.2)
    assert diff.lift_drive.setpoint == setpoint and diff.world.lift_height() == before


def test_stop_during_lift_brakes_the_axis_and_ends_the_command_aborted(diff, core):
    from locem_bridge.locem.registry import Interface
    execution = core.dispatcher.submit("LIFT z=1.4", Interface.SERVICE)
    assert wait_until(lambda: abs(diff.lift_drive.velocity) > 0.1, timeout=5.0)
    assert run(core, "STOP").success
    assert execution.wait(3.0).code.value == "ABORTED"
    assert wait_until(lambda: diff.lift_drive.velocity == 0.0, timeout=2.0)
    time.sleep(0.2)                                           # a world step or two: the world shows where it stands
    held = diff.world.lift_height()
    time.sleep(0.5)
    assert abs(diff.world.lift_height() - held) < 1e-6 and held < 1.4 - 0.05


def test_wall_targets_in_the_arm_frame_follow_the_lift_height(diff, core):
    """A map point a wall command works on lands in the arm's base frame at the lift's height now: after LIFT the
    same point is lower in the arm frame by exactly the lift's travel, nothing else changes."""
    from locem_bridge.bridges.commands_wall import WallCommands
    wall = WallCommands(diff.robot, base=diff.base, lift=diff.lift)
    x, y, th = diff.base.pose()
    point = [x + 0.9 * math.cos(th), y + 0.9 * math.sin(th), 1.2]
    normal = [-math.cos(th), -math.sin(th), 0.0]
    before = wall.to_arm(point, normal)
    z0 = diff.lift.height()
    assert run(core, "LIFT z=1.25").success
    after = wall.to_arm(point, normal)
    rise = diff.lift.height() - z0
    assert rise == pytest.approx(1.25 - z0, abs=diff.robot["lift"]["tolerance"])
    assert after[2] == pytest.approx(before[2] - rise, abs=1e-9)
    assert after[:2] == pytest.approx(before[:2], abs=1e-9) and after[3:] == pytest.approx(before[3:], abs=1e-9)
