"""The operator page's Manual work panel: the planned manual work HICEM's task reports name (parts of areas and
joints the robot cannot reach, left for a person), collected by :class:`locem_bridge.hmi.manual_work.ManualWorkLog`.

- the collection logic on its own (which states count, duplicates, a RECOVER re-run, a report seen again);
- the JSON API (``manual`` in /api/state, GET /api/manual) over the in-process backend fed by the controller's
  state listener, and over a backend without manual work;
- the real operator_hmi ROS node, fed HICEM states on /hicem/state by the HICEM test double (the path of the real
  node: each message reaches ``RosHmiBackend._on_state``), with the page open in a real headless Chromium: the
  panel shows "no manual work", then lists the parts live as the tasks report, and the API returns them.
"""
import json
import os
import subprocess
import sys

import pytest

from hmi_client import get, state, wait_state
from locem_bridge.hmi import ExecutiveBackend, HmiServer, ManualWorkLog
from locem_bridge.hmi.manual_work import manual_parts
from locem_bridge.ros.processes import free_port
from test_browser import CHROMIUM, ON_UBUNTU, browser  # noqa: F401 - the chromium fixture
from test_ros_operator_hmi import READY, ros, serving, wait_for  # noqa: F401 - the private ROS master fixture

PLB = "https://locem-bridge.example.org/ont/plasterboard#"
SPRAYING, SANDING, TAPING = PLB + "SprayingProcess", PLB + "SandingProcess", PLB + "TapingProcess"
AREA_1 = "sprayed; manual work on wall_1_area_1: section 3 (along 1.2..1.8 m, height 0..2.5 m)"
AREA_2 = ("sprayed; manual work on wall_1_area_2: section 1 (along 0..0.6 m, height 2.2..2.5 m), "
          "section 4 (along 1.8..2.4 m, height 0..0.3 m)")
JOINT_3 = ("taped; manual work on wall_1_joint_3: part 1 (along 0..0.42 m; near a corner), "
           "part 2 (along 2.1..2.5 m; above the tool's height band)")


def report(action, task, detail, process=SPRAYING):
    return {"process": process, "phase": "reporting", "action_type": action, "task": task, "detail": detail}


def short(items):
    return [(m["kind"], m["work"], m["feature"], m["part"], m["along"], m["height"], m["reason"]) for m in items]


# -- the collection logic ------------------------------------------------------------------------------------------
def test_area_and_joint_reports_become_parts():
    log = ManualWorkLog()
    assert log.items() == []
    assert log.update(report("SPRAY_AREA", "urn:t1", AREA_1)) is True
    assert log.update(report("TAPE_LINE", "urn:t2", JOINT_3, TAPING)) is True
    assert log.update(report("SAND_AREA", "urn:t3", AREA_1.replace("sprayed", "sanded"), SANDING)) is True
    assert short(log.items()) == [
        ("area", "spray", "wall_1_area_1", 3, [1.2, 1.8], [0.0, 2.5], ""),
        ("joint", "tape", "wall_1_joint_3", 1, [0.0, 0.42], None, "near a corner"),
        ("joint", "tape", "wall_1_joint_3", 2, [2.1, 2.5], None, "above the tool's height band"),
        ("area", "sand", "wall_1_area_1", 3, [1.2, 1.8], [0.0, 2.5], ""),    # the same area, other work: its own
    ]
    first = log.items()[0]
    assert first["text"] == "spray wall_1_area_1, section 3: along 1.2..1.8 m, height 0..2.5 m"
    assert (first["task"], first["process"]) == ("urn:t1", SPRAYING)
    assert log.items()[2]["text"] == "tape wall_1_joint_3, part 2: along 2.1..2.5 m; above the tool's height band"
    json.dumps(log.items())                                                   # ready for the API as it is


def test_only_the_reports_of_spray_sand_and_tape_tasks_count():
    log = ManualWorkLog()
    # HICEM keeps the last report's detail while the next task starts and runs: not a report of that task
    for phase in ("starting", "running", "asking", "waiting_for_pemkre", "ended", "failed"):
        assert not log.update(dict(report("SPRAY_AREA", "urn:t1", AREA_1), phase=phase)), phase
    for action in ("VALIDATE_TAPE_LINE", "MANUAL_TAPING", "RECOVER", "GET_TOOL", ""):
        assert not log.update(report(action, "urn:t1", AREA_1)), action
    assert not log.update(report("SPRAY_AREA", "urn:t1", "sprayed"))         # no manual work named
    assert not log.update(report("SPRAY_AREA", "urn:t1", ""))
    assert not log.update(report("SPRAY_AREA", "urn:t1", JOINT_3))           # a joint's text is no area's
    assert not log.update(report("TAPE_LINE", "urn:t1", AREA_1))
    assert log.items() == [] and manual_parts({}) == []


