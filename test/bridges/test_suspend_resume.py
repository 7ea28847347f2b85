"""Suspend, resume and halt a running device command (the skill methods of LOCEM's commands) through one LOCEM
core with every bridge against the worksite stand-ins (UR controller, compressor, drives, PyBullet world): the
devices come to rest within 300 ms of sim time, the valve closes and the compressor keeps its pressure, the sander
lifts off the wall, and after Resume the work goes on from the stop point with no gap and no second coat (the world's pass maps)."""
import time

import numpy as np
import pytest

from locem_bridge.common.raster_progress import parse_progress_text
from locem_bridge.locem.registry import Interface
from locem_bridge.sim.outcome import PASS_GRID, TAPE_BIN

from bridge_rigs import last_motion, wait_until

pytest.importorskip("rtde_control")
pytestmark = pytest.mark.slow

NORMAL = "0 -1 0"
JOINT = "wall_1_joint_1"      # the horizontal joint at z = 1.25 m, x 1.8 .. 3.0, y = 3.6
# wall_1 (s = x - 1.8): the area s 0.2 .. 1.0, lanes at z 0.9, 1.2, 1.5 (0.8 m each, run_in 0)
AREA = "SPRAY_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.3 standoff=0.3 speed=0.1 pressure=3.5 run_in=0" % NORMAL
REST_S = 0.3                  # sim s from Suspend to every device at rest (the goal)
LONGEST_FLAW_M = 0.02         # longest stretch with no coat or a second coat at the resume point


def run(core, text):
    return core.dispatcher.execute(text)


def _rest_times(rig, t0, valve=True, timeout=3.0):
    """Sim seconds after ``t0`` at which the arm was first seen still and the valve closed (polled, ~1 ms)."""
    arm_at = valve_at = None
    end = time.monotonic() + timeout
    while (arm_at is None or (valve and valve_at is None)) and time.monotonic() < end:
        now = rig.clock.now()
        if arm_at is None and not rig.standin.get_state()["moving"]:
            arm_at = now - t0
        if valve and valve_at is None and not rig.model.snapshot()["valve_open"]:
            valve_at = now - t0
    return arm_at, valve_at


def _runs(flags, cell):
    """Lengths (m) of the runs of True in ``flags``."""
    out, n = [], 0
    for f in list(flags) + [False]:
        if f:
            n += 1
        elif n:
            out.append(n * cell)
            n = 0
    return out


def _transitions(events, exec_id):
    return [(e.transition.name, e.transition.method) for e in events if e.id == exec_id and e.transition]


