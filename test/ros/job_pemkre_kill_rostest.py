#!/usr/bin/env python3
"""rostest: PEMKRE on a SPARQL 1.1 server; ``kill -9`` of the PEMKRE node, then of the server, while HICEM tapes.

When HICEM reports its 2nd taped joint (phase ``reporting`` of a TAPE_LINE: its ``set_task_status`` is under way
and its ``next_action`` follows at once), PEMKRE is frozen with SIGSTOP -- whatever call HICEM has in flight then
waits on it -- and killed with SIGKILL 0.3 s later; roslaunch respawns it on the server's data. When HICEM reports
its 4th, the server (``oxigraph serve``, a helper node that writes its pid) is killed with SIGKILL from the same
callback; roslaunch starts it again 4 s later on the same data folder.

Checked: PEMKRE came back (another pid) and HICEM did not die; the server came back and PEMKRE did not die of its
absence but answered NOT_READY naming the server's endpoint (HICEM logs the answer as it waits); HICEM's call log
shows a call in flight across each restart that completed (sent to the frozen PEMKRE before its kill; under way
while the server was away); HICEM went on with
the same specific taping process (resumed, not restarted); the job completes with every process succeeded and
every outcome goal met; no joint taped twice or skipped (PEMKRE's task log and feature states, the world's tape
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
from rosgraph_msgs.msg import Log  # noqa: E402

from job_support import (SANDING, TAPING, TERMINAL, HicemTimeline, SimCalls, init_test_node,  # noqa: E402
                         kpi_count, node_pid, outcome_goal_failures, pemkre_rows, setting, try_node_pid,
                         wait_for_report, wait_until)
from locem_bridge.job.call_log import read_call_log  # noqa: E402
from locem_bridge.msg import HicemState  # noqa: E402

PKG = "locem_bridge"
KILL_AT = (2, 4)             # when the report of the 2nd (PEMKRE is killed) and of the 4th (the server) begins
KILLED = ("pemkre", "server")


class _KillOnReport:
    """Acts from the /hicem/state callback itself, the moment HICEM starts reporting the TAPE_LINE numbered in
    ``targets``: freezes PEMKRE (SIGSTOP; the test then kills it) or kills the SPARQL server (SIGKILL), with no
    polling delay between HICEM's call and the signal."""

    def __init__(self, pids, targets, kinds):
        self.pids = dict(pids)                 # "pemkre" / "server" -> pid
        self.targets = list(targets)
        self.kinds = list(kinds)
        self.done = [threading.Event() for _ in self.targets]
        self.states = [None] * len(self.targets)
        self.signalled_at = [None] * len(self.targets)
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
                if len(self._reported) == target and not self.done[k].is_set():
                    kind = self.kinds[k]
                    os.kill(self.pids[kind], signal.SIGSTOP if kind == "pemkre" else signal.SIGKILL)
                    self.signalled_at[k] = time.time()
                    self.states[k] = {"specific_process": m.specific_process, "task": m.task}
                    self.done[k].set()

    def close(self):
        self._sub.unregister()


class _NotReadyLines:
    """HICEM's log lines (/rosout: a rostest runs no aggregator) that quote a NOT_READY answer of PEMKRE."""

    def __init__(self):
        self.lines = []
        self._sub = rospy.Subscriber("/rosout", Log, self._on_log, queue_size=500)

    def _on_log(self, m):
        if "NOT_READY" in m.msg and "hicem" in m.name:
            self.lines.append(m.msg)

    def close(self):
        self._sub.unregister()


def _server_pid(path):
    try:
        with open(path, encoding="utf-8") as f:
            return int(f.read().strip() or 0) or None
    except (OSError, ValueError):
        return None


def _alive(pid):
    try:
        os.kill(pid, 0)
        return True
    except OSError:
        return False


