"""PyBullet worksite: scripted TCP passes produce the expected outcome maps; collisions; tools; pictures."""
import copy
import os

import numpy as np
import pytest

from locem_bridge.sim.arm_source import KinematicArm
from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.modbus.compressor import CompressorModel
from locem_bridge.sim.errors import SimStateError
from locem_bridge.sim.world import World


class ManualWall:
    """Wall clock under test control (sim time advances only when the test says so)."""

    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


@pytest.fixture
def rig(site_cfg, robot_cfg):
    wall = ManualWall()
    clock = SimClock(1.0, wall=wall)
    arm = KinematicArm(robot_cfg["robot"]["arm"]["named_poses"]["wall_ready"])
    comp = CompressorModel(copy.deepcopy(robot_cfg["robot"]["compressor"]), clock.now)
    world = World(copy.deepcopy(site_cfg), robot_cfg, clock, arm=arm, compressor=comp, gui=False)
    yield world, arm, comp, wall
    world.close()


def _pass(world, arm, wall, points, normal, speed=0.2):
    q = world.joint_positions()
    prev = None
    for p in points:
        q = world.ik_tcp(p, normal, q)
        arm.set_joint_positions(q)
        if prev is not None:
            wall.t += np.linalg.norm(np.asarray(p) - prev) / speed
        prev = np.asarray(p)
        world.step()
    return q


def _spray_ready(world, comp, wall):
    """Base before wall_1, spray gun mounted, compressor at 4.5 bar (20 s of sim time to build it up)."""
    world.set_base_pose(1.8, 2.3, np.pi / 2)
    world.mount_tool("spray_gun")
    comp.set_setpoint(4.5)
    comp.set_motor(True)
    wall.t += 20.0


def _vertical(x, y, z0, z1, step=0.01):
    return [[x, y, z] for z in np.arange(z0, z1 + 1e-9, step)]


def test_taping_pass_along_joint_with_tool_on_covers_it(rig):
    world, arm, comp, wall = rig
    world.set_base_pose(1.2, 2.5, np.pi / 2)          # facing wall_1 (y = 3.6), joint 1 at x = 1.2
    world.mount_tool("taping_tool")
    _pass(world, arm, wall, [[1.2, 3.5, 0.9]], [0, 1, 0])     # approach off the wall, tool off
    arm.set_digital_output(0, True)
    _pass(world, arm, wall, _vertical(1.2, 3.6, 0.9, 1.9), [0, 1, 0])
    s = world.outcome.summary()
    j = s["joints"]
    assert j["wall_1_joint_1"]["coverage"] == pytest.approx(1.0 / 2.5, abs=0.02)   # 1 m of a 2.5 m joint
    assert j["wall_1_joint_2"]["coverage"] == 0.0 and j["wall_1_joint_3"]["coverage"] == 0.0
    assert j["wall_1_joint_4"]["coverage"] < 0.01      # the horizontal joint is only crossed
    assert s["joints_taped"] == 0
    assert world.collisions == 0


def _tape_joint_1(site_cfg, robot_cfg, z0, z1, step=0.01, **wall_1):
    """A world whose wall_1 has ``wall_1`` changed; the taping tool laid along its joint 1 (x = 1.2 m) from z0 to
    z1 in steps of ``step``; returns the world (closed by the caller)."""
    site = copy.deepcopy(site_cfg)
    site["site"]["walls"][0].update(wall_1)
    wall = ManualWall()
    arm = KinematicArm(robot_cfg["robot"]["arm"]["named_poses"]["wall_ready"])
    world = World(site, robot_cfg, SimClock(1.0, wall=wall), arm=arm, gui=False)
    world.set_base_pose(1.2, 2.5, np.pi / 2)
    world.mount_tool("taping_tool")
    _pass(world, arm, wall, [[1.2, 3.5, z0]], [0, 1, 0])
    arm.set_digital_output(0, True)
    _pass(world, arm, wall, _vertical(1.2, 3.6, z0, z1, step), [0, 1, 0])
    return world


def test_joint_above_a_skirting_is_measured_from_its_own_foot(site_cfg, robot_cfg):
    # wall_1: joints from z 0.3 to 2.5 (2.2 m); the lower half of joint 1 taped
    world = _tape_joint_1(site_cfg, robot_cfg, 0.3, 1.4, skirting=0.3)
    try:
        j = world.outcome.summary()["joints"]["wall_1_joint_1"]
        assert j["coverage"] == pytest.approx(1.1 / 2.2, abs=0.02)
        bins = world.outcome.tape["wall_1_joint_1"]
        assert bins[:100].all() and not bins[120:].any()   # the taped bins are the bottom ones
    finally:
        world.close()


