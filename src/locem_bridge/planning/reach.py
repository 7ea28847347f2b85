"""Plan before touching: which parts of a wall's joints and areas the robot can work, and from where.

Everything here is decided from the scan (walls with their corners and openings, joints, areas: the SCAN shape
of ``docs/contracts.md``) and the robot's geometry (:class:`RobotEnvelope`, from the robot file and its derived
facts), before the base drives and before the tool goes near the wall. The robot never finds a wall by a
protective stop: what it cannot work without touching something else is reported as manual work with its extent.

The model, in one wall's frame (``s`` along the wall from ``p0``, ``t`` up, ``d`` out of the face into the room):

- **Obstacles** are 2D segments on the floor plan: every other wall of the scan, the scan's ``obstacles`` (walls
  that are no work surface, e.g. concrete: :meth:`Wall2D.from_obstacle`), and at each end of the wall where
  another wall meets it at an inside corner (``corners[].angle`` below pi) the neighbour's face, a ray from the
  corner at that angle (a concrete wall the scan does not report still has a face the robot must not touch).
- **The tool** working at ``s`` (and up to ``run_on`` either side of it: a raster lane runs on past its
  section's end) stands perpendicular to the wall: its working end (the pad or roller on the wall,
  the nozzle ``tool_standoff`` off it) with its radius (a sander's pad, the tool body), its body up to the flange,
  and the wrist behind the flange (``wrist_length``, ``arm_radius``). Each keeps ``clearance`` from every
  obstacle. Every tool stays in the height band the arm reaches (``z_range``); under a ceiling (a wall's
  ``ceiling`` in the scan: the room's ceiling height) the working end keeps its radius plus the clearance below
  it. A wall without one stands free (a mock-up wall): its top edge is worked like its ends.
- **The base** stands ``base_standoff`` off the wall facing it (as every wall tree drives it); its chassis
  rectangle keeps ``clearance`` from every obstacle, and so does the arm's shoulder. From a base centre at
  ``s_b`` the tool reaches ``s_b +- reach`` along the wall (the robot's lateral reach less the room a raster lane
  needs past its section's end).

A point of the wall can be worked when the tool fits there and some base position within reach of it is free.
Both are sampled along the wall every :data:`STEP` (vectorised: microseconds per sample), so a wall plans in
milliseconds; the result is a set of intervals along the wall and a height band per work.
"""
import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

STEP = 0.02                       # m, sampling step along the wall
SHORTEST_PIECE = 0.10            # m, no piece of joint the robot tapes is shorter (nor split shorter for a base)
SHORT_REASON = "shorter than the %.2f m the robot tapes as one piece" % SHORTEST_PIECE
OUTLINE_STEP = 0.10               # m, spacing of the sample points on the chassis outline
Interval = Tuple[float, float]


@dataclass
class ToolEnvelope:
    """One wall work's tool and base numbers (m). ``tip_radius``: radius of the working end at the wall (a pad;
    the body radius for a roller or a nozzle); ``tip_distance``: the working end's distance from the face (0 for
    contact tools, the nozzle standoff for a spray gun); ``length``: flange to working end."""
    work: str
    tip_radius: float
    tip_distance: float
    body_radius: float
    length: float
    base_standoff: float
    reach: float
    z_range: Interval
    contact: bool
    run_on: float = 0.0        # m the tool travels past the worked part along the wall (a raster lane's run-in and
                               # run-up past its section's end)

    @classmethod
    def from_facts(cls, work: str, facts: Mapping[str, Any], reach: float, run_on: float) -> "ToolEnvelope":
        """From one work's robot facts (``robot.work.<work>``: tool_standoff, tool_length, tip_radius,
        body_radius, base_standoff, z_range)."""
        return cls(work=work, tip_radius=float(facts["tip_radius"]), tip_distance=float(facts["tool_standoff"]),
                   body_radius=float(facts["body_radius"]), length=float(facts["tool_length"]),
                   base_standoff=float(facts["base_standoff"]), reach=reach,
                   z_range=(float(facts["z_range"][0]), float(facts["z_range"][1])),
                   contact=float(facts["tool_standoff"]) == 0.0, run_on=run_on)


