#!/usr/bin/env python3
"""rostest: SIGKILL the PEMKRE node mid-run; roslaunch respawns it; the run continues where it stopped."""
import json
import os
import signal
import time
import unittest
import xmlrpc.client

import rosgraph
import rospy
import rostest
from locem_bridge.srv import (PemkreNextAction, PemkreQuery, PemkreSetTaskStatus, PemkreStartProcess,
                              PemkreUpdateWorld)

PKG = "locem_bridge"
TAPING = "https://locem-bridge.example.org/ont/plasterboard#TapingProcess"
SCAN = {"stamp": 1.0, "walls": [{"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.8, 3.0], "height": 2.5}],
        "joints": [{"id": "wall_1_joint_%d" % i, "wall": "wall_1", "kind": "vertical", "start": [1.0 * i, 3.0, 0.0],
                    "end": [1.0 * i, 3.0, 2.5], "width": 0.05} for i in (1, 2, 3, 4)], "areas": []}


def proxies():
    for name in ("start_process", "next_action", "set_task_status", "query", "update_world"):
        rospy.wait_for_service("/pemkre/" + name, timeout=90)
    return (rospy.ServiceProxy("/pemkre/start_process", PemkreStartProcess),
            rospy.ServiceProxy("/pemkre/next_action", PemkreNextAction),
            rospy.ServiceProxy("/pemkre/set_task_status", PemkreSetTaskStatus),
            rospy.ServiceProxy("/pemkre/query", PemkreQuery),
            rospy.ServiceProxy("/pemkre/update_world", PemkreUpdateWorld))


def node_pid():
    uri = rosgraph.Master("/pemkre_crash_test").lookupNode("/pemkre")
    code, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/pemkre_crash_test")
    assert code == 1
    return pid


class PemkreCrashTest(unittest.TestCase):
    def test_kill_dash_nine_mid_task_and_after_an_acknowledged_status(self):
        rospy.init_node("pemkre_crash_test", anonymous=True)
        start, nxt, status, query, world = proxies()
        self.assertTrue(world(json.dumps(SCAN)).success)
        self.assertTrue(start(TAPING, '{"validateLines": false}', True).success)
        done = []
        kills = 0
        for step in range(30):
            a = nxt("")
            self.assertTrue(a.success, a.message)
            if a.status != "action":
                break
            if a.task_status == "issued":
                self.assertTrue(status(a.task, "in_progress", "").success)
            if step in (2, 4) and kills < 2:       # crash while the task is in progress: it must come back
                pid = node_pid()
                os.kill(pid, signal.SIGKILL)
                kills += 1
                deadline = time.monotonic() + 60
                while time.monotonic() < deadline:
                    try:
                        if node_pid() != pid:
                            break
                    except Exception:
                        pass
                    time.sleep(0.2)
                start, nxt, status, query, world = proxies()
                again = nxt("")
                self.assertEqual((again.task, again.action_type, again.task_status), (a.task, a.action_type, "in_progress"))
            r = status(a.task, "succeeded", "")
            self.assertTrue(r.success, r.message)
            done.append((a.action_type, a.parameters))
        self.assertEqual(kills, 2)
        self.assertEqual([d[0] for d in done], ["GET_TOOL"] + ["TAPE_LINE"] * 4 + ["GO_HOME"])
        lines = [d[1].split()[2] for d in done if d[0] == "TAPE_LINE"]
        self.assertEqual(len(set(lines)), 4)           # no line repeated, none skipped
        log = json.loads(query("task_log", [], []).results)["results"]["bindings"]
        last = [r for r in log if r["process"]["value"] == log[-1]["process"]["value"]]
        self.assertEqual([r["status"]["value"] for r in last], ["succeeded"] * 6)
        self.assertEqual([int(r["seq"]["value"]) for r in last], list(range(1, 7)))


if __name__ == "__main__":
    rostest.rosrun(PKG, "pemkre_crash", PemkreCrashTest)