def test_duplicates_are_not_repeated():
    log = ManualWorkLog()
    assert log.update(report("SPRAY_AREA", "urn:t1", AREA_1))
    assert not log.update(report("SPRAY_AREA", "urn:t1", AREA_1))           # the same state published again
    twice = AREA_1 + ", section 3 (along 1.2..1.8 m, height 0..2.5 m)"       # a part named twice in one detail
    assert not log.update(report("SPRAY_AREA", "urn:t1", twice))
    assert short(log.items()) == [("area", "spray", "wall_1_area_1", 3, [1.2, 1.8], [0.0, 2.5], "")]
    assert log.update(report("TAPE_LINE", "urn:t2", JOINT_3, TAPING))
    assert not log.update(report("TAPE_LINE", "urn:t2", JOINT_3, TAPING))
    assert [m["part"] for m in log.items() if m["kind"] == "joint"] == [1, 2]


def test_a_recover_rerun_or_a_resumed_task_does_not_double_the_parts():
    log = ManualWorkLog()
    states = [
        {"process": SPRAYING, "phase": "running", "action_type": "SPRAY_AREA", "task": "urn:t1", "detail": ""},
        report("SPRAY_AREA", "urn:t1", AREA_1),
        dict(report("SPRAY_AREA", "urn:t2", AREA_1), phase="starting"),      # next area, old detail kept
        report("SPRAY_AREA", "urn:t2", "failed: compressor link lost"),       # area 2 fails part-way ...
        dict(report("RECOVER", "urn:t3", "failed: compressor link lost"), phase="running"),
        report("RECOVER", "urn:t3", "recovered"),
        dict(report("SPRAY_AREA", "urn:t4", "recovered"), phase="running"),  # ... and is worked again
        report("SPRAY_AREA", "urn:t4", AREA_2),
        report("SPRAY_AREA", "urn:t4", AREA_2),                               # its report published again
    ]
    for st in states:
        log.update(st)
    expected = [("area", "spray", "wall_1_area_1", 3, [1.2, 1.8], [0.0, 2.5], ""),
                ("area", "spray", "wall_1_area_2", 1, [0.0, 0.6], [2.2, 2.5], ""),
                ("area", "spray", "wall_1_area_2", 4, [1.8, 2.4], [0.0, 0.3], "")]
    assert short(log.items()) == expected
    # the area's task run once more (a retry, a resume after a HICEM restart): its report names the same parts
    log.update(report("SPRAY_AREA", "urn:t5", AREA_2))
    assert short(log.items()) == expected and log.items()[1]["task"] == "urn:t5"
    # a newer report of an area is its whole list of manual parts: it replaces the older one, in place
    log.update(report("SPRAY_AREA", "urn:t6", "sprayed; manual work on wall_1_area_1: section 3 (along 1.2..1.8 m, "
                                              "height 0..2.5 m), section 5 (along 2.4..3 m, height 2..2.5 m)"))
    assert [(m["feature"], m["part"]) for m in log.items()] == [("wall_1_area_1", 3), ("wall_1_area_1", 5),
                                                                ("wall_1_area_2", 1), ("wall_1_area_2", 4)]
    log.clear()
    assert log.items() == []


# -- the JSON API --------------------------------------------------------------------------------------------------
class _Controller:
    """Just what ExecutiveBackend reads of HICEM's controller for the state: state() and state listeners."""

    def __init__(self):
        self.listeners = []
        self._state = {"process": "", "phase": "idle", "detail": ""}

    def add_state_listener(self, cb):
        self.listeners.append(cb)

    def state(self):
        return dict(self._state)

    def set(self, **kw):                                   # as HighLevelController._set_state
        self._state.update(kw)
        for cb in self.listeners:
            cb(dict(self._state))


class _Desk:
    def open_prompts(self):
        return []


