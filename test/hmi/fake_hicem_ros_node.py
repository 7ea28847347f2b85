#!/usr/bin/env python3
"""TEST DOUBLE of the HICEM ROS node (and of the simulator's operator services) for the operator_hmi node test.

The real HICEM message and service types on the real names (/hicem/state latched, /hicem/start_process,
/hicem/stop, /hicem/operator_reply) playing a fixed script: mount_tool prompt, then one validate_line prompt per
joint (invalid -> a manual_taping prompt for it), then ended. The running action's skill state: one program state
machine per process run (Start at start_process, Halted at stop), /hicem/{suspend,resume,halt,reset}
(SkillControl) and /hicem/skill_state (SkillTransition, latched). The simulator side: /sim/remove_tool,
/sim/mount_tool, /sim/manual_taping, /sim/outcome, /sim/save_outcome (locem_bridge/JsonCall; save_outcome writes
one PNG per wall with Pillow). ``~feed_states`` (locem_bridge/JsonCall, ``{"states": [partial state dicts]}``)
publishes the given states on /hicem/state one after the other, at once (what HICEM publishes as its tasks
report, e.g. a SPRAY_AREA report naming manual work). Every call is appended to a JSON-lines log (``~log``) so
the test can check what the operator_hmi node did, in order. Not the executive, not the simulator."""
import io
import json
import os
import threading
import uuid

from PIL import Image

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from locem_bridge.common.program_state import Method, ProgramStateMachine, TransitionRefused
from locem_bridge.hicem.skill_control import operator_methods
from locem_bridge.msg import HicemState, SkillTransition
from locem_bridge.srv import (HicemOperatorReply, HicemOperatorReplyResponse, HicemStartProcess,
                              HicemStartProcessResponse, HicemStop, HicemStopResponse, JsonCall, JsonCallResponse,
                              PemkreStartProcess, SkillControl, SkillControlResponse)

JOINTS = ["wall_1_joint_1", "wall_1_joint_2"]


