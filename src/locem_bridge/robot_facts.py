"""The robot facts the trees and LOCEM's argument ranges need, derived in one place from the robot file.

The robot file (``config/robots/*.yaml``, :mod:`locem_bridge.robot_file`) holds what was measured on one robot:
per tool its TCP offset, its working width (spray fan, pad, tape) and its ``wall_work`` block (flange distance
from the base centre while the tool works at the wall, lateral reach, height band, longest line); the arm's
reach. This module turns them into the numbers the executive uses, with the formulas below (unit-tested in
``test/test_robot_facts.py``). Process tuning (lane overlap, the lane run-in room) is not a robot fact: it comes
from the HICEM parameters, passed in as ``tuning`` (the HICEM section named like the work, e.g. ``spray``).

HICEM puts the result on the root blackboard (:meth:`RobotFacts.blackboard_entries`):

==================================  ================================================================================
``robot.name``                      the robot file's ``robot.name``
``robot.tools``                     the tool names (``MOUNT_TOOL``'s choices)
``robot.reach``                     m, the arm's reach (``robot.arm.reach``)
``robot.tcp_bound``                 m, largest TCP coordinate LOCEM accepts: reach + the longest tool's TCP offset
``robot.work.<work>.tool``          the tool that does the work
``robot.work.<work>.base_standoff`` m, base centre to wall: flange_distance + tool length + tool standoff
``robot.work.<work>.tool_standoff`` m, TCP to wall while working (the tool's ``standoff``; 0 for contact tools)
``robot.work.<work>.work_width``    m, width worked by one pass: spray fan on the wall, pad diameter, tape width
``robot.arm.transit_pose``          the named arm pose the arm folds into while the base drives
                                    (``robot.arm.transit_pose``: a non-holonomic base turns in place, and the arm
                                    held out at 'wall_ready' would sweep into a wall beside it); '' when the arm
                                    stays where it is (at 'wall_ready')
``robot.lift.fitted``               true when the arm rides on a lift (``robot.lift``), else false
``robot.lift.range``                m, [bottom, top] arm mount heights of the lift (``lift.range``); [] without one
``robot.work.<work>.z_band``        m, [z_min, z_max] reached from one base pose and one lift height: with a lift,
                                    at the lift's bottom (``wall_work.z_band``); the band rides up with the lift
``robot.work.<work>.z_range``       m, [z_min, z_max] reached from one base pose: z_band, its top raised by the
                                    lift's travel (top - bottom of ``lift.range``; 0 without a lift)
``robot.work.<work>.band_height``   m, tallest strip worked from one lift height: z_band's span with a lift (areas
                                    are raster in bands no taller); 0 without one (an area is one band)
``robot.work.<work>.lateral_reach`` m, to either side of the base axis (``wall_work.lateral_reach``)
``robot.work.<work>.segment_length``  m, longest line worked from one pose (``wall_work.line_length``)
``robot.work.<work>.section_width`` m, 2 x (lateral_reach - tuning lane_overrun); only with ``lane_overrun``
``robot.work.<work>.lane_spacing``  m, work_width x tuning lane_ratio, rounded down to whole mm; only with
                                    ``lane_ratio``
``robot.work.<work>.tip_radius``    m, radius of the tool's working end (a pad's radius; else its body's)
``robot.work.<work>.body_radius``   m, radius of the tool's body (``body.radius``)
``robot.base.footprint``            m, [length, width] of the chassis (``base.chassis``), centred on the base frame
``robot.arm.shoulder_x``            m, the arm's mount ahead of the base centre (``arm.mount.xyz[0]``)
==================================  ================================================================================

Lengths are rounded to 0.1 mm (so 0.82 + 0.18 + 0.30 is 1.30, not 1.3000000000000003).
"""
import math
from typing import Any, Callable, Dict, List, Mapping, Optional

from .common.config_errors import ConfigError
from .robot_file import RobotFileError, load_robot

# the HICEM parameter keys (in the section named like the work) the derivation reads
TUNING_KEYS = ("lane_ratio", "lane_overrun")


def _r(value: float) -> float:
    """A length rounded to 0.1 mm (float noise of sums and products gone)."""
    return round(float(value), 4) + 0.0


def tool_length(tool: Mapping[str, Any]) -> float:
    """m, TCP distance from the flange along the tool axis (flange z): the TCP offset's z."""
    return _r(tool["tcp"][2])


def tool_standoff(tool: Mapping[str, Any]) -> float:
    """m, TCP to wall while the tool works: its ``standoff`` (a spray gun's nozzle distance), 0 for contact tools."""
    return _r(tool.get("standoff", 0.0))


