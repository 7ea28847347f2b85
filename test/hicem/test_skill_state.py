"""Skill state of HICEM's running action (issue 18): OPC UA Part 10 ProgramStateMachineType on a composite skill,
driven through the controller's Suspend / Resume / Halt / Reset against the PEMKRE and LOCEM test doubles.

Suspend keeps the tree (the same node runs on after Resume, no command is sent again), suspends the outstanding
LOCEM commands, freezes the clock the tree sees and records the suspension in the HDICT; a command that cannot be
suspended delays the suspension until it ends; Halt fails the task ``halted: ...`` and the process goes on; Reset
returns the halted instance to Ready; refusals change nothing; a HICEM that died while suspended comes back
Suspended with no device command.
"""
import time

import pytest

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble, PemkreDouble, SITE
from hicem_rig import TREES, params
from locem_bridge.common.program_state import Method, ProgramState
from locem_bridge.hicem.controller import HHLC
from locem_bridge.hicem.errors import ControllerError, SkillMethodRefused
from locem_bridge.hicem.executive import create_executive
from locem_bridge.hicem.skill_control import PausableClock, operator_methods
from locem_bridge.hicem.xml_loader import TreeLibrary

P = PemkreDouble.PROCESS
APPLY = "APPLY_TAPE "

PAUSE_TREE = """<root BTCPP_format="4"><BehaviorTree ID="PAUSE_TEST"><Sequence name="pause_test">
  <Timeout name="limit" msec="600"><SendLocemCommand name="wait_cmd" command="WAIT 0.3" timeout="0.5"/></Timeout>
  <Sleep name="nap" msec="300"/>
  <SetBlackboard output_key="task_detail" value="in time"/>
</Sequence></BehaviorTree></root>"""


def wait_for(cond, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.005)
    return False


class Rig:
    """A whole HICEM (real trees, HDICT file) over the doubles, recording state and transitions."""

    def __init__(self, tmp_path, durations=None, trees=(), extra_actions=(), after_failure="continue",
                 hdict_name="hdict.sqlite", pemkre=None, locem=None):
        lib = TreeLibrary(params().node_registry())
        lib.load_directory(TREES)
        for i, xml in enumerate(trees):
            lib.load_string(xml, "extra%d.xml" % i)
        self.locem = locem or LocemDouble(durations=durations)
        self.pemkre = pemkre or PemkreDouble(extra_actions=list(extra_actions), after_failure=after_failure,
                                             validate_lines=False)
        self.ex = create_executive(self.pemkre, self.locem, str(tmp_path / hdict_name), params=params(),
                                   library=lib)
        self.ctrl = self.ex.controller
        self.transitions = []
        self.ctrl.add_transition_listener(self.transitions.append)
        self.ex.operator.add_listener(AutoOperator(self.ctrl, {"mount_tool": "done", "validate_line": "valid",
                                                               "manual_taping": "done",
                                                               "finish_interrupted": "done"}))
        self.ex.health.heartbeat("locem")
        self.beats = Heartbeats(self.ex.health)

    def close(self):
        self.beats.stop()
        self.ex.close()

    def of(self, task):
        return [(t.name, t.method) for t in self.transitions if t.instance == task]

    def running(self, prefix):
        return [h for h in self.locem.running() if h.command.startswith(prefix)]

    def action(self):
        return self.ex.store.value(HHLC, "action")


@pytest.fixture
def rig(tmp_path):
    r = Rig(tmp_path, durations={"APPLY_TAPE": 0.6})
    yield r
    r.close()


def test_pausable_clock_stands_still_while_frozen():
    now = [100.0]
    c = PausableClock(lambda: now[0])
    assert c() == 100.0
    c.freeze()
    now[0] = 110.0
    assert c() == 100.0 and c.frozen
    c.freeze()                                       # idempotent
    now[0] = 112.0
    c.unfreeze()
    assert c() == 100.0 and not c.frozen and c.frozen_s == 12.0
    now[0] = 113.5
    assert c() == 101.5
    assert [m.value for m in operator_methods(ProgramState.RUNNING)] == ["Suspend", "Halt"]
    assert [m.value for m in operator_methods(ProgramState.SUSPENDED)] == ["Resume", "Halt"]
    assert [m.value for m in operator_methods(ProgramState.HALTED)] == ["Reset"]
    assert operator_methods(ProgramState.READY) == [] and operator_methods(None) == []