def test_a_joint_whose_length_is_no_whole_number_of_bins_counts_its_last_bin_for_what_it_holds(site_cfg, robot_cfg):
    """A joint 0.791 m long (up to a window frame, say) taped to 2 mm short of its end, as scan noise leaves it:
    its last 1 cm bin holds 1 mm of joint, and the joint is 99.7 % taped, not 98.75 % (79 of 80 bins)."""
    # wall_1: joints from z 0.709 to 1.5 (0.791 m)
    world = _tape_joint_1(site_cfg, robot_cfg, 0.709, 1.498, 0.005, skirting=0.709, height=1.5)
    try:
        assert len(world.outcome.tape["wall_1_joint_1"]) == 80 and not world.outcome.tape["wall_1_joint_1"][-1]
        j = world.outcome.summary()["joints"]["wall_1_joint_1"]
        assert j["coverage"] == pytest.approx(0.790 / 0.791, abs=1e-3) and j["coverage"] >= 0.99
        assert j["coverage_reachable"] == j["coverage"]
    finally:
        world.close()


def test_taping_pass_with_tool_off_or_off_the_wall_covers_nothing(rig):
    world, arm, comp, wall = rig
    world.set_base_pose(1.2, 2.5, np.pi / 2)
    world.mount_tool("taping_tool")
    _pass(world, arm, wall, _vertical(1.2, 3.6, 0.9, 1.9), [0, 1, 0])       # output 0 off
    _pass(world, arm, wall, [[1.2, 3.55, 1.9]], [0, 1, 0])                   # retract, then switch on
    arm.set_digital_output(0, True)
    _pass(world, arm, wall, _vertical(1.2, 3.55, 1.9, 0.9, -0.01), [0, 1, 0])   # 5 cm in front of the wall
    s = world.outcome.summary()
    assert s["tape_coverage"] == 0.0
    assert all(v["coverage"] == 0.0 for v in s["joints"].values())


def test_full_joint_pass_counts_joint_as_taped_and_shows_green_in_picture(site_cfg, robot_cfg, tmp_path):
    site = copy.deepcopy(site_cfg)
    site["site"]["walls"][0]["height"] = 2.0          # a 2 m wall: one pass from the floor to the top is in reach
    wall = ManualWall()
    clock = SimClock(1.0, wall=wall)
    arm = KinematicArm(robot_cfg["robot"]["arm"]["named_poses"]["wall_ready"])
    world = World(site, robot_cfg, clock, arm=arm)
    try:
        _full_joint_pass(world, arm, wall, tmp_path)
    finally:
        world.close()


def _full_joint_pass(world, arm, wall, tmp_path):
    world.set_base_pose(2.4, 2.75, np.pi / 2)
    world.mount_tool("taping_tool")
    arm.set_digital_output(0, True)
    _pass(world, arm, wall, _vertical(2.4, 3.6, 0.0, 2.0), [0, 1, 0])
    s = world.outcome.summary()
    assert s["joints"]["wall_1_joint_2"]["taped"] is True
    assert s["joints_taped"] == 1
    world.outcome.mark_manual_taping("wall_1_joint_1")
    paths = world.outcome.save_pictures(str(tmp_path))
    assert sorted(os.path.basename(p) for p in paths) == ["wall_1.png", "wall_2.png"]
    from PIL import Image
    img = np.asarray(Image.open(str(tmp_path / "wall_1.png")).convert("RGB")).astype(int)
    green = (img[..., 1] > 140) & (img[..., 0] < 60) & (img[..., 2] < 90)
    blue = (img[..., 2] > 200) & (img[..., 0] < 60)
    assert green.sum() > 100 and blue.sum() > 100
    img2 = np.asarray(Image.open(str(tmp_path / "wall_2.png")).convert("RGB")).astype(int)
    assert ((img2[..., 1] > 140) & (img2[..., 0] < 60) & (img2[..., 2] < 90)).sum() == 0


def _raster(x0, x1, z0, z1, y, lane=0.1, step=0.02):
    pts = []
    for k, z in enumerate(np.arange(z0, z1 + 1e-9, lane)):
        xs = np.arange(x0, x1 + 1e-9, step)
        pts += [[x, y, z] for x in (xs if k % 2 == 0 else xs[::-1])]
    return pts


