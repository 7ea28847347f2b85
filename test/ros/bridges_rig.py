"""Shared by the bridge rostest nodes: the worksite stand-ins on the addresses the LOCEM node under test was given
(``/locem/robot_overrides``), and small ROS helpers."""
import os
import sys
import time

import rospy

HERE = os.path.dirname(os.path.abspath(__file__))
BRIDGE_TESTS = os.path.join(os.path.dirname(HERE), "bridges")
if BRIDGE_TESTS not in sys.path:
    sys.path.insert(0, BRIDGE_TESTS)

from bridge_rigs import ROBOT_YAML, SHORT_WALL, WorksiteRig  # noqa: E402
from locem_bridge.bridges.config import load_robot_config  # noqa: E402
from locem_bridge.srv import Command  # noqa: E402
from rostest_support import result_of  # noqa: E402


def start_worksite(time_scale=4.0):
    overrides = rospy.get_param("/locem/robot_overrides")
    return WorksiteRig(load_robot_config(ROBOT_YAML), SHORT_WALL, time_scale=time_scale, overrides=overrides)


class Reply:
    def __init__(self, success, code, message, data):
        self.success, self.code, self.message, self.data = success, code, message, data

    def __repr__(self):
        return "Reply(%s, %s, %r)" % (self.success, self.code, self.message)


class Locem:
    """/locem/command through a rospy service proxy; results parsed."""

    def __init__(self):
        rospy.wait_for_service("/locem/command", timeout=60)
        self._call = rospy.ServiceProxy("/locem/command", Command)

    def __call__(self, text):
        reply = self._call(text)
        return Reply(reply.success, reply.code, reply.message, result_of(reply.result))

    def wait_ready(self, devices=("arm", "compressor", "base"), timeout=60.0):
        end = time.monotonic() + timeout
        health = {}
        while time.monotonic() < end:
            health = self("STATUS").data["health"]
            if all(health.get(d, {}).get("link") == "up" for d in devices):
                return health
            time.sleep(0.2)
        raise AssertionError("devices not up within %.0f s: %s" % (timeout, health))


class ArmMotionSampler:
    """Ground truth of the arm while a stop is measured. The UR stand-in records ``last_moving_time``, its own sim
    time (``motion_time``) at the end of the last control cycle in which the arm moved; a light thread reads its
    state every ``period`` s of wall time, each sample stamped with the wall clock (``time.time()``, the clock of ROS
    stamps here) at the middle of its request, so a wall instant maps to the controller's sim time."""

    def __init__(self, standin, period=0.01):
        import threading
        self.standin = standin
        self.period = period
        self.samples = []                   # (wall, motion_time, last_moving_time)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        end = time.monotonic() + 60.0
        while not self._stop.is_set() and time.monotonic() < end:
            t0 = time.time()
            st = self.standin.get_state()
            t1 = time.time()
            self.samples.append(((t0 + t1) / 2.0, st["motion_time"], st["last_moving_time"]))
            self._stop.wait(self.period)

    def close(self):
        self._stop.set()
        self._thread.join(2.0)

    def motion_time_at(self, wall):
        """The controller's sim time at the wall instant ``wall``, interpolated between the samples around it."""
        before = [s for s in self.samples if s[0] <= wall]
        after = [s for s in self.samples if s[0] > wall]
        assert before and after, "no samples around %.3f" % wall
        (w0, m0, _), (w1, m1, _) = before[-1], after[0]
        return m0 + (m1 - m0) * (wall - w0) / (w1 - w0)

    def stop_time(self, accepted_wall):
        """(sim s from ``accepted_wall`` to the end of the last control cycle with motion, the uncertainty of the
        wall -> sim mapping in sim s: the sim time between the two samples around ``accepted_wall``)."""
        t_acc = self.motion_time_at(accepted_wall)
        before = [s for s in self.samples if s[0] <= accepted_wall][-1]
        after = [s for s in self.samples if s[0] > accepted_wall][0]
        last = self.samples[-1][2]
        return max(0.0, last - t_acc), after[1] - before[1]
