"""Seeded generator of valid, realistic plasterboard bays: site documents for the simulated worksite.

:func:`generate_bay` returns the plain dictionary a site file (``config/sites/*.yaml``) parses to, which
:func:`locem_bridge.sim.config.validate_site` accepts and :class:`locem_bridge.sim.site.Site` builds, the same
for the same seed (a private ``random.Random``, no global state). What it generates (defaults; each range is a
keyword argument of :func:`generate_bay`):

* 2-5 plasterboard walls, each 1-4 m long, as a chain (wall k ends where wall k+1 starts) turning left, so the
  room is on the same side of every wall; the corner between consecutive plasterboard walls is 60-150 degrees,
  the angle between the two faces seen from the room (as :meth:`Site.corners` reports it);
* a convex room: the chain closed by one or two concrete walls (0.5-6 m, corners at them 45-170 degrees), or,
  sometimes with 4-5 walls, by the last plasterboard wall itself; no two walls cross or touch except at a
  shared corner (a candidate that would is drawn again from a seed derived from ``seed``);
* one wall height per bay, 2.0-2.5 m, and one skirting, 0-0.1 m (none in about a third of the bays);
* 0-2 openings per plasterboard wall (fewer more often), where they fit: doors 0.8-0.9 m wide and 2.0-2.05 m
  high (only on walls at least 0.05 m higher than door and frame), windows 0.5-1.2 m wide, 0.6-1.2 m high on a
  sill at 0.8-1.0 m; frames 0.04-0.06 m; at least 0.15 m of wall between a frame and a wall end or another frame;
* a vertical joint every ``panel_width`` (0.6, 0.9 or 1.2 m, a width leaving no sliver under 0.1 m at the wall
  end preferred) from ``p0``; sometimes one horizontal joint: at 1.2 m or just under a window's frame;
* 1-3 work areas per plasterboard wall, side by side along ``s`` from the skirting to the top, each at least
  0.3 m wide: neighbours share an edge exactly or leave a 0.05-0.3 m gap; at about 70 % of the wall ends the
  ~0.3 m next to the (inside) corner is left out;
* a room the robot can work in (the rule below): the room is placed so that its point farthest from every wall
  (the centre of the largest circle inside it) lies at :data:`HOME_XY`, ``robot_start`` and ``room.inside`` are
  that point (the start facing the middle of the first plasterboard wall), and a draw whose farthest point is
  nearer than ``robot_clearance`` to a wall is drawn again; ``room.floor_size`` covers the room with 1 m to spare;
* a ``simulation`` section with the defaults of ``config/sites/default.yaml`` and ``seed`` = the bay's seed.

The rule that makes every bay workable. The robot does some of its arm motions standing still at one place of
the room: GET_TOOL drives to the tool-change location, turns there and brings the arm HOME for the operator to
mount the next tool (``trees/GET_TOOL.xml``), and the first wall task after it starts there with WALL_READY (home
to wall_ready); PlanTransit makes there the turns too large to make next to a wall (``trees/common.xml``); GO_HOME
parks there. That place is not a key of
the site file: it is ``cfg.site.locations.home`` of the HICEM parameters (``config/hicem/plasterboard.yaml``, the
transit point and ``tool_change_location``) and the base's named pose ``home`` (``launch/locem_robot.launch``), the
same (1.4, 1.4) for every site, which is :data:`HOME_XY`. Around it the robot sweeps, at any heading, the arm's
joint moves between the named poses ``home``, ``wall_ready`` and ``tool_change`` of ``robot.arm.named_poses``
with no tool or any of its tools on the flange. Measured in the simulated world (:class:`~locem_bridge.sim.world.
World`, arm URDF, chassis, pedestal and tool bodies; every heading in 5 degree steps, each joint move in 30
steps; ``test/sim/test_bays.py`` checks it again in 10 degree and 20 step samples), on the RB-KAIROS+ / UR10e of
``config/robots/rbkairos_ur10e.yaml`` nothing comes farther than :data:`STATIONARY_RADIUS` (1.04 m: the sander on
the way between ``home`` and ``wall_ready``; the arm at ``home`` alone 0.95 m, the chassis' corners 0.62 m) from the
base's centre. The default ``robot_clearance`` is that plus :data:`POSITION_MARGIN` (the GOTO position tolerance,
localisation and odometry error, the sampling of the measurement): 1.10 m. So every generated room holds a circle of
``robot_clearance`` around :data:`HOME_XY` (and its start), and a draw whose largest circle is smaller is drawn
again (from a seed derived from ``seed``, as for any draw that gives no room): the smallest rooms of the ranges are
left out, none is shrunk into a room where the robot could not change tools. Another robot needs its own
``robot_clearance`` (measured the same way).

Command line: ``python3 -m locem_bridge.sim.bays --seed N [--count K] [--out DIR]`` writes ``bay_<seed>.yaml``
for seeds N..N+K-1 and prints one line per bay (walls, openings, joints, areas, corner angles).
"""
from __future__ import annotations