def test_spray_raster_with_valve_open_covers_the_area(rig):
    world, arm, comp, wall = rig
    world.set_base_pose(1.8, 2.3, np.pi / 2)
    world.mount_tool("spray_gun")
    comp.set_setpoint(4.5)
    comp.set_motor(True)
    wall.t += 20.0                                    # let the pressure build up
    comp.set_valve(True)
    wall.t += 10.0
    assert comp.spraying()
    standoff = 0.3
    _pass(world, arm, wall, _raster(1.5, 2.1, 1.2, 1.6, 3.6 - standoff), [0, 1, 0], speed=0.3)
    m = world.outcome.maps["wall_1"]
    g = m.grid
    inner = m.thickness[int(1.25 / g):int(1.55 / g), int(1.55 / g):int(2.05 / g)]
    assert (inner >= world.outcome.target).mean() > 0.95
    assert m.thickness[:, int(3.0 / g):].max() == 0.0            # nothing far away
    s = world.outcome.summary()
    assert 0.0 < s["walls"]["wall_1"]["spray_coverage"] < 0.2
    assert s["walls"]["wall_1"]["thickness_cv"] < 1.0
    assert s["walls"]["wall_2"]["spray_coverage"] == 0.0


def test_spray_with_valve_closed_or_no_pressure_covers_nothing(rig):
    world, arm, comp, wall = rig
    world.set_base_pose(1.8, 2.3, np.pi / 2)
    world.mount_tool("spray_gun")
    comp.set_valve(True)                              # valve open but the motor never ran: no pressure
    _pass(world, arm, wall, _raster(1.5, 2.1, 1.2, 1.4, 3.3), [0, 1, 0])
    assert world.outcome.summary()["spray_coverage"] == 0.0


def test_sander_in_contact_sands_and_off_the_wall_does_not(rig):
    world, arm, comp, wall = rig
    world.set_base_pose(1.8, 2.5, np.pi / 2)
    world.mount_tool("sander")
    arm.set_digital_output(1, True)
    _pass(world, arm, wall, [[x, 3.55, 1.3] for x in np.arange(1.5, 2.1, 0.02)], [0, 1, 0])   # 5 cm off
    assert world.outcome.summary()["sand_coverage"] == 0.0
    _pass(world, arm, wall, [[x, 3.6, 1.3] for x in np.arange(1.5, 2.1, 0.02)], [0, 1, 0])
    w1 = world.outcome.summary()["walls"]["wall_1"]["sand_coverage"]
    expected = (0.6 + 0.225) * 0.225 / (4.8 * 2.5)            # swept band of the pad
    assert w1 == pytest.approx(expected, rel=0.25)


def test_a_pad_centred_past_the_walls_top_edge_still_presses_on_the_wall(rig):
    """The force reading the UR stand-in gets (World.wall_contact): a sander whose pad centre sits on or up to the
    pad's radius above the wall's top edge presses with its lower half (a raster's top lane is at the area's top);
    a pad further up, or a tool without a pad there, touches nothing."""
    world, arm, comp, wall = rig
    w1 = next(w for w in world.site.walls if w.id == "wall_1")
    world.set_base_pose(1.8, 2.5, np.pi / 2)
    world.step()
    r = world.tools_cfg["sander"]["pad_radius"]

    def contact(t):
        face = w1.from_wall_coords(1.8, t, -0.003)                # 3 mm into the wall, in front of the base
        return world.wall_contact(world.tcp_target_in_arm_base(face, -w1.n))

    world.mount_tool("taping_tool")
    assert contact(1.0) is not None and contact(w1.height + 0.0005) is None      # no pad: the point alone
    world.remove_tool()
    world.mount_tool("sander")
    for t in (1.0, w1.height, w1.height + 0.5 * r, w1.height + r - 1e-3):
        depth, _normal = contact(t)
        assert depth == pytest.approx(0.003, abs=1e-6), t
    assert contact(w1.height + r + 1e-3) is None


def test_collisions_of_base_and_arm_with_walls_are_counted_once_per_contact(rig, robot_cfg):
    world, arm, comp, wall = rig
    poses = robot_cfg["robot"]["arm"]["named_poses"]
    arm.set_joint_positions(poses["stow"])               # arm folded over the base
    world.step()
    assert world.collisions == 0
    world.set_base_pose(2.4, 3.2, np.pi / 2)              # chassis front reaches y = 3.69 > 3.6
    world.step()
    world.step()
    assert world.collisions == 1
    assert [w for _, w in world.in_contact] == ["wall_1"]
    assert all(part.startswith("base") for part, _ in world.in_contact)
    world.set_base_pose(2.4, 1.8, np.pi / 2)
    world.step()
    assert world.in_contact == [] and world.collisions == 1
    # base clear of the wall, stretched arm (no tool: tools may touch walls) goes through it
    world.set_base_pose(2.4, 2.9, np.pi / 2)
    arm.set_joint_positions([0.0, -1.5708, 1.5708, 0.0, 1.5708, 0.0])   # forearm stretched forward, wrist ahead
    world.step()
    assert world.collisions > 1
    assert world.in_contact and all(part.startswith("arm:") for part, _ in world.in_contact)
    assert world.collision_log[-1]["wall"] == "wall_1"


