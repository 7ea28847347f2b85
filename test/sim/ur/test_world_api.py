"""The Python API the PyBullet world uses: step listener, fault injection, IO, restart (in-process)."""
import time

import numpy as np

from locem_bridge.sim.ur import ArmSnapshot, UrControllerStandIn


def test_step_listener_sees_every_cycle_and_can_trigger_a_protective_stop(ur_address):
    ctl = UrControllerStandIn(ur_address, time_scale=4.0)
    seen = []
    wall = []

    def on_step(snap: ArmSnapshot) -> None:
        seen.append(snap)
        wall.append(time.perf_counter())
        if len(seen) == 50:                       # e.g. the world detected a collision
            ctl.inject_protective_stop("collision with wall_1")

    ctl.add_step_listener(on_step)
    ctl.start()
    try:
        t_end = time.time() + 2.0
        while len(seen) < 100 and time.time() < t_end:
            time.sleep(0.01)
        assert len(seen) >= 100
        first, last = seen[0], seen[-1]
        assert len(first.q) == 6 and len(first.tcp_pose) == 6
        assert np.allclose(first.tcp_pose, ctl.get_tcp_pose(), atol=1e-12)
        # motion time runs 4x faster than the wall clock (a stall longer than 50 ms is not caught up)
        ratio = (last.motion_time - first.motion_time) / (wall[len(seen) - 1] - wall[0])
        assert 3.0 < ratio < 4.4
        assert last.safety_mode == 3
        state = ctl.get_state()
        assert state["safety_mode_name"] == "PROTECTIVE_STOP"
        assert "collision with wall_1" in state["last_error"]
        ctl.remove_step_listener(on_step)
        n = len(seen)
        time.sleep(0.05)
        assert len(seen) == n
    finally:
        ctl.stop()


def test_stop_start_keeps_arm_state_and_joins_threads(ur_address):
    import threading
    before = {t.name for t in threading.enumerate()}
    ctl = UrControllerStandIn(ur_address, q0=[0.1, -1.2, 1.3, -1.5, -1.6, 0.2])
    ctl.start()
    ctl.set_standard_digital_input(3, True)
    ctl.stop()
    assert {t.name for t in threading.enumerate()} - before == set()
    ctl.start()
    try:
        assert np.allclose(ctl.get_joint_positions(), [0.1, -1.2, 1.3, -1.5, -1.6, 0.2])
        assert ctl.arm.values["actual_digital_input_bits"] == (1 << 3,)
        assert ctl.get_state()["runtime_state_name"] == "STOPPED"
    finally:
        ctl.stop()


def test_contact_provider_from_the_world_drives_the_force_reading(ur_address):
    """The world injects a callable that knows its walls; the stand-in asks it every cycle with the TCP pose."""
    import pytest
    from locem_bridge.sim.ur import ConfigurationError
    ctl = UrControllerStandIn(ur_address, time_scale=1.0)
    asked = []

    def wall(tcp_pose):
        asked.append(list(tcp_pose))
        x_face = tcp_pose[0] - 0.001                  # the TCP is 1 mm into a wall whose outward normal is +x
        return (tcp_pose[0] - x_face, [1.0, 0.0, 0.0])

    with pytest.raises(ConfigurationError, match="must be callable"):
        ctl.set_contact_provider("wall_1")
    with pytest.raises(ConfigurationError, match="stiffness must be a finite number > 0"):
        ctl.set_contact_provider(wall, stiffness=-1.0)
    ctl.set_contact_provider(wall, stiffness=10000.0)
    ctl.start()
    try:
        end = time.time() + 2.0
        while len(asked) < 20 and time.time() < end:
            time.sleep(0.01)
        assert np.allclose(asked[-1], ctl.get_tcp_pose(), atol=1e-9)
        assert np.allclose(ctl.get_tcp_force(), [10.0, 0, 0, 0, 0, 0], atol=1e-6)     # 10 kN/m x 1 mm
        ctl.set_contact_provider(None)
        assert np.allclose(ctl.get_tcp_force(), 0.0)
    finally:
        ctl.stop()


def test_protective_stop_of_an_arm_at_rest_leaves_it_at_rest(ur_address):
    """A protective stop while nothing moves starts no stop motion: the arm is not reported moving, and the world
    may still set the joints (a collision detected by the world while it places the arm once made the next
    set_joint_positions fail with 'cannot set joint positions while the arm moves'). Not started: no control
    thread, so nothing can end a stop motion in between."""
    ctl = UrControllerStandIn(ur_address, time_scale=2.0)
    ctl.inject_protective_stop("collision: arm:wrist_3_link with wall_1")
    state = ctl.get_state()
    assert state["safety_mode_name"] == "PROTECTIVE_STOP"
    assert state["moving"] is False
    q = [0.1, -1.4, 1.5, -1.6, -1.5, 0.2]
    ctl.set_joint_positions(q)
    assert np.allclose(ctl.get_joint_positions(), q)
