"""Plan before touching (planning.reach): what the robot can work near corners of any angle, checked against the
PyBullet worksite -- the planned base and tool poses touch nothing but the wall being worked, while the pose an
unplanned raster would take in the same corner does."""
import copy
import math

import numpy as np
import pytest

from locem_bridge.planning.reach import Wall2D, plan_area, plan_joint, plan_site, wall_reach
from locem_bridge.sim.config import validate_site
from locem_bridge.sim.site import Site

def corner_site(angle_deg, length=3.0):
    """wall_1 (plasterboard) along x from (0, 3) to (length, 3), the room below it; at its p1 a concrete wall_2
    meets it at ``angle_deg`` between the faces, at its p0 a square corner; a fourth wall closes the room."""
    a = math.radians(angle_deg)
    p1 = np.array([length, 3.0])
    p2 = p1 + 3.0 * np.array([-math.cos(a), -math.sin(a)])   # along wall_2, away from the corner
    p3 = np.array([0.0, -1.0])
    inside = (np.array([0.0, 3.0]) + p1 + p2 + p3) / 4.0
    doc = {"site": {"name": "corner_%d" % angle_deg, "room": {"inside": inside.tolist()},
                    "robot_start": [float(inside[0]), float(inside[1]), 1.5708], "walls": [
        {"id": "wall_1", "p0": [0.0, 3.0], "p1": p1.tolist(), "height": 2.0, "panel_width": 0.75,
         "horizontal_joints": [1.2]},
        {"id": "wall_2", "material": "concrete", "p0": p1.tolist(), "p1": p2.tolist(), "height": 2.0},
        {"id": "wall_3", "material": "concrete", "p0": p2.tolist(), "p1": p3.tolist(), "height": 2.0},
        {"id": "wall_4", "material": "concrete", "p0": p3.tolist(), "p1": [0.0, 3.0], "height": 2.0}]}}
    return validate_site(doc)


def _reach(angle, envelope, work):
    scan = Site(copy.deepcopy(corner_site(angle))).to_contract()
    w1 = Wall2D.from_scan(scan["walls"][0])
    return w1, wall_reach(w1, [w1], envelope, work), scan


@pytest.mark.parametrize("work", ["taping", "spray", "sand"])
def test_the_sharper_the_corner_the_more_is_left_to_the_hand(envelope, work):
    ends, bases = {}, {}
    for angle in (60, 90, 120, 150):
        w1, r, _ = _reach(angle, envelope, work)
        assert len(r.tool) == 1
        ends[angle], bases[angle] = r.tool[0][1], r.base[-1][1]
    tool = envelope.tools[work]
    arm = envelope.wrist_offset + envelope.arm_radius          # the wrist beside the tool axis
    room = max(tool.tip_radius, tool.body_radius, arm) + envelope.clearance + tool.run_on   # lanes run on
    for angle in (60, 90, 120, 150):                          # the square corner at p0: only the tool's own size
        assert _reach(angle, envelope, work)[1].tool[0][0] == pytest.approx(room, abs=0.011)
    # a square corner: the tool and the wrist beside it keep their radius plus the clearance from the corner's
    # edge; an acute one leaves more (the neighbour leans over the wall), an obtuse one less
    assert ends[90] == pytest.approx(3.0 - room, abs=0.011)
    assert ends[60] < ends[90] - 0.2 and ends[90] <= ends[120] <= ends[150]
    # the base gets closer to the corner the wider it is
    assert bases[60] < bases[90] <= bases[120] <= bases[150] and bases[90] < 3.0


def test_an_area_into_a_corner_is_cut_where_the_robot_stops_and_the_rest_is_manual_with_its_extent(envelope):
    w1, r, scan = _reach(60, envelope, "sand")
    area = scan["areas"][0]
    plan = plan_area(area, w1, r)
    (s0, s1, t0, t1), = plan.parts
    assert s0 == pytest.approx(r.tool[0][0]) and s1 == pytest.approx(r.tool[0][1])
    corner = [m for m in plan.manual if m["along"][1] == pytest.approx(area["width"])]
    assert len(corner) == 1 and corner[0]["along"][0] == pytest.approx(s1)
    assert corner[0]["height"] == [area["origin"][2], area["origin"][2] + area["height"]]
    assert "base" in corner[0]["reason"] or "touch" in corner[0]["reason"]
    # the manual parts and the worked part tile the area along the wall
    along = sorted([(s0, s1)] + [tuple(m["along"]) for m in plan.manual if m["height"][1] - m["height"][0] >= area["height"] - 1e-9])
    assert along[0][0] == pytest.approx(0.0) and along[-1][1] == pytest.approx(area["width"])
    assert all(a[1] == pytest.approx(b[0]) for a, b in zip(along, along[1:]))