def test_tools_are_mounted_one_at_a_time(rig):
    world, arm, comp, wall = rig
    with pytest.raises(SimStateError, match="unknown tool"):
        world.mount_tool("hammer")
    world.mount_tool("sander")
    with pytest.raises(SimStateError, match="remove it"):
        world.mount_tool("spray_gun")
    p_sander, _ = world.tcp_pose()
    assert world.remove_tool() == "sander"
    world.mount_tool("taping_tool")
    p_tape, z = world.tcp_pose()
    # TCP offsets along the flange z axis: 0.22 (taping) vs 0.14 (sander)
    assert np.dot(np.subtract(p_tape, p_sander), z) == pytest.approx(0.08, abs=1e-4)


def _spray_line(world, arm, wall, y, speed, z=1.4):
    return _pass(world, arm, wall, [[x, y, z] for x in np.arange(1.5, 2.11, 0.02)], [0, 1, 0], speed=speed)


@pytest.mark.parametrize("change", ["slower", "farther"])
def test_spray_thickness_depends_on_speed_and_distance(site_cfg, robot_cfg, change):
    results = []
    for variant in ("reference", change):
        wall = ManualWall()
        clock = SimClock(1.0, wall=wall)
        arm = KinematicArm(robot_cfg["robot"]["arm"]["named_poses"]["wall_ready"])
        comp = CompressorModel(copy.deepcopy(robot_cfg["robot"]["compressor"]), clock.now)
        world = World(copy.deepcopy(site_cfg), robot_cfg, clock, arm=arm, compressor=comp)
        try:
            world.set_base_pose(1.8, 2.3, np.pi / 2)
            world.mount_tool("spray_gun")
            comp.set_setpoint(4.5)
            comp.set_motor(True)
            wall.t += 30.0
            standoff = 0.45 if variant == "farther" else 0.30
            speed = 0.15 if variant == "slower" else 0.30
            _pass(world, arm, wall, [[1.5, 3.6 - standoff, 1.4]], [0, 1, 0])    # go to the start, valve closed
            comp.set_valve(True)
            _spray_line(world, arm, wall, 3.6 - standoff, speed)
            m = world.outcome.maps["wall_1"]
            column = m.thickness[:, int(1.8 / m.grid)]                # across the sprayed band at x = 1.8
            results.append((column.max(), (column > 0.1 * column.max()).sum() * m.grid))
        finally:
            world.close()
    (t_ref, w_ref), (t_new, w_new) = results
    if change == "slower":
        assert t_new == pytest.approx(2.0 * t_ref, rel=0.15)           # half the speed, twice the layer
        assert w_new == pytest.approx(w_ref, abs=0.03)
    else:
        assert t_new < 0.7 * t_ref                                     # farther: thinner ...
        assert w_new > 1.3 * w_ref                                     # ... and wider


def _line(x0, x1, y, z, step=0.01):
    n = int(round(abs(x1 - x0) / step))
    return [[x0 + (x1 - x0) * i / n, y, z] for i in range(n + 1)]


def test_a_controller_catching_up_in_a_burst_coats_its_stretch_like_the_rest(rig):
    """A controller stalled by a busy machine moves the arm on by the cycles it missed, in a burst of steps that
    reach the world at one wall time; they carry the controller's motion clock, and the stretch passed in the
    burst gets the coat of its real duration, like the rest of the lane (timed by the world clock, it got none)."""
    world, arm, comp, wall = rig
    _spray_ready(world, comp, wall)
    speed, y = 0.3, 3.3
    q = world.ik_tcp([1.4, y, 1.4], [0, 1, 0], world.joint_positions())
    arm.set_joint_positions(q, motion_time=50.0)       # the controller's clock has its own origin
    world.step()
    comp.set_valve(True)
    motion, late = 50.0, []
    for p in _line(1.4, 2.2, y, 1.4):
        q = world.ik_tcp(p, [0, 1, 0], q)
        motion += 0.01 / speed
        if 1.75 <= p[0] <= 1.95:                        # the controller stalls here: the wall goes on, no samples
            wall.t += 0.01 / speed
            late.append(q)
            continue
        for q_late in late:                             # ... then catches up: a burst of steps at one wall time
            arm.set_joint_positions(q_late, motion_time=motion - 0.01 / speed * (len(late) - late.index(q_late)))
        late = []
        wall.t += 0.01 / speed
        arm.set_joint_positions(q, motion_time=motion)
        world.step()
    comp.set_valve(False)
    m = world.outcome.maps["wall_1"]
    row = m.thickness[int(1.4 / m.grid)]
    burst = row[int(1.78 / m.grid):int(1.93 / m.grid)]
    steady = np.concatenate([row[int(1.55 / m.grid):int(1.7 / m.grid)], row[int(2.0 / m.grid):int(2.1 / m.grid)]])
    assert steady.min() > 0.0
    assert burst.mean() == pytest.approx(steady.mean(), rel=0.15), (burst.mean(), steady.mean())


