#!/usr/bin/env python3
"""rostest: ``kill -9`` of the PEMKRE node in the middle of HICEM's calls while it tapes, twice.

Each time HICEM reports a taped joint (phase ``reporting`` of a TAPE_LINE: its ``set_task_status`` is under way
and its ``next_action`` follows at once), PEMKRE is frozen with SIGSTOP -- whatever call HICEM has in flight
then waits on it -- and killed with SIGKILL 0.3 s later; roslaunch respawns it from its store.

Checked: PEMKRE came back (another pid) and HICEM did not die; HICEM's call log shows calls that started
before PEMKRE was back and completed after the kill (they spanned the restart); HICEM went on with the same
specific taping process (resumed, not restarted); the job completes with every process succeeded and every
outcome goal met; no joint taped twice or skipped (PEMKRE's task log and feature states, the world's tape
outcome).
"""
import os
import signal
import sys
import threading
import time
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE]                          # job_support.py lives beside this file

import rospy  # noqa: E402
import rostest  # noqa: E402

from job_support import (SANDING, TAPING, TERMINAL, HicemTimeline, SimCalls, init_test_node,  # noqa: E402
                         kpi_count, node_pid, outcome_goal_failures, pemkre_rows, setting, try_node_pid,
                         wait_for_report, wait_until)
from locem_bridge.job.call_log import read_call_log  # noqa: E402
from locem_bridge.msg import HicemState  # noqa: E402

PKG = "locem_bridge"
KILL_AT = (2, 4)             # when the report of the 2nd and of the 4th TAPE_LINE begins


class _FreezeOnReport:
    """Freezes PEMKRE (SIGSTOP) from the /hicem/state callback itself, the moment HICEM starts reporting the
    TAPE_LINE numbered in ``targets``: no polling delay between HICEM's call and the freeze."""

    def __init__(self, pid, targets):
        self.pid = pid
        self.targets = list(targets)
        self.frozen = [threading.Event() for _ in self.targets]
        self.states = [None] * len(self.targets)
        self._reported = []
        self._lock = threading.Lock()
        self._sub = rospy.Subscriber("/hicem/state", HicemState, self._on_state, queue_size=200)

    def _on_state(self, m):
        if m.process != TAPING or m.action_type != "TAPE_LINE" or m.phase != "reporting":
            return
        with self._lock:
            if m.task not in self._reported:
                self._reported.append(m.task)
            for k, target in enumerate(self.targets):
                if len(self._reported) == target and not self.frozen[k].is_set():
                    os.kill(self.pid, signal.SIGSTOP)
                    self.states[k] = {"specific_process": m.specific_process, "task": m.task}
                    self.frozen[k].set()

    def close(self):
        self._sub.unregister()


