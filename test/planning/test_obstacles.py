"""Walls that are no work surface (the SCAN's ``obstacles``: concrete) keep the planned base off them too: on
generated bay 21 the concrete wall_3 stands behind the robot working wall_1's last area, not at a corner of
wall_1, and only the scan's obstacles tell the planner about it."""
import copy

import numpy as np
import pytest

from locem_bridge.planning.reach import Wall2D, plan_site, wall_reach
from locem_bridge.sim.bays import generate_bay
from locem_bridge.sim.config import validate_site
from locem_bridge.sim.perception import WallScanner
from locem_bridge.sim.site import Site

def chassis(wall, s_b, standoff, envelope):
    """Corners (4, 2) of the chassis with its centre ``standoff`` in front of ``wall`` at ``s_b``, facing it."""
    centre = wall.p0[:2] + s_b * wall.u[:2] + standoff * wall.n[:2]
    hl, hw = envelope.base_length / 2.0, envelope.base_width / 2.0
    n, u = wall.n[:2], wall.u[:2]
    return np.array([centre + a * hl * n + b * hw * u for a, b in ((-1, -1), (-1, 1), (1, 1), (1, -1))])


def _point_segment(p, a, b):
    t = float(np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * (b - a))))


def _cross(o, a, b):
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _intersect(a, b, c, d):
    return _cross(a, b, c) * _cross(a, b, d) < 0 and _cross(c, d, a) * _cross(c, d, b) < 0