@dataclass
class RobotEnvelope:
    """The robot's outline for planning: chassis ``base_length`` x ``base_width`` centred on the base frame,
    the arm's shoulder ``shoulder_x`` ahead of it, and one :class:`ToolEnvelope` per wall work. Behind the
    flange the arm's wrist and forearm stay within ``wrist_length`` along the tool axis and ``wrist_offset`` to
    either side of it (a UR arm working perpendicular to a wall: the wrist links sit beside the tool axis, on
    either side depending on the arm's branch), links of ``arm_radius``; the upper arm and the elbow stay within
    ``shoulder_radius`` of the shoulder's axis on the floor plan (they swing out sideways as the tool reaches
    along the wall: a base close to a corner lets the forearm meet the neighbouring wall); every part keeps
    ``clearance``."""
    base_length: float
    base_width: float
    shoulder_x: float
    tools: Dict[str, ToolEnvelope]
    clearance: float = 0.05
    arm_radius: float = 0.06
    wrist_length: float = 0.35
    wrist_offset: float = 0.10
    shoulder_radius: float = 0.45

    @classmethod
    def from_robot(cls, robot: Mapping[str, Any], facts: Any, clearance: float = 0.05, arm_radius: float = 0.06,
                   wrist_length: float = 0.35, wrist_offset: float = 0.10, shoulder_radius: float = 0.45,
                   overrun: Optional[Mapping[str, float]] = None) -> "RobotEnvelope":
        """From a validated robot section (``load_robot(...)["robot"]``) and its :class:`RobotFacts`;
        ``overrun``: per work the room a raster lane needs past its section's end (HICEM ``<work>.lane_overrun``),
        taken off the lateral reach."""
        chassis = robot["base"]["chassis"]
        tools: Dict[str, ToolEnvelope] = {}
        for work, wf in facts.work.items():
            run_on = float((overrun or {}).get(work, 0.0))
            tools[work] = ToolEnvelope.from_facts(work, wf.entries, float(wf["lateral_reach"]) - run_on, run_on)
        return cls(float(chassis["length"]), float(chassis["width"]), float(robot["arm"]["mount"]["xyz"][0]), tools,
                   clearance, arm_radius, wrist_length, wrist_offset, shoulder_radius)


@dataclass
class WallReach:
    """What one work can do on one wall: ``tool``: intervals along the wall where the tool can work (its
    working point), each also reachable from a free base position; ``base``: intervals of free base centres;
    ``t``: the height band of the working point; ``why``: per blocked stretch what blocks it."""
    wall: str
    work: str
    tool: List[Interval]
    base: List[Interval]
    t: Interval
    why: List[Tuple[Interval, str]] = field(default_factory=list)

    def base_for(self, a: float, b: float, reach: float) -> Optional[float]:
        """A free base centre from which the tool reaches ``a..b`` along the wall: the one nearest the middle;
        None when there is none."""
        mid = (a + b) / 2.0
        lo, hi = b - reach - 1e-6, a + reach + 1e-6
        best: Optional[float] = None
        for p, q in self.base:
            x = min(max(mid, p, lo), q, hi)
            if max(p, lo) <= x <= min(q, hi) and (best is None or abs(x - mid) < abs(best - mid)):
                best = x
        return best


@dataclass
class Wall2D:
    id: str
    p0: np.ndarray
    p1: np.ndarray
    n: np.ndarray          # unit normal into the room (2D)
    height: float
    corners: List[Dict[str, Any]]
    ceiling: Optional[float] = None        # m above the floor; None: open above the wall (a free-standing wall)

    @property
    def u(self) -> np.ndarray:
        d = self.p1 - self.p0
        return d / np.linalg.norm(d)

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.p1 - self.p0))

    @classmethod
    def from_scan(cls, w: Mapping[str, Any]) -> "Wall2D":
        n = np.array(w["normal"][:2], dtype=float)
        ceiling = w.get("ceiling")
        return cls(str(w["id"]), np.array(w["p0"], dtype=float), np.array(w["p1"], dtype=float),
                   n / np.linalg.norm(n), float(w["height"]), list(w.get("corners", [])),
                   float(ceiling) if ceiling is not None else None)

    @classmethod
    def from_obstacle(cls, o: Mapping[str, Any]) -> "Wall2D":
        """An item of the scan's ``obstacles`` (``id``, ``p0``, ``p1``, ``height``): a segment other walls'
        plans keep off (never planned itself: its normal is only one of the two)."""
        p0, p1 = np.array(o["p0"], dtype=float), np.array(o["p1"], dtype=float)
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        return cls(str(o["id"]), p0, p1, np.array([-d[1], d[0]]), float(o["height"]), [])

    def point(self, s: Any, d: Any) -> np.ndarray:
        """Map points of wall coordinates ``(s, d)`` (arrays broadcast), shape (..., 2)."""
        s, d = np.asarray(s, dtype=float), np.asarray(d, dtype=float)
        return self.p0 + s[..., None] * self.u + d[..., None] * self.n


