"""The operator_hmi ROS node (``rosrun locem_bridge operator_hmi``) against a test double of the HICEM ROS node
and of the simulator's operator services, on a private ROS master: the page's JSON API drives the real /hicem/*
services, the automatic operator answers the prompts published in /hicem/state (one line rejected by
``_reject_lines``), the simulated operator's hands mount the tool and tape the rejected joint in the simulator
before the answers go out, wall pictures come from the simulator, processes come from the shipped ontologies,
KPIs and the skill matching of a process come from the real PEMKRE node (with the shipped robot's resource
model), and PEMKRE's absence is reported, not fatal. Needs the environment of tools/test.sh (skipped otherwise, like
test/ros)."""
import json
import os
import shutil
import subprocess
import sys
import time

import pytest

from hmi_client import get, post, wait_state
from locem_bridge.ros.processes import RosProcesses, free_port

READY = bool(os.environ.get("LOCEM_REPO")) and shutil.which("rosrun") is not None
pytestmark = [pytest.mark.ros, pytest.mark.slow,
              pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh (ROS + catkin workspace)")]

HERE = os.path.dirname(os.path.abspath(__file__))
TAPING = "https://locem-bridge.example.org/ont/plasterboard#TapingProcess"


def calls(path):
    if not os.path.exists(path):
        return []
    with open(path) as fh:
        return [json.loads(line) for line in fh if line.strip()]


def answers(path):
    return [c[2] for c in calls(path) if c[0] == "reply"]


def wait_for(predicate, timeout, what):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError("timed out after %.0f s waiting for %s" % (timeout, what))


def serving(url):
    try:
        return get(url, "/api/state", timeout=2).status == 200
    except OSError:
        return False


@pytest.fixture
def ros(tmp_path):
    procs = RosProcesses(log_dir=str(tmp_path / "logs"))
    procs.env["ROS_HOME"] = str(tmp_path / "ros_home")
    procs.env["ROS_LOG_DIR"] = str(tmp_path / "ros_log")
    try:
        procs.start_master()
        yield procs
    finally:
        procs.close()


def test_operator_hmi_node_over_ros(ros, tmp_path):
    log = str(tmp_path / "hicem_calls.jsonl")
    ros.spawn([sys.executable, os.path.join(HERE, "fake_hicem_ros_node.py"), "_log:=%s" % log], "fake_hicem")
    ros.wait_for_service("/hicem/operator_reply", 30)
    port = free_port()
    node = ros.spawn(["rosrun", "locem_bridge", "operator_hmi", "_mode:=both", "_port:=%d" % port,
                      "_sim_picture_period:=0.5",
                      "_reject_lines:=wall_1_joint_2", "_process_options:={validateLines: true}",
                      "_auto_operator:={poll_period_s: 0.05, kinds: {mount_tool: {answer: done, delay_s: 0.3}}}"],
                     "operator_hmi")
    url = "http://127.0.0.1:%d/" % port
    wait_for(lambda: serving(url) or node.poll() is not None, 60, "the operator_hmi page")
    assert node.poll() is None, open(str(tmp_path / "logs" / "operator_hmi.log")).read()

    doc = wait_state(url, lambda d: d["snapshot"]["health"]["status"] == "ok" and d["walls"], timeout=15)
    assert [p["name"] for p in doc["processes"]] == ["SandingProcess", "SprayingProcess", "TapingProcess"]
    assert doc["snapshot"]["phase"] == "idle" and [w["id"] for w in doc["walls"]] == ["wall_1", "wall_2"]
    png = get(url, doc["walls"][0]["url"])                                # drawn by the simulator double
    assert png.status == 200 and png.body.startswith(b"\x89PNG")

    assert post(url, "/api/processes/start", {"iri": TAPING}).status == 200
    assert [c for c in calls(log) if c[0] == "start_process"] == [
        ["start_process", TAPING, json.dumps({"validateLines": True})]]
    doc = wait_state(url, lambda d: d["snapshot"]["phase"] == "running", timeout=10)
    assert doc["snapshot"]["tree"] in ("GET_TOOL", "VALIDATE_TAPE_LINE")

    again = post(url, "/api/processes/start", {"iri": TAPING})          # refused by HICEM: shown as 409
    assert again.status == 409 and "still running" in again.error["message"]

    doc = wait_state(url, lambda d: d["snapshot"]["phase"] == "ended", timeout=20)   # the automatic operator
    assert answers(log) == ["done", "valid", "invalid", "done"]
    # the simulated operator's hands acted before the answers that needed them
    steps = [c[1] if c[0] == "sim" else "%s %s" % (c[0], c[2]) for c in calls(log) if c[0] in ("sim", "reply")]
    steps = [s for s in steps if s not in ("save_outcome", "outcome")]
    assert steps == ["remove_tool", "mount_tool", "reply done", "reply valid", "reply invalid", "manual_taping",
                     "reply done"], steps
    sim = {c[1]: c[2] for c in calls(log) if c[0] == "sim"}
    assert sim["mount_tool"] == {"name": "taping_tool"} and sim["manual_taping"] == {"joint": "wall_1_joint_2"}
    assert any("automatic operator answered validate_line: invalid" in e["text"] for e in doc["events"])
    doc = wait_state(url, lambda d: "kpis()" in d["backend_error"], timeout=10)   # no PEMKRE in this test
    assert "/pemkre/query" in doc["backend_error"] and doc["snapshot"]["phase"] == "ended"

    stale = post(url, "/api/prompts/nope/reply", {"answer": "done"})
    assert stale.status == 409 and stale.error["code"] == "prompt_not_open"

    assert post(url, "/api/processes/start", {"iri": TAPING}).status == 200
    before = len(calls(log))
    assert post(url, "/api/stop", {}).status == 200
    # HICEM got the stop (other traffic, e.g. the periodic wall-picture refresh, may interleave)
    assert ["stop", "STOP pressed on the operator HMI"] in calls(log)[before:]
    wait_state(url, lambda d: d["snapshot"]["phase"] == "stopped" and not d["prompts"], timeout=10)


def test_pause_resume_abort_reset_over_ros(ros, tmp_path):
    """The page's skill buttons call /hicem/{suspend,resume,halt,reset}; the skill state shown and the methods
    allowed follow /hicem/skill_state; HICEM's refusal is shown as such."""
    log = str(tmp_path / "hicem_calls.jsonl")
    ros.spawn([sys.executable, os.path.join(HERE, "fake_hicem_ros_node.py"), "_log:=%s" % log], "fake_hicem")
    ros.wait_for_service("/hicem/reset", 30)
    port = free_port()
    ros.spawn(["rosrun", "locem_bridge", "operator_hmi", "_mode:=web", "_port:=%d" % port], "operator_hmi")
    url = "http://127.0.0.1:%d/" % port
    wait_for(lambda: serving(url), 60, "the operator_hmi page")
    r = post(url, "/api/skill/suspend", {})
    assert r.status == 409 and "no HICEM action is running" in r.error["message"]
    assert post(url, "/api/processes/start", {"iri": TAPING}).status == 200
    snap = wait_state(url, lambda d: d["snapshot"]["skill_state"] == "Running", timeout=10)["snapshot"]
    assert snap["allowed"] == ["Suspend", "Halt"] and snap["skill_detail"] == "HICEM runs the tree GET_TOOL"
    r = post(url, "/api/skill/suspend", {})
    assert r.status == 200 and (r.json["state"], r.json["allowed"]) == ("Suspended", ["Resume", "Halt"])
    snap = wait_state(url, lambda d: d["snapshot"]["skill_detail"] == "Pause pressed on the operator HMI",
                      timeout=10)["snapshot"]
    assert (snap["skill_state"], snap["allowed"]) == ("Suspended", ["Resume", "Halt"])
    r = post(url, "/api/skill/suspend", {"cause": "twice"})
    assert r.status == 409 and "is Suspended (allowed in Suspended: Resume, Halt)" in r.error["message"]
    assert post(url, "/api/skill/resume", {"cause": "bay clear"}).json["state"] == "Running"
    assert post(url, "/api/skill/halt", {}).json["state"] == "Halted"
    wait_state(url, lambda d: d["snapshot"]["allowed"] == ["Reset"] and d["snapshot"]["skill_state"] == "Halted",
               timeout=10)
    assert post(url, "/api/skill/reset", {}).json["state"] == "Ready"
    wait_state(url, lambda d: d["snapshot"]["skill_state"] == "Ready" and d["snapshot"]["allowed"] == [], timeout=10)
    assert [c[1:] for c in calls(log) if c[0] == "skill"] == [
        ["Suspend", "Pause pressed on the operator HMI"],                      # refused: no action yet
        ["Suspend", "Pause pressed on the operator HMI"], ["Suspend", "twice"], ["Resume", "bay clear"],
        ["Halt", "Abort pressed on the operator HMI"], ["Reset", "Reset pressed on the operator HMI"]]


def test_kpis_and_skill_matching_from_the_real_pemkre_node(ros, tmp_path):
    robot = os.path.join(HERE, "..", "..", "config", "robots", "rbkairos_ur10e.yaml")
    ros.spawn(["rosrun", "locem_bridge", "pemkre_node", "_store_path:=%s" % (tmp_path / "pemkre_store"),
               "_fresh:=true", "_robot:=%s" % os.path.abspath(robot)], "pemkre")
    ros.wait_for_service("/pemkre/query", 120)
    log = str(tmp_path / "hicem_calls.jsonl")
    ros.spawn([sys.executable, os.path.join(HERE, "fake_hicem_ros_node.py"), "_log:=%s" % log], "fake_hicem")
    ros.wait_for_service("/hicem/operator_reply", 30)
    port = free_port()
    ros.spawn(["rosrun", "locem_bridge", "operator_hmi", "_mode:=web", "_port:=%d" % port], "operator_hmi")
    url = "http://127.0.0.1:%d/" % port
    wait_for(lambda: serving(url), 60, "the operator_hmi page")
    assert post(url, "/api/processes/start", {"iri": TAPING}).status == 200
    doc = wait_state(url, lambda d: d["kpis"].get("processes"), timeout=20)
    (row,) = doc["kpis"]["processes"]
    assert row["abstractProcess"] == TAPING and row["status"] == "running" and row["count"] == 0
    assert isinstance(row["count"], int) and doc["kpis"]["task_types"] == []
    assert "kpis()" not in doc["backend_error"]
    # the page's skill matching through <pemkre>/match: the shipped robot's operator tree realizes GET_TOOL
    r = get(url, "/api/match?process=" + TAPING.replace("#", "%23"))
    assert r.status == 200, r
    view = r.json["match"]
    assert view["ok"] is True and view["robot_name"] == "rbkairos_ur10e"
    get_tool = next(t for t in view["tasks"] if t["action_type"] == "GET_TOOL")
    assert (get_tool["chosen"]["name"], get_tool["chosen"]["kind"], get_tool["chosen"]["operator"]) == (
        "GET_TOOL", "composite", True)
    assert [(c["name"], c["kind"]) for c in get_tool["rejected"]] == [("tmpl_getToolAutomatically", "template")]
    r = get(url, "/api/match?process=" + "https://locem-bridge.example.org/ont/plasterboard%23SandingProcess")
    assert r.status == 200 and r.json["match"]["process"].endswith("#SandingProcess")


def _auto_operator_node(ros, tmp_path, port, name="operator_hmi"):
    log = str(tmp_path / "hicem_calls.jsonl")
    ros.spawn([sys.executable, os.path.join(HERE, "fake_hicem_ros_node.py"), "_log:=%s" % log], "fake_hicem")
    ros.wait_for_service("/hicem/operator_reply", 30)
    node = ros.spawn(["rosrun", "locem_bridge", "operator_hmi", "_mode:=auto", "_port:=%d" % port,
                      "_auto_operator:={kinds: {validate_line: {answer: valid, delay_s: 0.0, "
                      "per_feature: {invalid: [wall_1_joint_1]}}}}"], name)
    node_log = str(tmp_path / "logs" / ("%s.log" % name))
    wait_for(lambda: (os.path.exists(node_log) and "mode auto" in open(node_log).read()) or node.poll() is not None,
             60, "operator_hmi to start")
    assert node.poll() is None
    done = subprocess.run(["rosservice", "call", "/hicem/start_process", "{process: '%s', options: ''}" % TAPING],
                          env=ros.env, capture_output=True, text=True, timeout=30)
    assert "success: True" in done.stdout, done.stdout + done.stderr
    wait_for(lambda: len(answers(log)) >= 4, 30, "the automatic operator's four answers")
    assert answers(log) == ["done", "invalid", "done", "valid"]
    return node, node_log


def test_automatic_operator_answers_and_the_page_shows_the_job(ros, tmp_path):
    port = free_port()
    node, node_log = _auto_operator_node(ros, tmp_path, port)
    url = "http://127.0.0.1:%d/" % port
    assert serving(url)                                                   # the page is served in auto mode too
    doc = wait_state(url, lambda d: len([e for e in d["events"] if "automatic operator answered" in e["text"]]) >= 4,
                     timeout=10)
    assert doc["snapshot"]["process"] == TAPING
    assert any("automatic operator answered validate_line: invalid" in e["text"] for e in doc["events"])
    assert "per_feature rule for wall_1_joint_1" in open(node_log).read()


def test_automatic_operator_carries_on_when_the_page_port_is_taken(ros, tmp_path):
    import socket
    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen(1)
    try:
        port = taken.getsockname()[1]
        node, node_log = _auto_operator_node(ros, tmp_path, port)        # still answers every prompt
        assert node.poll() is None
        text = open(node_log).read()
        assert "cannot serve the operator HMI on 127.0.0.1 port %d" % port in text
        assert "the automatic operator answers without a page" in text
    finally:
        taken.close()


@pytest.mark.parametrize("param, message", [
    ("_mode:=robot", "~mode must be one of web, auto, both, got 'robot'"),
    ("_sim_hands:=maybe", "~sim_hands must be auto, true or false, got 'maybe'"),
])
def test_bad_parameters_stop_the_node_with_a_clear_message(ros, tmp_path, param, message):
    node = ros.spawn(["rosrun", "locem_bridge", "operator_hmi", param, "_port:=0"], "bad_operator_hmi")
    try:
        code = node.wait(60)
    except subprocess.TimeoutExpired:
        pytest.fail("operator_hmi kept running with %s" % param)
    assert code == 2
    assert message in open(str(tmp_path / "logs" / "bad_operator_hmi.log")).read()
