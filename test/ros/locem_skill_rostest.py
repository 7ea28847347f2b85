#!/usr/bin/env python3
"""rostest: the skill methods of a running LOCEM command through every way in -- SUSPEND / RESUME id=N on
/locem/command for an action goal (its id from the goal's feedback), /locem/procedure/{suspend,resume,halt,reset},
HICEM's LOCEM client (ros/hicem_locem.py) -- each transition seen on /locem/skill_state."""
import threading
import time
import unittest

import actionlib
import rospy
import rostest
from actionlib_msgs.msg import GoalStatus
from locem_bridge.hicem.errors import LocemCallError
from locem_bridge.msg import CommandAction, CommandGoal, ProcedureState, SkillTransition, Status
from locem_bridge.ros.hicem_locem import RosLocemClient
from locem_bridge.srv import Command, ProcedureAdd, ProcedureControl

from rostest_support import result_of, rosservice_call, wait_until

PKG = "locem_bridge"
NS = "/locem/procedure/"
OPS = ("query_state", "cancel", "pause", "resume", "suspend", "halt", "reset")


class LocemSkillTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("locem_skill_test", anonymous=True)
        for name in ("add",) + OPS:
            rospy.wait_for_service(NS + name, timeout=30)
        rospy.wait_for_service("/locem/command", timeout=30)
        cls.call = staticmethod(rospy.ServiceProxy("/locem/command", Command))
        cls.add = staticmethod(rospy.ServiceProxy(NS + "add", ProcedureAdd))
        cls.ops = {name: rospy.ServiceProxy(NS + name, ProcedureControl) for name in OPS}
        cls.action = actionlib.SimpleActionClient("/locem/command_action", CommandAction)
        assert cls.action.wait_for_server(rospy.Duration(30)), "action server did not come up"
        cls.lock = threading.Lock()
        cls.transitions = []
        cls.statuses = []
        cls.procedure_states = []
        subscribers = [
            rospy.Subscriber("/locem/skill_state", SkillTransition, cls._keep(cls.transitions), queue_size=1000),
            rospy.Subscriber("/locem/status", Status, cls._keep(cls.statuses), queue_size=1000),
            rospy.Subscriber(NS + "state", ProcedureState, cls._keep(cls.procedure_states), queue_size=1000)]
        # connected before the first transition is published (the topics are not latched)
        assert wait_until(lambda: all(s.get_num_connections() for s in subscribers), 10), "LOCEM's topics not seen"

    @classmethod
    def _keep(cls, into):
        def keep(message):
            with cls.lock:
                into.append(message)
        return keep

    def tearDown(self):
        self.call("STOP")

    def skill_states(self, instance):
        with self.lock:
            return [t for t in self.transitions if t.instance == str(instance)]

    def names(self, instance):
        return [t.transition for t in self.skill_states(instance)]

    def command_id_of(self, command, interface):
        """The LOCEM command id of the latest ``command`` from ``interface``, as /locem/status told it."""
        def find():
            with self.lock:
                ids = [s.id for s in self.statuses if s.interface == interface and s.command == command]
            return ids[-1] if ids else 0
        return wait_until(find, 5)

    # -- an action goal, suspended by its id through /locem/command ------------------------------------------
    def test_action_goal_suspended_and_resumed_by_its_command_id(self):
        feedback = []
        started = time.monotonic()
        self.action.send_goal(CommandGoal("WAIT 5"), feedback_cb=feedback.append)
        self.assertTrue(wait_until(lambda: feedback, 5), "no feedback after the goal was accepted")
        first = feedback[0]
        self.assertEqual((first.state, first.progress), ("running", 0.0))
        command_id = first.id
        self.assertGreater(command_id, 0)
        # the README's line, through the real rosservice command line
        reply = rosservice_call("/locem/command", "command: 'SUSPEND id=%d cause=operator'" % command_id)
        self.assertEqual((reply["success"], reply["code"]), (True, "OK"), reply)
        self.assertEqual(result_of(reply["result"])["states"], {str(command_id): "Suspended"})
        suspended_at = time.monotonic()
        self.assertTrue(wait_until(lambda: any(f.state == "paused" for f in feedback), 3))
        again = self.call("SUSPEND id=%d" % command_id)
        self.assertEqual((again.success, again.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("is Suspended (allowed in Suspended: Resume, Halt)", again.message)
        time.sleep(max(0.0, 1.0 - (time.monotonic() - suspended_at)))
        resumed = self.call("RESUME id=%d cause=operator" % command_id)
        self.assertTrue(resumed.success, resumed.message)
        self.assertTrue(self.action.wait_for_result(rospy.Duration(15)))
        elapsed = time.monotonic() - started
        self.assertEqual(self.action.get_state(), GoalStatus.SUCCEEDED)
        self.assertEqual(result_of(self.action.get_result().result), {"waited_s": 5.0})
        self.assertGreaterEqual(elapsed, 6.0)          # the suspended second does not count as waited
        self.assertEqual({f.id for f in feedback}, {command_id})  # every feedback carries the id
        self.assertTrue(wait_until(lambda: len(self.skill_states(command_id)) >= 4, 3))
        states = self.skill_states(command_id)
        self.assertEqual([t.transition for t in states],
                         ["ReadyToRunning", "RunningToSuspended", "SuspendedToRunning", "RunningToReady"])
        self.assertEqual([t.number for t in states], [2, 5, 6, 4])
        self.assertEqual([(t.from_state, t.to_state) for t in states],
                         [("Ready", "Running"), ("Running", "Suspended"), ("Suspended", "Running"),
                          ("Running", "Ready")])
        self.assertEqual([t.method for t in states], ["Start", "Suspend", "Resume", ""])
        self.assertEqual((states[0].cause, states[1].cause, states[2].cause), ("action interface", "operator",
                                                                               "operator"))
        self.assertEqual({t.skill for t in states}, {"WAIT"})
        gap = states[2].header.stamp.to_sec() - states[1].header.stamp.to_sec()
        self.assertGreaterEqual(gap, 0.9)   # stamped when the transition happened, not when published
        self.assertLess(abs(states[0].header.stamp.to_sec() - (time.time() - elapsed)), 2.0)

    def test_a_refused_method_changes_nothing(self):
        self.action.send_goal(CommandGoal("WAIT 3"))
        self.assertTrue(wait_until(lambda: self.action.get_state() == GoalStatus.ACTIVE, 5))
        command_id = self.command_id_of("WAIT 3", "action")
        refused = self.call("RESET id=%d" % command_id)
        self.assertEqual((refused.success, refused.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("Reset is not allowed", refused.message)
        self.assertIn("allowed in Running: Suspend, Halt", refused.message)
        halted = self.call("HALT id=%d cause=operator" % command_id)
        self.assertTrue(halted.success, halted.message)
        self.assertTrue(self.action.wait_for_result(rospy.Duration(5)))
        self.assertEqual(self.action.get_result().code, "ABORTED")
        self.assertIn("halted: operator", self.action.get_result().message)
        self.assertTrue(wait_until(lambda: self.names(command_id)[-1:] == ["RunningToHalted"], 3))
        self.assertEqual(self.names(command_id), ["ReadyToRunning", "RunningToHalted"])
        self.assertEqual(self.skill_states(command_id)[-1].method, "Halt")

    # -- a procedure, through the procedure services -----------------------------------------------------------
    def test_procedure_suspend_resume_halt_reset(self):
        added = self.add("WAIT 7")
        self.assertTrue(added.success, added.message)
        pid = added.id
        self.assertTrue(wait_until(lambda: self.ops["query_state"](pid).state == "running", 5))
        command_id = self.command_id_of("WAIT 7", "procedure")
        self.assertGreater(command_id, 0)

        refused = self.ops["resume"](pid)
        self.assertEqual((refused.success, refused.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("Resume is not allowed", refused.message)
        self.assertIn("allowed in Running: Suspend, Halt", refused.message)
        refused = self.ops["reset"](pid)
        self.assertEqual((refused.success, refused.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("Reset is not allowed", refused.message)
        self.assertEqual(self.ops["query_state"](pid).state, "running")   # nothing changed

        suspended = self.ops["suspend"](pid)
        self.assertEqual((suspended.success, suspended.code, suspended.state), (True, "OK", "paused"))
        refused = self.ops["suspend"](pid)
        self.assertEqual((refused.success, refused.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("allowed in Suspended: Resume, Halt", refused.message)
        resumed = self.ops["resume"](pid)
        self.assertEqual((resumed.success, resumed.state), (True, "running"))

        started = time.monotonic()
        halted = self.ops["halt"](pid)           # answered once the command has ended
        self.assertLess(time.monotonic() - started, 2.0)
        self.assertEqual((halted.success, halted.state, halted.result_code), (True, "finished", "ABORTED"))
        self.assertEqual(self.ops["query_state"](pid).state, "finished")
        refused = self.ops["halt"](pid)
        self.assertEqual((refused.success, refused.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("is Halted (allowed in Halted: Reset)", refused.message)

        reset = self.ops["reset"](pid)
        self.assertEqual((reset.success, reset.code, reset.state, reset.result_code),
                         (True, "OK", "finished", "ABORTED"))
        refused = self.ops["reset"](pid)
        self.assertEqual((refused.success, refused.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("Reset is not allowed", refused.message)

        self.assertTrue(wait_until(lambda: len(self.skill_states(command_id)) >= 5, 3))
        states = self.skill_states(command_id)
        self.assertEqual([t.transition for t in states],
                         ["ReadyToRunning", "RunningToSuspended", "SuspendedToRunning", "RunningToHalted",
                          "HaltedToReady"])
        self.assertEqual([t.method for t in states], ["Start", "Suspend", "Resume", "Halt", "Reset"])
        self.assertEqual(states[0].cause, "procedure interface")
        with self.lock:
            history = [m.state for m in self.procedure_states if m.id == pid]
        self.assertEqual(history, ["queued", "running", "paused", "running", "finished"])

    def test_queued_procedure_has_no_skill_to_suspend(self):
        first, second = self.add("WAIT 5 hold=arm").id, self.add("WAIT 5 hold=arm").id
        self.assertTrue(wait_until(lambda: self.ops["query_state"](first).state == "running", 5))
        refused = self.ops["suspend"](second)
        self.assertEqual((refused.success, refused.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("queued", refused.message)
        self.assertEqual(self.ops["query_state"](second).state, "queued")
        unknown = self.ops["halt"](99999)
        self.assertEqual((unknown.success, unknown.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("no procedure with id 99999", unknown.message)

    # -- HICEM's LOCEM client ----------------------------------------------------------------------------------
    def test_hicem_client_suspends_and_resumes_its_command(self):
        client = RosLocemClient("/locem", wait_s=10.0)
        started = time.monotonic()
        handle = client.send("WAIT 2")
        handle.suspend("operator Anna: hold on")   # right after send: waits for the goal's command id
        suspended_at = time.monotonic()
        command_id = handle.command_id
        self.assertGreater(command_id, 0)
        with self.assertRaises(LocemCallError) as refused:
            handle.suspend("again")
        self.assertEqual(refused.exception.code, "INVALID_ARGUMENT")
        self.assertIn("allowed in Suspended: Resume, Halt", str(refused.exception))
        time.sleep(max(0.0, 1.0 - (time.monotonic() - suspended_at)))
        self.assertFalse(handle.done())
        handle.resume("go on")
        self.assertTrue(wait_until(handle.done, 10))
        elapsed = time.monotonic() - started
        reply = handle.reply()
        self.assertTrue(reply.success, reply.message)
        self.assertEqual(reply.result, {"waited_s": 2.0})
        self.assertGreaterEqual(elapsed, 3.0)
        with self.assertRaises(LocemCallError) as ended:
            handle.resume()
        self.assertEqual(ended.exception.code, "INVALID_ARGUMENT")
        self.assertTrue(wait_until(lambda: len(self.skill_states(command_id)) >= 4, 3))
        states = self.skill_states(command_id)
        self.assertEqual([t.transition for t in states],
                         ["ReadyToRunning", "RunningToSuspended", "SuspendedToRunning", "RunningToReady"])
        self.assertEqual((states[1].cause, states[2].cause), ("operator_Anna:_hold_on", "go_on"))

    def test_hicem_client_without_a_locem_gives_up_on_the_id(self):
        client = RosLocemClient("/no_locem_here", wait_s=3.0)   # the goal is held, waiting for a LOCEM
        handle = client.send("WAIT 2")
        started = time.monotonic()
        with self.assertRaises(LocemCallError) as failed:
            handle.suspend("operator")
        self.assertGreaterEqual(time.monotonic() - started, 0.9)   # waited up to 1 s for the id
        self.assertLess(time.monotonic() - started, 2.0)
        self.assertEqual((failed.exception.code, handle.command_id), ("NOT_READY", 0))
        self.assertIn("command id", str(failed.exception))
        self.assertIn("WAIT 2", str(failed.exception))
        handle.cancel()


if __name__ == "__main__":
    rostest.rosrun(PKG, "locem_skill", LocemSkillTest)