def test_suspend_mid_tape_line_keeps_the_tree_and_resume_sends_nothing_again(rig):
    rig.ctrl.start_process(P)
    assert wait_for(lambda: rig.running(APPLY))
    assert wait_for(lambda: rig.ctrl.state()["node"] == "locem_command")
    (handle,) = rig.running(APPLY)
    before = rig.ctrl.state()
    task = before["task"]
    assert (before["skill_state"], before["allowed"]) == ("Running", ["Suspend", "Halt"])

    assert rig.ctrl.suspend_action("someone walked into the bay") == ProgramState.SUSPENDED
    st = rig.ctrl.state()
    assert (st["skill_state"], st["allowed"], st["phase"]) == ("Suspended", ["Resume", "Halt"], "suspended")
    assert st["skill_detail"] == "someone walked into the bay"
    assert rig.locem.sent[-1] == "SUSPEND %s cause=someone walked into the bay" % handle.command
    rec = rig.action()
    assert rec["phase"] == "suspended" and rec["suspend_cause"] == "someone walked into the bay"
    assert abs(rec["suspended_at"] - time.time()) < 5
    sent = len(rig.locem.sent)
    time.sleep(0.9)                                   # longer than the whole APPLY_TAPE: it must not end
    assert not handle.done() and len(rig.locem.sent) == sent   # nothing sent while suspended
    assert rig.ctrl.state()["path"] == before["path"]            # the tree stands where it stood

    assert rig.ctrl.resume_action("bay clear") == ProgramState.RUNNING
    assert rig.locem.sent[sent] == "RESUME %s cause=bay clear" % handle.command
    assert rig.action()["phase"] == "running" and "suspended_at" not in rig.action()
    st = rig.ctrl.state()
    assert (st["skill_state"], st["allowed"], st["phase"]) == ("Running", ["Suspend", "Halt"], "running")
    assert rig.ctrl.join(20) and rig.ctrl.state()["phase"] == "ended"
    # that joint's tape was applied once, by the same command, which the same node saw to its end
    applies = [c for c in rig.locem.sent if c.startswith(APPLY)]
    # three joints, the 2 m horizontal one in two pieces (1.2 m at most from one pose); no piece taped twice
    assert applies.count(handle.command) == 1 and len(applies) == 4 and len(set(applies)) == 4
    tapes = rig.pemkre.executed("TAPE_LINE")
    assert [t[2] for t in tapes] == ["succeeded"] * 3
    assert rig.of(task) == [("ReadyToRunning", "Start"), ("RunningToSuspended", "Suspend"),
                            ("SuspendedToRunning", "Resume"), ("RunningToReady", "")]
    assert rig.ctrl.state()["skill_state"] == "Ready" and rig.ctrl.state()["allowed"] == []
    assert [t.number for t in rig.transitions if t.instance == task] == [2, 5, 6, 4]


