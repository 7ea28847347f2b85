"""The resource model of the shipped robot, generated from its robot file, the LOCEM registry and trees/."""
import glob
import math
import os
import re

import pytest

from locem_bridge.locem import system_commands
from rdflib import Graph, Literal, URIRef
from rdflib import namespace
from rdflib.namespace import RDF

from locem_bridge.bridges.commands_base import MAP_EXTENT
from locem_bridge.pemkre.vocab import PLB, PPR, PROC, SK
from locem_bridge.skills import build_resource_model
from locem_bridge.skills.units import QUDT_UNIT, UNITS

from skills_testkit import ONTOLOGIES, ROBOT, TREES


def _locem_node_registry():
    """The registry exactly as locem_node builds it for the robot file (LocemCore + build_robot + install)."""
    from locem_bridge.bridges.config import load_robot_config
    from locem_bridge.bridges.robot import build_robot
    from locem_bridge.locem.core import LocemCore

    core = LocemCore()
    robot = build_robot(load_robot_config(ROBOT))
    try:
        for command_set in robot.command_sets:
            core.install(command_set)
        return {s.name: (s, core.registry.handler(s.name) is not None) for s in core.registry.specs()}
    finally:
        robot.close()
        core.close()


def test_every_registered_command_is_a_basic_skill_with_its_arguments_units_and_ranges(shipped_model):
    registry = _locem_node_registry()
    basic = {s.name: s for s in shipped_model.basic_skills}
    # every command but the state machine's methods (SUSPEND, RESUME, HALT, RESET), which act on skills
    methods = {spec.name for spec in system_commands.SKILL_METHODS}
    assert methods <= set(registry) and not methods & set(basic)
    registry = {name: v for name, v in registry.items() if name not in methods}
    assert set(basic) == set(registry)
    assert len(basic) >= 37
    for name, (spec, served) in registry.items():
        skill = basic[name]
        assert skill.offered == served and served
        assert [p.name for p in skill.parameters] == [a.name for a in spec.args]
        for p, a in zip(skill.parameters, spec.args):
            assert (p.unit, p.minimum, p.maximum, p.required, p.keyword_only) == (
                a.unit, a.minimum, a.maximum, a.required, a.keyword_only), (name, a.name)
            assert p.choices == tuple(a.choices)
            if not a.required:
                assert p.default == a.default
        # the resources it occupies, and the device of its category (STOP_ARM, GET_POSE occupy none)
        expected = {r for r in spec.resources if r != "tool"} | ({spec.category} & {"arm", "base", "compressor"})
        assert skill.devices == tuple(sorted(expected)), name
    # the ranges a caller sees are the ones LOCEM enforces
    goto = shipped_model.skill("GOTO", "basic")
    assert goto.capability == str(SK.cap_DriveBase) and goto.devices == ("base",)
    x = goto.parameters[0]
    assert (x.name, x.datatype, x.unit, x.minimum, x.maximum, x.required) == (
        "x", "double", "m", -MAP_EXTENT, MAP_EXTENT, True)
    spray = shipped_model.skill("SPRAY_AREA", "basic")
    assert spray.devices == ("arm", "compressor")
    pressure = [p for p in spray.parameters if p.name == "pressure"][0]
    assert (pressure.unit, pressure.default, pressure.keyword_only) == ("bar", 2.5, True)
    mount = shipped_model.skill("MOUNT_TOOL", "basic")
    assert mount.parameters[0].choices == ("taping_tool", "spray_gun", "sander")
    assert mount.capability == str(SK.cap_MountToolByOperator)
    assert shipped_model.skill("WALL_READY", "basic").capability == str(SK.cap_ArmToWallReady)
    assert set(shipped_model.skill("HOME", "basic").interfaces) == {"service", "action"}


def _action_trees():
    out = []
    for path in sorted(glob.glob(os.path.join(TREES, "*.xml"))):
        text = open(path, encoding="utf-8").read()
        m = re.search(r'main_tree_to_execute="([A-Z_]+)"', text)
        if m and m.group(1) != "BASIC_SKILL":          # BASIC_SKILL runs basic skills; it is no skill itself
            out.append(m.group(1))
    return out


