"""The arm bridge (ur_rtde in its worker process) against the UR controller stand-in (child process)."""
import time

import numpy as np
import pytest

from locem_bridge.bridges.commands_arm import ArmCommands
from locem_bridge.common.health import ERROR as HEALTH_ERROR, OK as HEALTH_OK, grade as health_level
from locem_bridge.bridges.ur_arm import UrRtdeArm
from locem_bridge.locem.registry import Interface

from bridge_rigs import arm_cfg, next_ur_address, rtde_payload, wait_until

pytest.importorskip("rtde_control")
pytestmark = pytest.mark.slow

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


def make(robot, core, time_scale, deadline=None):
    from locem_bridge.sim.ur.process import StandInProcess
    address = next_ur_address()
    standin = StandInProcess(address, time_scale=time_scale).start()
    cfg = arm_cfg(robot, address)
    if deadline is not None:
        cfg["deadline"] = deadline
    arm = UrRtdeArm(cfg)
    arm.start()
    core.install(ArmCommands(arm))
    assert arm.wait_ready(20.0), arm.health()
    return standin, arm


@pytest.fixture
def rig(robot, core):
    standin, arm = make(robot, core, 10.0)
    yield standin, arm
    arm.close()
    standin.close()


@pytest.fixture
def rig_short_deadline(robot, core):
    """Motion deadlines at 5 % of the nominal path time, no margin (robot.arm.deadline), time scale 10: every
    motion overruns its deadline at about half of its way."""
    standin, arm = make(robot, core, 10.0, deadline={"scale": 0.05, "margin": 0.0})
    yield standin, arm
    arm.close()
    standin.close()


@pytest.fixture
def rig_realtime(robot, core):
    standin, arm = make(robot, core, 1.0)
    yield standin, arm
    arm.close()
    standin.close()


def run(core, text):
    return core.dispatcher.execute(text)


def nothing_running(standin):
    state = standin.get_state()
    return (not state["moving"] and max(abs(v) for v in standin.get_joint_velocities()) < 1e-9
            and not any(standin.get_standard_digital_outputs()))


def test_get_joints_and_tcp_pose_match_the_controller(rig, core):
    standin, _ = rig
    r = run(core, "GET_JOINTS")
    assert r.success and np.allclose(r.result["q"], standin.get_joint_positions(), atol=1e-9)
    assert r.result["names"][0] == "shoulder_pan_joint"
    p = run(core, "GET_TCP_POSE")
    assert p.success and np.allclose(p.result["pose"], standin.get_tcp_pose(), atol=1e-9)


def test_move_l_reaches_the_pose_within_1mm_and_move_j_the_joints(rig, core):
    standin, _ = rig
    start = standin.get_tcp_pose()
    target = list(start)
    target[0] += 0.10
    target[2] -= 0.05
    r = run(core, "MOVE_L %s speed=0.5 accel=2" % " ".join("%.6f" % v for v in target))
    assert r.success, r.message
    reached = standin.get_tcp_pose()
    assert np.linalg.norm(np.subtract(reached[:3], target[:3])) < 0.001
    q = [0.3, -1.4, 1.4, -1.5, -1.5, 0.2]
    r = run(core, "MOVE_J %s speed=2" % " ".join(map(str, q)))
    assert r.success, r.message
    assert np.max(np.abs(np.subtract(standin.get_joint_positions(), q))) < 1e-3
    r = run(core, "MOVE_HOME")
    assert r.success and np.max(np.abs(np.subtract(standin.get_joint_positions(), HOME))) < 1e-3
    assert r.result["duration_s"] > 0.0
    # a move to where the arm stands is answered at once without a motion (duration 0), joint and linear alike
    for again in ("MOVE_HOME", "MOVE_L %s" % " ".join("%.6f" % v for v in standin.get_tcp_pose())):
        r = run(core, again)
        assert r.success and r.result["duration_s"] == 0.0, (again, r.message, r.result)
    assert np.max(np.abs(np.subtract(standin.get_joint_positions(), HOME))) < 1e-3
    assert run(core, "MOVE_HOME nowhere").code.value == "INVALID_ARGUMENT"


