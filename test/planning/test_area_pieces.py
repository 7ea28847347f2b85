"""An area with door and window holes cut into rectangles a horizontal raster can work evenly."""
import itertools
import random

import pytest

from locem_bridge.planning.area_pieces import area_pieces, shared_bottom, shared_ends


def _covers(pieces, width, height, holes, gap, step=0.01):
    """Every grid point of the area outside the holes lies in a piece, or in the gap a piece leaves below it
    above the piece it sits on; no point lies in two pieces or in a hole."""
    def in_hole(s, t):
        return any(a < s < b and c < t < d for a, b, c, d in holes)
    missing = []
    for i, j in itertools.product(range(int(width / step)), range(int(height / step))):
        s, t = (i + 0.5) * step, (j + 0.5) * step
        inside = [p for p in pieces if p.s0 < s < p.s1 and p.t0 - (gap if p.on_piece else 0.0) < t < p.t1]
        assert len(inside) <= 1, (s, t, inside)
        if in_hole(s, t):
            assert not any(p.s0 < s < p.s1 and p.t0 < t < p.t1 for p in pieces), (s, t)
        elif not inside:
            missing.append((s, t))
    return missing


def test_an_area_without_holes_is_one_piece_open_at_both_ends():
    assert [(p.s0, p.s1, p.t0, p.t1, p.open_left, p.open_right, p.on_piece) for p in area_pieces(3.0, 2.3, [])] \
        == [(0.0, 3.0, 0.0, 2.3, True, True, False)]


def test_a_door_leaves_columns_beside_it_and_a_lintel_piece_over_it():
    pieces = area_pieces(3.0, 2.3, [(0.95, 1.95, 0.0, 2.0)], gap=0.15)
    cols = [p for p in pieces if p.t0 == 0.0]
    assert [(p.s0, p.s1, p.t1, p.open_left, p.open_right) for p in cols] == [(0.0, 0.95, 2.0, True, True),
                                                                            (1.95, 3.0, 2.0, True, True)]
    lintel = [p for p in pieces if p.s0 == 0.95]
    assert len(lintel) == 1 and lintel[0].t0 == 2.0 and not lintel[0].on_piece
    # the lanes stop at the lintel piece's sides (shared with the pieces above the columns), not in the door
    assert not lintel[0].open_left and not lintel[0].open_right
    above = [p for p in pieces if p.on_piece]
    assert sorted((p.s0, p.s1) for p in above) == [(0.0, 0.95), (1.95, 3.0)]
    assert all(p.t0 == pytest.approx(2.15) for p in above)
    assert _covers(pieces, 3.0, 2.3, [(0.95, 1.95, 0.0, 2.0)], 0.15) == []


def test_a_window_column_beside_it_merges_over_its_height_and_the_sill_row_spans_the_wall():
    hole = (0.75, 2.05, 0.85, 2.05)
    pieces = area_pieces(3.0, 2.4, [hole], gap=0.15)
    sill = [p for p in pieces if p.t0 == 0.0]
    assert [(p.s0, p.s1, p.t1) for p in sill] == [(0.0, 3.0, 0.85)]
    beside = [p for p in pieces if p.t0 == pytest.approx(1.0)]
    assert sorted((p.s0, p.s1, p.t1, p.open_left, p.open_right) for p in beside) == [
        (0.0, 0.75, 2.05, True, True), (2.05, 3.0, 2.05, True, True)]
    assert _covers(pieces, 3.0, 2.4, [hole], 0.15) == []


