"""Plasterboard use-case nodes: from PEMKRE's symbols and the scanned walls to the robot's poses and paths.

TagIdNameToObjectId (PEMKRE symbol → stored object id), GetTapingPosition (approach pose for a joint line),
GetTapePath (line endpoints and wall normal), GetTapeSegments (a joint cut into pieces taped from one base pose
each), GetAreaRaster (base stations and raster rectangles for an area), PlanTransit (base waypoints that turn
away from the walls), CheckArmTransit (whether the arm folds into its transit pose while the base drives). They
read the scanned walls, joints and areas through the HDH (the paper's data handler).

Like every node they hold no number of their own: standoffs, offsets and tolerances arrive through ports, by
default from the robot facts (``robot.work.taping.*``, ``robot.tools``: the robot file, derived by
:mod:`locem_bridge.robot_facts`) and the ``taping``/``site`` sections of the HICEM parameters
(``config/hicem/plasterboard.yaml``).
"""
import json
import math
from dataclasses import asdict, replace
from typing import Any, Dict, List, Sequence, Tuple

from py_trees.common import Status

from ...common.geometry import wrap_angle
from ...planning.area_pieces import area_pieces, shared_bottom, shared_ends
from ...planning.reach import RobotEnvelope, ToolEnvelope, Wall2D, WallReach, plan_area, plan_joint, wall_reach
from ..errors import HicemError, PortError
from ..interfaces import local_name
from ..node_base import ConditionLeaf, Leaf
from ..ports import ANY, BOOL, FLOAT, FLOAT_LIST, INT, JSON, STRING, STRING_LIST, input_port, output_port


# Ports the taping and area nodes declare alike, declared once: the same name, type, default and meaning in each.
LINE_ID = input_port("line_id", STRING, None, "", "stored joint id")
AREA_ID = input_port("area_id", STRING, None, "", "stored area id")
STANDOFF = input_port("standoff", FLOAT, "{@robot.work.taping.base_standoff}", "m", "base centre distance from the wall")
LATERAL_OFFSET = input_port("lateral_offset", FLOAT, "{@cfg.taping.lateral_offset}", "m", "shift along the wall")
YAW_OFFSET = input_port("yaw_offset", FLOAT, "{@cfg.taping.yaw_offset}", "rad", "added to the wall-facing heading")
SURFACE_OFFSET = input_port("surface_offset", FLOAT, "{@cfg.taping.surface_offset}", "m", "tool point off the wall")
MAX_TILT = input_port("max_tilt", FLOAT, "{@cfg.taping.plumb_tolerance}", "rad",
                      "a vertical joint within this angle of plumb (a horizontal one of level) is taped plumb "
                      "(level) through the mean of its ends; 0: as measured")


class TagIdNameToObjectId(Leaf):
    DESCRIPTION = ("Maps a PEMKRE symbol (IRI or local name) to the id of an object stored in HICEM and checks "
                   "it exists with the expected kind (joint, area, wall: features from the scan; tool: the "
                   "configured tools).")
    PORTS = (
        input_port("symbol", STRING, None, "", "PEMKRE parameter, e.g. {param_line}"),
        input_port("kind", STRING, None, "", "expected object kind", choices=("joint", "area", "wall", "tool")),
        input_port("tools", STRING_LIST, "{@robot.tools}", "", "tool names known to this robot"),
        output_port("object_id", STRING, None, "", "stored object id"),
    )

    def on_tick(self) -> Status:
        sym = local_name(self.get("symbol").strip())
        kind = self.get("kind")
        if kind == "tool":
            tools = self.get("tools")
            if sym not in tools:
                return self.fail("unknown tool '%s'; this robot has: %s" % (sym, ", ".join(tools)))
        else:
            self.ctx.require("data_handler", self.name).feature(sym, kind)
        self.set("object_id", sym)
        return Status.SUCCESS


def _wall_frame(hdh: Any, wall_id: str) -> Tuple[List[float], List[float]]:
    """(unit tangent p0→p1 in xy, inward normal (3D)) of a stored wall."""
    w = hdh.feature(wall_id, "wall")
    dx, dy = w["p1"][0] - w["p0"][0], w["p1"][1] - w["p0"][1]
    n = math.hypot(dx, dy)
    if n < 1e-9:
        raise HicemError("wall '%s' has zero length" % wall_id)
    return [dx / n, dy / n], list(w["normal"])


def _facing(normal: List[float], yaw_offset: float) -> float:
    """Base heading that faces the wall (base x axis against the inward normal) plus an offset."""
    return wrap_angle(math.atan2(-normal[1], -normal[0]) + yaw_offset)


def _joint_ends(j: Dict[str, Any], max_tilt: float) -> Tuple[List[float], List[float]]:
    """Start and end of a stored joint as the robot tapes it. Plasterboard joints are plumb (vertical joints) or
    level (horizontal ones): a vertical joint measured within ``max_tilt`` rad of plumb is taped plumb through
    the mean horizontal position of its two ends, a horizontal one within ``max_tilt`` of level at their mean
    height. The scanner's independent errors on the two ends then neither tilt the tape path nor add up at one
    end (the mean halves their variance); a joint tilted more than ``max_tilt`` is taped as measured, and
    ``max_tilt`` 0 keeps every measured line."""
    start, end = [float(v) for v in j["start"]], [float(v) for v in j["end"]]
    if max_tilt < 0.0:
        raise PortError("max_tilt must be >= 0 rad, got %g" % max_tilt)
    if max_tilt == 0.0:
        return start, end
    horizontal = math.hypot(end[0] - start[0], end[1] - start[1])
    rise = abs(end[2] - start[2])
    if j.get("kind") == "vertical" and math.atan2(horizontal, rise) <= max_tilt:
        mx, my = (start[0] + end[0]) / 2.0, (start[1] + end[1]) / 2.0
        return [mx, my, start[2]], [mx, my, end[2]]
    if j.get("kind") == "horizontal" and math.atan2(rise, horizontal) <= max_tilt:
        mz = (start[2] + end[2]) / 2.0
        return [start[0], start[1], mz], [end[0], end[1], mz]
    return start, end


