"""The opt-in PEMKRE call log (hook for the job benchmark), on a real client-shaped object and a real file."""
import json
import threading

import pytest

from locem_bridge.job.call_log import (ENV_VAR, CallLog, CallLogError, instrument, instrument_from_env,
                                       read_call_log)


class PemkreLike:
    """Shaped like HICEM's PemkreClient: the methods the hook times, plus an attribute."""

    def __init__(self):
        self.engine = "kept"
        self.calls = []

    def start_process(self, iri, options=None):
        self.calls.append(("start_process", iri, options))
        return "urn:specific"

    def next_action(self):
        raise RuntimeError("PEMKRE down")

    def set_task_status(self, task, status, detail=""):
        self.calls.append(("set_task_status", task, status, detail))

    def report_world(self, update):
        self.calls.append(("report_world", update))


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        self.t += 0.25
        return self.t


def test_every_call_is_recorded_with_its_times_and_outcome_and_the_object_keeps_working(tmp_path):
    path = str(tmp_path / "calls.jsonl")
    client = PemkreLike()
    log = CallLog(path, clock=Clock())
    same = instrument(client, ("start_process", "next_action", "set_task_status"), log, "pemkre")
    assert same is client and isinstance(client, PemkreLike) and client.engine == "kept"
    assert client.start_process("urn:p", {"a": 1}) == "urn:specific"
    with pytest.raises(RuntimeError, match="PEMKRE down"):   # the error reaches the caller unchanged
        client.next_action()
    client.set_task_status("urn:t", "succeeded", detail="ok")
    client.report_world({})                                  # not instrumented: not recorded
    log.close()
    assert client.calls[0] == ("start_process", "urn:p", {"a": 1})
    records = read_call_log(path)
    assert [(r["layer"], r["call"], r["ok"]) for r in records] == [
        ("pemkre", "start_process", True), ("pemkre", "next_action", False), ("pemkre", "set_task_status", True)]
    assert all(r["t1"] - r["t0"] == 0.25 for r in records)


def test_without_the_environment_variable_nothing_is_wrapped(tmp_path):
    client = PemkreLike()
    method = client.start_process
    assert instrument_from_env(client, environ={}) is client
    assert client.start_process == method
    path = tmp_path / "env.jsonl"
    instrument_from_env(client, environ={ENV_VAR: str(path)})
    client.start_process("urn:p")
    client.set_task_status("urn:t", "in_progress")
    client.report_world({"features": []})
    assert [r["call"] for r in read_call_log(str(path))] == ["start_process", "set_task_status", "report_world"]


def test_concurrent_calls_give_whole_lines_and_a_torn_line_is_skipped(tmp_path):
    path = tmp_path / "calls.jsonl"
    client = instrument(PemkreLike(), ("set_task_status",), CallLog(str(path)), "pemkre")

    def work():
        for i in range(50):
            client.set_task_status("urn:t%d" % i, "in_progress")
    threads = [threading.Thread(target=work) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    with open(path, "a") as handle:
        handle.write('{"call": "next_action", "t0": 1')     # a crash mid-write
    records = read_call_log(str(path))
    assert len(records) == 200
    assert all(json.dumps(r) for r in records)
    assert read_call_log(str(tmp_path / "missing.jsonl")) == []


def test_a_method_that_does_not_exist_is_refused_by_name(tmp_path):
    with pytest.raises(CallLogError, match="no method 'query'"):
        instrument(PemkreLike(), ("query",), CallLog(str(tmp_path / "x")), "pemkre")
    with pytest.raises(CallLogError, match="file path"):
        CallLog("")