@pytest.mark.parametrize("seed", range(40))
def test_random_holes_every_point_outside_them_is_worked_once(seed):
    rng = random.Random(seed)
    width, height = rng.uniform(1.0, 4.0), rng.uniform(1.8, 2.6)
    holes = []
    for _ in range(rng.randint(0, 2)):
        a = rng.uniform(0.0, width - 0.4)
        b = min(width, a + rng.uniform(0.3, 1.2))
        c = 0.0 if rng.random() < 0.4 else rng.uniform(0.3, 1.2)
        d = min(height, c + rng.uniform(0.5, 1.5))
        if all(b <= h[0] or a >= h[1] for h in holes):
            holes.append((a, b, c, d))
    pieces = area_pieces(width, height, holes, gap=0.0)
    assert _covers(pieces, width, height, holes, 0.0) == []
    for p in pieces:     # a side is open exactly where the area ends or a hole begins
        for side, s, open_ in (("left", p.s0, p.open_left), ("right", p.s1, p.open_right)):
            beyond = s - 0.005 if side == "left" else s + 0.005
            tm = (p.t0 + p.t1) / 2.0
            at_edge = beyond < 0 or beyond > width or any(a < beyond < b and c < tm < d for a, b, c, d in holes)
            assert open_ == at_edge, (side, p, holes)


def test_a_size_that_is_not_positive_is_refused_by_name():
    with pytest.raises(ValueError, match="positive size"):
        area_pieces(0.0, 2.0, [])


@pytest.mark.parametrize("seed", range(20))
def test_random_shared_ends_every_point_is_still_worked_once_and_a_side_is_shared_exactly_there(seed):
    rng = random.Random(100 + seed)
    width, height = rng.uniform(1.0, 3.0), rng.uniform(1.8, 2.6)
    holes = [] if rng.random() < 0.5 else [(width * 0.4, width * 0.6, 0.0, rng.uniform(1.0, 1.6))]
    ends = []
    for _ in range(2):            # a neighbour over all, part or none of each end
        c = rng.choice([0.0, rng.uniform(0.3, 1.0)])
        ends.append([] if rng.random() < 0.25 else [(c, rng.choice([height, rng.uniform(c + 0.4, height)]))])
    pieces = area_pieces(width, height, holes, 0.15, *ends)
    assert _covers(pieces, width, height, holes, 0.15) == []
    for p in pieces:
        tm = p.t0 + 1e-3          # where the piece begins (a strip thinner than a lane on top keeps its sides)
        for k, s, open_ in ((0, p.s0, p.open_left), (1, p.s1, p.open_right)):
            if (k == 0 and s == 0.0) or (k == 1 and s == width):      # the area's own end
                assert open_ == (not any(c < tm < d for c, d in ends[k])), (k, p, ends)


def test_shared_ends_of_two_touching_areas_and_what_is_not_a_neighbour():
    def area(aid, s0, s1, t0=0.1, t1=2.0, wall="wall_1", **kw):
        return dict({"id": aid, "wall": wall, "origin": [s0, 3.0, t0], "u": [1.0, 0.0, 0.0], "width": s1 - s0,
                     "height": t1 - t0}, **kw)
    a, b = area("a", 0.3, 1.3), area("b", 1.3, 2.7)
    assert shared_ends(a, [a, b], 0.02, 0.15) == ([], [(0.0, 1.9)])
    assert shared_ends(b, [a, b], 0.02, 0.15) == ([(0.0, 1.9)], [])
    assert shared_ends(a, [a, area("b", 1.3, 2.7, wall="wall_2")], 0.02, 0.15) == ([], [])    # another wall
    assert shared_ends(a, [a, area("b", 1.35, 2.7)], 0.02, 0.15) == ([], [])                  # 5 cm apart
    assert shared_ends(a, [a, area("b", 1.31, 2.7)], 0.02, 0.15) == ([], [(0.0, 1.9)])        # 1 cm: a scan's
    assert shared_ends(a, [a, area("b", 0.5, 1.0)], 0.02, 0.15) == ([], [])                   # inside it
    # over part of the end; above and below another area of the same column
    assert shared_ends(a, [a, area("b", 1.3, 2.7, t1=1.2), area("c", 1.3, 2.7, t0=1.2)], 0.02, 0.15) == \
        ([], [(0.0, 1.9)])
    assert shared_ends(a, [a, area("b", 1.3, 2.7, t1=1.2)], 0.02, 0.15) == ([], [(0.0, pytest.approx(1.1))])
    # the neighbour's window at the edge: not shared beside it
    win = area("b", 1.3, 2.7, holes=[{"s": [0.0, 0.5], "t": [0.8, 1.5]}])
    assert shared_ends(a, [a, win], 0.02, 0.15) == ([], [(0.0, pytest.approx(0.8)), (pytest.approx(1.5), 1.9)])


