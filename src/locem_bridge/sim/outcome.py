"""Outcome measurement of the wall work: tape per joint, spray thickness map, sanded map, pictures.

:class:`OutcomeRecorder` receives TCP path segments from the world (:meth:`OutcomeRecorder.record`: tool
name, process on/off, segment start/end in map, tool z axis, sim duration) and keeps, per plasterboard wall,
- per joint a 1 cm bin array of laid tape: a bin is taped when the taping tool is on and a TCP sample lies
  on the wall surface (``|d| <= contact_tolerance``) within ``tape_lateral_tolerance`` of the joint line;
- a thickness map (m, cells of ``grid``): while the spray gun sprays (valve open and pressure in range, decided
  by the world) the nozzle's footprint where its z axis meets the wall gets a Gaussian deposit; the footprint
  radius grows with distance (``standoff`` and ``spray_half_angle``), the deposit rate falls with the square of
  the distance and the deposit per pass falls with speed (it is integrated over time);
- a sanded map (bool): sander on and its pad on the surface (``|d| <= contact_tolerance``).
Spray and sand coverage, thickness mean and coefficient of variation count the cells of the wall's work areas
(the areas SCAN reports) outside their holes (the openings and frames inside them); deposits outside them are
overspray and show only in the pictures.
Openings (doors, windows): where a clear opening is there is no wall, so nothing lands there: spray is kept apart
(``sprayed_into_openings_m2``: opening cells reached with at least ``TRACE`` of the target thickness), the sander
sands nothing and tape is not laid. Frames (around an opening, in the wall plane) take what reaches them, but a tool
touching one is a fault: ``sprayed_on_frames_m2`` (at least ``TRACE`` of the target) and ``sanded_on_frames_m2``.
Seams (where a tool process was interrupted inside the work, e.g. by a suspension, and went on later): the pass
maps count how often the spray axis and the tape crossed each point (one count per switching on of the tool); per
joint the longest stretch taped twice (``double_m``) and the longest untaped stretch between taped ones (``gap_m``;
``gaps_at_m``: where the untaped stretches between taped ones lie along the joint, m from its start, the 5 longest);
per spray pass that ended inside a work area (``spray_seams``) the longest stretch never crossed (``gap_m``) and
crossed twice (``double_m``) along the pass's direction that reaches the point where it ended (followed up to
``SEAM_SPAN`` either side), and when it ended (``sim_time``, from the world's clock: match it with the valve's
closing to find a suspension's seam; where the sections of a raster meet, their designed overlap is a seam too).
Operator actions: :meth:`mark_manual_taping` records a joint taped by hand (reported separately).
Planned manual work: HICEM leaves the parts of areas and joints the robot cannot reach to the hand; given them
(``manual`` of :meth:`summary` and :meth:`save_pictures`, checked by :meth:`manual_plan`) the numbers add the
figures on the parts the robot was to work (``*_reachable``, ``reachable``) and the work found deep inside the
manual parts (``manual_touched``: what the robot cannot reach it must not have touched), and the pictures show
the manual parts (violet: joint stretches, hatching over area parts).
Numbers: :meth:`summary`; pictures: :meth:`save_pictures` (one PNG per wall: joints, thickness, sanded; the
openings drawn on all three, a title line and a legend row readable at any wall width: :func:`picture_layout`).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .site import Area, Site, Wall

TAPE_BIN = 0.01          # m, resolution of the tape record along a joint
TAPED_FRACTION = 0.95    # a joint counts as taped from this covered fraction on
PASS_GRID = 0.005        # m, resolution of the pass maps (how often the spray axis / the tape crossed a point)
SEAM_SPAN = 0.25         # m, how far either side of a spray pass's end its seam is followed
SEAM_TOUCH = 0.01        # m, a gap or second coat belongs to the seam when it reaches this close to the pass's end
SEAM_INSIDE = 0.02       # m, a pass ending at least this far inside a work area along its travel is a seam (lane
                         # ends at the area's edges are not; a lane on the edge, along it, is)
SEAM_TOLERANCE = 0.01    # m, how far outside an area's edges a point still counts as on it (and how far into a
                         # hole: a hole's edges are the area's edges too)
TRACE = 0.1              # fraction of the target thickness from which a cell counts as sprayed into an opening or
                         # on a frame
MANUAL_TAPE_EDGE = 0.02  # m, tape laid into a planned manual part of a joint up to this far from the robot's part is
                         # the end of the robot's stretch; farther in, it is work inside the manual part
MANUAL_EDGE = 0.05       # m, how far past the robot's part the edge of its work may reach into a planned manual part
                         # of an area: a spray coat's soft edge (with the shipped lanes the target thickness ends
                         # about 0.05 m past the outermost lane); the sander adds its pad's radius (its centre may
                         # run along the edge of the part it works), the spray gun half its fan's width (the
                         # nozzle stays over the robot's part, the fan's edge reaches past it)
MANUAL_WORKS = ("spray", "sand")


@dataclass
class ManualPlan:
    """The parts of the work planned for the hand (checked by :meth:`OutcomeRecorder.manual_plan`): ``areas``
    ``(work, area id, along0, along1, height0, height1)`` (along from the area's origin, height above the floor,
    m) and ``joints`` ``(joint id, along0, along1)`` (from the joint's start, m)."""
    areas: List[Tuple[str, str, float, float, float, float]]
    joints: List[Tuple[str, float, float]]


class _WallMaps:
    def __init__(self, wall: Wall, grid: float) -> None:
        self.wall = wall
        self.grid = grid
        self.ns = max(1, int(math.ceil(wall.length / grid)))
        self.nt = max(1, int(math.ceil(wall.height / grid)))
        self.thickness = np.zeros((self.nt, self.ns))
        self.sanded = np.zeros((self.nt, self.ns), dtype=bool)
        # cell centres
        self.sc = (np.arange(self.ns) + 0.5) * grid
        self.tc = (np.arange(self.nt) + 0.5) * grid
        # passes of the spray axis over each PASS_GRID cell (a pass: one opening of the valve), and the last pass
        # that counted there: a stretch sprayed twice (a second coat) shows 2, one never crossed 0
        ps, pt = int(math.ceil(wall.length / PASS_GRID)), int(math.ceil(wall.height / PASS_GRID))
        self.passes = np.zeros((pt, ps), dtype=np.int16)
        self._last_pass = np.zeros((pt, ps), dtype=np.int32)
        # the cells to be finished: centres inside one of the wall's areas (what SCAN reports as work), outside
        # its holes (the openings and their frames)
        self.work = np.zeros((self.nt, self.ns), dtype=bool)
        self.area_cells: Dict[str, np.ndarray] = {}       # per area its own work cells
        for a in wall.areas:
            ins = (self.sc >= a.s0) & (self.sc <= a.s0 + a.width)
            int_ = (self.tc >= a.t0) & (self.tc <= a.t0 + a.height)
            cells = int_[:, None] & ins[None, :]
            if a.holes:
                cells &= ~a.in_hole(self.sc[None, :] - a.s0, self.tc[:, None] - a.t0)
            self.area_cells[a.id] = cells
            self.work |= cells
        # openings: cells in a clear opening (no wall: nothing lands there) and on a frame (around it, in the
        # wall plane: takes a deposit, but a tool there is a fault); what the spray put into openings, apart
        s, t = self.sc[None, :], self.tc[:, None]
        self.opening = np.zeros((self.nt, self.ns), dtype=bool)
        outer = np.zeros((self.nt, self.ns), dtype=bool)
        for o in wall.openings:
            a0, a1, b0, b1 = o.outer
            self.opening |= (s > o.s0) & (s < o.s1) & (t >= o.t0) & (t < o.t1)
            outer |= (s > a0) & (s < a1) & (t >= b0) & (t < b1)
        self.frame = outer & ~self.opening
        self.has_openings = bool(self.opening.any())
        self.into_openings = np.zeros((self.nt, self.ns))


class OutcomeRecorder:
    """Accumulates the outcome maps of one run (see the module docstring). Not thread-safe: the world's lock."""

    def __init__(self, site: Site, tools_cfg: Dict[str, Any], outcome_cfg: Dict[str, Any],
                 clock: Optional[Callable[[], float]] = None) -> None:
        self.site = site
        self.clock = clock               # sim time of the world (stamps where spray passes ended)
        self.tools = tools_cfg
        self.grid = float(outcome_cfg["grid"])
        self.lateral_tol = float(outcome_cfg["tape_lateral_tolerance"])
        self.contact_tol = float(outcome_cfg["contact_tolerance"])
        self.spray_rate = float(outcome_cfg["spray_rate"])
        self.target = float(outcome_cfg["spray_target_thickness"])
        self.maps: Dict[str, _WallMaps] = {w.id: _WallMaps(w, self.grid) for w in site.work_walls}
        self.tape: Dict[str, np.ndarray] = {j.id: np.zeros(max(1, int(math.ceil(j.length / TAPE_BIN))), dtype=bool)
                                            for j in site.joints}
        self.manual: set = set()
        self.tape_off_joint = 0.0        # m of tape laid on a wall but not on any joint
        self.spray_time = 0.0
        #: per joint, how many taping passes (one switching on of the tool) laid tape in each TAPE_BIN
        self.tape_passes: Dict[str, np.ndarray] = {j.id: np.zeros(len(b), dtype=np.int16) for j, b in
                                                   ((j, self.tape[j.id]) for j in site.joints)}
        self._tape_last: Dict[str, np.ndarray] = {j: np.zeros(len(b), dtype=np.int32) for j, b in self.tape.items()}
        self._pass = 0                   # counts the switchings on of any tool process
        self._active: Dict[str, bool] = {}
        #: per wall, the last two spray-axis hit points (s, t) of the current pass
        self._axis_hits: Dict[str, List[Any]] = {}
        #: where spray passes ended: (wall id, end (s, t), unit direction (ds, dt) of travel, sim time or None)
        self.spray_pass_ends: List[Any] = []

    # -- recording ---------------------------------------------------------------------------------------------
    def record(self, tool: str, active: bool, p0: np.ndarray, p1: np.ndarray, z_axis: np.ndarray, dt: float) -> None:
        """One TCP segment ``p0 -> p1`` (map) lasting ``dt`` sim seconds with the tool process ``active``."""
        was = self._active.get(tool, False)
        self._active[tool] = active
        if not active:
            if was and tool == "spray_gun":
                self._end_spray_pass()
            return
        if not was:
            self._pass += 1
            self._axis_hits = {}
        if tool == "taping_tool":
            self._tape(p0, p1)
        elif tool == "spray_gun":
            self._spray(p0, p1, np.asarray(z_axis, dtype=float), dt)
        elif tool == "sander":
            self._sand(p0, p1)

    @staticmethod
    def _samples(p0: np.ndarray, p1: np.ndarray, step: float) -> np.ndarray:
        n = max(1, int(math.ceil(float(np.linalg.norm(p1 - p0)) / step)))
        return p0[None, :] + (p1 - p0)[None, :] * (np.arange(1, n + 1) / n)[:, None]

    def _tape(self, p0: np.ndarray, p1: np.ndarray) -> None:
        pts = self._samples(p0, p1, TAPE_BIN / 2)
        seg = float(np.linalg.norm(p1 - p0)) / len(pts)
        for wall in self.site.work_walls:
            for p in pts:
                s, t, d = wall.to_wall_coords(p)
                if abs(d) > self.contact_tol or not (0 <= s <= wall.length and 0 <= t <= wall.height):
                    continue
                if wall.openings and wall.in_opening(s, t):
                    continue                              # no wall to lay it on
                hit = False
                for j in wall.joints:
                    if j.kind == "vertical":
                        js = wall.to_wall_coords(j.start)[0]
                        lateral, along = abs(s - js), t - float(j.start[2])
                    else:
                        lateral, along = abs(t - float(j.start[2])), s - wall.to_wall_coords(j.start)[0]
                    if lateral <= self.lateral_tol and 0 <= along <= j.length:
                        bins = self.tape[j.id]
                        k = min(len(bins) - 1, int(along / TAPE_BIN))
                        bins[k] = True
                        if self._tape_last[j.id][k] != self._pass:
                            self._tape_last[j.id][k] = self._pass
                            self.tape_passes[j.id][k] += 1
                        hit = True
                if not hit:
                    self.tape_off_joint += seg

    def _spray(self, p0: np.ndarray, p1: np.ndarray, z: np.ndarray, dt: float) -> None:
        cfg = self.tools["spray_gun"]
        half = float(cfg["spray_half_angle"])
        standoff = float(cfg["standoff"])
        self.spray_time += dt
        for m in self.maps.values():
            wall = m.wall
            cos_in = -float(z @ wall.n)
            if cos_in <= 0.05:
                continue                                  # not pointing at this wall
            r_nom = standoff * math.tan(half)
            self._mark_axis(m, p0, p1, z, cos_in)
            pts = self._samples(p0, p1, max(self.grid, r_nom / 4))
            h = dt / len(pts)
            for p in pts:
                s, t, d = wall.to_wall_coords(p)
                if d <= 0.0:
                    continue
                dist = d / cos_in                          # along the spray axis to the wall
                hit = p + dist * z
                hs, ht, _ = wall.to_wall_coords(hit)
                radius = dist * math.tan(half)
                if hs < -radius or hs > wall.length + radius or ht < -radius or ht > wall.height + radius:
                    continue
                sigma = radius / 2.0
                rate = self.spray_rate * (standoff / max(dist, 0.02)) ** 2
                i0, i1 = max(0, int((hs - radius) / m.grid)), min(m.ns, int((hs + radius) / m.grid) + 1)
                k0, k1 = max(0, int((ht - radius) / m.grid)), min(m.nt, int((ht + radius) / m.grid) + 1)
                if i0 >= i1 or k0 >= k1:
                    continue
                ds = m.sc[i0:i1][None, :] - hs
                dtt = m.tc[k0:k1][:, None] - ht
                r2 = ds * ds + dtt * dtt
                dep = rate * h * np.exp(-r2 / (2 * sigma * sigma))
                dep[r2 > radius * radius] = 0.0
                if m.has_openings:                         # into a clear opening: kept apart, no wall there
                    op = m.opening[k0:k1, i0:i1]
                    m.into_openings[k0:k1, i0:i1] += np.where(op, dep, 0.0)
                    dep[op] = 0.0
                m.thickness[k0:k1, i0:i1] += dep

    def _mark_axis(self, m: _WallMaps, p0: np.ndarray, p1: np.ndarray, z: np.ndarray, cos_in: float) -> None:
        """The spray axis' hit points from ``p0`` to ``p1`` into the pass map (one count per pass and cell)."""
        wall = m.wall
        hits = []
        for p in (p0, p1):
            d = wall.to_wall_coords(p)[2]
            if d <= 0.0:
                return
            hits.append(wall.to_wall_coords(p + (d / cos_in) * z)[:2])
        (s0, t0), (s1, t1) = hits
        if math.hypot(s1 - s0, t1 - t0) > 1e-4:
            self._axis_hits[wall.id] = [(float(s0), float(t0)), (float(s1), float(t1))]
        n = max(1, int(math.ceil(math.hypot(s1 - s0, t1 - t0) / (PASS_GRID / 2))))
        f = np.arange(0, n + 1) / n
        ci = ((s0 + (s1 - s0) * f) / PASS_GRID).astype(int)
        ck = ((t0 + (t1 - t0) * f) / PASS_GRID).astype(int)
        ok = (ci >= 0) & (ci < m.passes.shape[1]) & (ck >= 0) & (ck < m.passes.shape[0])
        for i, k in zip(ci[ok], ck[ok]):
            if m._last_pass[k, i] != self._pass:
                m._last_pass[k, i] = self._pass
                m.passes[k, i] += 1

    def _end_spray_pass(self) -> None:
        for wid, ((s0, t0), (s1, t1)) in self._axis_hits.items():
            d = math.hypot(s1 - s0, t1 - t0)
            self.spray_pass_ends.append((wid, (s1, t1), ((s1 - s0) / d, (t1 - t0) / d),
                                         None if self.clock is None else float(self.clock())))
        self._axis_hits = {}

    def _seam(self, wall_id: str, end: Any, direction: Any, stamp: Optional[float]) -> Any:
        """The seam at a spray pass's end, or None unless the pass crossed a work area for SEAM_INSIDE on both
        sides of its end (along ``direction``): the longest run never crossed and crossed twice (m) along
        ``direction`` within SEAM_SPAN of ``end``, on the area; each sample takes the most passes across the track
        (one cell either side). Where sections of a raster meet, their designed overlap shows as a second coat."""
        m = self.maps[wall_id]
        s, t = end
        ds, dt = direction

        def inside(a: Area, ps: float, pt: float) -> bool:
            return bool(_on_area(a, np.array([ps]), np.array([pt]))[0])
        area = next((a for a in m.wall.areas if inside(a, s - SEAM_INSIDE * ds, t - SEAM_INSIDE * dt) and
                     inside(a, s + SEAM_INSIDE * ds, t + SEAM_INSIDE * dt)), None)
        if area is None:
            return None
        step = PASS_GRID / 2
        us = np.arange(-SEAM_SPAN, SEAM_SPAN + step / 2, step)
        ps, pt = s + us * ds, t + us * dt
        on = _on_area(area, ps, pt)
        best = np.zeros(len(us), dtype=int)
        nk, ni = m.passes.shape
        for w in (-1.0, 0.0, 1.0):                  # across the track: perpendicular to the direction
            i = ((ps - w * PASS_GRID * dt) / PASS_GRID).astype(int)
            k = ((pt + w * PASS_GRID * ds) / PASS_GRID).astype(int)
            ok = (i >= 0) & (i < ni) & (k >= 0) & (k < nk)
            best[ok] = np.maximum(best[ok], m.passes[k[ok], i[ok]])
        counts, at = best[on], (np.abs(us) <= SEAM_TOUCH)[on]
        return {"wall": wall_id, "area": area.id, "s": round(s, 4), "t": round(t, 4),
                "sim_time": None if stamp is None else round(stamp, 3),
                "gap_m": round(_touching_run(list(counts == 0), list(at)) * step, 4),
                "double_m": round(_touching_run(list(counts >= 2), list(at)) * step, 4)}

    def _sand(self, p0: np.ndarray, p1: np.ndarray) -> None:
        rad = float(self.tools["sander"]["pad_radius"])
        for m in self.maps.values():
            wall = m.wall
            for p in self._samples(p0, p1, max(self.grid, rad / 4)):
                s, t, d = wall.to_wall_coords(p)
                if abs(d) > self.contact_tol:
                    continue
                i0, i1 = max(0, int((s - rad) / m.grid)), min(m.ns, int((s + rad) / m.grid) + 1)
                k0, k1 = max(0, int((t - rad) / m.grid)), min(m.nt, int((t + rad) / m.grid) + 1)
                if i0 >= i1 or k0 >= k1:
                    continue
                r2 = (m.sc[i0:i1][None, :] - s) ** 2 + (m.tc[k0:k1][:, None] - t) ** 2
                pad = r2 <= rad * rad
                if m.has_openings:
                    pad &= ~m.opening[k0:k1, i0:i1]      # nothing to sand in a clear opening
                m.sanded[k0:k1, i0:i1] |= pad

    def mark_manual_taping(self, joint_id: str) -> None:
        """The operator taped ``joint_id`` by hand."""
        if joint_id not in self.tape:
            raise KeyError("unknown joint %r, known: %s" % (joint_id, ", ".join(sorted(self.tape))))
        self.manual.add(joint_id)

    # -- planned manual work -----------------------------------------------------------------------------------
    def manual_plan(self, manual: Optional[Dict[str, Any]] = None) -> ManualPlan:
        """Check the planned manual parts ``{"areas": [{"work": "spray"|"sand", "area": id, "along": [a, b],
        "height": [c, d]}], "joints": [{"joint": id, "along": [a, b]}]}`` (both lists optional, other keys of an
        entry ignored; None: none) against the site; a ValueError says what is wrong and what is allowed."""
        if manual is None:
            return ManualPlan([], [])
        if not isinstance(manual, dict):
            raise ValueError('manual must be an object {"areas": [...], "joints": [...]}, got %s'
                             % type(manual).__name__)
        extra = sorted(set(manual) - {"areas", "joints"})
        if extra:
            raise ValueError("manual: unknown key(s) %s; allowed: areas, joints" % ", ".join(map(repr, extra)))
        areas = {a.id: a for m in self.maps.values() for a in m.wall.areas}
        joints = {j.id: j for j in self.site.joints if j.id in self.tape}
        plan = ManualPlan([], [])
        for key, shape in (("areas", "{work, area, along, height}"), ("joints", "{joint, along}")):
            items = manual.get(key) or []
            if not isinstance(items, list):
                raise ValueError("manual.%s must be a list of %s, got %s" % (key, shape, type(items).__name__))
            for i, item in enumerate(items):
                where = "manual.%s[%d]" % (key, i)
                if not isinstance(item, dict):
                    raise ValueError("%s must be an object %s, got %r" % (where, shape, item))
                missing = [k for k in shape.strip("{}").split(", ") if k not in item]
                if missing:
                    raise ValueError("%s misses %s (an entry is %s)" % (where, ", ".join(missing), shape))
                if key == "areas":
                    if item["work"] not in MANUAL_WORKS:
                        raise ValueError("%s.work %r is not one of %s" % (where, item["work"], ", ".join(MANUAL_WORKS)))
                    if item["area"] not in areas:
                        raise ValueError("%s.area %r is not an area of this site; known: %s"
                                         % (where, item["area"], ", ".join(sorted(areas))))
                    a0, a1 = _span(where + ".along", item["along"], "metres along the area from its origin")
                    h0, h1 = _span(where + ".height", item["height"], "metres above the floor")
                    plan.areas.append((str(item["work"]), str(item["area"]), a0, a1, h0, h1))
                else:
                    if item["joint"] not in joints:
                        raise ValueError("%s.joint %r is not a joint of this site; known: %s"
                                         % (where, item["joint"], ", ".join(sorted(joints))))
                    a0, a1 = _span(where + ".along", item["along"], "metres from the joint's start")
                    plan.joints.append((str(item["joint"]), a0, a1))
        return plan

    def _manual_bins(self, joint_id: str, plan: ManualPlan) -> np.ndarray:
        """Per TAPE_BIN of the joint: whether its centre lies in a planned manual part."""
        n = len(self.tape[joint_id])
        centres = (np.arange(n) + 0.5) * TAPE_BIN
        out = np.zeros(n, dtype=bool)
        for jid, a0, a1 in plan.joints:
            if jid == joint_id:
                out |= (centres >= a0) & (centres <= a1)
        return out

    def _manual_cells(self, m: _WallMaps, work: str, plan: ManualPlan) -> np.ndarray:
        """The work cells of wall map ``m`` inside a planned manual part of ``work``."""
        out = np.zeros((m.nt, m.ns), dtype=bool)
        for w, area_id, a0, a1, h0, h1 in plan.areas:
            if w != work or area_id not in m.area_cells:
                continue
            area = next(a for a in m.wall.areas if a.id == area_id)
            ins = (m.sc >= area.s0 + a0) & (m.sc <= area.s0 + a1)
            int_ = (m.tc >= h0) & (m.tc <= h1)
            out |= int_[:, None] & ins[None, :] & m.area_cells[area_id]
        return out

    def _manual_edge(self, work: str) -> float:
        """How far into a planned manual part of ``work`` the robot's work on its part may reach (m)."""
        if work == "sand":
            return MANUAL_EDGE + float(self.tools["sander"]["pad_radius"])
        gun = self.tools.get("spray_gun", {})
        # the nozzle stays over the robot's part, but its fan reaches half its width past the lanes' ends
        return MANUAL_EDGE + float(gun.get("standoff", 0.0)) * math.tan(float(gun.get("spray_half_angle", 0.0)))

    # -- numbers -----------------------------------------------------------------------------------------------
    def joint_coverage(self, joint_id: str) -> float:
        bins = self.tape[joint_id]
        return float(bins.mean())

    def summary(self, manual: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
        """Numbers of the run: per joint, per wall and totals (fractions 0..1, thickness in m); per wall and in
        total the faults at openings (m2): ``sprayed_into_openings_m2``, ``sprayed_on_frames_m2``,
        ``sanded_on_frames_m2`` (0.0 on a wall without openings).

        ``manual``: the parts planned for the hand (:meth:`manual_plan`). The figures on the parts the robot was
        to work: per joint ``manual_m`` (m left manual) and ``coverage_reachable`` (over the TAPE_BINs outside
        its manual parts; None when the whole joint is manual); per wall ``spray_coverage_reachable``,
        ``sand_coverage_reachable``, ``thickness_cv_reachable`` (over the work cells outside that work's manual
        parts; None when the wall has work cells but all of them are manual), ``spray_manual_m2`` and
        ``sand_manual_m2``; in total ``reachable`` (``tape_coverage_min`` and ``tape_coverage``: min and mean
        over the joints with a part for the robot and not taped by hand, None when there is none;
        ``spray_coverage``, ``sand_coverage``; ``spray_thickness_cv``: the largest of the walls') and
        ``manual_touched``: work done deep inside the manual parts, where the robot cannot reach -- ``tape_m``
        laid more than MANUAL_TAPE_EDGE from the robot's part of the joint, ``spray_m2`` (at least the target
        thickness) and ``sand_m2`` more than the tool's edge (:data:`MANUAL_EDGE`, the sander plus its pad's
        radius) from the robot's part of the work. Without manual parts each reachable figure equals the plain
        one (the tape figures leave out the joints taped by hand)."""
        plan = self.manual_plan(manual)
        joints = {}
        touched_tape = 0
        for jid, bins in self.tape.items():
            weight = _bin_lengths(self.site.joint(jid).length, len(bins))
            cov = _weighted(bins, weight)
            taped = np.flatnonzero(bins)
            inner = bins[taped[0]:taped[-1] + 1] if taped.size else bins[:0]
            planned = self._manual_bins(jid, plan)
            robot = ~planned
            deep = planned & ~_dilate(robot[None, :], MANUAL_TAPE_EDGE / TAPE_BIN)[0]
            touched_tape += int((bins & deep).sum())
            # the planned ends come from the scan (mm of noise): the bins within MANUAL_TAPE_EDGE of a manual part
            # count neither way
            counted = robot & ~_dilate(planned[None, :], MANUAL_TAPE_EDGE / TAPE_BIN)[0] if planned.any() else robot
            length = self.site.joint(jid).length
            joints[jid] = {"coverage": cov, "taped": cov >= TAPED_FRACTION, "manual": jid in self.manual,
                           "double_m": round(_longest_run(self.tape_passes[jid] >= 2) * TAPE_BIN, 4),
                           "gap_m": round(_longest_run(~inner) * TAPE_BIN, 4),
                           "gaps_at_m": _runs_at(~inner, (taped[0] if taped.size else 0) * TAPE_BIN),
                           "manual_m": round(_union_length([(a, b) for j, a, b in plan.joints if j == jid],
                                                           0.0, length), 4),
                           "coverage_reachable": _weighted(bins[counted], weight[counted]) if counted.any()
                           else None}
        seams = [x for x in (self._seam(*e) for e in self.spray_pass_ends) if x is not None]
        walls = {}
        total_cells = covered_cells = sanded_cells = 0
        reach_cells = {"spray": 0, "sand": 0}
        reach_done = {"spray": 0, "sand": 0}
        touched = {"spray": 0.0, "sand": 0.0}
        fault_totals = {"sprayed_into_openings_m2": 0.0, "sprayed_on_frames_m2": 0.0, "sanded_on_frames_m2": 0.0}
        for wid, m in self.maps.items():
            # coverage and uniformity over the wall's work areas (cells outside them are overspray)
            cells = int(m.work.sum())
            covered = (m.thickness >= self.target) & m.work
            vals = m.thickness[covered]
            cv = _cv(vals)
            sanded = m.sanded & m.work
            cell_m2 = m.grid * m.grid
            trace = TRACE * self.target
            faults = {"sprayed_into_openings_m2": round(int((m.into_openings >= trace).sum()) * cell_m2, 6),
                      "sprayed_on_frames_m2": round(int(((m.thickness >= trace) & m.frame).sum()) * cell_m2, 6),
                      "sanded_on_frames_m2": round(int((m.sanded & m.frame).sum()) * cell_m2, 6)}
            walls[wid] = {"spray_coverage": float(covered.sum()) / cells if cells else 0.0,
                          "thickness_mean": float(vals.mean()) if vals.size else 0.0,
                          "thickness_cv": cv, "thickness_max": float(m.thickness.max()),
                          "sand_coverage": float(sanded.sum()) / cells if cells else 0.0,
                          "work_area_m2": cells * cell_m2}
            walls[wid].update(faults)
            # the same on the cells the robot was to work (outside the work's planned manual parts)
            for work, done in (("spray", covered), ("sand", sanded)):
                planned = self._manual_cells(m, work, plan)
                robot = m.work & ~planned
                n_robot = int(robot.sum())
                walls[wid]["%s_coverage_reachable" % work] = (float((done & robot).sum()) / n_robot if n_robot else
                                                              None if cells else 0.0)
                walls[wid]["%s_manual_m2" % work] = round(int(planned.sum()) * cell_m2, 6)
                if work == "spray":
                    walls[wid]["thickness_cv_reachable"] = (_cv(m.thickness[covered & robot]) if n_robot else
                                                            None if cells else 0.0)
                deep = planned & ~_dilate(robot, self._manual_edge(work) / m.grid)
                touched[work] += int((done & deep).sum()) * cell_m2
                reach_cells[work] += n_robot
                reach_done[work] += int((done & robot).sum())
            for k, v in faults.items():
                fault_totals[k] += v
            total_cells += cells
            covered_cells += int(covered.sum())
            sanded_cells += int(sanded.sum())
        n = len(joints)
        taped = sum(1 for j in joints.values() if j["taped"])
        robot_cov = [j["coverage_reachable"] for j in joints.values()
                     if j["coverage_reachable"] is not None and not j["manual"]]
        cvs = [w["thickness_cv_reachable"] for w in walls.values() if w["thickness_cv_reachable"] is not None]

        def reach_fraction(work: str) -> Optional[float]:
            if reach_cells[work]:
                return reach_done[work] / reach_cells[work]
            return None if total_cells else 0.0
        return {
            "joints_total": n,
            "joints_taped": taped,
            "joints_manual": sum(1 for j in joints.values() if j["manual"] and not j["taped"]),
            "tape_coverage": float(np.mean([j["coverage"] for j in joints.values()])) if n else 0.0,
            "tape_off_joint_m": self.tape_off_joint,
            "spray_coverage": covered_cells / total_cells if total_cells else 0.0,
            "sand_coverage": sanded_cells / total_cells if total_cells else 0.0,
            "sprayed_into_openings_m2": round(fault_totals["sprayed_into_openings_m2"], 6),
            "sprayed_on_frames_m2": round(fault_totals["sprayed_on_frames_m2"], 6),
            "sanded_on_frames_m2": round(fault_totals["sanded_on_frames_m2"], 6),
            "joints": joints,
            "walls": walls,
            "spray_seams": seams,
            "reachable": {"tape_coverage_min": min(robot_cov) if robot_cov else (None if n else 0.0),
                          "tape_coverage": float(np.mean(robot_cov)) if robot_cov else (None if n else 0.0),
                          "spray_coverage": reach_fraction("spray"), "sand_coverage": reach_fraction("sand"),
                          "spray_thickness_cv": max(cvs) if cvs else 0.0},
            "manual_touched": {"tape_m": round(touched_tape * TAPE_BIN, 4), "spray_m2": round(touched["spray"], 6),
                               "sand_m2": round(touched["sand"], 6)},
        }

    # -- pictures ----------------------------------------------------------------------------------------------
    def picture_layout(self, wall_id: str, px_per_m: float = 100.0,
                       manual: Optional[Dict[str, Any]] = None) -> "PictureLayout":
        """Where :meth:`save_pictures` puts the panels, texts and legend of wall ``wall_id``'s picture (with the
        planned manual parts ``manual``, see :meth:`manual_plan`)."""
        wall = self.maps[wall_id].wall
        return picture_layout(_title(wall), PANEL_LABELS, self._legend(wall, self.manual_plan(manual)),
                              *_wall_px(wall, px_per_m))

    def _legend(self, wall: Wall, plan: ManualPlan) -> List[Tuple[str, str]]:
        """The legend items (key, text) of ``wall``'s picture: the joint states shown on it, the scales, the
        outlines, the planned manual parts and the openings if it has any."""
        bins = [(self.tape[j.id], j.id in self.manual, self._manual_bins(j.id, plan)) for j in wall.joints]
        items = [(key, text) for key, text, shown in (
            ("taped", "taped", any(b.any() for b, _, _ in bins)),
            ("manual", "taped by hand", any(manual and not b.all() for b, manual, _ in bins)),
            ("open", "open joint", any(not manual and (~b & ~planned).any() for b, manual, planned in bins))) if shown]
        items += [("thickness", "spray 0 .. %.1f mm" % (2000.0 * self.target)), ("sanded", "sanded"),
                  ("area", "work area and its holes")]
        if any(p.any() for _, _, p in bins) or any(self._planned_rects(wall, work, plan) for work in MANUAL_WORKS):
            items += [("planned", "manual (planned)")]
        if wall.openings:
            items += [("opening", "opening (door: leaf arc, window: cross)"), ("frame", "frame")]
        return items

    def _planned_rects(self, wall: Wall, work: str, plan: ManualPlan) -> List[Tuple[float, float, float, float]]:
        """The planned manual parts of ``work`` on ``wall`` as wall rectangles (s0, s1, t0, t1), cut to their
        area."""
        out = []
        areas = {a.id: a for a in wall.areas}
        for w, area_id, a0, a1, h0, h1 in plan.areas:
            a = areas.get(area_id)
            if w != work or a is None:
                continue
            s0, s1 = max(a.s0, a.s0 + a0), min(a.s0 + a.width, a.s0 + a1)
            t0, t1 = max(a.t0, h0), min(a.t0 + a.height, h1)
            if s1 > s0 and t1 > t0:
                out.append((s0, s1, t0, t1))
        return out

    def save_pictures(self, folder: str, px_per_m: float = 100.0,
                      manual: Optional[Dict[str, Any]] = None) -> List[str]:
        """Write ``<wall>.png`` per plasterboard wall: a title line (wall, size, openings), three panels -- joints
        (green taped, blue manual, red open, violet planned manual and not taped), spray thickness (white 0 ->
        dark blue at 2x target), sanded area (brown) -- with the openings (dark grey, frame outlined brown) on
        each, the work areas with their holes outlined and the planned manual parts of that work (``manual``, see
        :meth:`manual_plan`) hatched violet on the last two, and a legend row below (:meth:`picture_layout`);
        returns the file paths."""
        from PIL import Image, ImageDraw

        os.makedirs(folder, exist_ok=True)
        font = _default_font()
        plan = self.manual_plan(manual)
        out = []
        for wid, m in self.maps.items():
            wall = m.wall
            lay = self.picture_layout(wid, px_per_m, manual)
            w_px, h_px = _wall_px(wall, px_per_m)
            img = Image.new("RGB", lay.size, WHITE)
            dr = ImageDraw.Draw(img)
            xs = [p[0] for p in lay.panels]
            y0 = lay.panels[0][1]

            def to_px(s: float, t: float, x_off: int) -> Tuple[float, float]:
                return (x_off + s * px_per_m, y0 + h_px - t * px_per_m)
            # panel 1: joints
            dr.rectangle([xs[0], y0, xs[0] + w_px, y0 + h_px], fill=BOARD, outline=BLACK)
            jw = max(2, int(0.05 * px_per_m))
            for j in wall.joints:
                bins = self.tape[j.id]
                planned = self._manual_bins(j.id, plan)
                s0 = wall.to_wall_coords(j.start)[0]
                t0 = float(j.start[2])
                for b, done in enumerate(bins):
                    a, e = b * TAPE_BIN, min(j.length, (b + 1) * TAPE_BIN)
                    color = TAPED if done else (MANUAL if j.id in self.manual else PLANNED if planned[b] else OPEN)
                    if j.kind == "vertical":
                        p, q = to_px(s0, t0 + a, xs[0]), to_px(s0, t0 + e, xs[0])
                    else:
                        p, q = to_px(s0 + a, t0, xs[0]), to_px(s0 + e, t0, xs[0])
                    dr.line([p, q], fill=color, width=jw)
            # panel 2: thickness, panel 3: sanded (maps of whole cells, cut to the wall at its foot)
            norm = np.clip(m.thickness / (2.0 * self.target), 0.0, 1.0)
            for k, rgb in ((1, _thickness_rgb(norm)),
                           (2, np.where(m.sanded[..., None], np.array(SANDED, dtype=np.uint8),
                                        np.array(BOARD, dtype=np.uint8)).astype(np.uint8))):
                full_w = max(w_px, int(round(m.ns * m.grid * px_per_m)))
                full_h = max(h_px, int(round(m.nt * m.grid * px_per_m)))
                pic = Image.fromarray(rgb[::-1]).resize((full_w, full_h), Image.NEAREST)
                img.paste(pic.crop((0, full_h - h_px, w_px, full_h)), (xs[k], y0))
                dr.rectangle([xs[k], y0, xs[k] + w_px, y0 + h_px], outline=BLACK)
                for r0, r1, u0, u1 in self._planned_rects(wall, MANUAL_WORKS[k - 1], plan):
                    (hx0, hy0), (hx1, hy1) = to_px(r0, u1, xs[k]), to_px(r1, u0, xs[k])
                    _hatch(dr, int(round(hx0)), int(round(hy0)), int(round(hx1)), int(round(hy1)), PLANNED)
            for k in range(3):   # the openings on every panel
                for o in wall.openings:
                    a0, a1, b0, b1 = o.outer
                    p, q = to_px(o.s0, o.t1, xs[k]), to_px(o.s1, o.t0, xs[k])
                    dr.rectangle([p, q], fill=OPENING)
                    if o.kind == "window":
                        dr.line([p, q], fill=OPENING_MARK)
                        dr.line([(p[0], q[1]), (q[0], p[1])], fill=OPENING_MARK)
                    else:                                   # the leaf swinging open from its hinge at s0
                        r = min(q[0] - p[0], q[1] - p[1])
                        dr.arc([p[0] - r, q[1] - r, p[0] + r, q[1] + r], 270, 360, fill=OPENING_MARK)
                        dr.line([(p[0], q[1]), (p[0] + r * math.sqrt(0.5), q[1] - r * math.sqrt(0.5))],
                                fill=OPENING_MARK)
                    dr.rectangle([to_px(a0, b1, xs[k]), to_px(a1, b0, xs[k])], outline=FRAME, width=2)
            for k in (1, 2):     # the work areas and their holes, outlined
                for a in wall.areas:
                    rects = [(a.s0, a.s0 + a.width, a.t0, a.t0 + a.height)]
                    rects += [(a.s0 + h0, a.s0 + h1, a.t0 + v0, a.t0 + v1) for h0, h1, v0, v1 in a.holes]
                    for r0, r1, u0, u1 in rects:
                        dr.rectangle([to_px(r0, u1, xs[k]), to_px(r1, u0, xs[k])], outline=AREA)
            for t in lay.texts:
                dr.text(t.xy, t.text, fill=BLACK, font=font)
            for key, (bx0, by0, bx1, by1) in lay.swatches:
                _swatch(dr, key, bx0, by0, bx1, by1)
            path = os.path.join(folder, "%s.png" % wid)
            img.save(path)
            out.append(path)
        return out


WHITE, BLACK, BOARD = (255, 255, 255), (0, 0, 0), (235, 235, 225)
TAPED, MANUAL, OPEN = (30, 160, 60), (40, 90, 220), (210, 40, 40)
PLANNED = (160, 40, 190)  # planned manual work: joint stretches, hatching over area parts
HATCH_PX = 7              # px, spacing of the hatching
SANDED, AREA = (150, 100, 50), (200, 120, 0)
OPENING, OPENING_MARK, FRAME = (70, 70, 70), (150, 150, 150), (110, 60, 15)
PANEL_LABELS = ("joints", "spray thickness", "sanded")
MIN_PANEL_PX = 160       # px, narrowest panel column (a narrower wall drawing is centred in it)
PIC_PAD = 10             # px, margin around the picture and between the panel columns
PIC_GAP = 6              # px, between the title, the labels, the panels and the legend
SWATCH = (16, 10)        # px, a legend swatch


@dataclass
class PlacedText:
    """One line of text in a picture: ``role`` (``title``, ``label<panel>``, ``legend``), where it is drawn
    (``xy``, PIL's default anchor) and the box it covers (x0, y0, x1, y1; px)."""
    role: str
    xy: Tuple[int, int]
    text: str
    box: Tuple[int, int, int, int]


@dataclass
class PictureLayout:
    """A wall picture's layout (px): its ``size``, the x range of each panel's column, the box of the wall
    drawing in each panel (x0, y0, x1, y1: the wall's s = 0 at x0, its foot at y1), the text lines and the legend
    swatches (key, box)."""
    size: Tuple[int, int]
    columns: List[Tuple[int, int]]
    panels: List[Tuple[int, int, int, int]]
    texts: List[PlacedText]
    swatches: List[Tuple[str, Tuple[int, int, int, int]]]


def picture_layout(title: str, labels: Sequence[str], legend: Sequence[Tuple[str, str]], w_px: int, h_px: int,
                   font: Any = None) -> PictureLayout:
    """Lay out a picture of three panels of a ``w_px`` x ``h_px`` wall drawing: the ``title`` across the picture,
    each of the three ``labels`` above its panel, the ``legend`` items (key, text) flowing in rows below the
    panels; text is wrapped to the width it has (measured with ``font``, default PIL's default font), a panel
    column is at least MIN_PANEL_PX wide."""
    from PIL import Image, ImageDraw

    dr = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    font = font or _default_font()

    def box(xy: Tuple[int, int], text: str) -> Tuple[int, int, int, int]:
        if hasattr(dr, "textbbox"):
            b = dr.textbbox(xy, text, font=font)
            return (int(math.floor(b[0])), int(math.floor(b[1])), int(math.ceil(b[2])), int(math.ceil(b[3])))
        w, h = font.getsize(text)                          # Pillow < 8
        return (xy[0], xy[1], xy[0] + w, xy[1] + h)

    def width(text: str) -> int:
        b = box((0, 0), text)
        return b[2] - min(0, b[0])

    ref = box((0, 0), "Ag")
    line_h = ref[3] - min(0, ref[1]) + 3
    y_off = max(0, -ref[1])                                 # a font drawing above its anchor
    texts: List[PlacedText] = []

    def put(role: str, x: int, y: int, text: str) -> None:
        xy = (x - min(0, box((0, 0), text)[0]), y + y_off)      # a glyph reaching left of its anchor
        texts.append(PlacedText(role, xy, text, box(xy, text)))

    cell_w = max(int(w_px), MIN_PANEL_PX)
    size_w = 4 * PIC_PAD + 3 * cell_w
    y = PIC_PAD
    for line in _wrap(width, title, size_w - 2 * PIC_PAD):
        put("title", PIC_PAD, y, line)
        y += line_h
    y += PIC_GAP
    columns = [(PIC_PAD + k * (cell_w + PIC_PAD), PIC_PAD + k * (cell_w + PIC_PAD) + cell_w) for k in range(3)]
    rows = 0
    for k, label in enumerate(labels):
        lines = _wrap(width, label, cell_w)
        for i, line in enumerate(lines):
            put("label%d" % k, columns[k][0], y + i * line_h, line)
        rows = max(rows, len(lines))
    y += rows * line_h + PIC_GAP // 2
    panels = [(x0 + (cell_w - w_px) // 2, y, x0 + (cell_w - w_px) // 2 + w_px, y + h_px) for x0, _ in columns]
    y += h_px + 2 * PIC_GAP
    swatches: List[Tuple[str, Tuple[int, int, int, int]]] = []
    left, right = PIC_PAD, size_w - PIC_PAD
    x = left
    for key, text in legend:
        if x > left and x + SWATCH[0] + 4 + width(text) > right:
            x, y = left, y + line_h
        sy = y + (line_h - SWATCH[1]) // 2
        swatches.append((key, (x, sy, x + SWATCH[0], sy + SWATCH[1])))
        tx = x + SWATCH[0] + 4
        lines = _wrap(width, text, right - tx)
        for i, line in enumerate(lines):
            put("legend", tx, y + i * line_h, line)
        y += (len(lines) - 1) * line_h
        x = right if len(lines) > 1 else tx + width(text) + 12
    y += line_h
    return PictureLayout((size_w, y + PIC_PAD), columns, panels, texts, swatches)


def _wrap(width: Callable[[str], int], text: str, room: int) -> List[str]:
    """``text`` in lines no wider than ``room`` px (by words; a word too long alone is cut)."""
    lines: List[str] = []
    line = ""
    for word in text.split():
        cand = line + " " + word if line else word
        if width(cand) <= room:
            line = cand
            continue
        if line:
            lines.append(line)
        while len(word) > 1 and width(word) > room:
            k = max(1, max((n for n in range(1, len(word)) if width(word[:n]) <= room), default=1))
            lines.append(word[:k])
            word = word[k:]
        line = word
    if line:
        lines.append(line)
    return lines


_FONT: List[Any] = []


def _default_font() -> Any:
    """PIL's default font (one instance: layout and drawing measure alike)."""
    if not _FONT:
        from PIL import ImageFont
        _FONT.append(ImageFont.load_default())
    return _FONT[0]


def _wall_px(wall: Wall, px_per_m: float) -> Tuple[int, int]:
    return max(1, int(wall.length * px_per_m)), max(1, int(wall.height * px_per_m))


def _title(wall: Wall) -> str:
    out = "%s: %.2f m long, %.2f m high" % (wall.id, wall.length, wall.height)
    if wall.openings:
        out += "; openings: " + ", ".join("%s (%s %.2f x %.2f m)" % (o.id, o.kind, o.s1 - o.s0, o.t1 - o.t0)
                                          for o in wall.openings)
    return out


def _thickness_rgb(norm: np.ndarray) -> np.ndarray:
    """White (0) to dark blue (1) for a thickness normalised to 2x the target."""
    return np.stack([255 * (1 - norm), 255 * (1 - 0.7 * norm), 255 - 90 * norm], axis=-1).astype(np.uint8)


def _swatch(dr: Any, key: str, x0: int, y0: int, x1: int, y1: int) -> None:
    """A legend swatch for ``key`` in the box (x0, y0, x1, y1)."""
    fills = {"taped": TAPED, "manual": MANUAL, "open": OPEN, "sanded": SANDED, "opening": OPENING}
    if key in fills:
        dr.rectangle([x0, y0, x1, y1], fill=fills[key], outline=BLACK if key == "sanded" else None)
    elif key == "thickness":
        ramp = _thickness_rgb(np.linspace(0.0, 1.0, x1 - x0 + 1))
        for i, c in enumerate(ramp):
            dr.line([(x0 + i, y0), (x0 + i, y1)], fill=tuple(int(v) for v in c))
        dr.rectangle([x0, y0, x1, y1], outline=BLACK)
    elif key == "area":
        dr.rectangle([x0, y0, x1, y1], outline=AREA)
    elif key == "frame":
        dr.rectangle([x0, y0, x1, y1], outline=FRAME, width=2)
    elif key == "planned":
        _hatch(dr, x0, y0, x1, y1, PLANNED, step=5)


def _hatch(dr: Any, x0: int, y0: int, x1: int, y1: int, color: Tuple[int, int, int], step: int = HATCH_PX) -> None:
    """The box (x0, y0, x1, y1) outlined and hatched with diagonal lines in ``color`` (what is under the hatching
    shows between its lines)."""
    w, h = x1 - x0, y1 - y0
    for d in range(-h, w + 1, step):          # lines rising to the right from (x0 + d, y1)
        t0, t1 = max(0, -d), min(h, w - d)
        if t1 > t0:
            dr.line([(x0 + d + t0, y1 - t0), (x0 + d + t1, y1 - t1)], fill=color)
    dr.rectangle([x0, y0, x1, y1], outline=color)


def _on_area(a: Area, ps: np.ndarray, pt: np.ndarray) -> np.ndarray:
    """Whether the wall points ``(ps, pt)`` lie on area ``a`` to within SEAM_TOLERANCE of its edges, a hole's
    edges included (a point in a hole farther than that from its edges is off the area)."""
    tol = SEAM_TOLERANCE
    on = (ps >= a.s0 - tol) & (ps <= a.s0 + a.width + tol) & (pt >= a.t0 - tol) & (pt <= a.t0 + a.height + tol)
    for h0, h1, v0, v1 in a.holes:
        on &= ~((ps > a.s0 + h0 + tol) & (ps < a.s0 + h1 - tol) & (pt > a.t0 + v0 + tol) & (pt < a.t0 + v1 - tol))
    return on


def _touching_run(flags: List[bool], at: List[bool]) -> int:
    """Length of the longest run of true ``flags`` that includes an index where ``at`` is true (0: none)."""
    best = n = 0
    touches = False
    for f, a in list(zip(flags, at)) + [(False, False)]:
        if f:
            n += 1
            touches = touches or a
        else:
            if touches:
                best = max(best, n)
            n, touches = 0, False
    return best


def _bin_lengths(length: float, n: int) -> np.ndarray:
    """How much of a joint of ``length`` each of its ``n`` TAPE_BINs holds: TAPE_BIN, the last one the rest (a
    joint 0.791 m long has 79 bins of 1 cm and one of 1 mm, which counts for 1 mm, not for 1 cm)."""
    return np.clip(length - np.arange(n) * TAPE_BIN, 0.0, TAPE_BIN)


def _weighted(bins: np.ndarray, weight: np.ndarray) -> float:
    """The share of the length ``weight`` the set ``bins`` hold."""
    total = float(weight.sum())
    return float(weight[bins].sum()) / total if total > 0 else float(bins.mean()) if bins.size else 0.0


def _runs_at(flags: Any, origin: float, most: int = 5) -> List[List[float]]:
    """Where the runs of true values in ``flags`` (TAPE_BINs from ``origin`` m) lie: ``[from, to]`` in m, the
    ``most`` longest, in order along the line."""
    runs, start = [], None
    for i, f in enumerate(list(flags) + [False]):
        if f and start is None:
            start = i
        elif not f and start is not None:
            runs.append((start, i))
            start = None
    runs = sorted(sorted(runs, key=lambda r: r[0] - r[1])[:most])
    return [[round(origin + a * TAPE_BIN, 3), round(origin + b * TAPE_BIN, 3)] for a, b in runs]


def _longest_run(flags: Any) -> int:
    """Length of the longest run of true values in ``flags``."""
    best = n = 0
    for f in flags:
        n = n + 1 if f else 0
        best = max(best, n)
    return best


def _cv(vals: np.ndarray) -> float:
    """Coefficient of variation of the thickness values (0.0 for fewer than two or a zero mean)."""
    return float(vals.std() / vals.mean()) if vals.size > 1 and vals.mean() > 0 else 0.0


def _span(where: str, value: Any, meaning: str) -> Tuple[float, float]:
    """``value`` as ``(a, b)``: two finite numbers with a <= b, else a ValueError naming ``where``."""
    ok = isinstance(value, (list, tuple)) and len(value) == 2 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok or value[0] > value[1]:
        raise ValueError("%s must be [a, b], two numbers with a <= b (%s), got %r" % (where, meaning, value))
    return float(value[0]), float(value[1])


def _dilate(mask: np.ndarray, radius: float) -> np.ndarray:
    """The cells of a 2D ``mask`` and every cell whose centre lies within ``radius`` cells of one of them."""
    out = mask.copy()
    r = int(math.floor(radius + 1e-9))
    nk, ni = mask.shape
    for dk in range(-r, r + 1):
        for di in range(-r, r + 1):
            if (dk, di) == (0, 0) or dk * dk + di * di > radius * radius + 1e-9 or abs(dk) >= nk or abs(di) >= ni:
                continue
            out[max(0, dk):nk + min(0, dk), max(0, di):ni + min(0, di)] |= \
                mask[max(0, -dk):nk + min(0, -dk), max(0, -di):ni + min(0, -di)]
    return out


def _union_length(spans: Sequence[Tuple[float, float]], lo: float, hi: float) -> float:
    """Length of the union of ``spans`` clipped to [lo, hi]."""
    total, end = 0.0, lo
    for a, b in sorted((max(lo, a), min(hi, b)) for a, b in spans):
        if b > max(a, end):
            total += b - max(a, end)
            end = b
    return total