def gap(corners, a, b):
    """Distance between a convex polygon (corners in order) and the segment a-b; 0 when they meet."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    edges = [(corners[i], corners[(i + 1) % len(corners)]) for i in range(len(corners))]
    if all(_cross(p, q, a) >= 0 for p, q in edges) or all(_cross(p, q, a) <= 0 for p, q in edges):
        return 0.0                                       # an end inside the chassis
    if any(_intersect(p, q, a, b) for p, q in edges):
        return 0.0
    return min([_point_segment(c, a, b) for c in corners] + [_point_segment(e, p, q) for e in (a, b) for p, q in edges])


def bay(seed):
    doc = validate_site(generate_bay(seed))
    return doc, Site(copy.deepcopy(doc))


def scan_of(doc, site, robot, noise):
    """What the job's SCAN from the start pose reports (the bay's noise and seed, or none)."""
    sim = doc["simulation"]
    return WallScanner(site, robot["robot"]["scanner"], noise, sim["seed"]).scan(site.robot_start)


def _bases(r):
    """Every free base centre of a plan, sampled along the wall (plus the intervals' ends)."""
    return [s for a, b in r.base for s in list(np.arange(a, b, 0.01)) + [b]]


def test_the_scan_of_bay_21_reports_the_concrete_walls_as_obstacles(robot):
    doc, site = bay(21)
    scan = scan_of(doc, site, robot, doc["simulation"]["perception"]["position_noise"])
    assert [w["id"] for w in scan["walls"]] == ["wall_1", "wall_2"]
    assert [o["id"] for o in scan["obstacles"]] == ["wall_3", "wall_4"]
    w3 = site.wall("wall_3")
    o3 = scan["obstacles"][0]
    assert np.allclose(o3["p0"], w3.p0, atol=0.03) and np.allclose(o3["p1"], w3.p1, atol=0.03)
    # wall_3 meets neither end of wall_1: wall_1's corners say nothing about it
    assert all(other.id != "wall_3" for _end, other, _ang in site.corners("wall_1"))


@pytest.mark.parametrize("noisy", [False, True])
def test_without_obstacles_the_base_backs_into_bay_21s_concrete_wall_and_with_them_it_keeps_clear(robot, envelope,
                                                                                                    noisy):
    doc, site = bay(21)
    noise = doc["simulation"]["perception"]["position_noise"] if noisy else 0.0
    scan = scan_of(doc, site, robot, noise)
    blind = {k: v for k, v in scan.items() if k != "obstacles"}
    w3 = site.wall("wall_3")
    truth = site.wall("wall_1")
    spray = envelope.tools["spray"]
    c = envelope.clearance
    before = plan_site(blind, envelope, works=("spray",)).reach[("wall_1", "spray")]
    after = plan_site(scan, envelope, works=("spray",)).reach[("wall_1", "spray")]
    wall = Wall2D.from_scan(next(w for w in scan["walls"] if w["id"] == "wall_1"))

    def clearance(s_b):
        # the scanned wall's frame puts the base where the robot drives; measured against the true wall_3
        centre = wall.p0 + s_b * wall.u + spray.base_standoff * wall.n
        s_true = float((centre - truth.p0) @ truth.u[:2])
        return gap(chassis(truth, s_true, float((centre - truth.p0) @ truth.n[:2]), envelope), w3.p0, w3.p1)

    # the scan without its obstacles: free base centres whose chassis reaches into wall_3's clearance, touching it
    worst = min(clearance(s) for s in _bases(before))
    assert worst < 0.01
    # with them no free base centre comes nearer than the clearance (less the scan's noise on wall_3's ends)
    tolerance = 1e-3 + (4 * noise if noisy else 0.0)
    assert min(clearance(s) for s in _bases(after)) >= c - tolerance
    # the plan around it: the end of wall_1 at wall_2 is worked from bases further back along the wall
    assert after.base[-1][1] < before.base[-1][1] - 0.2
    # wall_1_area_3 (1.5..2.12 m along wall_1): its sections' bases (the free one nearest each section's middle)
    area = next(a for a in scan["areas"] if a["id"] == "wall_1_area_3")
    s0 = float((np.array(area["origin"][:2]) - wall.p0) @ wall.u)
    sections = [(s0, s0 + area["width"] / 2), (s0 + area["width"] / 2, s0 + area["width"])]
    old = [before.base_for(a, b, spray.reach) for a, b in sections]
    new = [after.base_for(a, b, spray.reach) for a, b in sections]
    assert min(clearance(s) for s in old if s is not None) < c
    assert all(clearance(s) >= c - tolerance for s in new if s is not None)


def test_a_concrete_wall_behind_the_robot_in_a_small_room_is_kept_off(envelope):
    """A room only as deep as the spray base needs: wall_1 (plasterboard) along x, the concrete wall_3 parallel to
    it behind the robot (not at a corner of wall_1), closed by two plasterboard side walls."""
    spray = envelope.tools["spray"]
    depth = spray.base_standoff + envelope.base_length / 2.0 + 0.02     # the chassis' rear 0.02 m from wall_3
    doc = {"site": {"name": "shallow", "room": {"inside": [1.5, 3.0 - depth / 2.0]},
                    "robot_start": [1.5, 3.0 - depth / 2.0, 1.5708], "walls": [
        {"id": "wall_1", "p0": [0.0, 3.0], "p1": [3.0, 3.0], "height": 2.0, "panel_width": 0.75},
        {"id": "wall_2", "p0": [3.0, 3.0], "p1": [3.0, 3.0 - depth], "height": 2.0, "panel_width": 0.75},
        {"id": "wall_3", "material": "concrete", "p0": [3.0, 3.0 - depth], "p1": [0.0, 3.0 - depth], "height": 2.0},
        {"id": "wall_4", "p0": [0.0, 3.0 - depth], "p1": [0.0, 3.0], "height": 2.0, "panel_width": 0.75}]}}
    site = Site(validate_site(doc))
    scan = site.to_contract()
    assert [o["id"] for o in scan["obstacles"]] == ["wall_3"]
    w1 = Wall2D.from_scan(scan["walls"][0])
    walls = [Wall2D.from_scan(w) for w in scan["walls"]]
    blind = wall_reach(w1, walls, envelope, "spray")
    seeing = wall_reach(w1, walls + [Wall2D.from_obstacle(scan["obstacles"][0])], envelope, "spray")
    w3 = site.wall("wall_3")
    truth = site.wall("wall_1")
    assert blind.base and min(gap(chassis(truth, s, spray.base_standoff, envelope), w3.p0, w3.p1)
                              for s in _bases(blind)) == pytest.approx(0.02, abs=1e-6)
    # the chassis cannot stand there with its clearance: no free base, the wall is manual work with its reason
    assert seeing.base == [] and seeing.tool == []
    assert any("no free base pose" in why for _iv, why in seeing.why)
    # plan_site reads the scan's obstacles
    assert plan_site(scan, envelope, works=("spray",)).reach[("wall_1", "spray")].base == []
