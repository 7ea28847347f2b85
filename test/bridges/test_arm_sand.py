"""SAND_AREA contact=force through LOCEM: ur_rtde force mode (worker process) against the UR stand-in whose contact
surfaces are the worksite's wall (a plane in the UR base frame, set after the base has parked), with the PyBullet
world measuring the sanded area."""
import time

import numpy as np
import pytest

from locem_bridge.bridges.robot import build_robot

from bridge_rigs import WorksiteRig

pytest.importorskip("rtde_control")
pytestmark = pytest.mark.slow

NORMAL = "0 -1 0"
WALL_POINT = (2.0, 3.6, 0.9)             # on wall_1's face (map), normal -y towards the room
STIFFNESS = 20000.0


@pytest.fixture
def wall(robot, core):
    rig = WorksiteRig(robot)
    built = build_robot(rig.robot, site=rig.site_path, initial_pose=tuple(rig.world.base_pose()))
    built.start()
    for command_set in built.command_sets:
        core.install(command_set)
    for kind in ("arm", "compressor", "base"):
        assert built.get(kind).wait_ready(20.0), (kind, built.get(kind).health())
    rig.world.mount_tool("sander")
    assert core.dispatcher.execute("MOUNT_TOOL sander").success
    assert core.dispatcher.execute("GOTO 2.4 2.6 1.5708").success
    yield rig, built
    built.close()
    rig.close()


def _wall_in_arm_base(world):
    p = np.array(world.map_to_arm_base(WALL_POINT))
    q = np.array(world.map_to_arm_base(np.add(WALL_POINT, (0.0, -1.0, 0.0))))
    return {"point": p.tolist(), "normal": (q - p).tolist()}


def test_sand_area_holds_the_contact_force_on_every_lane(wall, core):
    rig, built = wall
    rig.standin.set_contact_planes([_wall_in_arm_base(rig.world)], STIFFNESS)
    r = core.dispatcher.execute("SAND_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.1 speed=0.15 force=20 contact=force"
                                % NORMAL)
    assert r.success, r.message
    print("SAND_AREA contact=force result: %s" % r.result)
    assert r.result["contact"] == "force" and r.result["lanes"] == 7
    assert 18.0 <= r.result["force_min_n"] <= r.result["force_max_n"] <= 22.0, r.result
    time.sleep(0.2)
    m = rig.world.outcome.maps["wall_1"]
    cells = m.sanded[(m.tc >= 0.9) & (m.tc <= 1.5)][:, (m.sc >= 0.2) & (m.sc <= 1.0)]
    assert cells.mean() >= 0.98, cells.mean()
    assert rig.standin.get_force_mode() is None
    assert rig.nothing_running()


def test_sand_area_without_a_wall_fails_clearly_and_leaves_nothing_running(wall, core):
    rig, built = wall
    rig.standin.set_contact_planes([], STIFFNESS)                   # the wall is not where HICEM said
    r = core.dispatcher.execute("SAND_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s force=20 contact=force" % NORMAL)
    assert r.code.value == "HARDWARE_ERROR" and "no contact" in r.message, r.message
    assert rig.standin.get_force_mode() is None
    assert rig.nothing_running()


def test_stop_during_force_controlled_sanding_ends_force_mode_and_switches_the_sander_off(wall, core):
    from locem_bridge.locem.registry import Interface
    from bridge_rigs import wait_until
    rig, built = wall
    rig.standin.set_contact_planes([_wall_in_arm_base(rig.world)], STIFFNESS)
    execution = core.dispatcher.submit("SAND_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s speed=0.05 force=20 contact=force"
                                       % NORMAL, Interface.ACTION)
    assert wait_until(lambda: rig.standin.get_force_mode() is not None
                      and any(rig.standin.get_standard_digital_outputs()), timeout=30.0)
    assert core.dispatcher.execute("STOP").success
    assert execution.wait(5.0).code.value == "ABORTED"
    assert rig.standin.get_force_mode() is None
    assert wait_until(rig.nothing_running, timeout=3.0)


def test_a_vertical_pass_of_width_0_sands_one_strip_up_the_side_under_force(wall, core):
    """The edge pass HICEM sends beside a door frame: one lane upwards (lanes=vertical, width 0) at x = 2.0 m
    (s = 0.2 m on wall_1), z 0.9 .. 1.5 m: the pad (radius 0.1125 m) sands a strip its diameter wide, nothing else."""
    rig, built = wall
    rig.standin.set_contact_planes([_wall_in_arm_base(rig.world)], STIFFNESS)
    r = core.dispatcher.execute("SAND_AREA 2.0 3.6 0.9 1 0 0 0 0.6 %s spacing=0.1 speed=0.15 force=20 contact=force "
                                "lanes=vertical" % NORMAL)
    assert r.success, r.message
    assert r.result["lanes"] == 1 and r.result["length_m"] == pytest.approx(0.6, abs=0.01), r.result
    assert 18.0 <= r.result["force_min_n"] <= r.result["force_max_n"] <= 22.0, r.result
    time.sleep(0.2)
    m = rig.world.outcome.maps["wall_1"]
    rows = (m.tc >= 0.9) & (m.tc <= 1.5)
    strip = m.sanded[rows][:, (m.sc >= 0.11) & (m.sc <= 0.29)]
    assert strip.mean() >= 0.98, strip.mean()
    assert not m.sanded[:, m.sc >= 0.34].any() and not m.sanded[:, m.sc <= 0.06].any()
    assert rig.standin.get_force_mode() is None
    assert rig.nothing_running()


def test_width_0_with_horizontal_lanes_is_refused_before_the_arm_moves(wall, core):
    rig, built = wall
    q = list(rig.standin.get_joint_positions())
    r = core.dispatcher.execute("SAND_AREA 2.0 3.6 0.9 1 0 0 0 0.6 %s force=20 contact=force" % NORMAL)
    assert r.code.value == "INVALID_ARGUMENT", (r.code, r.message)
    assert "width" in r.message and "lanes=vertical" in r.message, r.message
    assert max(abs(a - b) for a, b in zip(rig.standin.get_joint_positions(), q)) < 1e-6
    assert rig.nothing_running()