#: m, length of the ray that stands for a neighbouring wall at an inside corner
NEIGHBOUR_RAY = 6.0


def obstacles(wall: Wall2D, others: Sequence[Wall2D]) -> Tuple[np.ndarray, np.ndarray]:
    """Obstacles for work on ``wall``: segments, shape (k, 2, 2) -- the other walls and, at each inside corner,
    the neighbour's face as a ray from the corner -- and the neighbours' half-planes, shape (m, 2, 2) as
    (a point on the face, its unit normal into the room): at an inside corner the room lies on one side of the
    neighbour, whatever the distance."""
    segs = [np.array([o.p0, o.p1]) for o in others if o.id != wall.id]
    planes = []
    for c in wall.corners:
        ang = float(c["angle"])
        if not 0.0 < ang < math.pi - 1e-6:
            continue                          # straight on or an outside corner: nothing in front of the wall
        if c["end"] == 1:
            at, away = wall.p1, -wall.u
        else:
            at, away = wall.p0, wall.u
        direction = math.cos(ang) * away + math.sin(ang) * wall.n
        segs.append(np.array([at, at + NEIGHBOUR_RAY * direction]))
        normal = math.sin(ang) * away - math.cos(ang) * wall.n          # the room side of the neighbour
        planes.append(np.array([at, normal]))
    return np.array(segs, dtype=float).reshape(-1, 2, 2), np.array(planes, dtype=float).reshape(-1, 2, 2)


def _inside(points: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Whether each point (..., 2) lies on the room side of every half-plane."""
    ok = np.ones(points.shape[:-1], dtype=bool)
    for at, normal in planes:
        ok &= (points - at) @ normal >= 0.0
    return ok


def _distance(points: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distance of each point (..., 2) to the nearest segment (k, 2, 2); +inf without segments."""
    if segs.shape[0] == 0:
        return np.full(points.shape[:-1], np.inf)
    a, b = segs[:, 0], segs[:, 1]                       # (k, 2)
    ab = b - a
    p = points[..., None, :]                            # (..., 1, 2)
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-12), 0.0, 1.0)
    nearest = a + t[..., None] * ab
    return np.min(np.linalg.norm(p - nearest, axis=-1), axis=-1)


def _crosses(wall: Wall2D, s_b: np.ndarray, d0: float, d1: float, half_w: float, segs: np.ndarray) -> np.ndarray:
    """Whether an obstacle segment's end lies inside the base rectangle at each centre ``s_b`` (a thin wall
    could otherwise pass between the sampled outline points)."""
    if segs.shape[0] == 0:
        return np.zeros(s_b.shape, dtype=bool)
    ends = segs.reshape(-1, 2)
    rel = ends - wall.p0
    es, ed = rel @ wall.u, rel @ wall.n                  # (m,)
    return np.any((np.abs(es[None, :] - s_b[:, None]) <= half_w) & (ed[None, :] >= d0) & (ed[None, :] <= d1), axis=1)


def _intervals(s: np.ndarray, ok: np.ndarray) -> List[Interval]:
    out: List[Interval] = []
    start = None
    for x, flag in zip(s, ok):
        if flag and start is None:
            start = x
        elif not flag and start is not None:
            out.append((float(start), float(prev)))
            start = None
        prev = x
    if start is not None:
        out.append((float(start), float(s[-1])))
    return out


