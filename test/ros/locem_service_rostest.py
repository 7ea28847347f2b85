#!/usr/bin/env python3
"""rostest: /locem/command through the real rosservice CLI and a rospy client; bad input; BUSY and STOP."""
import threading
import time
import unittest

import rospy
import rostest
from locem_bridge.srv import Command

from rostest_support import result_of, rosservice_call

PKG = "locem_bridge"


class LocemServiceTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("locem_service_test", anonymous=True)
        rospy.wait_for_service("/locem/command", timeout=30)
        cls.call = staticmethod(rospy.ServiceProxy("/locem/command", Command))

    def test_help_through_the_rosservice_cli_lists_every_command(self):
        reply = rosservice_call("/locem/command", "command: 'HELP'")
        self.assertTrue(reply["success"])
        self.assertEqual(reply["code"], "OK")
        for name in ("HELP", "STATUS", "STOP", "WAIT"):
            self.assertIn(name, reply["message"])
        names = [c["name"] for c in result_of(reply["result"])["commands"]]
        system = ["HALT", "HELP", "RESET", "RESUME", "STATUS", "STOP", "SUSPEND", "WAIT"]
        self.assertEqual(names[:len(system)], system)  # the system commands first, by name

    def test_help_name_gives_units_and_ranges(self):
        reply = rosservice_call("/locem/command", "command: 'HELP wait'")
        self.assertTrue(reply["success"])
        self.assertIn("a number from 0 to 3600 s", reply["message"])
        arg = result_of(reply["result"])["command"]["args"][0]
        self.assertEqual((arg["name"], arg["unit"], arg["minimum"], arg["maximum"]), ("seconds", "s", 0.0, 3600.0))

    def test_empty_result_is_an_empty_json_object(self):
        reply = self.call("WAIT 0")
        self.assertTrue(reply.success)
        self.assertEqual(result_of(reply.result), {"waited_s": 0.0})

    def test_bad_input_is_answered_with_code_and_reason_and_the_node_keeps_serving(self):
        cases = [
            ("", "INVALID_COMMAND", "empty command"),
            ("   ", "INVALID_COMMAND", "empty command"),
            ("FLY 1", "INVALID_COMMAND", "unknown command 'FLY'"),
            ("WIAT 1", "INVALID_COMMAND", "did you mean WAIT"),
            ("WAIT", "INVALID_ARGUMENT", "missing argument 'seconds'"),
            ("WAIT 1 2", "INVALID_ARGUMENT", "at most 1 positional argument"),
            ("WAIT abc", "INVALID_ARGUMENT", "argument 'seconds' expects a number from 0 to 3600 s"),
            ("WAIT nan", "INVALID_ARGUMENT", "argument 'seconds'"),
            ("WAIT inf", "INVALID_ARGUMENT", "argument 'seconds'"),
            ("WAIT 1e999", "INVALID_ARGUMENT", "must be finite"),
            ("WAIT 4000", "INVALID_ARGUMENT", "out of range; allowed: a number from 0 to 3600 s"),
            ("WAIT 1 hold=wings", "INVALID_ARGUMENT", "one of none, base, arm, compressor, tool"),
            ("WAIT\x07 1", "INVALID_COMMAND", "U+0007"),
            ("WAIT 1\n", "INVALID_COMMAND", "U+000A"),
            ("X" * 2000, "INVALID_COMMAND", "at most 1024"),
        ]
        for command, code, fragment in cases:
            reply = self.call(command)
            self.assertFalse(reply.success, command)
            self.assertEqual(reply.code, code, "%r: %s" % (command, reply.message))
            self.assertIn(fragment, reply.message, repr(command))
            self.assertEqual(result_of(reply.result), {})
            self.assertTrue(self.call("STATUS").success, "node stopped serving after %r" % command)

    def test_busy_then_stop_preempts(self):
        replies = {}
        holder = threading.Thread(target=lambda: replies.setdefault("long", self.call("WAIT 20 hold=arm")))
        holder.start()
        time.sleep(0.5)
        busy = self.call("WAIT 1 hold=arm")
        self.assertEqual(busy.code, "BUSY")
        self.assertIn("needs the arm, which is running 'WAIT 20 hold=arm'", busy.message)
        self.assertTrue(self.call("WAIT 0.1 hold=base").success)  # other resources stay usable
        start = time.monotonic()
        stop = self.call("STOP")
        self.assertTrue(stop.success, stop.message)
        holder.join(5.0)
        self.assertLess(time.monotonic() - start, 1.0)
        self.assertEqual(replies["long"].code, "ABORTED")
        self.assertEqual(result_of(self.call("STATUS").result)["resources"], {})


if __name__ == "__main__":
    rostest.rosrun(PKG, "locem_service", LocemServiceTest)