import argparse
import copy
import math
import os
import random
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

import yaml

Point = Tuple[float, float]
Range = Tuple[float, float]

#: The ``simulation`` section of ``config/sites/default.yaml`` (``seed`` is replaced by the bay's seed).
SIMULATION_DEFAULTS: Dict[str, Any] = {
    "time_scale": 1.0,
    "world_rate": 50.0,
    "seed": 1,
    "gui": False,
    "perception": {"position_noise": 0.005},
    "outcome": {
        "grid": 0.02,
        "tape_lateral_tolerance": 0.015,
        "contact_tolerance": 0.01,
        "spray_rate": 0.004,
        "spray_target_thickness": 0.001,
    },
}

PLASTERBOARD_THICKNESS = 0.0125     # m
CONCRETE_THICKNESS = 0.2            # m
LINTEL = 0.05                       # m of wall kept above an opening's frame
#: (x, y) in map of the base's home: the tool-change location and transit point of the HICEM parameters
#: (``cfg.site.locations.home`` of config/hicem/plasterboard.yaml) and the named base pose ``home`` of
#: launch/locem_robot.launch; every generated room has its point farthest from the walls (and the start) here
HOME_XY: Point = (1.4, 1.4)
#: m, farthest any part of the robot (chassis, pedestal, arm, the mounted tool) comes from the base's centre while
#: the arm moves between its named poses home, wall_ready and tool_change, at any heading (module docstring)
STATIONARY_RADIUS = 1.04
#: m added to STATIONARY_RADIUS for the default robot_clearance: GOTO's position tolerance (0.01 m), localisation and
#: odometry error and the measurement's sampling, with room to spare
POSITION_MARGIN = 0.06
#: m, the default robot_clearance of generate_bay: every wall at least this far from HOME_XY
ROBOT_CLEARANCE = round(STATIONARY_RADIUS + POSITION_MARGIN, 3)
MAX_ATTEMPTS = 500                  # candidates (derived seeds) before giving up on a parameter set


# -- plane geometry -------------------------------------------------------------------------------------------
def _direction(heading_deg: float) -> Point:
    h = math.radians(heading_deg)
    return math.cos(h), math.sin(h)


def _sub(a: Point, b: Point) -> Point:
    return a[0] - b[0], a[1] - b[1]


def _cross(a: Point, b: Point) -> float:
    return a[0] * b[1] - a[1] * b[0]


def _turn(a: Point, b: Point) -> float:
    """Signed angle in degrees from direction ``a`` to direction ``b`` (positive: a left turn)."""
    return math.degrees(math.atan2(_cross(a, b), a[0] * b[0] + a[1] * b[1]))


def _segments_touch(p: Point, q: Point, r: Point, s: Point) -> bool:
    """Whether the closed segments ``p-q`` and ``r-s`` have a point in common."""
    def orient(a: Point, b: Point, c: Point) -> float:
        v = _cross(_sub(b, a), _sub(c, a))
        return 0.0 if abs(v) < 1e-12 else v

    def on(a: Point, b: Point, c: Point) -> bool:     # c on segment a-b, given the three are collinear
        return min(a[0], b[0]) - 1e-12 <= c[0] <= max(a[0], b[0]) + 1e-12 and \
            min(a[1], b[1]) - 1e-12 <= c[1] <= max(a[1], b[1]) + 1e-12

    d1, d2, d3, d4 = orient(r, s, p), orient(r, s, q), orient(p, q, r), orient(p, q, s)
    if d1 * d2 < 0 and d3 * d4 < 0:
        return True
    return ((d1 == 0 and on(r, s, p)) or (d2 == 0 and on(r, s, q)) or (d3 == 0 and on(p, q, r))
            or (d4 == 0 and on(p, q, s)))