def test_timeouts_and_sleeps_do_not_run_out_while_suspended(tmp_path):
    r = Rig(tmp_path, durations={"WAIT": 0.3}, trees=[PAUSE_TREE], extra_actions=["PAUSE_TEST"])
    try:
        r.ctrl.start_process(P)
        assert wait_for(lambda: r.running("WAIT 0.3"))
        time.sleep(0.1)
        assert r.ctrl.suspend_action("hose kinked") == ProgramState.SUSPENDED
        time.sleep(0.8)          # more than the 600 ms Timeout and the 0.5 s command deadline
        assert r.ctrl.state()["node"] == "wait_cmd"
        r.ctrl.resume_action("hose fixed")
        assert wait_for(lambda: r.ctrl.state()["node"] == "nap", 5)
        assert r.ctrl.suspend_action("again") == ProgramState.SUSPENDED
        t_suspended = time.monotonic()
        time.sleep(0.5)          # more than the 300 ms Sleep
        assert r.ctrl.state()["node"] == "nap" and r.ctrl.state()["skill_state"] == "Suspended"
        r.ctrl.resume_action("")
        assert r.ctrl.join(20) and r.ctrl.state()["phase"] == "ended", r.ctrl.state()
        (pause,) = r.pemkre.executed("PAUSE_TEST")
        assert pause[2:4] == ["succeeded", "in time"]
        assert time.monotonic() - t_suspended > 0.5
        assert [c for c in r.locem.sent if "WAIT" in c] == ["WAIT 0.3", "SUSPEND WAIT 0.3 cause=hose kinked",
                                                            "RESUME WAIT 0.3 cause=hose fixed"]
        causes = [t.cause for t in r.transitions if t.instance == pause[1]]
        assert causes[1:] == ["hose kinked", "hose fixed", "again", "resume requested", "succeeded: in time"]
    finally:
        r.close()


def test_a_command_that_cannot_be_suspended_delays_the_suspension_until_it_ends(tmp_path):
    r = Rig(tmp_path, durations={"MOUNT_TOOL": 0.5, "APPLY_TAPE": 0.05})
    try:
        r.ctrl.start_process(P)
        assert wait_for(lambda: r.running("MOUNT_TOOL"))
        (mount,) = r.running("MOUNT_TOOL")
        assert r.ctrl.suspend_action("operator") == ProgramState.RUNNING
        st = r.ctrl.state()
        assert (st["skill_state"], st["allowed"], st["phase"]) == ("Running", ["Halt"], "suspending")
        assert "MOUNT_TOOL cannot be suspended" in st["skill_detail"]
        assert r.ctrl.suspend_action("operator") == ProgramState.RUNNING       # asked again: the same
        with pytest.raises(SkillMethodRefused) as ei:
            r.ctrl.resume_action("changed my mind")
        assert "waits for MOUNT_TOOL" in str(ei.value) and ei.value.allowed == ["Halt"]
        assert r.action()["phase"] == "suspended"        # a crash now comes back Suspended
        assert wait_for(lambda: r.ctrl.state()["skill_state"] == "Suspended", 3)
        assert mount.done() and mount.reply().success
        tr = r.transitions[-1]
        assert (tr.name, tr.method) == ("RunningToSuspended", "Suspend")
        assert tr.cause == "operator; suspended when MOUNT_TOOL ended (it cannot be suspended)"
        sent = len(r.locem.sent)
        time.sleep(0.3)
        assert len(r.locem.sent) == sent and r.locem.sent[-1] == "MOUNT_TOOL taping_tool"   # nothing new sent
        r.ctrl.resume_action("go on")
        assert r.ctrl.join(20) and r.ctrl.state()["phase"] == "ended"
        assert r.pemkre.executed("GET_TOOL")[0][2] == "succeeded"
        assert r.locem.sent.count("MOUNT_TOOL taping_tool") == 1
    finally:
        r.close()


