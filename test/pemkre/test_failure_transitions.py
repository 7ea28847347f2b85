"""Failure transitions (proc:onTaskFailure): a failed spraying/sanding task leads to RECOVER and back to the loop
instead of failing the process; the failed task stays failed in the log and the KPIs; a node without a failure
transition fails its process as before; the state survives an engine restart; bad models are refused at load."""
import shutil

import pytest
from pemkre_testkit import quads_snapshot, run_process, scan_result
from rdflib import URIRef

from locem_bridge.pemkre import PLB, PPR, JournaledStore, ProcessEngine, compute_kpis
from locem_bridge.pemkre.errors import ProcessModelError, TaskStateError
from locem_bridge.pemkre.ontology import default_ontology_files
from locem_bridge.pemkre.vocab import SITE

SPRAY, SAND, TAPING = str(PLB.SprayingProcess), str(PLB.SandingProcess), str(PLB.TapingProcess)
LINK_DOWN = "HARDWARE_ERROR: compressor link is down (no answer for 0.60 s)"


def _fail_first(action_type, area, detail=LINK_DOWN, times=1):
    """decide(): the first ``times`` attempts of ``action_type`` on ``area`` fail with ``detail``."""
    left = {"n": times}

    def decide(a):
        if a.action_type == action_type and a.params().get("area") == area and left["n"] > 0:
            left["n"] -= 1
            return "failed", detail
        return "succeeded", ""
    return decide


def _log(e, sp):
    return [(str(r["actionType"]), str(r["status"]), str(r["detail"]) if r.get("detail") is not None else "")
            for r in e.query("task_log", {"process": URIRef(sp)}).rows]


def test_a_failed_spray_is_recovered_and_the_area_sprayed_again(make_engine):
    e = make_engine()
    e.update_world(scan_result(walls=1, areas_per_wall=2))
    sp = e.start_process(SPRAY)
    seen = run_process(e, _fail_first("SPRAY_AREA", "wall_1_area_1"))
    assert [s[0] for s in seen] == ["GET_TOOL", "SPRAY_AREA", "RECOVER", "SPRAY_AREA", "SPRAY_AREA", "GO_HOME",
                                    "ENDED"]
    assert seen[2][1] == {"robot": "robot"}                       # RECOVER gets the robot, like GO_HOME
    assert [s[1]["area"] for s in seen if s[0] == "SPRAY_AREA"] == ["wall_1_area_1", "wall_1_area_1",
                                                                      "wall_1_area_2"]
    assert seen[-1][1]["message"] == "completed"
    for a in (1, 2):
        assert e.store.value(SITE["wall_1_area_%d" % a], PPR.sprayingStatus) == PPR.processed
    # the failure is in the execution log with its reason, and counted by the KPIs
    log = _log(e, sp)
    assert log[1] == ("SPRAY_AREA", "failed", LINK_DOWN) and log[2][:2] == ("RECOVER", "succeeded")
    k = compute_kpis(e, sp)
    (proc,) = k["processes"]
    assert proc["status"] == "ended" and proc["outcome"] == "completed"
    assert proc["count"] == 6 and proc["failed"] == 1 and proc["succeeded"] == 5
    by_type = {r["actionType"]: r for r in k["task_types"]}
    assert by_type["SPRAY_AREA"]["count"] == 3 and by_type["SPRAY_AREA"]["failed"] == 1
    assert by_type["SPRAY_AREA"]["successRate"] == pytest.approx(2 / 3)
    assert by_type["RECOVER"]["count"] == 1 and by_type["RECOVER"]["succeeded"] == 1
    assert e.check_consistency(full_inference=True) == []


