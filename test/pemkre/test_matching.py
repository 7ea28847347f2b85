"""Capability matching in PEMKRE: each task of a process matched to a skill the robot offers, explained.

The resource model is the hand-written fixture data/three_robots.ttl (the shape skills/ generates): ``kairos``
(the operator changes tools: the GET_TOOL tree), ``diffdrive`` (an automatic tool changer: GET_TOOL is expanded by
plb:tmpl_getToolAutomatically into WALL_READY, CHANGE_TOOL) and ``bare`` (no compressor, no sander, a GET_TOOL
tree for the taping tool only). Engines run on real on-disk stores with the shipped ontologies.
"""
import json
import os

import pytest
from pemkre_testkit import DATA, FakeClock, quads_snapshot, scan_result
from rdflib import Graph, Literal, URIRef
from rdflib.namespace import RDF

from locem_bridge.pemkre import PLB, PPR, JournaledStore, ProcessEngine, compute_kpis
from locem_bridge.pemkre.errors import InvalidParameterError, PemkreError, TaskStateError, UnmatchableProcessError
from locem_bridge.pemkre.vocab import SK

ROBOT_NS = "https://locem-bridge.example.org/robot/%s/"
_FIXTURE = Graph().parse(os.path.join(DATA, "three_robots.ttl"))


def robot(name: str) -> str:
    return ROBOT_NS % name + "robot"


def model_of(*names: str) -> Graph:
    """The fixture's triples about the named robots (each robot's resource model)."""
    g = Graph()
    for s, p, o in _FIXTURE:
        if any(str(s).startswith(ROBOT_NS % n) for n in names):
            g.add((s, p, o))
    return g


def node(pm, local: str):
    return pm.node(str(PLB[local]))


def test_the_same_process_matches_differently_on_two_robots_sharing_one_store(make_engine):
    e = make_engine(resource_model=model_of("kairos", "diffdrive"), robot=robot("diffdrive"))
    changer = e.match_process(str(PLB.TapingProcess))
    assert changer.ok and changer.robot == robot("diffdrive")
    get_tool = node(changer, "taping_getTool")
    assert get_tool.capability == str(PLB.cap_GetTool)
    real = get_tool.realization
    assert real.kind == "template" and real.template == str(PLB.tmpl_getToolAutomatically)
    assert [(s.index, s.name, s.skill_kind) for s in real.steps] == [(1, "WALL_READY", "basic"),
                                                                     (2, "CHANGE_TOOL", "basic")]
    assert real.steps[1].arguments == [("tool", "{tool}")] and not real.involves_operator
    assert [(r.name, r.kind, r.reason) for r in get_tool.rejected] == [
        ("GET_TOOL", "composite", "uses MOUNT_TOOL, not offered by this robot")]
    tape = node(changer, "taping_tape").realization
    assert (tape.kind, tape.name, tape.skill_kind) == ("skill", "TAPE_LINE", "composite")

    e.load_resource_model(model_of("kairos", "diffdrive"), robot=robot("kairos"))
    operator = e.match_process(str(PLB.TapingProcess))
    assert operator.ok and operator.robot == robot("kairos")
    get_tool = node(operator, "taping_getTool")
    real = get_tool.realization
    assert (real.kind, real.name, real.skill_kind, real.involves_operator) == ("skill", "GET_TOOL", "composite", True)
    assert real.skill == ROBOT_NS % "kairos" + "skill_tree_GET_TOOL"
    assert [(r.name, r.kind, r.reason) for r in get_tool.rejected] == [
        ("tmpl_getToolAutomatically", "template",
         "step 2: no skill of this robot realizes sk:cap_ChangeToolAutomatically")]
    # the SCAN command is named like the action type but realizes the device capability, not plb:cap_ScanWalls
    scan = node(operator, "taping_scan")
    assert scan.realization.skill_kind == "composite"
    assert [(r.name, r.kind, r.reason) for r in scan.rejected] == [
        ("SCAN", "basic", "does not realize plb:cap_ScanWalls (it realizes sk:cap_DetectWallFeatures)")]
    data = json.loads(json.dumps(operator.to_dict()))      # the /pemkre/match answer is this, as JSON
    assert data["ok"] and {n["action_type"] for n in data["nodes"]} >= {"GET_TOOL", "SCAN", "TAPE_LINE", "GO_HOME"}