def test_refused_methods_change_nothing(rig):
    def refused(method, *texts):
        before_state, before_sent, before_tr = rig.ctrl.state(), list(rig.locem.sent), len(rig.transitions)
        before_rec = rig.action()
        with pytest.raises(SkillMethodRefused) as ei:
            rig.ctrl.skill_method(method, "test")
        for t in texts:
            assert t in str(ei.value), str(ei.value)
        assert isinstance(ei.value, ControllerError)
        assert rig.ctrl.state()["skill_state"] == before_state["skill_state"]
        assert rig.ctrl.state()["allowed"] == before_state["allowed"]
        assert rig.locem.sent == before_sent and len(rig.transitions) == before_tr and rig.action() == before_rec
        return ei.value

    err = refused("suspend", "Suspend is not allowed: no HICEM action is running", "allowed now: none")
    assert (err.method, err.state, err.allowed) == ("Suspend", "", [])
    refused("Resume", "no HICEM action is running")
    refused("HALT", "no HICEM action is running")
    refused("reset", "Reset is not allowed: no HICEM action is Halted")
    refused("start", "HICEM starts each action PEMKRE names")
    refused("pause", "unknown skill method 'pause'")
    rig.ctrl.start_process(P)
    assert wait_for(lambda: rig.running(APPLY))
    err = refused("resume", "Resume is not allowed: ", " is Running (allowed in Running: Suspend, Halt)")
    assert (err.state, err.allowed) == ("Running", ["Suspend", "Halt"])
    refused("reset", "Reset is not allowed")
    assert rig.ctrl.suspend_action() == ProgramState.SUSPENDED
    refused("suspend", "is Suspended (allowed in Suspended: Resume, Halt)")
    refused("reset", "is Suspended")
    assert rig.ctrl.resume_action() == ProgramState.RUNNING
    assert rig.ctrl.join(20) and rig.ctrl.state()["phase"] == "ended"
    refused("halt", "no HICEM action is running", "is Ready")
    assert [t[2] for t in rig.pemkre.executed("TAPE_LINE")] == ["succeeded"] * 3


def test_halt_fails_the_task_halted_and_the_process_goes_on_then_reset(rig):
    rig.ctrl.start_process(P)
    assert wait_for(lambda: rig.running(APPLY))
    (handle,) = rig.running(APPLY)
    task = rig.ctrl.state()["task"]
    assert rig.ctrl.halt_action("operator pressed Abort") == ProgramState.HALTED
    assert wait_for(lambda: handle.cancelled, 2)          # the tree was halted: its command cancelled
    assert wait_for(lambda: rig.pemkre.executed("TAPE_LINE"), 5)
    first = rig.pemkre.executed("TAPE_LINE")[0]
    assert first[1] == task and first[2:4] == ["failed", "halted: operator pressed Abort"]
    # the process goes on with PEMKRE's next action (this double's failure branch: the next joint)
    assert rig.ctrl.join(20) and rig.ctrl.state()["phase"] == "ended"
    assert [t[2] for t in rig.pemkre.executed("TAPE_LINE")] == ["failed", "succeeded", "succeeded"]
    assert rig.of(task) == [("ReadyToRunning", "Start"), ("RunningToHalted", "Halt")]
    assert rig.locem.running() == []
    # the halted instance is the one Reset applies to, also after later actions
    st = rig.ctrl.state()
    assert (st["skill_state"], st["allowed"]) == ("Ready", ["Reset"])
    assert rig.ctrl.reset_action("checked") == ProgramState.READY
    assert rig.of(task)[-1] == ("HaltedToReady", "Reset") and rig.transitions[-1].number == 1
    assert rig.ctrl.state()["allowed"] == []
    with pytest.raises(SkillMethodRefused):
        rig.ctrl.reset_action()


def test_halt_while_suspended_and_stop_while_suspended(tmp_path):
    r = Rig(tmp_path, durations={"APPLY_TAPE": 0.6})
    try:
        r.ctrl.start_process(P)
        assert wait_for(lambda: r.running(APPLY))
        (handle,) = r.running(APPLY)
        task = r.ctrl.state()["task"]
        r.ctrl.suspend_action("look")
        assert r.ctrl.halt_action("abort it") == ProgramState.HALTED
        assert wait_for(lambda: handle.cancelled, 2)
        assert r.of(task)[-1] == ("SuspendedToHalted", "Halt")
        assert wait_for(lambda: r.pemkre.executed("TAPE_LINE"), 5)
        assert r.pemkre.executed("TAPE_LINE")[0][2:4] == ["failed", "halted: abort it"]
        # the next joint: suspended, then the process is stopped
        assert wait_for(lambda: len([h for h in r.locem.handles if h.command.startswith(APPLY)]) == 2, 10)
        assert wait_for(lambda: r.ctrl.state()["skill_state"] == "Running", 5)
        task2 = r.ctrl.state()["task"]
        r.ctrl.suspend_action("look again")
        r.ctrl.stop("operator pressed STOP")
        assert r.ctrl.join(10) and r.ctrl.state()["phase"] == "stopped"
        assert r.of(task2)[-1] == ("SuspendedToHalted", "") and \
            r.transitions[-1].cause == "stopped: operator pressed STOP"
        assert r.pemkre.executed("TAPE_LINE")[-1][2:4] == ["failed", "stopped: operator pressed STOP"]
        assert r.locem.running() == [] and r.locem.sent[-1] == "STOP"
    finally:
        r.close()


