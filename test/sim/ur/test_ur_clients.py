"""The real ur_rtde 1.6.5 clients against the UR stand-in: connect, move, stop, IO, kinematics, restart."""
import math
import time

import numpy as np
import pytest

from ur_client_support import Q_HOME, disconnect_all, eventually

rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")
rtde_io = pytest.importorskip("rtde_io")
dashboard_client = pytest.importorskip("dashboard_client")

pytestmark = pytest.mark.slow


def _point_line_distance(p, a, b):
    p, a, b = np.asarray(p), np.asarray(a), np.asarray(b)
    d = b - a
    t = np.clip(np.dot(p - a, d) / np.dot(d, d), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * d)))


def test_clients_connect_with_default_flags_and_stream_at_500hz(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    io = rtde_io.RTDEIOInterface(addr)
    try:
        assert r.isConnected() and c.isConnected()
        assert c.isProgramRunning()
        assert r.getRobotMode() == 7            # RUNNING
        assert r.getSafetyMode() == 1           # NORMAL
        assert r.getRuntimeState() == 2         # PLAYING
        assert np.allclose(r.getActualQ(), Q_HOME, atol=1e-9)
        # the receive interface was set up for 500 Hz: timestamps advance in steps of 2 ms
        stamps = set()
        t_end = time.time() + 0.5
        while time.time() < t_end:
            stamps.add(round(r.getTimestamp(), 6))
            time.sleep(0.0005)
        stamps = sorted(stamps)
        assert len(stamps) > 50, "too few distinct samples in 0.5 s: %d" % len(stamps)
        steps = np.diff(stamps) / 0.002
        # every package is one 2 ms controller cycle later (a 125 Hz stream would step by 4 cycles); the client
        # may miss some while it polls, so look for the smallest step and for whole cycles only
        assert np.min(steps) == pytest.approx(1.0, abs=1e-3)
        assert np.allclose(steps, np.round(steps), atol=1e-3)
        assert ur_standin.refused() == []
    finally:
        disconnect_all(c, r, io)


def test_movej_reaches_target_with_synchronised_trapezoid(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    try:
        target = [0.5, -1.2, 1.2, -1.9, -1.3, 0.4]
        v, a = 1.0, 1.4
        assert c.moveJ(target, v, a, True)          # asynchronous: sample the motion
        samples = []
        t_end = time.time() + 10
        while time.time() < t_end:
            samples.append((r.getActualQ(), r.getActualQd()))
            if c.getAsyncOperationProgress() < 0 and not np.any(np.abs(samples[-1][1]) > 0):
                break
            time.sleep(0.002)
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), target))) < 1e-3)
        # synchronised: every joint has covered the same fraction of its distance at every sample
        delta = np.subtract(target, Q_HOME)
        fractions = [np.subtract(q, Q_HOME) / delta for q, _ in samples]
        spread = max(float(np.ptp(f)) for f in fractions)
        assert spread < 1e-6
        # trapezoid limits: the leading joint never exceeds v
        peak = max(float(np.max(np.abs(qd))) for _, qd in samples)
        assert peak <= v + 1e-6
        assert peak > 0.5 * v
        # a blocking moveJ back: returns True and getActualQ agrees within 1e-3 rad
        assert c.moveJ(Q_HOME, v, a)
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), Q_HOME))) < 1e-3)
    finally:
        disconnect_all(c, r)


