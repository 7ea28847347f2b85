"""MOVE_PATH through LOCEM: one blended ur_rtde path (worker process) against the UR stand-in (child process),
observed by a second real client (rtde_receive) the way a user would measure it."""
import time

import numpy as np
import pytest

from locem_bridge.bridges.commands_arm import ArmCommands, parse_path
from locem_bridge.bridges.errors import BadRequest
from locem_bridge.bridges.ur_arm import UrRtdeArm
from locem_bridge.locem.registry import Interface

from bridge_rigs import arm_cfg, next_ur_address, wait_until

rtde_receive = pytest.importorskip("rtde_receive")
pytest.importorskip("rtde_control")
pytestmark = pytest.mark.slow


@pytest.fixture
def rig(robot, core):
    from locem_bridge.sim.ur.process import StandInProcess
    address = next_ur_address()
    standin = StandInProcess(address, time_scale=2.0).start()
    arm = UrRtdeArm(arm_cfg(robot, address))
    arm.start()
    core.install(ArmCommands(arm))
    assert arm.wait_ready(20.0), arm.health()
    receive = rtde_receive.RTDEReceiveInterface(address)
    yield standin, arm, receive
    receive.disconnect()
    arm.close()
    standin.close()


def _offset(pose, dx, dy, dz):
    return [pose[0] + dx, pose[1] + dy, pose[2] + dz] + list(pose[3:6])


def _zigzag(p0):
    return [_offset(p0, 0, 0.10, 0), _offset(p0, 0, 0.10, 0.10), _offset(p0, 0, 0.20, 0.10)]


def _text(points):
    return "/".join(":".join("%.6f" % v for v in p) for p in points)


def _run_recorded(core, receive, command):
    """Run ``command`` while sampling TCP pose and speed from the receive interface (500 Hz stream)."""
    execution = core.dispatcher.submit(command, Interface.SERVICE)
    samples = []
    end = time.monotonic() + 30.0
    while time.monotonic() < end:
        samples.append((receive.getTimestamp(), receive.getActualTCPPose(), receive.getActualTCPSpeed()))
        if execution.done:
            break
        time.sleep(0.0005)
    result = execution.wait(5.0)
    pos = np.array([s[1][:3] for s in samples])
    speed = np.array([np.linalg.norm(s[2][:3]) for s in samples])
    moving = [s[0] for s in samples if np.linalg.norm(s[2][:3]) > 1e-6]
    return result, pos, speed, (moving[-1] - moving[0]) if moving else 0.0


def nothing_running(standin):
    return not standin.get_state()["moving"] and max(abs(v) for v in standin.get_joint_velocities()) < 1e-9


def test_move_path_with_blend_rounds_the_corners_without_stopping_and_ends_exactly(rig, core):
    standin, arm, receive = rig
    p0 = receive.getActualTCPPose()
    pts = _zigzag(p0)
    blend = 0.02
    r, pos, speed, duration_blended = _run_recorded(core, receive, "MOVE_PATH %s speed=0.25 accel=1.2 blend=%g"
                                                    % (_text(pts), blend))
    assert r.success, r.message
    assert r.result["waypoints"] == 3
    for w in pts[:2]:
        d = np.linalg.norm(pos - np.array(w[:3]), axis=1)
        assert np.min(d) < blend, "TCP passed %.4f m from an interior waypoint" % np.min(d)
        assert np.min(d) > 0.002, "TCP went through the waypoint instead of blending"
        assert np.min(speed[d < blend]) > 0.05, "TCP slowed to %.4f m/s in a blend" % np.min(speed[d < blend])
    final = standin.get_tcp_pose()
    assert np.linalg.norm(np.subtract(final[:3], pts[-1][:3])) < 1e-5
    assert nothing_running(standin)
    # the same path with blend 0 (the default) stops at every waypoint and takes longer
    assert core.dispatcher.execute("MOVE_L %s speed=0.5" % " ".join("%.6f" % v for v in p0)).success
    r, pos, speed, duration_stopping = _run_recorded(core, receive, "MOVE_PATH %s speed=0.25 accel=1.2" % _text(pts))
    assert r.success, r.message
    d = np.linalg.norm(pos - np.array(pts[0][:3]), axis=1)
    assert np.min(d) < 1e-5 and np.min(speed[d < 0.005]) < 0.02
    print("MOVE_PATH motion time: blend %.3f m %.3f s, blend 0 %.3f s" % (blend, duration_blended, duration_stopping))
    assert duration_blended < duration_stopping