def test_ranking_single_automatic_skill_then_template_then_operator(make_engine):
    g = model_of("kairos")
    k = ROBOT_NS % "kairos"
    changer = URIRef(k + "skill_CHANGE_TOOL")          # kairos gets a tool changer as well
    for t in [(changer, RDF.type, SK.BasicSkill), (changer, SK.skillName, Literal("CHANGE_TOOL")),
              (changer, SK.realizesCapability, SK.cap_ChangeToolAutomatically),
              (changer, SK.usesDevice, URIRef(k + "device_arm")), (URIRef(robot("kairos")), SK.providesSkill, changer)]:
        g.add(t)
    e = make_engine(resource_model=g)
    get_tool = node(e.match_process(str(PLB.SandingProcess)), "sanding_getTool")
    assert get_tool.realization.kind == "template"
    assert [(r.name, r.reason) for r in get_tool.rejected] == [
        ("GET_TOOL", "needs the operator; an automatic realization exists (template tmpl_getToolAutomatically)")]

    auto = URIRef(k + "skill_tree_AUTO_GET_TOOL")      # ... and a tree that gets tools on its own
    for t in [(auto, RDF.type, SK.CompositeSkill), (auto, SK.skillName, Literal("AUTO_GET_TOOL")),
              (auto, SK.involvesOperator, Literal(False)), (auto, SK.realizesCapability, PLB.cap_GetTool),
              (URIRef(robot("kairos")), SK.providesSkill, auto)]:
        g.add(t)
    e.load_resource_model(g)
    get_tool = node(e.match_process(str(PLB.SandingProcess)), "sanding_getTool")
    assert (get_tool.realization.kind, get_tool.realization.name) == ("skill", "AUTO_GET_TOOL")
    assert sorted((r.name, r.reason) for r in get_tool.rejected) == [
        ("GET_TOOL", "needs the operator; an automatic realization exists (AUTO_GET_TOOL)"),
        ("tmpl_getToolAutomatically", "a single skill realizes the task (AUTO_GET_TOOL)")]


def test_an_unmatchable_process_is_refused_with_every_reason_and_nothing_is_written(make_engine):
    e = make_engine(resource_model=model_of("kairos", "bare"), robot=robot("bare"))
    e.update_world(scan_result(joints_per_wall=1, areas_per_wall=1))
    before = quads_snapshot(e.store)
    with pytest.raises(UnmatchableProcessError) as info:
        e.start_process(str(PLB.SandingProcess))
    msg = str(info.value)
    assert isinstance(info.value, PemkreError) and info.value.code == "UNMATCHABLE_PROCESS"
    assert "sanding_getTool" in msg and "tool absent: parameter 'tool' binds sander" in msg
    assert "sanding_sand" in msg and "no skill of this robot realizes plb:cap_SandArea" in msg
    assert "sanding_scan" not in msg                   # the tasks that match are not blamed
    assert not info.value.match.ok

    with pytest.raises(UnmatchableProcessError) as info:
        e.start_process(str(PLB.SprayingProcess))
    msg = str(info.value)
    assert "parameter 'tool' value 'spray_gun' is not among the allowed values: taping_tool" in msg
    assert "SPRAY_AREA: uses device device_compressor, which this robot does not have" in msg
    assert quads_snapshot(e.store) == before and e.active_process() is None
    with pytest.raises(TaskStateError):
        e.next_action()
    assert e.start_process(str(PLB.TapingProcess))       # the robot can tape


def _step(e, status="succeeded", detail=""):
    a = e.next_action()
    assert a.status == "action", a
    e.set_task_status(a.task, "in_progress")
    return a, e.set_task_status(a.task, status, detail)