def test_an_end_in_an_inside_corner_is_shared_with_the_area_across_it_at_any_angle_not_at_an_outside_corner():
    import math
    # wall_1 runs +x along y = 3, the room below it (inward normal -y); wall_2 starts at its end (3, 3)
    a = _area("a", 0.3, 3.0)
    n = [0.0, -1.0, 0.0]

    def across(deg, start=(3.0, 3.0), backwards=False, **kw):
        """an area on wall_2 that leaves the corner ``deg`` degrees between the faces"""
        th = math.radians(180.0 - deg)                   # turning into the room (toward -y)
        d = [math.cos(th), -math.sin(th), 0.0]
        w = 1.5
        if backwards:                                    # its origin at the far end, u toward the corner
            return dict({"id": "b", "wall": "wall_2", "origin": [start[0] + d[0] * w, start[1] + d[1] * w, 0.1],
                         "u": [-d[0], -d[1], 0.0], "width": w, "height": 1.9}, **kw)
        return dict({"id": "b", "wall": "wall_2", "origin": [start[0], start[1], 0.1], "u": d, "width": w,
                     "height": 1.9}, **kw)
    for deg in (60.0, 90.0, 120.0, 150.0, 180.0):
        assert shared_ends(a, [a, across(deg)], 0.02, 0.15, normal=n) == ([], [(0.0, 1.9)]), deg
        assert shared_ends(a, [a, across(deg, backwards=True)], 0.02, 0.15, normal=n) == ([], [(0.0, 1.9)]), deg
    assert shared_ends(a, [a, across(120.0)], 0.02, 0.15) == ([], [])          # no normal: the same wall only
    assert shared_ends(a, [a, across(240.0)], 0.02, 0.15, normal=n) == ([], [])  # outside corner: behind the wall
    assert shared_ends(a, [a, across(120.0, start=(3.05, 3.0))], 0.02, 0.15, normal=n) == ([], [])  # 5 cm off
    assert shared_ends(a, [a, across(120.0, start=(3.01, 2.995))], 0.02, 0.15, normal=n) == ([], [(0.0, 1.9)])
    # the area across the corner on part of the height, a door at the corner's foot
    low = dict(across(90.0), height=1.0)
    assert shared_ends(a, [a, low], 0.02, 0.15, normal=n) == ([], [(0.0, pytest.approx(1.0))])
    door = across(90.0, holes=[{"s": [0.0, 0.9], "t": [0.0, 1.0]}])
    assert shared_ends(a, [a, door], 0.02, 0.15, normal=n) == ([], [(pytest.approx(1.0), 1.9)])
    # the other end of the area: wall_0 comes in at (0.3, 3.0) from the room's side
    c = {"id": "c", "wall": "wall_0", "origin": [0.3, 1.0, 0.1], "u": [0.0, 1.0, 0.0], "width": 2.0, "height": 1.9}
    assert shared_ends(a, [a, c], 0.02, 0.15, normal=n) == ([(0.0, 1.9)], [])


def _area(aid, s0, s1, t0=0.1, t1=2.0, wall="wall_1", **kw):
    return dict({"id": aid, "wall": wall, "origin": [s0, 3.0, t0], "u": [1.0, 0.0, 0.0], "width": s1 - s0,
                 "height": t1 - t0}, **kw)