def walls_cross(segments: Sequence[Tuple[Point, Point]]) -> bool:
    """Whether two of the floor segments meet anywhere but at a corner they share (segments that share an end
    may not overlap; segments that do not may not touch at all)."""
    for i in range(len(segments)):
        for j in range(i + 1, len(segments)):
            (p, q), (r, s) = segments[i], segments[j]
            shared = [(a, b) for a in (p, q) for b in (r, s) if a == b]
            if not shared:
                if _segments_touch(p, q, r, s):
                    return True
                continue
            if len(shared) > 1:
                return True                             # the same segment twice
            corner = shared[0][0]
            far_i = q if p == corner else p
            far_j = s if r == corner else r
            u, v = _sub(far_i, corner), _sub(far_j, corner)
            if abs(_cross(u, v)) < 1e-12 and u[0] * v[0] + u[1] * v[1] > 0:
                return True                             # folded back onto each other
    return False


def _det3(m: Sequence[Sequence[float]]) -> float:
    return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))


def _inward_normals(poly: Sequence[Point]) -> List[Tuple[Point, Point]]:
    """``(point on edge, unit normal to the left)`` of each edge of the counter-clockwise polygon ``poly``."""
    out = []
    for i, a in enumerate(poly):
        b = poly[(i + 1) % len(poly)]
        d = _sub(b, a)
        n = math.hypot(*d)
        out.append((a, (-d[1] / n, d[0] / n)))
    return out


def _clearance(p: Point, edges: Sequence[Tuple[Point, Point]]) -> float:
    """Distance from ``p`` to the boundary of the convex polygon of ``edges`` (negative outside)."""
    return min(n[0] * (p[0] - a[0]) + n[1] * (p[1] - a[1]) for a, n in edges)


def _largest_circle(poly: Sequence[Point]) -> Tuple[Point, float]:
    """Centre and radius of the largest circle inside the convex polygon ``poly`` (counter-clockwise): the linear
    program max r s.t. every edge is at least r away, solved at the vertices its constraints meet in."""
    edges = _inward_normals(poly)
    best: Tuple[Point, float] = ((sum(p[0] for p in poly) / len(poly), sum(p[1] for p in poly) / len(poly)), -1.0)
    rows = [([n[0], n[1], -1.0], n[0] * a[0] + n[1] * a[1]) for a, n in edges]   # n.p - r = n.a at equality
    for i in range(len(rows)):
        for j in range(i + 1, len(rows)):
            for k in range(j + 1, len(rows)):
                mat = [rows[i][0], rows[j][0], rows[k][0]]
                rhs = [rows[i][1], rows[j][1], rows[k][1]]
                det = _det3(mat)
                if abs(det) < 1e-12:
                    continue
                # Cramer's rule: column c replaced by the right-hand side
                x, y, r = (_det3([[rhs[row] if col == c else mat[row][col] for col in range(3)] for row in range(3)])
                           / det for c in range(3))
                if r > best[1] and _clearance((x, y), edges) >= r - 1e-9:
                    best = ((x, y), r)
    return best


# -- the room -------------------------------------------------------------------------------------------------
class _Params:
    """The keyword arguments of :func:`generate_bay`, checked."""

    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)
        for name in ("walls", "wall_length", "corner_angle", "wall_height", "skirting", "openings_per_wall",
                     "door_width", "door_height", "window_width", "window_height", "window_sill", "frame",
                     "areas_per_wall", "concrete_length", "concrete_corner_angle"):
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise ValueError("%s: (%r, %r) is not a range (first <= second)" % (name, lo, hi))
        if self.walls[0] < 1 or self.areas_per_wall[0] < 1 or self.openings_per_wall[0] < 0:
            raise ValueError("walls and areas_per_wall start at 1 or more, openings_per_wall at 0 or more")
        if not (0.0 < self.corner_angle[0] and self.corner_angle[1] < 180.0):
            raise ValueError("corner_angle must lie in (0, 180) degrees: the room is convex")
        if not (0.0 < self.concrete_corner_angle[0] and self.concrete_corner_angle[1] < 180.0):
            raise ValueError("concrete_corner_angle must lie in (0, 180) degrees: the room is convex")
        if self.wall_length[0] < 0.1 or self.concrete_length[0] < 0.1:
            raise ValueError("walls are at least 0.1 m long")
        if not self.panel_widths or min(self.panel_widths) <= 0.0:
            raise ValueError("panel_widths: at least one width, all positive")

    def turn_range(self, plasterboard_corner: bool) -> Range:
        """Left turn (degrees) between two walls at a corner of the given kind, from its angle range."""
        lo, hi = self.corner_angle if plasterboard_corner else self.concrete_corner_angle
        return 180.0 - hi, 180.0 - lo


