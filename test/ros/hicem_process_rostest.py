#!/usr/bin/env python3
"""rostest: HICEM node + real LOCEM node + embedded PEMKRE engine.

A whole taping process driven through /hicem/start_process with operator answers through /hicem/operator_reply;
bad input; /hicem/stop mid-action; a crucial module failing on /diagnostics; kill -9 of HICEM mid-taping and
the restarted node resuming without taping the interrupted joint again.
"""
import json
import os
import re
import signal
import subprocess
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from locem_bridge.msg import HicemPrompt, HicemState, Status
from locem_bridge.srv import Command, HicemOperatorReply, HicemStartProcess, HicemStop

from rostest_support import result_of, rosservice_call, wait_until

TAPING = "https://locem-bridge.example.org/ont/plasterboard#TapingProcess"
TAPE_CMD = "WAIT 2 hold=arm"  # what the rostest TAPE_LINE tree sends (cfg.test.tape_s = 2.0)


class HicemProcessTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("hicem_process_test", anonymous=True)
        cls.lock = threading.Lock()
        cls.states, cls.prompts, cls.locem_events = [], [], []
        cls.answered = set()
        cls.answers = {"mount_tool": "done", "validate_line": "valid", "manual_taping": "done",
                       "finish_interrupted": "done"}
        cls.reject = set()
        cls.auto_answer = True
        rospy.Subscriber("/hicem/state", HicemState, cls._on_state, queue_size=100)
        rospy.Subscriber("/hicem/prompts", HicemPrompt, cls._on_prompt, queue_size=100)
        rospy.Subscriber("/locem/status", Status, cls._on_locem, queue_size=500)
        cls.diag = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        for s in ("/hicem/start_process", "/hicem/stop", "/hicem/operator_reply", "/locem/command"):
            rospy.wait_for_service(s, timeout=120)
        cls.locem = rospy.ServiceProxy("/locem/command", Command)
        cls.start = rospy.ServiceProxy("/hicem/start_process", HicemStartProcess)
        cls.stop = rospy.ServiceProxy("/hicem/stop", HicemStop)
        cls.reply = rospy.ServiceProxy("/hicem/operator_reply", HicemOperatorReply)
        cls.extra_node = None

    @classmethod
    def tearDownClass(cls):
        if cls.extra_node is not None:
            cls.extra_node.send_signal(signal.SIGINT)
            try:
                cls.extra_node.wait(timeout=15)
            except subprocess.TimeoutExpired:
                cls.extra_node.kill()

    # -- recorders ------------------------------------------------------------------------------------------
    @classmethod
    def _on_state(cls, msg):
        with cls.lock:
            cls.states.append((time.monotonic(), msg))
        # the latched state lists the open prompts: answer from there too (a restarted node's prompt event may
        # go out before this subscriber is connected to it)
        for p in json.loads(msg.prompts or "[]"):
            cls._on_prompt(HicemPrompt(id=p["id"], event="opened", kind=p["kind"], text=p["text"],
                                       choices=p["choices"]), record=False)

    @classmethod
    def _on_locem(cls, msg):
        with cls.lock:
            cls.locem_events.append((time.monotonic(), msg))

    @classmethod
    def _on_prompt(cls, msg, record=True):
        with cls.lock:
            if record:
                cls.prompts.append(msg)
            if msg.event != "opened" or not cls.auto_answer or msg.id in cls.answered:
                return
            cls.answered.add(msg.id)
        answer = cls.answers[msg.kind]
        if msg.kind == "validate_line" and any(r in msg.text for r in cls.reject):
            answer = "invalid"
        threading.Thread(target=cls._answer, args=(msg.id, answer), daemon=True).start()

    @classmethod
    def _answer(cls, pid, answer):
        try:  # a fresh proxy: the node answering may have been restarted
            rospy.ServiceProxy("/hicem/operator_reply", HicemOperatorReply)(pid, answer)
        except (rospy.ServiceException, rospy.ROSException):
            with cls.lock:
                cls.answered.discard(pid)

    def state(self):
        with self.lock:
            return self.states[-1][1] if self.states else None

    def wait_phase(self, phases, timeout):
        ok = wait_until(lambda: self.state() is not None and self.state().phase in phases, timeout, 0.05)
        self.assertTrue(ok, "phase never became %s; last state %s" % (phases, self.state()))
        return self.state()

    def started(self, command, since=0):
        with self.lock:
            return [m for _t, m in self.locem_events[since:] if m.command == command and m.state == "running"]

    def mark(self):
        with self.lock:
            return len(self.locem_events), len(self.prompts)

    def start_taping(self, validate):
        resp = self.start(TAPING, json.dumps({"validateLines": validate}))
        self.assertTrue(resp.success, resp.message)
        self.wait_phase(("asking", "starting", "running"), 30)

    def wait_tape_running(self, since, n=1):
        self.assertTrue(wait_until(lambda: len(self.started(TAPE_CMD, since)) >= n, 60, 0.02),
                        "tape command #%d never started" % n)
        self.assertTrue(wait_until(lambda: self.state().tree == "TAPE_LINE" and self.state().node == "locem_command",
                                   5, 0.02), self.state())

    def locem_running(self):
        return result_of(self.locem("STATUS").result)["running"]

    # -- tests (run in name order, each leaves HICEM idle) ---------------------------------------------------
    def test_1_whole_taping_process_with_operator_validation(self):
        ev, pr = self.mark()
        type(self).reject = {"wall_1_joint_2"}
        # start through the real command line, as an operator or integrator would
        out = rosservice_call("/hicem/start_process",
                              "{process: '%s', options: '{\"validateLines\": true}'}" % TAPING)
        self.assertTrue(out["success"], out)
        st = self.wait_phase(("ended", "failed", "stopped"), 120)
        self.assertEqual(st.phase, "ended", st.detail)
        with self.lock:
            opened = [p.kind for p in self.prompts[pr:] if p.event == "opened"]
        self.assertEqual(opened.count("mount_tool"), 1)
        self.assertEqual(opened.count("validate_line"), 3)
        self.assertEqual(opened.count("manual_taping"), 1)  # the rejected joint
        self.assertEqual(len(self.started(TAPE_CMD, ev)), 2)  # joints 1 and 3 taped, joint 2 not
        self.assertEqual(self.locem_running(), [])
        type(self).reject = set()

    def test_2_bad_input_gets_clear_answers(self):
        resp = self.reply("no_such_prompt", "done")
        self.assertFalse(resp.success)
        self.assertIn("prompt 'no_such_prompt' is not known", resp.message)
        resp = self.start(TAPING, "{not json")
        self.assertFalse(resp.success)
        self.assertIn("options are not a JSON object", resp.message)
        resp = self.start("https://example.org/NoSuchProcess", "")
        self.assertTrue(resp.success)  # accepted; PEMKRE's refusal shows in the state
        st = self.wait_phase(("failed",), 30)
        self.assertIn("NoSuchProcess", st.detail)

    def test_3_stop_halts_the_running_command(self):
        ev, _ = self.mark()
        self.start_taping(False)
        self.wait_tape_running(ev)
        t0 = time.monotonic()
        resp = self.stop("operator pressed stop")
        self.assertTrue(resp.success, resp.message)
        self.assertEqual(self.locem_running(), [])
        print("stop: service answered after %.0f ms with LOCEM idle" % ((time.monotonic() - t0) * 1000))
        st = self.wait_phase(("stopped",), 10)
        self.assertIn("operator pressed stop", st.detail)
        with self.lock:
            ends = [m for _t, m in self.locem_events[ev:] if m.command == TAPE_CMD and m.state != "running"]
        self.assertTrue(ends and ends[-1].state in ("canceled", "failed"), [m.state for m in ends])

    def test_4_crucial_module_failure_halts_within_200_ms(self):
        ev, _ = self.mark()
        self.start_taping(False)
        self.wait_tape_running(ev)
        t_fault = rospy.Time.now()
        self.diag.publish(DiagnosticArray(status=[DiagnosticStatus(level=DiagnosticStatus.ERROR, name="locem",
                                                                   message="simulated RTDE failure")]))

        def tape_ended():
            with self.lock:
                return [m for _t, m in self.locem_events[ev:] if m.command == TAPE_CMD and m.state != "running"]
        self.assertTrue(wait_until(lambda: tape_ended(), 5, 0.01), "tape command never ended")
        latency = (tape_ended()[0].header.stamp - t_fault).to_sec()
        print("module failure -> LOCEM command ended after %.1f ms" % (latency * 1000))
        self.assertLess(latency, 0.2)
        self.assertEqual(self.locem_running(), [])
        st = self.wait_phase(("waiting_for_health",), 5)
        self.assertIn("simulated RTDE failure", st.detail)
        self.diag.publish(DiagnosticArray(status=[DiagnosticStatus(level=DiagnosticStatus.OK, name="locem",
                                                                   message="recovered")]))
        st = self.wait_phase(("failed", "ended"), 30)  # PEMKRE fails a process whose task failed
        self.assertIn("simulated RTDE failure", st.detail)

    def test_5_kill_9_mid_taping_then_resume_without_taping_twice(self):
        ev, pr = self.mark()
        self.start_taping(False)
        self.wait_tape_running(ev, n=2)  # second joint being taped
        info = subprocess.run(["rosnode", "info", "/hicem"], capture_output=True, text=True, timeout=30).stdout
        pid = int(re.search(r"Pid: (\d+)", info).group(1))
        os.kill(pid, signal.SIGKILL)
        killed_at = len(self.locem_events)
        # restart under the same name: it reads the same private parameters (HDICT, PEMKRE store)
        type(self).extra_node = subprocess.Popen(["rosrun", "locem_bridge", "hicem_node", "__name:=hicem"],
                                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.assertTrue(wait_until(lambda: bool(self.started("STOP", killed_at)) or any(
            m.command == "STOP" for _t, m in self.locem_events[killed_at:]), 60, 0.05), "no STOP after restart")
        st = self.wait_phase(("ended", "failed", "stopped"), 120)
        self.assertEqual(st.phase, "ended", st.detail)
        with self.lock:
            kinds = [p.kind for p in self.prompts[pr:]] + [m.prompts for _t, m in self.states]
        self.assertTrue(any("finish_interrupted" in k for k in kinds))  # the operator finished the interrupted joint by hand
        self.assertEqual(len(self.started(TAPE_CMD, ev)), 3)  # joints 1, 2 (interrupted), 3: none taped twice
        self.assertEqual(self.locem_running(), [])


if __name__ == "__main__":
    rostest.rosrun("locem_bridge", "hicem_process", HicemProcessTest)
