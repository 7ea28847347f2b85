"""KPIs from the execution log by SPARQL: counts, success rate, durations, operator interventions, fallbacks."""
import json

import pytest
from pemkre_testkit import FakeClock, scan_result

from locem_bridge.pemkre import PLB, compute_kpis, export_kpis


def test_kpis_per_process_and_task_type(make_engine, tmp_path):
    clock = FakeClock(start=1_800_000_000.0, step=0.0)
    e = make_engine(clock=clock)
    e.update_world(scan_result(joints_per_wall=3))
    sp = e.start_process(str(PLB.TapingProcess), {"validateLines": True})
    verdict = {"wall_1_joint_1": "valid", "wall_1_joint_2": "invalid", "wall_1_joint_3": "valid"}
    durations = {"GET_TOOL": 30.0, "VALIDATE_TAPE_LINE": 10.0, "TAPE_LINE": 20.0, "MANUAL_TAPING": 60.0, "GO_HOME": 5.0}
    for _ in range(20):
        a = e.next_action()
        if a.status != "action":
            break
        clock.t += 1.0                                         # HICEM picks the task up a second later
        e.set_task_status(a.task, "in_progress")
        clock.t += durations[a.action_type]
        detail = verdict[a.params()["line"]] if a.action_type == "VALIDATE_TAPE_LINE" else ""
        if a.action_type == "TAPE_LINE" and a.params()["line"] == "wall_1_joint_3":
            e.set_task_status(a.task, "failed", "tape torn")
            break
        e.set_task_status(a.task, "succeeded", detail)
    k = compute_kpis(e, sp)
    by_type = {r["actionType"]: r for r in k["task_types"]}
    assert by_type["VALIDATE_TAPE_LINE"]["count"] == 3 and by_type["VALIDATE_TAPE_LINE"]["successRate"] == 1.0
    assert by_type["TAPE_LINE"]["count"] == 2
    assert by_type["TAPE_LINE"]["succeeded"] == 1 and by_type["TAPE_LINE"]["failed"] == 1
    assert by_type["TAPE_LINE"]["successRate"] == pytest.approx(0.5)
    assert by_type["TAPE_LINE"]["durationSeconds"] == pytest.approx(40.0)      # measured from in_progress
    assert by_type["MANUAL_TAPING"]["manualFallbacks"] == 1
    assert by_type["GET_TOOL"]["operatorInterventions"] == 1
    (proc,) = k["processes"]
    assert proc["name"] == "TapingProcess" and proc["status"] == "failed"
    assert proc["count"] == 7 and proc["failed"] == 1 and proc["succeeded"] == 6
    assert proc["operatorInterventions"] == 1 + 3 + 1          # tool change, three validations, one manual taping
    assert proc["manualFallbacks"] == 1
    assert proc["durationSeconds"] == pytest.approx(clock.t - 1_800_000_000.0)
    out = tmp_path / "report" / "kpis.json"
    export_kpis(e, str(out))
    data = json.loads(out.read_text())
    assert data["processes"][0]["process"] == sp and len(data["task_types"]) == 4  # no GO_HOME: it failed before


#: what the task types of plasterboard.ttl declare: operator involvement and manual fallback
OPERATOR_TYPES = {"GET_TOOL", "VALIDATE_TAPE_LINE", "MANUAL_TAPING"}
MANUAL_TYPES = {"MANUAL_TAPING"}


def _drive(e, clock, durations, decide, log, limit=30):
    """Run the current process to its end like HICEM; append (actionType, status, seconds) per task to ``log``."""
    for _ in range(limit):
        a = e.next_action()
        if a.status != "action":
            return a
        clock.t += 1.0
        e.set_task_status(a.task, "in_progress")
        clock.t += durations[a.action_type]
        status, detail = decide(a)
        e.set_task_status(a.task, status, detail)
        log.append((a.action_type, status, durations[a.action_type]))
    raise AssertionError("process did not end")