def test_movel_reaches_pose_on_a_straight_line(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    try:
        start = r.getActualTCPPose()
        goal = list(start)
        goal[0] += 0.20
        goal[1] -= 0.15
        goal[2] += 0.10
        assert c.moveL(goal, 0.1, 1.2, True)               # ~3 s of motion (0.3 s wall)
        path = []
        t_end = time.time() + 10
        while time.time() < t_end:
            path.append(r.getActualTCPPose())
            if c.getAsyncOperationProgress() < 0 and len(path) > 5:
                break
            time.sleep(0.002)
        assert eventually(lambda: np.linalg.norm(np.subtract(r.getActualTCPPose()[:3], goal[:3])) < 1e-3)
        final = r.getActualTCPPose()
        path.append(final)
        assert np.linalg.norm(np.subtract(final[3:], goal[3:])) < 1e-3
        assert len(path) > 20, "too few samples during the move"
        deviation = max(_point_line_distance(p[:3], start[:3], goal[:3]) for p in path)
        assert deviation < 1e-3
        # a blocking moveL back to the start
        assert c.moveL(start, 0.25, 1.2)
        assert eventually(lambda: np.linalg.norm(np.subtract(r.getActualTCPPose()[:3], start[:3])) < 1e-3)
    finally:
        disconnect_all(c, r)


def test_speedl_then_stopl(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    try:
        start = r.getActualTCPPose()
        t0 = time.time()
        while time.time() - t0 < 0.3:
            assert c.speedL([0.0, 0.0, 0.05, 0.0, 0.0, 0.0], 0.5, 0.02)
            time.sleep(0.01)
        speed = r.getActualTCPSpeed()
        assert speed[2] == pytest.approx(0.05, abs=1e-3)
        assert abs(speed[0]) < 1e-4 and abs(speed[1]) < 1e-4
        c.stopL(1.0)
        assert eventually(lambda: np.allclose(r.getActualTCPSpeed(), 0.0, atol=1e-9))
        p1 = r.getActualTCPPose()
        time.sleep(0.1)
        p2 = r.getActualTCPPose()
        assert np.allclose(r.getActualTCPSpeed(), 0.0, atol=1e-9)
        assert np.allclose(p1, p2, atol=1e-9)            # at rest
        assert p2[2] - start[2] > 0.05                    # it did rise (0.3 s wall = 3 s motion at 0.05 m/s)
        assert abs(p2[0] - start[0]) < 1e-3 and abs(p2[1] - start[1]) < 1e-3
    finally:
        disconnect_all(c, r)


def test_speedj_and_speedstop(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    try:
        qd = [0.1, 0.0, 0.0, 0.0, 0.0, -0.1]
        t0 = time.time()
        while time.time() - t0 < 0.2:
            c.speedJ(qd, 1.0, 0.02)
            time.sleep(0.01)
        assert np.allclose(r.getActualQd(), qd, atol=1e-6)
        c.speedStop(2.0)
        assert eventually(lambda: np.allclose(r.getActualQd(), 0.0, atol=1e-9))
        assert r.getActualQ()[0] > Q_HOME[0] + 0.05
    finally:
        disconnect_all(c, r)


def test_protective_stop_fails_move_until_dashboard_unlock(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    db = dashboard_client.DashboardClient(addr)
    db.connect()
    try:
        ur_standin.later(0.2, "inject_protective_stop", ["test collision"])
        t0 = time.time()
        ok = c.moveJ([1.5, -1.2, 1.2, -1.9, -1.3, 0.4], 0.3, 0.5)    # would take ~5 s wall
        assert ok is False
        assert time.time() - t0 < 2.0
        assert eventually(r.isProtectiveStopped)
        assert r.getSafetyMode() == 3
        assert "PROTECTIVE_STOP" in db.safetymode()
        assert c.moveJ(Q_HOME, 1.0, 1.0) is False             # still stopped
        assert eventually(lambda: np.allclose(r.getActualQd(), 0.0))   # the arm has stopped
        time.sleep(0.6)                                        # 6 s of motion time at time scale 10
        db.unlockProtectiveStop()
        assert eventually(lambda: not r.isProtectiveStopped())
        assert r.getSafetyMode() == 1
        assert eventually(c.isProgramRunning)
        assert c.moveJ(Q_HOME, 1.0, 1.0) is True
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), Q_HOME))) < 1e-3)
    finally:
        disconnect_all(c, r, db)


def test_unlock_too_early_is_refused_like_polyscope(ur_address):
    from locem_bridge.sim.ur.process import StandInProcess
    with StandInProcess(ur_address, time_scale=1.0) as ur:
        db = dashboard_client.DashboardClient(ur_address)
        db.connect()
        try:
            ur.inject_protective_stop("test")
            with pytest.raises(RuntimeError, match="Cannot unlock protective stop until 5s"):
                db.unlockProtectiveStop()
            assert "PROTECTIVE_STOP" in db.safetystatus()
        finally:
            db.disconnect()


def test_emergency_stop_needs_power_on_and_brake_release(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    db = dashboard_client.DashboardClient(addr)
    db.connect()
    try:
        ur_standin.inject_emergency_stop("e-stop pressed")
        assert eventually(r.isEmergencyStopped)
        assert c.moveJ([0.3] + Q_HOME[1:], 1.0, 1.0) is False
        assert db.robotmode() == "Robotmode: POWER_OFF"
        db.powerOn()
        assert db.robotmode() == "Robotmode: POWER_OFF"       # button still pressed
        ur_standin.release_emergency_stop()
        db.closeSafetyPopup()
        db.powerOn()
        assert db.robotmode() == "Robotmode: IDLE"
        db.brakeRelease()
        assert db.robotmode() == "Robotmode: RUNNING"
        assert eventually(lambda: not r.isEmergencyStopped())
        assert c.reuploadScript()
        t_end = time.time() + 2
        while not c.isProgramRunning() and time.time() < t_end:
            time.sleep(0.01)
        assert c.moveJ([0.3] + Q_HOME[1:], 1.0, 1.0) is True
    finally:
        disconnect_all(c, r, db)


def test_restart_standin_then_reconnect(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    try:
        target = [0.3, -1.4, 1.4, -1.6, -1.5, 0.2]
        assert c.moveJ(target, 1.0, 1.0)
        ur_standin.stop()                       # the controller goes away ...
        t_end = time.time() + 5
        while (c.isConnected() or r.isConnected()) and time.time() < t_end:
            time.sleep(0.05)
        assert not c.isConnected()
        ur_standin.start_server()                # ... and comes back
        assert r.reconnect()
        assert c.reconnect()
        assert c.isConnected() and c.isProgramRunning()
        # the arm stayed where it was
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), target))) < 1e-3)
        assert c.moveJ(Q_HOME, 1.0, 1.0)
        assert eventually(lambda: np.max(np.abs(np.subtract(r.getActualQ(), Q_HOME))) < 1e-3)
    finally:
        disconnect_all(c, r)