def work_width(tool: Mapping[str, Any]) -> float:
    """m, width one pass of the tool works on the wall: a spray fan 2 standoff tan(half angle), a pad's diameter,
    or the tape width (0 when the tool declares none of them)."""
    if "spray_half_angle" in tool:
        return _r(2.0 * float(tool.get("standoff", 0.0)) * math.tan(float(tool["spray_half_angle"])))
    if "pad_radius" in tool:
        return _r(2.0 * float(tool["pad_radius"]))
    return _r(tool.get("tape_width", 0.0))


def base_standoff(flange_distance: float, length: float, standoff: float) -> float:
    """m, base centre to wall along its normal: the flange's distance ahead of the base centre while working, plus
    the tool's length, plus the TCP's distance from the wall."""
    return _r(flange_distance + length + standoff)


def section_width(lateral_reach: float, lane_overrun: float) -> float:
    """m, widest strip worked from one base pose: the TCP reaches ``lateral_reach`` to either side and a lane needs
    ``lane_overrun`` beyond the strip at each end (run-in, run-up before the tool switches on)."""
    return _r(2.0 * (lateral_reach - lane_overrun))


def lane_spacing(width: float, lane_ratio: float) -> float:
    """m, raster lane pitch: ``lane_ratio`` of the work width, rounded down to whole millimetres (lanes never
    further apart than the ratio asks)."""
    return math.floor(width * lane_ratio * 1000.0 + 1e-6) / 1000.0


def tcp_bound(robot: Mapping[str, Any]) -> float:
    """m, largest |x|, |y|, |z| of a TCP position (and of a TCP offset) LOCEM accepts in the arm base frame: the
    arm's reach plus the longest tool's TCP offset."""
    longest = max([math.sqrt(sum(float(c) ** 2 for c in t["tcp"][:3])) for t in robot.get("tools", {}).values()]
                  or [0.0])
    return _r(float(robot["arm"]["reach"]) + longest)


class WorkFacts:
    """The derived numbers of one wall work (one tool)."""

    def __init__(self, work: str, tool: str, entries: Dict[str, Any]) -> None:
        self.work = work
        self.tool = tool
        self.entries = entries

    def __getitem__(self, key: str) -> Any:
        return self.entries[key]


class RobotFacts:
    """Every derived robot fact: ``work`` (work name -> :class:`WorkFacts`), ``tools``, ``reach``, ``tcp_bound``."""

    def __init__(self, name: str, tools: List[str], reach: float, bound: float, work: Dict[str, WorkFacts],
                 path: str = "", lift_range: Optional[List[float]] = None, transit_pose: str = "",
                 footprint: Optional[List[float]] = None, shoulder_x: float = 0.0) -> None:
        self.name = name
        #: [length, width] of the chassis; the arm's mount ahead of the base centre
        self.footprint = list(footprint or [0.0, 0.0])
        self.shoulder_x = shoulder_x
        #: named arm pose for driving ('' = the arm stays where it is)
        self.transit_pose = transit_pose
        #: [bottom, top] of the lift carrying the arm; None without a lift
        self.lift_range = lift_range
        self.tools = tools
        self.reach = reach
        self.tcp_bound = bound
        self.work = work
        self.path = path

    def blackboard_entries(self, prefix: str = "robot") -> Dict[str, Any]:
        """``robot.*`` entries (every leaf and every sub-mapping under its dotted path, as ``cfg.*``)."""
        out: Dict[str, Any] = {prefix + ".name": self.name, prefix + ".tools": list(self.tools),
                               prefix + ".reach": self.reach, prefix + ".tcp_bound": self.tcp_bound,
                               prefix + ".arm.transit_pose": self.transit_pose,
                               prefix + ".lift.fitted": self.lift_range is not None,
                               prefix + ".lift.range": list(self.lift_range or []),
                               prefix + ".base.footprint": list(self.footprint),
                               prefix + ".arm.shoulder_x": self.shoulder_x}
        works: Dict[str, Any] = {}
        for name, facts in self.work.items():
            entry = dict(facts.entries, tool=facts.tool)
            works[name] = entry
            out["%s.work.%s" % (prefix, name)] = entry
            for key, value in entry.items():
                out["%s.work.%s.%s" % (prefix, name, key)] = value
        out[prefix + ".work"] = works
        return out