def test_shared_bottom_of_stacked_areas_and_what_does_not_adjoin_it():
    """An area whose bottom another area of the wall ends right under: the stretch along the bottom it covers."""
    low, up = _area("low", 0.3, 2.7, t1=1.1), _area("up", 0.3, 2.7, t0=1.1)
    assert shared_bottom(up, [low, up], 0.02, 0.15) == [(0.0, pytest.approx(2.4))]
    assert shared_bottom(low, [low, up], 0.02, 0.15) == []              # the lower one keeps its top lane
    assert shared_bottom(up, [_area("low", 0.3, 2.7, t1=1.09), up], 0.02, 0.15) == [(0.0, pytest.approx(2.4))]
    assert shared_bottom(up, [_area("low", 0.3, 2.7, t1=1.05), up], 0.02, 0.15) == []       # 5 cm apart
    assert shared_bottom(up, [_area("low", 0.3, 2.7, t1=1.1, wall="wall_2"), up], 0.02, 0.15) == []
    # under part of it (the lower one narrower), a lower area too short to count, one beside it in line
    assert shared_bottom(up, [_area("low", 1.3, 2.0, t1=1.1), up], 0.02, 0.15) == \
        [(pytest.approx(1.0), pytest.approx(1.7))]
    assert shared_bottom(up, [_area("low", 1.3, 1.4, t1=1.1), up], 0.02, 0.15) == []
    # the lower area's window reaching its top: nothing of it meets the bottom there
    win = _area("low", 0.3, 2.7, t1=1.1, holes=[{"s": [1.0, 1.6], "t": [0.3, 1.0]}])
    assert shared_bottom(up, [win, up], 0.02, 0.15) == [(0.0, pytest.approx(1.0)), (pytest.approx(1.6), pytest.approx(2.4))]


def test_a_piece_on_a_stacked_area_begins_one_lane_spacing_above_the_common_edge():
    """Over the shared stretch the bottom row sits on the lower area (first lane one gap up); beside it, it starts
    on the edge as on an area's own bottom; the two are split where the stretch ends."""
    pieces = area_pieces(2.4, 0.9, [], 0.15, shared_bottom=[(0.0, 1.2)])
    got = sorted((p.s0, p.s1, round(p.t0, 6), p.t1, p.on_piece) for p in pieces)
    assert got == [(0.0, 1.2, 0.15, 0.9, True), (1.2, 2.4, 0.0, 0.9, False)]
    assert _covers(pieces, 2.4, 0.9, [], 0.15) == []
    whole = area_pieces(2.4, 0.9, [], 0.15, shared_bottom=[(0.0, 2.4)])
    assert [(p.s0, p.s1, round(p.t0, 6), p.t1, p.open_left, p.open_right) for p in whole] == \
        [(0.0, 2.4, 0.15, 0.9, True, True)]


@pytest.mark.parametrize("seed", range(10))
def test_random_shared_bottom_every_point_is_still_worked_once(seed):
    rng = random.Random(300 + seed)
    width, height = rng.uniform(1.0, 3.0), rng.uniform(0.6, 1.6)
    holes = [] if rng.random() < 0.5 else [(width * 0.4, width * 0.6, rng.uniform(0.0, 0.3), height * 0.8)]
    c = rng.uniform(0.0, width / 2)
    bottom = [(c, rng.uniform(c + 0.2, width))]
    pieces = area_pieces(width, height, holes, 0.15, shared_bottom=bottom)
    # within one gap of a shared bottom the lower area's top lane lays the coat (under a hole's low sill too)
    assert [(s, t) for s, t in _covers(pieces, width, height, holes, 0.15)
            if not (t < 0.15 and any(a < s < b for a, b in bottom))] == []
    for p in pieces:
        if p.t0 - (0.15 if p.on_piece else 0.0) < 1e-9:           # on the area's bottom
            sm = (p.s0 + p.s1) / 2
            assert p.on_piece == any(a < sm < b for a, b in bottom), (p, bottom)
