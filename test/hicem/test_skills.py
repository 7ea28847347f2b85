"""HICEM runs the skill PEMKRE matched (docs/contracts.md, "PEMKRE next action": ``skill``, ``skill_kind``):
a composite skill's tree whatever the action type, a basic skill through the generic tree trees/BASIC_SKILL.xml
(one LOCEM command composed from the skill and the task parameters: against the LOCEM test double, and against
the real LOCEM core driving the compressor stand-in over Modbus), the skill kept in the HDICT so a resumed
action runs the same tree, and values that cannot be one command word refused before anything is sent."""
import os
import re
import time

import pytest
from py_trees.common import Status

from hicem_doubles import SITE, PemkreDouble
from hicem_rig import TREES, System
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.controller import HHLC, TASKS
from locem_bridge.hicem.errors import HicemError
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.nodes.generic import compose_skill_command
from locem_bridge.hicem.xml_loader import TreeLibrary

P = PemkreDouble.PROCESS
MOUNT = {"GET_TOOL": ("MOUNT_TOOL", "basic")}


def _system(tmp_path, skills, **kw):
    return System(tmp_path, pemkre=PemkreDouble(skills=skills, **kw))


def test_the_basic_skill_tree_file_is_documented():
    text = open(os.path.join(TREES, "BASIC_SKILL.xml"), encoding="utf-8").read()
    header = re.search(r"<!--(.*?)-->", text, re.S).group(1).strip()
    assert header.startswith("BASIC_SKILL:") and "param_*" in header and "task_detail" in header


def test_a_basic_skill_runs_the_generic_tree_with_the_composed_command(tmp_path):
    s = _system(tmp_path, MOUNT)
    try:
        assert s.ctrl.run_process(P) == "ended"
        # GET_TOOL realized by the basic skill MOUNT_TOOL: one command, no drive to the station, no prompt
        get_tool = s.pemkre.executed("GET_TOOL")
        assert [(g[2], g[3]) for g in get_tool] == [("succeeded", "MOUNT_TOOL tool=taping_tool")]
        assert s.locem.sent[:2] == ["SCAN", "MOUNT_TOOL tool=taping_tool"]
        assert "mount_tool" not in s.operator.asked
        assert any(st["tree"] == "BASIC_SKILL" and st["skill"] == "MOUNT_TOOL" and st["action_type"] == "GET_TOOL"
                   for st in s.states)
        # the other tasks name no skill: their action type's tree, as before
        assert any(st["tree"] == "TAPE_LINE" and st["skill"] == "" for st in s.states)
        assert len(s.pemkre.executed("TAPE_LINE")) == 3
        task = get_tool[0][1]
        assert s.ex.store.value(TASKS, task)["skill"] == "MOUNT_TOOL"
    finally:
        s.close()


def test_a_composite_skill_runs_its_tree_not_the_action_types(tmp_path):
    # PARK has no tree of its own: PEMKRE matched it to the composite skill GO_HOME
    s = _system(tmp_path, {"PARK": ("GO_HOME", "composite")}, extra_actions=["PARK"])
    try:
        assert s.ctrl.run_process(P) == "ended"
        park = s.pemkre.executed("PARK")
        assert [p[2] for p in park] == ["succeeded"]
        assert s.locem.sent[:2] == ["SCAN", "WALL_READY"] and "HOME" in s.locem.sent[:6]
        assert any(st["tree"] == "GO_HOME" and st["action_type"] == "PARK" and st["skill"] == "GO_HOME"
                   for st in s.states)
    finally:
        s.close()


def test_a_composite_skill_without_a_tree_fails_naming_the_skill(tmp_path):
    s = _system(tmp_path, {"SCAN": ("SCAN_3D", "composite")})
    try:
        assert s.ctrl.run_process(P) == "failed"
        (scan,) = s.pemkre.executed("SCAN")
        assert scan[2] == "failed"
        assert "no behavior tree for composite skill 'SCAN_3D' (action type SCAN)" in scan[3]
        assert "BASIC_SKILL" in scan[3]            # the trees there are are listed
        assert s.locem.sent == []
    finally:
        s.close()


class _LiteralPemkre(PemkreDouble):
    """Answers GET_TOOL with a literal ``tool`` parameter (text with a space), matched to MOUNT_TOOL."""

    def _answer(self, at, task, params):
        answer = super()._answer(at, task, params)
        if at == "GET_TOOL":
            answer["parameters"] = '<%s> <http://example.org/proc#tool> "spray gun" .' % task
        return answer


def test_a_parameter_that_is_not_one_word_is_refused_before_anything_is_sent(tmp_path):
    s = System(tmp_path, pemkre=_LiteralPemkre(skills=MOUNT, after_failure="fail_process"))
    try:
        assert s.ctrl.run_process(P) == "failed"
        (get_tool,) = s.pemkre.executed("GET_TOOL")
        assert get_tool[2] == "failed"
        assert "compose" in get_tool[3] and "'tool'" in get_tool[3] and "whitespace" in get_tool[3]
        assert s.locem.sent == ["SCAN"]
    finally:
        s.close()


