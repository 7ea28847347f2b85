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