def test_spray_suspended_mid_lane_rests_at_once_and_resumes_with_no_gap_and_no_second_coat(wall, core):
    rig, _ = wall
    rig.world.mount_tool("spray_gun")
    assert run(core, "MOUNT_TOOL spray_gun").success
    assert run(core, "GOTO 2.4 2.5 1.5708").success
    events = []
    core.dispatcher.add_listener(events.append)
    feedback = []
    ex = core.dispatcher.submit(AREA, Interface.ACTION, listener=lambda e: feedback.append(e.message))
    # in the middle of lane 1 (raster metres 0.8 .. 1.6)
    assert wait_until(lambda: any((parse_progress_text(m) or (0,))[0] >= 1.15 for m in feedback), timeout=60.0)
    t0 = rig.clock.now()
    r = run(core, "SUSPEND id=%d cause=person_in_bay" % ex.id)
    assert r.success and r.result["states"] == {str(ex.id): "Suspended"}, r
    arm_at, valve_at = _rest_times(rig, t0)
    print("spray: valve closed %.3f s, arm at rest %.3f s sim after Suspend" % (valve_at, arm_at))
    assert valve_at is not None and valve_at <= REST_S, valve_at
    assert arm_at is not None and arm_at <= REST_S, "arm still moving %.3f s sim after Suspend" % arm_at
    # suspended for 10 s of sim time: nothing moves, the valve stays closed, the compressor holds its pressure
    while rig.clock.now() < t0 + 10.0:
        time.sleep(0.05)
        truth = rig.model.snapshot()
        assert not truth["valve_open"] and truth["motor_on"], truth
        assert not rig.standin.get_state()["moving"]
    assert truth["pressure"] == pytest.approx(3.5, abs=0.3), truth
    assert ex.wait(0.0) is None and ex.program.value == "Suspended"
    # forbidden transitions are refused and change nothing
    r = run(core, "SUSPEND id=%d" % ex.id)
    assert r.code.value == "INVALID_ARGUMENT" and "Suspended" in r.message and "Resume, Halt" in r.message, r
    assert run(core, "RESET id=%d" % ex.id).code.value == "INVALID_ARGUMENT"
    assert ex.program.value == "Suspended"
    r = run(core, "RESUME id=%d cause=bay_clear" % ex.id)
    assert r.success, r
    done = ex.wait(120.0)
    assert done is not None and done.success, done
    assert done.result["suspensions"] == 1 and done.result["length_m"] == pytest.approx(2.4), done.result
    assert _transitions(events, ex.id) == [("ReadyToRunning", "Start"), ("RunningToSuspended", "Suspend"),
                                           ("SuspendedToRunning", "Resume"), ("RunningToReady", "")]
    causes = [e.transition.cause for e in events if e.id == ex.id and e.transition]
    assert causes[1:3] == ["person_in_bay", "bay_clear"]
    time.sleep(0.2)
    # the spray axis crossed every point of lane 1 exactly once: no gap, no second coat at the resume point
    m = rig.world.outcome.maps["wall_1"]
    k = int(1.2 / PASS_GRID)
    row = m.passes[k - 1:k + 2].max(axis=0)               # the lane's axis within one cell up or down
    lane = row[int(0.21 / PASS_GRID):int(0.99 / PASS_GRID)]
    gaps, doubles = _runs(lane == 0, PASS_GRID), _runs(lane >= 2, PASS_GRID)
    print("spray lane 1: gaps %s m, second coats %s m" % (gaps, doubles))
    assert max(gaps, default=0.0) <= LONGEST_FLAW_M and max(doubles, default=0.0) <= LONGEST_FLAW_M, (gaps, doubles)
    assert (lane >= 1).all() or max(gaps) <= LONGEST_FLAW_M
    # and the coat along the lane is even: its thickness stays within 20 % of its median along the worked stretch
    th = m.thickness[int(np.argmin(np.abs(m.tc - 1.2)))]
    worked = th[(m.sc >= 0.3) & (m.sc <= 0.9)]
    assert worked.min() >= 0.8 * np.median(worked) and worked.max() <= 1.2 * np.median(worked), worked
    assert rig.running() == ["compressor motor on"]


def test_tape_suspended_mid_joint_resumes_where_the_roller_stopped(wall, core):
    rig, _ = wall
    rig.world.mount_tool("taping_tool")
    assert run(core, "MOUNT_TOOL taping_tool").success
    ex = core.dispatcher.submit("APPLY_TAPE 1.8 3.6 1.25 3.0 3.6 1.25 %s speed=0.1" % NORMAL, Interface.ACTION)
    assert wait_until(lambda: rig.world.outcome.joint_coverage(JOINT) >= 0.4, timeout=60.0)
    t0 = rig.clock.now()
    assert run(core, "SUSPEND id=%d" % ex.id).success
    arm_at, _ = _rest_times(rig, t0, valve=False)
    assert arm_at is not None and arm_at <= REST_S, arm_at
    assert not any(rig.standin.get_standard_digital_outputs()), "the taping tool is still on"
    covered = rig.world.outcome.joint_coverage(JOINT)
    while rig.clock.now() < t0 + 10.0:
        time.sleep(0.05)
    assert rig.world.outcome.joint_coverage(JOINT) == covered          # nothing laid while suspended
    assert run(core, "RESUME id=%d" % ex.id).success
    done = ex.wait(60.0)
    assert done is not None and done.success and done.result["suspensions"] == 1, done
    time.sleep(0.2)
    assert rig.world.outcome.joint_coverage(JOINT) >= 0.99
    passes = rig.world.outcome.tape_passes[JOINT]
    print("tape: arm at rest %.3f s sim; taped twice %s m" % (arm_at, _runs(passes >= 2, TAPE_BIN)))
    assert max(_runs(passes >= 2, TAPE_BIN), default=0.0) <= LONGEST_FLAW_M, passes
    assert rig.nothing_running(), rig.running()