def test_a_resumed_basic_skill_runs_the_same_tree(tmp_path):
    s = _system(tmp_path, MOUNT)
    try:
        pem = s.pemkre
        pem.start_process(P)
        s.ex.data_handler.ingest_scan(SITE)
        pem.s["pending"] = [["GET_TOOL", {"tool": "sander"}]]
        na = pem.next_action()
        pem.set_task_status(na["task"], "in_progress")
        pem.s["home_done"] = True
        # what HICEM recorded before it died during the skill (controller._execute's record)
        s.ex.store.put(HHLC, "process", {"iri": P, "specific": "x", "state": "running"})
        s.ex.store.put(HHLC, "action", {"task": na["task"], "action_type": "GET_TOOL", "parameters": {"tool": "sander"},
                                        "raw_parameters": na["parameters"], "skill": "MOUNT_TOOL",
                                        "skill_kind": "basic", "phase": "running"})
        assert s.ctrl.resume() == "ended"            # GET_TOOL's resume policy: rerun
        assert s.locem.sent[:2] == ["STOP", "MOUNT_TOOL tool=sander"]
        assert "mount_tool" not in s.operator.asked   # not the GET_TOOL tree's operator prompt
        assert pem.executed("GET_TOOL")[0][2:4] == ["succeeded", "MOUNT_TOOL tool=sander"]
    finally:
        s.close()


@pytest.mark.parametrize("step", [("WALL_READY", {}, "WALL_READY"),
                                  ("CHANGE_TOOL", {"tool": "sander"}, "CHANGE_TOOL tool=sander")])
def test_a_template_step_a_crash_interrupted_is_run_again(tmp_path, step):
    """A template step (PEMKRE's expansion of GET_TOOL on a tool-changer robot) arrives with its basic skill as
    the action type; the shipped resume policy reruns WALL_READY and CHANGE_TOOL after a crash (both end in the
    same state when repeated), instead of failing the tool change."""
    skill, params, command = step
    s = _system(tmp_path, {skill: (skill, "basic")})
    try:
        assert s.ex.params.resume_policy[skill] == "rerun"
        pem = s.pemkre
        pem.start_process(P)
        s.ex.data_handler.ingest_scan(SITE)
        pem.s["pending"] = [[skill, params]]
        na = pem.next_action()
        pem.set_task_status(na["task"], "in_progress")
        pem.s["home_done"] = True
        s.ex.store.put(HHLC, "process", {"iri": P, "specific": "x", "state": "running"})
        s.ex.store.put(HHLC, "action", {"task": na["task"], "action_type": skill, "parameters": params,
                                        "raw_parameters": na["parameters"], "skill": skill,
                                        "skill_kind": "basic", "phase": "running"})
        assert s.ctrl.resume() == "ended"
        assert s.locem.sent[:2] == ["STOP", command]
        assert pem.executed(skill)[0][2:4] == ["succeeded", command]
    finally:
        s.close()


def test_the_hdict_records_the_skill_while_it_runs_and_with_its_outcome(tmp_path):
    s = System(tmp_path, durations={"MOUNT_TOOL": 0.5}, pemkre=PemkreDouble(skills=MOUNT, validate_lines=False))
    try:
        s.ctrl.start_process(P)
        deadline = time.monotonic() + 10
        running = None
        while time.monotonic() < deadline and running is None:
            rec = s.ex.store.value(HHLC, "action") or {}
            if rec.get("action_type") == "GET_TOOL" and rec.get("phase") == "running":
                running = rec
            time.sleep(0.005)
        assert running is not None and (running["skill"], running["skill_kind"]) == ("MOUNT_TOOL", "basic")
        assert s.ctrl.join(20) and s.ctrl.state()["phase"] == "ended"
        get_tool = s.pemkre.executed("GET_TOOL")[0][1]
        assert s.ex.store.value(TASKS, get_tool) == {"action_type": "GET_TOOL", "skill": "MOUNT_TOOL",
                                                     "outcome": "succeeded", "detail": "MOUNT_TOOL tool=taping_tool"}
        last = s.ex.store.value(HHLC, "action")
        assert last["action_type"] == "GO_HOME" and (last["skill"], last["skill_kind"]) == ("", "")
    finally:
        s.close()


