#!/usr/bin/env python3
"""rostest: subscriber /locem/command_in (fire and forget) and publisher /locem/status (changes only).

Every command published on /locem/command_in is accounted for by exactly one final /locem/status event, also in
a burst far past LOCEM's limit of running commands (64 by default) and for generated (fuzzed) strings.
"""
import threading
import time
import unittest

import rospy
import rostest
from locem_bridge.msg import CommandString, Status
from locem_bridge.srv import Command

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rostest_support import result_of, wait_until

PKG = "locem_bridge"
LIMIT = 64  # LOCEM's default ~max_running
FINAL = ("rejected", "succeeded", "failed", "canceled")


class LocemTopicsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("locem_topics_test", anonymous=True)
        rospy.wait_for_service("/locem/command", timeout=30)
        cls.call = staticmethod(rospy.ServiceProxy("/locem/command", Command))
        cls.events = []
        cls.lock = threading.Lock()
        # queue_size=None: rospy discards nothing on this side either; queue_size=0: the sender queues without bound
        rospy.Subscriber("/locem/status", Status, cls._record, queue_size=None)
        cls.publisher = rospy.Publisher("/locem/command_in", CommandString, queue_size=0)
        assert wait_until(lambda: cls.publisher.get_num_connections() > 0, 10), "LOCEM is not subscribed"
        assert wait_until(lambda: rospy.get_published_topics() and any(
            t == "/locem/status" for t, _ in rospy.get_published_topics()), 10)
        rospy.sleep(0.5)  # let the status subscription connect

    def setUp(self):
        with self.lock:  # each test sees its own events (generated strings may repeat another test's command)
            del self.events[:]

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

    def finals(self, commands, interface="subscriber"):
        """command -> its final events (rejected or ended), for the given commands."""
        wanted = set(commands)
        out = {c: [] for c in wanted}
        with self.lock:
            for event in self.events:
                if event.command in wanted and event.interface == interface and event.state in FINAL:
                    out[event.command].append(event)
        return out

    def assert_each_has_one_final_event(self, commands, timeout):
        complete = wait_until(lambda: all(self.finals(commands).values()), timeout, period=0.2)
        finals = self.finals(commands)
        missing = [c for c, events in finals.items() if not events]
        self.assertTrue(complete, "%d of %d commands have no final status event, e.g. %r"
                        % (len(missing), len(commands), missing[:5]))
        time.sleep(0.5)  # a duplicate would come right after
        twice = {c: [e.state for e in events] for c, events in self.finals(commands).items() if len(events) != 1}
        self.assertEqual(twice, {})
        return {c: events[0] for c, events in self.finals(commands).items()}

    def test_a_burst_far_past_the_limit_gets_exactly_one_final_event_per_command(self):
        waits = ["WAIT 0.5%04d" % i for i in range(1500)]          # 64 run, the rest are refused BUSY
        invalid = ["WAIT %d.5x" % i for i in range(750)]           # INVALID_ARGUMENT
        help_unknown = ["HELP NO_SUCH_%d" % i for i in range(750)]  # INVALID_ARGUMENT at admission
        commands = [c for triple in zip(waits[::2], waits[1::2], invalid, help_unknown) for c in triple]
        started = time.monotonic()
        for command in commands:
            self.publisher.publish(CommandString(command))
        final = self.assert_each_has_one_final_event(commands, 60)
        print("burst of %d commands accounted for in %.1f s" % (len(commands), time.monotonic() - started))
        ran = [c for c in waits if final[c].state == "succeeded"]
        busy = [final[c] for c in waits if final[c].state == "rejected"]
        self.assertEqual(len(ran) + len(busy), len(waits))
        self.assertGreater(len(ran), 0)
        self.assertTrue(all(e.code == "BUSY" and "its limit (max_running = %d" % LIMIT in e.message for e in busy))
        with self.lock:  # each command that ran announced itself once before its end
            running = [e.command for e in self.events if e.state == "running" and e.command in set(ran)]
        self.assertEqual(sorted(running), sorted(ran))
        self.assertEqual({(final[c].state, final[c].code) for c in invalid + help_unknown},
                         {("rejected", "INVALID_ARGUMENT")})
        self.assertIn("no command named 'NO_SUCH_0'", final["HELP NO_SUCH_0"].message)

    def test_stop_is_fast_with_the_limits_worth_of_waits_running(self):
        waits = ["WAIT 60.%03d" % i for i in range(LIMIT)]
        for command in waits:
            self.publisher.publish(CommandString(command))
        self.assertTrue(wait_until(lambda: len([e for e in self.events_for_any(waits) if e.state == "running"])
                                   == LIMIT, 10))
        self.assertEqual(self.call("WAIT 0").code, "BUSY")
        self.assertEqual(self.call("HELP STOP").code, "OK")
        started = time.monotonic()
        reply = self.call("STOP")
        elapsed = time.monotonic() - started
        print("STOP with %d WAITs running answered in %.1f ms" % (LIMIT, elapsed * 1000))
        self.assertTrue(reply.success, reply.message)
        self.assertEqual(len(result_of(reply.result)["stopped"]), LIMIT)
        self.assertEqual(result_of(reply.result)["still_running"], [])
        self.assertLess(elapsed, 1.0)
        final = self.assert_each_has_one_final_event(waits, 5)
        self.assertEqual({(e.state, e.code) for e in final.values()}, {("canceled", "ABORTED")})
        self.assertTrue(self.call("WAIT 0").success)

    def events_for_any(self, commands):
        wanted = set(commands)
        with self.lock:
            return [e for e in self.events if e.command in wanted]

    @settings(max_examples=1, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.lists(st.one_of(
        st.text(st.characters(blacklist_categories=("Cs",)), max_size=60),
        st.builds(lambda name, args: " ".join([name] + args),
                  st.sampled_from(["WAIT", "wait", "HELP", "STATUS", "GOTO", "W"]),
                  st.lists(st.one_of(st.floats().map(repr), st.integers(-5, 5).map(str), st.text(max_size=8),
                                     st.sampled_from(["hold=arm", "hold=", "\u0661", "0.01", "STOP", "="])),
                           max_size=4))), min_size=300, max_size=300, unique=True))
    def test_fuzzed_strings_on_command_in_each_get_one_final_event(self, texts):
        # STOP would cancel the others' waits; it has its own test. Long valid WAITs are ended by the STOP below.
        texts = [t for t in texts if t.strip()[:4].upper() != "STOP" and "\x00" not in t]
        for text in texts:
            self.publisher.publish(CommandString(text))
        wait_until(lambda: all(self.finals(texts).values()), 10, period=0.2)
        self.call("STOP")
        final = self.assert_each_has_one_final_event(texts, 10)
        codes = {"OK", "INVALID_COMMAND", "INVALID_ARGUMENT", "BUSY", "ABORTED"}
        self.assertTrue(all(e.code in codes and e.message for e in final.values()),
                        [(c, e.code, e.message) for c, e in final.items() if e.code not in codes or not e.message])
        self.assertEqual(self.call("STATUS").code, "OK")  # still serving


if __name__ == "__main__":
    rostest.rosrun(PKG, "locem_topics", LocemTopicsTest)