def _uniform(rng: random.Random, rng_range: Range, inset: float = 0.0) -> float:
    lo, hi = rng_range
    if hi - lo > 2.0 * inset:
        lo, hi = lo + inset, hi - inset
    return rng.uniform(lo, hi)


def _chain(rng: random.Random, prm: _Params, n: int, heading: float, turn_budget: float) -> List[Point]:
    """Vertices of a chain of ``n`` plasterboard walls from the origin turning left, lengths rounded to cm,
    corners inside the plasterboard range (an angle's ends kept 0.2 degree off for rounding), the sum of the
    turns at most ``turn_budget``; an empty list when no draw kept to the budget."""
    lo, hi = prm.turn_range(True)
    for _ in range(100):
        turns = [_uniform(rng, (lo, hi), 0.2) for _ in range(n - 1)]
        if sum(turns) <= turn_budget:
            break
    else:
        return []
    pts = [(0.0, 0.0)]
    h = heading
    for k in range(n):
        length = round(_uniform(rng, prm.wall_length, 0.01), 2)
        d = _direction(h)
        pts.append((pts[-1][0] + length * d[0], pts[-1][1] + length * d[1]))
        if k < n - 1:
            h += turns[k]
    return pts


def _settle(poly: Sequence[Point], plaster_edges: int, closed: bool, prm: _Params) -> Optional[List[Point]]:
    """The polygon moved so the centre of its largest inside circle lies at :data:`HOME_XY`, vertices rounded to mm,
    if it is a room: every corner a left turn within its range (plasterboard-plasterboard corners:
    ``corner_angle``, any other: ``concrete_corner_angle``), wall lengths within their ranges, turning once around,
    no walls crossing, and every wall at least ``robot_clearance`` from :data:`HOME_XY` (the robot's start and
    home); else ``None``. Edges ``0 .. plaster_edges-1`` are plasterboard (all when ``closed``)."""
    if not _is_room(poly, plaster_edges, closed, prm):
        return None                                     # checked before the move: the circle needs a convex room
    (cx, cy), _ = _largest_circle(poly)
    dx, dy = HOME_XY[0] - cx, HOME_XY[1] - cy
    pts = [(round(p[0] + dx, 3) + 0.0, round(p[1] + dy, 3) + 0.0) for p in poly]
    if not _is_room(pts, plaster_edges, closed, prm):  # again after rounding to mm
        return None
    if _clearance(HOME_XY, _inward_normals(pts)) < prm.robot_clearance:
        return None
    return pts


def _is_room(pts: Sequence[Point], plaster_edges: int, closed: bool, prm: _Params) -> bool:
    """The corner, length, turn and crossing conditions of :func:`_settle` on ``pts`` as they are."""
    m = len(pts)
    plaster = [i < plaster_edges for i in range(m)]
    total = 0.0
    for i in range(m):
        a, b = pts[i], pts[(i + 1) % m]
        length = math.hypot(*_sub(b, a))
        lo, hi = prm.wall_length if plaster[i] else prm.concrete_length
        if not lo <= length <= hi:
            return False
        prev = _sub(a, pts[i - 1])
        turn = _turn(prev, _sub(b, a))
        corner_plaster = plaster[i] and plaster[i - 1] and (i > 0 or closed)
        lo, hi = prm.turn_range(corner_plaster)
        if not lo <= turn <= hi:
            return False
        total += turn
    return abs(total - 360.0) <= 1e-6 and not walls_cross([(pts[i], pts[(i + 1) % m]) for i in range(m)])


