"""HHLC loop against the PEMKRE and LOCEM test doubles: whole processes, stop, bad input, resume branches."""
import time

import pytest

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble, PemkreDouble
from hicem_rig import TREES, System, params
from locem_bridge.hicem.controller import HHLC
from locem_bridge.hicem.errors import ControllerError, OperatorError
from locem_bridge.hicem.executive import create_executive
from locem_bridge.hicem.interfaces import LocemReply
from locem_bridge.hicem.xml_loader import TreeLibrary

P = PemkreDouble.PROCESS


def wait_for(cond, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.005)
    return False


@pytest.fixture
def system(tmp_path):
    s = System(tmp_path)
    yield s
    s.close()


def test_taping_process_runs_to_the_end_with_numbers_from_the_scan(system):
    assert system.ctrl.run_process(P) == "ended"
    # the test site's vertical joints run 0..2.5 m, the taping band is 0.10..2.00 m: their ends are planned manual
    # work, named in the detail after "taped"
    done = [(a, st, d.split(";")[0]) for a, _t, st, d, _p in system.pemkre.executed()]
    assert done == [("SCAN", "succeeded", ""), ("GET_TOOL", "succeeded", "taping_tool")] + [
        ("VALIDATE_TAPE_LINE", "succeeded", "valid"), ("TAPE_LINE", "succeeded", "taped")] * 3 + [
        ("GO_HOME", "succeeded", "")]
    sent = system.locem.sent
    assert sent[:6] == ["SCAN", "WALL_READY", "GET_POSE", "GOTO 1.4 1.4 0.7854", "HOME", "MOUNT_TOOL taping_tool"]
    assert "GOTO 1.2 1.95 1.570796" in sent  # 1.05 m in front of wall_1_joint_1, facing the wall
    assert "APPLY_TAPE 1.2 3 0.1 1.2 3 2 0 -1 0 speed=0.15" in sent     # clipped to the taping band
    # home is reached by driving out keeping the heading and turning there, not next to the last wall
    assert sent[-5:] == ["WALL_READY", "GET_POSE", "GOTO 1.4 1.4 0", "GOTO 1.4 1.4 0.7854", "HOME"]
    assert system.locem.running() == []
    assert system.operator.asked == ["mount_tool"] + ["validate_line"] * 3
    # features and their status are in the HDICT; in_progress was always reported before the outcome
    assert system.ex.data_handler.feature("wall_1_joint_2")["status"] == "taped"
    statuses = [c for c in system.pemkre.calls if c[0] == "set_task_status"]
    assert [c[2] for c in statuses[:2]] == ["in_progress", "succeeded"]
    phases = {s["phase"] for s in system.states}
    assert {"asking", "starting", "running", "reporting", "ended"} <= phases
    assert any(s["tree"] == "TAPE_LINE" and s["node"] == "tape_line" for s in system.states)


def test_tool_already_mounted_is_not_asked_again(system):
    system.ex.store.put("robot", "tool", "taping_tool")
    assert system.ctrl.run_process(P) == "ended"
    assert "mount_tool" not in system.operator.asked and "MOUNT_TOOL taping_tool" not in system.locem.sent


def test_operator_rejects_a_line_and_it_goes_to_manual_taping(tmp_path):
    s = System(tmp_path, reject=["wall_1_joint_2"])
    try:
        assert s.ctrl.run_process(P) == "ended"
        manual = s.pemkre.executed("MANUAL_TAPING")
        assert [m[4]["line"] for m in manual] == ["wall_1_joint_2"] and manual[0][3] == "manual"
        assert not any(c.startswith("APPLY_TAPE 2.4") for c in s.locem.sent)
        assert s.ex.data_handler.feature("wall_1_joint_2")["status"] == "manual"
    finally:
        s.close()