def test_the_api_lists_the_manual_work_the_controller_reported():
    ctrl = _Controller()
    backend = ExecutiveBackend(ctrl, _Desk())
    srv = HmiServer(backend, "127.0.0.1", 0, poll_period_s=0.05, shutdown_poll_s=0.05).start()
    try:
        assert state(srv.url)["manual"] == [] and get(srv.url, "/api/manual").json == {"manual": []}
        # a report followed at once by the next task: between two polls, yet collected (the state listener)
        ctrl.set(process=SPRAYING, phase="running", action_type="SPRAY_AREA", task="urn:t1", detail="")
        ctrl.set(phase="reporting", detail=AREA_1)
        ctrl.set(phase="starting", task="urn:t2")
        ctrl.set(phase="reporting", detail=AREA_1)                           # reported again: not doubled
        doc = wait_state(srv.url, lambda d: d["manual"])
        assert short(doc["manual"]) == [("area", "spray", "wall_1_area_1", 3, [1.2, 1.8], [0.0, 2.5], "")]
        r = get(srv.url, "/api/manual")
        assert r.status == 200 and r.json == {"manual": doc["manual"]}
        assert any(e["path"] == "/api/manual" for e in get(srv.url, "/api").json["endpoints"])
    finally:
        srv.close()


def test_a_controller_without_state_listeners_is_read_when_polled():
    class Polled:
        def __init__(self):
            self.st = report("TAPE_LINE", "urn:t1", JOINT_3, TAPING)

        def state(self):
            return dict(self.st)

    backend = ExecutiveBackend(Polled(), _Desk())
    assert backend.manual_work() == []
    backend.snapshot()
    assert [m["part"] for m in backend.manual_work()] == [1, 2]


def test_a_backend_without_manual_work_gives_an_empty_list(server):
    assert get(server.url, "/api/manual").json == {"manual": []}
    assert state(server.url)["manual"] == []


# -- the real operator_hmi node, fed over ROS, in a real browser ---------------------------------------------------
def _feed(ros, states):
    """HICEM's states published on /hicem/state, one after the other at once, by the HICEM test double."""
    args = json.dumps({"states": states}).replace("'", "''")                   # YAML single-quoted
    done = subprocess.run(["rosservice", "call", "/hicem/feed_states", "args: '%s'" % args], env=ros.env,
                          capture_output=True, text=True, timeout=30)
    assert "success: True" in done.stdout, done.stdout + done.stderr


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh (ROS + catkin workspace)")
@pytest.mark.skipif(ON_UBUNTU and not os.path.exists(CHROMIUM),
                    reason="platform: Ubuntu 20.04 has no Debian chromium package at /usr/bin/chromium")
