"""A wall area with holes (door and window openings with their frames) cut into rectangles a raster can work.

An area is the rectangle ``[0, width] x [0, height]`` (area coordinates: ``s`` along the wall, ``t`` up) minus
its holes. Raster lanes run horizontally (along ``s``), so the pieces are chosen for the two seams a raster
knows how to make evenly:

- a *side* of a piece (constant ``s``) is either an *open* edge -- the area's end or a hole's edge: the lanes run
  on past it by the edge run-in, as at an area's outer ends -- or a *shared* edge with the piece beside it: the
  lanes stop there and the neighbours overlap only by the sections' run-in, as two sections of one area do;
- a piece's *bottom* either sits on the area's bottom or a hole's top (its first lane on that edge) or on the
  piece below it (its first lane one lane spacing, ``gap``, above the lower piece's top lane: no lane twice).

A side or bottom that would be partly one and partly the other is split, so every piece has one kind of seam on
each side. An area without holes is one piece with open sides: exactly the raster used before holes existed.

An area's own end (``s = 0`` or ``s = width``) may also be *shared*: where another area of the same wall adjoins
it (``shared_left`` / ``shared_right``: the heights along that end the neighbour covers), the two areas meet
like two pieces of one area -- the lanes stop at the end, no run-in onto the neighbour, whose own lanes lay the
coat on its side. An end shared over part of its height is split at the neighbour's top and bottom like a side
beside a hole. The area's bottom may be shared too (``shared_bottom``: the stretches along it where another area
of the wall ends just below, whose top lane lies on the common edge): a piece there sits on that area as on a
piece of its own (its first lane one ``gap`` above the edge), and a bottom row shared over part of its width is
split there like a run over a hole's top.

The cut: the area is gridded at every hole edge (and every end of a shared stretch of the area's ends); each grid
row's free cells form runs (whose sides are then all open -- within a row every hole spans the row's full height --
but an area's end shared in that row); a run is split where what lies below it changes
(free, hole or the area's bottom), and a split point is a shared side; a run whose interval and side kinds
equal those of the piece right below it, and which sits on it, is merged into that piece (a full-height column
beside a window stays one piece). A strip on top of a piece less than two ``gap`` tall is merged into the piece
below it, whatever its sides (after the gap it would get no lane of its own, or two lanes closer than the
spacing: above a door's columns, beside a window's top under the tool's band), and so is a strip on top of
pieces side by side, into each of them.
"""
import math
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

from .reach import interval_minus

Hole = Tuple[float, float, float, float]        # s0, s1, t0, t1 in area coordinates
Stretch = Tuple[float, float]                   # t0, t1 along one of the area's ends

_EPS = 1e-9


@dataclass
class Piece:
    """A rectangle ``s0..s1 x t0..t1`` of an area to raster; ``open_left``/``open_right``: whether the lanes run
    on past that side (area end or hole edge) or stop at a shared edge; ``on_piece``: whether its bottom sits on
    another piece (its first lane is then one lane spacing above ``t0``, already in ``t0``)."""
    s0: float
    s1: float
    t0: float
    t1: float
    open_left: bool
    open_right: bool
    on_piece: bool = False

    @property
    def width(self) -> float:
        return self.s1 - self.s0

    @property
    def height(self) -> float:
        return self.t1 - self.t0


def _edges(lo: float, hi: float, cuts: Sequence[float]) -> List[float]:
    out = [lo, hi] + [c for c in cuts if lo + _EPS < c < hi - _EPS]
    out.sort()
    return [x for i, x in enumerate(out) if i == 0 or x - out[i - 1] > _EPS]