def test_every_action_tree_is_a_composite_skill_realizing_its_task_types_capability(shipped_model):
    trees = _action_trees()
    assert len(trees) >= 10
    composite = {s.name: s for s in shipped_model.composite_skills}
    assert set(trees) == set(composite)
    onto = Graph()
    for f in ("plasterboard.ttl", "skill.ttl"):
        onto.parse(os.path.join(ONTOLOGIES, f), format="turtle")
    for task_type in onto.subjects(PROC.actionType, None):
        action = str(onto.value(task_type, PROC.actionType))
        required = onto.value(task_type, SK.requiresCapability)
        # the tree named like the action type realizes exactly what the task type requires
        assert composite[action].capability == str(required), action
        assert composite[action].offered, action


# every tree that drives (DriveSafely) may fold the arm into the robot's transit pose first (MOVE_HOME)
@pytest.mark.parametrize("tree, params, invokes, operator, devices", [
    ("GET_TOOL", [("tool", True)], {"WALL_READY", "HOME", "MOUNT_TOOL", "GET_POSE", "GOTO", "MOVE_HOME"}, True,
     ("arm", "base")),
    ("TAPE_LINE", [("line", True)], {"APPLY_TAPE", "WALL_READY", "GET_POSE", "GOTO", "MOVE_HOME"}, False,
     ("arm", "base")),
    ("VALIDATE_TAPE_LINE", [("line", True)], {"APPLY_TAPE_START", "WALL_READY", "GET_POSE", "GOTO", "MOVE_HOME"},
     True, ("arm", "base")),
    ("SPRAY_AREA", [("area", True)], {"SPRAY_AREA", "WALL_READY", "GET_POSE", "GOTO", "MOVE_HOME"}, False,
     ("arm", "base", "compressor")),
    ("GO_HOME", [("location", False)], {"WALL_READY", "HOME", "GET_POSE", "GOTO", "MOVE_HOME"}, False,
     ("arm", "base")),
    ("SCAN", [], {"SCAN"}, False, ("scanner",)),
    ("RECOVER", [], {"GET_TOOL_POINT", "RESET_ARM", "WALL_READY"}, True, ("arm",)),
])
def test_composite_skill_params_invoked_commands_and_operator_come_from_the_tree(shipped_model, tree, params, invokes,
                                                                                  operator, devices):
    skill = shipped_model.skill(tree, "composite")
    assert [(p.name, p.required) for p in skill.parameters] == params
    assert set(skill.invokes) == invokes
    assert skill.involves_operator is operator
    assert skill.devices == devices
    assert skill.source == os.path.join(TREES, tree + ".xml")


def test_devices_tools_mount_chain_reach_and_kinematics_come_from_the_robot_file(shipped_model):
    m = shipped_model
    assert m.robot_name == "rbkairos_ur10e" and m.kinematics == "mecanum" and m.namespace == "robot_1"
    assert {d.name: d.kind for d in m.devices} == {"base": "base", "arm": "arm", "compressor": "compressor",
                                                   "scanner": "scanner"}
    arm = m.device("arm")
    assert (arm.model, arm.protocol, arm.reach) == ("ur10e", "ur_rtde", 1.3)
    assert m.device("base").kinematics == "mecanum" and m.device("base").protocol == "cia402"
    # the chain TCP -> flange -> arm -> pedestal -> base_footprint -> base, offsets adding up to the file's numbers
    frames = {"frame_" + f.name: f for f in m.frames}
    chain, node, z = [], "frame_tcp_spray_gun", 0.0
    tool = m.tool("spray_gun")
    frames["frame_" + tool.tcp.name] = tool.tcp
    while node:
        chain.append(node)
        if node in frames:
            f = frames[node]
            node, z = f.mounted_on, z + (f.xyz[2] if f.xyz else 0.0)
        else:
            d = m.device(node[len("device_"):])
            node, z = d.mounted_on, z + d.xyz[2]
    assert chain == ["frame_tcp_spray_gun", "frame_flange", "device_arm", "frame_pedestal", "frame_base_footprint",
                     "device_base"]
    assert z == pytest.approx(0.18 + 0.60 + 0.45)      # tcp z + pedestal + chassis top: flange offsets vary
    assert {t.name: t.tool_class for t in m.tools} == {"taping_tool": str(PPR.TapingTool),
                                                       "spray_gun": str(PPR.SprayGun), "sander": str(PPR.Sander)}
    assert {t.name: t.length for t in m.tools} == pytest.approx({"taping_tool": 0.22, "spray_gun": 0.18,
                                                                 "sander": 0.14})


