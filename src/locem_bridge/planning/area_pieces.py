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

The cut: the area is gridded at every hole edge; each grid row's free cells form runs (whose sides are then all
open: within a row every hole spans the row's full height); a run is split where what lies below it changes
(free, hole or the area's bottom), and a split point is a shared side; a run whose interval and side kinds
equal those of the piece right below it, and which sits on it, is merged into that piece (a full-height column
beside a window stays one piece). A strip on top of a piece no taller than ``gap`` is merged into the piece
below it, whatever its sides (it would get no lane of its own: above a door's columns, under the ceiling).
"""
from dataclasses import dataclass
from typing import List, Sequence, Tuple

Hole = Tuple[float, float, float, float]        # s0, s1, t0, t1 in area coordinates

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


def area_pieces(width: float, height: float, holes: Sequence[Hole], gap: float = 0.0) -> List[Piece]:
    """The pieces of the area ``width x height`` minus ``holes`` (see the module docstring), bottom row first
    and left to right within a row. ``gap``: lane spacing between a piece and the piece it sits on (a piece's
    ``t0`` already includes it). A piece left with no height after the gap is dropped."""
    if width <= 0 or height <= 0:
        raise ValueError("area must have a positive size, got %g x %g m" % (width, height))
    hs = [(max(0.0, a), min(width, b), max(0.0, c), min(height, d)) for a, b, c, d in holes]
    hs = [h for h in hs if h[1] - h[0] > _EPS and h[3] - h[2] > _EPS]
    S = _edges(0.0, width, [x for h in hs for x in h[:2]])
    T = _edges(0.0, height, [x for h in hs for x in h[2:]])

    def free(i: int, j: int) -> bool:
        sm, tm = (S[i] + S[i + 1]) / 2.0, (T[j] + T[j + 1]) / 2.0
        return not any(a < sm < b and c < tm < d for a, b, c, d in hs)

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
                return 0 if j == 0 else (1 if free(c, j - 1) else 2)   # 0 area bottom, 1 free, 2 hole
            a = i
            while a <= k:
                b = a
                while b + 1 <= k and under(b + 1) == under(a):
                    b += 1
                sits = under(a) == 1
                t0 = T[j] + (gap if sits else 0.0)
                piece = Piece(S[a], S[b + 1], t0, T[j + 1], open_left=(a == i), open_right=(b == k), on_piece=sits)
                merged = False
                if sits:
                    for c0, c1, p in below:
                        same = (c0, c1) == (a, b) and (p.open_left, p.open_right) == (piece.open_left, piece.open_right)
                        # a strip no taller than the gap on top of a piece: that piece runs on up to its top (one
                        # more lane there, not a piece with no lane of its own)
                        thin = T[j + 1] - T[j] <= gap + _EPS and c0 <= a and b <= c1
                        if same or thin:
                            p.t1 = T[j + 1]
                            row.append((c0, c1, p) if thin and not same else (a, b, p))
                            merged = True
                            break
                if not merged and piece.height > _EPS:
                    done.append(piece)
                    row.append((a, b, piece))
                a = b + 1
            i = k + 1
        below = row
    done.sort(key=lambda p: (p.s0, p.t0))
    return done
