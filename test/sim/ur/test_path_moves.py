"""Path moves with blends: the REAL ur_rtde 1.6.5 moveL(path) / moveJ(path) against the UR stand-in, plus the
planner and the script-path reader without sockets."""
import time

import numpy as np
import pytest

from locem_bridge.sim.ur import ArmKinematics
from locem_bridge.sim.ur.blended import PathMove
from locem_bridge.sim.ur.errors import ScriptRuntimeError
from locem_bridge.sim.ur.script_path import PathEntry, parse_move_path

Q_HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


def _offset(pose, dx, dy, dz):
    p = list(pose)
    p[0] += dx
    p[1] += dy
    p[2] += dz
    return p


def _zigzag(p0, r, v=0.25, a=1.2):
    """Three moves with 90 degree turns: +y 0.1, +z 0.1, +y 0.1 (blend r at the two interior waypoints)."""
    w1 = _offset(p0, 0, 0.10, 0)
    w2 = _offset(p0, 0, 0.10, 0.10)
    w3 = _offset(p0, 0, 0.20, 0.10)
    return [w1 + [v, a, r], w2 + [v, a, r], w3 + [v, a, 0.0]]


# ---------------------------------------------------------------------------------------------- without sockets
def test_script_path_reader_understands_the_injected_block_and_names_what_it_cannot_run():
    text = ("def rtde_control():\n    def exec_move_path():\n        textmsg(\"exec_move_path\")\n"
            "        # inject move path\n\tsignal_async_progress(0)\n"
            "\tmovel(p[-0.691398,-0.12415,0.67685,-2.22144,-2.22144,1.63164e-11],a=1.2,v=0.25,r=0.02)\n"
            "\tsignal_async_progress(1)\n\tmovej([0.1,-1.5,1.5,-1.6,-1.57,0],a=1.4,v=1.05,r=0)\n    end\nend\n")
    entries, error = parse_move_path(text)
    assert error is None
    assert [e.kind for e in entries] == ["movel", "movej"]
    assert entries[0].is_pose and not entries[1].is_pose
    assert entries[0].target[5] == pytest.approx(1.63164e-11)
    assert (entries[0].a, entries[0].v, entries[0].r, entries[0].progress) == (1.2, 0.25, 0.02, 0)
    assert entries[1].progress == 1
    bad = text.replace("movej(", "movec(")
    _, error = parse_move_path(bad)
    assert "not emulated" in error and "movec" in error
    assert parse_move_path("def rtde_control():\nend\n") == ([], None)


@pytest.fixture(scope="module")
def kin():
    return ArmKinematics("ur10e")


def _run(kin, entries, dt=0.002):
    q = np.array(Q_HOME)
    m = PathMove(kin, q, entries)
    pts, speeds = [], []
    prev = np.array(kin.fk(q)[:3])
    for _ in range(20000):
        q, _qd = m.step(dt, q, np.zeros(6))
        p = np.array(kin.fk(q)[:3])
        pts.append(p)
        speeds.append(np.linalg.norm(p - prev) / dt)
        prev = p
        if m.done:
            break
    assert m.done
    return np.array(pts), np.array(speeds)


def test_planner_blends_on_a_circular_arc_and_respects_the_limits(kin):
    p0 = kin.fk(Q_HOME)
    r, v, a = 0.02, 0.25, 1.2
    path = _zigzag(p0, r, v, a)
    entries = [PathEntry("movel", w[:6], True, w[7], w[6], w[8], i, "movel") for i, w in enumerate(path)]
    pts, speeds = _run(kin, entries)
    for w in path[:2]:
        d = np.linalg.norm(pts - np.array(w[:3]), axis=1)
        i = int(np.argmin(d))
        # the arc tangent to both segments r before / after a 90 degree corner passes it at r * tan(22.5 deg)
        assert d[i] == pytest.approx(r * np.tan(np.pi / 8), rel=0.02)
        assert speeds[i] > 0.5 * np.sqrt(a * r)          # centripetal limit sqrt(a R), R = r at 90 degrees
    assert np.max(speeds) <= v * 1.001
    assert np.max(np.abs(np.diff(speeds))) / 0.002 <= a * 1.05
    assert np.linalg.norm(pts[-1] - np.array(path[-1][:3])) < 1e-9