def test_between_the_failure_and_next_action_the_process_runs_and_the_area_stays_pending(make_engine):
    e = make_engine()
    e.update_world(scan_result(walls=1, areas_per_wall=1))
    sp = e.start_process(SPRAY)
    a = e.next_action()
    e.set_task_status(a.task, "succeeded")                           # GET_TOOL
    a = e.next_action()
    assert a.action_type == "SPRAY_AREA"
    e.set_task_status(a.task, "in_progress")
    e.set_task_status(a.task, "failed", LINK_DOWN)
    assert e.active_process() == sp                                  # not failed
    assert e.store.value(SITE.wall_1_area_1, PPR.sprayingStatus) == PPR.unprocessed
    with pytest.raises(TaskStateError):                              # a failed task takes no more statuses
        e.set_task_status(a.task, "succeeded")
    r = e.next_action()
    assert r.action_type == "RECOVER" and r.task_status == "issued" and r.task != a.task
    assert e.next_action().task == r.task                            # asked again: the same task
    e.set_task_status(r.task, "succeeded", "recovered")
    again = e.next_action()
    assert again.action_type == "SPRAY_AREA" and again.params() == {"area": "wall_1_area_1"}
    assert e.check_consistency(full_inference=True) == []


def test_the_failure_transition_is_never_taken_when_the_task_succeeds(make_engine):
    e = make_engine()
    e.update_world(scan_result(walls=2, areas_per_wall=2))
    e.start_process(SPRAY)
    seen = run_process(e)
    assert "RECOVER" not in [s[0] for s in seen] and seen[-1][0] == "ENDED"
    e.start_process(SAND)
    seen = run_process(e)
    assert [s[0] for s in seen] == ["GET_TOOL"] + ["SAND_AREA"] * 4 + ["GO_HOME", "ENDED"]


def test_sanding_recovers_the_same_way(make_engine):
    e = make_engine()
    e.update_world(scan_result(walls=1, areas_per_wall=2))
    e.start_process(SPRAY)
    run_process(e)
    e.start_process(SAND)
    seen = run_process(e, _fail_first("SAND_AREA", "wall_1_area_2", "pad worn", times=2))
    assert [s[0] for s in seen] == ["GET_TOOL", "SAND_AREA", "SAND_AREA", "RECOVER", "SAND_AREA", "RECOVER",
                                    "SAND_AREA", "GO_HOME", "ENDED"]
    assert e.store.value(SITE.wall_1_area_2, PPR.sandingStatus) == PPR.processed


def test_the_third_failure_on_the_same_area_fails_the_process(make_engine):
    e = make_engine()
    e.update_world(scan_result(walls=1, areas_per_wall=2))
    sp = e.start_process(SPRAY)
    seen = run_process(e, _fail_first("SPRAY_AREA", "wall_1_area_1", times=99))
    assert [s[0] for s in seen] == ["GET_TOOL"] + ["SPRAY_AREA", "RECOVER"] * 2 + ["SPRAY_AREA", "FAILED"]
    msg = seen[-1][1]["message"]
    assert LINK_DOWN in msg and "spraying_spray" in msg and "spraying_t14" in msg
    assert e.active_process() is None and e.next_action().status == "failed"
    assert e.store.value(SITE.wall_1_area_1, PPR.sprayingStatus) == PPR.unprocessed   # reported, not hidden
    (proc,) = compute_kpis(e, sp)["processes"]
    assert proc["status"] == "failed" and proc["failed"] == 3
    assert e.check_consistency(full_inference=True) == []


def test_failures_on_different_areas_each_get_their_own_attempts(make_engine):
    e = make_engine()
    e.update_world(scan_result(walls=1, areas_per_wall=2))
    e.start_process(SPRAY)
    fail_1, fail_2 = _fail_first("SPRAY_AREA", "wall_1_area_1", times=2), _fail_first("SPRAY_AREA", "wall_1_area_2",
                                                                                       times=2)
    seen = run_process(e, lambda a: fail_1(a) if a.params().get("area") == "wall_1_area_1" else fail_2(a))
    assert [s[0] for s in seen].count("RECOVER") == 4 and seen[-1][0] == "ENDED"


