"""Each shipped action tree, run against the LOCEM test double with the shipped parameters and a scanned site:
the LOCEM commands it sends, with the numbers computed from the scan and the parameters."""
import math

import pytest
from py_trees.common import Status

from hicem_doubles import SITE, LocemDouble
from hicem_rig import TREES, params
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.datahandler import DataHandler
from locem_bridge.hicem.datastore import DataManager
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.operator import OperatorDesk
from locem_bridge.hicem.xml_loader import TreeLibrary

LIB = TreeLibrary()
LIB.load_directory(TREES)


def run(action_type, answers=None, **param_values):
    locem = LocemDouble()
    store = DataManager()
    hdh = DataHandler(store)
    hdh.ingest_scan(SITE)
    desk = OperatorDesk()
    desk.add_listener(lambda ev, p: ev == "opened" and desk.reply(p.id, (answers or {})[p.kind]))
    ctx = NodeContext(locem=locem, store=store, health=HealthMonitor([ModuleSpec("locem", crucial=True)]),
                      operator=desk, data_handler=hdh)
    bb = Blackboard()
    bb.update(params().blackboard_entries())
    bb.update({"param_%s" % k: v for k, v in param_values.items()})
    tree = LIB.build(action_type, ctx, bb)
    for _ in range(100):
        st = tree.tick()
        if st != Status.RUNNING:
            break
    return st, locem, bb, ctx, hdh


def test_spray_area_sections_and_command_arguments():
    st, locem, bb, ctx, hdh = run("SPRAY_AREA", area="wall_1_area_1")
    assert st == Status.SUCCESS, ctx.failures
    # 4.8 m wide area, sections of at most 1.2 m: 4 base poses, one SPRAY_AREA each
    gotos = [c for c in locem.sent if c.startswith("GOTO")]
    sprays = [c for c in locem.sent if c.startswith("SPRAY_AREA")]
    assert len(gotos) == 4 and len(sprays) == 4 and locem.sent[0].startswith("GOTO")
    assert gotos[0] == "GOTO 0.6 1.9 1.570796"  # 1.1 m in front of the first section's middle, facing the wall
    assert sprays[0] == ("SPRAY_AREA 0 3 0 1 0 0 1.2 2.5 0 -1 0 spacing=0.1 standoff=0.3 speed=0.1 pressure=3.5")
    assert sprays[3].startswith("SPRAY_AREA 3.6 3 0 ")
    assert hdh.feature("wall_1_area_1")["status"] == "sprayed" and bb.get("task_detail") == "sprayed"


def test_sand_area_uses_the_sanding_parameters():
    st, locem, *_ = run("SAND_AREA", area="wall_1_area_1")
    assert st == Status.SUCCESS
    sands = [c for c in locem.sent if c.startswith("SAND_AREA")]
    assert len(sands) == 4 and sands[0].endswith("spacing=0.1 speed=0.15 force=20")


def test_tape_line_on_a_horizontal_joint():
    st, locem, bb, *_ = run("TAPE_LINE", line="wall_2_joint_1")
    assert st == Status.SUCCESS
    assert locem.sent == ["GOTO 4 1.5 0", "APPLY_TAPE 4.8 2.5 1.2 4.8 0.5 1.2 -1 0 0 speed=0.1"]


def test_validate_tape_line_answer_becomes_the_detail():
    st, locem, bb, *_ = run("VALIDATE_TAPE_LINE", answers={"validate_line": "invalid"}, line="wall_1_joint_1")
    assert st == Status.SUCCESS and bb.get("task_detail") == "invalid"
    assert locem.sent == ["GOTO 1.2 2.2 1.570796", "APPLY_TAPE_START 1.2 3 0 1.2 3 2.5 0 -1 0"]


def test_go_home_to_a_named_location_and_unknown_location():
    st, locem, *_ = run("GO_HOME", location="home")
    assert st == Status.SUCCESS and locem.sent == ["HOME", "GOTO 2.4 1.6 1.5708"]
    st, locem, bb, ctx, _ = run("GO_HOME", location="garage")
    assert st == Status.FAILURE and locem.sent == []
    assert "no entry 'garage'; the table has: home" in ctx.last_failure()[1]


def test_scan_ingests_features_and_get_tool_asks_the_operator():
    st, locem, bb, ctx, hdh = run("SCAN")
    assert st == Status.SUCCESS and locem.sent == ["SCAN"] and bb.get("new_features") == 0  # already known
    st, locem, bb, ctx, hdh = run("GET_TOOL", answers={"mount_tool": "done"}, tool="spray_gun")
    assert st == Status.SUCCESS and locem.sent == ["HOME", "MOUNT_TOOL spray_gun"]
    assert bb.get("task_detail") == "spray_gun"


@pytest.mark.parametrize("action_type,params,reason", [
    ("TAPE_LINE", {"line": "wall_9_joint_1"}, "no stored joint with id 'wall_9_joint_1'"),
    ("TAPE_LINE", {}, "'param_line', which is not set"),
    ("SPRAY_AREA", {"area": "wall_1_joint_1"}, "no stored area with id 'wall_1_joint_1'"),
    ("GET_TOOL", {"tool": "hammer"}, "unknown tool 'hammer'"),
])
def test_bad_parameters_fail_before_any_command(action_type, params, reason):
    st, locem, bb, ctx, _ = run(action_type, **params)
    assert st == Status.FAILURE and locem.sent == []
    assert reason in ctx.last_failure()[1]