def test_stop_halts_cleanly_mid_action(tmp_path):
    s = System(tmp_path, durations={"APPLY_TAPE": 30.0})
    try:
        s.pemkre.validate_lines = False
        s.ctrl.start_process(P)
        assert wait_for(lambda: any(h.command.startswith("APPLY_TAPE") for h in s.locem.running()))
        assert wait_for(lambda: s.ctrl.state()["node"] == "locem_command")
        st = s.ctrl.state()
        assert (st["tree"], st["action_type"], st["phase"]) == ("TAPE_LINE", "TAPE_LINE", "running")
        assert st["path"] == ("tape_line/one_pose_or_height_bands/planned_pieces/each_piece/tape_piece/apply_tape/"
                              "guarded_command/locem_command")
        with pytest.raises(ControllerError):
            s.ctrl.start_process(P)  # one process at a time
        s.ctrl.stop("operator pressed STOP")
        assert s.ctrl.join(5)
        assert s.ctrl.state()["phase"] == "stopped"
        assert s.locem.running() == []
        assert "CANCEL APPLY_TAPE" in " ".join(s.locem.sent) and s.locem.sent[-1] == "STOP"
        last = s.pemkre.executed()[-1]
        assert last[0] == "TAPE_LINE" and last[2] == "failed" and last[3] == "stopped: operator pressed STOP"
        assert s.ex.store.value(HHLC, "process")["state"] == "stopped"
    finally:
        s.close()


def test_stop_while_waiting_for_operator_withdraws_prompt(tmp_path):
    s = System(tmp_path)
    try:
        s.operator.answers["mount_tool"] = None  # nobody answers
        s.ex.operator._listeners.clear()
        s.ctrl.start_process(P)
        assert wait_for(lambda: len(s.ex.operator.open_prompts()) == 1)
        (p,) = s.ex.operator.open_prompts()
        assert p.kind == "mount_tool" and "taping_tool" in p.text
        with pytest.raises(OperatorError) as ei:
            s.ctrl.operator_reply(p.id, "maybe")
        assert "allowed: done" in str(ei.value)
        s.ctrl.stop()
        assert s.ctrl.join(5)
        assert s.ex.operator.open_prompts() == []
        with pytest.raises(OperatorError) as ei:
            s.ctrl.operator_reply(p.id, "done")
        assert "already cancelled" in str(ei.value) and "open prompts: none" in str(ei.value)
    finally:
        s.close()


def test_reply_to_unknown_prompt_is_a_clear_error(system):
    with pytest.raises(OperatorError) as ei:
        system.ctrl.operator_reply("nope", "done")
    assert "prompt 'nope' is not known; open prompts: none" in str(ei.value)


def test_action_type_without_tree_fails_process_and_tells_pemkre(tmp_path):
    s = System(tmp_path, pemkre=PemkreDouble(extra_actions=["PAINT_CEILING"]))
    try:
        assert s.ctrl.run_process(P) == "failed"
        last = s.pemkre.executed()[-1]
        assert last[0] == "PAINT_CEILING" and last[2] == "failed"
        assert "no behavior tree for action type 'PAINT_CEILING'" in last[3] and "TAPE_LINE" in last[3]
        assert "no behavior tree" in s.ctrl.state()["detail"] and s.locem.running() == []
    finally:
        s.close()


def test_unexpected_locem_code_fails_the_action_and_pemkre_fails_the_taping_process(tmp_path):
    # after_failure="fail_process": what the real taping process does with a failed TAPE_LINE
    s = System(tmp_path, pemkre=PemkreDouble(after_failure="fail_process"))
    try:
        s.locem.fail_next["APPLY_TAPE"] = LocemReply(False, "WEIRD_CODE", "firmware says no")
        assert s.ctrl.run_process(P) == "failed"
        (tape,) = s.pemkre.executed("TAPE_LINE")
        assert tape[2] == "failed" and "unexpected code 'WEIRD_CODE'" in tape[3]
        st = s.ctrl.state()
        assert "(TAPE_LINE) failed" in st["detail"] and "WEIRD_CODE" in st["detail"]
        assert len([c for c in s.locem.sent if c.startswith("APPLY_TAPE ")]) == 1  # no other joint taped
        assert s.locem.running() == []
    finally:
        s.close()


def test_unexpected_locem_code_fails_the_action_and_a_process_that_goes_on_continues(tmp_path):
    # after_failure="continue": a process model with a failure transition (as spraying's) asks for more work;
    # HICEM must then run the next actions normally
    s = System(tmp_path, pemkre=PemkreDouble(after_failure="continue"))
    try:
        s.locem.fail_next["APPLY_TAPE"] = LocemReply(False, "WEIRD_CODE", "firmware says no")
        assert s.ctrl.run_process(P) == "ended"
        tapes = s.pemkre.executed("TAPE_LINE")
        assert tapes[0][2] == "failed" and "unexpected code 'WEIRD_CODE'" in tapes[0][3]
        assert [t[2] for t in tapes[1:]] == ["succeeded", "succeeded"]
        assert s.locem.running() == []
    finally:
        s.close()


class BrokenPemkre(PemkreDouble):
    def __init__(self, answer):
        super().__init__()
        self.answer = answer

    def next_action(self):
        return self.answer