def test_io_outputs_visible_in_standin_and_stream(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    io = rtde_io.RTDEIOInterface(addr)
    try:
        assert io.setStandardDigitalOut(2, True)
        assert io.setStandardDigitalOut(5, True)
        assert io.setToolDigitalOut(0, True)
        assert io.setConfigurableDigitalOut(1, True)
        assert eventually(lambda: ur_standin.get_configurable_digital_outputs()[1])
        assert ur_standin.get_standard_digital_outputs() == [False, False, True, False, False, True, False, False]
        assert ur_standin.get_tool_digital_outputs() == [True, False]
        assert ur_standin.get_configurable_digital_outputs()[1] is True
        expected_bits = (1 << 2) | (1 << 5) | (1 << 9) | (1 << 16)
        assert eventually(lambda: r.getActualDigitalOutputBits() == expected_bits)
        assert r.getDigitalOutState(2) and r.getDigitalOutState(5) and not r.getDigitalOutState(3)
        assert io.setStandardDigitalOut(2, False)
        assert eventually(lambda: ur_standin.get_standard_digital_outputs()[2] is False)
        assert ur_standin.get_standard_digital_outputs()[5] is True
        ur_standin.set_standard_digital_input(4, True)
        assert eventually(lambda: r.getDigitalInState(4))
    finally:
        disconnect_all(io, r)


def test_speed_slider_scales_motion(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    io = rtde_io.RTDEIOInterface(addr)
    try:
        target = [0.4] + Q_HOME[1:]
        t0 = time.time()
        assert c.moveJ(target, 0.8, 2.0)
        full = time.time() - t0
        io.setSpeedSlider(0.25)
        assert eventually(lambda: r.getTargetSpeedFraction() == pytest.approx(0.25))
        assert c.moveJ(Q_HOME[:1] + [-1.0] + Q_HOME[2:], 0.8, 2.0, True)   # 0.57 rad: reaches 0.8 rad/s
        peak = 0.0
        t0 = time.time()
        while time.time() - t0 < 3.0:
            peak = max(peak, float(np.max(np.abs(r.getActualQd()))))
            if c.getAsyncOperationProgress() < 0:
                break
            time.sleep(0.002)
        slow = time.time() - t0
        assert peak == pytest.approx(0.25 * 0.8, rel=1e-6)      # 25 % of the programmed joint speed
        assert slow > 2.0 * full
    finally:
        disconnect_all(io, c, r)


def test_kinematics_round_trip_and_tcp_offset(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    try:
        rng = np.random.default_rng(7)
        for _ in range(4):
            q = (np.array(Q_HOME) + rng.uniform(-0.6, 0.6, 6)).tolist()
            assert c.moveJ(q, 3.0, 10.0)
            pose = c.getForwardKinematics()                 # current q, current TCP
            assert eventually(lambda: np.allclose(pose, r.getActualTCPPose(), atol=1e-9))
            q_back = c.getInverseKinematics(pose, Q_HOME)   # IK seeded away from q still finds q
            assert np.max(np.abs(np.subtract(q_back, q))) < 1e-6
        flange = c.getForwardKinematics()
        assert eventually(lambda: np.allclose(r.getActualTCPPose(), flange, atol=1e-9))
        assert c.setTcp([0.0, 0.0, 0.2, 0.0, 0.0, 0.0])
        # the TCP lies 0.2 m along the flange z axis
        rot = _rotvec_to_matrix(flange[3:])
        expected = np.asarray(flange[:3]) + rot @ [0, 0, 0.2]
        assert eventually(lambda: np.allclose(r.getActualTCPPose()[:3], expected, atol=1e-9))
        tcp = r.getActualTCPPose()
        assert c.getTCPOffset() == pytest.approx([0.0, 0.0, 0.2, 0.0, 0.0, 0.0])
        # moveJ_IK: move the TCP to a pose by IK
        goal = list(tcp)
        goal[2] -= 0.1
        assert c.moveJ_IK(goal, 1.0, 1.0)
        assert eventually(lambda: np.linalg.norm(np.subtract(r.getActualTCPPose()[:3], goal[:3])) < 1e-3)
        # moveL_FK: a straight line to the pose of a joint vector; getInverseKinematics without qnear
        q_goal = c.getInverseKinematics(tcp)
        assert np.allclose(c.getForwardKinematics(q_goal, [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]), tcp, atol=1e-9)
        assert c.moveL_FK(q_goal, 0.5, 1.2)
        assert eventually(lambda: np.linalg.norm(np.subtract(r.getActualTCPPose()[:3], tcp[:3])) < 1e-3)
        assert c.setPayload(2.0, [0.0, 0.0, 0.05])
        assert eventually(lambda: r.getPayload() == pytest.approx(2.0))
        assert r.getPayloadCog() == pytest.approx([0.0, 0.0, 0.05])
        # an unreachable pose: the control script halts (as get_inverse_kin does on a UR) -> the call fails
        # (ur_rtde 1.6.5 then returns an empty list instead of raising)
        try:
            q_bad = c.getInverseKinematics([5.0, 0.0, 0.0, 0.0, 0.0, 0.0], Q_HOME)
        except RuntimeError:
            q_bad = []
        assert q_bad == []
        assert not c.isProgramRunning()
        assert "no inverse kinematics solution" in ur_standin.get_state()["last_error"]
        assert c.reuploadScript()
        t_end = time.time() + 2
        while not c.isProgramRunning() and time.time() < t_end:
            time.sleep(0.01)
        assert c.isSteady()
    finally:
        disconnect_all(c, r)


def _rotvec_to_matrix(rv):
    rv = np.asarray(rv, dtype=float)
    th = float(np.linalg.norm(rv))
    if th < 1e-12:
        return np.eye(3)
    k = rv / th
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * kx + (1 - math.cos(th)) * kx @ kx


def test_async_movej_then_stopj_and_servoj(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    try:
        far = [1.5] + Q_HOME[1:]
        assert c.moveJ(far, 0.3, 1.0, True)             # ~5.3 s of motion (0.53 s wall), returns at once
        time.sleep(0.05)
        assert c.getAsyncOperationProgress() >= 0         # running
        assert not c.isSteady()
        c.stopJ(2.0)                                      # blocking stop with 2 rad/s^2 (returns None in 1.6.5)
        assert eventually(lambda: np.allclose(r.getActualQd(), 0.0))
        q_stop = r.getActualQ()[0]
        assert 0.0 < q_stop < 1.5                          # stopped part way
        assert c.getAsyncOperationProgress() < 0          # the async move is reported finished
        assert c.isSteady()
        # servoJ: stream targets, the arm follows, servoStop brings it to rest
        for k in range(40):
            target = [q_stop - 0.005 * (k + 1)] + Q_HOME[1:]
            c.servoJ(target, 0.5, 0.5, 0.02, 0.1, 300)
            time.sleep(0.002)
        assert eventually(lambda: abs(r.getActualQ()[0] - (q_stop - 0.2)) < 2e-3)
        c.servoStop(10.0)
        assert eventually(lambda: np.allclose(r.getActualQd(), 0.0))
    finally:
        disconnect_all(c, r)


def test_trigger_protective_stop_from_client(ur_standin):
    addr = ur_standin.address
    r = rtde_receive.RTDEReceiveInterface(addr)
    c = rtde_control.RTDEControlInterface(addr)
    db = dashboard_client.DashboardClient(addr)
    db.connect()
    try:
        c.triggerProtectiveStop()
        assert eventually(r.isProtectiveStopped)
        assert db.programState().startswith("PAUSED")
        assert c.moveJ([0.2] + Q_HOME[1:], 1.0, 1.0) is False
        time.sleep(0.6)
        db.unlockProtectiveStop()
        assert db.programState().startswith("PLAYING")
        assert eventually(c.isProgramRunning)             # the RTDE stream carries the new state
        assert c.moveJ([0.2] + Q_HOME[1:], 1.0, 1.0) is True
    finally:
        disconnect_all(c, r, db)


def test_new_control_interface_replaces_a_running_control_script(ur_standin):
    addr = ur_standin.address
    c = rtde_control.RTDEControlInterface(addr)
    c.disconnect()                                   # leaves the control script PLAYING on the controller
    assert ur_standin.get_state()["runtime_state_name"] == "PLAYING"
    c2 = rtde_control.RTDEControlInterface(addr)     # finds it running: stopScript + dashboard stop + upload
    try:
        assert c2.isProgramRunning()
        assert c2.moveJ([0.1] + Q_HOME[1:], 1.0, 1.0)
    finally:
        c2.disconnect()
