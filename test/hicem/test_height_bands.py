"""Height bands for a robot whose arm rides on a lift: GetLiftHeight (the LIFT that puts a piece of work in the band
the arm reaches from one lift height), GetAreaRaster's bands, and the LiftFor subtree that sends LIFT only on a
robot with a lift (robot.lift.fitted): the shipped robot's LOCEM has no LIFT."""
import os

import pytest
from py_trees.common import Status

from hicem_rig import TREES
from locem_bridge.hicem.xml_loader import TreeLibrary
from test_nodes import Rig

LIFT = {"robot.lift.fitted": True, "robot.lift.range": [0.55, 1.45]}
NO_LIFT = {"robot.lift.fitted": False, "robot.lift.range": []}
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
