#!/usr/bin/env python3
"""rostest: subscriber /locem/command_in (fire and forget) and publisher /locem/status (changes only)."""
import threading
import unittest

import rospy
import rostest
from locem_bridge.msg import CommandString, Status
from locem_bridge.srv import Command

from rostest_support import result_of, wait_until

PKG = "locem_bridge"


class LocemTopicsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("locem_topics_test", anonymous=True)
        rospy.wait_for_service("/locem/command", timeout=30)
        cls.call = staticmethod(rospy.ServiceProxy("/locem/command", Command))
        cls.events = []
        cls.lock = threading.Lock()
        rospy.Subscriber("/locem/status", Status, cls._record, queue_size=1000)
        cls.publisher = rospy.Publisher("/locem/command_in", CommandString, queue_size=10)
        assert wait_until(lambda: cls.publisher.get_num_connections() > 0, 10), "LOCEM is not subscribed"
        assert wait_until(lambda: rospy.get_published_topics() and any(
            t == "/locem/status" for t, _ in rospy.get_published_topics()), 10)
        rospy.sleep(0.5)  # let the status subscription connect

    @classmethod
    def _record(cls, message):
        with cls.lock:
            cls.events.append(message)

    def events_for(self, command, interface=None):
        with self.lock:
            return [e for e in self.events if e.command == command and (interface is None or e.interface == interface)]

    def test_subscriber_runs_commands_and_status_publishes_each_change_once(self):
        self.publisher.publish(CommandString("WAIT 0.5"))
        self.assertTrue(wait_until(lambda: any(e.state == "succeeded" for e in self.events_for("WAIT 0.5")), 5))
        events = self.events_for("WAIT 0.5")
        self.assertEqual([(e.state, e.interface, e.code) for e in events],
                         [("running", "subscriber", ""), ("succeeded", "subscriber", "OK")])
        self.assertEqual(events[0].id, events[1].id)
        self.assertEqual(result_of(events[1].result), {"waited_s": 0.5})
        self.assertGreater(events[1].header.stamp.to_sec(), 0)

    def test_rejections_from_the_subscriber_are_published(self):
        self.publisher.publish(CommandString("FLY to the moon"))
        self.assertTrue(wait_until(lambda: self.events_for("FLY to the moon"), 5))
        event = self.events_for("FLY to the moon")[0]
        self.assertEqual((event.state, event.code, event.interface), ("rejected", "INVALID_COMMAND", "subscriber"))
        self.assertIn("unknown command 'FLY'", event.message)

    def test_busy_and_stop_are_visible_on_status(self):
        self.publisher.publish(CommandString("WAIT 10 hold=tool"))
        self.assertTrue(wait_until(lambda: self.events_for("WAIT 10 hold=tool"), 5))
        self.assertEqual(self.call("WAIT 1 hold=tool").code, "BUSY")
        self.assertTrue(wait_until(lambda: self.events_for("WAIT 1 hold=tool", "service"), 5))
        rejected = self.events_for("WAIT 1 hold=tool", "service")[0]
        self.assertEqual((rejected.state, rejected.code), ("rejected", "BUSY"))
        self.assertTrue(self.call("STOP").success)
        self.assertTrue(wait_until(lambda: any(e.state == "canceled" for e in self.events_for("WAIT 10 hold=tool")), 5))
        final = [e for e in self.events_for("WAIT 10 hold=tool") if e.state == "canceled"][0]
        self.assertEqual(final.code, "ABORTED")
        # STOP's own events are published by another thread: wait for its end, then check the whole sequence
        self.assertTrue(wait_until(lambda: any(e.state == "succeeded" for e in self.events_for("STOP", "service")), 5))
        stop_events = [e.state for e in self.events_for("STOP", "service")]
        self.assertEqual(stop_events, ["running", "succeeded"])


if __name__ == "__main__":
    rostest.rosrun(PKG, "locem_topics", LocemTopicsTest)
