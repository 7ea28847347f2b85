#!/usr/bin/env python3
"""rostest: the whole plasterboard job on the default site, validate_lines false, automatic operator;
report.json meets every outcome goal of issue 7, every joint is taped once by the robot, and the sander held
the set contact force (LOCEM's SAND_AREA results on /locem/status)."""
import os
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE]                          # job_support.py lives beside this file

import rostest  # noqa: E402

from job_support import (SANDING, TAPING, TERMINAL, HicemTimeline, LocemResults, SimCalls,  # noqa: E402
                         init_test_node, kpi_count, outcome_goal_failures, setting, wait_for_report)

PKG = "locem_bridge"


class JobFullTest(unittest.TestCase):
    maxDiff = None

    @classmethod
    def setUpClass(cls):
        init_test_node("job_full_test")
        cls.results_dir = setting("results_dir")
        cls.timeline = HicemTimeline()
        cls.locem = LocemResults()
        cls.sim = SimCalls()
        cls.walls = sorted({a["wall"] for a in cls.sim.call("scan")["areas"]})
        cls.sanding_end = cls.timeline.wait_for(lambda s: s["process"] == SANDING and s["phase"] in TERMINAL,
                                                timeout=840.0)
        cls.asked = cls.timeline.asked()
        cls.report = wait_for_report(cls.results_dir, timeout=60.0)

    def test_1_outcome_goals(self):
        self.assertEqual([], outcome_goal_failures(self.report, self.asked))

    def test_2_no_validation_asked_and_tool_changes_counted(self):
        self.assertEqual(self.asked.get("validate_line", 0), 0, self.asked)
        self.assertEqual(kpi_count(self.report, "VALIDATE_TAPE_LINE"), 0)
        self.assertGreaterEqual(self.asked.get("mount_tool", 0), 3, "one tool per process: %s" % self.asked)
        self.assertEqual(self.report["outcome"]["operator_interventions"], self.asked.get("mount_tool", 0))

    def test_3_every_joint_taped_once_by_the_robot(self):
        o = self.report["outcome"]
        self.assertEqual(o["joints_taped"], o["joints_total"])
        self.assertEqual(kpi_count(self.report, "TAPE_LINE", "succeeded"), o["joints_total"])
        self.assertEqual(kpi_count(self.report, "TAPE_LINE", "failed"), 0)
        self.assertEqual(len([a for a, _t in self.timeline.actions(TAPING) if a == "TAPE_LINE"]), o["joints_total"])

    def test_4_sanded_under_force_control(self):
        # the shipped parameters sand with contact=force at sand.force = 20 N: every section's lanes held it
        sands = self.locem.of("SAND_AREA")
        self.assertGreaterEqual(len(sands), 2 * len(self.walls), sands)
        for r in sands:
            self.assertEqual(r.get("contact"), "force", r)
            self.assertTrue(16.0 <= r["force_min_n"] <= r["force_max_n"] <= 24.0, r)

    def test_5_report_files(self):
        folder = os.path.join(self.results_dir, self.report["run"])
        self.assertTrue(os.path.isfile(os.path.join(folder, "report.md")))
        self.assertEqual(sorted(self.report["pictures"]), ["%s.png" % w for w in self.walls])
        for picture in self.report["pictures"]:
            self.assertGreater(os.path.getsize(os.path.join(folder, picture)), 1000, picture)


if __name__ == "__main__":
    rostest.rosrun(PKG, "job_full", JobFullTest)
