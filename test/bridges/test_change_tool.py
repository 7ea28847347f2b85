"""CHANGE_TOOL through LOCEM's dispatcher with every bridge against the stand-ins (UR controller, compressor, CAN
drives, tool changer) and the PyBullet world: the shipped robot plus the tests' tool changer section
(test/data/tool_changer_rack.yaml). The tool the changer couples is the tool the world works with."""
import os
import time

import pytest

from locem_bridge.bridges.robot import build_robot
from locem_bridge.bridges.config import load_robot_config
from locem_bridge.common.locem_codes import Code
from locem_bridge.locem.catalogue import all_specs
from locem_bridge.locem.core import LocemCore

from bridge_rigs import ROBOT_YAML, SHORT_WALL, WorksiteRig, free_port, robot_with_changer, rtde_payload

JOINT = "wall_1_joint_1"      # the horizontal joint at z = 1.25 m, x 1.8 .. 3.0, y = 3.6
NORMAL = "0 -1 0"
AT_WALL = "GOTO 2.4 2.8 1.5708"          # the site's robot_start, 0.8 m from the wall: the taping pose
BACK_OFF = "GOTO 2.4 2.2 1.5708"         # 1.4 m from the wall: the arm turns to the rack without touching it


def _names(core):
    return {spec.name for spec in core.dispatcher.registry.specs()}


def test_a_robot_with_a_tool_changer_offers_change_tool_instead_of_mount_tool():
    """Registration only (built, never started: no device is contacted)."""
    for robot, offered, absent in ((load_robot_config(ROBOT_YAML), "MOUNT_TOOL", "CHANGE_TOOL"),
                                   (robot_with_changer(), "CHANGE_TOOL", "MOUNT_TOOL")):
        core = LocemCore(grace=0.5, stop_timeout=2.0)
        built = build_robot(robot, site=SHORT_WALL)
        try:
            for command_set in built.command_sets:
                core.install(command_set)
            assert offered in _names(core) and absent not in _names(core)
            declared = {spec.name for spec in all_specs(robot)}    # the catalogue (API doc, resource model)
            assert offered in declared and absent not in declared
            r = core.dispatcher.execute("%s sander" % absent)
            assert r.code == Code.INVALID_COMMAND, (r.code, r.message)
        finally:
            built.close()
            core.close()


@pytest.fixture
def changer_site(core):
    pytest.importorskip("rtde_control")
    rig = WorksiteRig(robot_with_changer())
    built = build_robot(rig.robot, site=rig.site_path, initial_pose=tuple(rig.world.base_pose()))
    built.start()
    try:
        for command_set in built.command_sets:
            core.install(command_set)
        for kind in ("arm", "compressor", "base", "tool_changer"):
            assert built.get(kind).wait_ready(20.0), (kind, built.get(kind).health())
        yield rig, built
    finally:
        built.close()
        rig.close()


@pytest.mark.slow
def test_change_tool_couples_the_tool_sets_tcp_and_payload_and_the_world_works_with_it(changer_site, core):
    rig, built = changer_site
    assert core.dispatcher.execute(BACK_OFF).success           # room to turn the arm to the rack
    before = rig.world.collisions
    r = core.dispatcher.execute("CHANGE_TOOL tool=taping_tool")
    assert r.success, r.message
    assert rig.world.collisions == before, rig.world.collision_log
    assert r.result["tool"] == "taping_tool" and r.result["previous"] == "" and r.result["changed"] is True
    assert rig.world.mounted_tool == "taping_tool"
    assert rig.changer.snapshot()["coupled_tool"] == "taping_tool"
    assert rig.standin.get_tcp_offset()[2] == pytest.approx(0.22)
    payload = rtde_payload(rig.address)
    assert payload["mass"] == pytest.approx(3.2) and payload["cog"] == pytest.approx([0.0, 0.0, 0.09]), payload
    # the coupled tool tapes: the whole joint covered
    assert core.dispatcher.execute(AT_WALL).success
    r = core.dispatcher.execute("APPLY_TAPE 1.8 3.6 1.25 3.0 3.6 1.25 %s speed=0.1" % NORMAL)
    assert r.success, r.message
    time.sleep(0.2)
    assert rig.world.outcome.joint_coverage(JOINT) >= 0.99, rig.world.outcome.joint_coverage(JOINT)
    # to the sander: the taping tool goes back into slot 1 first (from the wall pose: retract, home_via, rack)
    assert core.dispatcher.execute(BACK_OFF).success
    before = rig.world.collisions
    r = core.dispatcher.execute("CHANGE_TOOL sander")
    assert r.success, r.message
    assert rig.world.collisions == before, rig.world.collision_log
    assert r.result["previous"] == "taping_tool" and r.result["tool"] == "sander"
    snap = rig.changer.snapshot()
    assert snap["coupled_tool"] == "sander" and snap["slots_present"] == {1: True, 2: True, 3: False}
    assert rig.world.mounted_tool == "sander" and rig.standin.get_tcp_offset()[2] == pytest.approx(0.14)
    assert rtde_payload(rig.address)["mass"] == pytest.approx(2.8)
    # a wall command needing another tool says how to get it
    r = core.dispatcher.execute("APPLY_TAPE_START 1.8 3.6 1.25 3.0 3.6 1.25 %s" % NORMAL)
    assert r.code == Code.NOT_READY and "send CHANGE_TOOL tool=taping_tool" in r.message, r.message
    # already coupled: OK at once, nothing moves, the lock is not touched
    operations = snap["operations"]
    q = rig.standin.get_joint_positions()
    start = time.monotonic()
    r = core.dispatcher.execute("CHANGE_TOOL tool=sander")
    assert r.success and r.result["changed"] is False, r.message
    assert time.monotonic() - start < 1.0
    assert rig.standin.get_joint_positions() == pytest.approx(q, abs=1e-6)
    assert rig.changer.snapshot()["operations"] == operations
    assert rig.nothing_running(), rig.running()


