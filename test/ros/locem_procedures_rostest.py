#!/usr/bin/env python3
"""rostest: /locem/procedure/* -- queue order, pause/resume, cancel, errors, STOP; state on change only."""
import threading
import time
import unittest

import rospy
import rostest
from locem_bridge.msg import ProcedureState
from locem_bridge.srv import Command, ProcedureAdd, ProcedureControl

from rostest_support import result_of, wait_until

PKG = "locem_bridge"
NS = "/locem/procedure/"


class LocemProceduresTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("locem_procedures_test", anonymous=True)
        for name in ("add", "query_state", "cancel", "pause", "resume"):
            rospy.wait_for_service(NS + name, timeout=30)
        cls.add = staticmethod(rospy.ServiceProxy(NS + "add", ProcedureAdd))
        cls.ops = {name: rospy.ServiceProxy(NS + name, ProcedureControl)
                   for name in ("query_state", "cancel", "pause", "resume")}
        cls.call = staticmethod(rospy.ServiceProxy("/locem/command", Command))
        cls.states = []
        cls.commands = []
        cls.lock = threading.Lock()
        rospy.Subscriber(NS + "state", ProcedureState, cls._record, queue_size=1000)
        rospy.sleep(1.0)

    @classmethod
    def _record(cls, message):
        with cls.lock:
            cls.states.append((message.id, message.state, message.code))
            cls.commands.append(message.command)

    def op(self, name, procedure_id):
        return self.ops[name](procedure_id)

    def history(self, procedure_id):
        with self.lock:
            return [s for i, s, _ in self.states if i == procedure_id]

    def queue(self, command):
        reply = self.add(command)
        self.assertTrue(reply.success, reply.message)
        self.assertEqual(reply.state, "queued")
        return reply.id

    def state(self, procedure_id):
        return self.op("query_state", procedure_id).state

    def test_queue_runs_in_order_with_pause_resume_and_cancel(self):
        p1, p2, p3 = self.queue("WAIT 1.0"), self.queue("WAIT 0.2"), self.queue("WAIT 0.2")
        self.assertTrue(wait_until(lambda: self.state(p1) == "running", 5))
        self.assertEqual((self.state(p2), self.state(p3)), ("queued", "queued"))
        started = time.monotonic()
        self.assertEqual(self.op("pause", p1).state, "paused")
        time.sleep(0.6)
        self.assertEqual((self.state(p1), self.state(p2)), ("paused", "queued"))
        cancelled = self.op("cancel", p3)
        self.assertEqual((cancelled.state, cancelled.result_code), ("finished", "ABORTED"))
        self.assertEqual(self.op("resume", p1).state, "running")
        self.assertTrue(wait_until(lambda: self.state(p2) == "finished", 10))
        self.assertGreaterEqual(time.monotonic() - started, 0.6)
        first = self.op("query_state", p1)
        self.assertEqual((first.state, first.result_code), ("finished", "OK"))
        self.assertEqual(result_of(first.result), {"waited_s": 1.0})
        self.assertTrue(wait_until(lambda: len(self.history(p2)) == 3, 3))
        self.assertEqual(self.history(p1), ["queued", "running", "paused", "running", "finished"])
        self.assertEqual(self.history(p2), ["queued", "running", "finished"])
        self.assertEqual(self.history(p3), ["queued", "finished"])
        with self.lock:
            finished = [i for i, s, _ in self.states if s == "finished" and i in (p1, p2)]
        self.assertEqual(finished, [p1, p2])

    def test_errors_name_the_problem(self):
        unknown = self.op("query_state", 9999)
        self.assertEqual((unknown.success, unknown.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("no procedure with id 9999", unknown.message)
        bad = self.add("WAIT soon")
        self.assertEqual((bad.success, bad.code), (False, "INVALID_ARGUMENT"))
        p1, p2 = self.queue("WAIT 2"), self.queue("WAIT 0.1")
        self.assertTrue(wait_until(lambda: self.state(p1) == "running", 5))
        refused = self.op("pause", p2)
        self.assertEqual((refused.success, refused.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("only the running procedure can be paused", refused.message)
        resumed = self.op("resume", p1)
        self.assertFalse(resumed.success)
        self.call("STOP")

    def test_help_of_an_unknown_command_is_refused_and_never_queued(self):
        refused = self.add("HELP NO_SUCH_COMMAND")
        self.assertEqual((refused.success, refused.code, refused.id), (False, "INVALID_ARGUMENT", 0))
        self.assertIn("no command named 'NO_SUCH_COMMAND'", refused.message)
        self.assertIn("command registry", refused.message)
        digits = self.add("WAIT \u0661")  # an Arabic-Indic one is not a number here
        self.assertEqual((digits.success, digits.code), (False, "INVALID_ARGUMENT"))
        self.assertIn("argument 'seconds'", digits.message)
        known = self.queue("HELP WAIT")
        self.assertTrue(wait_until(lambda: self.state(known) == "finished", 5))
        self.assertEqual(self.op("query_state", known).result_code, "OK")
        self.assertTrue(wait_until(lambda: self.history(known)[-1:] == ["finished"], 3))
        with self.lock:  # nothing was queued or published for the refused ones
            self.assertEqual({c for c in self.commands if c.startswith("HELP") or c.startswith("WAIT \u0661")},
                             {"HELP WAIT"})

    def test_stop_cancels_the_running_procedure_and_the_queue(self):
        ids = [self.queue("WAIT 5") for _ in range(3)]
        self.assertTrue(wait_until(lambda: self.state(ids[0]) == "running", 5))
        self.assertTrue(self.call("STOP").success)
        self.assertTrue(wait_until(lambda: all(self.state(i) == "finished" for i in ids), 3))
        self.assertEqual({self.op("query_state", i).result_code for i in ids}, {"ABORTED"})
        self.assertTrue(wait_until(lambda: self.history(ids[2]) == ["queued", "finished"], 3))


if __name__ == "__main__":
    rostest.rosrun(PKG, "locem_procedures", LocemProceduresTest)