def area_pieces(width: float, height: float, holes: Sequence[Hole], gap: float = 0.0,
                shared_left: Sequence[Stretch] = (), shared_right: Sequence[Stretch] = (),
                shared_bottom: Sequence[Stretch] = ()) -> List[Piece]:
    """The pieces of the area ``width x height`` minus ``holes`` (see the module docstring), bottom row first
    and left to right within a row. ``gap``: lane spacing between a piece and the piece it sits on (a piece's
    ``t0`` already includes it). A piece left with no height after the gap is dropped. ``shared_left`` /
    ``shared_right``: the stretches ``(t0, t1)`` of the area's end at ``s = 0`` / ``s = width`` where another
    area adjoins it (a piece's side there is shared, not open); ``shared_bottom``: the stretches ``(s0, s1)``
    along the area's bottom where another area ends right below it (a piece there sits on it: ``on_piece``)."""
    if width <= 0 or height <= 0:
        raise ValueError("area must have a positive size, got %g x %g m" % (width, height))
    hs = [(max(0.0, a), min(width, b), max(0.0, c), min(height, d)) for a, b, c, d in holes]
    hs = [h for h in hs if h[1] - h[0] > _EPS and h[3] - h[2] > _EPS]
    ends = [[(max(0.0, c), min(height, d)) for c, d in side] for side in (shared_left, shared_right)]
    ends = [[e for e in side if e[1] - e[0] > _EPS] for side in ends]
    bottom = [(max(0.0, a), min(width, b)) for a, b in shared_bottom]
    bottom = [e for e in bottom if e[1] - e[0] > _EPS]
    S = _edges(0.0, width, [x for h in hs for x in h[:2]] + [x for e in bottom for x in e])
    T = _edges(0.0, height, [x for h in hs for x in h[2:]] + [x for side in ends for e in side for x in e])

    def free(i: int, j: int) -> bool:
        sm, tm = (S[i] + S[i + 1]) / 2.0, (T[j] + T[j + 1]) / 2.0
        return not any(a < sm < b and c < tm < d for a, b, c, d in hs)

    def shared(side: int, j: int) -> bool:
        tm = (T[j] + T[j + 1]) / 2.0
        return any(c < tm < d for c, d in ends[side])

    ncol = len(S) - 1
    done: List[Piece] = []
    below: List[Tuple[int, int, Piece]] = []      # pieces of the previous row: (first column, last column, piece)
    for j in range(len(T) - 1):
        row: List[Tuple[int, int, Piece]] = []
        i = 0
        while i < ncol:
            if not free(i, j):
                i += 1
                continue
            k = i
            while k + 1 < ncol and free(k + 1, j):
                k += 1
            # the run i..k: split where what lies below changes
            def under(c: int) -> int:
                # 0 area bottom, 1 free (or another area right below), 2 hole, 3 a bottom row on another area
                # too low for a lane of its own (a ghost: this row begins one gap above that area's edge)
                if j == 0:
                    sm = (S[c] + S[c + 1]) / 2.0
                    return 1 if any(a < sm < b for a, b in bottom) else 0
                if not free(c, j - 1):
                    return 2
                return 3 if any(c0 <= c <= c1 for c0, c1, g in below if g.t0 > g.t1) else 1

            def ghost_t0(c0: int, c1: int) -> float:
                return max(g.t0 for g0, g1, g in below if g.t0 > g.t1 and g0 <= c1 and c0 <= g1)
            a = i
            while a <= k:
                b = a
                while b + 1 <= k and under(b + 1) == under(a):
                    b += 1
                kind = under(a)
                sits = kind in (1, 3)
                t0 = ghost_t0(a, b) if kind == 3 else T[j] + (gap if sits else 0.0)
                short = T[j + 1] - T[j] < 2.0 * gap - _EPS
                piece = Piece(S[a], S[b + 1], t0, T[j + 1], open_left=(a == i and not (i == 0 and shared(0, j))),
                              open_right=(b == k and not (k == ncol - 1 and shared(1, j))), on_piece=sits)
                merged = False
                if kind == 3 and piece.height <= _EPS:
                    row.append((a, b, piece))                  # still below the first lane: a ghost again
                    merged = True
                elif kind == 1:
                    for c0, c1, p in below:
                        same = (c0, c1) == (a, b) and (p.open_left, p.open_right) == (piece.open_left, piece.open_right)
                        # a strip on top of a piece that would be left shorter than a lane spacing after the gap:
                        # that piece runs on up to its top (its lanes spread over it), not a piece with no lane of
                        # its own or two lanes closer than the spacing (a stripe of double coat)
                        thin = short and c0 <= a and b <= c1
                        if same or thin:
                            p.t1 = T[j + 1]
                            row.append((c0, c1, p) if thin and not same else (a, b, p))
                            merged = True
                            break
                    # a thin strip on top of several pieces side by side (whose sides differ where a shared end
                    # begins below it): each of them runs on up to its top
                    parts = [(c0, c1, p) for c0, c1, p in below if c0 <= b and a <= c1]
                    if (not merged and short and parts
                            and all(a <= c0 and c1 <= b for c0, c1, _p in parts)
                            and sum(c1 - c0 + 1 for c0, c1, _p in parts) == b - a + 1):
                        for c0, c1, p in parts:
                            p.t1 = T[j + 1]
                            row.append((c0, c1, p))
                        merged = True
                if not merged and piece.height > _EPS:
                    done.append(piece)
                    row.append((a, b, piece))
                elif not merged and j == 0 and sits:
                    row.append((a, b, piece))                  # a ghost (see under)
                a = b + 1
            i = k + 1
        below = row
    done.sort(key=lambda p: (p.s0, p.t0))
    return done