def test_a_tcp_rotation_vector_becomes_roll_pitch_yaw(robot_copy):
    text = open(robot_copy).read().replace("tcp: [0.0, 0.0, 0.14, 0.0, 0.0, 0.0]",
                                          "tcp: [0.0, 0.0, 0.14, 0.0, 0.0, 1.5708]")
    open(robot_copy, "w").write(text)
    tcp = build_resource_model(robot_copy, [TREES]).tool("sander").tcp
    assert tcp.rpy == pytest.approx((0.0, 0.0, 1.5708)) and tcp.xyz == pytest.approx((0.0, 0.0, 0.14))


def test_the_graph_says_what_the_records_say(shipped_model):
    g = shipped_model.to_graph()
    robot = shipped_model.robot_iri
    assert robot == URIRef("https://locem-bridge.example.org/robot/rbkairos_ur10e/robot")
    assert (robot, RDF.type, PPR.Robot) in g
    provided = set(g.objects(robot, SK.providesSkill))
    assert len(provided) == len(shipped_model.skills()) == 47
    assert len(set(g.subjects(RDF.type, SK.BasicSkill))) == 37
    assert len(set(g.subjects(RDF.type, SK.CompositeSkill))) == 10
    # tools keep the local names HICEM and LOCEM use, with the classes PEMKRE's parameter queries bind
    for name, cls in (("taping_tool", PPR.TapingTool), ("spray_gun", PPR.SprayGun), ("sander", PPR.Sander)):
        assert (shipped_model.iri(name), RDF.type, cls) in g
        assert (robot, SK.hasTool, shipped_model.iri(name)) in g
    rows = list(g.query(
        "SELECT ?min ?max ?unit ?dt WHERE { ?s sk:skillName 'GOTO' ; sk:hasParameter ?p . ?p sk:parameterName 'x' ; "
        "sk:minValue ?min ; sk:maxValue ?max ; sk:unit ?unit ; sk:datatype ?dt }", initNs={"sk": SK}))
    assert rows == [(Literal(-MAP_EXTENT, datatype=namespace.XSD.double), Literal(MAP_EXTENT, datatype=namespace.XSD.double),
                     URIRef(QUDT_UNIT + "M"), namespace.XSD.double)]
    get_tool = shipped_model.iri("skill_tree_GET_TOOL")
    assert (get_tool, SK.realizesCapability, PLB.cap_GetTool) in g
    assert (PLB.cap_GetTool, SK.isRealizedBySkill, get_tool) in g
    assert (get_tool, SK.involvesOperator, Literal(True)) in g
    assert (get_tool, SK.invokesSkill, shipped_model.iri("skill_MOUNT_TOOL")) in g
    assert (get_tool, SK.hasStateMachine, SK.ProgramStateMachine) in g
    assert (robot, SK.providesCapability, PLB.cap_TapeJoint) in g
    # every unit in the graph is a QUDT unit the table knows
    units = {str(u) for u in g.objects(None, SK.unit)}
    assert units and units <= {QUDT_UNIT + u for u in UNITS.values() if u}


