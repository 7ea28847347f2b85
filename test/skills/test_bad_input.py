"""A robot file, command declaration or tree declaration that is inconsistent is refused with FILE: KEY: PROBLEM,
and no model comes out (the CLI writes nothing)."""
import os
import subprocess
import sys

import pytest

from locem_bridge.common.config_errors import ConfigError
from locem_bridge.common.paths import child_env
from locem_bridge.skills import SkillModelError, build_resource_model

from skills_testkit import ROBOT, TREES


def _refused(call, file, key, *problem_words):
    with pytest.raises(SkillModelError) as info:
        call()
    err = info.value
    assert isinstance(err, ConfigError)
    assert err.file == file, err.one_line()
    assert key in err.key, err.one_line()
    for word in problem_words:
        assert word in err.one_line(), err.one_line()
    return err


def _edit(path, old, new):
    with open(path, encoding="utf-8") as handle:
        text = handle.read()
    assert old in text, old
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(text.replace(old, new, 1))


def test_a_skill_naming_a_device_the_robot_does_not_have_is_refused():
    # LOCEM built without the compressor bridge (~devices): SPRAY_AREA still occupies the compressor
    err = _refused(lambda: build_resource_model(ROBOT, [TREES], devices=("arm", "base", "scanner")),
                   ROBOT, "robot.compressor", "SPRAY_AREA", "'compressor'", "does not have")
    assert "arm, base, scanner" in err.allowed


def test_a_tool_without_tcp_is_refused(robot_copy):
    _edit(robot_copy, "      tcp: [0.0, 0.0, 0.14, 0.0, 0.0, 0.0]\n", "")
    _refused(lambda: build_resource_model(robot_copy, [TREES]), robot_copy, "robot.tools.sander.tcp", "missing key")


def test_a_tool_kind_that_names_no_tool_class_is_refused(robot_copy):
    _edit(robot_copy, "kind: sander", "kind: hammer")
    err = _refused(lambda: build_resource_model(robot_copy, [TREES]), robot_copy, "robot.tools.sander.kind",
                   "'hammer'", "ppr:Tool")
    assert "spray_gun" in err.allowed and "taping_tool" in err.allowed


def test_a_parameter_unit_that_is_not_a_known_unit_is_refused(trees_copy):
    path = os.path.join(trees_copy, "GO_HOME.xml")
    _edit(path, 'type="std::string" default="home"', 'type="double" unit="furlong" default="home"')
    err = _refused(lambda: build_resource_model(ROBOT, [trees_copy]), path,
                   "TreeNodesModel.SubTree[GO_HOME].input_port[param_location].unit", "'furlong' is not a known unit")
    assert "m/s" in err.allowed


def test_a_command_argument_with_an_unknown_unit_is_refused(monkeypatch):
    from dataclasses import replace

    from locem_bridge.bridges import commands_compressor as cc
    spec = cc.SET_PRESSURE
    bad = replace(spec, args=(replace(spec.args[0], unit="psi"),) + spec.args[1:])
    monkeypatch.setattr(cc, "SPECS", tuple(bad if s is spec else s for s in cc.SPECS))
    _refused(lambda: build_resource_model(ROBOT, [TREES]), cc.__file__, "SET_PRESSURE.pressure.unit",
             "'psi' is not a known unit")


def test_duplicate_skill_names_are_refused_naming_both_files(trees_copy):
    extra = os.path.join(trees_copy, "MY_GET_TOOL.xml")
    with open(os.path.join(trees_copy, "GET_TOOL.xml"), encoding="utf-8") as handle:
        text = handle.read()
    with open(extra, "w", encoding="utf-8") as handle:
        handle.write(text)
    # the file read second (folder order) is named, with the first
    _refused(lambda: build_resource_model(ROBOT, [trees_copy]), extra, "BehaviorTree[GET_TOOL]", "defined twice",
             os.path.join(trees_copy, "GET_TOOL.xml"))


def test_a_second_tree_folder_redefining_a_shipped_skill_is_refused(tmp_path):
    other = tmp_path / "integrator"
    other.mkdir()
    with open(os.path.join(TREES, "SCAN.xml"), encoding="utf-8") as handle:
        (other / "SCAN.xml").write_text(handle.read().replace('<include path="common.xml"/>', ""))
    _refused(lambda: build_resource_model(ROBOT, [TREES, str(other)]), str(other / "SCAN.xml"),
             "BehaviorTree[SCAN]", "defined twice", os.path.join(TREES, "SCAN.xml"))


def test_a_capability_that_is_not_declared_is_refused(trees_copy):
    path = os.path.join(trees_copy, "TAPE_LINE.xml")
    _edit(path, 'capability="plb:cap_TapeJoint"', 'capability="plb:cap_Teleport"')
    err = _refused(lambda: build_resource_model(ROBOT, [trees_copy]), path,
                   "TreeNodesModel.SubTree[TAPE_LINE].capability", "'plb:cap_Teleport' is not a capability")
    assert "plb:cap_TapeJoint" in err.allowed


@pytest.mark.parametrize("old, new, key, problem", [
    ('<input_port name="param_line" type="std::string">', '<input_port name="param_lane" type="std::string">',
     "TreeNodesModel.SubTree[TAPE_LINE].input_port[param_lane]", "never read"),
    ('<input_port name="param_line" type="std::string">the joint line (a feature id of the scan)</input_port>', "",
     "TreeNodesModel.SubTree[TAPE_LINE]", "reads {param_line}"),
    ('<input_port name="param_line" type="std::string">', '<input_port name="line" type="std::string">',
     "input_port[line]", "param_<name>"),
    ('<input_port name="param_line" type="std::string">', '<input_port name="param_line" type="Pose2D">',
     "input_port[param_line].type", "'Pose2D' is not a parameter type"),
    ('<SubTree ID="TAPE_LINE">', '<SubTree ID="TAPE_LINES">', "SubTree[TAPE_LINES]", "does not define"),
])
def test_a_skill_declaration_that_does_not_fit_its_tree_is_refused(trees_copy, old, new, key, problem):
    path = os.path.join(trees_copy, "TAPE_LINE.xml")
    _edit(path, old, new)
    _refused(lambda: build_resource_model(ROBOT, [trees_copy]), path, key, problem)


def test_the_export_command_writes_nothing_for_bad_input(trees_copy, tmp_path):
    _edit(os.path.join(trees_copy, "TAPE_LINE.xml"), 'capability="plb:cap_TapeJoint"', 'capability="nope"')
    out = tmp_path / "out" / "robot.ttl"
    proc = subprocess.run([sys.executable, "-m", "locem_bridge.skills", "export", "--robot", ROBOT, "--trees",
                           trees_copy, "--out", str(out)], capture_output=True, text=True, env=child_env(),
                          timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(os.path.join(trees_copy, "TAPE_LINE.xml") + ": ")
    assert "'nope' is not a capability" in lines[0]
    assert not out.exists() and not (tmp_path / "out").exists()


def test_the_pre_flight_refuses_an_inconsistent_resource_model(trees_copy):
    from locem_bridge.config_check import check_files

    from skills_testkit import ONTOLOGIES
    check_files(robot=ROBOT, trees_dir=TREES, ontology_dir=ONTOLOGIES)        # the shipped files pass
    path = os.path.join(trees_copy, "SCAN.xml")
    _edit(path, 'capability="plb:cap_ScanWalls"', 'capability="plb:cap_ScanEverything"')
    _refused(lambda: check_files(robot=ROBOT, trees_dir=trees_copy, ontology_dir=ONTOLOGIES), path,
             "TreeNodesModel.SubTree[SCAN].capability", "is not a capability")
