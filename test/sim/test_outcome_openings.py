"""Outcome maps and pictures of a wall with a door and a window: nothing lands in a clear opening (what went in is
reported), coverage counts the board outside the areas' holes, a tool on a frame is reported, a lane ending at a
hole is no seam, and the pictures draw the openings and stay readable on a narrow and a wide wall."""
import itertools

import numpy as np
import pytest

from locem_bridge.sim.config import validate_site
from locem_bridge.sim.outcome import OPENING, PANEL_LABELS, OutcomeRecorder
from locem_bridge.sim.site import Site

FRAME = 0.05
DOOR = {"id": "door_1", "kind": "door", "s": [1.0, 1.9], "t": [0.0, 2.05], "frame": FRAME}
WINDOW = {"id": "window_1", "kind": "window", "s": [2.6, 3.5], "t": [0.9, 1.9], "frame": FRAME}
NARROW_WINDOW = {"id": "window_2", "kind": "window", "s": [0.3, 0.7], "t": [1.0, 1.6], "frame": FRAME}


def _site():
    """wall_1: 4 m, a door and a window, a horizontal joint at 1.2 m (cut by both); wall_2: a 1 m wall with a
    window."""
    return validate_site({
        "site": {"name": "bay", "room": {"inside": [2.0, 1.5]}, "walls": [
            {"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.0, 3.0], "height": 2.4, "panel_width": 1.2,
             "skirting": 0.1, "horizontal_joints": [1.2], "openings": [dict(DOOR), dict(WINDOW)]},
            {"id": "wall_2", "p0": [4.0, 3.0], "p1": [4.0, 2.0], "height": 2.4, "panel_width": 0.6,
             "openings": [dict(NARROW_WINDOW)]}]},
        "simulation": {"outcome": {"grid": 0.02, "tape_lateral_tolerance": 0.015, "contact_tolerance": 0.01,
                                   "spray_rate": 0.004, "spray_target_thickness": 0.001}}})


@pytest.fixture
def bay(robot_cfg):
    cfg = _site()
    site = Site(cfg)
    tools = robot_cfg["robot"]["tools"]
    rec = OutcomeRecorder(site, tools, cfg["simulation"]["outcome"])
    wall = site.wall("wall_1")
    standoff = tools["spray_gun"]["standoff"]

    def spray(s0, s1, t0, t1, spacing=0.1, speed=0.1, on_wall=wall):
        """Horizontal lanes, nozzle at the standoff aimed at the wall, the gun on across everything."""
        for t in np.arange(t0, t1 + 1e-9, spacing):
            p0 = on_wall.from_wall_coords(s0, t) + standoff * on_wall.n
            p1 = on_wall.from_wall_coords(s1, t) + standoff * on_wall.n
            rec.record("spray_gun", True, p0, p1, -on_wall.n, abs(s1 - s0) / speed)

    def tool_line(tool, s0, s1, t):
        """One stroke of ``tool`` on the wall surface, switched on, then off."""
        rec.record(tool, True, wall.from_wall_coords(s0, t), wall.from_wall_coords(s1, t), -wall.n, 1.0)
        rec.record(tool, False, wall.from_wall_coords(s1, t), wall.from_wall_coords(s1, t), -wall.n, 0.1)
    return rec, wall, spray, tool_line


def _cells(m, s0, s1, t0, t1):
    """Map cells whose centre lies in s0 < s < s1, t0 < t < t1 (from the wall geometry, not the recorder's masks)."""
    return ((m.sc[None, :] > s0) & (m.sc[None, :] < s1)) & ((m.tc[:, None] > t0) & (m.tc[:, None] < t1))