def shared_ends(area: Dict[str, Any], others: Sequence[Dict[str, Any]], tolerance: float,
                shortest: float = 0.0, normal: Optional[Sequence[float]] = None
                ) -> Tuple[List[Stretch], List[Stretch]]:
    """The stretches ``(t0, t1)`` (area coordinates) of ``area``'s ends at ``s = 0`` and ``s = width`` where
    another area of the same wall adjoins it: the arguments of :func:`area_pieces` ``shared_left`` and
    ``shared_right``. Areas are SCAN contract objects (``id, wall, origin, u, width, height``, optional
    ``holes``; docs/contracts.md); ``others`` may hold ``area`` itself.

    An end is shared over the heights where a neighbour's surface goes on just beyond it: the neighbour begins
    within ``tolerance`` of the end (a gap or an overlap of a scan's few millimetres) or anywhere before it (the
    two areas overlap: the overlap is worked by both, as each area is worked whole, but no lane runs on past
    the end onto the neighbour) and reaches more than ``tolerance`` past it -- minus the neighbour's holes
    there (an opening at the edge: nothing of the neighbour's lanes meets this end there, it stays open). A
    stretch no longer than ``shortest`` is left open; an end of a stretch within ``shortest`` of the area's
    bottom or top is moved there (no piece thinner than a lane spacing of its own: ``shortest`` is the lane
    spacing or ``tolerance``, the larger).

    With the wall's inward ``normal`` (the side the tools work from), an end in an inside corner is shared too:
    where an area of the wall across the corner begins within ``tolerance`` of the corner (of this end) and runs
    away from it on the room's side of this wall (corners up to 180 degrees between the faces; not an outside
    corner). A spray fan stopped at the corner lays its outer half on the wall across it, as it lays it on the
    next section of its own wall: with a run-in on both sides the strip along the corner got two coats (a
    120-degree corner: thickness CV 0.154 on the wall beside it)."""
    o, u = [float(x) for x in area["origin"]], [float(x) for x in area["u"]]
    width, height = float(area["width"]), float(area["height"])
    snap = max(shortest, tolerance)
    ends: Tuple[List[Stretch], List[Stretch]] = ([], [])
    if normal is not None:
        for side, stretches in enumerate(_corner_ends(area, others, tolerance, normal)):
            ends[side].extend(stretches)
    for b in others:
        if b.get("id") == area.get("id") or b.get("wall") != area.get("wall"):
            continue
        e = sum(float(x) * y for x, y in zip(b["u"], u))
        if abs(e) < 0.99:                              # not along this area's line: not a neighbour on its ends
            continue
        p = sum((float(x) - y) * z for x, y, z in zip(b["origin"], o, u))
        n0, n1 = sorted((p, p + e * float(b["width"])))
        c0 = float(b["origin"][2]) - o[2]
        lo, hi = max(0.0, c0), min(height, c0 + float(b["height"]))
        if hi - lo <= tolerance:
            continue
        for side, probe in ((0, -tolerance), (1, width + tolerance)):
            # the neighbour holds the point just past this end and goes on further away from the area
            if not (n0 < probe <= n1 if side == 0 else n0 <= probe < n1):
                continue
            holes = []
            for h in b.get("holes", []):
                h0, h1 = sorted((p + e * float(h["s"][0]), p + e * float(h["s"][1])))
                if h0 <= probe <= h1:
                    holes.append((c0 + float(h["t"][0]), c0 + float(h["t"][1])))
            ends[side].extend(interval_minus(lo, hi, holes))
    return _snapped(ends[0], height, snap), _snapped(ends[1], height, snap)


