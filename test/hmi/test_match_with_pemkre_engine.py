"""The page's skill matching (GET /api/match) over the REAL PEMKRE engine with a robot's resource model (the
fixture test/pemkre/data/three_robots.ttl): per task the skill or template PEMKRE chose and the rejected
candidates with PEMKRE's reasons, a process that robot cannot run with why, and PEMKRE without a resource model
refusing (shown as a refusal, not an error of the page)."""
import os
import sys
from urllib.parse import quote

import pytest
from rdflib import Graph

pemkre = pytest.importorskip("locem_bridge.pemkre")

_HICEM_TESTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "hicem")
if _HICEM_TESTS not in sys.path:
    sys.path.insert(0, _HICEM_TESTS)

from hicem_doubles import LocemDouble  # noqa: E402
from hmi_client import get  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.pemkre_local import EngineClient  # noqa: E402
from locem_bridge.hmi import ExecutiveBackend, HmiServer  # noqa: E402
from locem_bridge.pemkre import PLB  # noqa: E402

FIXTURE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "pemkre", "data",
                       "three_robots.ttl")
ROBOT_NS = "https://locem-bridge.example.org/robot/%s/"
PROCESSES = [{"iri": str(PLB[p]), "name": p} for p in ("TapingProcess", "SprayingProcess", "SandingProcess")]


def model_of(name):
    g = Graph()
    for s, p, o in Graph().parse(FIXTURE):
        if str(s).startswith(ROBOT_NS % name):
            g.add((s, p, o))
    return g


@pytest.fixture
def page(tmp_path):
    """``open(robot or None)`` -> the HMI server's URL over an executive whose PEMKRE has that robot's model."""
    opened = []

    def open_page(robot):
        store = pemkre.JournaledStore(str(tmp_path / ("db_%s" % robot)))
        engine = pemkre.ProcessEngine(store, resource_model=model_of(robot) if robot else None)
        ex = create_executive(EngineClient(engine), LocemDouble(), None)
        backend = ExecutiveBackend.for_executive(ex, processes=PROCESSES,
                                                 match=lambda iri: engine.match_process(iri).to_dict())
        srv = HmiServer(backend, "127.0.0.1", 0, poll_period_s=0.05, shutdown_poll_s=0.05).start()
        opened.append((srv, ex, store))
        return srv.url

    yield open_page
    for srv, ex, store in opened:
        srv.close()
        ex.close()
        store.close()


def match(url, process):
    r = get(url, "/api/match?process=" + quote(str(PLB[process]), safe=""))
    assert r.status == 200, r
    return r.json["match"]


def test_the_tool_changer_robot_shows_the_template_and_why_the_operator_tree_is_not_used(page):
    view = match(page("diffdrive"), "TapingProcess")
    assert view["ok"] is True and view["robot_name"] == "diffdrive"
    tasks = {t["action_type"]: t for t in view["tasks"]}
    get_tool = tasks["GET_TOOL"]
    assert get_tool["capability"] == "cap_GetTool"
    assert get_tool["chosen"]["kind"] == "template" and get_tool["chosen"]["name"] == "tmpl_getToolAutomatically"
    assert [(s["name"], s["kind"], s["arguments"]) for s in get_tool["chosen"]["steps"]] == [
        ("WALL_READY", "basic", ""), ("CHANGE_TOOL", "basic", "tool={tool}")]
    assert get_tool["rejected"] == [{"name": "GET_TOOL", "kind": "composite",
                                     "reason": "uses MOUNT_TOOL, not offered by this robot"}]
    assert (tasks["TAPE_LINE"]["chosen"]["name"], tasks["TAPE_LINE"]["chosen"]["kind"]) == ("TAPE_LINE", "composite")
    scan = tasks["SCAN"]
    assert scan["chosen"]["kind"] == "composite" and scan["rejected"][0]["kind"] == "basic"
    assert "does not realize plb:cap_ScanWalls" in scan["rejected"][0]["reason"]


def test_a_process_the_robot_cannot_run_names_each_task_and_why(page):
    view = match(page("bare"), "SandingProcess")
    assert view["ok"] is False
    bad = {t["action_type"]: t for t in view["tasks"] if not t["ok"]}
    assert set(bad) == {"GET_TOOL", "SAND_AREA"}
    assert bad["SAND_AREA"]["chosen"] is None and "no skill of this robot realizes plb:cap_SandArea" in \
        bad["SAND_AREA"]["problem"]
    assert "tool absent" in bad["GET_TOOL"]["problem"] and "sander" in bad["GET_TOOL"]["problem"]


def test_pemkre_without_a_resource_model_refuses_and_the_page_says_so(page):
    url = page(None)
    r = get(url, "/api/match?process=" + quote(str(PLB.TapingProcess), safe=""))
    assert r.status == 409 and r.error["code"] == "refused"
    assert "no resource model is loaded" in r.error["message"]
