"""GetTapeSegments: a joint line cut into pieces an arm reaches from one base pose each (the TAPE_LINE tree)."""
import math

import pytest
from py_trees.common import Status

from test_nodes import Rig

CFG = {"robot.work.taping.segment_length": 1.2, "robot.work.taping.z_range": [0.0, 2.2]}
BODY = '<GetTapeSegments line_id="%s" segments="{s}" count="{c}" skipped="{k}"/>'


def test_vertical_joint_is_clipped_to_the_band_and_taped_outwards_from_its_middle():
    rig = Rig(BODY % "wall_1_joint_1", cfg=CFG)
    assert rig.tree.tick() == Status.SUCCESS
    segs = rig.bb.get("s")
    assert rig.bb.get("c") == 2 and len(segs) == 2
    # wall_1 at y=3, normal -y, surface_offset 0.01, standoff 0.8, lateral_offset 0.1 (Rig's cfg)
    up, down = segs
    assert up["start"] == pytest.approx([1.2, 2.99, 1.1]) and up["end"] == pytest.approx([1.2, 2.99, 2.2])
    assert down["start"] == pytest.approx([1.2, 2.99, 1.1]) and down["end"] == pytest.approx([1.2, 2.99, 0.0])
    for s in segs:
        assert s["approach"] == pytest.approx([1.3, 2.2, math.pi / 2])
        assert s["normal"] == pytest.approx([0.0, -1.0, 0.0])
    assert rig.bb.get("k") == pytest.approx(0.3)


def test_horizontal_joint_is_cut_into_pieces_each_approached_in_front_of_its_middle():
    rig = Rig(BODY % "wall_2_joint_1", cfg=dict(CFG, **{"robot.work.taping.segment_length": 0.8}))
    assert rig.tree.tick() == Status.SUCCESS
    segs = rig.bb.get("s")
    # 2.0 m from y=2.5 to y=0.5 on wall_2 (x=4.8, normal -x): three pieces of 2/3 m, no length skipped
    assert rig.bb.get("c") == 3 and rig.bb.get("k") == pytest.approx(0.0)
    assert sum(s["length"] for s in segs) == pytest.approx(2.0)
    assert segs[0]["start"] == pytest.approx([4.79, 2.5, 1.2]) and segs[-1]["end"] == pytest.approx([4.79, 0.5, 1.2])
    for a, b in zip(segs, segs[1:]):
        assert a["end"] == pytest.approx(b["start"])
    # wall_2 tangent is -y: lateral_offset 0.1 moves the base towards -y; base 0.8 m in front, facing +x
    mids = [(s["start"][1] + s["end"][1]) / 2.0 for s in segs]
    assert [s["approach"][1] for s in segs] == pytest.approx([m - 0.1 for m in mids])
    assert all(s["approach"][0] == pytest.approx(4.0) and s["approach"][2] == pytest.approx(0.0) for s in segs)


def test_joint_outside_the_band_fails_with_the_heights_and_bad_ports_are_named():
    rig = Rig(BODY % "wall_2_joint_1", cfg=dict(CFG, **{"robot.work.taping.z_range": [1.5, 2.2]}))
    rig2 = Rig(BODY % "wall_1_joint_1", cfg=dict(CFG, **{"robot.work.taping.z_range": [2.6, 3.0]}))
    assert rig2.tree.tick() == Status.FAILURE
    assert "outside the reachable band 2.60..3.00" in rig2.reason()
    # a horizontal joint is not clipped by height (its height is the line's own)
    assert rig.tree.tick() == Status.SUCCESS
    bad = Rig(BODY % "wall_1_joint_1", cfg=dict(CFG, **{"robot.work.taping.z_range": [2.0, 1.0]}))
    assert bad.tree.tick() == Status.FAILURE
    assert "z_range must be two heights z_min < z_max, got [2.0, 1.0]" in bad.reason()