def test_an_area_drawn_a_few_millimetres_past_a_wall_end_is_worked_to_its_ends_with_its_lanes_open(envelope):
    """An area drawn to a wall's ends that the scan puts a few millimetres inside them (bay 99's wall_1: 0.4 mm),
    where the tool works right up to the wall's ends: the strip past each end is worked with the part beside it.
    Else the worked part and its manual bands began 0.4 mm in, the sliver beside them closed the raster's
    end, its lanes ran on past neither, and the fan's soft edge left 2 cm of the robot's part under the target
    thickness. A strip inside the wall, where the tool is kept off something, stays out."""
    from locem_bridge.planning.area_pieces import area_pieces
    from locem_bridge.planning.reach import WallReach
    w1, r, scan = _reach(90, envelope, "spray")
    free = WallReach(w1.id, "spray", [(0.0, w1.length)], [(0.0, w1.length)], r.t)     # a wall with free ends
    area = dict(scan["areas"][0])
    area["origin"] = list(w1.point(-0.004, 0.0)) + [0.0]            # 4 mm before the wall's start
    area["width"] = w1.length + 0.006                               # 2 mm past its end
    area["height"] = r.t[1] + 0.3                                   # past the tool's band: manual bands
    plan = plan_area(area, w1, free, min_manual=0.03)
    (s0, s1, _t0, _t1), = plan.parts
    assert (s0, s1) == (pytest.approx(0.0), pytest.approx(area["width"]))
    assert plan.manual and all(m["along"] == [pytest.approx(0.0), pytest.approx(area["width"])]
                               for m in plan.manual)        # the bands below and above the tool's, end to end
    holes = [(m["along"][0], m["along"][1], m["height"][0], m["height"][1]) for m in plan.manual]
    pieces = [p for p in area_pieces(area["width"], area["height"], holes) if p.width > 1e-6]
    assert len(pieces) == 1 and pieces[0].open_left and pieces[0].open_right
    # where the tool stops inside the wall (the square corner's clearance) the strip before it stays out
    lo, _hi = r.tool[0]
    area["origin"] = list(w1.point(lo - 0.004, 0.0)) + [0.0]
    area["width"] = 1.0
    (s0, _s1, _t0, _t1), = plan_area(area, w1, r, min_manual=0.03).parts
    assert s0 == pytest.approx(0.004)


def test_a_joint_too_close_to_a_sharp_corner_is_manual_and_a_horizontal_one_is_cut_there(envelope):
    w1, r, scan = _reach(60, envelope, "taping")
    plans = {j["id"]: plan_joint(j, w1, r) for j in scan["joints"]}
    last = max((j for j in scan["joints"] if j["kind"] == "vertical"), key=lambda j: j["start"][0])
    assert last["start"][0] == pytest.approx(2.25) and plans[last["id"]].piece is None
    horizontal = next(j for j in scan["joints"] if j["kind"] == "horizontal")
    piece = plans[horizontal["id"]].piece
    assert piece[1][0] == pytest.approx(r.tool[0][1], abs=1e-6)
    assert plans[horizontal["id"]].manual[-1]["to"][0] == pytest.approx(3.0)