@pytest.mark.parametrize("answer,msg", [
    ({"status": "maybe"}, "status 'maybe' is not one of: action, ended, failed"),
    ({"status": "action", "task": "http://x#t"}, "'action_type' missing"),
    ({"status": "action", "action_type": "SCAN", "task": "http://x#t", "parameters": "garbage"},
     "not an N-Triples triple"),
    ({"status": "action", "action_type": "SCAN", "task": "http://x#t",
      "parameters": "<http://x#other> <http://x#line> <http://x#l1> ."}, "is not the task"),
])
def test_malformed_pemkre_answer_fails_the_process_with_reason(tmp_path, answer, msg):
    s = System(tmp_path, pemkre=BrokenPemkre(answer))
    try:
        assert s.ctrl.run_process(P) == "failed"
        assert msg in s.ctrl.state()["detail"]
    finally:
        s.close()


def test_unknown_process_iri(system):
    assert system.ctrl.run_process("http://example.org/proc#Nope") == "failed"
    assert "unknown process IRI" in system.ctrl.state()["detail"]
    with pytest.raises(ControllerError):
        system.ctrl.start_process("  ")


def test_parameters_reach_the_tree_as_param_keys(system):
    from locem_bridge.hicem.interfaces import parse_next_action
    na = parse_next_action({"status": "action", "action_type": "TAPE_LINE", "task": "http://r#t1",
                            "parameters": '<http://r#t1> <http://p#line> <http://w#wall_1_joint_1> .\n'
                                          '<http://r#t1> <http://p#speed> "0.2"^^<http://www.w3.org/2001/XMLSchema#double> .\n'
                                          '<http://r#t1> <http://p#note> "a \\"quoted\\" word"@en .'})
    assert na.blackboard_entries() == {"param_line": "wall_1_joint_1", "param_speed": 0.2,
                                       "param_note": 'a "quoted" word'}


# ---------------------------------------------------------------------------------------- resume branches --
def _crashed_state(system, phase, action_type, params, outcome=None):
    """Put PEMKRE and the HDICT in the state a crash during `action_type` leaves behind."""
    pem = system.pemkre
    pem.start_process(P)
    system.ex.data_handler.ingest_scan(__import__("hicem_doubles").SITE)
    pem.s["pending"] = [[action_type, params]]
    na = pem.next_action()
    pem.set_task_status(na["task"], "in_progress")
    system.ex.store.put(HHLC, "process", {"iri": P, "specific": "x", "state": "running"})
    rec = {"task": na["task"], "action_type": action_type, "parameters": params, "raw_parameters": "",
           "phase": phase}
    if outcome:
        rec.update(outcome=outcome[0], detail=outcome[1])
    system.ex.store.put(HHLC, "action", rec)
    return na["task"]


def test_resume_reports_a_finished_but_unreported_action_without_rerunning(system):
    task = _crashed_state(system, "finished", "TAPE_LINE", {"line": "wall_1_joint_1"}, ("succeeded", "taped"))
    system.pemkre.s["pending"] = []
    system.pemkre.s["home_done"] = True
    assert system.ctrl.resume() == "ended"
    assert system.pemkre.executed()[0][1:4] == [task, "succeeded", "taped"]
    assert not any(c.startswith("APPLY_TAPE") for c in system.locem.sent)
    assert system.locem.sent[0] == "STOP"  # devices brought safe first


def test_resume_reruns_an_action_whose_policy_is_rerun(system):
    _crashed_state(system, "running", "VALIDATE_TAPE_LINE", {"line": "wall_1_joint_1"})
    system.pemkre.s["home_done"] = True
    assert system.ctrl.resume() == "ended"
    ex = system.pemkre.executed()
    assert ex[0][0] == "VALIDATE_TAPE_LINE" and ex[0][2] == "succeeded"
    assert system.locem.sent[0] == "STOP" and any(c.startswith("APPLY_TAPE_START") for c in system.locem.sent)


def test_resume_runs_the_recovery_tree_instead_of_taping_again(system):
    system.operator.answers["finish_interrupted"] = "done"
    _crashed_state(system, "running", "TAPE_LINE", {"line": "wall_1_joint_1"})
    system.pemkre.s["home_done"] = True
    assert system.ctrl.resume() == "ended"
    first = system.pemkre.executed()[0]
    assert first[0] == "TAPE_LINE" and first[2] == "succeeded"
    assert not any(c.startswith("APPLY_TAPE") for c in system.locem.sent)
    assert system.operator.asked[0] == "finish_interrupted"
    assert system.ex.data_handler.feature("wall_1_joint_1")["status"] == "manual"