def test_a_tree_invoking_a_command_this_robot_does_not_register_is_kept_but_not_offered(trees_copy):
    with open(os.path.join(trees_copy, "GET_TOOL.xml"), encoding="utf-8") as handle:
        text = handle.read()
    text = text.replace('command="MOUNT_TOOL {tool}"', 'command="CHANGE_TOOL tool={tool}"')
    with open(os.path.join(trees_copy, "GET_TOOL.xml"), "w", encoding="utf-8") as handle:
        handle.write(text)
    model = build_resource_model(ROBOT, [trees_copy])
    skill = model.skill("GET_TOOL", "composite")
    assert not skill.offered
    assert skill.reason == "invokes CHANGE_TOOL, which this robot's LOCEM does not register"
    assert skill.capability == str(PLB.cap_GetTool)
    g = model.to_graph()
    node = model.iri("skill_tree_GET_TOOL")
    assert (model.robot_iri, SK.providesSkill, node) not in g
    assert (node, SK.notOfferedBy, model.robot_iri) in g
    assert str(g.value(node, SK.notOfferedReason)) == skill.reason
    # the robot still offers every other skill, and no longer claims the capability only that tree realized
    assert (model.robot_iri, SK.providesCapability, PLB.cap_GetTool) not in g
    assert len(model.offered_skills()) == len(model.skills()) - 1


def test_building_the_model_starts_and_connects_nothing():
    # the stand-ins do not run in this test: building succeeds without a UR controller, Modbus server or CAN bus,
    # and the build leaves no thread of a backend behind (threads other tests of this process left are not its)
    import threading
    before = {id(t) for t in threading.enumerate()}
    model = build_resource_model(ROBOT, [TREES])
    new = [t.name for t in threading.enumerate() if id(t) not in before]
    assert not [n for n in new if re.search(r"rtde|modbus|canopen|cia402|bus", n, re.I)], new
    assert math.isfinite(model.device("arm").reach)


def test_the_second_robot_has_its_own_base_kinematics_reach_lift_and_lift_skill():
    m = build_resource_model(os.path.join(os.path.dirname(ROBOT), "diffdrive_ur5e.yaml"), [TREES])
    assert m.robot_name == "diffdrive_ur5e" and m.kinematics == "differential"
    assert m.device("base").kinematics == "differential" and m.device("arm").reach == 0.85
    # the arm rides on the lift, the lift on the pedestal column
    assert (m.device("arm").mounted_on, m.device("lift").mounted_on) == ("device_lift", "frame_pedestal")
    lift = m.skill("LIFT", "basic")
    assert lift.capability == str(SK.cap_Lift) and lift.devices == ("lift",) and lift.offered
    assert (lift.parameters[0].name, lift.parameters[0].unit) == ("z", "m")
    g = m.to_graph()
    assert (m.iri("device_base"), SK.kinematics, SK.DifferentialDrive) in g
    assert (m.robot_iri, SK.providesCapability, SK.cap_Lift) in g
    # two robots' models share one store without clashing: every subject is under its own robot's IRI
    shipped = build_resource_model(ROBOT, [TREES]).to_graph()
    both = {s for s in g.subjects() if "/robot/" in str(s)} & {s for s in shipped.subjects() if "/robot/" in str(s)}
    assert both == set()


def test_on_the_tool_changer_robot_the_operators_tool_tree_is_not_offered_and_the_changer_skill_is():
    m = build_resource_model(os.path.join(os.path.dirname(ROBOT), "diffdrive_ur5e.yaml"), [TREES])
    change = m.skill("CHANGE_TOOL", "basic")
    assert change.offered and change.capability == str(SK.cap_ChangeToolAutomatically)
    assert "tool_changer" in change.devices and m.device("tool_changer").mounted_on == "frame_flange"
    with pytest.raises(KeyError):
        m.skill("MOUNT_TOOL", "basic")                  # only the changer couples this robot's tools
    get_tool = m.skill("GET_TOOL", "composite")
    assert not get_tool.offered
    assert get_tool.reason == "invokes MOUNT_TOOL, which this robot's LOCEM does not register"
    # the template's step capabilities are provided by this robot
    g = m.to_graph()
    assert (m.robot_iri, SK.providesCapability, SK.cap_ArmToWallReady) in g
    assert (m.robot_iri, SK.providesCapability, SK.cap_ChangeToolAutomatically) in g
    assert (m.robot_iri, SK.providesCapability, PLB.cap_GetTool) not in g