def _tuning(tuning: Mapping[str, Any], work: str, key: str, ok: Callable[[float], bool],
            allowed: str) -> Optional[float]:
    """``tuning[work][key]`` (None when absent), a finite number for which ``ok`` holds."""
    section = tuning.get(work)
    if not isinstance(section, Mapping) or key not in section:
        return None
    value = section[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError("must be a finite number, found %r" % (value,), key="%s.%s" % (work, key))
    if not ok(float(value)):
        raise ConfigError("%r is out of range" % (value,), key="%s.%s" % (work, key), allowed=allowed)
    return float(value)


def derive(robot: Mapping[str, Any], tuning: Optional[Mapping[str, Any]] = None, path: str = "") -> RobotFacts:
    """The facts of a validated robot section (``load_robot(...)["robot"]``). ``tuning`` maps a work name to its
    process parameters (:data:`TUNING_KEYS`; the HICEM parameter sections): a bad value raises
    :class:`ConfigError` naming ``<work>.<key>``, as does a ``lane_overrun`` that leaves no strip to work."""
    tuning = tuning or {}
    lift = robot.get("lift")
    lift_range = [_r(z) for z in lift["range"]] if isinstance(lift, Mapping) else None
    travel = lift_range[1] - lift_range[0] if lift_range else 0.0
    works: Dict[str, WorkFacts] = {}
    for name, tool in robot["tools"].items():
        ww = tool["wall_work"]
        work = str(ww["work"])
        length, standoff, width = tool_length(tool), tool_standoff(tool), work_width(tool)
        entries: Dict[str, Any] = {
            "base_standoff": base_standoff(float(ww["flange_distance"]), length, standoff),
            "tool_standoff": standoff, "tool_length": length, "work_width": width,
            "z_band": [_r(z) for z in ww["z_band"]],
            "z_range": [_r(ww["z_band"][0]), _r(ww["z_band"][1] + travel)], "lateral_reach": _r(ww["lateral_reach"]),
            "band_height": _r(ww["z_band"][1] - ww["z_band"][0]) if lift_range else 0.0,
            "segment_length": _r(ww["line_length"]),
            "body_radius": _r(tool["body"]["radius"]),
            "tip_radius": _r(max(float(tool.get("pad_radius", 0.0)), float(tool["body"]["radius"]))),
        }
        reach = float(ww["lateral_reach"])
        overrun = _tuning(tuning, work, "lane_overrun", lambda v: v >= 0.0, ">= 0")
        if overrun is not None:
            entries["section_width"] = section_width(reach, overrun)
            if entries["section_width"] <= 0.0:
                raise ConfigError("%g m leaves no strip within the %s's lateral reach of %g m"
                                  % (overrun, name, reach), key="%s.lane_overrun" % work, allowed="< %g" % reach)
        ratio = _tuning(tuning, work, "lane_ratio", lambda v: 0.0 < v <= 1.0, "> 0 and <= 1")
        if ratio is not None:
            entries["lane_spacing"] = lane_spacing(width, ratio)
            if entries["lane_spacing"] <= 0.0:
                raise ConfigError("%g of the %s's %g m work width is under 1 mm" % (ratio, name, width),
                                  key="%s.lane_ratio" % work)
        works[work] = WorkFacts(work, name, entries)
    return RobotFacts(str(robot.get("name", "")), list(robot["tools"]), _r(robot["arm"]["reach"]), tcp_bound(robot),
                      works, path, lift_range, str(robot["arm"].get("transit_pose") or ""),
                      [_r(robot["base"]["chassis"]["length"]), _r(robot["base"]["chassis"]["width"])],
                      _r(robot["arm"]["mount"]["xyz"][0]))


def load_facts(robot_file: Optional[str] = None, tuning: Optional[Mapping[str, Any]] = None,
               error: Callable[..., ConfigError] = RobotFileError) -> RobotFacts:
    """Load the robot file (default: the shipped one) and derive its facts; a problem of the file raises ``error``
    naming the file (a bad ``tuning`` value raises ``error`` naming its key, without a file: the caller knows
    which parameter file it came from)."""
    doc = load_robot(robot_file, error=error)
    try:
        return derive(doc["robot"], tuning, doc["_path"])
    except ConfigError as exc:
        raise exc.recast(error)


def shipped_tcp_bound() -> float:
    """:func:`tcp_bound` of the shipped robot file (the API documentation's and hardware-free tests' default)."""
    global _SHIPPED_BOUND
    if _SHIPPED_BOUND is None:
        _SHIPPED_BOUND = tcp_bound(load_robot()["robot"])
    return _SHIPPED_BOUND


_SHIPPED_BOUND: Optional[float] = None