def test_per_waypoint_blend_overrides_the_default(rig, core):
    standin, arm, receive = rig
    p0 = receive.getActualTCPPose()
    pts = _zigzag(p0)
    text = "%s:0.03/%s:0/%s" % tuple(":".join("%.6f" % v for v in p) for p in pts)
    r, pos, speed, _ = _run_recorded(core, receive, "MOVE_PATH %s blend=0.01" % text)
    assert r.success, r.message
    d1 = np.linalg.norm(pos - np.array(pts[0][:3]), axis=1)
    d2 = np.linalg.norm(pos - np.array(pts[1][:3]), axis=1)
    assert 0.01 < np.min(d1) < 0.03            # blended with 0.03 m (passes at 0.03 tan(22.5 deg) = 12 mm)
    assert np.min(d2) < 1e-5                   # the waypoint's own 0 stops there


def test_bad_paths_are_refused_with_the_reason_and_nothing_moves(rig, core):
    standin, arm, receive = rig
    p0 = receive.getActualTCPPose()
    q0 = standin.get_joint_positions()
    near = [_offset(p0, 0, 0.03, 0), _offset(p0, 0, 0.03, 0.2)]
    r = core.dispatcher.execute("MOVE_PATH %s blend=0.02" % _text(near))
    assert r.code.value == "INVALID_ARGUMENT"
    assert "waypoint 1" in r.message and "blend radius" in r.message and "at most 0.015" in r.message
    # the waypoint string may fill the command (1000 characters): the handler's 50-waypoint limit answers
    with pytest.raises(BadRequest, match="51 waypoints, allowed at most 50"):
        parse_path("/".join(["0.6:0.%d:0.5:0:3:0" % (i % 10) for i in range(51)]))
    r = core.dispatcher.execute("MOVE_PATH %s" % "/".join(["0.6:0.%d:0.5:0:3:0" % (i % 10) for i in range(51)]))
    assert r.code.value == "INVALID_ARGUMENT" and "51 waypoints, allowed at most 50" in r.message
    r = core.dispatcher.execute("MOVE_PATH %s" % "/".join(["0.6:0.%d:0.5:0:3:0" % (i % 10) for i in range(56)]))   # 1007 characters
    assert r.code.value == "INVALID_ARGUMENT" and "at most 1000 characters" in r.message
    r = core.dispatcher.execute("MOVE_PATH %s/2.0:0:0.5:0:3.14:0" % _text(near[:1]))
    assert r.code.value == "INVALID_ARGUMENT" and "waypoint 2 position out of range" in r.message
    r = core.dispatcher.execute("MOVE_PATH %s:0.7/%s" % tuple(_text([p]) for p in near))
    assert r.code.value == "INVALID_ARGUMENT" and "waypoint 1 blend radius 0.7 m out of range" in r.message
    r = core.dispatcher.execute("MOVE_PATH %s blend=0.9" % _text(near))
    assert r.code.value == "INVALID_ARGUMENT" and "blend" in r.message
    assert standin.get_joint_positions() == q0 and nothing_running(standin)
    # an unreachable waypoint passes LOCEM's checks; the controller refuses the path, nothing moves, and the
    # bridge brings the control script back so the next command works
    r = core.dispatcher.execute("MOVE_PATH %s/1.45:1.45:1.45:0:3.14:0 blend=0.01" % _text(near[:1]))
    assert r.code.value == "HARDWARE_ERROR" and "refused the 2-waypoint path" in r.message
    assert standin.get_joint_positions() == q0
    ok = core.dispatcher.execute("MOVE_PATH %s blend=0.01" % _text(near))
    assert ok.success, ok.message


def test_stop_during_a_blended_path_stops_the_arm(rig, core):
    standin, arm, receive = rig
    p0 = receive.getActualTCPPose()
    pts = [_offset(p0, 0, 0.15, 0), _offset(p0, 0, 0.15, 0.15), _offset(p0, 0, 0.0, 0.15), p0]
    execution = core.dispatcher.submit("MOVE_PATH %s speed=0.05 blend=0.05" % _text(pts), Interface.ACTION)
    assert wait_until(lambda: standin.get_state()["moving"], timeout=10.0)
    assert core.dispatcher.execute("STOP_ARM").success
    r = execution.wait(5.0)
    assert r.code.value == "ABORTED"
    assert wait_until(lambda: nothing_running(standin), timeout=3.0)