@pytest.mark.parametrize("resume_at, gap, double", [(1.80, 0.0, 0.0), (1.75, 0.0, 0.05), (1.85, 0.05, 0.0)])
def test_a_spray_lane_interrupted_and_resumed_shows_its_seam(rig, resume_at, gap, double):
    """The valve closes mid-lane at x 1.8 and opens again at ``resume_at``: the seam there shows the stretch
    never sprayed (resumed ahead) or sprayed twice (resumed behind), within a pass-map cell."""
    world, arm, comp, wall = rig
    _spray_ready(world, comp, wall)
    _pass(world, arm, wall, [[1.4, 3.3, 1.4]], [0, 1, 0])
    comp.set_valve(True)
    _pass(world, arm, wall, _line(1.4, 1.8, 3.3, 1.4), [0, 1, 0], speed=0.3)
    comp.set_valve(False)
    closed_at = wall.t
    _pass(world, arm, wall, [[1.8, 3.3, 1.4], [resume_at, 3.29, 1.4], [resume_at, 3.3, 1.4]], [0, 1, 0])
    comp.set_valve(True)
    _pass(world, arm, wall, _line(resume_at, 2.2, 3.3, 1.4), [0, 1, 0], speed=0.3)
    comp.set_valve(False)
    _pass(world, arm, wall, [[2.2, 3.3, 1.4], [2.2, 3.2, 1.4]], [0, 1, 0])
    seams = world.outcome.summary()["spray_seams"]
    assert len(seams) == 2, seams                       # the interruption and the lane's end, both in area_1
    seam = min(seams, key=lambda x: abs(x["s"] - 1.8))
    assert seam["wall"] == "wall_1" and seam["area"] == "wall_1_area_1" and seam["s"] == pytest.approx(1.8, abs=0.01)
    assert seam["t"] == pytest.approx(1.4, abs=0.01) and seam["sim_time"] == pytest.approx(closed_at, abs=0.001)
    assert seam["gap_m"] == pytest.approx(gap, abs=0.011) and seam["double_m"] == pytest.approx(double, abs=0.011)


@pytest.mark.parametrize("resume_at, gap, double", [(1.40, 0.0, 0.0), (1.34, 0.0, 0.06), (1.46, 0.06, 0.0)])
def test_a_joint_taped_in_two_passes_shows_its_seam(rig, resume_at, gap, double):
    world, arm, comp, wall = rig
    world.set_base_pose(1.2, 2.5, np.pi / 2)
    world.mount_tool("taping_tool")
    _pass(world, arm, wall, [[1.2, 3.5, 0.9]], [0, 1, 0])
    arm.set_digital_output(0, True)
    _pass(world, arm, wall, _vertical(1.2, 3.6, 0.9, 1.4), [0, 1, 0])
    arm.set_digital_output(0, False)
    _pass(world, arm, wall, [[1.2, 3.55, 1.4], [1.2, 3.55, resume_at], [1.2, 3.6, resume_at]], [0, 1, 0])
    arm.set_digital_output(0, True)
    _pass(world, arm, wall, _vertical(1.2, 3.6, resume_at, 1.9), [0, 1, 0])
    j = world.outcome.summary()["joints"]["wall_1_joint_1"]
    assert j["gap_m"] == pytest.approx(gap, abs=0.015) and j["double_m"] == pytest.approx(double, abs=0.015), j
    z0 = float(world.site.joint("wall_1_joint_1").start[2])       # the report says where the gap lies
    assert [[a + z0, b + z0] for a, b in j["gaps_at_m"]] == (
        [[pytest.approx(1.4, abs=0.011), pytest.approx(1.46, abs=0.011)]] if gap else []), j
