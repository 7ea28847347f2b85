"""The PEMKRE call-log hook inside the real HICEM controller, with the real PEMKRE engine (in process).

This is the hook the HICEM node gets (``instrument_from_env`` around its PEMKRE client): every PEMKRE call the
controller makes is in the log - including ``next_action``, which HICEM's own per-action statistics do not
count - and the job benchmark's split uses the log instead of HICEM's phases. The LOCEM side is HICEM's test
double (instant commands). The assertions hold whether the process ends or fails: what is checked is the
record of the calls, not the process.
"""
import os
import sys
import time

import pytest

pemkre = pytest.importorskip("locem_bridge.pemkre")

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "hicem"))

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble  # noqa: E402  (HICEM's test doubles)
from hicem_rig import params  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.pemkre_local import EngineClient  # noqa: E402
from locem_bridge.job.call_log import ENV_VAR, instrument_from_env, read_call_log  # noqa: E402
from locem_bridge.job.layers import JobRecording, analyse  # noqa: E402


def test_every_pemkre_call_of_a_hicem_process_is_logged_and_used_by_the_split(tmp_path):
    log = str(tmp_path / "pemkre_calls.jsonl")
    store = pemkre.OxigraphStore(str(tmp_path / "pemkre_db"))
    client = instrument_from_env(EngineClient(pemkre.ProcessEngine(store)), environ={ENV_VAR: log})
    ex = create_executive(client, LocemDouble(), str(tmp_path / "hdict.sqlite"), params=params())
    ex.operator.add_listener(AutoOperator(ex.controller, {"mount_tool": "done", "validate_line": "valid",
                                                          "manual_taping": "done"}))
    states = []
    ex.controller.add_state_listener(lambda s: states.append((time.time(), dict(s))))
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    iri = str(pemkre.PLB.TapingProcess)
    t0 = time.time()
    try:
        phase = ex.controller.run_process(iri, {"validateLines": False})
    finally:
        beats.stop()
        ex.close()
        store.close()
    t1 = time.time()
    assert phase in ("ended", "failed")
    records = read_call_log(log)
    calls = [r["call"] for r in records]
    assert calls[0] == "start_process" and records[0]["ok"]
    assert "next_action" in calls and "set_task_status" in calls
    actions = len(ex.controller.stats)
    # one next_action per action plus the final one (ended/failed); two status reports per action
    assert calls.count("next_action") >= actions
    assert calls.count("set_task_status") >= actions
    # one worker thread: the calls follow each other inside the run
    for before, after in zip(records, records[1:]):
        assert t0 <= before["t0"] <= before["t1"] <= after["t0"] <= after["t1"] <= t1
    # HICEM's own statistics miss next_action: the log sees at least as much PEMKRE time
    logged = sum(r["t1"] - r["t0"] for r in records)
    assert logged >= sum(s.pemkre_s for s in ex.controller.stats)

    rec = JobRecording(steps=[("taping", iri)], start=t0, end=t1, hicem_states=states, pemkre_calls=records)
    out = analyse(rec)
    assert out["pemkre_source"] == "call_log"
    (proc,) = out["processes"]
    assert proc["status"] == phase
    assert abs(proc["layers"]["pemkre"] - sum(r["t1"] - r["t0"] for r in records
                                              if proc["start"] <= r["t0"] and r["t1"] <= proc["end"])) < 0.05
