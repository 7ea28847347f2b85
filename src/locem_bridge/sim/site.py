"""Ground-truth geometry of a worksite: walls, joints and areas in the ``map`` frame.

Built once from a validated site dictionary (:func:`locem_bridge.sim.config.load_site`) and then read-only.
Each wall has a surface frame: origin at ``p0`` on the floor, unit tangent ``u`` along ``p0 -> p1``, ``z`` up,
and the unit normal ``n`` pointing into the room. A point maps to wall coordinates ``(s, t, d)``: ``s`` along
``u``, ``t`` height, ``d`` distance in front of the surface (negative = behind it). Joints and areas follow the
shapes of ``docs/contracts.md`` (SCAN result) so :meth:`Site.to_contract` is the ground-truth scan.

Openings (doors, windows) are holes in a wall: the clear opening ``s0..s1 x t0..t1`` with a frame of width
``frame`` around it in the wall plane (a door has none at the floor). Nothing is finished on an opening or its
frame: a joint that runs into one ends at the frame (the parts above and below, or beside it, are joints of
their own), and a work area keeps the rectangle it was given but carries the parts of openings and frames inside
it as ``holes`` (area coordinates), which no tool may work.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from ..planning.reach import interval_minus


def _r(x: float) -> float:
    """Round for JSON output (micrometres) and drop negative zero."""
    return round(float(x), 6) + 0.0


@dataclass
class Joint:
    """A joint between plasterboard panels: a segment on the wall surface (``kind`` vertical/horizontal)."""
    id: str
    wall: str
    kind: str
    start: np.ndarray       # 3D, map frame
    end: np.ndarray
    width: float

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))

    def to_contract(self) -> Dict[str, Any]:
        return {"id": self.id, "wall": self.wall, "kind": self.kind, "start": [_r(x) for x in self.start],
                "end": [_r(x) for x in self.end], "width": self.width}


@dataclass
class Opening:
    """A door or window: the clear opening ``s0..s1`` along the wall, ``t0..t1`` high, and its frame."""
    id: str
    wall: str
    kind: str               # door | window
    s0: float
    s1: float
    t0: float
    t1: float
    frame: float

    @property
    def outer(self) -> Tuple[float, float, float, float]:
        """``(s0, s1, t0, t1)`` of the opening with its frame (a door's frame stops at the floor)."""
        return (self.s0 - self.frame, self.s1 + self.frame, self.t0 - self.frame if self.t0 > 0 else 0.0,
                self.t1 + self.frame)

    def contains(self, s: float, t: float, margin: float = 0.0) -> bool:
        """Whether wall point ``(s, t)`` lies in the clear opening (no wall there), at least ``margin`` inside it."""
        return self.s0 + margin < s < self.s1 - margin and self.t0 + margin <= t < self.t1 - margin

    def to_contract(self) -> Dict[str, Any]:
        return {"id": self.id, "kind": self.kind, "s": [_r(self.s0), _r(self.s1)], "t": [_r(self.t0), _r(self.t1)],
                "frame": _r(self.frame)}


#: m, a joint piece shorter than this between an opening's frame and the wall's edge (or another frame) is left
#: to the hand (a trowel, not a robot pass)
SHORTEST_JOINT = 0.1


@dataclass
class Area:
    """A rectangle ``origin + s*u + t*z`` with ``s`` in [0, width], ``t`` in [0, height] on a wall surface."""
    id: str
    wall: str
    origin: np.ndarray
    u: np.ndarray
    width: float
    height: float
    s0: float               # offset of the area along the wall from p0
    t0: float
    holes: List[Tuple[float, float, float, float]] = field(default_factory=list)   # (s0, s1, t0, t1) area coords

    def in_hole(self, s: Any, t: Any) -> Any:
        """Whether area point(s) ``(s, t)`` (area coordinates, arrays allowed) lie in a hole."""
        out = np.zeros(np.broadcast(np.asarray(s), np.asarray(t)).shape, dtype=bool)
        for a, b, c, d in self.holes:
            out |= (np.asarray(s) > a) & (np.asarray(s) < b) & (np.asarray(t) > c) & (np.asarray(t) < d)
        return out

    def to_contract(self) -> Dict[str, Any]:
        out = {"id": self.id, "wall": self.wall, "origin": [_r(x) for x in self.origin],
               "u": [_r(x) for x in self.u], "width": self.width, "height": self.height}
        if self.holes:
            out["holes"] = [{"s": [_r(a), _r(b)], "t": [_r(c), _r(d)]} for a, b, c, d in self.holes]
        return out


@dataclass
class Wall:
    """One wall: a vertical rectangle standing on the floor segment ``p0 -> p1``."""
    id: str
    material: str
    p0: np.ndarray          # 2D
    p1: np.ndarray
    height: float
    thickness: float
    u: np.ndarray = field(default=None)         # 3D unit tangent
    n: np.ndarray = field(default=None)         # 3D unit normal into the room
    joints: List[Joint] = field(default_factory=list)
    areas: List[Area] = field(default_factory=list)
    openings: List[Opening] = field(default_factory=list)

    def in_opening(self, s: float, t: float, margin: float = 0.0) -> bool:
        """Whether wall point ``(s, t)`` lies in a clear opening (a door or window: no wall there), at least
        ``margin`` inside it."""
        return any(o.contains(s, t, margin) for o in self.openings)

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.p1 - self.p0))

    @property
    def origin3(self) -> np.ndarray:
        return np.array([self.p0[0], self.p0[1], 0.0])

    def to_wall_coords(self, point: np.ndarray) -> Tuple[float, float, float]:
        """Map a 3D map-frame point to ``(s, t, d)`` wall coordinates (see module docstring)."""
        rel = np.asarray(point, dtype=float) - self.origin3
        return float(rel @ self.u), float(rel[2]), float(rel @ self.n)

    def from_wall_coords(self, s: float, t: float, d: float = 0.0) -> np.ndarray:
        return self.origin3 + s * self.u + np.array([0.0, 0.0, t]) + d * self.n

    def to_contract(self) -> Dict[str, Any]:
        out = {"id": self.id, "p0": [_r(x) for x in self.p0], "p1": [_r(x) for x in self.p1],
               "height": self.height, "thickness": self.thickness, "normal": [_r(x) for x in self.n]}
        if self.openings:
            out["openings"] = [o.to_contract() for o in self.openings]
        return out