def _log(e, sp):
    return [(int(r["seq"].toPython()), str(r["actionType"]), str(r["status"]),
             str(r["skill"]) if r.get("skill") is not None else "",
             int(str(r["expandedFrom"]).rsplit("_", 1)[1]) if r.get("expandedFrom") is not None else 0)
            for r in e.query("task_log", {"process": URIRef(sp)}).rows]


def test_a_template_expands_the_task_into_ordered_subtasks_in_the_log_and_applies_its_effect_once(make_engine):
    e = make_engine(resource_model=model_of("diffdrive"))
    e.update_world(scan_result(joints_per_wall=1))
    sp = e.start_process(str(PLB.TapingProcess), {"validateLines": False})
    a, report = _step(e)
    assert (a.action_type, a.skill, a.skill_kind, a.params()) == ("WALL_READY", "WALL_READY", "basic", {})
    assert report.effects_applied == 0 and e.check_consistency() == []
    parent = URIRef(sp + "_task_1")
    assert e.store.value(parent, PPR.mountedTool) is None
    a = e.next_action()
    assert (a.action_type, a.skill, a.skill_kind, a.params()) == ("CHANGE_TOOL", "CHANGE_TOOL", "basic",
                                                                  {"tool": "taping_tool"})
    assert e.next_action() == a                          # asked again: the same step, nothing new issued
    e.set_task_status(a.task, "in_progress")
    assert e.check_consistency() == []                   # the parent is in progress while its step runs
    report = e.set_task_status(a.task, "succeeded")
    assert report.effects_applied == 1                   # the task's effect, once, when the last step succeeded
    tools = e.store.objects(URIRef(robot("diffdrive")), PPR.mountedTool)
    assert tools == [URIRef(ROBOT_NS % "diffdrive" + "taping_tool")]
    a, _ = _step(e)
    assert (a.action_type, a.skill, a.skill_kind) == ("TAPE_LINE", "TAPE_LINE", "composite")
    _step(e)
    assert e.next_action().status == "ended"
    assert _log(e, sp) == [(1, "GET_TOOL", "succeeded", "", 0),
                           (2, "WALL_READY", "succeeded", "WALL_READY", 1),
                           (3, "CHANGE_TOOL", "succeeded", "CHANGE_TOOL", 1),
                           (4, "TAPE_LINE", "succeeded", "TAPE_LINE", 0),
                           (5, "GO_HOME", "succeeded", "GO_HOME", 0)]
    assert e.check_consistency(full_inference=True) == []


def test_a_failed_step_fails_its_task_and_the_process_without_the_effect(make_engine):
    e = make_engine(resource_model=model_of("diffdrive"))
    e.update_world(scan_result(areas_per_wall=1))
    sp = e.start_process(str(PLB.SprayingProcess))
    _step(e)
    a, report = _step(e, "failed", "changer fault")
    assert a.skill == "CHANGE_TOOL" and report.effects_applied == 0
    end = e.next_action()
    assert end.status == "failed" and "changer fault" in end.message
    assert _log(e, sp)[:3] == [(1, "GET_TOOL", "failed", "", 0), (2, "WALL_READY", "succeeded", "WALL_READY", 1),
                               (3, "CHANGE_TOOL", "failed", "CHANGE_TOOL", 1)]
    detail = e.store.value(URIRef(sp + "_task_1"), URIRef("https://locem-bridge.example.org/ont/process#detail"))
    assert str(detail) == "step 2 (CHANGE_TOOL) failed: changer fault"
    assert e.store.value(URIRef(robot("diffdrive")), PPR.mountedTool) is None
    assert e.check_consistency() == []


def test_a_restart_between_two_steps_continues_with_the_next_step(tmp_path):
    path = str(tmp_path / "db")
    clock = FakeClock()
    store = JournaledStore(path)
    e = ProcessEngine(store, clock=clock, resource_model=model_of("diffdrive"))
    e.update_world(scan_result(joints_per_wall=1))
    e.start_process(str(PLB.TapingProcess), {"validateLines": False})
    first, _ = _step(e)
    store.close()
    store = JournaledStore(path)
    try:
        e = ProcessEngine(store, clock=clock, resource_model=model_of("diffdrive"))
        a = e.next_action()
        assert (a.skill, a.params(), int(a.task.rsplit("_", 1)[1])) == ("CHANGE_TOOL", {"tool": "taping_tool"}, 3)
    finally:
        store.close()