class FakeHicem:
    def __init__(self) -> None:
        self.log_path = rospy.get_param("~log")
        self.lock = threading.Lock()
        self.state = {"process": "", "specific_process": "", "phase": "idle", "action_type": "", "task": "",
                      "tree": "", "node": "", "path": "", "detail": ""}
        self.prompts = []
        self.step = -1
        self.pub = rospy.Publisher("~state", HicemState, queue_size=20, latch=True)
        self.diag = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        self.services = [rospy.Service("~start_process", HicemStartProcess, self.start),
                         rospy.Service("~stop", HicemStop, self.stop),
                         rospy.Service("~operator_reply", HicemOperatorReply, self.reply)]
        self.skill_pub = rospy.Publisher("~skill_state", SkillTransition, queue_size=20, latch=True)
        self.machine = None
        self.skill_services = [rospy.Service("~%s" % m.value.lower(), SkillControl, self.skill_handler(m))
                               for m in (Method.SUSPEND, Method.RESUME, Method.HALT, Method.RESET)]
        self.mounted = None
        self.feed_service = rospy.Service("~feed_states", JsonCall, self.feed_states)
        self.sim_services = [rospy.Service("/sim/%s" % op, JsonCall, self.sim_handler(op))
                             for op in ("remove_tool", "mount_tool", "manual_taping", "outcome", "save_outcome")]
        self.publish()

    def sim_handler(self, op):
        def handle(req):
            args = json.loads(req.args or "{}")
            with self.lock:
                self.record("sim", op, args)
                if op == "mount_tool":
                    if self.mounted is not None:
                        return JsonCallResponse(False, "mount_tool refused: %s is mounted" % self.mounted, "{}")
                    self.mounted = args["name"]
                elif op == "remove_tool":
                    self.mounted = None
                elif op == "outcome":
                    return JsonCallResponse(True, "outcome done", json.dumps({"joints": {j: 0.0 for j in JOINTS}}))
                elif op == "save_outcome":
                    for wall in ("wall_1", "wall_2"):
                        buf = io.BytesIO()
                        Image.new("RGB", (48, 25), (30, 160, 60) if self.mounted else (210, 40, 40)).save(buf, "PNG")
                        with open(os.path.join(args["folder"], wall + ".png"), "wb") as fh:
                            fh.write(buf.getvalue())
            return JsonCallResponse(True, "%s done" % op, "{}")
        return handle

    def feed_states(self, req):
        states = json.loads(req.args or "{}").get("states", [])
        with self.lock:
            self.record("feed_states", len(states))
            for st in states:
                unknown = sorted(set(st) - set(self.state))
                if unknown:
                    return JsonCallResponse(False, "unknown state field(s) %s" % ", ".join(unknown), "{}")
                self.state.update(st)
                self.publish()
        return JsonCallResponse(True, "%d states published" % len(states), "{}")

    def transition(self, tr) -> None:
        self.skill_pub.publish(SkillTransition(instance=tr.instance, skill=tr.skill, number=tr.number,
                                               transition=tr.name, from_state=tr.source.value,
                                               to_state=tr.target.value, method=tr.method, cause=tr.cause))

    def skill_handler(self, method):
        def handle(req):
            with self.lock:
                self.record("skill", method.value, req.cause)
                m = self.machine
                if m is None:
                    return SkillControlResponse(False, "INVALID_ARGUMENT", "%s is not allowed: no HICEM action is "
                                                "running" % method.value, "", "")
                try:
                    m.call(method, req.cause)
                except TransitionRefused as exc:
                    return SkillControlResponse(False, "INVALID_ARGUMENT", str(exc), m.state.value,
                                                ",".join(x.value for x in operator_methods(m.state)))
                return SkillControlResponse(True, "OK", "%s taken" % method.value, m.state.value,
                                            ",".join(x.value for x in operator_methods(m.state)))
        return handle

    def record(self, *call) -> None:
        with open(self.log_path, "a") as fh:
            fh.write(json.dumps(list(call)) + "\n")

    def publish(self) -> None:
        msg = HicemState(prompts=json.dumps(self.prompts), **self.state)
        msg.header.stamp = rospy.Time.now()
        self.pub.publish(msg)

    def open(self, kind, text, choices) -> None:
        self.prompts = [{"id": uuid.uuid4().hex[:12], "kind": kind, "text": text, "choices": choices}]

    def start(self, req):
        with self.lock:
            self.record("start_process", req.process, req.options)
            if self.state["phase"] == "running":
                return HicemStartProcessResponse(False, "process %s is still running; stop it first" %
                                                 self.state["process"])
            specific = "urn:fake:run"
            try:                                  # with a real PEMKRE node: a real specific process for the KPIs
                rospy.wait_for_service("/pemkre/start_process", timeout=0.2)
                reply = rospy.ServiceProxy("/pemkre/start_process", PemkreStartProcess)(
                    process=req.process, options=req.options, abort_running=True)
                specific = reply.specific_process if reply.success else specific
            except rospy.ROSException:
                pass
            self.state.update(process=req.process, specific_process=specific, phase="running",
                              action_type="GET_TOOL", task="urn:fake:task_1", tree="GET_TOOL", node="ask_mount",
                              detail="")
            self.step = -1
            self.machine = ProgramStateMachine("urn:fake:task_1", "GET_TOOL", listener=self.transition)
            self.machine.call(Method.START, "HICEM runs the tree GET_TOOL")
            self.open("mount_tool", "Mount the taping_tool on the arm, then answer done.", ["done"])
            self.publish()
            return HicemStartProcessResponse(True, "process %s started" % req.process)

    def stop(self, req):
        with self.lock:
            self.record("stop", req.reason)
            self.prompts = []
            if self.state["phase"] == "running":
                self.state.update(phase="stopped", detail="stopped: %s" % req.reason, tree="", node="")
                if self.machine is not None:
                    self.machine.fail("stopped: %s" % req.reason)
            self.publish()
            return HicemStopResponse(True, "stopped")

    def reply(self, req):
        with self.lock:
            self.record("reply", req.prompt_id, req.answer)
            open_ids = [p["id"] for p in self.prompts]
            if req.prompt_id not in open_ids:
                return HicemOperatorReplyResponse(False, "prompt '%s' is not known; open prompts: %s" % (
                    req.prompt_id, ", ".join(open_ids) or "none"))
            kind = self.prompts[0]["kind"]
            if kind == "validate_line" and req.answer == "invalid":
                joint = JOINTS[self.step]
                self.state.update(action_type="MANUAL_TAPING", tree="MANUAL_TAPING", node="ask_manual")
                self.open("manual_taping", "Please tape joint %s by hand, then answer done." % joint, ["done"])
                self.publish()
                return HicemOperatorReplyResponse(True, "answer '%s' given" % req.answer)
            self.step += 1
            if self.step < len(JOINTS):
                joint = JOINTS[self.step]
                self.state.update(action_type="VALIDATE_TAPE_LINE", task="urn:fake:task_%d" % (self.step + 2),
                                  tree="VALIDATE_TAPE_LINE", node="ask_valid")
                self.open("validate_line", "Is joint %s well placed for taping from here? Answer valid or invalid."
                          % joint, ["valid", "invalid"])
            else:
                self.prompts = []
                self.state.update(phase="ended", action_type="", task="", tree="", node="", detail="done")
            self.publish()
            return HicemOperatorReplyResponse(True, "answer '%s' given" % req.answer)

    def beat(self) -> None:
        self.diag.publish(DiagnosticArray(status=[DiagnosticStatus(level=DiagnosticStatus.OK, name="locem",
                                                                   message="alive")]))


def main() -> None:
    rospy.init_node("hicem")
    fake = FakeHicem()
    rate = rospy.Rate(2)
    while not rospy.is_shutdown():
        fake.beat()
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break


if __name__ == "__main__":
    main()