def test_speeds_from_the_polled_states_sample_ticks_are_the_arms_true_speed(rig, core):
    """While a MOVE_L runs at 0.15 m/s (1.5 m/s of wall time at time scale 10), the speed between any two states the
    bridge polled, their TCP distance over their ``sample_tick`` difference, is the commanded one: the stand-in's
    arm moves by the cycles its clock counts, the worker reads a stamp and a pose of one package, the tick follows
    the controller's clock. (The stand-in's arm moved by each late cycle's wall time while the stamp counted one
    cycle: such speeds on a busy machine came out at up to 2.4 times the true one, and the spray valve opened in
    the turn before a lane.) The poll's own arrival times give no such speed."""
    standin, arm = rig
    start = standin.get_tcp_pose()
    target = list(start)
    target[1] += 0.5
    samples = []
    done = []
    import threading

    def move():
        done.append(run(core, "MOVE_L %s speed=0.15 accel=5" % " ".join("%.6f" % v for v in target)))
    mover = threading.Thread(target=move)
    mover.start()
    while mover.is_alive():
        st = arm.cached_state()
        if st.get("sample_tick") is not None and (not samples or st["sample_tick"] > samples[-1][0]):
            samples.append((st["sample_tick"], np.asarray(st["tcp"][:3])))
        time.sleep(0.002)
    mover.join()
    assert done and done[0].success, done
    speeds = np.array([np.linalg.norm(b[1] - a[1]) / (b[0] - a[0]) for a, b in zip(samples, samples[1:])])
    # the pairs between the run-up's and the braking's (accel 5 m/s2: 2 mm each of the 0.5 m)
    cruise = speeds[speeds > 0.5 * 1.5][1:-1]
    assert len(cruise) >= 5, speeds
    assert np.all(np.abs(cruise - 1.5) < 0.1 * 1.5), np.round(speeds, 3)


def test_move_path_visits_every_waypoint(rig, core):
    standin, _ = rig
    p0 = standin.get_tcp_pose()
    pts = [list(p0), list(p0)]
    pts[0][1] += 0.05
    pts[1][1] += 0.05
    pts[1][2] += 0.05
    text = "/".join(":".join("%.6f" % v for v in p) for p in pts)
    r = run(core, "MOVE_PATH %s speed=0.5" % text)
    assert r.success, r.message
    assert r.result["waypoints"] == 2
    assert np.linalg.norm(np.subtract(standin.get_tcp_pose()[:3], pts[1][:3])) < 0.001
    bad = run(core, "MOVE_PATH 0.1:0.2:0.3")
    assert bad.code.value == "INVALID_ARGUMENT" and "waypoint 1" in bad.message


def test_tool_output_switches_the_controller_output(rig, core):
    standin, _ = rig
    assert run(core, "TOOL_OUTPUT 1 true").success
    assert standin.get_standard_digital_outputs()[1] is True
    assert run(core, "TOOL_OUTPUT 1 false").success
    assert standin.get_standard_digital_outputs()[1] is False


def test_stop_during_a_long_move_stops_the_arm_within_200ms_of_motion_time(rig_realtime, core):
    standin, _ = rig_realtime
    execution = core.dispatcher.submit("MOVE_J 2.5 -1.5708 1.5708 -1.5708 -1.5708 0 speed=1.0", Interface.SERVICE)
    assert wait_until(lambda: standin.get_state()["moving"], timeout=5.0)
    time.sleep(0.5)
    t_stop = standin.get_state()["motion_time"]
    r = run(core, "STOP")
    assert r.success
    assert execution.wait(3.0).code.value == "ABORTED"
    assert wait_until(lambda: not standin.get_state()["moving"], timeout=2.0)
    # motion time advances with wall time here (time scale 1): the standstill came within 200 ms of STOP
    states = []
    end = time.monotonic() + 0.5
    while time.monotonic() < end:
        states.append(standin.get_state())
    stopped_at = min(s["motion_time"] for s in states)
    assert stopped_at - t_stop < 0.2 + 0.05, "arm still moving %.3f s after STOP" % (stopped_at - t_stop)
    assert nothing_running(standin)


