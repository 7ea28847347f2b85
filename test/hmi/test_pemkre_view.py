"""What the operator sees from PEMKRE, checked against the REAL PEMKRE engine (embedded store under tmp_path):
KPI rows shipped as SPARQL results JSON text (as a ROS service would) come back with the same numbers as
PEMKRE's own compute_kpis; the feature_counts query becomes the taping progress; the processes offered come
from the shipped ontologies."""
import glob
import json
import os
import sys

import pytest
from rdflib import URIRef

_PEMKRE_TESTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "pemkre")
if _PEMKRE_TESTS not in sys.path:
    sys.path.insert(0, _PEMKRE_TESTS)

from pemkre_testkit import FakeClock, scan_result  # noqa: E402
from locem_bridge.hmi.pemkre_view import (KPI_QUERIES, processes_from_ontologies, rows_from_result,  # noqa: E402
                                          taping_progress)
from locem_bridge.pemkre import PLB, JournaledStore, ProcessEngine, compute_kpis  # noqa: E402

ONTOLOGIES = sorted(glob.glob(os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))), "ontologies", "*.ttl")))


@pytest.fixture
def engine(tmp_path):
    store = JournaledStore(str(tmp_path / "db"))
    try:
        yield ProcessEngine(store, clock=FakeClock(step=0.5))
    finally:
        store.close()


def test_kpis_and_progress_through_query_json(engine):
    engine.update_world(scan_result(joints_per_wall=3))
    sp = engine.start_process(str(PLB.TapingProcess), {"validateLines": True})
    verdict = {"wall_1_joint_1": "valid", "wall_1_joint_2": "invalid", "wall_1_joint_3": "valid"}
    progress = []
    for _ in range(30):
        a = engine.next_action()
        if a.status != "action":
            break
        engine.set_task_status(a.task, "in_progress")
        detail = verdict[a.params()["line"]] if a.action_type == "VALIDATE_TAPE_LINE" else ""
        engine.set_task_status(a.task, "succeeded", detail)
        text = json.dumps(engine.query("feature_counts").to_sparql_json())
        progress.append(taping_progress(rows_from_result(text)))
    assert progress[-1] == {"done": 3, "total": 3, "text": "joints taped or done by hand: 3 of 3"}
    assert [p["done"] for p in progress if p] == sorted(p["done"] for p in progress if p)   # never goes back
    assert progress[0] is None or progress[0]["done"] == 0

    tables = {table: rows_from_result(json.dumps(engine.query(name, {"process": URIRef(sp)}).to_sparql_json()))
              for table, name in KPI_QUERIES}
    reference = compute_kpis(engine, sp)
    (mine,), (ref,) = tables["processes"], reference["processes"]
    for key in ("count", "succeeded", "failed", "operatorInterventions", "manualFallbacks", "status"):
        assert mine[key] == ref[key], key
    assert isinstance(mine["count"], int) and isinstance(mine["successRate"], float)
    assert mine["operatorInterventions"] == 1 + 3 + 1 and mine["manualFallbacks"] == 1
    by_type = {r["actionType"]: r for r in tables["task_types"]}
    assert by_type["MANUAL_TAPING"]["count"] == 1 and by_type["TAPE_LINE"]["count"] == 2


@pytest.mark.parametrize("answer, rows", [
    ('[{"a": 1}]', [{"a": 1}]),
    ({"rows": [{"a": "x"}]}, [{"a": "x"}]),
    ({"head": {}, "boolean": True}, [{"boolean": True}]),
    ("", []),
])
def test_other_answer_shapes(answer, rows):
    assert rows_from_result(answer) == rows


@pytest.mark.parametrize("answer, words", [
    ("{not json", "not JSON"), ({"bindings": []}, "unknown shape"), ([1, 2], "row objects"),
])
def test_bad_answers_are_named(answer, words):
    with pytest.raises(ValueError) as info:
        rows_from_result(answer)
    assert words in str(info.value)


def test_processes_from_the_shipped_ontologies(tmp_path):
    procs = processes_from_ontologies(ONTOLOGIES)
    assert [p["name"] for p in procs] == ["SandingProcess", "SprayingProcess", "TapingProcess"]
    taping = procs[-1]
    assert taping["iri"] == str(PLB.TapingProcess) and taping["description"] == "taping of plasterboard joint lines"
    bad = tmp_path / "broken.ttl"
    bad.write_text("@prefix x: <urn:x#> .\nx:a x:b ")
    with pytest.raises(ValueError) as info:
        processes_from_ontologies([str(bad)])
    assert "broken.ttl" in str(info.value)


def test_progress_follows_the_running_process(engine):
    """Taping, spraying then sanding on the real PEMKRE engine, the states HICEM publishes for each action fed to
    the WorkFollower in order, the progress read from the real feature_status query the way the ROS backend
    does: joints while taping, areas sprayed while spraying, areas sanded while sanding -- never the joints
    again once the areas are worked on."""
    from locem_bridge.hmi.hicem_view import WorkFollower
    from locem_bridge.hmi.pemkre_view import work_progress

    engine.update_world(scan_result(walls=2, joints_per_wall=3, areas_per_wall=2))
    follower = WorkFollower()
    shown = []
    for process in (PLB.TapingProcess, PLB.SprayingProcess, PLB.SandingProcess):
        engine.start_process(str(process), {})
        for _ in range(60):
            a = engine.next_action()
            if a.status != "action":
                break
            state = {"process": str(process), "phase": "running", "action_type": a.action_type, "task": a.task}
            engine.set_task_status(a.task, "in_progress")
            work = follower.update(state)
            rows = rows_from_result(json.dumps(engine.query("feature_status").to_sparql_json()))
            shown.append((str(process), a.action_type, work_progress(rows, work) if work else None))
            engine.set_task_status(a.task, "succeeded", "valid" if a.action_type == "VALIDATE_TAPE_LINE" else "")
        follower.update({"process": str(process), "phase": "ended"})
        rows = rows_from_result(json.dumps(engine.query("feature_status").to_sparql_json()))
        shown.append((str(process), "END", work_progress(rows, follower.work) if follower.work else None))

    def texts(process, action=None):
        return [p["text"] for proc, act, p in shown if proc == str(process) and p and act in (action, "END")
                or (proc == str(process) and p and action is None)]

    assert texts(PLB.TapingProcess, "TAPE_LINE") == ["joints taped or done by hand: %d of 6" % n
                                                      for n in range(6)] + ["joints taped or done by hand: 6 of 6"]
    assert texts(PLB.SprayingProcess, "SPRAY_AREA") == ["areas sprayed: %d of 4" % n for n in range(5)]
    assert texts(PLB.SandingProcess, "SAND_AREA") == ["areas sanded: %d of 4" % n for n in range(5)]
    # before its first work action a process shows no progress (not the previous process's count)
    for process in (PLB.SprayingProcess, PLB.SandingProcess):
        first = [p for proc, act, p in shown if proc == str(process)]
        assert first[0] is None, shown
    assert not [p for proc, _a, p in shown if proc != str(PLB.TapingProcess) and p and "joints" in p["text"]]
