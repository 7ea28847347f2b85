"""The operator page's Pause / Resume / Abort / Reset (POST /api/skill/<method>) over the REAL HICEM executive in
process (ExecutiveBackend; HICEM's PEMKRE and LOCEM test doubles), and the ROS-free pieces the ROS backend uses.

Each method reaches the controller's running action, the state document shows the skill state and the methods
it allows, refusals come back as 409 with the state machine's text and change nothing, bad requests get their
4xx, a backend without skill methods answers 404.
"""
import os
import sys
import time

import pytest

_HICEM_TESTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "hicem")
if _HICEM_TESTS not in sys.path:
    sys.path.insert(0, _HICEM_TESTS)

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble, PemkreDouble  # noqa: E402
from hmi_client import get, post, request, state, wait_state  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hmi import ExecutiveBackend, HmiServer, normalize_snapshot  # noqa: E402

PROCESS = PemkreDouble.PROCESS


@pytest.fixture
def live():
    """An HMI server over a real executive whose TAPE_LINE commands take 30 s (the action stays running)."""
    pemkre = PemkreDouble(validate_lines=False, after_failure="continue")
    locem = LocemDouble(durations={"APPLY_TAPE": 30.0})
    ex = create_executive(pemkre, locem, None)
    ex.operator.add_listener(AutoOperator(ex.controller, {"mount_tool": "done"}))
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    backend = ExecutiveBackend.for_executive(ex, processes=[{"iri": PROCESS, "name": "Taping"}])
    srv = HmiServer(backend, "127.0.0.1", 0, poll_period_s=0.05, shutdown_poll_s=0.05).start()
    try:
        yield srv, ex, pemkre, locem
    finally:
        srv.close()
        beats.stop()
        ex.close()


def _tape_running(locem):
    return [h for h in locem.running() if h.command.startswith("APPLY_TAPE ")]


def test_pause_resume_abort_reset_through_the_api(live):
    srv, ex, pemkre, locem = live
    snap = state(srv.url)["snapshot"]
    assert (snap["skill_state"], snap["allowed"]) == ("", [])
    r = post(srv.url, "/api/skill/suspend", {})
    assert r.status == 409 and r.error["code"] == "refused"
    assert r.error["message"].startswith("Pause: Suspend is not allowed: no HICEM action is running")

    assert post(srv.url, "/api/processes/start", {"iri": PROCESS}).status == 200
    deadline = time.monotonic() + 15
    while not _tape_running(locem):
        assert time.monotonic() < deadline, ex.controller.state()
        time.sleep(0.01)
    doc = wait_state(srv.url, lambda d: d["snapshot"]["skill_state"] == "Running"
                     and d["snapshot"]["action"].startswith("TAPE_LINE"))
    assert doc["snapshot"]["allowed"] == ["Suspend", "Halt"]

    r = post(srv.url, "/api/skill/suspend", {"cause": "someone in the bay"})
    assert r.status == 200, r
    assert r.json == {"ok": True, "method": "Suspend", "state": "Suspended", "allowed": ["Resume", "Halt"],
                      "message": "someone in the bay"}
    snap = wait_state(srv.url, lambda d: d["snapshot"]["phase"] == "suspended")["snapshot"]
    assert (snap["skill_state"], snap["allowed"], snap["skill_detail"]) == ("Suspended", ["Resume", "Halt"],
                                                                            "someone in the bay")
    assert locem.sent[-1].startswith("SUSPEND APPLY_TAPE ")
    # refused: nothing changes
    sent = list(locem.sent)
    r = post(srv.url, "/api/skill/SUSPEND", {})
    assert r.status == 409 and "is Suspended (allowed in Suspended: Resume, Halt)" in r.error["message"]
    assert locem.sent == sent and state(srv.url)["snapshot"]["skill_state"] == "Suspended"

    r = post(srv.url, "/api/skill/resume")                      # no body at all: the default cause
    assert r.status == 200 and r.json["state"] == "Running" and r.json["allowed"] == ["Suspend", "Halt"]
    assert locem.sent[-1].endswith("cause=Resume pressed on the operator HMI")

    r = post(srv.url, "/api/skill/halt", {"cause": "abort"})
    assert r.status == 200 and r.json["state"] == "Halted"
    assert wait_state(srv.url, lambda d: any(e["text"] == "Abort pressed: Halted (abort)" for e in d["events"]))
    deadline = time.monotonic() + 10
    while not pemkre.executed("TAPE_LINE"):
        assert time.monotonic() < deadline
        time.sleep(0.01)
    assert pemkre.executed("TAPE_LINE")[0][2:4] == ["failed", "halted: abort"]
    ex.controller.stop("test over")             # the next joint runs meanwhile (this double's failure branch)
    assert ex.controller.join(10)
    snap = wait_state(srv.url, lambda d: d["snapshot"]["phase"] == "stopped")["snapshot"]
    assert snap["allowed"] == ["Reset"]          # the halted TAPE_LINE (the stopped one is Halted as well)
    r = post(srv.url, "/api/skill/reset", {})
    assert r.status == 200 and (r.json["state"], r.json["allowed"]) == ("Ready", [])
    log = [e["text"] for e in state(srv.url)["events"]]
    assert "Pause pressed: Suspended (someone in the bay)" in log and "Resume pressed: Running" in log
    assert "Reset pressed: Ready" in log


def test_bad_skill_requests(live, server):
    srv = live[0]
    r = post(srv.url, "/api/skill/pause", {})
    assert r.status == 404 and r.error["code"] == "unknown_skill_method"
    assert "methods: suspend, resume, halt, reset" in r.error["message"]
    assert get(srv.url, "/api/skill/suspend").status == 405
    r = post(srv.url, "/api/skill/suspend", {"cause": "x", "force": True})
    assert r.status == 400 and r.error["code"] == "unknown_field"
    r = post(srv.url, "/api/skill/suspend", {"cause": 3})
    assert r.status == 400 and r.error["code"] == "bad_body"
    r = request(srv.url, "POST", "/api/skill/suspend", raw=b"{}", headers={"Content-Type": "text/plain"})
    assert r.status == 415
    assert any(e["path"] == "/api/skill/<method>" for e in get(srv.url, "/api").json["endpoints"])
    # the scripted double offers no skill methods: the page's buttons stay disabled, the API says why
    r = post(server.url, "/api/skill/suspend", {})
    assert r.status == 404 and r.error["code"] == "no_skill_control"
    assert state(server.url)["snapshot"]["allowed"] == []


def test_snapshot_allowed_is_normalized():
    snap = normalize_snapshot({"allowed": ["Halt", "Start", "Suspend", 3], "skill_state": None})
    assert snap["allowed"] == ["Suspend", "Halt"] and snap["skill_state"] == "" and snap["skill_detail"] == ""
    assert normalize_snapshot({"allowed": "Suspend"})["allowed"] == []