@pytest.mark.slow
def test_bad_change_tool_input_is_refused_naming_the_allowed_tools_and_nothing_moves(changer_site, core):
    rig, built = changer_site
    q = rig.standin.get_joint_positions()
    r = core.dispatcher.execute("CHANGE_TOOL tool=hammer")
    assert r.code == Code.INVALID_ARGUMENT
    assert "hammer" in r.message and "taping_tool" in r.message and "sander" in r.message, r.message
    r = core.dispatcher.execute("CHANGE_TOOL")
    assert r.code == Code.INVALID_ARGUMENT and "tool" in r.message, r.message
    # a tool the operator took out of the rack: NOT_READY before anything moves
    rig.changer.take_from_rack("spray_gun")
    r = core.dispatcher.execute("CHANGE_TOOL tool=spray_gun")
    assert r.code == Code.NOT_READY and "not in its rack slot 2" in r.message, r.message
    assert rig.standin.get_joint_positions() == pytest.approx(q, abs=1e-6)
    assert rig.world.mounted_tool is None
    # no lock or unlock reached the device, no refusal either
    assert rig.changer.snapshot()["operations"] == 0 and rig.changer.history() == []


@pytest.mark.slow
def test_change_tool_on_the_second_robot_ur5e_on_a_differential_base(core):
    """config/robots/diffdrive_ur5e.yaml as shipped (its own rack poses), addresses moved to the test's: the
    UR5e stand-in reaches every slot through 'tool_change' without touching a wall, and the world swaps the tool."""
    pytest.importorskip("rtde_control")
    diff = load_robot_config(os.path.join(os.path.dirname(ROBOT_YAML), "diffdrive_ur5e.yaml"),
                             {"compressor": {"host": "127.0.0.1"},
                              "tool_changer": {"host": "127.0.0.1", "port": free_port()}})
    rig = WorksiteRig(diff)
    rig.world.set_base_pose(2.4, 2.0, 1.5708)          # 1.6 m from the wall: room to turn the arm to the rack
    time.sleep(0.2)
    built = build_robot(rig.robot, devices=("arm", "compressor", "base", "scanner", "tool_changer"),
                        site=rig.site_path, initial_pose=tuple(rig.world.base_pose()))
    built.start()
    try:
        for command_set in built.command_sets:
            core.install(command_set)
        for kind in ("arm", "base", "tool_changer"):
            assert built.get(kind).wait_ready(20.0), (kind, built.get(kind).health())
        assert "MOUNT_TOOL" not in _names(core)
        before = rig.world.collisions
        for tool, previous, tcp_z in (("taping_tool", "", 0.22), ("sander", "taping_tool", 0.14)):
            r = core.dispatcher.execute("CHANGE_TOOL tool=%s" % tool)
            assert r.success, r.message
            assert r.result["previous"] == previous and rig.world.mounted_tool == tool
            assert rig.standin.get_tcp_offset()[2] == pytest.approx(tcp_z)
        assert rig.changer.snapshot()["slots_present"] == {1: True, 2: True, 3: False}
        assert rig.world.collisions == before, rig.world.collision_log
        assert rig.nothing_running(), rig.running()
    finally:
        built.close()
        rig.close()