def wall_reach(wall: Wall2D, others: Sequence[Wall2D], robot: RobotEnvelope, work: str) -> WallReach:
    """:class:`WallReach` of ``work`` on ``wall`` (see the module docstring)."""
    tool = robot.tools[work]
    c = robot.clearance
    segs, planes = obstacles(wall, others)
    n = max(2, int(round(wall.length / STEP)) + 1)
    s = np.linspace(0.0, wall.length, n)

    def clear(ds: float, d: float, need: float) -> np.ndarray:
        pts = wall.point(s + ds, np.full(n, d))
        return (_distance(pts, segs) >= need) & _inside(pts, planes)
    # the tool at s: its working end, its body up to the flange, the wrist and forearm behind it
    flange = tool.tip_distance + tool.length
    tool_ok = np.ones(n, dtype=bool)
    for ds in (-tool.tip_radius, 0.0, tool.tip_radius):
        tool_ok &= clear(ds, tool.tip_distance, c)
    for ds in (-tool.body_radius, 0.0, tool.body_radius):
        tool_ok &= clear(ds, flange, c)
    w = robot.wrist_offset + robot.arm_radius
    for d in np.linspace(flange, flange + robot.wrist_length, 4):
        for ds in (-w, 0.0, w):
            tool_ok &= clear(ds, float(d), c)
    # the base at s_b: its chassis outline (every OUTLINE_STEP; _crosses catches a wall end between two points)
    # and the arm's shoulder
    d0, d1 = tool.base_standoff - robot.base_length / 2.0, tool.base_standoff + robot.base_length / 2.0
    hw = robot.base_width / 2.0
    base_ok = np.ones(n, dtype=bool)
    for dd in np.linspace(d0, d1, max(2, int(math.ceil((d1 - d0) / OUTLINE_STEP)) + 1)):
        for side in (-hw, hw):
            base_ok &= clear(side, float(dd), c)
    for ds in np.linspace(-hw, hw, max(2, int(math.ceil(2 * hw / OUTLINE_STEP)) + 1)):
        for dd in (d0, d1):
            base_ok &= clear(float(ds), dd, c)
    base_ok &= clear(0.0, tool.base_standoff - robot.shoulder_x, robot.shoulder_radius + c)
    base_ok &= ~_crosses(wall, s, d0 - c, d1 + c, hw + c, segs)
    # the tool also travels run_on past the worked part: a point is worked only when the tool fits that far on
    if tool.run_on > 0.0:
        m = int(math.ceil(tool.run_on / STEP - 1e-9))
        padded = np.pad(tool_ok, m, mode="edge")      # past a wall end as at the end (a corner blocks there)
        eroded = np.ones(n, dtype=bool)
        for off in range(2 * m + 1):
            eroded &= padded[off:off + n]
        tool_ok = eroded
    # a working point is reached when a free base centre lies within reach of it
    k = int(math.floor(tool.reach / STEP + 1e-9))
    padded = np.concatenate([np.zeros(k, dtype=bool), base_ok, np.zeros(k, dtype=bool)])
    within = np.zeros(n, dtype=bool)
    for off in range(2 * k + 1):
        within |= padded[off:off + n]
    ok = tool_ok & within
    lo = tool.z_range[0]
    hi = tool.z_range[1]
    if wall.ceiling is not None:          # the working end keeps its radius and the clearance from the ceiling
        hi = min(hi, wall.ceiling - tool.tip_radius - c)
    why: List[Tuple[Interval, str]] = []
    for a, b in _intervals(s, ~tool_ok):
        why.append(((a, b), "the %s would touch a wall or frame there" % work))
    for a, b in _intervals(s, tool_ok & ~within):
        why.append(((a, b), "no free base pose within reach (%.2f m)" % tool.reach))
    return WallReach(wall.id, work, _intervals(s, ok), _intervals(s, base_ok), (lo, hi), why)


def _clip(lo: float, hi: float, intervals: Sequence[Interval]) -> List[Interval]:
    return [(max(lo, a), min(hi, b)) for a, b in intervals if min(hi, b) - max(lo, a) > 1e-9]


