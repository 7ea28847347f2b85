"""Sanding right up to a door's frame (config/sites/door.yaml: the default bay, a 0.9 m x 1.8 m door with a
0.05 m frame in wall_1, wall_1_area_1 s 0.3 .. 2.7 m, t 0.1 .. 2.0 m, the wall 2.0 m high, open above).

SAND_AREA's GetAreaRaster keeps the pad's centre one pad radius (``hole_margin``) off the door and its frame,
so the pad's edge reaches the frame. The strip above the frame (1.85 .. 2.0 m) is thinner than a lane spacing:
with the margin it is 1.9625 .. 2.0 m of pad-centre room. The shipped SAND_AREA tree ticked for the area
through the real LOCEM core and bridges against the worksite stand-ins (UR controller, compressor, drives,
PyBullet world), measured on the world's ground truth: the sanded share of the wall's work cells and the
sanded frame."""
import faulthandler
import os
from typing import Any, Dict

import pytest

from test_adjacent_areas import work_areas_on_site

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DOOR = os.path.join(REPO, "config", "sites", "door.yaml")


def bare_cells(maps: Any) -> Dict[str, int]:
    """The work cells left unsanded on wall_1 of the door site, by where they lie: above the door's frame (over
    its width), beside the frame (within a pad diameter of its sides, below its top), elsewhere."""
    bare = maps.work & ~maps.sanded
    s, t = maps.sc[None, :], maps.tc[:, None]
    above = bare & (s > 1.05) & (s < 2.05) & (t > 1.85)
    beside = bare & ~above & (((s > 1.05 - 0.225) & (s < 1.05)) | ((s > 2.05) & (s < 2.05 + 0.225))) & (t < 1.85)
    return {"above": int(above.sum()), "beside": int(beside.sum()), "elsewhere": int((bare & ~above & ~beside).sum()),
            "work": int(maps.work.sum())}


@pytest.mark.slow
def test_the_door_area_is_sanded_up_to_the_frame_all_round_without_touching_it():
    """About 40 s at time scale 10. Measured: before GetAreaRaster.FRAME_REACH (the pad's edge exactly on the
    frame's outer line) sand coverage 0.960 of wall_1's work cells, 285 bare: 51 in the row along the frame's top
    (1.85 m), 174 in the columns along its sides, 60 more between the lanes' ends beside it; with it 0.974, 184
    bare: none above the door, 184 beside it (a round pad at a lane's end reaches the frame's side only near the
    lane's height: between two lanes 0.173 m apart it stops up to 4 cm short); with the vertical pass up each
    side of the frame (edge_passes) 1.000, no cell bare. Never a frame cell sanded."""
    pytest.importorskip("rtde_control")
    faulthandler.dump_traceback_later(240, exit=True)    # ur_rtde may hold the GIL while it blocks
    try:
        out = work_areas_on_site(DOOR, "sand", ["wall_1_area_1"], time_scale=10.0)
    finally:
        faulthandler.cancel_dump_traceback_later()
    wall, cells = out["wall"], bare_cells(out["maps"])
    print("wall_1 sanded: coverage %.4f, on frames %.4f m2, bare cells %r; %.0f s; %s"
          % (wall["sand_coverage"], wall["sanded_on_frames_m2"], cells, out["seconds"],
             [c for c in out["sent"] if c.startswith("SAND_AREA")]))
    assert out["details"][0][1].startswith("sanded"), out["details"]
    # one vertical pass up each side of the frame, the pad's radius (less FRAME_REACH) off it, from the floor's
    # band to the frame's top plus that margin
    passes = [c.split() for c in out["sent"] if c.startswith("SAND_AREA") and "lanes=vertical" in c]
    assert len(passes) == 2, out["sent"]
    assert sorted(float(p[1]) for p in passes) == pytest.approx([1.05 - 0.1105, 2.05 + 0.1105], abs=0.01)
    assert all(float(p[7]) == 0.0 for p in passes)
    assert wall["sand_coverage"] >= 0.98, (wall, cells)
    assert cells["beside"] <= 20, cells
    assert wall["sanded_on_frames_m2"] == 0.0, wall
    assert cells["above"] == 0, cells
    assert out["collisions"] == 0