# ------------------------------------------------------------------------------ a restart while suspended --
def _suspended_crash(tmp_path, action_type, params_, cause="operator"):
    """PEMKRE and the HDICT as a HICEM that died while ``action_type`` was suspended leaves them."""
    pem = PemkreDouble(after_failure="continue", state_path=str(tmp_path / "pemkre.json"))
    first = Rig(tmp_path, pemkre=pem)
    pem.start_process(P)
    first.ex.data_handler.ingest_scan(SITE)
    pem.s["pending"] = [[action_type, params_]]
    na = pem.next_action()
    pem.set_task_status(na["task"], "in_progress")
    pem.s["home_done"] = True
    pem._save()
    first.ex.store.put(HHLC, "process", {"iri": P, "specific": "x", "state": "running"})
    first.ex.store.put(HHLC, "action", {"task": na["task"], "action_type": action_type, "parameters": params_,
                                        "raw_parameters": "", "skill": "", "skill_kind": "", "phase": "suspended",
                                        "suspended_at": time.time() - 3, "suspend_cause": cause})
    first.close()
    return na["task"]


def _restarted(tmp_path, durations=None):
    pem = PemkreDouble(after_failure="continue", state_path=str(tmp_path / "pemkre.json"))
    return Rig(tmp_path, pemkre=pem, durations=durations)


def test_a_restart_while_suspended_comes_back_suspended_then_resume_follows_the_resume_policy(tmp_path):
    task = _suspended_crash(tmp_path, "VALIDATE_TAPE_LINE", {"line": "wall_1_joint_1"}, "hose kinked")
    r = _restarted(tmp_path)
    try:
        assert r.ctrl.resume_in_background()
        assert wait_for(lambda: r.ctrl.state()["skill_state"] == "Suspended", 5)
        st = r.ctrl.state()
        assert (st["phase"], st["allowed"], st["task"]) == ("suspended", ["Resume", "Halt"], task)
        (tr,) = r.transitions
        assert (tr.instance, tr.name, tr.method) == (task, "RunningToSuspended", "Suspend")
        assert tr.cause.startswith("restored after a HICEM restart: the action was suspended at ")
        assert "(hose kinked); no device command sent" in tr.cause
        time.sleep(0.3)
        assert r.locem.sent == []                        # no device command, not even the safe STOP
        assert r.action()["phase"] == "suspended"
        assert r.ctrl.resume_action("bay clear") == ProgramState.RUNNING
        assert r.ctrl.join(20) and r.ctrl.state()["phase"] == "ended", r.ctrl.state()
        assert r.locem.sent[0] == "STOP"                 # then as after any restart: safe commands first,
        first = r.pemkre.executed()[0]                   # VALIDATE_TAPE_LINE's policy: rerun
        assert first[:3] == ["VALIDATE_TAPE_LINE", task, "succeeded"]
        assert [(n, m) for n, m in r.of(task)] == [("RunningToSuspended", "Suspend"),
                                                   ("SuspendedToRunning", "Resume"), ("RunningToReady", "")]
    finally:
        r.close()