class GetTapingPosition(Leaf):
    DESCRIPTION = ("Approach pose [x, y, theta] (map frame) of the base for taping a joint line: in front of the "
                   "line's foot (vertical) or middle (horizontal) as straightened within max_tilt, standoff from "
                   "the wall along its normal, "
                   "shifted along the wall by lateral_offset, facing the wall plus yaw_offset.")
    PORTS = (
        LINE_ID, STANDOFF, LATERAL_OFFSET, YAW_OFFSET, MAX_TILT,
        output_port("approach_pose", FLOAT_LIST, None, "m, m, rad", "x y theta for GOTO"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        j = hdh.feature(self.get("line_id"), "joint")
        t, nrm = _wall_frame(hdh, j["wall"])
        start, end = _joint_ends(j, self.get("max_tilt"))
        if j["kind"] == "vertical":
            fx, fy = start[0], start[1]
        else:
            fx, fy = (start[0] + end[0]) / 2.0, (start[1] + end[1]) / 2.0
        nxy = math.hypot(nrm[0], nrm[1])
        if nxy < 1e-9:
            return self.fail("wall '%s' normal has no horizontal part" % j["wall"])
        nx, ny = nrm[0] / nxy, nrm[1] / nxy
        d, lat = self.get("standoff"), self.get("lateral_offset")
        pose = [fx + nx * d + t[0] * lat, fy + ny * d + t[1] * lat, _facing([nx, ny], self.get("yaw_offset"))]
        self.set("approach_pose", pose)
        return Status.SUCCESS


class GetTapePath(Leaf):
    DESCRIPTION = ("Tape path of a joint line in the map frame: start and end points (straightened to plumb or "
                   "level within max_tilt) moved off the wall by surface_offset along the wall normal, the normal "
                   "itself and the length.")
    PORTS = (
        LINE_ID, SURFACE_OFFSET, MAX_TILT,
        output_port("path_start", FLOAT_LIST, None, "m", "x y z"),
        output_port("path_end", FLOAT_LIST, None, "m", "x y z"),
        output_port("normal", FLOAT_LIST, None, "", "inward wall normal nx ny nz"),
        output_port("length", FLOAT, None, "m", "path length"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        j = hdh.feature(self.get("line_id"), "joint")
        _t, n = _wall_frame(hdh, j["wall"])
        off = self.get("surface_offset")
        start, end = _joint_ends(j, self.get("max_tilt"))
        s = [start[i] + n[i] * off for i in range(3)]
        e = [end[i] + n[i] * off for i in range(3)]
        self.set("path_start", s)
        self.set("path_end", e)
        self.set("normal", n)
        self.set("length", math.dist(s, e))
        return Status.SUCCESS


class GetTapeSegments(Leaf):
    DESCRIPTION = ("Splits a joint line into pieces taped one after the other, each from its own base pose, for "
                   "arms that cannot reach a whole joint from one pose. A vertical joint is clipped to the "
                   "reachable height band [z_min, z_max] and taped outwards from its middle (middle to top, "
                   "middle to bottom: the approach to mid height is the one free of the wall); a horizontal joint "
                   "is cut into pieces no longer than segment_length, each approached in front of its middle. "
                   "Each piece: approach [x, y, theta] at standoff from the wall facing it (plus yaw_offset, "
                   "shifted along the wall by lateral_offset), start and end points (moved off the wall by "
                   "surface_offset) and the inward normal. The clipped length is reported as skipped.")
    PORTS = (
        LINE_ID,
        input_port("segment_length", FLOAT, "{@robot.work.taping.segment_length}", "m",
                   "longest piece taped from one base pose"),
        input_port("z_range", FLOAT_LIST, "{@robot.work.taping.z_range}", "m",
                   "z_min;z_max, the height band the arm reaches with the tool facing the wall"),
        STANDOFF, LATERAL_OFFSET, YAW_OFFSET, SURFACE_OFFSET, MAX_TILT,
        output_port("segments", JSON, None, "", "list of {approach, start, end, normal, length, z: [z_min, z_max]}"),
        output_port("count", INT, None, "", "number of pieces"),
        output_port("skipped", FLOAT, None, "m", "joint length outside the reachable band (not taped)"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        j = hdh.feature(self.get("line_id"), "joint")
        t, nrm = _wall_frame(hdh, j["wall"])
        seg_len = self.get("segment_length")
        if seg_len <= 0:
            raise PortError("%s: segment_length must be > 0 m, got %g" % (self.name, seg_len))
        band = list(self.get("z_range"))
        if len(band) != 2 or band[0] >= band[1]:
            raise PortError("%s: z_range must be two heights z_min < z_max, got %s" % (self.name, band))
        nxy = math.hypot(nrm[0], nrm[1])
        if nxy < 1e-9:
            return self.fail("wall '%s' normal has no horizontal part" % j["wall"])
        nx, ny = nrm[0] / nxy, nrm[1] / nxy
        d, lat, off = self.get("standoff"), self.get("lateral_offset"), self.get("surface_offset")
        heading = _facing([nx, ny], self.get("yaw_offset"))
        start, end = _joint_ends(j, self.get("max_tilt"))
        total = math.dist(start, end)
        pieces = []  # (a, b, foot) in map, before the surface offset
        if j["kind"] == "vertical":
            lo, hi = sorted((start, end), key=lambda p: p[2])
            z0, z1 = max(lo[2], band[0]), min(hi[2], band[1])
            if z1 - z0 < 1e-3:
                return self.fail("joint '%s' (z %.2f..%.2f m) lies outside the reachable band %.2f..%.2f m"
                                 % (j["id"], lo[2], hi[2], band[0], band[1]))

            def at(z: float) -> List[float]:
                f = (z - lo[2]) / (hi[2] - lo[2])
                return [lo[k] + (hi[k] - lo[k]) * f for k in range(3)]

            mid = (z0 + z1) / 2.0
            for a, b in ((mid, z1), (mid, z0)):
                n = max(1, int(math.ceil(abs(b - a) / seg_len - 1e-9)))
                for i in range(n):
                    za, zb = a + (b - a) * i / n, a + (b - a) * (i + 1) / n
                    pieces.append((at(za), at(zb), lo))
        else:
            n = max(1, int(math.ceil(total / seg_len - 1e-9)))
            for i in range(n):
                a = [start[k] + (end[k] - start[k]) * i / n for k in range(3)]
                b = [start[k] + (end[k] - start[k]) * (i + 1) / n for k in range(3)]
                pieces.append((a, b, [(a[k] + b[k]) / 2.0 for k in range(3)]))
        segments = []
        for a, b, foot in pieces:
            approach = [foot[0] + nx * d + t[0] * lat, foot[1] + ny * d + t[1] * lat, heading]
            segments.append({"approach": approach, "start": [a[k] + nrm[k] * off for k in range(3)],
                             "end": [b[k] + nrm[k] * off for k in range(3)], "normal": list(nrm),
                             "length": math.dist(a, b), "z": sorted((a[2], b[2]))})
        self.set("segments", segments)
        self.set("count", len(segments))
        self.set("skipped", max(0.0, total - sum(s["length"] for s in segments)))
        return Status.SUCCESS


def _outwards(length: float, most: float) -> List[Tuple[float, float]]:
    """A line of ``length`` taped from its middle outwards in pieces no longer than ``most``: (from, to) as
    fractions of it, middle to the end (1) first, then middle to the start (0)."""
    out = []
    for end in (1.0, 0.0):
        n = max(1, int(math.ceil(length / 2.0 / most - 1e-9)))
        out += [(0.5 + (end - 0.5) * i / n, 0.5 + (end - 0.5) * (i + 1) / n) for i in range(n)]
    return out


def _reach_of(plan: Dict[str, Any]) -> WallReach:
    """The :class:`WallReach` GetWallReach's ``plan`` output describes."""
    return WallReach(plan["wall"], plan["work"], [tuple(iv) for iv in plan["tool"]], [tuple(iv) for iv in plan["base"]],
                     tuple(plan["t"]), [(tuple(iv), why) for iv, why in plan.get("why", [])])


class GetTapePlan(Leaf):
    DESCRIPTION = ("Plans the taping of a joint line before the robot moves (locem_bridge.planning.reach."
                   "plan_joint on GetWallReach's plan for taping): a vertical joint is one piece clipped to the "
                   "height band, taped from the free base pose nearest it within side m along the wall; a "
                   "horizontal joint is taped on every stretch the tool reaches, in pieces no longer than "
                   "segment_length, each from the free base pose nearest its middle. Each piece: approach "
                   "[x, y, theta] at standoff facing the wall (plus yaw_offset, lateral_offset), start and end "
                   "(straightened within max_tilt, moved off the wall by surface_offset) and the inward normal. "
                   "The rest (near a corner, out of the band, no free base) is manual work: listed with its "
                   "extent along the joint and reason, named in the task detail; nothing of it is touched.")
    PORTS = (
        LINE_ID,
        input_port("plan", JSON, None, "", "what taping reaches on the joint's wall (GetWallReach, work taping)"),
        input_port("side", FLOAT, "{@robot.work.taping.lateral_reach}", "m",
                   "how far along the wall from the base a vertical joint is taped"),
        input_port("segment_length", FLOAT, "{@robot.work.taping.segment_length}", "m",
                   "longest piece of a horizontal joint taped from one base pose (0: a reachable stretch whole)"),
        input_port("min_manual", FLOAT, "{@cfg.plan.min_manual}", "m", "a vertical joint reaching less than this "
                   "past the height band is taped to its end; a shorter manual part is not listed"),
        STANDOFF, LATERAL_OFFSET, YAW_OFFSET, SURFACE_OFFSET, MAX_TILT,
        input_port("done", STRING, "taped", "", "the task detail's first word when something is taped"),
        input_port("outwards", BOOL, "false", "", "true (an arm on a lift, the plan's band is the lift's z_range): "
                   "a vertical piece is taped from its middle outwards, middle to top then middle to bottom, in "
                   "pieces no longer than segment_length, each at its own lift height (its z)"),
        output_port("segments", JSON, None, "", "list of {approach, start, end, normal, length, along: [a, b], "
                    "z: [z_min, z_max]}"),
        output_port("count", INT, None, "", "number of pieces taped by the robot"),
        output_port("manual", JSON, None, "", "[{along: [a, b], reason}] left to the hand (m from the joint's start)"),
        output_port("status", STRING, None, "", "'taped' when a piece is taped, 'manual' when none is"),
        output_port("detail", STRING, None, "", "task detail: 'taped', or followed by '; manual work on <joint>: "
                    "part 1 (along a..b m; reason)'; 'manual work on ...' alone when nothing is taped"),
    )

    def on_tick(self) -> Status:
        from .area_work import manual_joint_text
        hdh = self.ctx.require("data_handler", self.name)
        jid = self.get("line_id")
        j = hdh.feature(jid, "joint")
        plan = self.get("plan")
        if not isinstance(plan, dict) or plan.get("work") != "taping" or plan.get("wall") != j["wall"]:
            raise PortError("%s: plan must be GetWallReach's plan for taping on wall '%s', got %r"
                            % (self.name, j["wall"], plan if not isinstance(plan, dict) else
                               {k: plan.get(k) for k in ("wall", "work")}))
        side, seg = self.get("side"), self.get("segment_length")
        if side < 0 or seg < 0:
            raise PortError("%s: side and segment_length must be >= 0 m, got %g, %g" % (self.name, side, seg))
        _t, nrm = _wall_frame(hdh, j["wall"])
        nxy = math.hypot(nrm[0], nrm[1])
        if nxy < 1e-9:
            return self.fail("wall '%s' normal has no horizontal part" % j["wall"])
        wall = Wall2D.from_scan(hdh.feature(j["wall"], "wall"))
        start, end = _joint_ends(j, self.get("max_tilt"))
        planned = plan_joint(dict(j, start=start, end=end), wall, _reach_of(plan), side, seg,
                             max(0.0, self.get("min_manual")))
        nx, ny = nrm[0] / nxy, nrm[1] / nxy
        d, lat, off = self.get("standoff"), self.get("lateral_offset"), self.get("surface_offset")
        heading = _facing([nx, ny], self.get("yaw_offset"))
        u = [float(wall.u[0]), float(wall.u[1])]
        segments = []
        for piece in planned.pieces:
            a, b = piece["from"], piece["to"]
            foot = a if j["kind"] == "vertical" else [(a[k] + b[k]) / 2.0 for k in range(3)]
            shift = piece["base"] - float((foot[0] - wall.p0[0]) * u[0] + (foot[1] - wall.p0[1]) * u[1]) + lat
            approach = [foot[0] + nx * d + u[0] * shift, foot[1] + ny * d + u[1] * shift, heading]
            parts = [(0.0, 1.0)]
            if self.get("outwards") and j["kind"] == "vertical" and seg > 0:
                parts = _outwards(math.dist(a, b), seg)
            al0, al1 = piece["along"]
            for fa, fb in parts:
                pa = [a[k] + (b[k] - a[k]) * fa for k in range(3)]
                pb = [a[k] + (b[k] - a[k]) * fb for k in range(3)]
                segments.append({"approach": list(approach), "start": [pa[k] + nrm[k] * off for k in range(3)],
                                 "end": [pb[k] + nrm[k] * off for k in range(3)], "normal": list(nrm),
                                 "length": math.dist(pa, pb), "along": [al0 + (al1 - al0) * fa,
                                                                        al0 + (al1 - al0) * fb],
                                 "z": sorted((pa[2], pb[2]))})
        manual = [{"along": list(m["along"]), "reason": m["reason"]} for m in planned.manual]
        detail = self.get("done") if segments else ""
        if manual:
            text = manual_joint_text(jid, manual)
            detail = detail + "; " + text if detail else text
        self.set("segments", segments)
        self.set("count", len(segments))
        self.set("manual", manual)
        self.set("status", "taped" if segments else "manual")
        self.set("detail", detail)
        if manual:
            self.ctx.log.warning("%s: %s", jid, detail)
        return Status.SUCCESS


class CheckLift(ConditionLeaf):
    DESCRIPTION = ("SUCCESS when the robot's arm rides on a lift (robot fact robot.lift.fitted), FAILURE otherwise: "
                   "trees work in height bands with LIFT on such a robot and skip LIFT (not registered) on others.")
    PORTS = (input_port("fitted", BOOL, "{@robot.lift.fitted}", "", "the robot has a lift"),)

    def on_tick(self) -> Status:
        return Status.SUCCESS if self.get("fitted") else Status.FAILURE


class GetLiftHeight(Leaf):
    DESCRIPTION = ("The LIFT command that puts a piece of wall work spanning heights z (map z_min;z_max) inside "
                   "the band the tool reaches from one lift height (band: at the lift's bottom; it rides up with "
                   "the lift): of the lift heights that keep the piece in the band (within the lift's range), the "
                   "one nearest the piece's middle (the arm reaches furthest sideways at its mount's height). "
                   "Without a lift (empty lift_range) command is empty (LOCEM judges the reach as before). "
                   "FAILURE naming the heights when no lift height covers the piece.")
    PORTS = (
        input_port("z", FLOAT_LIST, None, "m", "z_min;z_max of the piece (e.g. {piece.z})"),
        input_port("band", FLOAT_LIST, None, "m", "z_min;z_max reached from one lift height, at the lift's bottom"),
        input_port("lift_range", FLOAT_LIST, "{@robot.lift.range}", "m", "bottom;top of the lift, empty: no lift"),
        input_port("tolerance", FLOAT, "0.0", "m", "how far the piece may reach past the band at either end (a "
                   "joint GetTapePlan tapes to its scanned end within cfg.plan.min_manual of the band)"),
        output_port("command", STRING, None, "", "'LIFT z=<m>', or empty when the robot has no lift"),
        output_port("height", FLOAT, None, "m", "the lift height (0 without a lift)"),
    )

    def on_tick(self) -> Status:
        z = list(self.get("z"))
        if len(z) != 2:
            raise PortError("%s: z must be two heights z_min;z_max, got %s" % (self.name, z))
        lo, hi = sorted(z)
        tol = self.get("tolerance")
        if tol < 0:
            raise PortError("%s: tolerance must be >= 0 m, got %g" % (self.name, tol))
        band, lift = list(self.get("band")), list(self.get("lift_range"))
        if len(band) != 2 or band[0] >= band[1]:
            raise PortError("%s: band must be two heights z_min < z_max, got %s" % (self.name, band))
        if lift and (len(lift) != 2 or lift[0] > lift[1]):
            raise PortError("%s: lift_range must be empty or bottom;top, got %s" % (self.name, lift))
        if not lift:
            self.set("command", "")
            self.set("height", 0.0)
            return Status.SUCCESS
        # lift heights that keep the piece in the band, within the lift's range; of these the one nearest the
        # piece's middle (the arm reaches furthest sideways at its mount's height)
        def limits(z0: float, z1: float) -> Tuple[float, float]:
            return max(lift[0], lift[0] + z1 - band[1]), min(lift[1], lift[0] + z0 - band[0])

        low, high = limits(lo, hi)
        if low > high + 1e-6:
            # within the tolerance: the height between the two limits, inside what the tolerance allows
            low_t, high_t = limits(min(lo + tol, (lo + hi) / 2.0), max(hi - tol, (lo + hi) / 2.0))
            if low_t > high_t + 1e-6:
                return self.fail("heights %.3f..%.3f m are out of reach from one lift height (band %.2f..%.2f m at "
                                 "the lift's bottom, lift %.2f..%.2f m)" % (lo, hi, band[0], band[1], lift[0],
                                                                           lift[1]))
            height = min(max((low + high) / 2.0, low_t), max(low_t, high_t))
        else:
            height = min(max((lo + hi) / 2.0, low), max(low, high))
        self.set("command", "LIFT z=%.4f" % height)
        self.set("height", height)
        return Status.SUCCESS


_REACH_CACHE: Dict[str, WallReach] = {}


class GetWallReach(Leaf):
    DESCRIPTION = ("Plans, before the robot moves, what one wall work can reach on the wall of a joint or area "
                   "(locem_bridge.planning.reach): from the scanned walls, their corners (any angle), the scan's "
                   "obstacles (walls that are no work surface, e.g. concrete) and the robot's "
                   "outline -- chassis, the tool's working end, body and the wrist beside it, each keeping clearance "
                   "from every wall -- the stretches along the wall the tool can work from a free base pose, the "
                   "free base centres and the height band. GetAreaRaster cuts an area to it; the rest is manual "
                   "work with its extent and reason.")
    PORTS = (
        input_port("feature_id", STRING, None, "", "stored joint or area id (its wall is planned)"),
        input_port("work", STRING, None, "", "the wall work (taping, spray, sand): its robot facts are used"),
        input_port("footprint", FLOAT_LIST, "{@robot.base.footprint}", "m", "chassis length;width"),
        input_port("shoulder_x", FLOAT, "{@robot.arm.shoulder_x}", "m", "arm mount ahead of the base centre"),
        input_port("works", JSON, "{@robot.work}", "", "the robot facts per work (robot.work)"),
        input_port("reach", FLOAT, "0.0", "m", "how far to either side of the base the tool works (0: the work's "
                   "section_width / 2, else its lateral_reach)"),
        input_port("run_on", FLOAT, "-1.0", "m", "how far the tool travels past the worked part (a raster lane's "
                   "run-in and run-up; -1: lateral_reach - section_width / 2 for a raster work, 0 otherwise)"),
        input_port("clearance", FLOAT, "{@cfg.plan.clearance}", "m", "what every part keeps from every wall"),
        input_port("arm_radius", FLOAT, "{@cfg.plan.arm_radius}", "m", "radius of the wrist and forearm links"),
        input_port("wrist_length", FLOAT, "{@cfg.plan.wrist_length}", "m", "wrist and forearm behind the flange"),
        input_port("wrist_offset", FLOAT, "{@cfg.plan.wrist_offset}", "m", "wrist links beside the tool axis"),
        input_port("shoulder_radius", FLOAT, "{@cfg.plan.shoulder_radius}", "m", "upper arm and elbow around the "
                   "shoulder's axis (floor plan)"),
        output_port("plan", JSON, None, "", "{wall, work, tool: [[s0, s1]...], base: [[s0, s1]...], t: [lo, hi], "
                    "reach, why: [[[s0, s1], reason]...]} along the wall from p0 (m)"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        fid = self.get("feature_id")
        feature = hdh.feature(fid)
        work = self.get("work")
        facts = (self.get("works") or {}).get(work)
        if not isinstance(facts, dict):
            return self.fail("this robot has no tool for work '%s'" % work)
        stored = sorted(hdh.features("wall"), key=lambda w: w["id"])
        walls = [Wall2D.from_scan(w) for w in stored]
        wall = next((w for w in walls if w.id == feature["wall"]), None)
        if wall is None:
            return self.fail("wall '%s' of %s is not stored" % (feature["wall"], fid))
        obstacles = sorted(hdh.obstacles(), key=lambda o: o["id"])      # the latest scan's non-work walls
        fp = list(self.get("footprint"))
        if len(fp) != 2 or min(fp) <= 0:
            raise PortError("%s: footprint must be length;width > 0, got %s" % (self.name, fp))
        reach = self.get("reach") or float(facts.get("section_width", 2.0 * facts["lateral_reach"])) / 2.0
        run_on = self.get("run_on")
        if run_on < 0:
            run_on = max(0.0, float(facts["lateral_reach"]) - float(facts.get("section_width",
                                                                              2.0 * facts["lateral_reach"])) / 2.0)
        tool = ToolEnvelope.from_facts(work, facts, reach, run_on)
        env = RobotEnvelope(fp[0], fp[1], self.get("shoulder_x"), {work: tool}, self.get("clearance"),
                            self.get("arm_radius"), self.get("wrist_length"), self.get("wrist_offset"),
                            self.get("shoulder_radius"))
        key = json.dumps([stored, obstacles, wall.id, asdict(env)], sort_keys=True)
        r = _REACH_CACHE.get(key)
        if r is None:            # the areas of one wall share its plan: planned once per scan and robot
            r = wall_reach(wall, walls + [Wall2D.from_obstacle(o) for o in obstacles], env, work)
            if len(_REACH_CACHE) > 64:
                _REACH_CACHE.clear()
            _REACH_CACHE[key] = r
        self.set("plan", {"wall": r.wall, "work": work, "tool": [list(iv) for iv in r.tool],
                          "base": [list(iv) for iv in r.base], "t": list(r.t), "reach": reach,
                          "why": [[list(iv), why] for iv, why in r.why]})
        return Status.SUCCESS


class GetAreaRaster(Leaf):
    DESCRIPTION = ("Splits a wall area into sections no wider than section_width; for each: a base approach pose "
                   "facing the section's middle at base_standoff, and the raster rectangle (origin, u, width, "
                   "height, wall normal) in the map frame. An area with holes (door and window openings with "
                   "their frames, the scan's holes) is first cut into pieces around them "
                   "(locem_bridge.planning.area_pieces): no section covers a hole, the lanes run on past a hole's "
                   "edge like past the area's ends, and a piece sitting on another starts one band_gap above it. "
                   "An end of the area another stored area of the same wall adjoins (neighbours) is shared: the "
                   "lanes stop exactly at it, as two sections of one area meet, and run no edge_extension onto the "
                   "neighbour, whose own lanes coat its side: the two areas lay one coat across their common "
                   "edge (an end adjoined over part of its height is split there; "
                   "locem_bridge.planning.area_pieces.shared_ends). So is an end in an inside corner where an area "
                   "of the wall across the corner begins: the fan stopped at the corner lays its outer half on the "
                   "other wall, as on a next section. So is the bottom where another area of the "
                   "wall ends right below it (stacked areas): its lanes there begin one band_gap above the edge, "
                   "on which the lower area's top lane lies (area_pieces.shared_bottom).")
    #: m, how far a pad kept ``hole_margin`` (its radius) off a hole reaches over the hole's edge (the frame's outer
    #: line): the wall right up to the line is sanded though the arm tracks a lane only to a millimetre or two (with
    #: the edge exactly on the line the last 1 cm of wall beside and above a door was left to chance: on door.yaml
    #: the cells along the frame, 3.2 % of wall_1's area, stayed bare); far less than a grid cell of the outcome
    #: (2 cm), nothing a frame's sanding fault would show, and no lane of spraying (no hole_margin) moves
    FRAME_REACH = 0.002
    PORTS = (
        AREA_ID,
        input_port("section_width", FLOAT, None, "m", "widest strip covered from one base pose"),
        input_port("base_standoff", FLOAT, None, "m", "base centre distance from the wall"),
        input_port("yaw_offset", FLOAT, None, "rad", "added to the wall-facing heading"),
        input_port("edge_extension", FLOAT, "0.0", "m", "the first and last section of a piece reach this far "
                   "beyond the area's ends and a hole's edges (spray run-in at the outer edges; sections meet "
                   "exactly in between)"),
        input_port("neighbours", BOOL, "true", "", "true: an end of the area that another stored area of the same "
                   "wall adjoins, or one of the wall across an inside corner (within neighbour_tolerance, over part "
                   "of the height or all of it) is shared: no "
                   "edge_extension past it, the neighbour's lanes cover its side; a bottom another area ends right "
                   "below (within neighbour_tolerance) begins one band_gap above the edge; overlapping areas are each "
                   "worked whole; false: every end of the area is open (each area on its own)"),
        input_port("neighbour_tolerance", FLOAT, "0.02", "m", "a neighbour whose end lies within this of the "
                   "area's end (a gap or an overlap) adjoins it; wider apart, both ends are open"),
        input_port("band_height", FLOAT, "0.0", "m", "tallest section (e.g. {@robot.work.spray.band_height}: what "
                   "the arm covers from one lift height); a taller area is cut into bands of equal height, bottom "
                   "first in the first column, then alternating (the next column starts in the band the last one "
                   "ended in: the lift moves once between two columns, not twice); 0: one band"),
        input_port("band_gap", FLOAT, "0.0", "m", "a band starts this far above the band below it (the lane "
                   "spacing: its bottom lane is one lane above the lower band's top lane, no lane twice)"),
        input_port("hole_margin", FLOAT, "0.0", "m", "lanes keep this far from a hole (an opening's frame): a pad's "
                   "radius, whose edge then works right up to the frame; a margin > 0 is shortened by FRAME_REACH "
                   "(2 mm: the pad's edge reaches the frame's outer line despite the arm's path tolerance, the "
                   "frame itself is not sanded)"),
        input_port("min_manual", FLOAT, "{@cfg.plan.min_manual}", "m", "a planned manual strip narrower than this "
                   "is not reported (the fan or pad past the worked part's edge covers it)"),
        input_port("edge_passes", BOOL, "false", "", "true: where a section's side is a hole's edge (the lanes "
                   "stop there, hole_margin off the frame) a vertical pass follows the section, from the same "
                   "base pose, up that side over the height the hole borders it (lanes 'vertical', width 0): a "
                   "round pad on horizontal lanes that cannot run on leaves scallops of wall bare between them"),
        input_port("plan", JSON, "null", "", "what the work reaches on the area's wall (GetWallReach); null: the "
                   "whole area, each section's base in front of its middle"),
        input_port("lane_spacing", FLOAT, "0.0", "m", "even coat (spray): a section's lanes are spread over its "
                   "height as near this spacing as whole intervals allow (a 0.2 m strip: 2 lanes 0.2 m apart, "
                   "not 3 lanes 0.1 m apart, half again the coat) and its speed is scaled by its spacing's ratio "
                   "to this one, so every m2 gets the same coat; 0: spacing band_gap, at most that far apart"),
        input_port("speed", FLOAT, "0.0", "m/s", "lane speed at lane_spacing (each section's 'speed')"),
        input_port("max_speed", FLOAT, "1.0", "m/s", "the scaled speed's cap (the run-up a lane has room for)"),
        output_port("sections", JSON, None, "", "list of {approach, origin, u, width, height, normal, index, z, "
                    "lanes, spacing, speed} (lanes: 'horizontal', or 'vertical' for an edge pass; spacing (m) and "
                    "speed (m/s) of its lanes)"),
        output_port("count", INT, None, "", "number of sections"),
        output_port("manual", JSON, None, "", "the parts of the area the plan leaves to the hand: "
                    "[{along: [a, b], height: [c, d], reason}] (along from the area's origin, height above the floor)"),
    )
    MORE_COLUMNS = 3      # a piece is cut into up to this many more sections for each to have a free base pose

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        a = hdh.feature(self.get("area_id"), "area")
        _t, n = _wall_frame(hdh, a["wall"])
        sw, bs = self.get("section_width"), self.get("base_standoff")
        if sw <= 0:
            raise PortError("%s: section_width must be > 0 m, got %g" % (self.name, sw))
        nxy = math.hypot(n[0], n[1]) or 1.0
        heading = _facing([n[0] / nxy, n[1] / nxy], self.get("yaw_offset"))
        ext = self.get("edge_extension")
        if ext < 0:
            raise PortError("%s: edge_extension must be >= 0 m, got %g" % (self.name, ext))
        band_h, gap = self.get("band_height"), self.get("band_gap")
        if band_h < 0 or gap < 0:
            raise PortError("%s: band_height and band_gap must be >= 0 m, got %g, %g" % (self.name, band_h, gap))
        margin = self.get("hole_margin")
        if margin < 0:
            raise PortError("%s: hole_margin must be >= 0 m, got %g" % (self.name, margin))
        if margin > 0:
            # a pad's edge exactly on the frame's outer line leaves the wall along it to chance (the arm's path
            # tolerance): it reaches FRAME_REACH over the line, never further (see FRAME_REACH)
            margin = max(0.0, margin - self.FRAME_REACH)
        holes = [(h["s"][0] - margin, h["s"][1] + margin, h["t"][0] - margin if h["t"][0] > 1e-9 else h["t"][0],
                  h["t"][1] + margin) for h in a.get("holes", [])]
        u = a["u"]
        frames = list(holes) if self.get("edge_passes") else []       # the openings' holes, not the manual parts
        plan, reach, manual = self.get("plan"), None, []
        if plan:
            wall = Wall2D.from_scan(hdh.feature(a["wall"], "wall"))
            reach = _reach_of(plan)
            worked = plan_area(a, wall, reach, self.get("min_manual"))
            manual = worked.manual
            # the parts out of reach become holes: the pieces stop there and run no lanes into them
            holes += [(m["along"][0], m["along"][1], m["height"][0] - a["origin"][2], m["height"][1] - a["origin"][2])
                      for m in manual]
            along0 = float((a["origin"][0] - wall.p0[0]) * wall.u[0] + (a["origin"][1] - wall.p0[1]) * wall.u[1])
        tol = self.get("neighbour_tolerance")
        if tol < 0:
            raise PortError("%s: neighbour_tolerance must be >= 0 m, got %g" % (self.name, tol))
        others = hdh.features("area") if self.get("neighbours") else []
        shared: Any = shared_ends(a, others, tol, gap, normal=n)
        stacked = shared_bottom(a, others, tol, gap)
        sections: List[Dict[str, Any]] = []
        smallest = max(0.0, self.get("min_manual")) if reach is not None else 0.0
        # never above the band the tool reaches (a sliver the plan's manual parts leave beside a hole at the area's
        # end ran up to the wall's top: protective stop); below it by min_manual at most (above the area's origin)
        top = reach.t[1] - a["origin"][2] if reach is not None else math.inf
        bottom = reach.t[0] - a["origin"][2] - smallest if reach is not None else -math.inf
        for piece in area_pieces(a["width"], a["height"], holes, gap, *shared, shared_bottom=stacked):
            # a piece sitting on another begins one lane spacing above it: as manual work that strip is its own
            below = piece.t0 - (gap if piece.on_piece else 0.0)
            if reach is not None:
                if piece.t1 > top + 1e-9 or piece.t0 < bottom - 1e-9:
                    piece = replace(piece, t0=max(piece.t0, min(bottom, piece.t1)),
                                    t1=min(piece.t1, max(top, piece.t0)))
                # a sliver the plan's cuts leave (scan noise between a manual part and a hole) or a piece outside
                # the tool's band is never sent to the arm: manual work if it is worth listing
                z0, z1 = a["origin"][2] + piece.t0, a["origin"][2] + piece.t1
                inside = min(z1, reach.t[1]) - max(z0, reach.t[0])
                if piece.width < smallest or piece.height < smallest or inside < min(smallest, piece.height) - 1e-9:
                    if piece.width >= smallest and piece.height >= smallest:
                        manual.append({"along": [piece.s0, piece.s1], "height": [a["origin"][2] + below, z1],
                                       "reason": "outside the tool's height band"})
                    continue
            count = max(1, int(math.ceil(piece.width / sw - 1e-9)))
            if reach is not None:
                # near the end of what the bases reach each point may be reachable from some base but a whole
                # section from none: of up to MORE_COLUMNS more (narrower) sections, the count that leaves the
                # least width without a free base pose (manual), the fewest sections among equals
                def unreached(c: int) -> float:
                    ww = piece.width / c
                    return sum(ww for i in range(c) if reach.base_for(along0 + piece.s0 + ww * i, along0 + piece.s0
                                                                      + ww * (i + 1), float(plan["reach"])) is None)
                count = min(range(count, count + self.MORE_COLUMNS + 1), key=lambda c: (round(unreached(c), 6), c))
            w = piece.width / count
            bands = 1
            if band_h > 0 and piece.height > band_h + 1e-9:
                bands = int(math.ceil((piece.height + gap) / (band_h + gap) - 1e-9))
            bh = (piece.height - gap * (bands - 1)) / bands
            if bh <= 0:
                raise PortError("%s: band_gap %g m leaves no band in a %g m high piece of the area"
                                % (self.name, gap, piece.height))
            sh = bh if bands > 1 else piece.height                # a section's height
            spacing, speed = self._lanes(sh, gap)
            # the columns of the piece, each with its planned free base pose (None: none reaches all of it);
            # neighbours one base reaches together are one column (no seam of run-ins between them)
            cols: List[List[Any]] = [[piece.s0 + w * i, piece.s0 + w * (i + 1), None] for i in range(count)]
            if reach is not None:
                for col in cols:
                    col[2] = reach.base_for(along0 + col[0], along0 + col[1], float(plan["reach"]))
                joined = [cols[0]]
                for col in cols[1:]:
                    last = joined[-1]
                    both = (reach.base_for(along0 + last[0], along0 + col[1], float(plan["reach"]))
                            if last[2] is not None and col[2] is not None and col[1] - last[0] <= sw + 1e-9
                            else None)
                    if both is not None:
                        last[1], last[2] = col[1], both
                    elif last[2] is None and col[2] is None:
                        last[1] = col[1]                      # one manual part, not several side by side
                    else:
                        joined.append(col)
                cols = joined
            count = len(cols)
            for i, (along, end, at) in enumerate(cols):
                w = end - along
                o = [a["origin"][k] + u[k] * along for k in range(3)]
                o[2] += piece.t0
                mx, my = o[0] + u[0] * w / 2.0, o[1] + u[1] * w / 2.0
                s0 = -ext if i == 0 and piece.open_left else 0.0     # along u, from the section's own start
                s1 = w + ext if i == count - 1 and piece.open_right else w
                if reach is not None:      # the free base pose nearest the section's middle (planned)
                    if at is None:
                        manual.append({"along": [along, along + w],
                                       "height": [a["origin"][2] + below, a["origin"][2] + piece.t1],
                                       "reason": "no free base pose reaches all of it"})
                        continue
                    # beside a part left manual the lanes run on into it as at an open edge (else the fan's soft
                    # edge leaves the last centimetres of the robot's part thin), if a free base reaches that too
                    e0 = -ext if i > 0 and cols[i - 1][2] is None else s0
                    e1 = w + ext if i < count - 1 and cols[i + 1][2] is None else s1
                    if (e0, e1) != (s0, s1):
                        wider = reach.base_for(along0 + along + e0, along0 + along + e1, float(plan["reach"]))
                        if wider is not None:
                            s0, s1, at = e0, e1, wider
                    mx, my = wall.p0[0] + wall.u[0] * at, wall.p0[1] + wall.u[1] * at
                o = [o[k] + u[k] * s0 for k in range(3)]
                sides = ([piece.s0] if i == 0 else []) + ([piece.s1] if i == count - 1 else [])
                for b in (range(bands) if i % 2 == 0 else reversed(range(bands))):
                    ob = list(o)
                    ob[2] = o[2] + b * (bh + gap)
                    approach = [mx + n[0] / nxy * bs, my + n[1] / nxy * bs, heading]
                    sections.append({"approach": approach, "origin": ob, "u": list(u), "width": s1 - s0,
                                     "height": sh, "normal": n, "index": len(sections), "z": [ob[2], ob[2] + bh],
                                     "lanes": "horizontal", "spacing": spacing, "speed": speed})
                    t0 = piece.t0 + b * (bh + gap)
                    for side, lo, hi in _edge_passes(frames, sides, t0, min(top, t0 + sh)):
                        og = [a["origin"][k] + u[k] * side for k in range(3)]
                        og[2] = a["origin"][2] + lo
                        sections.append({"approach": approach, "origin": og, "u": list(u), "width": 0.0,
                                         "height": hi - lo, "normal": n, "index": len(sections),
                                         "z": [ob[2], ob[2] + bh], "lanes": "vertical", "spacing": gap,
                                         "speed": self.get("speed")})
        self.set("sections", sections)
        self.set("count", len(sections))
        self.set("manual", manual)
        return Status.SUCCESS

    def _lanes(self, height: float, gap: float) -> Tuple[float, float]:
        """(spacing, speed) of a section ``height`` tall (see the ports lane_spacing, speed, max_speed)."""
        nominal, speed = self.get("lane_spacing"), self.get("speed")
        if nominal < 0 or speed < 0 or self.get("max_speed") <= 0:
            raise PortError("%s: lane_spacing and speed must be >= 0 and max_speed > 0, got %g, %g, %g"
                            % (self.name, nominal, speed, self.get("max_speed")))
        if nominal <= 0:
            return gap, speed
        spacing = height / max(1, int(round(height / nominal))) if height > 1e-9 else nominal
        # rounded up (to what the command text carries): LOCEM's lanes at most this far apart are then exactly
        # the whole intervals above, not one more
        spacing = math.ceil(spacing * 1e5 - 1e-6) / 1e5
        return spacing, round(min(self.get("max_speed"), speed * nominal / spacing), 4)


#: m, shortest edge pass (GetAreaRaster edge_passes): a hole bordering a section over less is left to its lanes
EDGE_PASS_MIN = 0.05


def _edge_passes(holes: Sequence[Tuple[float, float, float, float]], sides: Sequence[float], t0: float,
                 t1: float) -> List[Tuple[float, float, float]]:
    """(along, from, to) of the vertical passes up a section's ``sides`` (along the area) over [t0, t1] (above
    the area's origin): where a hole (s0, s1, t0, t1) ends or starts exactly at a side, over the height they
    share, EDGE_PASS_MIN or more."""
    out = []
    for side in sides:
        for hs0, hs1, ht0, ht1 in holes:
            if abs(hs1 - side) < 1e-6 or abs(hs0 - side) < 1e-6:
                lo, hi = max(t0, ht0), min(t1, ht1)
                if hi - lo >= EDGE_PASS_MIN:
                    out.append((side, lo, hi))
    return out


def _pose_of(here: Any) -> Any:
    """[x, y, theta] of a pose port: the value itself or GET_POSE's result (its 'pose')."""
    return here.get("pose") if isinstance(here, dict) else here


def _folds(transit_pose: Any) -> bool:
    """Whether the robot names an arm pose for driving (robot fact robot.arm.transit_pose)."""
    return bool(str(transit_pose or "").strip())


class PlanTransit(Leaf):
    DESCRIPTION = ("Base waypoints from the current pose to goal [x, y, theta] (map). A turn larger than max_turn "
                   "is not made next to a wall, where the corners of the turning base would sweep into it: the "
                   "base first drives to the transit point keeping its heading, turns there, then drives to the "
                   "goal. Otherwise the goal alone, and always on a robot whose arm folds for driving (a transit "
                   "pose is named: a non-holonomic base, which turns in place on every move anyway; folded, only "
                   "its chassis sweeps, and the work poses keep it clear of the walls).")
    PORTS = (
        input_port("here", ANY, None, "m, m, rad", "current pose: [x, y, theta] or GET_POSE's result"),
        input_port("goal", FLOAT_LIST, None, "m, m, rad", "x y theta to reach"),
        input_port("transit", FLOAT_LIST, "{@cfg.site.locations.home}", "m", "x y (theta ignored) with room "
                   "to turn"),
        input_port("max_turn", FLOAT, "{@cfg.site.max_turn_near_walls}", "rad", "largest turn made on the way"),
        input_port("transit_pose", STRING, "{@robot.arm.transit_pose}", "", "the arm's pose for driving; "
                   "named: any turn is made on the way (see above)"),
        output_port("waypoints", JSON, None, "", "list of [x, y, theta] poses for GOTO, in order"),
    )

    def on_tick(self) -> Status:
        here = _pose_of(self.get("here"))
        goal, transit = list(self.get("goal")), list(self.get("transit"))
        if not isinstance(here, (list, tuple)) or len(here) != 3 or len(goal) != 3 or len(transit) < 2:
            raise PortError("%s: here and goal must be [x, y, theta] and transit [x, y, ...], got %r, %r, %r"
                            % (self.name, here, goal, transit))
        turn = abs(wrap_angle(float(goal[2]) - float(here[2])))
        if turn <= self.get("max_turn") or _folds(self.get("transit_pose")):
            waypoints = [goal]
        else:
            waypoints = [[transit[0], transit[1], float(here[2])], [transit[0], transit[1], float(goal[2])], goal]
        kept = [waypoints[0]]
        for w in waypoints[1:]:       # a goal at the transit point itself is not driven to twice
            if max(abs(float(a) - float(b)) for a, b in zip(w, kept[-1])) > 1e-6:
                kept.append(w)
        self.set("waypoints", kept)
        return Status.SUCCESS


class CheckArmTransit(ConditionLeaf):
    DESCRIPTION = ("SUCCESS when the arm folds into its transit pose (robot fact robot.arm.transit_pose, a named "
                   "arm pose) while the base drives: the robot names one (a non-holonomic base turns in place, "
                   "and an arm held out at 'wall_ready' would sweep into a wall beside it) and, when waypoints are "
                   "given, they move the base from here (more than move_tolerance or turn_tolerance). FAILURE "
                   "otherwise: the arm stays where it is.")
    PORTS = (
        input_port("pose", STRING, "{@robot.arm.transit_pose}", "", "the transit pose's name; empty: none"),
        input_port("here", ANY, "", "m, m, rad", "current pose: [x, y, theta] or GET_POSE's result; empty: "
                   "the base is taken to move"),
        input_port("waypoints", ANY, "", "m, m, rad", "PlanTransit's waypoints; empty: the base is taken to move"),
        input_port("move_tolerance", FLOAT, "0.01", "m", "a waypoint nearer than this (and turned less than "
                   "turn_tolerance) does not move the base"),
        input_port("turn_tolerance", FLOAT, "0.02", "rad", "see move_tolerance"),
    )

    def on_tick(self) -> Status:
        if not _folds(self.get("pose")):
            return Status.FAILURE
        here, waypoints = _pose_of(self.get("here")), self.get("waypoints")
        if not isinstance(here, (list, tuple)) or not isinstance(waypoints, (list, tuple)):
            return Status.SUCCESS
        if len(here) != 3 or any(not isinstance(w, (list, tuple)) or len(w) != 3 for w in waypoints):
            raise PortError("%s: here and every waypoint must be [x, y, theta], got %r, %r"
                            % (self.name, here, waypoints))
        x, y, th = (float(v) for v in here)
        for w in waypoints:
            if (math.hypot(float(w[0]) - x, float(w[1]) - y) > self.get("move_tolerance")
                    or abs(wrap_angle(float(w[2]) - th)) > self.get("turn_tolerance")):
                return Status.SUCCESS
        return Status.FAILURE


LIBRARY = (TagIdNameToObjectId, GetTapingPosition, GetTapePath, GetTapeSegments, GetTapePlan, CheckLift, GetLiftHeight,
           GetWallReach, GetAreaRaster, PlanTransit, CheckArmTransit)