def test_planner_refuses_bad_paths_before_moving(kin):
    p0 = kin.fk(Q_HOME)
    near = _offset(p0, 0, 0.03, 0)
    far = _offset(p0, 0, 0.03, 0.2)
    entries = [PathEntry("movel", near, True, 1.2, 0.25, 0.02, 0, "movel(near)"),
               PathEntry("movel", far, True, 1.2, 0.25, 0.0, 1, "movel(far)")]
    with pytest.raises(ScriptRuntimeError, match=r"waypoint 1: blend radius 0.02 m is larger than half"):
        PathMove(kin, np.array(Q_HOME), entries)
    with pytest.raises(ScriptRuntimeError, match=r"waypoint 2 .*v=0.0 must be a positive"):
        PathMove(kin, np.array(Q_HOME), [entries[0]._replace(r=0.0), entries[1]._replace(v=0.0)])
    with pytest.raises(ScriptRuntimeError, match=r"waypoint 1 .*no inverse kinematics solution"):
        PathMove(kin, np.array(Q_HOME), [entries[0]._replace(target=[3.0, 0, 0, 0, 0, 0])])
    mixed = [entries[0]._replace(r=0.01), PathEntry("movej", [0.2] + Q_HOME[1:], False, 1.4, 1.0, 0.0, 1, "movej")]
    with pytest.raises(ScriptRuntimeError, match="blending from movel into movej"):
        PathMove(kin, np.array(Q_HOME), mixed)


# ---------------------------------------------------------------------------------------------- real ur_rtde
rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")


@pytest.fixture
def slow_standin(ur_address):
    """Time scale 2: a 1.5 s path lasts 0.75 s of wall time, sampled by the receive interface at 500 Hz."""
    from locem_bridge.sim.ur.process import StandInProcess
    proc = StandInProcess(ur_address, time_scale=2.0).start()
    yield proc
    proc.close()


@pytest.fixture
def clients(slow_standin):
    r = rtde_receive.RTDEReceiveInterface(slow_standin.address)
    c = rtde_control.RTDEControlInterface(slow_standin.address)
    yield slow_standin, r, c
    for cl in (c, r):
        try:
            cl.disconnect()
        except Exception:
            pass


def _record(r, c, timeout=20.0):
    """(controller time, TCP pose, TCP speed, async progress) samples until the async path has finished."""
    samples = []
    end = time.time() + timeout
    started = False
    while time.time() < end:
        prog = c.getAsyncOperationProgress()
        samples.append((r.getTimestamp(), r.getActualTCPPose(), r.getActualTCPSpeed(), prog))
        started = started or prog >= 0
        if started and prog < 0 and np.linalg.norm(samples[-1][2][:3]) == 0.0:
            break
        time.sleep(0.0005)
    return samples


def _motion_interval(samples):
    moving = [s[0] for s in samples if np.linalg.norm(s[2][:3]) > 1e-6]
    return moving[-1] - moving[0]


def test_movel_path_blends_through_interior_waypoints_and_ends_exactly(clients):
    standin, r, c = clients
    p0 = r.getActualTCPPose()
    radius = 0.02
    path = _zigzag(p0, radius)
    assert c.moveL(path, True)
    samples = _record(r, c)
    pos = np.array([s[1][:3] for s in samples])
    speed = np.array([np.linalg.norm(s[2][:3]) for s in samples])
    for w in path[:2]:
        d = np.linalg.norm(pos - np.array(w[:3]), axis=1)
        i = int(np.argmin(d))
        assert d[i] < radius, "the TCP never came within the blend radius of %s" % (w[:3],)
        assert d[i] > 0.5 * radius * np.tan(np.pi / 8), "the TCP went through the waypoint: no blend"
        zone = d < radius
        assert np.min(speed[zone]) > 0.05, "the TCP slowed to %.4f m/s in the blend" % np.min(speed[zone])
    # ends exactly at the last waypoint as sent (ur_rtde prints 6 significant digits into the script)
    final = r.getActualTCPPose()
    assert np.linalg.norm(np.subtract(final[:3], path[-1][:3])) < 2e-6
    assert np.linalg.norm(np.subtract(final[3:], path[-1][3:6])) < 2e-5
    # the async progress word named each waypoint in turn
    seen = [s[3] for s in samples if s[3] >= 0]
    assert sorted(set(seen)) == [0, 1, 2] and seen == sorted(seen)
    assert standin.refused() == [] and c.isProgramRunning()