def _corner_ends(area: Dict[str, Any], others: Sequence[Dict[str, Any]], tolerance: float,
                 normal: Sequence[float]) -> Tuple[List[Stretch], List[Stretch]]:
    """The stretches of ``area``'s two ends an area of another wall adjoins across an inside corner (see
    :func:`shared_ends`), unsnapped."""
    o, u = [float(x) for x in area["origin"]], [float(x) for x in area["u"]]
    width, height = float(area["width"]), float(area["height"])
    nxy = math.hypot(float(normal[0]), float(normal[1]))
    ends: Tuple[List[Stretch], List[Stretch]] = ([], [])
    if nxy < 1e-9:
        return ends
    nx, ny = float(normal[0]) / nxy, float(normal[1]) / nxy
    corners = ((o[0], o[1]), (o[0] + u[0] * width, o[1] + u[1] * width))
    for b in others:
        if b.get("id") == area.get("id") or b.get("wall") == area.get("wall"):
            continue
        bo, bu, bw = [float(x) for x in b["origin"]], [float(x) for x in b["u"]], float(b["width"])
        c0 = bo[2] - o[2]
        lo, hi = max(0.0, c0), min(height, c0 + float(b["height"]))
        if hi - lo <= tolerance:
            continue
        for side, (cx, cy) in enumerate(corners):
            # this end's own direction away from the area (the line runs on that way past the end)
            ax, ay = (-u[0], -u[1]) if side == 0 else (u[0], u[1])
            for k, sign in ((0, 1.0), (1, -1.0)):
                ex, ey = bo[0] + bu[0] * bw * k, bo[1] + bu[1] * bw * k
                if math.hypot(ex - cx, ey - cy) > tolerance:
                    continue
                dx, dy = bu[0] * sign, bu[1] * sign          # b runs away from the corner this way
                # into the room (an inside corner) or straight on; not behind this wall (an outside corner)
                into = dx * nx + dy * ny
                if into < -0.02 or (into <= 0.02 and dx * ax + dy * ay < 0.0):
                    continue
                holes = [(c0 + float(h["t"][0]), c0 + float(h["t"][1])) for h in b.get("holes", [])
                         if min(float(h["s"][0]), float(h["s"][1])) <= (tolerance if k == 0 else bw - tolerance)
                         and max(float(h["s"][0]), float(h["s"][1])) >= (tolerance if k == 0 else bw - tolerance)]
                ends[side].extend(interval_minus(lo, hi, holes))
    return ends


def _snapped(stretches: Sequence[Stretch], length: float, snap: float) -> List[Stretch]:
    """``stretches`` of an edge ``length`` long merged where they touch or overlap; a stretch no longer than
    ``snap`` dropped, an end within ``snap`` of the edge's ends moved there."""
    merged: List[List[float]] = []
    for c, d in sorted(stretches):
        if merged and c <= merged[-1][1] + _EPS:
            merged[-1][1] = max(merged[-1][1], d)
        else:
            merged.append([c, d])
    return [(0.0 if c <= snap else c, length if d >= length - snap else d) for c, d in merged if d - c > snap]


def shared_bottom(area: Dict[str, Any], others: Sequence[Dict[str, Any]], tolerance: float,
                  shortest: float = 0.0) -> List[Stretch]:
    """The stretches ``(s0, s1)`` (area coordinates) of ``area``'s bottom where another area of the same wall, along
    the same line, ends right below it (its top within ``tolerance`` of this bottom): the argument of
    :func:`area_pieces` ``shared_bottom``. That area's top lane lies on the common edge, so this area's first lane
    there goes one lane spacing above it -- one coat across the edge, not two lanes on it. Minus the lower
    area's holes that reach its top (an opening there: nothing below to meet). A stretch no longer than
    ``shortest`` (or ``tolerance``) is left open; an end within that of the area's end is moved there."""
    o, u = [float(x) for x in area["origin"]], [float(x) for x in area["u"]]
    width = float(area["width"])
    snap = max(shortest, tolerance)
    found: List[Stretch] = []
    for b in others:
        if b.get("id") == area.get("id") or b.get("wall") != area.get("wall"):
            continue
        e = sum(float(x) * y for x, y in zip(b["u"], u))
        if abs(e) < 0.99:
            continue
        top = float(b["origin"][2]) + float(b["height"])
        if abs(top - o[2]) > tolerance:
            continue
        p = sum((float(x) - y) * z for x, y, z in zip(b["origin"], o, u))
        n0, n1 = sorted((p, p + e * float(b["width"])))
        lo, hi = max(0.0, n0), min(width, n1)
        if hi - lo <= tolerance:
            continue
        holes = []
        for h in b.get("holes", []):
            if float(h["t"][1]) >= float(b["height"]) - tolerance:
                holes.append(tuple(sorted((p + e * float(h["s"][0]), p + e * float(h["s"][1])))))
        found.extend(interval_minus(lo, hi, holes))
    return _snapped(found, width, snap)
