"""The base bridge (python-can + canopen BaseNode402) against four CiA 402 drive stand-ins and the PyBullet world."""
import math
import threading
import time

import pytest

from locem_bridge.bridges.cia402_base import Cia402Base
from locem_bridge.bridges.commands_base import BaseCommands
from locem_bridge.common.health import ERROR as HEALTH_ERROR, OK as HEALTH_OK, grade as health_level
from locem_bridge.locem.registry import Interface

from bridge_rigs import BaseRig, HeartbeatWatch, last_motion, sim_time_of, wait_until

pytestmark = pytest.mark.slow


def _make(robot, core, deadline=None):
    rig = BaseRig(robot, time_scale=1.0)
    cfg = dict(rig.cfg)
    cfg["named_poses"] = {"door": [2.0, 1.2, 0.0]}
    if deadline is not None:
        cfg["deadline"] = deadline
    base = Cia402Base(cfg, rig.eds, initial_pose=tuple(rig.world.base_pose()))
    base.start()
    core.install(BaseCommands(base))
    assert base.wait_ready(10.0), base.health()
    return rig, base


@pytest.fixture
def rig(robot, core):
    rig, base = _make(robot, core)
    yield rig, base
    base.close()
    rig.close()


@pytest.fixture
def rig_short_deadline(robot, core):
    """GOTO deadlines at 20 % of the nominal travel time, no margin (robot.base.deadline)."""
    rig, base = _make(robot, core, deadline={"scale": 0.2, "margin": 0.0})
    yield rig, base
    base.close()
    rig.close()


def run(core, text):
    return core.dispatcher.execute(text)


def truth_error(world, goal):
    x, y, th = world.base_pose()
    return math.hypot(x - goal[0], y - goal[1]), abs((th - goal[2] + math.pi) % (2 * math.pi) - math.pi)


def test_goto_reaches_the_goal_within_2cm_and_1deg_of_ground_truth(rig, core):
    r_, base = rig
    goal = (2.9, 1.35, 1.2)
    r = run(core, "GOTO %g %g %g speed=0.5" % goal)
    assert r.success, r.message
    time.sleep(0.1)
    d, a = truth_error(r_.world, goal)
    assert d < 0.02 and a < math.radians(1.0), (d, math.degrees(a))
    p = run(core, "GET_POSE").result["pose"]
    assert math.hypot(p[0] - goal[0], p[1] - goal[1]) < 0.02
    assert r_.still()


def test_move_base_rel_and_goto_tag(rig, core):
    r_, base = rig
    x0, y0, th0 = r_.world.base_pose()
    r = run(core, "MOVE_BASE_REL 0.3 0.1 0.2")
    assert r.success, r.message
    goal = (x0 + math.cos(th0) * 0.3 - math.sin(th0) * 0.1, y0 + math.sin(th0) * 0.3 + math.cos(th0) * 0.1, th0 + 0.2)
    d, a = truth_error(r_.world, goal)
    assert d < 0.02 and a < math.radians(1.0), (d, math.degrees(a))
    r = run(core, "GOTO_TAG door")
    assert r.success, r.message
    d, a = truth_error(r_.world, (2.0, 1.2, 0.0))
    assert d < 0.02 and a < math.radians(1.0)
    bad = run(core, "GOTO_TAG kitchen")
    assert bad.code.value == "INVALID_ARGUMENT" and "door" in bad.message