def test_goto_suspended_brakes_the_base_and_resumes_to_the_goal(wall, core):
    rig, _ = wall
    goto = core.dispatcher.submit("GOTO 2.4 1.2 1.5708 speed=0.8", Interface.ACTION)
    assert wait_until(lambda: abs(rig.drives.wheel_speeds()[0]) > 3.0, timeout=10.0)
    t0 = rig.clock.now()
    assert run(core, "SUSPEND id=%d" % goto.id).success
    assert wait_until(lambda: all(abs(v) < 1e-9 for v in rig.drives.wheel_speeds()), timeout=2.0, period=0.002)
    took = last_motion(rig.drives, t0, rig.clock.now()) - t0
    print("base: at rest %.3f s sim after Suspend" % took)
    assert took <= REST_S, "base still turning %.3f s sim after Suspend" % took
    time.sleep(0.5)
    assert all(abs(v) < 1e-9 for v in rig.drives.wheel_speeds()) and goto.wait(0.0) is None
    # Resume while running is refused (nothing changes); Resume when suspended drives on
    assert run(core, "RESUME id=%d" % goto.id).success
    r = run(core, "RESUME id=%d" % goto.id)
    assert r.code.value == "INVALID_ARGUMENT" and "Running" in r.message and "Suspend, Halt" in r.message, r
    done = goto.wait(60.0)
    assert done is not None and done.success and done.result["error_xy"] <= 0.01, done


def test_halt_mid_spray_ends_the_command_halted_with_every_device_safe(wall, core):
    rig, _ = wall
    rig.world.mount_tool("spray_gun")
    assert run(core, "MOUNT_TOOL spray_gun").success
    assert run(core, "GOTO 2.4 2.5 1.5708").success
    feedback = []
    ex = core.dispatcher.submit(AREA, Interface.ACTION, listener=lambda e: feedback.append(e.message))
    assert wait_until(lambda: any((parse_progress_text(m) or (0,))[0] >= 0.3 for m in feedback), timeout=60.0)
    r = run(core, "HALT id=%d cause=hose_kinked" % ex.id)
    assert r.success and r.result["states"] == {str(ex.id): "Halted"}, r
    done = ex.wait(5.0)
    assert done is not None and done.code.value == "ABORTED" and "halted: hose_kinked" in done.message, done
    assert wait_until(lambda: not rig.standin.get_state()["moving"], timeout=1.0)
    assert rig.running() == ["compressor motor on"]
    assert run(core, "RESUME id=%d" % ex.id).code.value == "INVALID_ARGUMENT"
    assert run(core, "HALT id=%d" % ex.id).code.value == "INVALID_ARGUMENT"
    r = run(core, "RESET id=%d" % ex.id)
    assert r.success and r.result["states"] == {str(ex.id): "Ready"}, r
    assert run(core, "COMPRESSOR_OFF").success


def _sanded(rig):
    m = rig.world.outcome.maps["wall_1"]
    return float(m.sanded[(m.tc >= 0.9) & (m.tc <= 1.5)][:, (m.sc >= 0.2) & (m.sc <= 1.0)].mean())


def _off_the_wall(rig):
    """Distance (m) of the sander's pad from wall_1's surface, from the world's ground truth."""
    with rig.world._lock:
        pos, _z = rig.world._tcp()
    return float(rig.world.outcome.maps["wall_1"].wall.to_wall_coords(pos)[2])


def test_sander_suspended_mid_lane_lifts_off_the_wall_and_sands_on_from_there(wall, core):
    rig, _ = wall
    rig.world.mount_tool("sander")
    assert run(core, "MOUNT_TOOL sander").success
    assert run(core, "GOTO 2.4 2.6 1.5708").success
    ex = core.dispatcher.submit("SAND_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.1 speed=0.15" % NORMAL,
                                Interface.ACTION)
    assert wait_until(lambda: _sanded(rig) >= 0.3, timeout=90.0)
    assert rig.standin.get_standard_digital_outputs()[1] and abs(_off_the_wall(rig)) <= 0.01
    t0 = rig.clock.now()
    assert run(core, "SUSPEND id=%d cause=dust_check" % ex.id).success
    arm_at, _ = _rest_times(rig, t0, valve=False)
    print("sand: arm at rest %.3f s sim after Suspend" % arm_at)
    assert arm_at is not None and arm_at <= REST_S, arm_at
    assert not rig.standin.get_standard_digital_outputs()[1], "the sander is still on"
    # then it backs off the wall along its axis and stays there, nothing sanded while suspended
    assert wait_until(lambda: _off_the_wall(rig) >= 0.025, timeout=5.0), _off_the_wall(rig)
    sanded = _sanded(rig)
    while rig.clock.now() < t0 + 10.0:
        time.sleep(0.05)
    assert _off_the_wall(rig) >= 0.025 and _sanded(rig) == sanded
    assert not rig.standin.get_state()["moving"] and ex.program.value == "Suspended"
    assert run(core, "RESUME id=%d cause=checked" % ex.id).success
    done = ex.wait(120.0)
    assert done is not None and done.success and done.result["suspensions"] == 1, done
    time.sleep(0.2)
    assert _sanded(rig) >= 0.98, _sanded(rig)
    assert rig.nothing_running(), rig.running()
