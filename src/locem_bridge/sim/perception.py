"""Perception stand-in behind the SCAN command: wall features visible from the robot's current pose.

:class:`WallScanner` sees a plasterboard wall when the wall faces the sensor (sensor in front of the surface)
and some part of it lies within ``range`` and the horizontal field of view ``fov`` of the sensor (mounted at
``scanner.mount`` on the base, looking along the base x axis rotated by ``mount.yaw``). A joint is reported when
its clipped visible part is not empty; the reported start/end are that visible part. Areas are reported whole
for every visible wall. Positions get zero-mean Gaussian noise of standard deviation ``position_noise``
(in the wall plane, along the wall and in height), drawn from a seeded generator so runs repeat. Ids are the
ground-truth ids, stable across scans. A wall carries its openings (doors, windows: exact, no noise) and the
angles of its corners with the walls meeting it; an area the parts of openings inside it as ``holes``. Output is the SCAN JSON shape of ``docs/contracts.md``.

Every other wall (concrete, any material but plasterboard: nothing to work on it, but the chassis, the arm and the
tool must keep off it) is reported under ``obstacles`` as its floor-plan segment ``p0``/``p1`` and ``height``, seen
like a plasterboard wall (facing the sensor, some part in range and field of view) and with the same position
noise on its ends (along and across the face). That noise comes from a generator of its own (seeded from
``seed``), so the walls', joints' and areas' numbers are the same as without obstacles. The key is left out when
no obstacle is seen (the contract's default: none).

With an :class:`~locem_bridge.sim.outcome.OutcomeRecorder` attached (constructor argument or the ``outcome``
attribute) every reported area carries ``finish``, what a camera would see on the surface: ``sanded`` when at
least :data:`FINISHED_FRACTION` of its cells are sprayed to the target thickness *and* sanded, ``sprayed`` when at
least that fraction is sprayed, else ``bare`` (cells as in the recorder's coverage numbers: centres inside the
area, outside its holes). Sanding bare board is not a sanded finish: ``sanded`` tells PEMKRE that spraying is
done too. Without a recorder ``finish`` is left out (the contract's default, ``bare``, applies).
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..common.finish import BARE, SANDED, SPRAYED
from ..common.geometry import wrap_angle
from .site import Area, Site, Wall, _r

#: fraction of an area's cells that must be sprayed (sanded) for the scan to report it sprayed (sanded)
FINISHED_FRACTION = 0.98


def area_coverage(outcome: Any, area: Area) -> Tuple[float, float]:
    """``(spray, sand)`` coverage of ``area`` in ``outcome`` (an OutcomeRecorder): the fraction of the cells whose
    centre lies in the area that hold at least the target thickness, resp. are sanded. (0, 0) if not recorded."""
    m = outcome.maps.get(area.wall)
    if m is None:
        return 0.0, 0.0
    along = (m.sc >= area.s0) & (m.sc <= area.s0 + area.width)
    up = (m.tc >= area.t0) & (m.tc <= area.t0 + area.height)
    cells = up[:, None] & along[None, :]
    if area.holes:
        cells &= ~area.in_hole(m.sc[None, :] - area.s0, m.tc[:, None] - area.t0)
    n = int(cells.sum())
    if n == 0:
        return 0.0, 0.0
    sprayed = (m.thickness >= outcome.target) & cells
    return float(sprayed.sum()) / n, float((m.sanded & cells).sum()) / n


def area_finish(outcome: Any, area: Area) -> str:
    """``bare`` / ``sprayed`` / ``sanded`` for ``area`` (see the module docstring)."""
    spray, sand = area_coverage(outcome, area)
    if spray < FINISHED_FRACTION:
        return BARE
    return SANDED if sand >= FINISHED_FRACTION else SPRAYED


class WallScanner:
    """Visible wall features from a base pose; one instance per robot.

    :param site: ground truth.
    :param scanner_cfg: ``robot.scanner`` section (mount, range, fov).
    :param position_noise: standard deviation in m (``simulation.perception.position_noise``).
    :param seed: seed of the noise generator.
    :param outcome: optional OutcomeRecorder of the same site; when set, areas carry ``finish``.
    """

    SAMPLES_PER_M = 50  # resolution used to clip walls and joints to the visible region

    def __init__(self, site: Site, scanner_cfg: Dict[str, Any], position_noise: float = 0.0, seed: int = 1,
                 outcome: Any = None) -> None:
        self.site = site
        self.outcome = outcome
        self.mount_xyz = list(scanner_cfg["mount"]["xyz"])
        self.mount_yaw = float(scanner_cfg["mount"].get("yaw", 0.0))
        self.range = float(scanner_cfg["range"])
        self.fov = float(scanner_cfg["fov"])
        self.noise = float(position_noise)
        self._rng = np.random.default_rng(seed)
        self._obstacle_rng = np.random.default_rng([seed, 1])     # its own stream: the features' noise unchanged

    def sensor_pose(self, base_pose: Sequence[float]) -> Tuple[np.ndarray, float]:
        """Return the sensor position (x, y) in map and its heading for a base pose ``(x, y, yaw)``."""
        x, y, yaw = base_pose
        mx, my = self.mount_xyz[0], self.mount_xyz[1]
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([x + c * mx - s * my, y + s * mx + c * my]), yaw + self.mount_yaw

    def _visible_mask(self, pts2: np.ndarray, sensor: np.ndarray, heading: float, wall: Wall) -> np.ndarray:
        rel = pts2 - sensor
        dist = np.hypot(rel[:, 0], rel[:, 1])
        ang = np.arctan2(rel[:, 1], rel[:, 0]) - heading
        ang = wrap_angle(ang)
        in_front = float((sensor - wall.p0) @ wall.n[:2]) > 0.0
        return (dist <= self.range) & (np.abs(ang) <= self.fov / 2.0) & in_front

    def _visible_s_interval(self, wall: Wall, s0: float, s1: float, sensor: np.ndarray,
                            heading: float) -> Optional[Tuple[float, float]]:
        n = max(2, int((s1 - s0) * self.SAMPLES_PER_M) + 1)
        s = np.linspace(s0, s1, n)
        pts = wall.p0[None, :] + s[:, None] * wall.u[None, :2]
        mask = self._visible_mask(pts, sensor, heading, wall)
        if not mask.any():
            return None
        idx = np.nonzero(mask)[0]
        return float(s[idx[0]]), float(s[idx[-1]])

    def _noisy(self, p: np.ndarray, wall: Wall) -> np.ndarray:
        if self.noise <= 0.0:
            return p
        e = self._rng.normal(0.0, self.noise, size=2)
        return p + e[0] * wall.u + np.array([0.0, 0.0, e[1]])

    def scan(self, base_pose: Sequence[float], stamp: float = 0.0) -> Dict[str, Any]:
        """Return the SCAN JSON object for the base pose ``(x, y, yaw)`` in map."""
        sensor, heading = self.sensor_pose(base_pose)
        walls: List[Dict[str, Any]] = []
        joints: List[Dict[str, Any]] = []
        areas: List[Dict[str, Any]] = []
        for wall in self.site.work_walls:
            vis = self._visible_s_interval(wall, 0.0, wall.length, sensor, heading)
            if vis is None:
                continue
            wc = self.site.wall_contract(wall)
            if self.noise > 0.0:
                e = self._rng.normal(0.0, self.noise, size=4)
                p0 = wall.p0 + e[0] * wall.u[:2] + e[1] * wall.n[:2]
                p1 = wall.p1 + e[2] * wall.u[:2] + e[3] * wall.n[:2]
                wc["p0"], wc["p1"] = [_r(x) for x in p0], [_r(x) for x in p1]
            walls.append(wc)
            for j in wall.joints:
                s_a, _, _ = wall.to_wall_coords(j.start)
                s_b, _, _ = wall.to_wall_coords(j.end)
                if j.kind == "vertical":
                    if not (vis[0] - 1e-9 <= s_a <= vis[1] + 1e-9):
                        continue
                    start, end = j.start.copy(), j.end.copy()
                else:
                    lo, hi = max(min(s_a, s_b), vis[0]), min(max(s_a, s_b), vis[1])
                    if hi - lo <= 1e-6:
                        continue
                    t = float(j.start[2])
                    start, end = wall.from_wall_coords(lo, t), wall.from_wall_coords(hi, t)
                jc = j.to_contract()
                jc["start"] = [_r(x) for x in self._noisy(start, wall)]
                jc["end"] = [_r(x) for x in self._noisy(end, wall)]
                joints.append(jc)
            for a in wall.areas:
                ac = a.to_contract()
                if self.outcome is not None:
                    ac["finish"] = area_finish(self.outcome, a)
                areas.append(ac)
        out: Dict[str, Any] = {"stamp": float(stamp), "walls": walls, "joints": joints, "areas": areas}
        obstacles = self._obstacles(sensor, heading)
        if obstacles:
            out["obstacles"] = obstacles
        return out

    def _obstacles(self, sensor: np.ndarray, heading: float) -> List[Dict[str, Any]]:
        """The walls that are no work surface seen from ``sensor``: SCAN ``obstacles`` (see the module docstring)."""
        out: List[Dict[str, Any]] = []
        for wall in self.site.walls:
            if wall.material == "plasterboard":
                continue
            if self._visible_s_interval(wall, 0.0, wall.length, sensor, heading) is None:
                continue
            p0, p1 = wall.p0, wall.p1
            if self.noise > 0.0:
                e = self._obstacle_rng.normal(0.0, self.noise, size=4)
                p0 = p0 + e[0] * wall.u[:2] + e[1] * wall.n[:2]
                p1 = p1 + e[2] * wall.u[:2] + e[3] * wall.n[:2]
            out.append({"id": wall.id, "p0": [_r(x) for x in p0], "p1": [_r(x) for x in p1], "height": wall.height})
        return out
