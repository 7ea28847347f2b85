"""A status report (and a process start) sent again with the same request id is applied exactly once: in the same
engine, after the store is reopened, and after PEMKRE was killed with SIGKILL between applying a report and
answering it (a HICEM client retrying after a PEMKRE restart). Real on-disk stores (journal and RocksDB)."""
import os
import signal
import subprocess
import sys
import textwrap

import pytest
from rdflib import URIRef
from pemkre_testkit import quads_snapshot, scan_result

from locem_bridge.pemkre import PLB, PPR, JournaledStore, OxigraphStore, ProcessEngine
from locem_bridge.pemkre.errors import InvalidParameterError, TaskStateError
from locem_bridge.pemkre.vocab import SITE

TAPING = str(PLB.TapingProcess)
_SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")
STORES = {"journal": JournaledStore, "rocksdb": OxigraphStore}


def _to_first_tape_line(e):
    """Taping without validation on one wall of two joints; returns the first TAPE_LINE task (not reported)."""
    e.update_world(scan_result(joints_per_wall=2))
    e.start_process(TAPING, {"validateLines": False}, request_id="job-1-taping")
    a = e.next_action()
    assert a.action_type == "GET_TOOL"
    e.set_task_status(a.task, "in_progress", request_id="r-get-tool-1")
    e.set_task_status(a.task, "succeeded", request_id="r-get-tool-2")
    a = e.next_action()
    assert (a.action_type, a.params()) == ("TAPE_LINE", {"line": "wall_1_joint_1"})
    return a


def _task_log(e):
    return [(str(r["task"]), str(r["status"])) for r in e.query("task_log").rows]


def test_a_retried_report_is_applied_once(make_engine):
    e = make_engine()
    a = _to_first_tape_line(e)
    r1 = e.set_task_status(a.task, "in_progress", request_id="r-tape-1")
    assert not r1.repeated
    # without a request id the same report is refused (the task is already in_progress): the old failure
    with pytest.raises(TaskStateError):
        e.set_task_status(a.task, "in_progress")
    before = quads_snapshot(e.store)
    r2 = e.set_task_status(a.task, "in_progress", request_id="r-tape-1")
    assert r2.repeated and r2.task == a.task and r2.status == "in_progress"
    assert quads_snapshot(e.store) == before
    done = e.set_task_status(a.task, "succeeded", request_id="r-tape-2")
    assert done.effects_applied >= 1 and not done.repeated
    after = quads_snapshot(e.store)
    again = e.set_task_status(a.task, "succeeded", request_id="r-tape-2")
    assert again.repeated and again.effects_applied == 0
    assert quads_snapshot(e.store) == after
    # the process went on exactly one step: the second joint is next, the first is taped once
    nxt = e.next_action()
    assert (nxt.action_type, nxt.params()) == ("TAPE_LINE", {"line": "wall_1_joint_2"})
    assert e.store.value(SITE.wall_1_joint_1, PPR.tapingStatus) == PPR.processed
    assert [s for t, s in _task_log(e) if t == a.task] == ["succeeded"]
    assert e.check_consistency(full_inference=True) == []


def test_a_request_id_names_one_report(make_engine):
    e = make_engine()
    a = _to_first_tape_line(e)
    e.set_task_status(a.task, "in_progress", request_id="r-x")
    before = quads_snapshot(e.store)
    with pytest.raises(InvalidParameterError) as info:       # same id, another status: a client bug, refused
        e.set_task_status(a.task, "succeeded", request_id="r-x")
    assert "r-x" in str(info.value) and "in_progress" in str(info.value)
    with pytest.raises(InvalidParameterError) as info:       # an id already used for another task
        e.set_task_status(a.task, "succeeded", request_id="r-get-tool-2")
    assert "r-get-tool-2" in str(info.value)
    for bad in ("with space", "x" * 201, "tab\there", "é"):
        with pytest.raises(InvalidParameterError) as info:
            e.set_task_status(a.task, "succeeded", request_id=bad)
        assert "request id" in str(info.value) and "200 printable ASCII" in str(info.value)
    assert quads_snapshot(e.store) == before


def test_a_retried_start_returns_the_same_process(make_engine):
    e = make_engine()
    sp = e.start_process(TAPING, {"validateLines": True}, request_id="job-7-taping")
    before = quads_snapshot(e.store)
    # HICEM always starts with abort_running: without the id a retry would fail the first process
    assert e.start_process(TAPING, {"validateLines": True}, abort_running=True, request_id="job-7-taping") == sp
    assert quads_snapshot(e.store) == before
    assert e.active_process() == sp
    with pytest.raises(InvalidParameterError) as info:
        e.start_process(str(PLB.SprayingProcess), abort_running=True, request_id="job-7-taping")
    assert "job-7-taping" in str(info.value) and "TapingProcess" in str(info.value)
    assert quads_snapshot(e.store) == before


