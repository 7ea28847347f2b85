"""Ground-truth geometry of a worksite: walls, joints and areas in the ``map`` frame.

Built once from a validated site dictionary (:func:`locem_bridge.sim.config.load_site`) and then read-only.
Each wall has a surface frame: origin at ``p0`` on the floor, unit tangent ``u`` along ``p0 -> p1``, ``z`` up,
and the unit normal ``n`` pointing into the room. A point maps to wall coordinates ``(s, t, d)``: ``s`` along
``u``, ``t`` height, ``d`` distance in front of the surface (negative = behind it). Joints and areas follow the
shapes of ``docs/contracts.md`` (SCAN result) so :meth:`Site.to_contract` is the ground-truth scan.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Tuple

import numpy as np


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

    def to_contract(self) -> Dict[str, Any]:
        return {"id": self.id, "wall": self.wall, "origin": [_r(x) for x in self.origin],
                "u": [_r(x) for x in self.u], "width": self.width, "height": self.height}


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
        return {"id": self.id, "p0": [_r(x) for x in self.p0], "p1": [_r(x) for x in self.p1],
                "height": self.height, "thickness": self.thickness, "normal": [_r(x) for x in self.n]}


class Site:
    """The walls of a worksite with their joints and areas (ground truth, map frame)."""

    def __init__(self, site_cfg: Dict[str, Any]) -> None:
        site = site_cfg["site"]
        self.name: str = site["name"]
        self.robot_start: List[float] = list(site["robot_start"])
        self.floor_size: List[float] = list(site["room"]["floor_size"])
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
        for i in range(1, n_panels + 1):
            s = i * pw
            if s >= wall.length - 1e-6:
                break
            wall.joints.append(Joint(id="%s_joint_%d" % (wall.id, k), wall=wall.id, kind="vertical",
                                     start=wall.from_wall_coords(s, low), end=wall.from_wall_coords(s, wall.height),
                                     width=wc["joint_width"]))
            k += 1
        for h in wc.get("horizontal_joints", []):
            wall.joints.append(Joint(id="%s_joint_%d" % (wall.id, k), wall=wall.id, kind="horizontal",
                                     start=wall.from_wall_coords(0.0, h), end=wall.from_wall_coords(wall.length, h),
                                     width=wc["joint_width"]))
            k += 1
        areas = wc.get("areas") or [{"id": "%s_area_1" % wall.id, "s": [0.0, wall.length], "t": [low, wall.height]}]
        for a in areas:
            s0, s1 = sorted(a["s"])
            t0, t1 = sorted(a["t"])
            s0, s1 = max(0.0, s0), min(wall.length, s1)
            t0, t1 = max(low, t0), min(wall.height, t1)
            wall.areas.append(Area(id=a["id"], wall=wall.id, origin=wall.from_wall_coords(s0, t0), u=wall.u.copy(),
                                   width=s1 - s0, height=t1 - t0, s0=s0, t0=t0))

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

    def to_contract(self, stamp: float = 0.0) -> Dict[str, Any]:
        """The complete ground truth in the SCAN JSON shape (all plasterboard walls, no noise)."""
        return {"stamp": stamp, "walls": [w.to_contract() for w in self.work_walls],
                "joints": [j.to_contract() for j in self.joints], "areas": [a.to_contract() for a in self.areas]}