def test_a_restart_while_suspended_then_halt_reports_halted(tmp_path):
    task = _suspended_crash(tmp_path, "TAPE_LINE", {"line": "wall_1_joint_1"})
    r = _restarted(tmp_path)
    try:
        assert r.ctrl.resume_in_background()
        assert wait_for(lambda: r.ctrl.state()["skill_state"] == "Suspended", 5)
        assert r.ctrl.halt_action("abandon the joint") == ProgramState.HALTED
        assert r.ctrl.join(20) and r.ctrl.state()["phase"] == "ended"
        first = r.pemkre.executed()[0]
        assert first[:4] == ["TAPE_LINE", task, "failed", "halted: abandon the joint"]
        assert r.locem.sent == ["STOP"]                  # the devices made safe; nothing applied
        assert r.of(task)[-1] == ("SuspendedToHalted", "Halt")
        assert r.ctrl.reset_action() == ProgramState.READY
    finally:
        r.close()


def test_a_restart_while_suspended_then_resume_with_policy_fail(tmp_path):
    # SPRAY_AREA's policy is fail: PEMKRE's failure branch (RECOVER, then the area from its recorded progress)
    task = _suspended_crash(tmp_path, "SPRAY_AREA", {"area": "wall_1_area_1"})
    r = _restarted(tmp_path)
    try:
        assert r.ctrl.resume_in_background()
        assert wait_for(lambda: r.ctrl.state()["skill_state"] == "Suspended", 5)
        r.ctrl.resume_action("go on")
        assert r.ctrl.join(20)
        first = r.pemkre.executed()[0]
        assert first[:3] == ["SPRAY_AREA", task, "failed"] and first[3].startswith("interrupted")
        assert not any(c.startswith("SPRAY_AREA") for c in r.locem.sent)
        assert r.of(task)[-1][0] == "RunningToHalted" and r.ctrl.state()["allowed"] == ["Reset"]
    finally:
        r.close()


def test_kill_9_while_suspended_comes_back_suspended(tmp_path):
    """The real thing: a HICEM process suspended mid-TAPE_LINE is killed; the next one comes back Suspended."""
    import os
    import signal
    import subprocess
    import sys
    child = os.path.join(os.path.dirname(os.path.abspath(__file__)), "hicem_crash_child.py")
    log = tmp_path / "locem.log"
    proc = subprocess.Popen([sys.executable, child, "suspend", str(tmp_path)])
    try:
        assert wait_for(lambda: log.exists() and "## suspended" in log.read_text(), 60), \
            log.read_text() if log.exists() else "no log"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=10)
    lines = log.read_text().splitlines()
    suspended_cmd = next(line for line in lines if line.startswith("SUSPEND APPLY_TAPE"))
    pem = PemkreDouble(state_path=str(tmp_path / "pemkre.json"))
    loc = LocemDouble(durations={"APPLY_TAPE": 0.05}, log_path=str(log))
    r = Rig(tmp_path, pemkre=pem, locem=loc)
    try:
        assert r.ctrl.resume_in_background()
        assert wait_for(lambda: r.ctrl.state()["skill_state"] == "Suspended", 5)
        assert r.ctrl.state()["tree"] == "" and "restored after a HICEM restart" in r.transitions[0].cause
        time.sleep(0.2)
        assert loc.sent == []
        r.ctrl.resume_action("operator")
        assert r.ctrl.join(30) and r.ctrl.state()["phase"] == "ended", r.ctrl.state()
        assert loc.sent[0] == "STOP"
        tapes = [(s[4]["line"], s[2]) for s in pem.executed("TAPE_LINE")]
        # the suspended joint is finished by hand (TAPE_LINE's resume policy), none taped twice
        assert tapes == [("wall_1_joint_1", "succeeded"), ("wall_1_joint_2", "succeeded"),
                         ("wall_2_joint_1", "succeeded")]
        applies = [line for line in log.read_text().splitlines() if line.startswith(APPLY)]
        assert len(applies) == 4 and len(set(applies)) == 4 and suspended_cmd.startswith("SUSPEND " + applies[1])
    finally:
        r.close()
