"""Height bands for a robot whose arm rides on a lift: GetLiftHeight (the LIFT that puts a piece of work in the band
the arm reaches from one lift height), GetAreaRaster's bands, and the LiftFor subtree that sends LIFT only on a
robot with a lift (robot.lift.fitted): the shipped robot's LOCEM has no LIFT."""
import math
import os

import pytest
from py_trees.common import Status

from hicem_rig import TREES
from locem_bridge.hicem.xml_loader import TreeLibrary
from test_nodes import Rig

LIFT = {"robot.lift.fitted": True, "robot.lift.range": [0.55, 1.45], "cfg.plan.min_manual": 0.03}
NO_LIFT = {"robot.lift.fitted": False, "robot.lift.range": [], "cfg.plan.min_manual": 0.03}
BAND = "0.10;1.45"


def _lift(z, cfg):
    rig = Rig('<GetLiftHeight z="%s" band="%s" command="{c}" height="{h}"/>' % (z, BAND), cfg=cfg)
    return rig, rig.tree.tick()


def test_the_lift_puts_the_arm_mount_at_the_pieces_middle_within_the_lift_range():
    rig, st = _lift("0.70;1.50", LIFT)         # band 0.65..2.00 at 1.10
    assert st == Status.SUCCESS and rig.bb.get("h") == pytest.approx(1.10) and rig.bb.get("c") == "LIFT z=1.1000"
    rig, st = _lift("0.20;1.50", LIFT)         # the mount at the middle (0.85) would leave 0.20 below its band:
    assert st == Status.SUCCESS and rig.bb.get("c") == "LIFT z=0.6500"     # the highest that keeps it in
    rig, st = _lift("1.05;2.0", LIFT)          # the upper half of a 0.10..2.0 m joint: the lift at its top
    assert st == Status.SUCCESS and rig.bb.get("c") == "LIFT z=1.4500"
    rig, st = _lift("0.10;1.05", LIFT)         # the lower half: the lift at its bottom
    assert st == Status.SUCCESS and rig.bb.get("c") == "LIFT z=0.5500"
    rig, st = _lift("0.10;2.0", LIFT)          # 1.9 m do not fit the 1.35 m band at any height
    assert st == Status.FAILURE
    assert "heights 0.100..2.000 m are out of reach from one lift height (band 0.10..1.45 m" in rig.reason()
    rig, st = _lift("2.2;2.6", LIFT)           # above the band at the lift's top
    assert st == Status.FAILURE and "lift 0.55..1.45 m" in rig.reason()


def test_a_piece_a_few_millimetres_past_the_band_fits_within_the_tolerance():
    """A joint taped to its scanned end 1 mm below the band (GetTapePlan's min_manual) on the lift robot (job_robot2:
    'heights 0.099..1.051 m are out of reach from one lift height' without it)."""
    rig = Rig('<GetLiftHeight z="0.099;1.051" band="%s" command="{c}" height="{h}"/>' % BAND, cfg=LIFT)
    assert rig.tree.tick() == Status.FAILURE and "0.099..1.051" in rig.reason()
    rig = Rig('<GetLiftHeight z="0.099;1.051" band="%s" tolerance="0.03" command="{c}" height="{h}"/>' % BAND,
              cfg=LIFT)
    assert rig.tree.tick() == Status.SUCCESS and rig.bb.get("c") == "LIFT z=0.5500"     # the lift's bottom
    rig = Rig('<GetLiftHeight z="0.05;1.051" band="%s" tolerance="0.03" command="{c}" height="{h}"/>' % BAND,
              cfg=LIFT)
    assert rig.tree.tick() == Status.FAILURE                 # 5 cm past it: no


def test_without_a_lift_no_command_and_the_reach_is_left_to_locem():
    rig, st = _lift("0.10;2.0", NO_LIFT)
    assert st == Status.SUCCESS and rig.bb.get("c") == "" and rig.bb.get("h") == 0.0


def _raster(band_height, gap):
    rig = Rig('<GetAreaRaster area_id="wall_1_area_1" section_width="1.6" base_standoff="1.0" yaw_offset="0" '
              'band_height="%s" band_gap="%s" sections="{s}" count="{n}"/>' % (band_height, gap))
    assert rig.tree.tick() == Status.SUCCESS, rig.reason()
    return rig.bb.get("s"), rig.bb.get("n")


