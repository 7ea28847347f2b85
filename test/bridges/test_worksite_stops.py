"""STOP_BASE among the other devices: every bridge through one LOCEM core against the worksite stand-ins
(WorksiteRig: UR controller, compressor, four drives, PyBullet world)."""
import time

import pytest

from locem_bridge.locem.registry import Interface

from bridge_rigs import last_motion, wait_until

pytest.importorskip("rtde_control")
pytestmark = pytest.mark.slow


def run(core, text):
    return core.dispatcher.execute(text)


def test_stop_base_stops_the_base_only(wall, core):
    rig, built = wall
    # the compressor runs (motor on, valve open) and the arm is in a long joint move while the base drives
    assert run(core, "COMPRESSOR_ON").success
    assert run(core, "SET_PRESSURE 3.0").success
    assert run(core, "SPRAY_ON").success
    q_goal = [1.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
    arm_move = core.dispatcher.submit("MOVE_J %s speed=0.3" % " ".join(map(str, q_goal)), Interface.ACTION)
    goto = core.dispatcher.submit("GOTO 2.4 1.2 1.5708 speed=0.8", Interface.ACTION)
    assert wait_until(lambda: abs(rig.drives.wheel_speeds()[0]) > 3.0, timeout=10.0)
    assert rig.standin.get_state()["moving"]
    t0 = rig.clock.now()
    r = run(core, "STOP_BASE")
    assert r.success and r.result["stopped"] is True, r
    assert wait_until(lambda: all(abs(v) < 1e-9 for v in rig.drives.wheel_speeds()), timeout=2.0, period=0.002)
    took = last_motion(rig.drives, t0, rig.clock.now()) - t0        # ground truth, 1 ms sim grid
    assert took <= 0.2, "base still turning %.3f s sim after STOP_BASE" % took
    ended = goto.wait(2.0)
    # the code STOP gives a running command (ABORTED), naming STOP_BASE
    assert ended is not None and ended.code.value == "ABORTED" and "STOP_BASE" in ended.message, ended
    # nothing else was stopped: the arm is still on its way and arrives, the compressor still sprays
    assert rig.standin.get_state()["moving"]
    assert arm_move.wait(0.0) is None
    truth = rig.model.snapshot()
    assert truth["motor_on"] is True and truth["valve_open"] is True, truth
    done = arm_move.wait(30.0)
    assert done is not None and done.success, done
    assert max(abs(a - b) for a, b in zip(rig.standin.get_joint_positions(), q_goal)) < 1e-3
    assert rig.running() == ["spray valve open", "compressor motor on"]
    assert run(core, "COMPRESSOR_OFF").success
    assert rig.nothing_running(), rig.running()
    time.sleep(0.2)
    assert all(abs(v) < 1e-9 for v in rig.drives.wheel_speeds())
