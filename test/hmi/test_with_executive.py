"""The HMI and the automatic operator over the REAL HICEM executive (controller, trees, operator desk, health
monitor) in process, with HICEM's own test doubles standing in for PEMKRE and LOCEM (test/hicem/hicem_doubles).

Proves the pieces fit: the prompts the real trees open are answered by the configured policy (joint 2 rejected
-> PEMKRE sends it to MANUAL_TAPING), the page's state document shows the real controller's process, tree and
health, and STOP from the HTTP API halts the real controller and withdraws the open prompt.
"""
import os
import sys
import time

import pytest

_HICEM_TESTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "hicem")
if _HICEM_TESTS not in sys.path:
    sys.path.insert(0, _HICEM_TESTS)

from hicem_doubles import Heartbeats, LocemDouble, PemkreDouble  # noqa: E402
from hmi_client import post, state, wait_state  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hmi import (DEFAULT_CONFIG, AutoOperator, AutoOperatorConfig, ExecutiveBackend,  # noqa: E402
                              HmiServer)

PROCESS = PemkreDouble.PROCESS


@pytest.fixture
def hicem():
    pemkre = PemkreDouble()
    locem = LocemDouble(durations={"GOTO": 0.02, "APPLY_TAPE": 0.02, "HOME": 0.02})
    ex = create_executive(pemkre, locem, None)
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    backend = ExecutiveBackend.for_executive(ex, processes=[{"iri": PROCESS, "name": "Taping"}])
    try:
        yield ex, pemkre, locem, backend
    finally:
        beats.stop()
        ex.close()


def _run_to_its_end(backend, auto, timeout=30.0):
    """Start PROCESS with the automatic operator answering and wait (bounded) until it is over."""
    auto.start()
    try:
        backend.start_process(PROCESS)
        end = time.monotonic() + timeout
        while time.monotonic() < end and backend.snapshot()["phase"] not in ("ended", "failed", "stopped"):
            time.sleep(0.02)
    finally:
        auto.stop()


def test_headless_run_with_the_automatic_operator(hicem):
    ex, pemkre, locem, backend = hicem
    cfg = AutoOperatorConfig.from_dict({"poll_period_s": 0.02, "kinds": {
        "mount_tool": {"answer": "done", "delay_s": 0.05},
        "validate_line": {"answer": "valid", "delay_s": 0.0, "per_feature": {"invalid": ["wall_1_joint_2"]}}}},
        base=DEFAULT_CONFIG)
    auto = AutoOperator(backend, cfg)
    _run_to_its_end(backend, auto)
    snap = backend.snapshot()
    assert snap["phase"] == "ended", snap
    assert snap["health"]["status"] == "ok" and "locem" in snap["health"]["detail"]
    # what the real trees asked, and what PEMKRE was told
    assert [(a["kind"], a["answer"]) for a in auto.answers] == [
        ("mount_tool", "done"), ("validate_line", "valid"), ("validate_line", "invalid"),
        ("manual_taping", "done"), ("validate_line", "valid")]
    assert auto.answers[2]["features"] == ["wall_1_joint_2"]       # found in the tree's prompt text
    assert [s[4]["line"] for s in pemkre.executed("MANUAL_TAPING")] == ["wall_1_joint_2"]
    assert sorted(s[4]["line"] for s in pemkre.executed("TAPE_LINE")) == ["wall_1_joint_1", "wall_2_joint_1"]
    assert ex.operator.interventions == 5 and not auto.errors


def test_stop_from_the_http_api_halts_the_real_controller(hicem):
    ex, pemkre, locem, backend = hicem
    with HmiServer(backend, "127.0.0.1", 0, poll_period_s=0.05, shutdown_poll_s=0.05) as srv:
        assert post(srv.url, "/api/processes/start", {"iri": PROCESS}).status == 200
        doc = wait_state(srv.url, lambda d: d["prompts"], timeout=15)
        mount = doc["prompts"][0]
        assert mount["kind"] == "mount_tool" and "taping_tool" in mount["text"]
        snap = doc["snapshot"]
        assert snap["process"] == PROCESS and snap["tree"] == "GET_TOOL" and snap["node"] == "ask_mount"
        assert snap["action"].startswith("GET_TOOL (") and snap["health"]["status"] == "ok"
        again = post(srv.url, "/api/processes/start", {"iri": PROCESS})
        assert again.status == 409 and "still running" in again.error["message"]

        assert post(srv.url, "/api/stop", {}).status == 200
        doc = wait_state(srv.url, lambda d: d["snapshot"]["phase"] == "stopped", timeout=10)
        assert doc["prompts"] == [] and "STOP pressed on the operator HMI" in doc["snapshot"]["detail"]
        assert ex.controller.join(5.0) and not locem.running()
        assert ex.operator.get(mount["id"]).state == "cancelled"
        stale = post(srv.url, "/api/prompts/%s/reply" % mount["id"], {"answer": "done"})
        assert stale.status == 409 and stale.error["code"] == "prompt_not_open"
        assert mount["id"] in stale.error["message"]
        assert state(srv.url)["snapshot"]["phase"] == "stopped"


