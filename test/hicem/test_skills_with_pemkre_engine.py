"""HICEM runs what the real PEMKRE engine matched (docs/contracts.md, the next action's ``skill``): on a robot
with an automatic tool changer (the resource model of test/pemkre/data/three_robots.ttl, robot ``diffdrive``:
CHANGE_TOOL instead of MOUNT_TOOL, no GET_TOOL tree) PEMKRE expands GetToolTask with the template
plb:tmpl_getToolAutomatically into two subtasks realized by basic skills, which HICEM runs through
trees/BASIC_SKILL.xml as the LOCEM commands ``WALL_READY`` and ``CHANGE_TOOL tool=taping_tool`` (no operator
prompt); every other task runs its composite skill's tree. On the robot whose operator mounts tools (``kairos``)
the same process runs the GET_TOOL tree with its prompt. LOCEM is HICEM's LOCEM test double."""
import os

import pytest
from rdflib import Graph, URIRef

pemkre = pytest.importorskip("locem_bridge.pemkre")

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble  # noqa: E402
from hicem_rig import params  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.pemkre_local import EngineClient  # noqa: E402
from locem_bridge.pemkre import PLB  # noqa: E402

FIXTURE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "pemkre", "data",
                       "three_robots.ttl")
ROBOT_NS = "https://locem-bridge.example.org/robot/%s/"


def model_of(name: str) -> Graph:
    """The fixture's resource model of one robot."""
    g = Graph()
    for s, p, o in Graph().parse(FIXTURE):
        if str(s).startswith(ROBOT_NS % name):
            g.add((s, p, o))
    return g


def run(tmp_path, robot):
    store = pemkre.JournaledStore(str(tmp_path / "pemkre_db"))
    engine = pemkre.ProcessEngine(store, resource_model=model_of(robot), robot=ROBOT_NS % robot + "robot")
    locem = LocemDouble()
    ex = create_executive(EngineClient(engine), locem, str(tmp_path / "hdict.sqlite"), params=params())
    states = []
    ex.controller.add_state_listener(states.append)
    op = AutoOperator(ex.controller, {"mount_tool": "done", "validate_line": "valid", "manual_taping": "done"})
    ex.operator.add_listener(op)
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    try:
        phase = ex.controller.run_process(str(PLB.TapingProcess), {"validateLines": False})
        log = [(str(r["actionType"]), str(r["status"]), str(r.get("detail") or ""))
               for r in engine.query("task_log", {"process": URIRef(engine.current_process())}).rows]
        return phase, locem, states, op, log, ex.controller.state()
    finally:
        beats.stop()
        ex.close()
        store.close()


def test_the_tool_changer_robot_runs_the_get_tool_template_as_basic_skills(tmp_path):
    phase, locem, states, op, log, last = run(tmp_path, "diffdrive")
    assert phase == "ended", last
    # the template's two subtasks: the commands composed by BASIC_SKILL reach LOCEM, in order, after the scan
    assert locem.sent[:3] == ["SCAN", "WALL_READY", "CHANGE_TOOL tool=taping_tool"]
    assert "MOUNT_TOOL" not in " ".join(locem.sent) and op.asked == []        # no operator intervention
    basic = [(s["action_type"], s["skill"]) for s in states if s["tree"] == "BASIC_SKILL" and s["phase"] == "running"]
    assert sorted(set(basic)) == [("CHANGE_TOOL", "CHANGE_TOOL"), ("WALL_READY", "WALL_READY")]
    # the composite skills run their own trees
    assert any(s["tree"] == "TAPE_LINE" and s["skill"] == "TAPE_LINE" for s in states)
    assert len([c for c in locem.sent if c.startswith("APPLY_TAPE ")]) == 4   # the 2 m horizontal joint in two
    # PEMKRE's log: both steps succeeded with the command HICEM sent as their detail
    assert ("CHANGE_TOOL", "succeeded", "CHANGE_TOOL tool=taping_tool") in log
    assert ("WALL_READY", "succeeded", "WALL_READY") in log


def test_the_operator_robot_runs_the_get_tool_tree_for_the_same_process(tmp_path):
    phase, locem, states, op, log, last = run(tmp_path, "kairos")
    assert phase == "ended", last
    assert "MOUNT_TOOL taping_tool" in locem.sent and "CHANGE_TOOL" not in " ".join(locem.sent)
    assert op.asked == ["mount_tool"]
    assert any(s["tree"] == "GET_TOOL" and s["skill"] == "GET_TOOL" for s in states)
    assert not any(s["tree"] == "BASIC_SKILL" for s in states)