def test_spray_across_a_door_puts_nothing_in_it_and_reports_what_went_in(bay):
    rec, wall, spray, _ = bay
    spray(0.3, 2.4, 0.5, 1.5)                                  # lanes straight across the door, gun always on
    m = rec.maps["wall_1"]
    door = _cells(m, 1.0, 1.9, 0.0, 2.05)
    assert m.thickness[door].max() == 0.0                      # no wall there: nothing on the thickness map
    beside = _cells(m, 0.5, 0.85, 0.6, 1.4)                    # the board left of the door got its coat
    assert (m.thickness[beside] >= rec.target).all()
    s = rec.summary()
    w1 = s["walls"]["wall_1"]
    band = 0.9 * (1.5 - 0.5)                                   # the door's width across the sprayed band ...
    assert band < w1["sprayed_into_openings_m2"] < 0.9 * (1.5 - 0.5 + 2 * 0.15)    # ... plus the fan's reach
    frames = 2 * FRAME * (1.5 - 0.5)                           # both jambs across the band took spray: a fault
    assert frames <= w1["sprayed_on_frames_m2"] < 2 * FRAME * (1.5 - 0.5 + 2 * 0.15) + 1e-9
    assert w1["sanded_on_frames_m2"] == 0.0
    assert s["sprayed_into_openings_m2"] == w1["sprayed_into_openings_m2"]
    assert s["sprayed_on_frames_m2"] == w1["sprayed_on_frames_m2"] and s["sanded_on_frames_m2"] == 0.0
    assert s["walls"]["wall_2"]["sprayed_into_openings_m2"] == 0.0


def test_coverage_counts_only_the_board_outside_the_holes(bay):
    rec, wall, spray, _ = bay
    w = rec.summary()["walls"]["wall_1"]
    # area: s 0..4, t 0.1..2.4 (above the skirting); holes: the door with its frame (1 x 2.0 m above the skirting)
    # and the window with its frame (1.0 x 1.1 m); cells whose centre falls on a hole's edge may go either way
    assert w["work_area_m2"] == pytest.approx(4.0 * 2.3 - 1.0 * 2.0 - 1.0 * 1.1, abs=0.06)
    spray(-0.1, 4.1, 0.0, 2.5)                                 # the whole wall, openings included
    w = rec.summary()["walls"]["wall_1"]
    assert w["spray_coverage"] >= 0.99                         # the openings (bare: no wall) do not count
    assert w["thickness_cv"] < 0.3
    assert w["sprayed_into_openings_m2"] == pytest.approx(0.9 * 2.05 + 0.9 * 1.0, abs=0.05)


def test_sanding_over_a_frame_is_reported_and_nothing_is_sanded_in_the_opening(bay, robot_cfg):
    rec, wall, _, tool_line = bay
    rad = robot_cfg["robot"]["tools"]["sander"]["pad_radius"]
    tool_line("sander", 2.0, 4.0, 2.2)                         # above the window's frame (top at 1.95)
    assert rec.summary()["sanded_on_frames_m2"] == 0.0
    tool_line("sander", 2.0, 4.0, 1.4)                         # across the window
    m = rec.maps["wall_1"]
    assert not m.sanded[_cells(m, 2.6, 3.5, 0.9, 1.9)].any()
    assert m.sanded[_cells(m, 2.1, 2.5, 1.35, 1.45)].all()     # the board beside it is sanded
    s = rec.summary()
    assert s["sanded_on_frames_m2"] == pytest.approx(2 * FRAME * 2 * rad, rel=0.3)    # both jambs under the pad
    assert s["walls"]["wall_1"]["sanded_on_frames_m2"] == s["sanded_on_frames_m2"]
    assert s["sprayed_on_frames_m2"] == 0.0


def test_tape_is_not_laid_in_a_door(bay):
    rec, wall, _, tool_line = bay
    tool_line("taping_tool", 0.2, 2.4, 1.2)                    # along the horizontal joint, across the door
    s = rec.summary()
    assert s["tape_off_joint_m"] == pytest.approx(2 * FRAME, abs=0.02)     # on the two jambs only
    pieces = [j for j in wall.joints if j.kind == "horizontal"]
    assert [round(j.length, 2) for j in pieces] == [0.95, 0.6, 0.45]
    assert s["joints"][pieces[0].id]["coverage"] == pytest.approx(0.75 / 0.95, abs=0.02)
    assert s["joints"][pieces[1].id]["coverage"] == pytest.approx(0.45 / 0.6, abs=0.03)


