"""Real bays in the site model: doors and windows with frames, joints that end at them, work areas that leave
them out, corners at any angle; the PyBullet walls have the openings as holes."""
import copy
import math

import numpy as np
import pytest

from locem_bridge.sim.config import load_robot, validate_site
from locem_bridge.sim.errors import SimConfigError
from locem_bridge.sim.site import Site
from locem_bridge.sim.world import World, wall_boxes

BAY = {"site": {"name": "openings", "room": {"inside": [1.5, 1.2]}, "robot_start": [1.5, 1.2, 1.5708], "walls": [
    {"id": "wall_1", "p0": [0.0, 3.0], "p1": [3.0, 3.0], "height": 2.4, "panel_width": 0.6, "skirting": 0.1,
     "horizontal_joints": [1.2],
     "openings": [{"id": "door_1", "kind": "door", "s": [1.0, 1.9], "t": [0.0, 2.05], "frame": 0.05}]},
    # 120 degrees between wall_1 and wall_2's faces
    {"id": "wall_2", "p0": [3.0, 3.0], "p1": [3.0 + 3.0 * math.cos(math.radians(-60)), 3.0 + 3.0 * math.sin(
        math.radians(-60))], "height": 2.4, "panel_width": 1.2, "horizontal_joints": [0.8],
     "openings": [{"id": "window_1", "kind": "window", "s": [0.8, 2.0], "t": [0.9, 2.0]}],
     "areas": [{"id": "wall_2_area_1", "s": [0.0, 1.4], "t": [0.0, 2.4]},
               {"id": "wall_2_area_2", "s": [1.4, 3.0], "t": [0.0, 2.4]}]},
    {"id": "wall_3", "material": "concrete", "p0": [4.5, 0.4], "p1": [0.0, 3.0], "height": 2.4}]}}


def _site(mutate=None):
    data = copy.deepcopy(BAY)
    if mutate:
        mutate(data)
    return Site(validate_site(data))


def test_joints_end_at_the_frames_of_doors_and_windows():
    site = _site()
    w1 = site.wall("wall_1")
    spans = sorted((round(w1.to_wall_coords(j.start)[0], 3), round(j.start[2], 3), round(j.end[2], 3))
                   for j in w1.joints if j.kind == "vertical")
    # joints at 0.6, 1.2, 1.8, 2.4: those at 1.2 and 1.8 run into the door (frame 0.95..1.95, up to 2.1 m)
    assert spans == [(0.6, 0.1, 2.4), (1.2, 2.1, 2.4), (1.8, 2.1, 2.4), (2.4, 0.1, 2.4)]
    horizontal = sorted(round(w1.to_wall_coords(p)[0], 3) for j in w1.joints if j.kind == "horizontal"
                        for p in (j.start, j.end))
    assert horizontal == [0.0, 0.95, 1.95, 3.0]           # the 1.2 m joint stops at both sides of the door frame
    w2 = site.wall("wall_2")
    under = [j for j in w2.joints if j.kind == "horizontal"]
    assert len(under) == 1 and under[0].length == pytest.approx(3.0)   # under the window: the whole wall
    assert len({j.id for j in site.joints}) == len(site.joints)


def test_areas_carry_the_openings_inside_them_as_holes_and_the_scan_reports_openings_and_corners():
    site = _site()
    a1 = site.wall("wall_1").areas[0]
    assert (a1.t0, a1.height) == (0.1, pytest.approx(2.3))
    assert a1.holes == [pytest.approx((0.95, 1.95, 0.0, 2.0))]       # door + frame, above the skirting
    assert bool(a1.in_hole(1.5, 1.0)) and not bool(a1.in_hole(0.5, 1.0))
    left, right = site.wall("wall_2").areas
    assert left.holes == [pytest.approx((0.75, 1.4, 0.85, 2.05))]
    assert right.holes == [pytest.approx((0.0, 0.65, 0.85, 2.05))]   # the window spans the shared edge
    scan = site.to_contract()
    w2 = next(w for w in scan["walls"] if w["id"] == "wall_2")
    assert w2["openings"] == [{"id": "window_1", "kind": "window", "s": [0.8, 2.0], "t": [0.9, 2.0], "frame": 0.05}]
    assert {c["end"]: round(math.degrees(c["angle"]), 3) for c in w2["corners"]}[0] == 120.0
    w1 = next(w for w in scan["walls"] if w["id"] == "wall_1")
    assert {c["end"]: round(math.degrees(c["angle"]), 3) for c in w1["corners"]}[1] == 120.0


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["site"]["walls"][0]["openings"][0].update(t=[0.3, 2.0]),
     "openings[0].t: a door starts at the floor, found t from 0.3 m"),
    (lambda d: d["site"]["walls"][1]["openings"][0].update(t=[0.0, 1.0]), "a window starts above the floor"),
    (lambda d: d["site"]["walls"][0]["openings"][0].update(s=[2.5, 3.0]), "is not an interval inside the wall"),
    (lambda d: d["site"]["walls"][0]["openings"][0].update(kind="hatch"), "allowed: door, window"),
    (lambda d: d["site"]["walls"][0]["openings"][0].update(width=0.9), "openings[0].width: unknown key"),
    (lambda d: d["site"]["walls"][0]["openings"].append({"id": "door_2", "kind": "door", "s": [1.8, 2.6],
                                                         "t": [0.0, 2.0]}), "overlaps opening 'door_1'"),
    (lambda d: d["site"]["walls"][1]["openings"][0].update(id="wall_2_area_1"), "used twice"),
    (lambda d: d["site"]["walls"][1]["areas"].append({"id": "a3", "s": [0.9, 1.9], "t": [1.0, 1.9]}),
     "lies inside opening 'window_1'"),
])
def test_bad_openings_are_refused_naming_the_key_and_what_is_allowed(mutate, message):
    data = copy.deepcopy(BAY)
    mutate(data)
    with pytest.raises(SimConfigError) as exc:
        validate_site(data)
    assert message in str(exc.value)


def test_the_pybullet_wall_has_the_openings_as_holes_and_a_tool_there_touches_nothing():
    site = _site()
    w1 = site.wall("wall_1")
    boxes = wall_boxes(w1)
    area = sum((b - a) * (d - c) for a, b, c, d in boxes)
    assert area == pytest.approx(3.0 * 2.4 - 0.9 * 2.05)
    world = World(validate_site(copy.deepcopy(BAY)), load_robot(), gui=False)
    try:
        world.set_base_pose(1.45, 2.2, math.pi / 2)
        world.step()
        world.mount_tool("taping_tool")
        w1 = world.site.wall("wall_1")

        def contact(s, t):
            face = w1.from_wall_coords(s, t, -0.003)
            return world.wall_contact(world.tcp_target_in_arm_base(face, -w1.n))
        assert contact(1.45, 1.0) is None                   # in the door: no wall
        assert contact(0.97, 1.0) is not None               # on the frame: wall
        assert contact(1.45, 2.2) is not None               # above the door
        assert np.allclose(contact(0.5, 1.0)[1], contact(1.45, 2.2)[1])
    finally:
        world.close()