class JobPemkreKillTest(unittest.TestCase):
    maxDiff = None

    @classmethod
    def setUpClass(cls):
        init_test_node("job_pemkre_kill_test")
        cls.results_dir = setting("results_dir")
        cls.call_log = setting("call_log")
        cls.server_pid_file = setting("server_pid")
        cls.query_url = setting("query_url")
        cls.timeline = HicemTimeline()
        cls.sim = SimCalls()
        cls.not_ready = _NotReadyLines()
        cls.hicem_pid = node_pid("/hicem")
        cls.kills = []            # (what, pid, new pid, time.time() of the kill, time.time() it answered again)
        cls.pemkre_after_server_kill = None
        cls.specific = set()
        server = wait_until(lambda: _server_pid(cls.server_pid_file), timeout=60.0)
        assert server, "the SPARQL server node wrote no pid to %s" % cls.server_pid_file
        cls.killer = _KillOnReport({"pemkre": node_pid("/pemkre"), "server": server}, KILL_AT, KILLED)
        try:
            for k in range(len(KILL_AT)):
                cls._kill_when_reporting(k)
        finally:
            cls.killer.close()
        cls.taping_end = cls.timeline.wait_for(lambda s: s["process"] == TAPING and s["phase"] in TERMINAL,
                                               timeout=600.0)
        cls.line_states = {r["state"].split("#")[-1]: int(r["lines"]) for r in pemkre_rows("feature_counts")}
        cls.joints = cls.sim.outcome()["joints"]
        cls.sanding_end = cls.timeline.wait_for(lambda s: s["process"] == SANDING and s["phase"] in TERMINAL,
                                                timeout=900.0)
        cls.asked = cls.timeline.asked()
        cls.report = wait_for_report(cls.results_dir, timeout=120.0)
        cls.calls = read_call_log(cls.call_log)
        cls.not_ready.close()

    @classmethod
    def _kill_when_reporting(cls, k):
        killer = cls.killer
        kind = KILLED[k]
        assert killer.done[k].wait(600.0), "never saw HICEM report TAPE_LINE number %d (last state %s)" % (
            KILL_AT[k], cls.timeline.latest())
        pid = killer.pids[kind]
        cls.specific.add(killer.states[k]["specific_process"])
        if kind == "pemkre":
            time.sleep(0.3)                   # the call in flight (or the next one) waits on the frozen PEMKRE
            os.kill(pid, signal.SIGKILL)
            t_kill = time.time()
            new_pid = wait_until(lambda: (lambda p: p if p not in (None, pid) else None)(try_node_pid("/pemkre")),
                                 timeout=60.0, period=0.05)
            assert new_pid, "no new /pemkre within 60 s of kill -9 of pid %d (respawn in launch/pemkre.launch?)" % pid
            rospy.wait_for_service("/pemkre/next_action", timeout=60.0)
        else:
            t_kill = killer.signalled_at[k]
            pemkre = try_node_pid("/pemkre")
            new_pid = wait_until(lambda: (lambda p: p if p not in (None, pid) and _alive(p) else None)(
                _server_pid(cls.server_pid_file)), timeout=60.0, period=0.05)
            assert new_pid, "no new SPARQL server within 60 s of kill -9 of pid %d (respawn of sparql_server)" % pid
            cls.pemkre_after_server_kill = (pemkre, try_node_pid("/pemkre"))
        killer.pids[kind] = new_pid
        cls.kills.append((kind, pid, new_pid, t_kill, time.time()))

    def test_1_pemkre_and_the_server_restarted_under_hicem_calls_that_went_on(self):
        self.assertEqual([k[0] for k in self.kills], list(KILLED))
        for kind, pid, new_pid, t_kill, t_back in self.kills:
            self.assertNotEqual(pid, new_pid)
            print("%s pid %d killed, pid %d up %.1f s later" % (kind, pid, new_pid, t_back - t_kill))
        self.assertEqual(try_node_pid("/hicem"), self.hicem_pid, "HICEM must not die when PEMKRE does")
        before, after = self.pemkre_after_server_kill
        self.assertEqual(before, after, "PEMKRE must not die when its server does")
        # while the server was away, PEMKRE answered NOT_READY naming the endpoint, and HICEM waited
        server = self.query_url.rsplit("/", 1)[0]
        quoted = [line for line in self.not_ready.lines if server in line]
        print("HICEM quoting NOT_READY: %d line(s), e.g. %s" % (len(quoted), quoted[:1]))
        self.assertTrue(quoted, "no HICEM log line quoting PEMKRE's NOT_READY with %s: %s" % (
            server, self.not_ready.lines[:5]))
        # per kill: a call HICEM had in flight that completed after the restart (PEMKRE: sent before the kill, to the
        # frozen node; the server: under way when it came back -- the kill comes from HICEM's "reporting" state, so
        # the report may leave just before or just after it, and waits on NOT_READY through the outage)
        spanned = [[c for c in self.calls if c["layer"] == "pemkre" and c["ok"] and
                    c["t0"] < (t_kill if kind == "pemkre" else t_back) < c["t1"]]
                   for kind, _p, _n, t_kill, t_back in self.kills]
        print("HICEM calls in flight across each kill: %s" % [[(c["call"], round(c["t1"] - c["t0"], 2)) for c in s]
                                                               for s in spanned])
        self.assertTrue(all(spanned), "calls around the kills: %s" % [
            c for c in self.calls if any(abs(c["t1"] - tk) < 15 for _k, _p, _n, tk, _b in self.kills)])
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