def test_a_failed_recover_fails_the_process(make_engine):
    # RECOVER has no failure transition: devices that do not come back end the process (bounded)
    e = make_engine()
    e.update_world(scan_result(walls=1, areas_per_wall=1))
    e.start_process(SPRAY)

    def decide(a):
        if a.action_type == "SPRAY_AREA":
            return "failed", LINK_DOWN
        if a.action_type == "RECOVER":
            return "failed", "CheckDevicesUp: compressor: link down"
        return "succeeded", ""
    seen = run_process(e, decide)
    assert [s[0] for s in seen] == ["GET_TOOL", "SPRAY_AREA", "RECOVER", "FAILED"]
    assert "RECOVER" in seen[-1][1]["message"] and "compressor: link down" in seen[-1][1]["message"]


def test_a_node_without_failure_transition_fails_its_process_at_once(make_engine):
    e = make_engine()
    e.update_world(scan_result(joints_per_wall=2))
    sp = e.start_process(TAPING, {"validateLines": False})
    a = e.next_action()
    e.set_task_status(a.task, "succeeded")                           # GET_TOOL
    a = e.next_action()
    assert a.action_type == "TAPE_LINE"
    e.set_task_status(a.task, "in_progress")
    e.set_task_status(a.task, "failed", "tape torn")
    assert e.active_process() is None                                # failed at once, as before
    r = e.next_action()
    assert r.status == "failed" and "tape torn" in r.message
    assert _log(e, sp)[-1] == ("TAPE_LINE", "failed", "tape torn")


def test_the_failed_state_survives_an_engine_restart(tmp_path, clock):
    path = str(tmp_path / "db")
    store = JournaledStore(path)
    try:
        e = ProcessEngine(store, clock=clock)
        e.update_world(scan_result(walls=1, areas_per_wall=2))
        sp = e.start_process(SPRAY)
        a = e.next_action()
        e.set_task_status(a.task, "succeeded")
        a = e.next_action()
        e.set_task_status(a.task, "in_progress")
        e.set_task_status(a.task, "failed", LINK_DOWN)
        failed_task = a.task
    finally:
        store.close()
    store = JournaledStore(path)                                     # restart between the failure and next_action
    try:
        e = ProcessEngine(store, clock=clock)
        assert e.active_process() == sp
        r = e.next_action()
        assert r.action_type == "RECOVER" and r.task != failed_task
    finally:
        store.close()
    store = JournaledStore(path)                                     # restart with RECOVER issued: the same task
    try:
        e = ProcessEngine(store, clock=clock)
        r2 = e.next_action()
        assert (r2.action_type, r2.task, r2.task_status) == ("RECOVER", r.task, "issued")
        e.set_task_status(r2.task, "succeeded", "recovered")
        seen = run_process(e)
        assert [s[0] for s in seen] == ["SPRAY_AREA", "SPRAY_AREA", "GO_HOME", "ENDED"]
        assert [s[1]["area"] for s in seen[:2]] == ["wall_1_area_1", "wall_1_area_2"]
        assert [x[:2] for x in _log(e, sp)] == [("GET_TOOL", "succeeded"), ("SPRAY_AREA", "failed"),
                                                 ("RECOVER", "succeeded"), ("SPRAY_AREA", "succeeded"),
                                                 ("SPRAY_AREA", "succeeded"), ("GO_HOME", "succeeded")]
        assert e.check_consistency(full_inference=True) == []
    finally:
        store.close()


