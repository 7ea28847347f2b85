#!/usr/bin/env python3
"""rostest: the running HICEM action's skill state through ROS (issue 18) -- HICEM node + real LOCEM node +
embedded PEMKRE engine, the rostest trees (every device command a LOCEM WAIT).

/hicem/suspend in the middle of a joint's tape command: the command is suspended in LOCEM (its own transition on
/locem/skill_state), stays suspended longer than it would have run, and after /hicem/resume ends once -- no command
sent again, the process ends with every joint taped once. /hicem/halt mid-joint: the command is cancelled, the
task fails ``halted: ...`` and PEMKRE's taping process (no failure transition) fails with it; /hicem/reset brings
the halted instance back to Ready. Methods the state does not allow are refused with the state's text and change
nothing. Every transition is seen on /hicem/skill_state with its cause.
"""
import json
import threading
import time
import unittest

import rospy
import rostest
from locem_bridge.msg import HicemPrompt, HicemState, SkillTransition, Status
from locem_bridge.srv import Command, HicemStartProcess, HicemOperatorReply, SkillControl

from rostest_support import result_of, rosservice_call, wait_until

TAPING = "https://locem-bridge.example.org/ont/plasterboard#TapingProcess"
TAPE_CMD = "WAIT 2 hold=arm"  # what the rostest TAPE_LINE tree sends (cfg.test.tape_s = 2.0)
METHODS = ("suspend", "resume", "halt", "reset")


class HicemSkillTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("hicem_skill_test", anonymous=True)
        cls.lock = threading.Lock()
        cls.states, cls.transitions, cls.locem_transitions, cls.locem_events = [], [], [], []
        cls.answered = set()
        for s in ("/hicem/start_process", "/hicem/operator_reply", "/locem/command") + tuple(
                "/hicem/" + m for m in METHODS):
            rospy.wait_for_service(s, timeout=120)
        subs = [rospy.Subscriber("/hicem/state", HicemState, cls._on_state, queue_size=200),
                rospy.Subscriber("/hicem/prompts", HicemPrompt, cls._on_prompt, queue_size=100),
                rospy.Subscriber("/hicem/skill_state", SkillTransition, cls._keep(cls.transitions), queue_size=200),
                rospy.Subscriber("/locem/skill_state", SkillTransition, cls._keep(cls.locem_transitions),
                                 queue_size=1000),
                rospy.Subscriber("/locem/status", Status, cls._keep(cls.locem_events), queue_size=1000)]
        assert wait_until(lambda: all(s.get_num_connections() for s in subs), 20), "topics not connected"
        cls.start = rospy.ServiceProxy("/hicem/start_process", HicemStartProcess)
        cls.skill = {m: rospy.ServiceProxy("/hicem/" + m, SkillControl) for m in METHODS}
        cls.locem = rospy.ServiceProxy("/locem/command", Command)

    @classmethod
    def _keep(cls, into):
        def keep(msg):
            with cls.lock:
                into.append(msg)
        return keep

    @classmethod
    def _on_state(cls, msg):
        with cls.lock:
            cls.states.append(msg)
        for p in json.loads(msg.prompts or "[]"):           # answer every prompt (the tool mount) at once
            cls._on_prompt(HicemPrompt(id=p["id"], event="opened", kind=p["kind"], text=p["text"],
                                       choices=p["choices"]))

    @classmethod
    def _on_prompt(cls, msg):
        with cls.lock:
            if msg.event != "opened" or msg.id in cls.answered:
                return
            cls.answered.add(msg.id)
        answer = {"mount_tool": "done", "validate_line": "valid"}.get(msg.kind, msg.choices[0])
        threading.Thread(target=lambda: rospy.ServiceProxy("/hicem/operator_reply", HicemOperatorReply)(
            msg.id, answer), daemon=True).start()

    # -- helpers --------------------------------------------------------------------------------------------
    def state(self):
        with self.lock:
            return self.states[-1] if self.states else None

    def wait_phase(self, phases, timeout):
        ok = wait_until(lambda: self.state() is not None and self.state().phase in phases, timeout, 0.05)
        self.assertTrue(ok, "phase never became %s; last state %s" % (phases, self.state()))
        return self.state()

    def tape_events(self, since=0, state=None):
        with self.lock:
            return [m for m in self.locem_events[since:] if m.command == TAPE_CMD and
                    (state is None or m.state == state)]

    def of(self, instance):
        with self.lock:
            return [(t.transition, t.method, t.cause) for t in self.transitions if t.instance == instance]

    def expect_last(self, task, transition):
        ok = wait_until(lambda: self.of(task) and self.of(task)[-1] == transition, 5, 0.02)
        self.assertTrue(ok, "last transition of %s is not %s: %s" % (task, transition, self.of(task)))

    def start_taping_to_a_tape_command(self):
        with self.lock:
            since = len(self.locem_events)
        resp = self.start(TAPING, json.dumps({"validateLines": False}))
        self.assertTrue(resp.success, resp.message)
        self.assertTrue(wait_until(lambda: self.tape_events(since, "running"), 90, 0.02), "no tape command")
        self.assertTrue(wait_until(lambda: self.state().tree == "TAPE_LINE" and self.state().node == "locem_command",
                                   5, 0.02), self.state())
        self.assertTrue(wait_until(lambda: self.of(self.state().task), 5, 0.02), "no Start transition")
        return since, self.state().task, self.tape_events(since, "running")[0].id

    def locem_running(self):
        return result_of(self.locem("STATUS").result)["running"]

    # -- tests (in name order; each leaves HICEM idle) ------------------------------------------------------
    def test_1_methods_with_no_action_running_are_refused(self):
        for method, text in (("suspend", "Suspend is not allowed: no HICEM action is running"),
                             ("resume", "Resume is not allowed: no HICEM action is running"),
                             ("halt", "Halt is not allowed: no HICEM action is running"),
                             ("reset", "Reset is not allowed: no HICEM action is Halted")):
            resp = self.skill[method]("test")
            self.assertFalse(resp.success, resp)
            self.assertEqual(resp.code, "INVALID_ARGUMENT")
            self.assertIn(text, resp.message)
            self.assertEqual((resp.state, resp.allowed), ("", ""))
        with self.lock:
            self.assertEqual(self.transitions, [])

    def test_2_suspend_mid_joint_then_resume_continues_the_same_command(self):
        since, task, command_id = self.start_taping_to_a_tape_command()
        time.sleep(0.5)
        # through the real command line, as the README shows
        out = rosservice_call("/hicem/suspend", "cause: 'someone walked into the bay'")
        self.assertTrue(out["success"], out)
        self.assertEqual((out["code"], out["state"], out["allowed"]), ("OK", "Suspended", "Resume,Halt"))
        self.assertTrue(wait_until(lambda: self.state().phase == "suspended", 5, 0.02), self.state())
        self.expect_last(task, ("RunningToSuspended", "Suspend", "someone walked into the bay"))
        # the command itself is suspended in LOCEM (its basic skill's own transition)
        self.assertTrue(wait_until(lambda: any(
            t.instance == str(command_id) and t.transition == "RunningToSuspended"
            for t in list(self.locem_transitions)), 5, 0.02), "LOCEM never suspended command %d" % command_id)
        resp = self.skill["suspend"]("again")
        self.assertFalse(resp.success)
        self.assertIn("is Suspended (allowed in Suspended: Resume, Halt)", resp.message)
        resp = self.skill["reset"]("")
        self.assertFalse(resp.success)
        self.assertTrue(wait_until(lambda: self.tape_events(since, "paused"), 5, 0.02), "no paused event")
        time.sleep(2.5)                                    # longer than the whole 2 s command
        self.assertEqual(self.tape_events(since, "succeeded"), [], "the suspended command ended")
        self.assertEqual(self.state().node, "locem_command")
        resp = self.skill["resume"]("bay clear")
        self.assertTrue(resp.success, resp.message)
        self.assertEqual((resp.state, resp.allowed), ("Running", "Suspend,Halt"))
        self.expect_last(task, ("SuspendedToRunning", "Resume", "bay clear"))
        st = self.wait_phase(("ended", "failed", "stopped"), 120)
        self.assertEqual(st.phase, "ended", st.detail)
        # three joints, three tape commands, each sent once and finished once; the suspended one is the same
        self.assertEqual(len({m.id for m in self.tape_events(since, "running")}), 3)
        finished = self.tape_events(since, "succeeded")
        self.assertEqual(len(finished), 3, [(m.id, m.state) for m in self.tape_events(since)])
        self.assertEqual(finished[0].id, command_id)
        self.assertEqual([t[:2] for t in self.of(task)], [("ReadyToRunning", "Start"),
                                                          ("RunningToSuspended", "Suspend"),
                                                          ("SuspendedToRunning", "Resume"),
                                                          ("RunningToReady", "")])
        self.assertEqual(self.locem_running(), [])

    def test_3_halt_mid_joint_fails_the_task_halted_then_reset(self):
        since, task, command_id = self.start_taping_to_a_tape_command()
        resp = self.skill["resume"]("")
        self.assertFalse(resp.success)
        self.assertIn("is Running (allowed in Running: Suspend, Halt)", resp.message)
        self.assertEqual((resp.state, resp.allowed), ("Running", "Suspend,Halt"))
        resp = self.skill["halt"]("operator pressed Abort")
        self.assertTrue(resp.success, resp.message)
        self.assertEqual(resp.state, "Halted")
        self.assertIn(resp.allowed, ("", "Reset"))        # Reset once the worker has halted the tree
        self.assertTrue(wait_until(lambda: [m for m in self.tape_events(since) if m.state != "running"], 5, 0.02))
        ended = [m for m in self.tape_events(since) if m.state != "running"]
        self.assertIn(ended[0].state, ("canceled", "failed"), ended[0])
        # the taping process has no failure transition: PEMKRE fails it with the halted task
        st = self.wait_phase(("ended", "failed", "stopped"), 60)
        self.assertEqual(st.phase, "failed", st.detail)
        self.assertIn("(TAPE_LINE) failed: halted: operator pressed Abort", st.detail)
        self.expect_last(task, ("RunningToHalted", "Halt", "operator pressed Abort"))
        self.assertEqual(self.locem_running(), [])
        out = rosservice_call("/hicem/reset", "cause: 'checked'")
        self.assertTrue(out["success"], out)
        self.assertEqual((out["state"], out["allowed"]), ("Ready", ""))
        self.expect_last(task, ("HaltedToReady", "Reset", "checked"))
        resp = self.skill["reset"]("")
        self.assertFalse(resp.success)
        self.assertIn("no HICEM action is Halted", resp.message)


if __name__ == "__main__":
    rostest.rosrun("locem_bridge", "hicem_skill", HicemSkillTest)
