#!/usr/bin/env python3
"""rostest: the sim_worksite node -- scan, operator actions, faults, outcome, ground truth, real device clients."""
import json
import os
import tempfile
import unittest

import rospy
import rostest
from geometry_msgs.msg import Pose2D
from locem_bridge.srv import JsonCall

PKG = "locem_bridge"


class SimWorksiteTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("sim_worksite_test", anonymous=True)
        cls.calls = {}
        for name in ("scan", "mount_tool", "remove_tool", "manual_taping", "inject_fault", "clear_fault", "outcome",
                     "save_outcome"):
            rospy.wait_for_service("/sim/" + name, timeout=60)
            cls.calls[name] = rospy.ServiceProxy("/sim/" + name, JsonCall)

    def call(self, service, **args):
        reply = self.calls[service](json.dumps(args))
        return reply.success, reply.message, json.loads(reply.result)

    def test_scan_reports_walls_joints_and_areas_in_the_contract_shape(self):
        ok, _, scan = self.call("scan")
        self.assertTrue(ok)
        self.assertGreaterEqual(len(scan["walls"]), 2)
        self.assertGreaterEqual(len(scan["joints"]), 4)
        walls = {w["id"] for w in scan["walls"]}
        for joint in scan["joints"]:
            self.assertIn(joint["wall"], walls)
            self.assertIn(joint["kind"], ("vertical", "horizontal"))
            self.assertEqual(len(joint["start"]), 3)
        for area in scan["areas"]:
            self.assertGreater(area["width"] * area["height"], 0)

    def test_operator_actions_and_their_refusals(self):
        ok, message, _ = self.call("mount_tool", name="sprayer")
        self.assertFalse(ok)
        self.assertIn("allowed: taping_tool, spray_gun, sander", message)
        self.assertEqual(self.call("mount_tool", name="sander")[2], {"tool": "sander"})
        self.assertEqual(self.call("remove_tool")[2], {"tool": "sander"})
        ok, message, _ = self.call("manual_taping", joint="no_such_joint")
        self.assertFalse(ok)
        self.assertIn("unknown joint", message)
        ok, message, _ = self.call("inject_fault", kind="gremlins")
        self.assertFalse(ok)
        self.assertIn("compressor_link_drop", message)
        reply = self.calls["outcome"]("[1, 2]")
        self.assertFalse(reply.success)
        self.assertIn("JSON object", reply.message)

    def test_outcome_and_pictures(self):
        folder = tempfile.mkdtemp()
        ok, _, saved = self.call("save_outcome", folder=folder)
        self.assertTrue(ok)
        self.assertEqual(saved["collisions"], 0)
        self.assertTrue(saved["pictures"])
        for picture in saved["pictures"]:
            with open(os.path.join(folder, picture), "rb") as handle:
                self.assertEqual(handle.read(8), b"\x89PNG\r\n\x1a\n")

    def test_ground_truth_pose_is_published(self):
        pose = rospy.wait_for_message("/sim/ground_truth/base_pose", Pose2D, timeout=10)
        self.assertTrue(abs(pose.x) < 50 and abs(pose.y) < 50)

    def test_the_stand_ins_answer_their_real_clients(self):
        from pymodbus.client import ModbusTcpClient
        from rtde_receive import RTDEReceiveInterface

        client = ModbusTcpClient("127.0.0.23", port=15023, timeout=2)
        self.assertTrue(client.connect())
        try:
            reply = client.read_input_registers(0, count=4, device_id=1)
            self.assertFalse(reply.isError())
        finally:
            client.close()
        receiver = RTDEReceiveInterface("127.0.0.23")
        try:
            self.assertTrue(receiver.isConnected())
            self.assertEqual(len(receiver.getActualQ()), 6)
        finally:
            receiver.disconnect()


if __name__ == "__main__":
    rostest.rosrun(PKG, "sim_worksite", SimWorksiteTest)
