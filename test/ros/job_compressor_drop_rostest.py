#!/usr/bin/env python3
"""rostest (PENDING: move to test/ros/ once the full job completes): the compressor's Modbus TCP link drops while
an area is being sprayed (the worksite's ``compressor_link_drop`` fault, /sim/inject_fault, for DROP_WALL_S).

Checked: the running SPRAY_AREA task is reported failed with the compressor's reason (it fails cleanly: no
hang, the valve is closed once the link is back); LOCEM's compressor health is back up after the link returns
and the spraying process recovers (it ends succeeded, every area sprayed, the job goes on to sanding); and no
area is left half-sprayed without being reported (a wall whose coverage is partial has an area PEMKRE does not
record as sprayed, and the report's KPI table shows the failed SPRAY_AREA task).
"""
import os
import sys
import threading
import time
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE]

import rospy  # noqa: E402
import rostest  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402

from job_support import (SANDING, SPRAYING, TERMINAL, HicemTimeline, MotionProbe, SimCalls,  # noqa: E402
                         feature_status, init_test_node, kpi_count, process_record, setting, wait_for_report,
                         wait_until)

PKG = "locem_bridge"
DROP_WALL_S = 4.0            # link down this long (wall seconds)
REASON_WORDS = ("compressor", "modbus", "link", "hardware_error", "not_ready")


class JobCompressorDropTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        init_test_node("job_compressor_drop_test")
        cls.results_dir = setting("results_dir")
        cls.timeline = HicemTimeline()
        cls.sim = SimCalls()
        cls.areas = {a["id"]: a["wall"] for a in cls.sim.call("scan")["areas"]}
        cls._diag_lock = threading.Lock()
        cls.compressor_diag = []           # (t, level, message) of "locem: compressor"
        cls._diag_sub = rospy.Subscriber("/diagnostics", DiagnosticArray, cls._on_diag, queue_size=20)
        cls.probe = MotionProbe(setting("host"), int(setting("modbus_port")))
        try:
            cls._drop_while_spraying()
        finally:
            cls.probe.close()
        cls.report = wait_for_report(cls.results_dir, timeout=120.0)

    @classmethod
    def _on_diag(cls, msg):
        now = time.monotonic()
        with cls._diag_lock:
            for st in msg.status:
                if st.name == "locem: compressor":
                    level = ord(st.level) if isinstance(st.level, bytes) else int(st.level)
                    cls.compressor_diag.append((now, level, st.message))

    @classmethod
    def _drop_while_spraying(cls):
        def spraying_with_valve_open():
            s = cls.timeline.latest()
            if s.get("process") == SPRAYING and s.get("action_type") == "SPRAY_AREA" and s.get("phase") == "running":
                return s if cls.probe.spray_valve_open() else None
            return None
        cls.dropped = wait_until(spraying_with_valve_open, timeout=600.0, period=0.1)
        assert cls.dropped, "no SPRAY_AREA with the valve open (last HICEM state %s)" % cls.timeline.latest()
        time.sleep(1.0)                                   # well inside the area
        cls.t_drop = time.monotonic()
        cls.sim.inject_fault("compressor_link_drop", duration=DROP_WALL_S, mode="close")
        cls.dropped_report = cls.timeline.wait_for(
            lambda s: s["task"] == cls.dropped["task"] and s["phase"] == "reporting", timeout=DROP_WALL_S + 20.0)
        cls.t_reported = time.monotonic()
        cls.t_back = cls.t_drop + DROP_WALL_S
        wait_until(lambda: time.monotonic() > cls.t_back + 0.5, timeout=DROP_WALL_S + 5.0)
        s = cls.timeline.latest()
        cls.spraying_at_back = s.get("action_type") == "SPRAY_AREA" and s.get("phase") == "running"
        try:
            cls.valve_open_at_back = cls.probe.spray_valve_open()
        except AssertionError as error:          # checked in test_1: the link must be back by now
            cls.valve_open_at_back = error
        cls.health_back = wait_until(lambda: cls._compressor_ok_after(cls.t_back), timeout=15.0, period=0.2)
        cls.spraying_end = cls.timeline.wait_for(lambda s: s["process"] == SPRAYING and s["phase"] in TERMINAL,
                                                 timeout=600.0)
        cls.observe_error = None
        try:                                    # the job goes on to sanding: the graph is still up here
            cls.coverage = {w: v["spray_coverage"] for w, v in cls.sim.outcome()["walls"].items()}
            cls.area_status = {a: feature_status(a).get("sprayingStatus", "") for a in cls.areas}
        except Exception as error:  # noqa: BLE001 - reported by test_3
            cls.observe_error = "%s: %s" % (type(error).__name__, error)
        cls.sanding_end = cls.timeline.wait_for(lambda s: s["process"] == SANDING and s["phase"] in TERMINAL,
                                                timeout=600.0)

    @classmethod
    def _compressor_ok_after(cls, t):
        with cls._diag_lock:
            return any(level == 0 for when, level, _m in cls.compressor_diag if when > t)

    def test_1_task_fails_cleanly_with_the_compressor_reason(self):
        self.assertIsNotNone(self.dropped_report, "the SPRAY_AREA task never reported after the link dropped")
        detail = self.dropped_report["detail"].lower()
        self.assertTrue(any(w in detail for w in REASON_WORDS), self.dropped_report)
        with self._diag_lock:
            down = [(t, lvl, m) for t, lvl, m in self.compressor_diag if self.t_drop < t < self.t_back]
        self.assertTrue(any(lvl == 2 for _t, lvl, _m in down), "LOCEM never reported the compressor link down: "
                                                                "%s" % down[-3:])
        self.assertNotIsInstance(self.valve_open_at_back, AssertionError, "compressor unreachable 0.5 s after the "
                                 "link returned: %s" % self.valve_open_at_back)
        if not self.spraying_at_back:
            self.assertFalse(self.valve_open_at_back, "spray valve open after the link returned, nothing spraying")

    def test_2_process_recovers_when_the_link_returns(self):
        self.assertTrue(self.health_back, "compressor diagnostics not OK again after the link returned")
        self.assertIsNotNone(self.spraying_end)
        later = [a for a, _task in self.timeline.actions(SPRAYING) if a == "SPRAY_AREA"]
        self.assertGreater(len(later), 1, "no SPRAY_AREA after the failed one: %s" % self.timeline.actions(SPRAYING))
        self.assertEqual(process_record(self.report, "spraying")["status"], "succeeded",
                         process_record(self.report, "spraying"))
        self.assertEqual(process_record(self.report, "sanding")["status"], "succeeded")
        self.assertGreaterEqual(self.report["outcome"]["spray_coverage"], 0.98)

    def test_3_no_area_half_sprayed_without_being_reported(self):
        self.assertIsNone(self.observe_error, "could not read coverage / PEMKRE area states when spraying ended")
        self.assertGreaterEqual(kpi_count(self.report, "SPRAY_AREA", "failed"), 1,
                                "the failed SPRAY_AREA task is not in the report's KPI table")
        for wall, coverage in sorted(self.coverage.items()):
            areas = sorted(a for a, w in self.areas.items() if w == wall)
            unprocessed = [a for a in areas if self.area_status[a] != "processed"]
            if coverage < 0.98:
                self.assertTrue(unprocessed, "%s is %.1f %% sprayed but PEMKRE records all its areas %s sprayed"
                                % (wall, 100 * coverage, areas))
            else:
                self.assertEqual(unprocessed, [], "%s is sprayed but PEMKRE says %s are not" % (wall, unprocessed))


if __name__ == "__main__":
    rostest.rosrun(PKG, "job_compressor_drop", JobCompressorDropTest)