def _run(e, validate=False):
    sp = e.start_process(str(PLB.TapingProcess), {"validateLines": validate})
    for _ in range(30):
        a = e.next_action()
        if a.status != "action":
            break
        e.set_task_status(a.task, "in_progress")
        e.set_task_status(a.task, "succeeded", "valid" if a.action_type == "VALIDATE_TAPE_LINE" else "")
    return compute_kpis(e, sp)


def test_operator_interventions_count_the_realized_skill(make_engine):
    kpis = {}
    for name in ("kairos", "diffdrive"):
        e = make_engine(name, resource_model=model_of(name))
        e.update_world(scan_result(joints_per_wall=2))
        kpis[name] = _run(e, validate=True)
    for name, k in kpis.items():
        (proc,) = k["processes"]
        by_type = {r["actionType"]: r for r in k["task_types"]}
        assert proc["status"] == "ended" and proc["count"] == 1 + 2 + 2 + 1   # tool, 2 validations, 2 tapings, home
        assert by_type["VALIDATE_TAPE_LINE"]["operatorInterventions"] == 2
        assert by_type["GET_TOOL"]["count"] == 1          # the steps are not tasks of their own
    assert {r["actionType"]: r["operatorInterventions"] for r in kpis["kairos"]["task_types"]}["GET_TOOL"] == 1
    assert {r["actionType"]: r["operatorInterventions"] for r in kpis["diffdrive"]["task_types"]}["GET_TOOL"] == 0
    assert kpis["kairos"]["processes"][0]["operatorInterventions"] == 3
    assert kpis["diffdrive"]["processes"][0]["operatorInterventions"] == 2


def test_next_action_names_the_matched_skill_and_without_a_model_none(make_engine):
    e = make_engine(resource_model=model_of("kairos"))
    e.update_world(scan_result(joints_per_wall=1))
    e.start_process(str(PLB.TapingProcess), {"validateLines": False})
    a = e.next_action()
    assert (a.action_type, a.skill, a.skill_kind) == ("GET_TOOL", "GET_TOOL", "composite")
    assert e.next_action().skill == "GET_TOOL"           # the stored answer names it too
    plain = make_engine("plain")
    plain.update_world(scan_result(joints_per_wall=1))
    plain.start_process(str(PLB.TapingProcess), {"validateLines": False})
    a = plain.next_action()
    assert (a.action_type, a.skill, a.skill_kind) == ("GET_TOOL", "", "")
    assert not plain.matching
    with pytest.raises(TaskStateError):
        plain.match_process(str(PLB.TapingProcess))


def test_loading_the_model_again_writes_nothing_and_bad_input_is_refused(make_engine):
    e = make_engine(resource_model=model_of("kairos"))
    before = quads_snapshot(e.store)
    assert e.load_resource_model(model_of("kairos")) == len(model_of("kairos"))
    assert quads_snapshot(e.store) == before
    with pytest.raises(InvalidParameterError):
        e.load_resource_model("kairos.ttl")              # type: ignore[arg-type]
    assert quads_snapshot(e.store) == before
    e.load_resource_model(model_of("diffdrive"))         # replaces kairos: its skills are gone from the store
    assert e.store.value(URIRef(robot("kairos")), SK.providesSkill) is None
    assert e.match_process(str(PLB.TapingProcess)).robot == robot("diffdrive")