def interval_minus(lo: float, hi: float, cuts: Sequence[Interval], shortest: float = 1e-9) -> List[Interval]:
    """``[lo, hi]`` without the intervals ``cuts`` (in any order, overlapping or not); pieces shorter than
    ``shortest`` are dropped."""
    pieces = [(lo, hi)]
    for a, b in sorted(cuts):
        nxt = []
        for p, q in pieces:
            if b <= p or a >= q:
                nxt.append((p, q))
                continue
            if a > p:
                nxt.append((p, a))
            if b < q:
                nxt.append((b, q))
        pieces = nxt
    return [(p, q) for p, q in pieces if q - p >= shortest]


@dataclass
class AreaPlan:
    """An area for one work: ``parts`` the robot works (area coordinates: ``(s0, s1, t0, t1)``), ``manual``
    what is left to the hand, each ``{"along": [a, b], "height": [c, d], "reason": text}`` (``along`` from the
    area's origin, ``height`` above the floor, m)."""
    area: str
    work: str
    parts: List[Tuple[float, float, float, float]]
    manual: List[Dict[str, Any]]


def plan_area(area: Mapping[str, Any], wall: Wall2D, reach: WallReach, min_manual: float = 0.0) -> AreaPlan:
    """Cut an area (SCAN shape) into what ``reach`` can work and what is manual. A manual strip narrower than
    ``min_manual`` is not reported: the tool's footprint past the worked part's edge (a spray fan, a pad) covers
    it; such a strip of the area past a wall's end the tool works up to is worked with the part beside it."""
    rel = np.array(area["origin"][:2], dtype=float) - wall.p0
    s0 = float(rel @ wall.u)
    t0 = float(area["origin"][2])
    w, h = float(area["width"]), float(area["height"])
    lo, hi = max(reach.t[0], t0), min(reach.t[1], t0 + h)
    manual: List[Dict[str, Any]] = []
    parts: List[Tuple[float, float, float, float]] = []
    along = _clip(s0, s0 + w, reach.tool)
    if along:
        # an area drawn to a wall's end that the scan puts a little inside it (scan noise): where the tool works
        # right up to the wall's end, the strip of the area past it (narrower than min_manual) is worked with the
        # part beside it, so the part's end is the area's and its lanes run on past it. Else the part stopped short
        # of the area's end and, that strip too narrow to list, its lanes ran on past neither (on bay 99 a 0.4 mm
        # strip at a corner left the fan's soft edge, 2 cm of wall_1, under the target thickness). A strip inside
        # the wall stays out: the tool is kept off what stops it there by the clearance, not by a tolerance.
        end = wall.length
        if along[0][0] <= 1e-9 and 0.0 < -s0 < min_manual:
            along[0] = (s0, along[0][1])
        if along[-1][1] >= end - 1e-9 and 0.0 < s0 + w - end < min_manual:
            along[-1] = (along[-1][0], s0 + w)
    if hi - lo > 1e-9:
        parts = [(a - s0, b - s0, lo - t0, hi - t0) for a, b in along]
    for a, b in interval_minus(s0, s0 + w, along):
        reason = next((r for (p, q), r in reach.why if p <= b and q >= a), "out of reach")
        manual.append({"along": [a - s0, b - s0], "height": [t0, t0 + h], "reason": reason})
    for a, b in along:
        if lo > t0 + 1e-9:
            manual.append({"along": [a - s0, b - s0], "height": [t0, lo], "reason": "below the tool's reach"})
        if hi < t0 + h - 1e-9:
            manual.append({"along": [a - s0, b - s0], "height": [max(hi, t0), t0 + h],
                           "reason": "above the tool's reach (arm or ceiling)"})
    manual = [m for m in manual if min(m["along"][1] - m["along"][0], m["height"][1] - m["height"][0]) >= min_manual]
    return AreaPlan(str(area["id"]), reach.work, parts, manual)


@dataclass
class JointPlan:
    """A joint for taping: ``pieces`` the robot tapes one after the other, each ``{"from": [x, y, z], "to": [x, y,
    z], "along": [a, b], "base": s_b}`` (map points; ``along`` m from the joint's start; ``base`` the free base
    centre along the wall it is taped from), and ``manual`` pieces, each ``{"from", "to", "along", "reason"}``.
    ``piece``: from the first taped point to the last (None: none of it is taped)."""
    joint: str
    pieces: List[Dict[str, Any]]
    manual: List[Dict[str, Any]]

    @property
    def piece(self) -> Optional[List[List[float]]]:
        return [self.pieces[0]["from"], self.pieces[-1]["to"]] if self.pieces else None