def test_an_area_taller_than_one_band_is_cut_into_bands_serpentine_no_lane_twice():
    # wall_1_area_1: 4.8 m wide, 2.5 m high from z 0: 3 columns of 1.6 m
    one, n = _raster(0.0, 0.15)
    assert n == 3 and [s["height"] for s in one] == [2.5] * 3 and [s["z"] for s in one] == [[0.0, 2.5]] * 3
    secs, n = _raster(1.35, 0.15)
    assert n == 6 and [s["index"] for s in secs] == list(range(6))
    # two bands of (2.5 - 0.15) / 2 = 1.175 m: the upper one starts one lane spacing above the lower one's top
    assert [s["z"] for s in secs[:2]] == [pytest.approx([0.0, 1.175]), pytest.approx([1.325, 2.5])]
    # bottom first in the first column, then each column starts in the band the one before ended in (the lift
    # moves once between columns)
    assert [s["origin"][2] for s in secs] == [pytest.approx(z) for z in (0.0, 1.325, 1.325, 0.0, 0.0, 1.325)]
    pairs = [(secs[k], secs[k + 1]) if k % 4 == 0 else (secs[k + 1], secs[k]) for k in range(0, 6, 2)]
    for (low, high), col in zip(pairs, one):
        assert low["approach"] == high["approach"] == col["approach"]
        assert low["origin"][:2] == high["origin"][:2] == col["origin"][:2]
        assert low["origin"][2] == pytest.approx(0.0) and high["origin"][2] == pytest.approx(1.325)
        assert low["height"] == high["height"] == pytest.approx(1.175)


def _lift_for(cfg):
    body = '<SubTree ID="LiftFor" z="0.10;1.05" band="%s"/>' % BAND
    rig = Rig("<AlwaysSuccess/>", cfg=cfg)
    lib = TreeLibrary()
    lib.load_file(os.path.join(TREES, "common.xml"))
    lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T">%s</BehaviorTree></root>' % body)
    rig.tree = lib.build("T", rig.ctx, rig.bb)
    for _ in range(20):
        st = rig.tree.tick()
        if st != Status.RUNNING:
            return rig, st
    raise AssertionError("LiftFor still running")


def test_lift_for_sends_lift_only_on_a_robot_with_a_lift():
    rig, st = _lift_for(LIFT)
    assert st == Status.SUCCESS and rig.locem.sent == ["LIFT z=0.5500"]
    rig, st = _lift_for(NO_LIFT)
    assert st == Status.SUCCESS and rig.locem.sent == []


def _robot2_tape_plan(line, outwards):
    from locem_bridge.hicem.config import DEFAULT_PARAMS_FILE, load_params
    from locem_bridge.robot_file import default_robot_path
    facts = load_params(DEFAULT_PARAMS_FILE, robot_file=os.path.join(os.path.dirname(default_robot_path()),
                                                                      "diffdrive_ur5e.yaml")).blackboard_entries()
    rig = Rig('<Sequence><GetWallReach feature_id="%s" work="taping" plan="{p}"/>'
              '<GetTapePlan line_id="%s" plan="{p}" outwards="%s" segments="{s}" count="{c}" manual="{m}" '
              'status="{st}" detail="{d}"/></Sequence>' % (line, line, outwards), cfg=facts)
    assert rig.tree.tick() == Status.SUCCESS, rig.reason()
    return rig.bb, facts


def test_a_lift_robot_plans_a_joint_and_tapes_it_from_the_middle_outwards_one_lift_height_per_piece():
    """TAPE_LINE on the second robot (arm on a lift): the joint is planned like on the first (GetWallReach,
    GetTapePlan: clipped to what the tool reaches over the lift's travel, the rest manual), then taped from its
    middle outwards in pieces no longer than segment_length, each fitting the band of one lift height."""
    whole, facts = _robot2_tape_plan("wall_1_joint_1", "false")
    bb, _ = _robot2_tape_plan("wall_1_joint_1", "true")
    z_lo, z_hi = facts["robot.work.taping.z_range"]                  # 0.10 .. 2.35 over the lift's travel
    band = facts["robot.work.taping.z_band"]
    assert [s["z"] for s in whole.get("s")] == [pytest.approx([z_lo, z_hi])]        # one piece: no lift height fits
    pieces = bb.get("s")
    mid = (z_lo + z_hi) / 2.0
    # middle to top, then middle to bottom; each within one lift height's band and segment_length
    seg = facts["robot.work.taping.segment_length"]
    n = int(math.ceil((z_hi - mid) / seg - 1e-9))
    assert len(pieces) == 2 * n
    up = [mid + (z_hi - mid) * i / n for i in range(n + 1)]
    down = [mid + (z_lo - mid) * i / n for i in range(n + 1)]
    ends = [v for a, b in list(zip(up, up[1:])) + list(zip(down, down[1:])) for v in (a, b)]
    assert [v for s in pieces for v in (s["start"][2], s["end"][2])] == pytest.approx(ends)
    assert all(s["z"] == sorted(s["z"]) and s["z"][1] - s["z"][0] <= min(band[1] - band[0], seg) + 1e-9
               for s in pieces)
    assert all(s["approach"] == whole.get("s")[0]["approach"] for s in pieces)        # one base pose
    assert [v for s in pieces for v in s["along"]] == pytest.approx(ends)     # the joint runs up from z 0
    # what is out of reach is manual work, the same as planned without the lift's pieces
    assert bb.get("m") == whole.get("m") and [m["along"] for m in bb.get("m")] == [[0.0, z_lo],
                                                                                   pytest.approx([z_hi, 2.5])]
    assert bb.get("st") == "taped" and bb.get("d").startswith("taped; manual work on wall_1_joint_1")