def test_failure_transition_conditions_answer_like_a_full_owlrl_closure(make_engine):
    from test_reasoning import _reference_store
    e = make_engine()
    e.update_world(scan_result(walls=1, areas_per_wall=2))
    sp = URIRef(e.start_process(SPRAY))
    decide = _fail_first("SPRAY_AREA", "wall_1_area_1", times=99)
    answers = []
    for _ in range(8):
        a = e.next_action()
        if a.status != "action":
            break
        e.set_task_status(a.task, *decide(a))
        if a.action_type != "SPRAY_AREA":
            continue
        ref = _reference_store(e)
        node = e.model.task_node_index[PLB.spraying_spray][1]
        (tr,) = node.on_failure
        q2 = ref.prepare(tr.condition.text, tr.condition.name, e.prefixes)
        fast, slow = e.store.ask(tr.condition, {"process": sp}), ref.ask(q2, {"process": sp})
        assert fast == slow
        answers.append(fast)
    assert answers == [True, True, False]                            # attempts 1 and 2 recover, the third fails


# ----------------------------------------------------------------------------------------------- bad models --
def _onto_with(tmp_path, extra: str):
    d = tmp_path / "onto"
    d.mkdir()
    for f in default_ontology_files():
        shutil.copy(f, d)
    p = d / "plasterboard.ttl"
    p.write_text(p.read_text() + "\n" + extra + "\n")
    return sorted(str(x) for x in d.iterdir())


@pytest.mark.parametrize("extra,fragments", [
    ("plb:bad_t a proc:Transition ; proc:source plb:spraying_morePending ; proc:target plb:spraying_goHome ; "
     "proc:onTaskFailure true .", ("bad_t", "spraying_morePending", "decision node", "proc:TaskNode")),
    ("plb:bad_t a proc:Transition ; proc:source plb:taping_start ; proc:target plb:taping_end ; "
     "proc:onTaskFailure true .", ("bad_t", "taping_start", "start node")),
    ("plb:bad_t a proc:Transition ; proc:source plb:taping_tape ; proc:target plb:taping_loop ; "
     "proc:onTaskFailure \"yes\" .", ("bad_t", "must be one boolean", "yes")),
    ("plb:bad_t a proc:Transition ; proc:source plb:spraying_spray ; proc:target plb:spraying_loop ; "
     "proc:onTaskFailure true .", ("spraying_spray", "more than one failure transition without condition")),
])
def test_bad_failure_transitions_are_refused_at_load(tmp_path, make_engine, extra, fragments):
    e = make_engine("db")
    before = quads_snapshot(e.store)
    e.store.close()
    files = _onto_with(tmp_path, extra.replace("plb:bad_t a", "plb:bad_t a owl:NamedIndividual,"))
    if "spraying_spray" in extra:   # two unconditional failure transitions: drop the shipped one's condition
        text = open([f for f in files if f.endswith("plasterboard.ttl")][0]).read()
        start = text.index("plb:spraying_t14 a")
        cond = text.index("proc:condition", start)
        end = text.index('" .\n', cond) + 4
        text = text[:cond] + 'rdfs:comment "no condition" .\n' + text[end:]
        open([f for f in files if f.endswith("plasterboard.ttl")][0], "w").write(text)
    store = JournaledStore(str(tmp_path / "db"))
    try:
        with pytest.raises(ProcessModelError) as info:
            ProcessEngine(store, files)
        for f in fragments:
            assert f in str(info.value), (f, str(info.value))
        assert quads_snapshot(store) == before                       # nothing written
    finally:
        store.close()


def test_a_task_node_with_only_a_failure_exit_is_refused(tmp_path):
    files = _onto_with(tmp_path, "")
    p = [f for f in files if f.endswith("plasterboard.ttl")][0]
    text = open(p).read()
    old = "plb:spraying_t12 a proc:Transition, owl:NamedIndividual ; proc:source plb:spraying_spray ; " \
          "proc:target plb:spraying_loop ."
    assert old in text
    open(p, "w").write(text.replace(old, ""))
    store = JournaledStore(str(tmp_path / "db5"))
    try:
        with pytest.raises(ProcessModelError, match="spraying_spray.*no outgoing transition.*failure transitions"):
            ProcessEngine(store, files)
    finally:
        store.close()