def plan_joint(joint: Mapping[str, Any], wall: Wall2D, reach: WallReach, side: Optional[float] = None,
               segment_length: float = 0.0, min_manual: float = 0.0) -> JointPlan:
    """The parts of a joint (SCAN shape, or ``start``/``end`` straightened) ``reach`` can tape, the rest manual.

    A vertical joint is taped in one piece, clipped to the height band, from the free base centre nearest it
    within ``side`` m along the wall (the arm's lateral reach; None: any base the plan allows). A horizontal joint
    is taped on every stretch the tool reaches, each cut into pieces no longer than ``segment_length`` (0: one
    piece per stretch) taped from the free base centre nearest each piece's middle that reaches both its ends
    (within half a piece length plus nothing more: a piece is as long as the arm lays tape from one pose). What
    is left -- out of the band, near a corner, no free base -- is manual, with its reason. A vertical joint
    reaching less than ``min_manual`` past the band is taped to its end (the band is measured with margin; a
    scanned end a few millimetres below it is no manual work); a horizontal manual part shorter than
    ``min_manual`` is not listed. A stretch the tool reaches that is shorter than SHORTEST_PIECE (between a
    corner and a frame, say) is manual too: the robot lays no tape shorter than that."""
    a, b = np.array(joint["start"], dtype=float), np.array(joint["end"], dtype=float)
    total = float(np.linalg.norm(b - a))

    def s_of(p: np.ndarray) -> float:
        return float((p[:2] - wall.p0) @ wall.u)

    def at(f: float) -> List[float]:
        return [float(x) for x in a + (b - a) * f]

    def part(f0: float, f1: float, **extra: Any) -> Dict[str, Any]:
        return dict({"from": at(f0), "to": at(f1), "along": [total * f0, total * f1]}, **extra)

    def why(s: float) -> str:
        return next((r for (p, q), r in reach.why if p - 1e-9 <= s <= q + 1e-9), "out of reach")

    jid = str(joint["id"])
    if total < 1e-9:
        return JointPlan(jid, [], [])
    if joint["kind"] == "vertical":
        s = (s_of(a) + s_of(b)) / 2.0
        if not any(p - 1e-9 <= s <= q + 1e-9 for p, q in reach.tool):
            return JointPlan(jid, [], [part(0.0, 1.0, reason=why(s))])
        base = reach.base_for(s, s, side if side is not None else 1e9)
        if base is None:
            return JointPlan(jid, [], [part(0.0, 1.0, reason="no free base pose within %.2f m of it" % side)])
        z0, z1 = sorted((float(a[2]), float(b[2])))
        lo = z0 if reach.t[0] - z0 < min_manual else max(z0, reach.t[0])
        hi = z1 if z1 - reach.t[1] < min_manual else min(z1, reach.t[1])
        if hi - lo < 1e-3:
            return JointPlan(jid, [], [part(0.0, 1.0, reason="outside the tool's height band")])
        if hi - lo < SHORTEST_PIECE - 1e-9:
            return JointPlan(jid, [], [part(0.0, 1.0, reason=SHORT_REASON)])
        span = float(b[2] - a[2])
        if abs(span) < 1e-9:
            return JointPlan(jid, [part(0.0, 1.0, base=base)], [])
        fa, fb = sorted(((lo - a[2]) / span, (hi - a[2]) / span))
        manual = [part(f0, f1, reason=r) for f0, f1, r in
                  ((0.0, fa, "below the tool's reach" if span > 0 else "above the tool's reach"),
                   (fb, 1.0, "above the tool's reach" if span > 0 else "below the tool's reach")) if f1 - f0 > 1e-6]
        return JointPlan(jid, [part(fa, fb, base=base)], manual)
    sa, sb = s_of(a), s_of(b)
    length = sb - sa
    z = float((a[2] + b[2]) / 2.0)
    if not reach.t[0] - 1e-9 <= z <= reach.t[1] + 1e-9:
        return JointPlan(jid, [], [part(0.0, 1.0, reason="outside the tool's height band")])
    if abs(length) < 1e-9:
        return JointPlan(jid, [], [part(0.0, 1.0, reason="not along the wall")])
    pieces: List[Dict[str, Any]] = []
    short: List[Tuple[float, float]] = []          # reachable stretches too short to tape (along the joint)
    for p, q in _clip(min(sa, sb), max(sa, sb), reach.tool):
        if q - p < SHORTEST_PIECE - 1e-9:
            short.append(tuple(sorted(((p - sa) / length * total, (q - sa) / length * total))))
            continue
        n = max(1, int(math.ceil((q - p) / segment_length - 1e-9))) if segment_length > 0 else 1
        todo = [(p + (q - p) * i / n, p + (q - p) * (i + 1) / n) for i in range(n)]
        while todo:
            u, v = todo.pop()
            half = (v - u) / 2.0 if segment_length > 0 else 1e9
            base = reach.base_for(u, v, half + 1e-6)
            if base is not None:
                f0, f1 = sorted(((u - sa) / length, (v - sa) / length))
                pieces.append(part(f0, f1, base=base))
            elif v - u > 2 * SHORTEST_PIECE:       # no free base in front of its middle: two shorter pieces
                todo += [(u, (u + v) / 2.0), ((u + v) / 2.0, v)]
    pieces.sort(key=lambda x: x["along"][0])
    manual = []
    for lo_, hi_ in interval_minus(0.0, total, [tuple(x["along"]) for x in pieces] + short, max(min_manual, 1e-6)):
        mid = sa + length * (lo_ + hi_) / 2.0 / total
        manual.append(part(lo_ / total, hi_ / total, reason=why(mid)))
    manual += [part(lo_ / total, hi_ / total, reason=SHORT_REASON) for lo_, hi_ in short if hi_ - lo_ >= min_manual]
    manual.sort(key=lambda x: x["along"][0])
    return JointPlan(jid, pieces, manual)