def _room(rng: random.Random, prm: _Params, n: int, closed: bool) -> Optional[Tuple[List[Point], int]]:
    """A convex room ``(vertices counter-clockwise, number of plasterboard walls)`` with ``n`` plasterboard walls:
    walls ``i -> i+1``, the first ``n`` plasterboard, the rest concrete (none if ``closed`` and this draw can
    close the room with plasterboard alone); ``None`` if this draw gives no room."""
    heading = float(rng.choice((0, 90, 180, 270))) if rng.random() < 0.5 else rng.uniform(0.0, 360.0)
    if closed:
        # all plasterboard: the last wall runs from the end of the others back to the start
        for _ in range(60):
            pts = _chain(rng, prm, n - 1, heading, 360.0)
            if pts:
                room = _settle(pts, n, True, prm)
                if room is not None:
                    return room, n
    lo_c = prm.turn_range(False)[0]
    pts = _chain(rng, prm, n, heading, 360.0 - 2.0 * lo_c)
    if not pts:
        return None
    start, end = pts[0], pts[-1]
    candidates: List[List[Point]] = []
    if rng.random() < 0.3:
        candidates.append(pts)                                  # one concrete wall from the end to the start
    parallel = [_sub(_add(end, start), pts[1]),                 # opposite wall 1, as long
                _sub(_add(start, end), pts[-2])]                # opposite the last wall, as long
    rng.shuffle(parallel)
    candidates += [pts + [q] for q in parallel]
    last = _sub(end, pts[-2])
    h_last = math.degrees(math.atan2(last[1], last[0]))
    for _ in range(80):                                         # two concrete walls through a corner q
        d = _direction(h_last + _uniform(rng, prm.turn_range(False), 0.2))
        length = _uniform(rng, prm.concrete_length, 0.01)
        candidates.append(pts + [(end[0] + length * d[0], end[1] + length * d[1])])
    for poly in candidates:
        room = _settle(poly, n, False, prm)
        if room is not None:
            return room, n
    return None


def _add(a: Point, b: Point) -> Point:
    return a[0] + b[0], a[1] + b[1]


# -- the walls' features --------------------------------------------------------------------------------------
def _panel_width(rng: random.Random, prm: _Params, length: float) -> float:
    """A panel width from ``panel_widths``, preferring one that leaves no sliver (< 0.1 m) at the wall's end."""
    widths = list(prm.panel_widths)
    rng.shuffle(widths)
    for w in widths:
        rest = length - math.floor(length / w + 1e-9) * w
        if rest < 1e-6 or rest >= 0.1:
            return float(w)
    return float(widths[0])


def _openings(rng: random.Random, prm: _Params, wid: str, length: float, height: float) -> List[Dict[str, Any]]:
    """Doors and windows for one wall, each with its frame, ``opening_margin`` of wall between frames and ends."""
    weights = [0.5 ** k for k in range(prm.openings_per_wall[0], prm.openings_per_wall[1] + 1)]
    count = rng.choices(range(prm.openings_per_wall[0], prm.openings_per_wall[1] + 1), weights)[0]
    made: List[Dict[str, Any]] = []
    for _ in range(count):
        frame = round(_uniform(rng, prm.frame), 3)
        door_height = round(_uniform(rng, prm.door_height), 3)
        if door_height + frame + LINTEL <= height and rng.random() < 0.4:
            made.append({"kind": "door", "w": round(_uniform(rng, prm.door_width), 2), "t": [0.0, door_height],
                         "frame": frame})
            continue
        sill = round(_uniform(rng, prm.window_sill), 2)
        top = min(round(sill + _uniform(rng, prm.window_height), 2), round(height - frame - LINTEL, 3))
        if sill <= frame or top - sill < prm.window_height[0] - 1e-9:
            continue                                            # no window fits under this wall's top
        made.append({"kind": "window", "w": round(_uniform(rng, prm.window_width), 2), "t": [sill, top],
                     "frame": frame})
    gap = prm.opening_margin
    while made and sum(o["w"] + 2.0 * o["frame"] for o in made) + gap * (len(made) + 1) > length - 0.002:
        made.pop()                                              # the last drawn does not fit: leave it out
    if not made:
        return []
    slack = length - 0.002 - sum(o["w"] + 2.0 * o["frame"] for o in made) - gap * (len(made) + 1)
    cuts = sorted(rng.uniform(0.0, slack) for _ in range(len(made)))
    shares = [math.floor((b - a) * 1000.0) / 1000.0 for a, b in zip([0.0] + cuts, cuts)]
    out = []
    s = 0.001
    counts = {"door": 0, "window": 0}
    for op, share in zip(made, shares):
        s0 = round(s + gap + share + op["frame"], 3)
        s1 = round(s0 + op["w"], 3)
        counts[op["kind"]] += 1
        out.append({"id": "%s_%s_%d" % (wid, op["kind"], counts[op["kind"]]), "kind": op["kind"],
                    "s": [s0, s1], "t": list(op["t"]), "frame": op["frame"]})
        s = s1 + op["frame"]
    return out