def test_stop_arm_cancels_only_the_arm_command(rig, core):
    standin, _ = rig
    execution = core.dispatcher.submit("MOVE_J 2.5 -1.5708 1.5708 -1.5708 -1.5708 0 speed=0.3", Interface.ACTION)
    assert wait_until(lambda: standin.get_state()["moving"], timeout=5.0)
    assert run(core, "STOP_ARM").success
    r = execution.wait(3.0)
    assert r.code.value == "ABORTED" and "STOP_ARM" in r.message
    assert wait_until(lambda: nothing_running(standin), timeout=2.0)


def test_action_cancel_stops_the_arm(rig, core):
    standin, _ = rig
    execution = core.dispatcher.submit("MOVE_J -2.5 -1.5708 1.5708 -1.5708 -1.5708 0 speed=0.3", Interface.ACTION)
    assert wait_until(lambda: standin.get_state()["moving"], timeout=5.0)
    execution.cancel("action goal canceled by its client")
    assert execution.wait(3.0).code.value == "ABORTED"
    assert wait_until(lambda: nothing_running(standin), timeout=2.0)


def _unlock_on_the_dashboard(standin, timeout=10.0):
    """What someone at the teach pendant would do: 'unlock protective stop' on the controller's dashboard server
    (port 29999, ur_rtde's DashboardClient), retried until the controller's 5 s unlock delay has passed."""
    import dashboard_client
    dash = dashboard_client.DashboardClient(standin.address)
    dash.connect()
    try:
        end = time.monotonic() + timeout
        while standin.get_state()["safety_mode"] != 1 and time.monotonic() < end:
            try:
                dash.unlockProtectiveStop()
            except RuntimeError:             # "Cannot unlock protective stop until 5s after occurrence"
                pass
            time.sleep(0.1)
    finally:
        dash.disconnect()
    state = standin.get_state()
    assert state["safety_mode"] == 1 and state["runtime_state_name"] == "PLAYING", state


def test_protective_stop_is_latched_until_reset_arm(rig, core):
    standin, arm = rig
    start = standin.get_tcp_pose()
    target = list(start)
    target[0] += 0.3
    execution = core.dispatcher.submit("MOVE_L %s speed=0.05" % " ".join("%.6f" % v for v in target),
                                       Interface.SERVICE)
    assert wait_until(lambda: standin.get_state()["moving"], timeout=5.0)
    standin.inject_protective_stop("test: collision")
    r = execution.wait(5.0)
    assert r is not None and r.code.value == "HARDWARE_ERROR" and "protective stop" in r.message
    assert wait_until(lambda: nothing_running(standin), timeout=2.0)
    health = core.dispatcher.health()["arm"]           # the source of the node's /diagnostics
    assert health_level(health) == HEALTH_ERROR and "protective stop" in health["last_error"], health
    # the controller is back to normal (unlocked on its own dashboard, not through LOCEM) ...
    _unlock_on_the_dashboard(standin)
    assert wait_until(lambda: arm.cached_state().get("safety_mode") == 1 and arm.cached_state()["program_running"],
                      timeout=3.0), arm.cached_state()
    # ... and the bridge still refuses every move until an operator sends RESET_ARM
    q0 = standin.get_joint_positions()
    refused = run(core, "MOVE_HOME")
    assert refused.code.value == "HARDWARE_ERROR" and "RESET_ARM" in refused.message
    refused = run(core, "MOVE_L %s speed=0.1" % " ".join("%.6f" % v for v in start))
    assert refused.code.value == "HARDWARE_ERROR" and "RESET_ARM" in refused.message
    time.sleep(0.2)
    assert standin.get_joint_positions() == q0 and not standin.get_state()["moving"]
    assert "safety stop" in run(core, "STATUS").result["health"]["arm"]["device"]
    assert health_level(core.dispatcher.health()["arm"]) == HEALTH_ERROR
    reset = run(core, "RESET_ARM")
    assert reset.success, reset.message
    assert "protective stop" in reset.result["cleared"]
    assert health_level(core.dispatcher.health()["arm"]) == HEALTH_OK
    ok = run(core, "MOVE_HOME")
    assert ok.success, ok.message