def test_the_default_automatic_operator_resets_a_protective_stop_so_a_headless_job_goes_on():
    """RECOVER (real tree) finds the arm in a latched protective stop; the automatic operator with its DEFAULT
    configuration answers the safety_stop prompt with reset, HICEM sends RESET_ARM, and the process goes on."""
    from hicem_rig import params
    pemkre = PemkreDouble(extra_actions=["RECOVER"])
    locem = LocemDouble(durations={"GOTO": 0.02, "APPLY_TAPE": 0.02, "HOME": 0.02})
    locem.health["arm"] = {"link": "up", "device": "safety stop: protective stop (safety mode 3)", "last_error": ""}
    sent = locem.send

    def send(command):
        if command == "RESET_ARM":
            locem.health["arm"] = {"link": "up", "device": "ok", "last_error": ""}
        return sent(command)
    locem.send = send
    ex = create_executive(pemkre, locem, None, params=params(recover__poll_s=0.05))
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    backend = ExecutiveBackend.for_executive(ex, processes=[{"iri": PROCESS, "name": "Taping"}])
    auto = AutoOperator(backend, AutoOperatorConfig.from_dict({"poll_period_s": 0.02}, base=DEFAULT_CONFIG))
    try:
        _run_to_its_end(backend, auto)
    finally:
        beats.stop()
        ex.close()
    assert backend.snapshot()["phase"] == "ended", backend.snapshot()
    stop = [a for a in auto.answers if a["kind"] == "safety_stop"]
    assert [a["answer"] for a in stop] == ["reset"] and stop[0]["text"].startswith("protective stop (safety mode 3)")
    assert stop[0]["open_for_s"] >= DEFAULT_CONFIG["kinds"]["safety_stop"]["delay_s"]
    assert pemkre.executed("RECOVER")[0][2:4] == ["succeeded", "recovered"]
    i_reset = locem.sent.index("RESET_ARM")
    assert "WALL_READY" not in locem.sent[:i_reset] and locem.sent[i_reset + 2] == "WALL_READY"
    assert ex.operator.interventions == len(auto.answers) and not auto.errors


def test_the_page_names_the_skill_the_real_controller_runs():
    """PEMKRE (its test double) matched GET_TOOL to the basic skill MOUNT_TOOL: the page's state shows that skill
    and the generic tree HICEM runs it with, while the command takes its time on LOCEM."""
    pemkre = PemkreDouble(skills={"GET_TOOL": ("MOUNT_TOOL", "basic")})
    locem = LocemDouble(durations={"MOUNT_TOOL": 2.0})
    ex = create_executive(pemkre, locem, None)
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    backend = ExecutiveBackend.for_executive(ex, processes=[{"iri": PROCESS, "name": "Taping"}])
    try:
        with HmiServer(backend, "127.0.0.1", 0, poll_period_s=0.05, shutdown_poll_s=0.05) as srv:
            assert post(srv.url, "/api/processes/start", {"iri": PROCESS}).status == 200
            doc = wait_state(srv.url, lambda d: d["snapshot"]["tree"] == "BASIC_SKILL", timeout=15)
            snap = doc["snapshot"]
            assert snap["skill"] == "MOUNT_TOOL" and snap["action"].startswith("GET_TOOL (")
            assert any(h.command == "MOUNT_TOOL tool=taping_tool" for h in locem.running())
            assert post(srv.url, "/api/stop", {}).status == 200
            assert ex.controller.join(5.0)
    finally:
        beats.stop()
        ex.close()