def _horizontal_joints(rng: random.Random, prm: _Params, openings: List[Dict[str, Any]], skirting: float,
                       height: float) -> List[float]:
    """None, one at ``horizontal_joint`` height, or one just under a window's frame."""
    windows = [o for o in openings if o["kind"] == "window"]
    r = rng.random()
    if windows and r < 0.2:
        w = rng.choice(windows)
        h = round(w["t"][0] - w["frame"] - 0.01, 3)
    elif r < 0.45:
        h = float(prm.horizontal_joint)
    else:
        return []
    return [h] if skirting < h < height else []


def _areas(rng: random.Random, prm: _Params, wid: str, length: float, skirting: float,
           height: float) -> List[Dict[str, Any]]:
    """1-3 areas side by side along the wall, from the skirting to the top (see the module docstring)."""
    least = prm.min_area_width
    lo_margin = round(_uniform(rng, (prm.corner_margin - 0.05, prm.corner_margin + 0.05)), 2) \
        if rng.random() < prm.corner_margin_probability else 0.0
    hi_margin = round(_uniform(rng, (prm.corner_margin - 0.05, prm.corner_margin + 0.05)), 2) \
        if rng.random() < prm.corner_margin_probability else 0.0
    if length - lo_margin - hi_margin < least:
        lo_margin = hi_margin = 0.0
    a, b = lo_margin, length - hi_margin
    count = rng.randint(*prm.areas_per_wall)
    gaps = [0.0 if rng.random() < 0.5 else round(rng.uniform(0.05, 0.3), 2) for _ in range(count - 1)]
    while count > 1 and count * least + sum(gaps) > b - a - 0.01:
        count -= 1
        gaps.pop()
    free = b - a - count * least - sum(gaps)
    cuts = sorted(rng.uniform(0.0, free) for _ in range(count - 1))
    extra = [y - x for x, y in zip([0.0] + cuts, cuts + [free])]
    out = []
    s = a
    for k in range(count):
        s0 = round(s, 3) + 0.0
        if k < count - 1:
            s1 = round(min(b, s0 + least + extra[k]), 3)
        else:                                               # to the margin, or to the very end of the wall
            s1 = round(b, 3) if hi_margin else b
        out.append({"id": "%s_area_%d" % (wid, k + 1), "s": [s0, s1], "t": [skirting, height]})
        s = s1 + (gaps[k] if k < count - 1 else 0.0)
    return out


def _attempt(rng: random.Random, prm: _Params, seed: int, n: int, closed: bool) -> Optional[Dict[str, Any]]:
    found = _room(rng, prm, n, closed)
    if found is None:
        return None
    pts, n_plaster = found
    m = len(pts)
    height = round(_uniform(rng, prm.wall_height), 2)
    skirting = 0.0 if rng.random() < 1.0 / 3.0 else round(_uniform(rng, prm.skirting), 2)
    walls = []
    for i in range(m):
        p0, p1 = pts[i], pts[(i + 1) % m]
        wid = "wall_%d" % (i + 1)
        wall: Dict[str, Any] = {"id": wid, "material": "plasterboard" if i < n_plaster else "concrete",
                                "p0": [p0[0], p0[1]], "p1": [p1[0], p1[1]], "height": height}
        if i >= n_plaster:
            wall["thickness"] = CONCRETE_THICKNESS
            walls.append(wall)
            continue
        length = math.hypot(*_sub(p1, p0))
        openings = _openings(rng, prm, wid, length, height)
        wall.update({"thickness": PLASTERBOARD_THICKNESS, "panel_width": _panel_width(rng, prm, length),
                     "joint_width": float(prm.joint_width), "skirting": skirting,
                     "horizontal_joints": _horizontal_joints(rng, prm, openings, skirting, height),
                     "areas": _areas(rng, prm, wid, length, skirting, height)})
        if openings:
            wall["openings"] = openings
        walls.append(wall)
    # the start is the room's point farthest from its walls, where _settle put it: the home of the robot
    x, y = HOME_XY
    first_mid = ((pts[0][0] + pts[1][0]) / 2.0, (pts[0][1] + pts[1][1]) / 2.0)
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    yaw = math.atan2(first_mid[1] - y, first_mid[0] - x)
    # the floor is centred on the mean of the wall midpoints (locem_bridge.sim.world)
    mids = [((pts[i][0] + pts[(i + 1) % m][0]) / 2.0, (pts[i][1] + pts[(i + 1) % m][1]) / 2.0) for i in range(m)]
    cx, cy = sum(p[0] for p in mids) / m, sum(p[1] for p in mids) / m
    floor = [max(8.0, math.ceil((2.0 * max(abs(v - c) for v in vs) + 2.0) * 2.0) / 2.0)
             for vs, c in ((xs, cx), (ys, cy))]
    simulation = copy.deepcopy(SIMULATION_DEFAULTS)
    simulation["seed"] = int(seed)
    return {
        "site": {
            "name": "bay_%d" % seed,
            "room": {"inside": [round(x, 3), round(y, 3)], "floor_size": floor},
            "walls": walls,
            "robot_start": [round(x, 3), round(y, 3), round(yaw, 4)],
        },
        "simulation": simulation,
    }