@pytest.mark.parametrize("angle", [60, 90, 120])
def test_a_horizontal_joint_is_taped_in_pieces_from_free_bases_up_to_the_corner(envelope, angle):
    w1, r, scan = _reach(angle, envelope, "taping")
    horizontal = next(j for j in scan["joints"] if j["kind"] == "horizontal")
    plan = plan_joint(horizontal, w1, r, side=0.4, segment_length=1.2)
    total = math.dist(horizontal["start"], horizontal["end"])
    reachable = r.tool[0][1] - r.tool[0][0]
    assert len(plan.pieces) == math.ceil(reachable / 1.2)  # no piece longer than the arm tapes from one pose
    for piece in plan.pieces:
        a, b = piece["along"]
        assert 0.0 <= a < b <= total + 1e-9 and b - a <= 1.2 + 1e-9
        s0 = piece["from"][0]                              # wall_1 runs along x from 0
        s1 = piece["to"][0]
        # taped from a free base centre that reaches both ends from one pose
        assert any(p - 1e-9 <= piece["base"] <= q + 1e-9 for p, q in r.base)
        assert abs(piece["base"] - (s0 + s1) / 2.0) <= (b - a) / 2.0 + 1e-6
        assert r.tool[0][0] - 1e-9 <= min(s0, s1) and max(s0, s1) <= r.tool[0][1] + 1e-9
    # the pieces and the manual parts tile the joint, the manual part at the corner end with its reason
    parts = sorted([tuple(p["along"]) for p in plan.pieces] + [tuple(m["along"]) for m in plan.manual])
    assert parts[0][0] == pytest.approx(0.0) and parts[-1][1] == pytest.approx(total)
    assert all(x[1] == pytest.approx(y[0]) for x, y in zip(parts, parts[1:]))
    corner = [m for m in plan.manual if m["along"][1] == pytest.approx(total)]
    assert len(corner) == 1 and corner[0]["reason"] and corner[0]["to"][0] == pytest.approx(3.0)
    # the sharper the corner, the longer the manual end
    assert corner[0]["along"][1] - corner[0]["along"][0] == pytest.approx(3.0 - r.tool[0][1], abs=1e-6)


def test_a_vertical_joint_is_clipped_to_the_band_and_left_whole_when_no_base_is_free_near_it(envelope):
    w1, r, scan = _reach(60, envelope, "taping")
    first = min((j for j in scan["joints"] if j["kind"] == "vertical"), key=lambda j: j["start"][0])
    tall = dict(first, start=[first["start"][0], first["start"][1], 0.0], end=[first["end"][0], first["end"][1], 2.5])
    plan = plan_joint(tall, w1, r, side=0.4)
    (piece,) = plan.pieces
    assert piece["from"][2] == pytest.approx(r.t[0]) and piece["to"][2] == pytest.approx(r.t[1])
    assert [m["reason"] for m in plan.manual] == ["below the tool's reach", "above the tool's reach"]
    # a joint in the corner: its tool point reachable from a base up to 0.4 m beside it, but not with side=0.05
    last = max((j for j in scan["joints"] if j["kind"] == "vertical"), key=lambda j: j["start"][0])
    w90, r90, _ = _reach(90, envelope, "taping")
    s = last["start"][0]
    if any(p <= s <= q for p, q in r90.tool) and not any(p <= s <= q for p, q in r90.base):
        narrow = plan_joint(last, w90, r90, side=0.05)
        assert narrow.pieces == [] and "no free base pose" in narrow.manual[0]["reason"]


def test_a_stretch_of_joint_shorter_than_the_shortest_piece_is_manual_not_a_stub_of_tape(envelope):
    """A horizontal joint whose reachable stretch is a few centimetres (cut by a corner and a frame: seed 125's
    wall_4_joint_2 taped 5 cm) and a vertical one whose part in the band is: manual, with that reason."""
    from locem_bridge.planning.reach import SHORTEST_PIECE, WallReach
    w1, r, scan = _reach(90, envelope, "taping")
    horizontal = next(j for j in scan["joints"] if j["kind"] == "horizontal")
    p0 = r.tool[0][0]
    cut = WallReach(r.wall, r.work, [(p0, p0 + 0.06), (p0 + 0.5, p0 + 1.0)], list(r.base), r.t, list(r.why))
    plan = plan_joint(horizontal, w1, cut, side=0.4, segment_length=1.2)
    assert [round(p["along"][1] - p["along"][0], 6) for p in plan.pieces] == [0.5]
    stub = [m for m in plan.manual if m["along"][0] <= p0 + 0.03 <= m["along"][1]]
    assert len(stub) == 1 and stub[0]["reason"] == "shorter than the 0.10 m the robot tapes as one piece"
    assert SHORTEST_PIECE == 0.10
    vertical = next(j for j in scan["joints"] if j["kind"] == "vertical")
    top = dict(vertical, start=[vertical["start"][0], vertical["start"][1], r.t[1] - 0.06],
               end=[vertical["end"][0], vertical["end"][1], r.t[1] + 0.3])
    plan = plan_joint(top, w1, r, side=0.4)
    assert plan.pieces == [] and [m["reason"] for m in plan.manual] == [stub[0]["reason"]]


