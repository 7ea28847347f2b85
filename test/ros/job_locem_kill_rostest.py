#!/usr/bin/env python3
"""rostest: ``kill -9`` of the LOCEM node while it sprays an area (SPRAY_AREA running, spray valve open).

Checked on the devices themselves, not on LOCEM's view: the arm (a second RTDE client, outputs only, so it does not
feed the controller's watchdog) stands still within 2 s of the kill (1 s watchdog + braking); and the compressor stand-in's own record of its valve and
motor (``/sim/compressor``, wall time of each change and its cause) shows the valve closed and the motor off within
1 s of the kill, by its communication watchdog (nobody else talks to it: this suite reads the device through the
simulator's service, never over Modbus, which would keep the watchdog alive). roslaunch starts a new LOCEM
(another pid) that makes the compressor safe before it accepts commands and reports the trip in its health. Then
the job resumes and meets the outcome goals of the full job (report.json: every process succeeded, spray coverage
>= 0.98, thickness CV <= 0.15, sand coverage >= 0.98, ...). That resume needs HICEM's LOCEM client to survive
LOCEM's restart and RECOVER to wait for the device links (issue 15 items 2 and 3).
"""
import json
import os
import signal
import sys
import time
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE]                          # job_support.py lives beside this file

import rospy  # noqa: E402
import rostest  # noqa: E402

from job_support import (SANDING, SPRAYING, TERMINAL, HicemTimeline, MotionProbe, SimCalls,  # noqa: E402
                         init_test_node, node_pid, outcome_goal_failures, setting, try_node_pid, wait_for_report,
                         wait_until)

PKG = "locem_bridge"


def locem_status():
    from locem_bridge.srv import Command
    rospy.wait_for_service("/locem/command", timeout=5.0)
    answer = rospy.ServiceProxy("/locem/command", Command)(command="STATUS")
    return json.loads(answer.result or "{}") if answer.success else None


class JobLocemKillTest(unittest.TestCase):
    maxDiff = None

    @classmethod
    def setUpClass(cls):
        init_test_node("job_locem_kill_test")
        cls.results_dir = setting("results_dir")
        cls.timeline = HicemTimeline()
        cls.sim = SimCalls()
        cls.probe = MotionProbe(setting("host"), int(setting("modbus_port")))
        try:
            cls._kill_while_spraying()
        finally:
            cls.probe.close()
        cls.sanding_end = cls.timeline.wait_for(lambda s: s["process"] == SANDING and s["phase"] in TERMINAL,
                                                timeout=840.0)
        cls.asked = cls.timeline.asked()
        cls.report = wait_for_report(cls.results_dir, timeout=120.0)

    @classmethod
    def _kill_while_spraying(cls):
        def spraying_with_valve_open():
            s = cls.timeline.latest()
            if s.get("process") == SPRAYING and s.get("phase") == "running" and s.get("action_type") == "SPRAY_AREA":
                state = cls.sim.call("compressor")
                return state if state["valve_open"] and state["motor_on"] else None
            return None
        cls.before = wait_until(spraying_with_valve_open, timeout=600.0, period=0.05)
        assert cls.before, "never saw SPRAY_AREA with the valve open (last state %s)" % cls.timeline.latest()
        cls.old_pid = node_pid("/locem")
        cls.killed = time.time()
        cls.killed_mono = time.monotonic()
        os.kill(cls.old_pid, signal.SIGKILL)

        def safe():
            state = cls.sim.call("compressor")
            return state if not state["valve_open"] and not state["motor_on"] else None
        cls.after = wait_until(safe, timeout=10.0, period=0.05)
        time.sleep(max(0.0, cls.killed_mono + 3.0 - time.monotonic()))
        cls.arm_still = cls._arm_still_after(cls.killed_mono, hold=0.3, window=3.0)
        cls.new_pid = wait_until(lambda: (lambda p: p if p not in (None, cls.old_pid) else None)(
            try_node_pid("/locem")), timeout=60.0, period=0.2)
        if cls.new_pid is None:
            raise AssertionError("no new /locem within 60 s of kill -9 of pid %d (respawn missing on the locem node "
                                 "of launch/locem_robot.launch?)" % cls.old_pid)

        def compressor_up():
            try:
                status = locem_status()
            except Exception:
                return None
            health = (status or {}).get("health", {}).get("compressor", {})
            return health if health.get("link") == "up" else None
        cls.health = wait_until(compressor_up, timeout=60.0, period=0.5)

    @classmethod
    def _arm_still_after(cls, t0, hold, window):
        """First arm sample after ``t0`` from which the arm stands still for ``hold`` s (within ``window`` s of
        ``t0``: the respawned LOCEM may move it again later); None if there is none."""
        with cls.probe._lock:
            samples = [(t, v > cls.probe.ARM_STILL) for t, v in cls.probe.arm if t0 <= t <= t0 + window]
        for i, (t, moving) in enumerate(samples):
            if moving:
                continue
            run = [m for tt, m in samples[i:] if tt <= t + hold]
            if not any(run) and samples[-1][0] >= t + hold:
                return t
        return None

    def test_1_valve_closed_and_motor_off_within_1_s_by_the_devices_watchdog(self):
        self.assertIsNotNone(self.after, "compressor still running 10 s after kill -9 of LOCEM")
        changes = {}
        for e in self.after["history"]:
            if e["wall"] >= self.killed and e["what"] not in changes:
                changes[e["what"]] = e
        self.assertEqual(sorted(changes), ["motor_on", "valve_open"], self.after["history"][-6:])
        for what, e in sorted(changes.items()):
            self.assertFalse(e["value"], e)
            self.assertEqual(e["cause"], "watchdog", e)
            self.assertLessEqual(e["wall"] - self.killed, 1.0, "%s changed %.3f s after the kill" % (
                what, e["wall"] - self.killed))
        self.assertTrue(self.after["watchdog"]["trips"] >= 1, self.after["watchdog"])

    def test_2_respawned_locem_made_the_compressor_safe_and_reports_the_trip(self):
        self.assertNotEqual(self.new_pid, self.old_pid)
        self.assertIsNotNone(self.health, "the respawned LOCEM never reported the compressor link up")
        self.assertEqual(self.health["watchdog"]["trips_seen"], 1, self.health)
        state = self.sim.call("compressor")
        self.assertEqual(state["watchdog"]["timeout_ms"], 500, state["watchdog"])

    def test_3_arm_stopped_by_the_controllers_watchdog(self):
        self.assertIsNotNone(self.arm_still, "the arm never stood still for 0.3 s within 3 s of kill -9 of LOCEM")
        self.assertLessEqual(self.arm_still - self.killed_mono, 2.0)

    def test_4_job_resumed_and_meets_the_outcome_goals(self):
        self.assertIsNotNone(self.sanding_end, "sanding never ended")
        # the thickness CV included: the section the kill cut goes on where the spray stopped (SPRAY_AREA's progress
        # feedback kept by HICEM, skip= on the retry), not from its start
        print("spray thickness CV after the kill: %.3f" % self.report["outcome"]["spray_thickness_cv"])
        self.assertEqual([], outcome_goal_failures(self.report, self.asked))

if __name__ == "__main__":
    rostest.rosrun(PKG, "job_locem_kill", JobLocemKillTest)