def test_a_start_written_whose_answer_was_lost_is_the_current_process_when_retried(make_engine):
    """The store wrote the start, then failed to say so (NOT_READY: a SPARQL server's answer lost): HICEM's
    retry with the same request id answers that process and the engine runs it (it was not the current one in
    memory: the first call raised)."""
    from locem_bridge.pemkre.errors import StoreUnavailable

    e = make_engine()
    first = e.start_process(str(PLB.SprayingProcess), request_id="job-8-spraying")
    for a in iter(e.next_action, None):                # run the first process to its end
        if a.status != "action":
            break
        e.set_task_status(a.task, "in_progress")
        e.set_task_status(a.task, "succeeded")
    real_apply = e.store.apply

    def apply_then_lose_the_answer(cs):
        real_apply(cs)
        raise StoreUnavailable("SPARQL update endpoint x: connection reset after the write was sent", "x",
                               "connection reset", applied=None)

    e.store.apply = apply_then_lose_the_answer
    with pytest.raises(StoreUnavailable):
        e.start_process(TAPING, {"validateLines": False}, abort_running=True, request_id="job-8-taping")
    e.store.apply = real_apply
    assert e.current_process() == first                 # the engine did not learn of the start

    def taping_runs():
        return sorted(str(s) for s, _, _, _ in e.store.quads(None, None, URIRef(TAPING), None) if "/log/" in str(s))

    written = taping_runs()
    assert len(written) == 1                            # ... but the store holds it
    sp = e.start_process(TAPING, {"validateLines": False}, abort_running=True, request_id="job-8-taping")
    assert sp == written[0] and taping_runs() == written    # that one, not a second
    assert e.current_process() == sp and e.active_process() == sp
    assert e.next_action().action_type in ("SCAN", "GET_TOOL")


@pytest.mark.parametrize("kind", sorted(STORES))
def test_a_retried_report_is_applied_once_across_a_reopened_store(tmp_path, clock, kind):
    path = str(tmp_path / kind)
    store = STORES[kind](path)
    e = ProcessEngine(store, clock=clock)
    a = _to_first_tape_line(e)
    e.set_task_status(a.task, "in_progress", request_id="r-tape-1")
    e.set_task_status(a.task, "succeeded", request_id="r-tape-2")
    sp = e.current_process()
    store.close()
    store = STORES[kind](path)
    try:
        e = ProcessEngine(store, clock=clock)
        before = quads_snapshot(store)
        assert e.set_task_status(a.task, "succeeded", request_id="r-tape-2").repeated
        assert e.set_task_status(a.task, "in_progress", request_id="r-tape-1").repeated
        assert e.start_process(TAPING, {"validateLines": False}, abort_running=True,
                               request_id="job-1-taping") == sp
        assert quads_snapshot(store) == before
        assert e.next_action().params() == {"line": "wall_1_joint_2"}
    finally:
        store.close()


_DIE_AFTER_APPLYING = textwrap.dedent("""
    import os, signal, sys
    sys.path.insert(0, {src!r})
    from locem_bridge.pemkre import JournaledStore, ProcessEngine
    store = JournaledStore({path!r})
    engine = ProcessEngine(store)
    task = engine.next_action().task
    engine.set_task_status(task, "succeeded", "", request_id="r-tape-2")
    os.kill(os.getpid(), signal.SIGKILL)   # applied and persisted, then dead before any answer went out
""")


def test_a_report_applied_just_before_a_kill_is_not_applied_again(tmp_path, clock):
    """The window the request id exists for: PEMKRE stored the report and died before answering; HICEM's
    client, seeing the connection drop, sends the same report again to the respawned PEMKRE."""
    path = str(tmp_path / "store")
    store = JournaledStore(path)
    e = ProcessEngine(store, clock=clock)
    a = _to_first_tape_line(e)
    e.set_task_status(a.task, "in_progress", request_id="r-tape-1")
    store.close()
    proc = subprocess.run([sys.executable, "-c", _DIE_AFTER_APPLYING.format(src=_SRC, path=path)],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=120)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
    store = JournaledStore(path)
    try:
        e = ProcessEngine(store)
        before = quads_snapshot(store)
        report = e.set_task_status(a.task, "succeeded", "", request_id="r-tape-2")   # the client's retry
        assert report.repeated
        assert quads_snapshot(store) == before
        assert [s for t, s in _task_log(e) if t == a.task] == ["succeeded"]
        nxt = e.next_action()                    # the next joint, not the first one again and none skipped
        assert nxt.params() == {"line": "wall_1_joint_2"}
        assert e.check_consistency(full_inference=True) == []
    finally:
        store.close()