def test_set_payload_reaches_the_controller(rig, core):
    standin, _ = rig
    assert rtde_payload(standin.address) == {"mass": 0.0, "cog": [0.0, 0.0, 0.0]}
    r = run(core, "SET_PAYLOAD 1.75 0.01 -0.02 0.065")
    assert r.success, r.message
    assert r.result == {"mass": 1.75, "cog": [0.01, -0.02, 0.065]}
    # read back by a plain RTDE client from the controller's outputs 'payload' / 'payload_cog'
    seen = rtde_payload(standin.address)
    assert seen["mass"] == pytest.approx(1.75) and seen["cog"] == pytest.approx([0.01, -0.02, 0.065])
    bad = run(core, "SET_PAYLOAD 20 0 0 0")
    assert bad.code.value == "INVALID_ARGUMENT" and "mass" in bad.message
    assert rtde_payload(standin.address)["mass"] == pytest.approx(1.75)


def test_move_l_overrunning_its_deadline_ends_timeout_with_the_arm_stopped(rig_short_deadline, core):
    standin, arm = rig_short_deadline
    start = standin.get_tcp_pose()
    target = list(start)
    target[0] += 0.3
    # nominal 0.3 m / 0.05 m/s = 6 s of motion time (0.6 s wall at time scale 10); deadline 5 % of it: ~0.3 s
    t0 = time.monotonic()
    r = run(core, "MOVE_L %s speed=0.05" % " ".join("%.6f" % v for v in target))
    took = time.monotonic() - t0
    assert r.code.value == "TIMEOUT" and "did not finish within" in r.message, r
    assert took < 0.3 + 0.5, "answered after %.2f s" % took
    assert wait_until(lambda: nothing_running(standin), timeout=2.0)
    reached = standin.get_tcp_pose()
    left = float(np.linalg.norm(np.subtract(reached[:3], target[:3])))
    assert 0.02 < left < 0.29, "stopped %.3f m before the target: the move was cut short, not completed" % left
    time.sleep(0.3)
    assert standin.get_tcp_pose() == reached                  # and it stays where it stopped


