"""The taping process (Fig. 2 of the PEMKRE paper), one test per branch, on a real on-disk store."""
from pemkre_testkit import json_dumps, run_process, scan_result
from rdflib import Namespace

from locem_bridge.pemkre import PLB, PPR
from locem_bridge.pemkre.vocab import BASE, SITE

TAPING = str(PLB.TapingProcess)


def _status(engine, fid):
    return engine.store.value(SITE[fid], PPR.tapingStatus)


def _scan_with(scan):
    def decide(a):
        if a.action_type == "SCAN":
            return "succeeded", json_dumps(scan)
        if a.action_type == "VALIDATE_TAPE_LINE":
            return "succeeded", "valid"
        return "succeeded", ""
    return decide


def test_nothing_at_all_goes_home_and_ends_early(make_engine):
    e = make_engine()
    e.start_process(TAPING)
    seen = run_process(e, _scan_with({"stamp": 1.0, "walls": [], "joints": [], "areas": []}))
    assert [s[0] for s in seen] == ["SCAN", "GO_HOME", "ENDED"]
    assert seen[1][1] == {"robot": "robot", "location": "home"}
    assert seen[-1][1]["message"] == "nothing_to_do"
    assert e.check_consistency(full_inference=True) == []


def test_unprocessed_lines_left_skip_the_scan(make_engine):
    e = make_engine()
    e.update_world(scan_result(joints_per_wall=2))
    e.start_process(TAPING, {"validateLines": False})
    first = e.next_action()
    assert first.action_type == "GET_TOOL"
    assert first.params() == {"tool": "taping_tool", "robot": "robot"}


def test_validate_lines_false_tapes_straight_away_then_goes_home(make_engine):
    e = make_engine()
    e.start_process(TAPING, {"validateLines": False})
    seen = run_process(e, _scan_with(scan_result(joints_per_wall=3)))
    assert seen == [("SCAN", {}), ("GET_TOOL", {"tool": "taping_tool", "robot": "robot"}),
                    ("TAPE_LINE", {"line": "wall_1_joint_1"}), ("TAPE_LINE", {"line": "wall_1_joint_2"}),
                    ("TAPE_LINE", {"line": "wall_1_joint_3"}), ("GO_HOME", {"robot": "robot", "location": "home"}),
                    ("ENDED", {"message": "completed"})]
    for j in (1, 2, 3):
        assert _status(e, "wall_1_joint_%d" % j) == PPR.processed
    # the robot's world state follows the effects of GET_TOOL and GO_HOME
    robot = Namespace(BASE + "robot/rbkairos_ur10e/")          # the default robot (ontologies/default_robot.ttl)
    assert e.store.value(robot.robot, PPR.mountedTool) == robot.taping_tool
    assert e.store.value(robot.robot, PPR.atLocation) == SITE.home
    assert e.check_consistency(full_inference=True) == []


def test_operator_valid_tapes_and_invalid_pauses_for_manual_taping(make_engine):
    e = make_engine()
    e.update_world(scan_result(joints_per_wall=2))
    e.start_process(TAPING)  # validateLines defaults to true

    def decide(a):
        if a.action_type == "VALIDATE_TAPE_LINE":
            return "succeeded", "invalid" if a.params()["line"] == "wall_1_joint_1" else "valid"
        return "succeeded", ""
    seen = run_process(e, decide)
    assert [s[0] for s in seen] == ["GET_TOOL", "VALIDATE_TAPE_LINE", "MANUAL_TAPING", "VALIDATE_TAPE_LINE",
                                    "TAPE_LINE", "GO_HOME", "ENDED"]
    assert seen[1][1] == seen[2][1] == {"line": "wall_1_joint_1"}
    assert seen[3][1] == seen[4][1] == {"line": "wall_1_joint_2"}
    assert _status(e, "wall_1_joint_1") == PPR.processedManually
    assert _status(e, "wall_1_joint_2") == PPR.processed
    assert e.check_consistency(full_inference=True) == []


def test_all_lines_done_goes_home_and_a_new_run_finds_nothing(make_engine):
    e = make_engine()
    scan = scan_result(joints_per_wall=1)
    e.start_process(TAPING, {"validateLines": False})
    assert [s[0] for s in run_process(e, _scan_with(scan))][-2:] == ["GO_HOME", "ENDED"]
    # everything is taped: a second run scans (nothing pending), the same features come back taped -> home, early
    e.start_process(TAPING, {"validateLines": False})
    seen = run_process(e, _scan_with(scan))
    assert [s[0] for s in seen] == ["SCAN", "GO_HOME", "ENDED"]
    assert seen[-1][1]["message"] == "nothing_to_do"
    assert _status(e, "wall_1_joint_1") == PPR.processed


def test_asking_twice_returns_the_same_task_and_a_failure_fails_the_process(make_engine):
    e = make_engine()
    e.update_world(scan_result(joints_per_wall=1))
    e.start_process(TAPING, {"validateLines": "false"})
    a1 = e.next_action()
    a2 = e.next_action()
    assert (a1.task, a1.action_type, a1.parameters) == (a2.task, a2.action_type, a2.parameters)
    e.set_task_status(a1.task, "in_progress")
    assert e.next_action().task_status == "in_progress"
    e.set_task_status(a1.task, "failed", "tool changer jammed")
    end = e.next_action()
    assert end.status == "failed" and "tool changer jammed" in end.message and "GET_TOOL" in end.message
    assert e.active_process() is None and e.current_process() == end.process
    assert e.check_consistency() == []


def test_parameters_are_ntriples_about_the_task(make_engine):
    e = make_engine()
    e.update_world(scan_result(joints_per_wall=1))
    e.start_process(TAPING)
    a = e.next_action()
    e.set_task_status(a.task, "succeeded")
    v = e.next_action()
    assert v.action_type == "VALIDATE_TAPE_LINE"
    lines = [ln for ln in v.parameters.splitlines() if ln]
    assert lines == ["<%s> <%s> <%s> ." % (v.task, PLB.line, SITE.wall_1_joint_1)]