def _wheels_stopped_within(rig, since_sim, budget_sim, timeout=2.0):
    """Sim time at which every wheel stood still (None if not within ``timeout`` s wall)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if rig.still():
            return rig.clock.now() - since_sim
        time.sleep(0.002)
    return None


def test_stop_during_goto_stops_the_base_within_200ms_sim_time(rig, core):
    r_, base = rig
    execution = core.dispatcher.submit("GOTO 2.4 3.0 1.5708 speed=0.8", Interface.SERVICE)
    assert wait_until(lambda: abs(r_.drives.wheel_speeds()[0]) > 3.0, timeout=5.0)
    t_stop = r_.clock.now()
    assert run(core, "STOP").success
    took = _wheels_stopped_within(r_, t_stop, 0.2)
    assert took is not None and took < 0.2, took
    assert execution.wait(2.0).code.value == "ABORTED"
    time.sleep(0.3)
    assert r_.still()


def test_action_cancel_stops_the_base(rig, core):
    r_, base = rig
    execution = core.dispatcher.submit("GOTO 2.4 3.0 1.5708 speed=0.8", Interface.ACTION)
    assert wait_until(lambda: abs(r_.drives.wheel_speeds()[0]) > 3.0, timeout=5.0)
    t_stop = r_.clock.now()
    execution.cancel("action goal canceled by its client")
    took = _wheels_stopped_within(r_, t_stop, 0.2)
    assert took is not None and took < 0.2, took
    assert execution.wait(2.0).code.value == "ABORTED"


def test_cmd_vel_twist_moves_the_base_and_stops_when_it_goes_stale(rig, core):
    r_, base = rig
    x0, y0, th0 = r_.world.base_pose()
    end = time.monotonic() + 0.6
    while time.monotonic() < end:
        base.set_velocity(0.3, 0.0, 0.0, hold=0.2)
        time.sleep(0.05)
    assert wait_until(r_.still, timeout=2.0)
    x1, y1, _ = r_.world.base_pose()
    moved = (x1 - x0) * math.cos(th0) + (y1 - y0) * math.sin(th0)
    assert 0.08 < moved < 0.3


def test_drive_heartbeat_loss_stops_the_base_and_fails_the_goto(rig, core):
    r_, base = rig
    # robot YAML: heartbeat_ms 100 x consumer_timeout_factor 2 = a drive is silent after 200 ms
    assert base.hb_timeout == pytest.approx(0.2)
    watch = HeartbeatWatch(r_.cfg["drives"]["can"])
    try:
        execution = core.dispatcher.submit("GOTO 2.4 3.0 1.5708 speed=0.8", Interface.SERVICE)
        assert wait_until(lambda: abs(r_.drives.wheel_speeds()[0]) > 3.0, timeout=5.0)
        node = r_.drives.drive(3).node_id
        r_.drives.drive(3).inject_heartbeat_loss()
        t_loss = r_.clock.now()
        assert wait_until(lambda: base.health()["fault"], timeout=1.0)
        t_detect = r_.clock.now()
        took = _wheels_stopped_within(r_, t_detect, 0.1)
        assert took is not None and took < 0.1, "base stood still %.3f s after the loss was detected" % took
        assert t_detect - t_loss < 0.1 + base.hb_timeout
        # from the last heartbeat the drive sent (seen on the bus) to the base standing still (ground truth of
        # every wheel): within the configured consumer timeout + 100 ms
        last_hb = sim_time_of(r_.clock, watch.last[node])
        still = last_motion(r_.drives, last_hb, r_.clock.now())
        print("last heartbeat -> base still: %.0f ms (consumer timeout %.0f ms)"
              % ((still - last_hb) * 1000, base.hb_timeout * 1000))
        assert still - last_hb <= base.hb_timeout + 0.1, (
            "base stood still %.0f ms after the last heartbeat (consumer timeout %.0f ms)"
            % ((still - last_hb) * 1000, base.hb_timeout * 1000))
    finally:
        watch.close()
    r = execution.wait(2.0)
    assert r.code.value == "HARDWARE_ERROR" and "heartbeat" in r.message
    health = core.dispatcher.health()["base"]             # the source of the node's /diagnostics
    assert health_level(health) == HEALTH_ERROR and "heartbeat lost" in health["last_error"], health
    assert run(core, "GOTO 2.4 1.6 1.5708").code.value in ("HARDWARE_ERROR", "NOT_READY")
    assert "heartbeat" in run(core, "STATUS").result["health"]["base"]["fault"]
    time.sleep(0.3)
    assert r_.still()
    # the drive comes back: the bridge enables it again, the base obeys again
    r_.drives.drive(3).restore()
    assert wait_until(lambda: base.health()["link"] == "up" and not base.health()["fault"], timeout=10.0)
    assert health_level(core.dispatcher.health()["base"]) == HEALTH_OK
    assert run(core, "MOVE_BASE_REL 0.05 0 0").success


def test_stop_base_ends_the_goto_like_stop_does(rig, core):
    r_, base = rig
    execution = core.dispatcher.submit("GOTO 2.4 3.0 1.5708 speed=0.8", Interface.ACTION)
    assert wait_until(lambda: abs(r_.drives.wheel_speeds()[0]) > 3.0, timeout=5.0)
    t_stop = r_.clock.now()
    r = run(core, "STOP_BASE")
    assert r.success and r.result["stopped"] is True, r
    took = _wheels_stopped_within(r_, t_stop, 0.2)
    assert took is not None and took < 0.2, took
    ended = execution.wait(2.0)
    assert ended.code.value == "ABORTED" and "STOP_BASE" in ended.message, ended
    time.sleep(0.3)
    assert r_.still()
    # nothing latched: the base obeys the next command
    assert run(core, "MOVE_BASE_REL 0.05 0 0").success


def test_goto_overrunning_its_deadline_ends_timeout_with_the_base_stopped(rig_short_deadline, core):
    r_, base = rig_short_deadline
    x0, y0, _ = r_.world.base_pose()
    goal = (2.4, 3.0, 1.5708)
    t0 = time.monotonic()
    r = run(core, "GOTO %g %g %g speed=0.5" % goal)
    took = time.monotonic() - t0
    assert r.code.value == "TIMEOUT" and "did not reach" in r.message, r
    # the deadline is 20 % of the nominal travel time: the base is stopped on its way
    dist = math.hypot(goal[0] - x0, goal[1] - y0)
    assert took < 0.2 * (dist / 0.5 + 2 * 0.5 / base.lin_accel + base.max_ang / base.ang_accel) + 1.0
    assert wait_until(r_.still, timeout=1.0), r_.drives.wheel_speeds()
    x, y, _ = r_.world.base_pose()
    assert math.hypot(goal[0] - x, goal[1] - y) > 0.2 * dist, "the GOTO was not cut short"
    time.sleep(0.3)
    assert r_.still()


def test_drive_fault_is_latched_until_reset_base(rig, core):
    r_, base = rig
    execution = core.dispatcher.submit("GOTO 2.4 3.0 1.5708 speed=0.8", Interface.SERVICE)
    assert wait_until(lambda: abs(r_.drives.wheel_speeds()[0]) > 3.0, timeout=5.0)
    r_.drives.drive(1).inject_fault()
    r = execution.wait(3.0)
    assert r is not None and r.code.value == "HARDWARE_ERROR" and "FAULT" in r.message, r
    assert wait_until(r_.still, timeout=1.0), r_.drives.wheel_speeds()
    time.sleep(1.0)                                   # not cleared by itself
    assert "FAULT" in base.health()["fault"], base.health()
    refused = run(core, "GOTO 2.4 1.6 1.5708")
    assert refused.code.value == "HARDWARE_ERROR", refused
    reset = run(core, "RESET_BASE")
    assert reset.success, reset.message
    assert "FAULT" in reset.result["cleared"]
    moved = run(core, "MOVE_BASE_REL 0.05 0 0")
    assert moved.success, moved


def test_a_fix_replaces_the_drifted_odometry_pose_only_while_standing_still(rig, core):
    r_, base = rig
    x, y, th = r_.world.base_pose()
    base.set_pose(x + 0.03, y - 0.02, th + 0.01)           # odometry drifted 3.6 cm / 0.6 deg from the truth
    assert base.correct_pose(x, y, th)                     # standing still: the fix is taken
    assert max(abs(a - b) for a, b in zip(base.pose(), (x, y, th))) < 1e-9
    # during a GOTO the fix is refused and the odometry pose is left alone
    refused = []
    done = threading.Event()

    def drive():
        core.dispatcher.execute("GOTO %g %g %g speed=0.3" % (x + 0.4, y, th))
        done.set()
    threading.Thread(target=drive, daemon=True).start()
    assert wait_until(lambda: abs(base.twist()[0]) + abs(base.twist()[1]) > 0.05, timeout=5.0)
    before = base.pose()
    refused.append(base.correct_pose(before[0] - 1.0, before[1], before[2]))
    assert refused == [False] and abs(base.pose()[0] - (before[0] - 1.0)) > 0.5
    assert done.wait(20.0)
    gx, gy, _ = r_.world.base_pose()
    assert abs(gx - (x + 0.4)) < 0.03 and abs(gy - y) < 0.03   # the GOTO was not thrown off by the refused fix


def test_fixes_while_standing_still_are_averaged_and_a_move_starts_afresh(rig, core):
    import random
    r_, base = rig
    x, y, th = r_.world.base_pose()
    base.set_pose(x + 0.03, y - 0.02, th + 0.01)
    rnd = random.Random(7)
    fixes = [(x + rnd.gauss(0, 0.002), y + rnd.gauss(0, 0.002), th + rnd.gauss(0, 0.002)) for _ in range(14)]
    assert base.correct_pose(*fixes[0])
    assert base.pose() == pytest.approx(list(fixes[0]), abs=1e-12)          # the first fix replaces the drift
    for f in fixes[1:]:
        assert base.correct_pose(*f)
    window = fixes[-base.fix_window:]                                         # then: the mean of the last 10
    mean = [sum(f[i] for f in window) / len(window) for i in range(3)]
    assert base.pose() == pytest.approx(mean, abs=1e-6)
    assert math.hypot(base.pose()[0] - x, base.pose()[1] - y) < 0.002       # closer than one fix's 2 mm sigma
    # a move clears the fixes: the first fix after it replaces the pose again, nothing from before is averaged in
    moved = run(core, "MOVE_BASE_REL 0.1 0 0")
    assert moved.success, moved
    assert wait_until(lambda: math.hypot(*base.twist()[:2]) < 0.001, timeout=5.0)
    x2, y2, th2 = r_.world.base_pose()
    assert base.correct_pose(x2, y2, th2)
    assert base.pose() == pytest.approx([x2, y2, th2], abs=1e-12)
