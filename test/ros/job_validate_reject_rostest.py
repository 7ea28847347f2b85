#!/usr/bin/env python3
"""rostest: validate_lines true, the automatic operator
rejects one joint (reject_lines): that joint goes to manual taping and is manual in the report, every other joint
is taped by the robot, every joint was validated once, and the interventions add up."""
import os
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE]                          # job_support.py lives beside this file

import rostest  # noqa: E402

from job_support import (SANDING, TAPING, TERMINAL, HicemTimeline, init_test_node, kpi_count,  # noqa: E402
                         outcome_goal_failures, setting, wait_for_report)

PKG = "locem_bridge"


class JobValidateRejectTest(unittest.TestCase):
    maxDiff = None

    @classmethod
    def setUpClass(cls):
        init_test_node("job_validate_reject_test")
        cls.results_dir = setting("results_dir")
        cls.rejected = tuple(j.strip() for j in str(setting("reject_lines")).split(",") if j.strip())
        cls.timeline = HicemTimeline()
        cls.taping_end = cls.timeline.wait_for(lambda s: s["process"] == TAPING and s["phase"] in TERMINAL,
                                               timeout=600.0)
        cls.sanding_end = cls.timeline.wait_for(lambda s: s["process"] == SANDING and s["phase"] in TERMINAL,
                                                timeout=840.0)
        cls.asked = cls.timeline.asked()
        cls.answers = cls.timeline.answered()
        cls.report = wait_for_report(cls.results_dir, timeout=60.0)

    def test_1_outcome_goals_with_the_rejected_joint_manual(self):
        self.assertEqual(len(self.rejected), 1, self.rejected)
        self.assertIn(self.rejected[0], self.report["outcome"]["joints"])
        self.assertEqual([], outcome_goal_failures(self.report, self.asked, manual=self.rejected))

    def test_2_rejected_joint_is_manual_others_taped(self):
        o = self.report["outcome"]
        joint = o["joints"][self.rejected[0]]
        self.assertTrue(joint["manual"], joint)
        self.assertEqual(o["joints_manual"], 1)
        self.assertEqual(o["joints_taped"], o["joints_total"] - 1)
        self.assertEqual(kpi_count(self.report, "TAPE_LINE", "succeeded"), o["joints_total"] - 1)
        self.assertEqual(kpi_count(self.report, "MANUAL_TAPING", "succeeded"), 1)

    def test_3_every_joint_validated_once_one_answer_invalid(self):
        o = self.report["outcome"]
        self.assertEqual(self.asked.get("validate_line", 0), o["joints_total"], self.asked)
        self.assertEqual(kpi_count(self.report, "VALIDATE_TAPE_LINE"), o["joints_total"])
        validations = [a for a in self.answers if a["kind"] == "validate_line"]
        self.assertEqual(sorted(a["answer"] for a in validations),
                         sorted(["invalid"] + ["valid"] * (o["joints_total"] - 1)), validations)
        self.assertEqual(self.asked.get("manual_taping", 0), 1, self.asked)

    def test_4_interventions_match(self):
        o = self.report["outcome"]
        self.assertEqual(o["operator_interventions"], len(self.answers))
        self.assertEqual(o["operator_interventions"], self.asked.get("mount_tool", 0) + o["joints_total"] + 1,
                         "tool changes + one validation per joint + the joint taped by hand: %s" % self.asked)


if __name__ == "__main__":
    rostest.rosrun(PKG, "job_validate_reject", JobValidateRejectTest)
