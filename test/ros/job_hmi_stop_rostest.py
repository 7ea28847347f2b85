#!/usr/bin/env python3
"""rostest: STOP from the operator web page mid-action.

The job runs on the default site with operator:=both. As soon as the base drives in the taping process (a wheel
at DRIVING_RAD_S or faster), the test presses STOP the way the page does (POST /api/stop, same origin, JSON) and
then checks, on the devices themselves (UR stand-in over RTDE, the wheel drives' velocity TPDOs on the base's
CAN bus, compressor over Modbus): arm and base still within 200 ms of sim time and still from then on, the spray
valve and the tool outputs off;
HICEM ends the taping process "stopped" with the operator's reason, the page shows it; report.json records the
taping process as stopped and nothing after it as succeeded.

The job ends after a stopped process and writes its report; the .test keeps the other nodes up after that
(end_with_job false), so the test, not the job's exit, ends the launch. The live devices and the page are read
right after the stop; arm and base are judged from the probe's samples over OBSERVE_WALL_S (or until a later
process starts, should a job go on after a stop). Sim time = wall time x time_scale (the .test runs at time_scale 1, where
the software path page -> HMI -> HICEM -> LOCEM -> devices is not compressed 5x against the sim clock).
"""
import sys
import time
import unittest

import rospy
import rostest

from job_support import (TAPING, HicemTimeline, HmiClient, MotionProbe, SimCalls, init_test_node,
                         process_record, setting, wait_for_report, wait_until)

PKG = "locem_bridge"
LIMIT_SIM_S = 0.200           # issue 7: all devices stopped within 200 ms of sim time
OBSERVE_WALL_S = 1.5          # how long the base is watched after STOP at most
DRIVING_RAD_S = 1.0           # STOP is pressed once a wheel turns this fast (0.13 m/s at the rim): the base drives,
                              # it does not creep into or out of a pose


class JobHmiStopTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        init_test_node("job_hmi_stop_test")
        cls.results_dir = setting("results_dir")
        cls.timeline = HicemTimeline()
        cls.sim = SimCalls()
        cls.scale = cls.sim.time_scale()
        cls.hmi = HmiClient(int(setting("hmi_port")))
        cls.hmi.wait_up(timeout=60.0)
        cls.probe = MotionProbe(setting("host"), int(setting("modbus_port")), can=True)   # base: its drives
        try:
            cls._stop_mid_action()
        finally:
            cls.probe.close()
        cls.report = wait_for_report(cls.results_dir, timeout=120.0)

    @classmethod
    def _stop_mid_action(cls):
        def base_moving_in_taping():
            s = cls.timeline.latest()
            if s.get("process") != TAPING or s.get("phase") != "running":
                return None
            m = cls.probe.moving(window=0.12)
            wheel = cls.probe.wheel_speed(0.05)
            return (s, m, wheel) if m["base"] and wheel >= DRIVING_RAD_S else None
        found = wait_until(base_moving_in_taping, timeout=90.0, period=0.005)
        assert found, "the base never moved during taping (last HICEM state %s, motion %s)" % (
            cls.timeline.latest(), cls.probe.moving())
        cls.stopped_state, cls.moving_before, cls.wheels_before = found
        cls.t_stop = time.monotonic()
        cls.stop_answer = cls.hmi.stop()
        cls.t_answer = time.monotonic()
        # Everything that needs a live device or page is read now, the rest from recorded samples.
        time.sleep(max(0.3, 2.5 * LIMIT_SIM_S / cls.scale))
        cls.outputs_after = cls.probe.tool_outputs()
        cls.valve_open_after = cls.probe.spray_valve_open()
        cls.taping_end = cls.timeline.wait_for(
            lambda s: s["process"] == TAPING and s["phase"] in ("ended", "failed", "stopped"), timeout=30.0)
        try:
            cls.page_after = cls.hmi.state()
        except Exception as exc:          # the page may already be shutting down with the launch
            cls.page_after = {"snapshot": {"phase": ""}, "events": [], "error": repr(exc)}
        # devices are judged until a later process starts (if the job went on) or for OBSERVE_WALL_S
        later = wait_until(lambda: cls._later_state(), timeout=max(0.0, cls.t_stop + OBSERVE_WALL_S
                                                                    - time.monotonic()), period=0.002)
        cls.t_next = later[0] if later else time.monotonic()
        cls.t_observed = cls.t_next
        cls.driving_action = later[1]["action_type"] if later else ""
        cls.windows = {"arm": (cls.t_stop, cls.t_next), "base": (cls.t_stop, cls.t_observed)}
        cls.still = {d: cls.probe.still_since(d, *w) for d, w in cls.windows.items()}
        cls.samples = {d: cls.probe.samples_between(d, *w) for d, w in cls.windows.items()}
        cls.measured = ("STOP pressed during %s (moving: %s, fastest wheel %.2f rad/s); page answered in %.3f s "
                        "wall; devices still after %s s wall (time_scale %.1f); watched %.3f s wall%s" % (
                            cls.stopped_state["action_type"], cls.moving_before, cls.wheels_before,
                            cls.t_answer - cls.t_stop,
                            {k: (None if v is None else round(v - cls.t_stop, 3)) for k, v in cls.still.items()},
                            cls.scale, cls.t_observed - cls.t_stop,
                            " (until the next process's %s)" % cls.driving_action if cls.driving_action else ""))
        rospy.logwarn("job_hmi_stop: %s", cls.measured)
        sys.stderr.write("[job_hmi_stop] %s\n" % cls.measured)

    @classmethod
    def _later_state(cls, except_actions=None):
        """(arrival time, state) of the first HICEM state of a process after taping (with an action type not in
        ``except_actions`` when given), or None."""
        for t, s in cls.timeline.timed():
            if t >= cls.t_stop and s["process"] not in ("", TAPING):
                if except_actions is None or s["action_type"] not in except_actions:
                    return t, s
        return None

    def test_1_page_accepted_stop(self):
        status, body = self.stop_answer
        self.assertEqual(status, 200, body)
        self.assertEqual(body.get("ok"), True, body)

    def test_2_devices_still_within_200ms_sim(self):
        for device in ("arm", "base"):
            start, end = self.windows[device]
            if device == "base":
                self.assertGreaterEqual((end - start) * self.scale, 2 * LIMIT_SIM_S, "base: watched only %.3f s "
                                        "wall: too short to judge (%s)" % (end - start, self.measured))
            self.assertGreater(self.samples[device], 2, "%s: too few samples (%s)" % (device, self.measured))
            t = self.still[device]
            self.assertIsNotNone(t, "%s still moving at the end of the window (%s)" % (device, self.measured))
            sim_s = (t - self.t_stop) * self.scale
            self.assertLessEqual(sim_s, LIMIT_SIM_S, "%s still only after %.3f s sim (%s)" % (device, sim_s,
                                                                                          self.measured))

    def test_3_tools_and_spray_off(self):
        self.assertEqual(self.outputs_after & 0b11, 0, "taping/sander outputs on after STOP: %s"
                         % bin(self.outputs_after))
        self.assertFalse(self.valve_open_after, "spray valve open after STOP")

    def test_4_hicem_and_page_show_the_stop(self):
        self.assertIsNotNone(self.taping_end, "taping never reached an end state after STOP")
        self.assertEqual(self.taping_end["phase"], "stopped", self.taping_end)
        self.assertIn("STOP pressed on the operator HMI", self.taping_end["detail"])
        events = " ".join(e.get("text", "") for e in self.page_after.get("events", []))
        self.assertTrue(self.page_after["snapshot"]["phase"] == "stopped" or "stop" in events.lower(),
                        self.page_after["snapshot"])

    def test_5_report_records_the_stop(self):
        taping = process_record(self.report, "taping")
        self.assertEqual(taping["status"], "stopped", taping)
        self.assertIn("STOP pressed on the operator HMI", taping["detail"])
        later = self.report["processes"][self.report["processes"].index(taping) + 1:]
        self.assertFalse([p for p in later if p["status"] == "succeeded"],
                         "processes after the STOP ran to success: %s" % later)


if __name__ == "__main__":
    rostest.rosrun(PKG, "job_hmi_stop", JobHmiStopTest)