def test_the_shipped_robot_model_matches_every_shipped_process(make_engine):
    from locem_bridge.skills import build_resource_model

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    g = build_resource_model(os.path.join(root, "config", "robots", "rbkairos_ur10e.yaml")).to_graph()
    e = make_engine(resource_model=g)
    for process in (PLB.TapingProcess, PLB.SprayingProcess, PLB.SandingProcess):
        pm = e.match_process(str(process))
        assert pm.ok, pm.problems()
        assert pm.robot.endswith("/robot/rbkairos_ur10e/robot")
        for n in pm.nodes:                               # every task runs the tree named like its action type
            assert (n.realization.kind, n.realization.name, n.realization.skill_kind) == (
                "skill", n.action_type, "composite"), n
    get_tool = node(e.match_process(str(PLB.TapingProcess)), "taping_getTool")
    assert get_tool.realization.involves_operator
    assert [(r.name, r.reason) for r in get_tool.rejected] == [
        ("tmpl_getToolAutomatically", "step 2: no skill of this robot realizes sk:cap_ChangeToolAutomatically")]


def test_the_shipped_robot_with_a_tool_changer_gets_its_tools_through_the_template(make_engine):
    import yaml
    from locem_bridge.skills import build_resource_model

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(root, "test", "data", "tool_changer_rack.yaml")) as handle:
        overrides = yaml.safe_load(handle)                # the tests' tool changer section on the shipped robot
    g = build_resource_model(os.path.join(root, "config", "robots", "rbkairos_ur10e.yaml"),
                             overrides=overrides).to_graph()
    e = make_engine(resource_model=g)
    pm = e.match_process(str(PLB.SprayingProcess))
    assert pm.ok, pm.problems()
    get_tool = node(pm, "spraying_getTool")
    assert [(s.name, s.skill_kind, s.arguments) for s in get_tool.realization.steps] == [
        ("WALL_READY", "basic", []), ("CHANGE_TOOL", "basic", [("tool", "{tool}")])]
    assert [(r.name, r.kind) for r in get_tool.rejected] == [("GET_TOOL", "composite")]
    assert "MOUNT_TOOL" in get_tool.rejected[0].reason
    e.update_world(scan_result(areas_per_wall=1))
    e.start_process(str(PLB.SprayingProcess))
    steps = []
    for _ in range(2):
        a, _ = _step(e)
        steps.append((a.skill, a.skill_kind, a.params()))
    assert steps == [("WALL_READY", "basic", {}), ("CHANGE_TOOL", "basic", {"tool": "spray_gun"})]
    a = e.next_action()
    assert (a.action_type, a.skill, a.skill_kind) == ("SPRAY_AREA", "SPRAY_AREA", "composite")
    assert e.store.objects(URIRef(pm.robot), PPR.mountedTool) == [URIRef(pm.robot[:-len("robot")] + "spray_gun")]


def test_a_restarted_engine_resumes_the_stored_model_of_the_same_key(tmp_path):
    path = str(tmp_path / "db")
    store = JournaledStore(path)
    e = ProcessEngine(store)
    e.load_resource_model(model_of("diffdrive"), key="inputs-1")
    store.close()
    store = JournaledStore(path)
    try:
        e = ProcessEngine(store)
        assert not e.resume_resource_model("inputs-2") and not e.matching    # other inputs: build it again
        assert e.resume_resource_model("inputs-1") and e.matching
        real = node(e.match_process(str(PLB.TapingProcess)), "taping_getTool").realization
        assert real.kind == "template"
    finally:
        store.close()


def test_a_recover_task_whose_tree_may_prompt_is_no_operator_intervention(make_engine):
    e = make_engine(resource_model=model_of("kairos"))
    e.update_world(scan_result(areas_per_wall=1))
    sp = e.start_process(str(PLB.SprayingProcess))
    seen = []
    for _ in range(10):
        a = e.next_action()
        if a.status != "action":
            break
        seen.append(a.action_type)
        e.set_task_status(a.task, "in_progress")
        failed = a.action_type == "SPRAY_AREA" and seen.count("SPRAY_AREA") == 1
        e.set_task_status(a.task, "failed" if failed else "succeeded", "compressor link lost" if failed else "")
    assert seen == ["GET_TOOL", "SPRAY_AREA", "RECOVER", "SPRAY_AREA", "GO_HOME"]
    by_type = {r["actionType"]: r["operatorInterventions"] for r in compute_kpis(e, sp)["task_types"]}
    assert by_type == {"GET_TOOL": 1, "SPRAY_AREA": 0, "RECOVER": 0, "GO_HOME": 0}