def test_kpis_of_two_processes_in_one_store_per_process_and_per_task_type(make_engine):
    clock = FakeClock(start=1_800_000_000.0, step=0.0)
    e = make_engine(clock=clock)
    e.update_world(scan_result(joints_per_wall=2, areas_per_wall=2))
    runs = {}   # specific process -> (abstract name, [(actionType, status, seconds)], duration)

    # run 1: taping with validation; the operator rejects the first line -> manual taping
    t0 = clock.t
    taping = e.start_process(str(PLB.TapingProcess), {"validateLines": True})
    log = []
    end = _drive(e, clock, {"GET_TOOL": 30.0, "VALIDATE_TAPE_LINE": 10.0, "TAPE_LINE": 20.0, "MANUAL_TAPING": 60.0,
                            "GO_HOME": 5.0},
                 lambda a: ("succeeded", ("invalid" if a.params()["line"] == "wall_1_joint_1" else "valid")
                            if a.action_type == "VALIDATE_TAPE_LINE" else ""), log)
    assert (end.status, end.message) == ("ended", "completed")
    runs[taping] = ("TapingProcess", log, clock.t - t0)

    # run 2: spraying; the second area fails once (compressor link), RECOVER, sprayed on the second attempt
    clock.t += 100.0
    t0 = clock.t
    spraying = e.start_process(str(PLB.SprayingProcess))
    log = []
    failed_once = []

    def spray_decide(a):
        if a.action_type == "SPRAY_AREA" and a.params()["area"] == "wall_1_area_2" and not failed_once:
            failed_once.append(a.task)
            return "failed", "compressor link down"
        return "succeeded", ""
    end = _drive(e, clock, {"GET_TOOL": 25.0, "SPRAY_AREA": 40.0, "RECOVER": 8.0, "GO_HOME": 4.0}, spray_decide, log)
    assert (end.status, end.message) == ("ended", "completed")
    runs[spraying] = ("SprayingProcess", log, clock.t - t0)
    assert [x[:2] for x in log] == [("GET_TOOL", "succeeded"), ("SPRAY_AREA", "succeeded"), ("SPRAY_AREA", "failed"),
                                    ("RECOVER", "succeeded"), ("SPRAY_AREA", "succeeded"), ("GO_HOME", "succeeded")]

    k = compute_kpis(e)                                           # every process of the store
    procs = {r["process"]: r for r in k["processes"]}
    assert set(procs) == {taping, spraying}
    assert [r["process"] for r in k["processes"]] == [taping, spraying]      # ordered by start
    for sp, (name, log, duration) in runs.items():
        row = procs[sp]
        ok = sum(1 for _, s, _ in log if s == "succeeded")
        bad = sum(1 for _, s, _ in log if s == "failed")
        assert row["name"] == name and row["status"] == "ended" and row["outcome"] == "completed"
        assert (row["count"], row["succeeded"], row["failed"]) == (len(log), ok, bad)
        assert row["successRate"] == pytest.approx(ok / (ok + bad))
        assert row["durationSeconds"] == pytest.approx(duration)
        assert row["operatorInterventions"] == sum(1 for t, _, _ in log if t in OPERATOR_TYPES)
        assert row["manualFallbacks"] == sum(1 for t, _, _ in log if t in MANUAL_TYPES)
    # what the two runs were, independently of the bookkeeping above
    assert (procs[taping]["count"], procs[taping]["failed"], procs[taping]["successRate"]) == (6, 0, 1.0)
    assert (procs[spraying]["count"], procs[spraying]["failed"]) == (6, 1)
    assert procs[spraying]["successRate"] == pytest.approx(5 / 6)
    assert (procs[taping]["operatorInterventions"], procs[taping]["manualFallbacks"]) == (4, 1)
    assert (procs[spraying]["operatorInterventions"], procs[spraying]["manualFallbacks"]) == (1, 0)

    # per task type: one row per (process, action type), never mixed across processes
    rows = {(r["process"], r["actionType"]): r for r in k["task_types"]}
    expected = {}
    for sp, (_, log, _) in runs.items():
        for t, s, secs in log:
            d = expected.setdefault((sp, t), {"count": 0, "succeeded": 0, "failed": 0, "durationSeconds": 0.0})
            d["count"] += 1
            d[s] += 1
            d["durationSeconds"] += secs
    assert set(rows) == set(expected)
    assert len(k["task_types"]) == len(expected)                 # GET_TOOL / GO_HOME: one row per process each
    for key, d in expected.items():
        row = rows[key]
        assert (row["count"], row["succeeded"], row["failed"]) == (d["count"], d["succeeded"], d["failed"]), key
        assert row["successRate"] == pytest.approx(d["succeeded"] / (d["succeeded"] + d["failed"])), key
        assert row["durationSeconds"] == pytest.approx(d["durationSeconds"]), key
        assert row["operatorInterventions"] == (d["count"] if key[1] in OPERATOR_TYPES else 0), key
        assert row["manualFallbacks"] == (d["count"] if key[1] in MANUAL_TYPES else 0), key
    spray = rows[(spraying, "SPRAY_AREA")]
    assert (spray["count"], spray["succeeded"], spray["failed"]) == (3, 2, 1)
    assert spray["successRate"] == pytest.approx(2 / 3) and spray["durationSeconds"] == pytest.approx(120.0)
    assert rows[(taping, "GET_TOOL")]["durationSeconds"] == pytest.approx(30.0)
    assert rows[(spraying, "GET_TOOL")]["durationSeconds"] == pytest.approx(25.0)

    # asking for one process gives exactly its rows
    only = compute_kpis(e, spraying)
    assert [r["process"] for r in only["processes"]] == [spraying]
    assert {(r["process"], r["actionType"]) for r in only["task_types"]} == {x for x in expected if x[0] == spraying}
    assert only["processes"][0] == procs[spraying]