@pytest.mark.parametrize("end, seam", [(0.95, False), (0.7, True)])
def test_a_lane_ending_at_a_hole_is_no_seam(bay, end, seam):
    """A lane ends at the door's frame (the area's hole): an edge of the work, not a seam; ended in the middle of
    the board it is one."""
    rec, wall, spray, _ = bay
    spray(0.2, end, 1.0, 1.0)
    rec.record("spray_gun", False, wall.from_wall_coords(end, 1.0), wall.from_wall_coords(end, 1.0), -wall.n, 0.1)
    seams = rec.summary()["spray_seams"]
    assert len(seams) == (1 if seam else 0), seams


def _overlap(a, b):
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


@pytest.mark.parametrize("wall_id, opening", [("wall_1", WINDOW), ("wall_2", NARROW_WINDOW), ("wall_1", DOOR)])
def test_pictures_draw_the_openings_and_keep_their_texts_apart(bay, tmp_path, wall_id, opening):
    from PIL import Image
    rec, wall, spray, _ = bay
    spray(0.3, 2.4, 0.5, 1.5)
    px = 100.0
    lay = rec.picture_layout(wall_id, px)
    w, h = lay.size
    boxes = [t.box for t in lay.texts] + [b for _, b in lay.swatches] + list(lay.panels)
    for a, b in itertools.combinations(boxes, 2):
        assert not _overlap(a, b), (a, b)
    assert all(0 <= x0 and 0 <= y0 and x1 <= w and y1 <= h for x0, y0, x1, y1 in boxes)
    for k, label in enumerate(PANEL_LABELS):                   # each label whole, within its own panel's column
        mine = [t for t in lay.texts if t.role == "label%d" % k]
        assert " ".join(t.text for t in mine) == label
        assert all(lay.columns[k][0] <= t.box[0] and t.box[2] <= lay.columns[k][1] for t in mine)
    title = " ".join(t.text for t in lay.texts if t.role == "title")
    assert title.startswith(wall_id) and opening["id"] in title
    assert {"opening", "frame"} <= {k for k, _ in lay.swatches}

    rec.save_pictures(str(tmp_path), px)
    img = np.asarray(Image.open(str(tmp_path / ("%s.png" % wall_id))).convert("RGB")).astype(int)
    assert img.shape[:2] == (h, w)
    (s0, s1), (t0, t1) = opening["s"], opening["t"]
    for x0, _, _, y1 in lay.panels:                            # on all three panels, inside the clear opening
        clear = img[int(y1 - t1 * px) + 3:int(y1 - t0 * px) - 3, int(x0 + s0 * px) + 3:int(x0 + s1 * px) - 3]
        is_opening = (clear == np.array(OPENING)).all(axis=-1)
        assert is_opening.mean() > 0.9                         # the window's cross / the door's arc: thin lines
    if wall_id == "wall_1":                                    # the thickness panel: sprayed board beside the door
        x0, _, _, y1 = lay.panels[1]
        r, g, b = img[int(y1 - 1.0 * px), int(x0 + 0.6 * px)]
        assert b > 150 and r < 60


def test_a_narrow_wall_gets_a_panel_wide_enough_for_its_labels(bay):
    rec = bay[0]
    narrow, wide = rec.picture_layout("wall_2", 100.0), rec.picture_layout("wall_1", 100.0)
    for lay in (narrow, wide):
        assert [len([t for t in lay.texts if t.role == "label%d" % k]) for k in range(3)] == [1, 1, 1]
        xs = [p[0] for p in lay.panels]
        assert xs == sorted(xs) and all(p[2] - p[0] == lay.panels[0][2] - lay.panels[0][0] for p in lay.panels)
    assert narrow.panels[0][2] - narrow.panels[0][0] == 100     # the wall drawn to scale, centred in its column
    assert narrow.columns[0][1] - narrow.columns[0][0] > 100
    assert wide.panels[0][2] - wide.panels[0][0] == 400
