#!/usr/bin/env python3
"""rostest: the plasterboard taping process on the second robot (diffdrive_ur5e: UR5e on a lift, differential base,
tool changer) with the shipped process and trees: every joint taped once with coverage >= 0.99 and no collision,
the operator was never asked (zero interventions in the report), every GET_TOOL task was expanded by PEMKRE's
tool-changer template into WALL_READY and CHANGE_TOOL (the task log), and the arm taped in height bands (LIFT on
LOCEM). The job file (job_robot2_taping.yaml) holds the processes that run there today."""
import os
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE]                          # job_support.py lives beside this file

import rostest  # noqa: E402

from job_support import (TAPING, HicemTimeline, LocemResults, init_test_node, kpi_count,  # noqa: E402
                         pemkre_rows, setting, wait_for_report)

PKG = "locem_bridge"


class JobRobot2Test(unittest.TestCase):
    maxDiff = None

    @classmethod
    def setUpClass(cls):
        init_test_node("job_robot2_test")
        cls.results_dir = setting("results_dir")
        cls.timeline = HicemTimeline()
        cls.locem = LocemResults()
        cls.report = wait_for_report(cls.results_dir, timeout=840.0)
        cls.asked = cls.timeline.asked()
        cls.log = pemkre_rows("task_log")

    def test_1_outcome_goals_of_the_processes_run(self):
        o = self.report["outcome"]
        self.assertEqual([(p["name"], p["status"]) for p in self.report["processes"]], [("taping", "succeeded")])
        self.assertGreaterEqual(o["joints_total"], 1)
        for jid, j in sorted(o["joints"].items()):
            self.assertTrue(j.get("taped") and float(j.get("coverage", 0.0)) >= 0.99, (jid, j))
        self.assertEqual(o["collisions"], 0)

    def test_2_zero_operator_interventions(self):
        self.assertEqual(self.asked, {})
        self.assertEqual(self.report["outcome"]["operator_interventions"], 0)

    def test_3_get_tool_realized_by_the_tool_changer_template(self):
        parents = [r for r in self.log if r["actionType"] == "GET_TOOL"]
        self.assertEqual(len(parents), len(self.report["processes"]), "one tool per process: %s" % parents)
        for parent in parents:
            self.assertEqual(parent["status"], "succeeded", parent)
            steps = sorted((int(r["seq"]), r["actionType"], r["status"]) for r in self.log
                           if r.get("expandedFrom") == parent["task"])
            self.assertEqual([(a, s) for _n, a, s in steps], [("WALL_READY", "succeeded"),
                                                              ("CHANGE_TOOL", "succeeded")], parent)
        self.assertGreaterEqual(len(self.locem.of("CHANGE_TOOL")), len(parents))

    def test_4_every_joint_taped_once_in_height_bands(self):
        o = self.report["outcome"]
        self.assertEqual(o["joints_taped"], o["joints_total"])
        self.assertEqual(kpi_count(self.report, "TAPE_LINE", "succeeded"), o["joints_total"])
        self.assertEqual(kpi_count(self.report, "TAPE_LINE", "failed"), 0)
        self.assertEqual(len([a for a, _t in self.timeline.actions(TAPING) if a == "TAPE_LINE"]), o["joints_total"])
        lifts = self.locem.of("LIFT")
        self.assertGreaterEqual(len(lifts), 2 * o["joints_total"], "a LIFT per piece of every joint")
        self.assertTrue(all(0.55 - 1e-3 <= r["height"] <= 1.45 + 1e-3 for r in lifts), lifts)


if __name__ == "__main__":
    rostest.rosrun(PKG, "job_robot2", JobRobot2Test)
