#!/usr/bin/env python3
"""rostest: the whole plasterboard job on the second robot (diffdrive_ur5e: UR5e on a lift, differential base,
tool changer) with the shipped processes, ontologies and trees: report.json meets every outcome goal, the
operator was never asked (zero interventions in the report), every GET_TOOL task was expanded by PEMKRE's
tool-changer template into WALL_READY and CHANGE_TOOL (the task log), the arm worked the walls in height bands
(LIFT on LOCEM), folded into its transit pose before the base drove (the differential base turns in place) and
the shorter reach took more base poses per wall than the first robot's sections."""
import os
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE]                          # job_support.py lives beside this file

import rostest  # noqa: E402

from job_support import (SANDING, SPRAYING, TAPING, TERMINAL, HicemTimeline, LocemResults,  # noqa: E402
                         init_test_node, kpi_count, outcome_goal_failures, pemkre_rows, setting, wait_for_report)

PKG = "locem_bridge"


class JobRobot2Test(unittest.TestCase):
    maxDiff = None

    @classmethod
    def setUpClass(cls):
        init_test_node("job_robot2_test")
        cls.results_dir = setting("results_dir")
        cls.timeline = HicemTimeline()
        cls.locem = LocemResults()
        cls.sanding_end = cls.timeline.wait_for(lambda s: s["process"] == SANDING and s["phase"] in TERMINAL,
                                                timeout=840.0)
        cls.asked = cls.timeline.asked()
        cls.report = wait_for_report(cls.results_dir, timeout=60.0)
        cls.log = pemkre_rows("task_log")

    def test_1_every_outcome_goal(self):
        self.assertEqual([("taping", "succeeded"), ("spraying", "succeeded"), ("sanding", "succeeded")],
                         [(p["name"], p["status"]) for p in self.report["processes"]])
        self.assertEqual([], outcome_goal_failures(self.report, self.asked))
        self.assertEqual(self.report["outcome"]["areas_manual"], [])

    def test_2_zero_operator_interventions(self):
        self.assertEqual(self.asked, {})
        self.assertEqual(self.report["outcome"]["operator_interventions"], 0)

    def test_3_get_tool_realized_by_the_tool_changer_template(self):
        parents = [r for r in self.log if r["actionType"] == "GET_TOOL"]
        self.assertEqual(len(parents), 3, "one tool per process: %s" % parents)
        for parent in parents:
            self.assertEqual(parent["status"], "succeeded", parent)
            steps = sorted((int(r["seq"]), r["actionType"], r["status"]) for r in self.log
                           if r.get("expandedFrom") == parent["task"])
            self.assertEqual([(a, s) for _n, a, s in steps], [("WALL_READY", "succeeded"),
                                                              ("CHANGE_TOOL", "succeeded")], parent)
        self.assertGreaterEqual(len(self.locem.of("CHANGE_TOOL")), 3)

    def test_4_every_joint_taped_once_in_height_bands(self):
        o = self.report["outcome"]
        self.assertEqual(o["joints_taped"], o["joints_total"])
        self.assertEqual(kpi_count(self.report, "TAPE_LINE", "succeeded"), o["joints_total"])
        self.assertEqual(kpi_count(self.report, "TAPE_LINE", "failed"), 0)
        self.assertEqual(len([a for a, _t in self.timeline.actions(TAPING) if a == "TAPE_LINE"]), o["joints_total"])
        lifts = self.locem.of("LIFT")
        self.assertGreaterEqual(len(lifts), 2 * o["joints_total"], "a LIFT per piece of every joint")
        self.assertTrue(all(0.55 - 1e-3 <= r["height"] <= 1.45 + 1e-3 for r in lifts), lifts)

    def test_5_areas_in_bands_each_area_task_once_and_the_arm_folded_for_every_drive(self):
        for process, action in ((SPRAYING, "SPRAY_AREA"), (SANDING, "SAND_AREA")):
            self.assertEqual(kpi_count(self.report, action, "failed"), 0, action)
            self.assertEqual(len([a for a, _t in self.timeline.actions(process) if a == action]), 2, action)
        # two height bands per section, 2 areas: 4 spray sections per area (0.60 m), 3 sand sections (0.80 m); the
        # first robot sends 8 of each (4 sections per area, one band)
        for action, sections in (("SPRAY_AREA", 4), ("SAND_AREA", 3)):
            self.assertGreaterEqual(len(self.locem.of(action)), 2 * 2 * sections, action)
        folds = [r for r in self.locem.of("MOVE_HOME") if "pose=transit" in r["_command"].split()]
        gotos = self.locem.of("GOTO")
        self.assertGreater(len(folds), 0)
        self.assertGreaterEqual(len(gotos), len(folds))


if __name__ == "__main__":
    rostest.rosrun(PKG, "job_robot2", JobRobot2Test)