def test_resume_recovery_abandoned_reports_failed(system):
    system.operator.answers["finish_interrupted"] = "abandon"
    _crashed_state(system, "running", "TAPE_LINE", {"line": "wall_1_joint_1"})
    system.pemkre.s["home_done"] = True
    system.ctrl.resume()
    first = system.pemkre.executed()[0]
    assert first[0] == "TAPE_LINE" and first[2] == "failed" and "finished_by_hand" in first[3]


def test_resume_policy_fail_does_not_repeat_the_action(tmp_path):
    # the spraying process goes on after a failed area (its failure transition to RECOVER); the double is told
    # to go on explicitly (after_failure="continue") so the test can check nothing is sprayed again after it
    system = System(tmp_path, pemkre=PemkreDouble(after_failure="continue"))
    try:
        _crashed_state(system, "running", "SPRAY_AREA", {"area": "wall_1_area_1"})
        system.pemkre.s["home_done"] = True
        assert system.ctrl.resume() == "ended"
        first = system.pemkre.executed()[0]
        assert first[0] == "SPRAY_AREA" and first[2] == "failed" and first[3].startswith("interrupted")
        assert not any(c.startswith("SPRAY_AREA") for c in system.locem.sent)
    finally:
        system.close()


def test_resume_without_interrupted_process(system):
    with pytest.raises(ControllerError):
        system.ctrl.resume()
    assert system.ctrl.resume_in_background() is False


def test_operator_answers_are_logged_in_the_data_store(system):
    assert system.ctrl.run_process(P) == "ended"
    log = system.ex.store.entries("operator_log")
    answered = [e.value for e in log if e.value["event"] == "answered"]
    assert sorted(a["kind"] for a in answered) == ["mount_tool"] + ["validate_line"] * 3
    assert all(a["answer"] in ("done", "valid") for a in answered)


def test_resume_when_pemkre_already_has_the_outcome(system):
    # crash after PEMKRE took "succeeded" but before the HDICT said "reported": the re-report is refused
    task = _crashed_state(system, "finished", "TAPE_LINE", {"line": "wall_1_joint_1"}, ("succeeded", ""))
    system.pemkre.set_task_status(task, "succeeded", "")
    system.pemkre.s["home_done"] = True
    assert system.ctrl.resume() == "ended"
    assert [e[0] for e in system.pemkre.executed()] == ["TAPE_LINE"]  # reported once, nothing repeated
    assert not any(c.startswith("APPLY_TAPE") for c in system.locem.sent)
    assert system.ex.store.value(HHLC, "action")["phase"] == "reported"


def test_a_log_node_in_an_action_tree_writes_to_the_controller_log_not_the_state(tmp_path, caplog):
    """Log lines of a running tree go to the HICEM controller's logger (the ROS node's log), filled with the
    action's blackboard (task, PEMKRE parameters, cfg); /hicem/state only names the node, never the text."""
    caplog.set_level("INFO", logger="locem_bridge.hicem.controller")
    lib = TreeLibrary()
    lib.load_directory(TREES)
    lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="NOTE"><Sequence>'
                    '<Log name="note_line" message="note for {task}: {action_type} at speed {@cfg.taping.speed}" '
                    'level="warning"/><SetBlackboard output_key="task_detail" value="noted"/>'
                    '</Sequence></BehaviorTree></root>', "note.xml")
    pemkre = PemkreDouble(extra_actions=["NOTE"])
    ex = create_executive(pemkre, LocemDouble(), str(tmp_path / "hdict.sqlite"), params=params(), library=lib)
    states = []
    ex.controller.add_state_listener(states.append)
    ex.operator.add_listener(AutoOperator(ex.controller, {"mount_tool": "done", "validate_line": "valid"}))
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    try:
        assert ex.controller.run_process(P) == "ended"
    finally:
        beats.stop()
        ex.close()
    (note,) = pemkre.executed("NOTE")
    assert note[2:4] == ["succeeded", "noted"]
    expected = "note for %s: NOTE at speed 0.15" % note[1]
    assert [(r.levelname, r.getMessage()) for r in caplog.records
            if r.name == "locem_bridge.hicem.controller" and r.getMessage().startswith("note for")] == [
        ("WARNING", expected)]
    assert not any("note for" in str(v) for s in states for v in s.values())
