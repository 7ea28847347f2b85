#!/usr/bin/env python3
"""rostest: with ns:=robot1 every LOCEM interface lives under /robot1/locem/ and nothing under /locem/."""
import unittest

import rosgraph
import rospy
import rostest
from locem_bridge.srv import Command

from rostest_support import rosservice_call

PKG = "locem_bridge"


class LocemNamespaceTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("locem_namespace_test", anonymous=True)
        rospy.wait_for_service("/robot1/locem/command", timeout=30)

    def test_all_interfaces_are_in_the_robot_namespace(self):
        master = rosgraph.Master("/locem_namespace_test")
        services = {name for name, _ in master.getSystemState()[2]}
        topics = {name for name, _ in master.getTopicTypes()}
        for name in ("command", "procedure/add", "procedure/query_state", "procedure/cancel", "procedure/pause",
                     "procedure/resume"):
            self.assertIn("/robot1/locem/" + name, services)
        for name in ("status", "command_in", "procedure/state", "command_action/goal", "command_action/result"):
            self.assertIn("/robot1/locem/" + name, topics)
        self.assertFalse([s for s in services | topics if s.startswith("/locem/")])

    def test_commands_work_in_the_namespace(self):
        reply = rosservice_call("/robot1/locem/command", "command: 'WAIT 0.1'")
        self.assertEqual(reply["code"], "OK")
        proxy = rospy.ServiceProxy("/robot1/locem/command", Command)
        self.assertTrue(proxy("STATUS").success)


if __name__ == "__main__":
    rostest.rosrun(PKG, "locem_namespace", LocemNamespaceTest)