@dataclass
class SitePlan:
    """Per wall and work its :class:`WallReach`, per area and work its :class:`AreaPlan`, per joint its
    :class:`JointPlan`; ``seconds``: planning time per wall."""
    reach: Dict[Tuple[str, str], WallReach]
    areas: Dict[Tuple[str, str], AreaPlan]
    joints: Dict[str, JointPlan]
    seconds: Dict[str, float]

    def manual_summary(self) -> Dict[str, Any]:
        """The manual work in plain data (for the report and the operator page)."""
        return {"areas": [dict(m, area=p.area, work=p.work) for p in self.areas.values() for m in p.manual],
                "joints": [dict(m, joint=j.joint) for j in self.joints.values() for m in j.manual]}


def plan_site(scan: Mapping[str, Any], robot: RobotEnvelope, works: Sequence[str] = ("taping", "spray", "sand"),
              clock: Any = None) -> SitePlan:
    """Plan every joint (taping) and area (``works`` other than taping) of a SCAN result (its ``obstacles`` kept
    off like the other walls)."""
    import time
    clock = clock or time.perf_counter
    walls = [Wall2D.from_scan(w) for w in scan.get("walls", [])]
    others = walls + [Wall2D.from_obstacle(o) for o in scan.get("obstacles", [])]
    reach: Dict[Tuple[str, str], WallReach] = {}
    areas: Dict[Tuple[str, str], AreaPlan] = {}
    joints: Dict[str, JointPlan] = {}
    seconds: Dict[str, float] = {}
    for w in walls:
        t0 = clock()
        for work in works:
            if work in robot.tools:
                reach[(w.id, work)] = wall_reach(w, others, robot, work)
        for j in scan.get("joints", []):
            if j["wall"] == w.id and (w.id, "taping") in reach:
                joints[j["id"]] = plan_joint(j, w, reach[(w.id, "taping")])
        for a in scan.get("areas", []):
            if a["wall"] != w.id:
                continue
            for work in works:
                if work != "taping" and (w.id, work) in reach:
                    areas[(a["id"], work)] = plan_area(a, w, reach[(w.id, work)])
        seconds[w.id] = clock() - t0
    return SitePlan(reach, areas, joints, seconds)