def test_the_page_lists_the_manual_work_as_tasks_report(ros, browser, tmp_path):  # noqa: F811
    from selenium.common.exceptions import StaleElementReferenceException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    here = os.path.dirname(os.path.abspath(__file__))
    ros.spawn([sys.executable, os.path.join(here, "fake_hicem_ros_node.py"), "_log:=%s" % (tmp_path / "calls.jsonl")],
              "fake_hicem")
    ros.wait_for_service("/hicem/feed_states", 30)
    port = free_port()
    node = ros.spawn(["rosrun", "locem_bridge", "operator_hmi", "_mode:=web", "_port:=%d" % port,
                      "_sim_picture_period:=0"], "operator_hmi")
    url = "http://127.0.0.1:%d/" % port
    wait_for(lambda: serving(url) or node.poll() is not None, 60, "the operator_hmi page")
    assert node.poll() is None

    def wait(cond, what):
        return WebDriverWait(browser, 15, poll_frequency=0.05,
                             ignored_exceptions=(StaleElementReferenceException,)).until(lambda d: cond(),
                                                                                         message=what)

    def rows():
        return [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
                for tr in browser.find_elements(By.CSS_SELECTOR, "#manual-table tr.manual-row")]

    browser.get(url)
    wait(lambda: browser.find_element(By.ID, "connection").text == "live", "the event stream to connect")
    assert browser.find_element(By.ID, "manual-list").text == "no manual work"
    assert browser.find_element(By.ID, "manual-count").text == "0"

    # a spraying process: area 1 reports a part (and, PEMKRE away for a moment, the same report once more), area 2
    # fails part-way, RECOVER, area 2 is worked again and reports its parts; the next state follows each at once
    run = {"process": SPRAYING, "specific_process": "urn:fake:spray", "action_type": "SPRAY_AREA", "tree": "",
           "node": "", "path": ""}
    _feed(ros, [dict(run, phase="starting", task="urn:fake:t1", detail=""),
                {"phase": "running", "tree": "SPRAY_AREA", "node": "spray_section"},
                {"phase": "reporting", "detail": AREA_1},
                {"phase": "waiting_for_pemkre", "detail": "PEMKRE set_task_status failed: /pemkre did not answer"},
                {"phase": "reporting", "detail": AREA_1},
                {"phase": "starting", "task": "urn:fake:t2"},
                {"phase": "reporting", "detail": "failed: compressor link lost"},
                {"phase": "running", "action_type": "RECOVER", "task": "urn:fake:t3", "tree": "RECOVER"},
                {"phase": "running", "action_type": "SPRAY_AREA", "task": "urn:fake:t4", "tree": "SPRAY_AREA"},
                {"phase": "reporting", "detail": AREA_2},
                {"phase": "ended", "action_type": "", "task": "", "tree": "", "node": "", "detail": "done"}])
    wait(lambda: len(rows()) == 3, "the three parts of the spraying process")
    assert rows() == [["spray", "wall_1_area_1", "section 3", "1.2–1.8 m", "0–2.5 m", "–"],
                      ["spray", "wall_1_area_2", "section 1", "0–0.6 m", "2.2–2.5 m", "–"],
                      ["spray", "wall_1_area_2", "section 4", "1.8–2.4 m", "0–0.3 m", "–"]]
    assert browser.find_element(By.ID, "manual-count").text == "3"
    assert not browser.find_elements(By.ID, "no-manual")

    # taping reports a joint's parts with their reasons; sanding reports the area it could not reach either
    _feed(ros, [{"process": TAPING, "specific_process": "urn:fake:tape", "phase": "running", "action_type": "TAPE_LINE",
                 "task": "urn:fake:t5", "tree": "TAPE_LINE", "detail": ""},
                {"phase": "reporting", "detail": JOINT_3},
                {"process": SANDING, "specific_process": "urn:fake:sand", "phase": "running",
                 "action_type": "SAND_AREA", "task": "urn:fake:t6", "tree": "SAND_AREA"},
                {"phase": "reporting", "detail": AREA_1.replace("sprayed", "sanded")},
                {"phase": "ended", "action_type": "", "task": "", "tree": "", "detail": "done"}])
    wait(lambda: len(rows()) == 6, "the parts of the taping and sanding processes too")
    assert rows()[3:] == [["tape", "wall_1_joint_3", "part 1", "0–0.42 m", "–", "near a corner"],
                          ["tape", "wall_1_joint_3", "part 2", "2.1–2.5 m", "–", "above the tool's height band"],
                          ["sand", "wall_1_area_1", "section 3", "1.2–1.8 m", "0–2.5 m", "–"]]
    assert browser.find_element(By.ID, "manual-count").text == "6"
    row = browser.find_element(By.CSS_SELECTOR, '#manual-table tr[data-feature="wall_1_joint_3"][data-part="2"]')
    assert row.get_attribute("data-kind") == "joint" and row.get_attribute("data-work") == "tape"
    assert browser.save_screenshot(str(tmp_path / "operator_hmi_manual_work.png"))

    # the same list for other tools
    manual = get(url, "/api/manual").json["manual"]
    assert short(manual) == [
        ("area", "spray", "wall_1_area_1", 3, [1.2, 1.8], [0.0, 2.5], ""),
        ("area", "spray", "wall_1_area_2", 1, [0.0, 0.6], [2.2, 2.5], ""),
        ("area", "spray", "wall_1_area_2", 4, [1.8, 2.4], [0.0, 0.3], ""),
        ("joint", "tape", "wall_1_joint_3", 1, [0.0, 0.42], None, "near a corner"),
        ("joint", "tape", "wall_1_joint_3", 2, [2.1, 2.5], None, "above the tool's height band"),
        ("area", "sand", "wall_1_area_1", 3, [1.2, 1.8], [0.0, 2.5], "")]
    assert [m["process"] for m in manual] == [SPRAYING] * 3 + [TAPING] * 2 + [SANDING]
    assert manual[2]["task"] == "urn:fake:t4" and manual[5]["task"] == "urn:fake:t6"
    assert state(url)["manual"] == manual
    severe = [e["message"] for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert severe == [], severe