def generate_bay(seed: int, *, walls: Tuple[int, int] = (2, 5), wall_length: Range = (1.0, 4.0),
                 corner_angle: Range = (60.0, 150.0), wall_height: Range = (2.0, 2.5), skirting: Range = (0.0, 0.1),
                 openings_per_wall: Tuple[int, int] = (0, 2), door_width: Range = (0.8, 0.9),
                 door_height: Range = (2.0, 2.05), window_width: Range = (0.5, 1.2),
                 window_height: Range = (0.6, 1.2), window_sill: Range = (0.8, 1.0), frame: Range = (0.04, 0.06),
                 opening_margin: float = 0.15, panel_widths: Sequence[float] = (0.6, 0.9, 1.2),
                 joint_width: float = 0.05, horizontal_joint: float = 1.2, areas_per_wall: Tuple[int, int] = (1, 3),
                 min_area_width: float = 0.3, corner_margin: float = 0.3, corner_margin_probability: float = 0.7,
                 robot_clearance: float = ROBOT_CLEARANCE, closed_probability: float = 0.2,
                 concrete_length: Range = (0.5, 6.0),
                 concrete_corner_angle: Range = (45.0, 170.0)) -> Dict[str, Any]:
    """A site document (the dictionary a site YAML file parses to) of a random plasterboard bay, the same for the
    same ``seed`` and arguments; :func:`~locem_bridge.sim.config.validate_site` accepts it.

    Ranges are ``(low, high)``, lengths in m, angles in degrees (see the module docstring for how each is used):
    ``walls`` plasterboard walls, their lengths ``wall_length``, the angle between consecutive ones seen from
    the room ``corner_angle``; one ``wall_height`` and ``skirting`` per bay; ``openings_per_wall`` doors
    (``door_width`` x ``door_height``) and windows (``window_width`` x ``window_height`` on a ``window_sill``)
    with a ``frame``, ``opening_margin`` of wall around their frames; vertical joints every one of
    ``panel_widths`` (``joint_width`` wide), sometimes a horizontal joint at ``horizontal_joint`` or under a
    window; ``areas_per_wall`` areas at least ``min_area_width`` wide, leaving ~``corner_margin`` at a corner
    with probability ``corner_margin_probability``; the room's farthest point from its walls (moved to
    :data:`HOME_XY`, the robot's start and home) ``robot_clearance`` from every wall (the module docstring: the
    default is what the RB-KAIROS+ / UR10e needs for its arm motions there); with
    probability ``closed_probability`` (4 or more walls) the plasterboard walls alone close the room, else
    concrete walls ``concrete_length`` long at ``concrete_corner_angle`` corners do. A draw that gives no valid
    room (walls crossing, corners or lengths out of range after rounding, too small for the robot's home) is
    replaced by a draw from a seed derived from ``seed``; ``ValueError`` if none of ``MAX_ATTEMPTS`` is one.
    """
    prm = _Params(walls=walls, wall_length=wall_length, corner_angle=corner_angle, wall_height=wall_height,
                  skirting=skirting, openings_per_wall=openings_per_wall, door_width=door_width,
                  door_height=door_height, window_width=window_width, window_height=window_height,
                  window_sill=window_sill, frame=frame, opening_margin=opening_margin, panel_widths=panel_widths,
                  joint_width=joint_width, horizontal_joint=horizontal_joint, areas_per_wall=areas_per_wall,
                  min_area_width=min_area_width, corner_margin=corner_margin,
                  corner_margin_probability=corner_margin_probability, robot_clearance=robot_clearance,
                  closed_probability=closed_probability, concrete_length=concrete_length,
                  concrete_corner_angle=concrete_corner_angle)
    # the wall count and whether to close the room with plasterboard are drawn once, so that redrawing a bay
    # that gave no room keeps their distributions
    once = random.Random("bay %d walls" % seed)
    n = once.randint(*prm.walls)
    closed = n >= 4 and once.random() < prm.closed_probability
    for attempt in range(MAX_ATTEMPTS):
        rng = random.Random(seed if attempt == 0 else "bay %d attempt %d" % (seed, attempt))
        doc = _attempt(rng, prm, seed, n, closed)
        if doc is not None:
            return doc
    raise ValueError("no valid bay for seed %d with these ranges in %d attempts" % (seed, MAX_ATTEMPTS))


