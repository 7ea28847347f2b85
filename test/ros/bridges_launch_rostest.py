#!/usr/bin/env python3
"""rostest: locem_robot.launch brings LOCEM up with every bridge from the robot YAML; odometry starts at the
site's robot_start; GOTO_TAG uses the launch's named poses."""
import math
import unittest

import rospy
import rostest

from bridges_rig import Locem, start_worksite
from rostest_support import rosservice_call

PKG = "locem_bridge"


class BridgesLaunchTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("bridges_launch_test", anonymous=True)
        cls.rig = start_worksite()
        cls.locem = Locem()
        cls.locem.wait_ready(("arm", "compressor", "base"))

    @classmethod
    def tearDownClass(cls):
        cls.rig.close()

    def test_help_lists_the_device_commands_as_served(self):
        reply = rosservice_call("/locem/command", "command: 'HELP'")
        self.assertTrue(reply["success"])
        served = {line.split()[0] for line in reply["message"].splitlines()[1:] if "[not served here]" not in line}
        for name in ("MOVE_L", "GOTO", "SPRAY_AREA", "GET_PRESSURE", "APPLY_TAPE", "SCAN", "RESET_ARM"):
            self.assertIn(name, served)
        self.assertIn("a number from 0.001 to 1 m/s", rosservice_call("/locem/command", "command: 'HELP MOVE_L'")["message"])

    def test_odometry_starts_at_the_site_robot_start_and_goto_tag_works(self):
        pose = self.locem("GET_POSE").data["pose"]
        self.assertLess(math.hypot(pose[0] - 2.4, pose[1] - 2.8), 0.01)
        reply = self.locem("GOTO_TAG back")
        self.assertTrue(reply.success, reply.message)
        x, y, th = self.rig.world.base_pose()
        self.assertLess(math.hypot(x - 2.4, y - 2.5), 0.02)
        joints = self.locem("GET_JOINTS").data["q"]
        self.assertLess(max(abs(a - b) for a, b in zip(joints, self.rig.standin.get_joint_positions())), 1e-3)


if __name__ == "__main__":
    rostest.rosrun(PKG, "bridges_launch", BridgesLaunchTest)