class Site:
    """The walls of a worksite with their joints and areas (ground truth, map frame)."""

    def __init__(self, site_cfg: Dict[str, Any]) -> None:
        site = site_cfg["site"]
        self.name: str = site["name"]
        self.robot_start: List[float] = list(site["robot_start"])
        self.floor_size: List[float] = list(site["room"]["floor_size"])
        #: m, the room's ceiling above the floor; None: open above the walls (free-standing mock-up walls)
        self.ceiling: Optional[float] = site["room"].get("ceiling")
        walls_cfg = site["walls"]
        inside = site["room"].get("inside")
        if inside is None:
            mids = [(np.array(w["p0"]) + np.array(w["p1"])) / 2.0 for w in walls_cfg]
            inside = list(np.mean(mids, axis=0))
        inside = np.array(inside, dtype=float)
        self.walls: List[Wall] = []
        for wc in walls_cfg:
            wall = Wall(id=wc["id"], material=wc["material"], p0=np.array(wc["p0"], dtype=float),
                        p1=np.array(wc["p1"], dtype=float), height=wc["height"], thickness=wc["thickness"])
            d = (wall.p1 - wall.p0) / wall.length
            wall.u = np.array([d[0], d[1], 0.0])
            n2 = np.array([d[1], -d[0]])
            mid = (wall.p0 + wall.p1) / 2.0
            if float(n2 @ (inside - mid)) < 0.0:
                n2 = -n2
            wall.n = np.array([n2[0], n2[1], 0.0])
            wall.openings = [Opening(id=o["id"], wall=wall.id, kind=o["kind"], s0=o["s"][0], s1=o["s"][1],
                                     t0=o["t"][0], t1=o["t"][1], frame=o["frame"]) for o in wc.get("openings", [])]
            if wall.material == "plasterboard":
                self._make_features(wall, wc)
            self.walls.append(wall)
        self._by_id = {w.id: w for w in self.walls}

    @staticmethod
    def _make_features(wall: Wall, wc: Dict[str, Any]) -> None:
        k = 1
        pw = wc["panel_width"]
        low = float(wc.get("skirting", 0.0))       # the strip behind the skirting board is not finished
        n_panels = int(math.floor(wall.length / pw + 1e-9))
        outer = [o.outer for o in wall.openings]
        half = wc["joint_width"] / 2.0
        for i in range(1, n_panels + 1):
            s = i * pw
            if s >= wall.length - 1e-6:
                break
            cuts = [(c, d) for a, b, c, d in outer if a - half < s < b + half]
            for t0, t1 in interval_minus(low, wall.height, cuts, SHORTEST_JOINT):
                wall.joints.append(Joint(id="%s_joint_%d" % (wall.id, k), wall=wall.id, kind="vertical",
                                         start=wall.from_wall_coords(s, t0), end=wall.from_wall_coords(s, t1),
                                         width=wc["joint_width"]))
                k += 1
        for h in wc.get("horizontal_joints", []):
            cuts = [(a, b) for a, b, c, d in outer if c - half < h < d + half]
            for s0, s1 in interval_minus(0.0, wall.length, cuts, SHORTEST_JOINT):
                wall.joints.append(Joint(id="%s_joint_%d" % (wall.id, k), wall=wall.id, kind="horizontal",
                                         start=wall.from_wall_coords(s0, h), end=wall.from_wall_coords(s1, h),
                                         width=wc["joint_width"]))
                k += 1
        areas = wc.get("areas") or [{"id": "%s_area_1" % wall.id, "s": [0.0, wall.length], "t": [low, wall.height]}]
        for a in areas:
            s0, s1 = sorted(a["s"])
            t0, t1 = sorted(a["t"])
            s0, s1 = max(0.0, s0), min(wall.length, s1)
            t0, t1 = max(low, t0), min(wall.height, t1)
            holes = []
            for a0, a1, b0, b1 in outer:
                h = (max(a0, s0) - s0, min(a1, s1) - s0, max(b0, t0) - t0, min(b1, t1) - t0)
                if h[1] - h[0] > 1e-9 and h[3] - h[2] > 1e-9:
                    holes.append(h)
            wall.areas.append(Area(id=a["id"], wall=wall.id, origin=wall.from_wall_coords(s0, t0), u=wall.u.copy(),
                                   width=s1 - s0, height=t1 - t0, s0=s0, t0=t0, holes=holes))

    def corners(self, wall_id: str, tolerance: float = 0.02) -> List[Tuple[int, "Wall", float]]:
        """The walls meeting wall ``wall_id`` at its ends: ``(end, other wall, angle)`` with ``end`` 0 (at ``p0``)
        or 1 (at ``p1``) and ``angle`` the angle in degrees between the two wall faces seen from the room (90
        for a square inside corner; below 180 an inside corner, where the neighbour stands in front of this
        wall's surface). Ends closer than ``tolerance`` m meet."""
        me = self.wall(wall_id)
        out = []
        for end, p in ((0, me.p0), (1, me.p1)):
            away = (me.p1 - me.p0) if end == 0 else (me.p0 - me.p1)
            away = away / np.linalg.norm(away)
            for other in self.walls:
                if other is me:
                    continue
                for q, far in ((other.p0, other.p1), (other.p1, other.p0)):
                    if np.linalg.norm(q - p) <= tolerance:
                        d = (far - q) / np.linalg.norm(far - q)
                        cos = float(np.clip(d @ away, -1.0, 1.0))
                        ang = math.degrees(math.acos(cos))
                        if float(d @ me.n[:2]) < 0.0:      # the neighbour goes behind this wall: outside corner
                            ang = 360.0 - ang
                        out.append((end, other, ang))
        return out

    def wall(self, wall_id: str) -> Wall:
        try:
            return self._by_id[wall_id]
        except KeyError:
            raise KeyError("unknown wall %r, known: %s" % (wall_id, ", ".join(sorted(self._by_id))))

    @property
    def work_walls(self) -> List[Wall]:
        """Walls with plasterboard (the ones with joints and areas)."""
        return [w for w in self.walls if w.material == "plasterboard"]

    @property
    def joints(self) -> List[Joint]:
        return [j for w in self.walls for j in w.joints]

    @property
    def areas(self) -> List[Area]:
        return [a for w in self.walls for a in w.areas]

    def joint(self, joint_id: str) -> Joint:
        for j in self.joints:
            if j.id == joint_id:
                return j
        raise KeyError("unknown joint %r" % joint_id)

    def wall_contract(self, wall: Wall) -> Dict[str, Any]:
        """:meth:`Wall.to_contract` plus ``corners``: per end where another wall meets this one, ``end`` (0: at
        ``p0``, 1: at ``p1``) and ``angle`` (rad) between the two faces seen from the room (pi/2 for a square
        inside corner): what a planner needs to keep the tool and the robot off the neighbouring wall."""
        out = wall.to_contract()
        if self.ceiling is not None:
            out["ceiling"] = self.ceiling
        corners = [{"end": end, "angle": _r(math.radians(ang))} for end, _other, ang in self.corners(wall.id)]
        if corners:
            out["corners"] = corners
        return out

    def to_contract(self, stamp: float = 0.0) -> Dict[str, Any]:
        """The complete ground truth in the SCAN JSON shape (all plasterboard walls, no noise; every other wall
        under ``obstacles``, left out when there is none)."""
        out: Dict[str, Any] = {"stamp": stamp, "walls": [self.wall_contract(w) for w in self.work_walls],
                               "joints": [j.to_contract() for j in self.joints],
                               "areas": [a.to_contract() for a in self.areas]}
        obstacles = [{"id": w.id, "p0": [_r(x) for x in w.p0], "p1": [_r(x) for x in w.p1], "height": w.height}
                     for w in self.walls if w.material != "plasterboard"]
        if obstacles:
            out["obstacles"] = obstacles
        return out
