"""kill -9 of a real process running the engine, at random moments, then a restart: the run continues where it
stopped -- no task repeated, none skipped -- and the store stays consistent."""
import os
import random
import signal
import subprocess
import sys
import time

import pytest
from rdflib import URIRef

from locem_bridge.pemkre import PLB, JournaledStore, OxigraphStore, ProcessEngine
from locem_bridge.pemkre.store import G_LOG
from locem_bridge.pemkre.terms import local_name

_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, _HERE)
import crash_driver  # noqa: E402


def _executed(engine):
    """[(action type, {param: value})] of every task of the last process, in order, with its status."""
    rows = engine.query("task_log", {"process": URIRef(engine.current_process())}).rows
    out = []
    for r in rows:
        params = {}
        for _, p, o, _ in engine.store.quads(r["task"], None, None, (G_LOG,)):
            if str(p).startswith(str(PLB)):
                params[local_name(p)] = local_name(o)
        out.append((str(r["actionType"]), params, str(r["status"]), int(r["seq"].toPython())))
    return out


def _reference(tmp_path):
    store = OxigraphStore(str(tmp_path / "reference"))
    try:
        e = ProcessEngine(store)
        e.start_process(str(PLB.TapingProcess), {"validateLines": True})
        for _ in range(200):
            a = e.next_action()
            if a.status != "action":
                break
            e.set_task_status(a.task, "in_progress")
            e.set_task_status(a.task, "succeeded", crash_driver.decide(a))
        return [x[:2] for x in _executed(e)]
    finally:
        store.close()


@pytest.mark.slow
def test_kill_dash_nine_mid_run_and_restart_continues_exactly(tmp_path):
    expected = _reference(tmp_path)
    assert len(expected) > 20 and expected[-1][0] == "GO_HOME"
    store_dir, ack_log = str(tmp_path / "store"), str(tmp_path / "acks.log")
    rnd = random.Random(1234)
    kills, finished = 0, False
    deadline = time.monotonic() + 240
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    while not finished and time.monotonic() < deadline:
        before = _count(ack_log)
        proc = subprocess.Popen([sys.executable, os.path.join(_HERE, "crash_driver.py"), store_dir, ack_log],
                                env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            target = before + rnd.randint(1, 4)
            extra = rnd.random() * 0.004
            while proc.poll() is None and time.monotonic() < deadline:
                if kills < 8 and _count(ack_log) >= target:
                    time.sleep(extra)  # land somewhere inside the next next_action / set_task_status
                    proc.send_signal(signal.SIGKILL)
                    proc.wait(timeout=10)
                    kills += 1
                    break
                time.sleep(0.0005)
            if proc.poll() is None:
                proc.wait(timeout=60)
            if proc.returncode == 0:
                finished = True
            elif proc.returncode != -signal.SIGKILL:
                raise AssertionError("driver failed (rc %s): %s" % (proc.returncode, proc.stderr.read().decode()[-2000:]))
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
            proc.stderr.close()
    assert finished, "the driver never finished (kills: %d)" % kills
    assert kills >= 5
    store = JournaledStore(store_dir)
    try:
        e = ProcessEngine(store)
        done = _executed(e)
        assert [d[:2] for d in done] == expected            # none repeated, none skipped, same order
        assert all(d[2] == "succeeded" for d in done)
        assert [d[3] for d in done] == list(range(1, len(done) + 1))
        assert e.next_action().status == "ended"
        assert e.check_consistency(full_inference=True) == []
        acked = [ln.split()[1] for ln in open(ack_log) if ln.startswith("ACK")]
        assert len(acked) == len(set(acked))               # no task was acknowledged twice
        statuses = {str(r["task"]): str(r["status"]) for r in e.query("task_log").rows}
        assert all(statuses[t] == "succeeded" for t in acked)  # every acknowledged status survived kill -9
    finally:
        store.close()


def _count(path):
    try:
        with open(path) as fh:
            return sum(1 for ln in fh if ln.startswith("ACK"))
    except FileNotFoundError:
        return 0