def generate_bays(first_seed: int, count: int, **ranges: Any) -> List[Dict[str, Any]]:
    """:func:`generate_bay` for the seeds ``first_seed .. first_seed + count - 1`` (``ranges``: its keywords)."""
    return [generate_bay(seed, **ranges) for seed in range(first_seed, first_seed + count)]


# -- command line ---------------------------------------------------------------------------------------------
def summary(doc: Dict[str, Any]) -> str:
    """One line on a bay: walls, openings, joints, areas and the corners between consecutive plasterboard walls."""
    from .config import validate_site
    from .site import Site

    site = Site(validate_site(copy.deepcopy(doc)))
    work = site.work_walls
    openings = [o for w in site.walls for o in w.openings]
    joints = site.joints
    angles = []
    for wall in work:
        for end, other, angle in site.corners(wall.id):
            if end == 1 and other.material == "plasterboard":
                angles.append("%.0f" % angle)
    return ("%s: %d walls (%d plasterboard: %s m, %d concrete), height %.2f m, %d openings (%d doors, %d windows), "
            "%d joints (%d vertical, %d horizontal), %d areas, corners %s deg"
            % (site.name, len(site.walls), len(work), "/".join("%.2f" % w.length for w in work),
               len(site.walls) - len(work), work[0].height, len(openings),
               sum(o.kind == "door" for o in openings), sum(o.kind == "window" for o in openings), len(joints),
               sum(j.kind == "vertical" for j in joints), sum(j.kind == "horizontal" for j in joints),
               len(site.areas), "/".join(angles) or "-"))


def write_bay(doc: Dict[str, Any], folder: str) -> str:
    """Write ``doc`` to ``folder/bay_<seed>.yaml`` with a header saying how it was made; returns the path."""
    seed = doc["simulation"]["seed"]
    path = os.path.join(folder, "bay_%d.yaml" % seed)
    header = ("# Generated bay (not edited by hand): python3 -m locem_bridge.sim.bays --seed %d\n"
              "# = locem_bridge.sim.bays.generate_bay(%d) with the default ranges; the same seed gives the same "
              "file.\n" % (seed, seed))
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(header)
        yaml.safe_dump(doc, fh, default_flow_style=None, sort_keys=False, width=120)
    return path


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m locem_bridge.sim.bays", description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, required=True, help="seed of the first bay")
    ap.add_argument("--count", type=int, default=1, help="number of bays, seeds N..N+K-1 (default: %(default)s)")
    ap.add_argument("--out", default=".", help="folder for the bay_<seed>.yaml files (default: %(default)s)")
    args = ap.parse_args(argv)
    if args.count < 1:
        ap.error("--count must be 1 or more")
    os.makedirs(args.out, exist_ok=True)
    for doc in generate_bays(args.seed, args.count):
        path = write_bay(doc, args.out)
        print("%s  (%s)" % (summary(doc), path))
    return 0


if __name__ == "__main__":
    sys.exit(main())