def test_controller_restart_is_followed_by_an_automatic_reconnect(rig, core):
    standin, arm = rig
    assert run(core, "GET_JOINTS").success
    standin.stop()
    assert wait_until(lambda: arm.health()["link"] != "up", timeout=3.0)
    r = run(core, "MOVE_HOME")
    assert r.code.value in ("HARDWARE_ERROR", "NOT_READY")
    standin.start_server()
    assert wait_until(lambda: arm.health()["link"] == "up", timeout=20.0), arm.health()
    assert arm.reconnects >= 1
    q = [0.2, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
    r = run(core, "MOVE_J %s" % " ".join(map(str, q)))
    assert r.success, r.message
    assert np.max(np.abs(np.subtract(standin.get_joint_positions(), q))) < 1e-3


def test_emergency_stop_needs_reset_arm_after_release(rig, core):
    standin, arm = rig
    standin.inject_emergency_stop("test: e-stop pressed")
    assert wait_until(lambda: arm.safety_latched, timeout=3.0)
    r = run(core, "MOVE_HOME")
    assert r.code.value == "HARDWARE_ERROR" and "emergency" in r.message
    standin.release_emergency_stop()
    reset = run(core, "RESET_ARM")
    assert reset.success, reset.message
    assert "emergency" in reset.result["cleared"] and "power on" in reset.result["steps"]
    q = [0.1, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
    r = run(core, "MOVE_J %s" % " ".join(map(str, q)))
    assert r.success, r.message


_LOCEM_CHILD = """
import json, sys, time
from locem_bridge.bridges.commands_arm import ArmCommands
from locem_bridge.bridges.ur_arm import UrRtdeArm
from locem_bridge.locem.core import LocemCore
from locem_bridge.locem.registry import Interface
arm = UrRtdeArm(json.loads(sys.argv[1]))
arm.start()
core = LocemCore()
core.install(ArmCommands(arm))
assert arm.wait_ready(20.0), arm.health()
core.dispatcher.submit("MOVE_J 2.5 -1.5708 1.5708 -1.5708 -1.5708 0 speed=0.3", Interface.SERVICE)
print("moving", flush=True)
time.sleep(600)
"""


def test_bridge_arms_the_controller_watchdog_and_a_killed_locem_leaves_the_arm_stopped(robot):
    """LOCEM (here a child process holding the arm bridge) killed with kill -9 during a long joint move: its
    polls stop kicking the controller's RTDE watchdog, the controller stops the program and the arm."""
    import json
    import os
    import signal
    import subprocess
    import sys
    from locem_bridge.sim.ur.process import StandInProcess
    address = next_ur_address()
    standin = StandInProcess(address, time_scale=1.0).start()
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")
    env = dict(os.environ, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
    child = subprocess.Popen([sys.executable, "-c", _LOCEM_CHILD, json.dumps(arm_cfg(robot, address))],
                             stdout=subprocess.PIPE, env=env, text=True)
    try:
        assert child.stdout.readline().strip() == "moving"
        assert wait_until(lambda: standin.get_state()["moving"], timeout=5.0)
        state = standin.get_state()
        assert state["rtde_watchdog"] == ["input_int_register_0", 1.0], state
        time.sleep(1.5)                                   # the bridge's polls keep it alive
        assert standin.get_state()["moving"] and standin.get_state()["watchdog_trips"] == 0
        killed = time.monotonic()
        os.kill(child.pid, signal.SIGKILL)
        child.wait(5.0)
        stopped = wait_until(lambda: (lambda s: s if not s["moving"] else None)(standin.get_state()), timeout=5.0)
        elapsed = time.monotonic() - killed
        assert stopped, standin.get_state()
        assert stopped["program"] is None and stopped["runtime_state_name"] == "STOPPED", stopped
        # 1 s watchdog + braking from 0.3 rad/s (the worker, orphaned, may also disconnect first)
        assert elapsed <= 2.0, elapsed
        # a fresh bridge (the respawned LOCEM) finds the arm stopped, uploads its script and arms the watchdog
        arm = UrRtdeArm(arm_cfg(robot, address))
        arm.start()
        try:
            assert arm.wait_ready(20.0), arm.health()
            assert standin.get_state()["rtde_watchdog"] == ["input_int_register_0", 1.0]
            assert not standin.get_state()["moving"]
        finally:
            arm.close()
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(5.0)
        standin.close()


def test_before_its_first_connection_every_arm_command_is_not_ready_with_the_reason(robot, core):
    """A fresh LOCEM whose UR controller does not answer yet: NOT_READY naming why, never HARDWARE_ERROR."""
    arm = UrRtdeArm(arm_cfg(robot, next_ur_address()), connect_timeout=2.0)     # nothing listens there
    arm.start()
    core.install(ArmCommands(arm))
    try:
        for text in ("GET_JOINTS", "GET_TCP_POSE", "MOVE_HOME", "MOVE_J 0 -1.5708 1.5708 -1.5708 -1.5708 0"):
            r = run(core, text)
            assert r.code.value == "NOT_READY" and "not connected yet" in r.message, (text, r.code, r.message)
    finally:
        arm.close()


def test_watchdog_kicks_never_overwrite_force_mode_before_the_controller_saw_it(rig):
    """forceMode is a realtime command (answered at once, read by the script's next cycle); the state poll's
    watchdog kick writes command 0 into the same register and must not replace it before that cycle."""
    standin, arm = rig
    for _ in range(5):
        arm.force_mode_start(arm.tcp_pose(), 10.0, 0.02)
        for _ in range(3):
            arm._poll()                                  # what the 50 Hz supervisor and wait_for_contact do
        assert wait_until(lambda: standin.get_force_mode() is not None, timeout=1.0), "force mode never started"
        arm.force_mode_stop()
        assert wait_until(lambda: standin.get_force_mode() is None, timeout=2.0)
