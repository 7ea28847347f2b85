#!/usr/bin/env python3
"""rostest: the plasterboard job on a site without joints or areas (config/sites/bare_room.yaml).

Every process of the job must find nothing to do: SCAN, GO_HOME, end -- succeeded, nothing taped, sprayed or
sanded, no operator asked, no collision -- and report.json / report.md must say exactly that.
"""
import os
import unittest

import rostest

from job_support import SANDING, SPRAYING, TAPING, init_test_node, kpi_actions, setting, wait_for_report

PKG = "locem_bridge"


class JobNoJointsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        init_test_node("job_no_joints_test")
        cls.results_dir = setting("results_dir")
        cls.report = wait_for_report(cls.results_dir, timeout=100.0)

    def test_every_process_is_scan_home_end(self):
        report = self.report
        self.assertEqual([p["name"] for p in report["processes"]], ["taping", "spraying", "sanding"])
        for process, record in zip((TAPING, SPRAYING, SANDING), report["processes"]):
            self.assertEqual(record["iri"], process)
            self.assertEqual(record["status"], "succeeded", record)
            self.assertEqual(record["detail"], "nothing_to_do", record)
            actions = kpi_actions(report, process)
            self.assertEqual(sorted(actions), ["GO_HOME", "SCAN"], (process, actions))
            for action, row in actions.items():
                self.assertEqual((row["count"], row["succeeded"], row["failed"]), ("1", "1", "0"), (process, row))
                self.assertEqual(row["operatorInterventions"], "0", row)

    def test_outcome_says_nothing_was_done(self):
        o = self.report["outcome"]
        self.assertEqual(o["joints"], {})
        self.assertEqual((o["joints_total"], o["joints_taped"], o["joints_manual"]), (0, 0, 0))
        self.assertEqual((o["spray_coverage"], o["sand_coverage"]), (0.0, 0.0))
        self.assertEqual(o["operator_interventions"], 0)
        self.assertEqual(o["collisions"], 0)
        self.assertEqual(sorted(o["walls"]), [], "bare_room has no plasterboard wall: %s" % o["walls"])

    def test_markdown_and_settings(self):
        folder = os.path.join(self.results_dir, self.report["run"])
        with open(os.path.join(folder, "report.md"), encoding="utf-8") as handle:
            text = handle.read()
        self.assertIn("| joints taped by the robot | 0 of 0 (0 manual) |", text)
        for name in ("taping", "spraying", "sanding"):
            self.assertRegex(text, r"\| %s \| succeeded \|" % name)
        self.assertTrue(self.report["settings"]["site"].endswith("config/sites/bare_room.yaml"),
                        self.report["settings"])
        self.assertEqual(self.report["settings"]["operator"], "auto")


if __name__ == "__main__":
    rostest.rosrun(PKG, "job_no_joints", JobNoJointsTest)