def test_planning_takes_milliseconds_per_wall(envelope):
    scan = Site(copy.deepcopy(corner_site(90))).to_contract()
    plan = plan_site(scan, envelope)
    assert set(plan.seconds) == {"wall_1"} and plan.seconds["wall_1"] < 1.0


@pytest.fixture(scope="module")
def kinematics(robot):
    from locem_bridge.sim.config import resolve_arm_urdf
    from locem_bridge.sim.ur.kinematics import ArmKinematics
    return ArmKinematics(resolve_arm_urdf(robot["robot"]["arm"])[0])


TOOL = {"taping": "taping_tool", "spray": "spray_gun", "sand": "sander"}


def _touches(world, kinematics, robot, wall, base_s, tool_s, z, work, envelope):
    """What the robot touches with its base at ``base_s`` facing ``wall`` and the tool working at ``tool_s``, z."""
    from locem_bridge.sim.ur.kinematics import KinematicsError
    tool = envelope.tools[work]
    heading = math.atan2(-wall.n[1], -wall.n[0])
    bx, by = wall.p0[:2] + base_s * wall.u[:2] + tool.base_standoff * wall.n[:2]
    world.set_base_pose(float(bx), float(by), heading)
    world.step()
    point = wall.from_wall_coords(tool_s, z, tool.tip_distance)
    pose = world.tcp_target_in_arm_base(point, -wall.n)
    seed = robot["robot"]["arm"]["named_poses"]["wall_ready"]
    length = robot["robot"]["tools"][TOOL[work]]["tcp"][2]
    try:
        q = kinematics.ik(pose, seed, tcp_pose=[0.0, 0.0, length, 0.0, 0.0, 0.0])
    except KinematicsError:
        return [("ik", "unreachable")]
    return [(part, wid) for part, wid in world.touching(q) if not (part == "tool" and wid == wall.id)]


@pytest.mark.parametrize("angle", [60, 90, 120])
@pytest.mark.parametrize("work", ["taping", "spray", "sand"])
def test_planned_poses_touch_nothing_but_the_worked_wall_in_the_simulated_world(angle, work, robot, envelope,
                                                                                kinematics):
    from locem_bridge.sim.world import World
    site_doc = corner_site(angle)
    world = World(copy.deepcopy(site_doc), robot, gui=False)
    try:
        world.mount_tool(TOOL[work])
        wall = world.site.wall("wall_1")
        w1, r, _ = _reach(angle, envelope, work)
        (a, b), = r.tool
        for s in (b, b - 0.2):                        # the last point reached at the corner, and just before it
            base = r.base_for(s, s, envelope.tools[work].reach)
            assert base is not None
            for z in (0.3, 1.0, 1.7):
                assert _touches(world, kinematics, robot, wall, base, s, z, work, envelope) == [], (s, z)
        if angle <= 90:
            # without planning: the base centred on the last 0.6 m of an area that runs into the corner
            naive = _touches(world, kinematics, robot, wall, 3.0 - 0.3, 3.0 - 0.05, 1.0, work, envelope)
            assert naive != []
    finally:
        world.close()


def test_under_a_ceiling_a_pad_stays_its_radius_below_it_and_a_free_standing_wall_is_worked_to_its_top(envelope):
    doc = corner_site(90)
    scan = Site(copy.deepcopy(doc)).to_contract()
    free = Wall2D.from_scan(scan["walls"][0])
    assert wall_reach(free, [free], envelope, "sand").t[1] == envelope.tools["sand"].z_range[1]
    doc["site"]["room"]["ceiling"] = 2.0
    scan = Site(validate_site(doc)).to_contract()
    assert scan["walls"][0]["ceiling"] == 2.0
    under = Wall2D.from_scan(scan["walls"][0])
    sand = envelope.tools["sand"]
    assert wall_reach(under, [under], envelope, "sand").t[1] == pytest.approx(2.0 - sand.tip_radius - envelope.clearance)
    area = scan["areas"][0]
    top = [m for m in plan_area(area, under, wall_reach(under, [under], envelope, "sand")).manual
           if m["height"][0] > 1.0]
    assert len(top) == 1 and "ceiling" in top[0]["reason"] and top[0]["height"][1] == pytest.approx(2.0)