def test_blend_zero_stops_at_each_waypoint_and_blending_saves_time(clients):
    standin, r, c = clients
    p0 = r.getActualTCPPose()
    durations = {}
    for radius in (0.0, 0.02):
        assert c.moveL(_zigzag(p0, radius), True)
        samples = _record(r, c)
        durations[radius] = _motion_interval(samples)
        pos = np.array([s[1][:3] for s in samples])
        speed = np.array([np.linalg.norm(s[2][:3]) for s in samples])
        w1 = np.array(_zigzag(p0, radius)[0][:3])
        d = np.linalg.norm(pos - w1, axis=1)
        if radius == 0.0:
            assert np.min(d) < 1e-5                     # reached the waypoint itself
            assert np.min(speed[d < 0.005]) < 0.02      # and (almost) stood still there
        else:
            assert np.min(speed[d < radius]) > 0.1        # kept moving through the blend zone
        assert c.moveL(p0, 0.5, 1.2)                    # back to the start
    assert durations[0.02] < durations[0.0]


def test_movej_path_blends_in_joint_space_and_ends_at_the_last_joints(clients):
    standin, r, c = clients
    q1 = [0.4, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
    q2 = [0.4, -1.2, 1.2, -1.5708, -1.5708, 0.0]
    q3 = [0.8, -1.2, 1.2, -1.5708, -1.5708, 0.0]
    path = [q1 + [1.0, 2.0, 0.05], q2 + [1.0, 2.0, 0.05], q3 + [1.0, 2.0, 0.0]]
    tcp1 = c.getForwardKinematics(q1, [0.0] * 6)
    assert c.moveJ(path, True)
    samples = _record(r, c)
    pos = np.array([s[1][:3] for s in samples])
    speed = np.array([np.linalg.norm(s[2][:3]) for s in samples])
    d = np.linalg.norm(pos - np.array(tcp1[:3]), axis=1)
    assert 1e-4 < np.min(d) < 0.05
    assert np.min(speed[d < 0.05]) > 0.05
    assert np.max(np.abs(np.subtract(r.getActualQ(), q3))) < 1e-5


def test_blocking_path_returns_when_done(clients):
    standin, r, c = clients
    p0 = r.getActualTCPPose()
    path = _zigzag(p0, 0.01, v=0.5)
    assert c.moveL(path)
    assert np.linalg.norm(np.subtract(r.getActualTCPPose()[:3], path[-1][:3])) < 1e-3 or \
        np.linalg.norm(np.subtract(standin.get_tcp_pose()[:3], path[-1][:3])) < 2e-6


def test_overlapping_blend_halts_the_program_before_anything_moves(clients):
    standin, r, c = clients
    p0 = r.getActualTCPPose()
    q0 = standin.get_joint_positions()
    path = [_offset(p0, 0, 0.03, 0) + [0.25, 1.2, 0.02], _offset(p0, 0, 0.03, 0.2) + [0.25, 1.2, 0.0]]
    assert c.moveL(path, True) is False
    state = standin.get_state()
    assert state["runtime_state_name"] == "STOPPED"
    assert "waypoint 1" in state["last_error"] and "blend radius" in state["last_error"]
    assert np.max(np.abs(np.subtract(standin.get_joint_positions(), q0))) == 0.0
    # ur_rtde checks ranges itself: a blend above 2 m never reaches the controller
    with pytest.raises(Exception, match="not within"):
        c.moveL([_offset(p0, 0, 0.1, 0) + [0.25, 1.2, 3.0]], True)
    assert c.reuploadScript()
    end = time.time() + 5.0
    while not c.isProgramRunning() and time.time() < end:     # the stream shows PLAYING a few cycles later
        time.sleep(0.01)
    assert c.isProgramRunning()
    assert c.moveL(_offset(p0, 0, 0.05, 0), 0.5, 1.2)
