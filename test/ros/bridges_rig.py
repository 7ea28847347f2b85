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