# ----------------------------------------------------------------------------- the compose node on its own --
@pytest.mark.parametrize("skill,params,command", [
    ("CHANGE_TOOL", {"tool": "spray_gun"}, "CHANGE_TOOL tool=spray_gun"),
    ("set_pressure", {"wait": False, "pressure": 2.5, "tolerance": 0.25}, "SET_PRESSURE pressure=2.5 "
                                                                          "tolerance=0.25 wait=false"),
    ("LIFT", {"z": 1.2000000001}, "LIFT z=1.2"),
    ("WALL_READY", {}, "WALL_READY"),
])
def test_the_command_is_the_skill_and_its_parameters_sorted(skill, params, command):
    assert compose_skill_command(skill, params) == command


@pytest.mark.parametrize("skill,params,msg", [
    ("", {}, "'' is not a LOCEM command name"),
    ("CHANGE TOOL", {}, "'CHANGE TOOL' is not a LOCEM command name"),
    ("CHANGE_TOOL", {"tool": "spray gun"}, "'tool' = 'spray gun' is empty or contains whitespace"),
    ("CHANGE_TOOL", {"tool": ""}, "'tool' = '' is empty"),
    ("CHANGE_TOOL", {"tool": 'x"y'}, "contains '\"'"),
    ("CHANGE_TOOL", {"tool": "{skill}"}, "contains '{'"),
    ("GOTO", {"pose": [1.0, 2.0, 0.0]}, "parameter 'pose' of GOTO is a list"),
    ("LIFT", {"z": float("nan")}, "'z' is nan, not a finite number"),
    ("LIFT", {"z-height": 1.0}, "parameter name 'z-height' of LIFT is not an identifier"),
])
def test_values_that_are_not_one_command_word_are_refused_naming_them(skill, params, msg):
    with pytest.raises(HicemError) as err:
        compose_skill_command(skill, params)
    assert msg in str(err.value)


def test_the_node_reads_the_task_parameters_and_leaves_out_the_omitted_ones():
    lib = TreeLibrary()
    lib.load_string('<root BTCPP_format="4" main_tree_to_execute="T"><BehaviorTree ID="T">'
                    '<ComposeSkillCommand omit="robot" command="{out}"/></BehaviorTree></root>', "t.xml")
    bb = Blackboard()
    bb.update({"skill": "CHANGE_TOOL", "param_tool": "sander", "param_robot": "robot", "task": "urn:t",
               "cfg.tools": ["sander"]})
    tree = lib.build("T", NodeContext(), bb)
    assert tree.tick() == Status.SUCCESS
    assert bb.get("out") == "CHANGE_TOOL tool=sander"


# ------------------------------------------------------------- against the real LOCEM and compressor --
from test_recover_tree import real_locem  # noqa: E402,F401 - the real LOCEM core on the compressor stand-in


@pytest.fixture
def compressor_locem(real_locem):  # noqa: F811
    """The real LOCEM core with the real compressor bridge (pymodbus) on the compressor stand-in."""
    from test_recover_tree import CoreClient
    rig, core, _backend, _wait = real_locem
    yield rig, CoreClient(core)


def _run_basic(tmp_path, locem, skill, params):
    """One task matched to a basic skill, run by HICEM's controller on ``locem``: (phase, executed)."""
    from hicem_doubles import AutoOperator, Heartbeats
    from hicem_rig import params as hicem_params
    from locem_bridge.hicem.executive import create_executive

    class OneTask(PemkreDouble):
        def start_process(self, process_iri, options=None):
            out = super().start_process(process_iri, options)
            self.s["pending"] = [["PRESSURIZE", params]]
            self.s["home_done"] = True
            return out

    pem = OneTask(skills={"PRESSURIZE": (skill, "basic")}, after_failure="fail_process")
    ex = create_executive(pem, locem, str(tmp_path / "hdict.sqlite"), params=hicem_params())
    ex.operator.add_listener(AutoOperator(ex.controller, {}))
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    try:
        return ex.controller.run_process(P), pem.executed()
    finally:
        beats.stop()
        ex.close()


def test_a_basic_skill_reaches_the_real_compressor_through_locem(tmp_path, compressor_locem):
    rig, client = compressor_locem
    phase, executed = _run_basic(tmp_path, client, "SET_PRESSURE", {"pressure": 3.5, "wait": False})
    assert phase == "ended", executed
    assert client.sent == ["SET_PRESSURE pressure=3.5 wait=false"]
    assert executed[0][2:4] == ["succeeded", "SET_PRESSURE pressure=3.5 wait=false"]
    assert rig.model.setpoint == pytest.approx(3.5)          # the stand-in's set-point register took it


def test_a_value_locem_refuses_fails_the_task_with_locems_reason_and_no_device_change(tmp_path, compressor_locem):
    rig, client = compressor_locem
    before = rig.model.setpoint
    phase, executed = _run_basic(tmp_path, client, "SET_PRESSURE", {"pressure": 12.0, "wait": False})
    assert phase == "failed"
    assert executed[0][2] == "failed"
    assert "INVALID_ARGUMENT" in executed[0][3] and "pressure" in executed[0][3] and "10" in executed[0][3]
    assert rig.model.setpoint == before
