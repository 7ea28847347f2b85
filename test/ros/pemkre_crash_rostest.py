#!/usr/bin/env python3
"""rostest: SIGKILL the PEMKRE node mid-run; roslaunch respawns it; the run continues where it stopped. And
HICEM's PEMKRE client (the real one, ros/hicem_pemkre.py) with a call in flight when PEMKRE is killed: the call
is sent again after the respawn, completes within its deadline, and the report is applied once. And HICEM's
LOCEM client (ros/hicem_locem.py) across a kill -9 of LOCEM: a command sent while LOCEM is away runs once on the
respawned LOCEM; the command that was running when LOCEM died ends ABORTED and is not sent again."""
import json
import os
import signal
import threading
import time
import unittest
import xmlrpc.client

import rosgraph
import rospy
import rostest
from locem_bridge.msg import Status
from locem_bridge.ros.hicem_locem import RosLocemClient
from locem_bridge.ros.hicem_pemkre import RosPemkreClient
from locem_bridge.srv import (PemkreNextAction, PemkreQuery, PemkreSetTaskStatus, PemkreStartProcess,
                              PemkreUpdateWorld)

PKG = "locem_bridge"
TAPING = "https://locem-bridge.example.org/ont/plasterboard#TapingProcess"
SCAN = {"stamp": 1.0, "walls": [{"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.8, 3.0], "height": 2.5}],
        "joints": [{"id": "wall_1_joint_%d" % i, "wall": "wall_1", "kind": "vertical", "start": [1.0 * i, 3.0, 0.0],
                    "end": [1.0 * i, 3.0, 2.5], "width": 0.05} for i in (1, 2, 3, 4)], "areas": []}

SCAN2 = {"stamp": 2.0, "walls": [{"id": "wall_2", "p0": [0.0, 6.0], "p1": [4.8, 6.0], "height": 2.5}],
         "joints": [{"id": "wall_2_joint_%d" % i, "wall": "wall_2", "kind": "vertical", "start": [1.0 * i, 6.0, 0.0],
                     "end": [1.0 * i, 6.0, 2.5], "width": 0.05} for i in (1, 2)], "areas": []}


def proxies():
    for name in ("start_process", "next_action", "set_task_status", "query", "update_world"):
        rospy.wait_for_service("/pemkre/" + name, timeout=90)
    return (rospy.ServiceProxy("/pemkre/start_process", PemkreStartProcess),
            rospy.ServiceProxy("/pemkre/next_action", PemkreNextAction),
            rospy.ServiceProxy("/pemkre/set_task_status", PemkreSetTaskStatus),
            rospy.ServiceProxy("/pemkre/query", PemkreQuery),
            rospy.ServiceProxy("/pemkre/update_world", PemkreUpdateWorld))


def node_pid(node="/pemkre"):
    uri = rosgraph.Master("/pemkre_crash_test").lookupNode(node)
    code, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/pemkre_crash_test")
    assert code == 1
    return pid


def wait_new_pid(old, timeout=60.0, node="/pemkre"):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            pid = node_pid(node)
            if pid != old:
                return pid
        except Exception:
            pass
        time.sleep(0.1)
    raise AssertionError("no new /pemkre within %.0f s of the kill of pid %d" % (timeout, old))


class PemkreCrashTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("pemkre_crash_test", anonymous=True)

    def test_y_locem_commands_across_kill_dash_nine_of_locem(self):
        events = []
        sub = rospy.Subscriber("/locem/status", Status, lambda m: events.append((time.monotonic(), m.command,
                                                                                m.state, m.code)), queue_size=500)
        client = RosLocemClient("/locem", wait_s=60.0)
        try:
            long = client.send("WAIT 30")
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline and not any(c == "WAIT 30" and st == "running" for _t, c, st, _c in events):
                time.sleep(0.02)
            self.assertFalse(long.done())
            pid = node_pid("/locem")
            os.kill(pid, signal.SIGKILL)
            t_kill = time.monotonic()
            deadline = time.monotonic() + 10
            while client.server_ready() and time.monotonic() < deadline:      # the client sees LOCEM gone
                time.sleep(0.01)
            self.assertFalse(client.server_ready(), "the action client still sees the killed LOCEM")
            held = client.send("WAIT 0.2")      # LOCEM away: held, sent when it is back
            self.assertFalse(held.done())
            deadline = time.monotonic() + 10
            while not long.done() and time.monotonic() < deadline:
                time.sleep(0.02)
            self.assertTrue(long.done(), "the goal LOCEM was running when it died never ended")
            lost = long.reply()
            self.assertEqual(lost.code, "ABORTED", lost)
            self.assertIn("went away while running 'WAIT 30'", lost.message)
            new_pid = wait_new_pid(pid, node="/locem")
            self.assertNotEqual(new_pid, pid)
            deadline = time.monotonic() + 60
            while not held.done() and time.monotonic() < deadline:
                time.sleep(0.02)
            reply = held.reply()
            self.assertIsNotNone(reply, "the held command never ran")
            self.assertTrue(reply.success, reply)
            after = [(c, st) for t, c, st, _c in events if t > t_kill]
            self.assertEqual([st for c, st in after if c == "WAIT 0.2"], ["running", "succeeded"])   # once
            self.assertNotIn("WAIT 30", [c for c, _st in after])                                   # not resent
        finally:
            sub.unregister()

    def test_z_hicem_client_call_in_flight_outlives_kill_dash_nine(self):
        """PEMKRE frozen (SIGSTOP) so the client's call is provably in flight, then SIGKILL: the call fails
        underneath, the client sends it again to the respawned PEMKRE and returns normally."""
        proxies()
        client = RosPemkreClient("/pemkre", deadline_s=60.0)
        client.report_world(SCAN2)      # runs after the other test: joints of its own
        client.start_process(TAPING, {"validateLines": False})
        a = client.next_action()
        self.assertEqual(a.action_type, "GET_TOOL")
        client.set_task_status(a.task, "in_progress")
        client.set_task_status(a.task, "succeeded")
        tape = client.next_action()
        self.assertEqual(tape.action_type, "TAPE_LINE")
        client.set_task_status(tape.task, "in_progress")
        for call, args in (("set_task_status", (tape.task, "succeeded")), ("next_action", ())):
            pid = node_pid()
            os.kill(pid, signal.SIGSTOP)
            outcome = {}

            def in_flight():
                t0 = time.monotonic()
                try:
                    outcome["result"] = getattr(client, call)(*args)
                except Exception as exc:          # reported by the assertions below
                    outcome["error"] = exc
                outcome["took"] = time.monotonic() - t0
            th = threading.Thread(target=in_flight, daemon=True)
            th.start()
            time.sleep(1.0)
            self.assertTrue(th.is_alive(), "the %s call did not wait for the frozen PEMKRE: %s" % (call, outcome))
            os.kill(pid, signal.SIGKILL)
            t_kill = time.monotonic()
            new_pid = wait_new_pid(pid)
            th.join(60.0)
            self.assertFalse(th.is_alive(), "the %s call did not return within 60 s of the kill" % call)
            self.assertNotIn("error", outcome)
            self.assertNotEqual(new_pid, pid)
            name, attempts, took = client.retried[-1]
            self.assertEqual(name, call)
            self.assertGreaterEqual(attempts, 2)
            self.assertGreater(outcome["took"], 1.0)          # in flight from before the kill until after it
        # the succeeded report reached the respawned PEMKRE once: the next action is the second joint
        self.assertEqual(outcome["result"].action_type, "TAPE_LINE")
        self.assertNotEqual(outcome["result"].task, tape.task)
        start, nxt, status, query, world = proxies()
        log = json.loads(query("task_log", [], []).results)["results"]["bindings"]
        mine = [r for r in log if r["task"]["value"] == tape.task]
        self.assertEqual([r["status"]["value"] for r in mine], ["succeeded"])
        # the same report sent again (a HICEM that restarted before recording the answer) changes nothing
        again = status(tape.task, "succeeded", "", "hicem-x")
        self.assertFalse(again.success)          # a new id: PEMKRE refuses it as the task is no longer running
        client.set_task_status(tape.task, "succeeded")          # the client's own id: already applied, OK
        self.assertEqual(nxt("").task, outcome["result"].task)

    def test_kill_dash_nine_mid_task_and_after_an_acknowledged_status(self):
        start, nxt, status, query, world = proxies()
        self.assertTrue(world(json.dumps(SCAN)).success)
        self.assertTrue(start(TAPING, '{"validateLines": false}', True, "").success)
        done = []
        kills = 0
        for step in range(30):
            a = nxt("")
            self.assertTrue(a.success, a.message)
            if a.status != "action":
                break
            if a.task_status == "issued":
                self.assertTrue(status(a.task, "in_progress", "", "").success)
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
            r = status(a.task, "succeeded", "", "")
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
