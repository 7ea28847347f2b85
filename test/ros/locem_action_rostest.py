#!/usr/bin/env python3
"""rostest: /locem/command_action -- feedback, cancel stops the command, rejection, BUSY, STOP, concurrency."""
import time
import unittest

import actionlib
import rospy
import rostest
from actionlib_msgs.msg import GoalStatus
from locem_bridge.msg import CommandAction, CommandGoal
from locem_bridge.srv import Command

from rostest_support import result_of, wait_until

PKG = "locem_bridge"


class LocemActionTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("locem_action_test", anonymous=True)
        rospy.wait_for_service("/locem/command", timeout=30)
        cls.call = staticmethod(rospy.ServiceProxy("/locem/command", Command))
        cls.clients = [actionlib.SimpleActionClient("/locem/command_action", CommandAction) for _ in range(2)]
        for client in cls.clients:
            assert client.wait_for_server(rospy.Duration(30)), "action server did not come up"

    def tearDown(self):
        self.call("STOP")

    def test_wait_reports_feedback_and_succeeds(self):
        feedback = []
        client = self.clients[0]
        client.send_goal(CommandGoal("WAIT 1.0"), feedback_cb=feedback.append)
        self.assertTrue(client.wait_for_result(rospy.Duration(10)))
        self.assertEqual(client.get_state(), GoalStatus.SUCCEEDED)
        result = client.get_result()
        self.assertTrue(result.success)
        self.assertEqual(result.code, "OK")
        self.assertEqual(result_of(result.result), {"waited_s": 1.0})
        progress = [f.progress for f in feedback]
        self.assertGreaterEqual(len(progress), 5)
        self.assertEqual(progress, sorted(progress))
        self.assertEqual({f.state for f in feedback}, {"running"})
        self.assertGreater(progress[-1], 0.9)

    def test_cancel_stops_the_command_and_frees_its_resource(self):
        client = self.clients[0]
        client.send_goal(CommandGoal("WAIT 30 hold=arm"))
        self.assertTrue(wait_until(lambda: client.get_state() == GoalStatus.ACTIVE, 5))
        start = time.monotonic()
        client.cancel_goal()
        self.assertTrue(client.wait_for_result(rospy.Duration(5)))
        elapsed = time.monotonic() - start
        self.assertEqual(client.get_state(), GoalStatus.PREEMPTED)
        self.assertEqual(client.get_result().code, "ABORTED")
        self.assertLess(elapsed, 1.0)
        status = result_of(self.call("STATUS").result)
        self.assertEqual(status["running"], [])
        self.assertEqual(status["resources"], {})

    def test_invalid_goal_is_rejected_with_the_reason(self):
        client = self.clients[0]
        client.send_goal(CommandGoal("WAIT -1"))
        self.assertTrue(client.wait_for_result(rospy.Duration(5)))
        self.assertEqual(client.get_state(), GoalStatus.REJECTED)
        self.assertEqual(client.get_result().code, "INVALID_ARGUMENT")
        self.assertIn("argument 'seconds'", client.get_result().message)

    def test_help_of_an_unknown_command_is_rejected_as_a_goal(self):
        client = self.clients[0]
        client.send_goal(CommandGoal("HELP NO_SUCH_COMMAND"))
        self.assertTrue(client.wait_for_result(rospy.Duration(5)))
        self.assertEqual(client.get_state(), GoalStatus.REJECTED)
        result = client.get_result()
        self.assertEqual((result.success, result.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("no command named 'NO_SUCH_COMMAND'", result.message)
        self.assertIn("command registry", result.message)
        client.send_goal(CommandGoal("HELP WAIT"))  # a known name is still described
        self.assertTrue(client.wait_for_result(rospy.Duration(5)))
        self.assertEqual(client.get_state(), GoalStatus.SUCCEEDED)
        self.assertIn("WAIT seconds", client.get_result().message)

    def test_busy_goal_is_rejected_and_stop_aborts_the_running_one(self):
        first, second = self.clients
        first.send_goal(CommandGoal("WAIT 20 hold=base"))
        self.assertTrue(wait_until(lambda: first.get_state() == GoalStatus.ACTIVE, 5))
        second.send_goal(CommandGoal("WAIT 1 hold=base"))
        self.assertTrue(second.wait_for_result(rospy.Duration(5)))
        self.assertEqual(second.get_state(), GoalStatus.REJECTED)
        self.assertEqual(second.get_result().code, "BUSY")
        start = time.monotonic()
        self.assertTrue(self.call("STOP").success)
        self.assertTrue(first.wait_for_result(rospy.Duration(5)))
        self.assertLess(time.monotonic() - start, 1.0)
        self.assertEqual(first.get_state(), GoalStatus.ABORTED)
        self.assertEqual(first.get_result().code, "ABORTED")
        self.assertIn("STOP", first.get_result().message)

    def test_goals_on_different_resources_run_side_by_side(self):
        arm, base = self.clients
        start = time.monotonic()
        arm.send_goal(CommandGoal("WAIT 1.0 hold=arm"))
        base.send_goal(CommandGoal("WAIT 1.0 hold=base"))
        self.assertTrue(arm.wait_for_result(rospy.Duration(10)) and base.wait_for_result(rospy.Duration(10)))
        self.assertEqual((arm.get_state(), base.get_state()), (GoalStatus.SUCCEEDED, GoalStatus.SUCCEEDED))
        self.assertLess(time.monotonic() - start, 1.8)


if __name__ == "__main__":
    rostest.rosrun(PKG, "locem_action", LocemActionTest)
