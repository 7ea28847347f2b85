"""The stand-in's controller clock and its arm's motion agree, as a real controller's exact cycles do: the
RTDE ``timestamp`` of a package and the pose in it belong together even when the control thread wakes up late."""
import time

import numpy as np

from locem_bridge.sim.ur import controller as controller_module
from locem_bridge.sim.ur.controller import UrControllerStandIn


class _LateWakeUps:
    """The ``time`` module for the control loop, whose every 7th sleep oversleeps by 3 control periods and every
    23rd by 20 (a busy 2-core machine: the first kind is caught up on the period grid, the second skipped)."""

    def __init__(self, period):
        self.period = period
        self.sleeps = 0

    def sleep(self, seconds):
        self.sleeps += 1
        extra = 20 if self.sleeps % 23 == 0 else 3 if self.sleeps % 7 == 0 else 0
        time.sleep(seconds + extra * self.period)

    def __getattr__(self, name):
        return getattr(time, name)


def test_the_arm_moves_by_the_cycles_its_clock_counts_when_cycles_wake_up_late(ur_address, monkeypatch):
    """Each cycle moves the arm by the controller time its clock (the RTDE timestamp) advanced, times the time
    scale: a client's speed from two packages' stamps and poses is the true one. Moved by the wall time each cycle
    took while the clock counted one period, a late cycle's package showed the arm 4 periods further on after one
    period: a speed 2.4 times the true one between two polls at a time scale of 10 (the valve opened in the turn
    before a lane)."""
    late = _LateWakeUps(1.0 / 500.0)
    monkeypatch.setattr(controller_module, "time", late)
    ctl = UrControllerStandIn(ur_address, time_scale=10.0)
    seen = []
    tick = ctl.arm.tick

    def recording_tick(wall_dt, time_scale, controller_time=0.0):
        tick(wall_dt, time_scale, controller_time)
        seen.append((controller_time, ctl.arm.motion_time))

    ctl.arm.tick = recording_tick
    ctl.start()
    try:
        time.sleep(0.8)
    finally:
        ctl.stop()
    assert late.sleeps > 100 and ctl.overruns >= 1          # late cycles of both kinds happened
    clock, motion = np.array(seen).T
    assert np.all(np.diff(clock) > 0)
    np.testing.assert_allclose(np.diff(motion), 10.0 * np.diff(clock), rtol=1e-9, atol=1e-12)