class JobPemkreKillTest(unittest.TestCase):
    maxDiff = None

    @classmethod
    def setUpClass(cls):
        init_test_node("job_pemkre_kill_test")
        cls.results_dir = setting("results_dir")
        cls.call_log = setting("call_log")
        cls.timeline = HicemTimeline()
        cls.sim = SimCalls()
        cls.hicem_pid = node_pid("/hicem")
        cls.kills = []                        # (pid, new pid, time.time() of the kill, time.time() PEMKRE back)
        cls.specific = set()
        cls.freezer = _FreezeOnReport(node_pid("/pemkre"), KILL_AT)
        try:
            for k in range(len(KILL_AT)):
                cls._kill_when_reporting(k)
        finally:
            cls.freezer.close()
        cls.taping_end = cls.timeline.wait_for(lambda s: s["process"] == TAPING and s["phase"] in TERMINAL,
                                               timeout=600.0)
        cls.line_states = {r["state"].split("#")[-1]: int(r["lines"]) for r in pemkre_rows("feature_counts")}
        cls.joints = cls.sim.outcome()["joints"]
        cls.sanding_end = cls.timeline.wait_for(lambda s: s["process"] == SANDING and s["phase"] in TERMINAL,
                                                timeout=900.0)
        cls.asked = cls.timeline.asked()
        cls.report = wait_for_report(cls.results_dir, timeout=120.0)
        cls.calls = read_call_log(cls.call_log)

    @classmethod
    def _kill_when_reporting(cls, k):
        freezer = cls.freezer
        assert freezer.frozen[k].wait(600.0), "never saw HICEM report TAPE_LINE number %d (last state %s)" % (
            KILL_AT[k], cls.timeline.latest())
        pid = freezer.pid
        cls.specific.add(freezer.states[k]["specific_process"])
        time.sleep(0.3)                       # the call in flight (or the next one) waits on the frozen PEMKRE
        os.kill(pid, signal.SIGKILL)
        t_kill = time.time()
        new_pid = wait_until(lambda: (lambda p: p if p not in (None, pid) else None)(try_node_pid("/pemkre")),
                             timeout=60.0, period=0.05)
        assert new_pid, "no new /pemkre within 60 s of kill -9 of pid %d (respawn in launch/pemkre.launch?)" % pid
        freezer.pid = new_pid
        rospy.wait_for_service("/pemkre/next_action", timeout=60.0)
        cls.kills.append((pid, new_pid, t_kill, time.time()))

    def test_1_pemkre_restarted_under_hicem_calls_that_went_on(self):
        self.assertEqual(len(self.kills), len(KILL_AT))
        for pid, new_pid, t_kill, t_back in self.kills:
            self.assertNotEqual(pid, new_pid)
            print("PEMKRE pid %d killed, pid %d answering %.1f s later" % (pid, new_pid, t_back - t_kill))
        self.assertEqual(try_node_pid("/hicem"), self.hicem_pid, "HICEM must not die when PEMKRE does")
        # per kill: a call HICEM had sent before PEMKRE was killed that completed (after the respawn)
        spanned = [[c for c in self.calls if c["layer"] == "pemkre" and c["ok"] and c["t0"] < t_kill < c["t1"]]
                   for _p, _n, t_kill, _b in self.kills]
        print("HICEM calls in flight across each kill: %s" % [[(c["call"], round(c["t1"] - c["t0"], 2)) for c in s]
                                                               for s in spanned])
        self.assertTrue(all(spanned), "calls around the kills: %s" % [
            c for c in self.calls if any(abs(c["t1"] - tk) < 15 for _p, _n, tk, _b in self.kills)])
        # HICEM went on with the same specific process: resumed, not started again
        self.assertEqual(len(self.specific), 1, self.specific)
        taping_runs = {s["specific_process"] for s in self.timeline.snapshot()
                       if s["process"] == TAPING and s["specific_process"]}
        self.assertEqual(taping_runs, self.specific)
        self.assertNotIn("resuming", [s["phase"] for s in self.timeline.snapshot()])

    def test_2_job_completes_with_every_outcome_goal(self):
        self.assertEqual([p["status"] for p in self.report["processes"]], ["succeeded"] * 3, self.report["processes"])
        self.assertEqual([], outcome_goal_failures(self.report, self.asked))

    def test_3_no_joint_taped_twice_or_skipped(self):
        total = len(self.joints)
        self.assertGreaterEqual(total, max(KILL_AT) + 1)
        self.assertEqual(kpi_count(self.report, "TAPE_LINE", "succeeded"), total)
        self.assertEqual(kpi_count(self.report, "TAPE_LINE"), total)
        self.assertEqual(len([a for a, _t in self.timeline.actions(TAPING) if a == "TAPE_LINE"]), total)
        self.assertNotIn("pending", " ".join(self.line_states).lower(), self.line_states)
        self.assertEqual(sum(self.line_states.values()), total, self.line_states)
        for jid, j in sorted(self.joints.items()):
            self.assertTrue(j["taped"] and not j["manual"] and j["coverage"] >= 0.99, (jid, j))


if __name__ == "__main__":
    rostest.rosrun(PKG, "job_pemkre_kill", JobPemkreKillTest)
