"""Loading and validation of site and robot configuration (YAML) for the simulated worksite.

Two files describe a run: a *site* file (``config/sites/*.yaml``: walls, joints, areas, start pose and the
``simulation`` settings), validated here, and a *robot* file (``config/robots/*.yaml``: base, pedestal, arm,
tools, device addresses), validated by the one robot-file loader every layer uses (:mod:`locem_bridge.robot_file`).
:func:`load_site` and :func:`load_robot` return plain dictionaries; errors raise
:class:`~locem_bridge.sim.errors.SimConfigError` naming the key path, the value found and what is allowed.
Nothing here touches PyBullet or sockets.
"""
from __future__ import annotations

import math
import os
import re
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

from .. import robot_file
from ..common.config_errors import ConfigError
from ..common.config_keys import get, item, load_mapping, only, vec
from ..common.paths import checkout_root
from .errors import SimConfigError

FEATURE_ID = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
# Every key a site file may hold, per mapping (lists' items under their own name). A key not listed is refused
# with its name: a misspelt section would otherwise be ignored. A new key a loader reads is added here too (the
# robot file's keys: locem_bridge.robot_file.ROBOT_KEYS).
SITE_KEYS: Dict[str, Sequence[str]] = {
    "": ("site", "simulation"),
    "site": ("name", "room", "walls", "robot_start"),
    "site.room": ("inside", "floor_size", "ceiling"),
    "wall": ("id", "material", "p0", "p1", "height", "thickness", "panel_width", "joint_width", "skirting",
             "horizontal_joints", "areas", "openings"),
    "area": ("id", "s", "t"),
    "opening": ("id", "kind", "s", "t", "frame"),
    "simulation": ("time_scale", "world_rate", "seed", "gui", "perception", "outcome"),
    "simulation.perception": ("position_noise",),
    "simulation.outcome": ("grid", "tape_lateral_tolerance", "contact_tolerance", "spray_rate",
                           "spray_target_thickness"),
}


def default_site_path(root: str = "") -> str:
    """Path of ``config/sites/default.yaml`` in the package folder ``root`` (default: the source tree)."""
    return os.path.join(root or checkout_root(), "config", "sites", "default.yaml")


def _feature_id(value: Any, full: str) -> str:
    if not isinstance(value, str) or not FEATURE_ID.match(value):
        raise SimConfigError("%r is not a valid feature id" % (value,), key=full, allowed="[A-Za-z][A-Za-z0-9_]*")
    return value


def _unique_id(d: Dict[str, Any], path: str, ids: set, what: str = "feature") -> str:
    """``d["id"]``, a valid feature id not in ``ids`` (then added): wall, opening and area ids share one space."""
    fid = _feature_id(get(d, "id", path), path + ".id")
    if fid in ids:
        raise SimConfigError("%r is used twice; %s ids must be unique" % (fid, what), key=path + ".id")
    ids.add(fid)
    return fid


def _interval(item: Dict[str, Any], key: str, path: str, lo: float, hi: float) -> List[float]:
    a, b = vec(item, key, path, 2)
    if not lo - 1e-9 <= a < b <= hi + 1e-9:
        raise SimConfigError("[%g, %g] is not an interval inside the wall" % (a, b), key="%s.%s" % (path, key),
                             allowed="%g <= first < second <= %g m" % (lo, hi))
    return [a, b]


def _openings(wall: Dict[str, Any], path: str, ids: set) -> List[Dict[str, Any]]:
    """The wall's door and window openings (``s``, ``t``: the clear opening in wall coordinates; ``frame``: the
    width of the frame around it, in the wall plane), checked: inside the wall with their frames, a door
    standing on the floor, a window above it, no two overlapping."""
    length = math.hypot(wall["p1"][0] - wall["p0"][0], wall["p1"][1] - wall["p0"][1])
    out = []
    for k, op in enumerate(get(wall, "openings", path, list, default=[])):
        opath = "%s.openings[%d]" % (path, k)
        item(op, opath, SITE_KEYS["opening"])
        oid = _unique_id(op, opath, ids)
        kind = get(op, "kind", opath, str, choices=("door", "window"))
        frame = get(op, "frame", opath, float, default=0.05, lo=0.0, hi=0.3)
        s = _interval(op, "s", opath, frame, length - frame)
        if kind == "door":
            t = _interval(op, "t", opath, 0.0, wall["height"] - frame)
            if t[0] != 0.0:
                raise SimConfigError("a door starts at the floor, found t from %g m" % t[0], key=opath + ".t",
                                     allowed="t: [0, top]; an opening above the floor is a window")
        else:
            if vec(op, "t", opath, 2)[0] <= 0.0:
                raise SimConfigError("a window starts above the floor", key=opath + ".t",
                                     allowed="t[0] >= frame (%g m); an opening at the floor is a door" % frame)
            t = _interval(op, "t", opath, frame, wall["height"] - frame)
        for other in out:
            if (s[0] - frame < other["s"][1] + other["frame"] and other["s"][0] - other["frame"] < s[1] + frame
                    and t[0] - frame < other["t"][1] + other["frame"]
                    and other["t"][0] - other["frame"] < t[1] + frame):
                raise SimConfigError("overlaps opening %r (with their frames)" % other["id"], key=opath,
                                     allowed="openings apart, frames included")
        out.append({"id": oid, "kind": kind, "s": s, "t": t, "frame": frame})
    return out


def _area_not_in_opening(area: Dict[str, Any], wall: Dict[str, Any], apath: str) -> None:
    s0, s1 = sorted(area["s"])
    t0, t1 = sorted(area["t"])
    for op in wall.get("openings", []):
        f = op["frame"]
        if (op["s"][0] - f <= s0 and s1 <= op["s"][1] + f and (op["t"][0] - f if op["t"][0] > 0 else 0.0) <= t0
                and t1 <= op["t"][1] + f):
            raise SimConfigError("lies inside opening %r: nothing to finish" % op["id"], key=apath)


def validate_site(data: Dict[str, Any]) -> Dict[str, Any]:
    """Check a site document (already parsed) and fill defaults; returns the normalised dictionary."""
    try:
        return _validate_site(data)
    except ConfigError as exc:
        raise exc.recast(SimConfigError)


def _validate_site(data: Dict[str, Any]) -> Dict[str, Any]:
    only(data, "", SITE_KEYS[""])
    site = get(data, "site", "", dict)
    only(site, "site", SITE_KEYS["site"])
    get(site, "name", "site", str)
    room = get(site, "room", "site", dict, default={})
    only(room, "site.room", SITE_KEYS["site.room"])
    walls = get(site, "walls", "site", list)
    if not walls:
        raise SimConfigError("must list at least one wall", key="site.walls")
    ids: set = set()
    for i, wall in enumerate(walls):
        path = "site.walls[%d]" % i
        if not isinstance(wall, dict):
            raise SimConfigError("must be a mapping, found %r" % (wall,), key=path)
        only(wall, path, SITE_KEYS["wall"])
        _unique_id(wall, path, ids, "wall")
        wall["material"] = get(wall, "material", path, str, default="plasterboard",
                               choices=("plasterboard", "concrete"))
        p0 = vec(wall, "p0", path, 2)
        p1 = vec(wall, "p1", path, 2)
        if math.hypot(p1[0] - p0[0], p1[1] - p0[1]) < 0.1:
            raise SimConfigError("p0 and p1 are %.3f m apart" % math.hypot(p1[0] - p0[0], p1[1] - p0[1]),
                                 key=path, allowed=">= 0.1 m")
        wall["p0"], wall["p1"] = p0, p1
        wall["height"] = get(wall, "height", path, float, lo=0.1, hi=20.0)
        wall["thickness"] = get(wall, "thickness", path, float, default=0.0125, lo=0.001, hi=1.0)
        wall["openings"] = _openings(wall, path, ids)
        if wall["material"] == "plasterboard":
            wall["panel_width"] = get(wall, "panel_width", path, float, lo=0.1, hi=100.0)
            wall["joint_width"] = get(wall, "joint_width", path, float, default=0.05, lo=0.001, hi=0.5)
            wall["skirting"] = get(wall, "skirting", path, float, default=0.0, lo=0.0, hi=wall["height"] / 2.0)
            hj = get(wall, "horizontal_joints", path, list, default=[])
            for k, h in enumerate(hj):
                if isinstance(h, bool) or not isinstance(h, (int, float)) or not wall["skirting"] < h < wall["height"]:
                    raise SimConfigError("%r is not a height above the skirting and below the wall top" % (h,),
                                         key="%s.horizontal_joints[%d]" % (path, k),
                                         allowed="(%g, %g)" % (wall["skirting"], wall["height"]))
            wall["horizontal_joints"] = [float(h) for h in hj]
            areas = get(wall, "areas", path, list, default=[])
            for k, area in enumerate(areas):
                apath = "%s.areas[%d]" % (path, k)
                item(area, apath, SITE_KEYS["area"])
                area["id"] = _unique_id(area, apath, ids)
                area["s"] = vec(area, "s", apath, 2)
                area["t"] = vec(area, "t", apath, 2)
                _area_not_in_opening(area, wall, apath)
            wall["areas"] = areas
    room["inside"] = vec(room, "inside", "site.room", 2, default=None) if room.get("inside") is not None else None
    room["floor_size"] = vec(room, "floor_size", "site.room", 2, default=[20.0, 20.0])
    room["ceiling"] = (get(room, "ceiling", "site.room", float, lo=0.5, hi=20.0) if room.get("ceiling") is not None
                       else None)
    if room["ceiling"] is not None:
        for i, wall in enumerate(walls):
            if wall["height"] > room["ceiling"] + 1e-9:
                raise SimConfigError("%g m reaches above the ceiling" % wall["height"],
                                     key="site.walls[%d].height" % i, allowed="<= site.room.ceiling (%g m)"
                                     % room["ceiling"])
    site["room"] = room
    site["robot_start"] = vec(site, "robot_start", "site", 3, default=[0.0, 0.0, 0.0])
    sim = get(data, "simulation", "", dict, default={})
    only(sim, "simulation", SITE_KEYS["simulation"])
    sim["time_scale"] = get(sim, "time_scale", "simulation", float, default=1.0, lo=0.01, hi=100.0)
    sim["world_rate"] = get(sim, "world_rate", "simulation", float, default=50.0, lo=1.0, hi=1000.0)
    sim["seed"] = get(sim, "seed", "simulation", int, default=1)
    sim["gui"] = get(sim, "gui", "simulation", bool, default=False)
    perc = get(sim, "perception", "simulation", dict, default={})
    only(perc, "simulation.perception", SITE_KEYS["simulation.perception"])
    perc["position_noise"] = get(perc, "position_noise", "simulation.perception", float, default=0.0, lo=0.0, hi=1.0)
    sim["perception"] = perc
    out = get(sim, "outcome", "simulation", dict, default={})
    p = "simulation.outcome"
    only(out, p, SITE_KEYS[p])
    out["grid"] = get(out, "grid", p, float, default=0.02, lo=0.002, hi=0.5)
    out["tape_lateral_tolerance"] = get(out, "tape_lateral_tolerance", p, float, default=0.015, lo=0.0, hi=0.5)
    out["contact_tolerance"] = get(out, "contact_tolerance", p, float, default=0.01, lo=0.0, hi=0.5)
    out["spray_rate"] = get(out, "spray_rate", p, float, default=0.002, lo=0.0, hi=1.0)
    out["spray_target_thickness"] = get(out, "spray_target_thickness", p, float, default=0.001, lo=1e-6, hi=0.1)
    sim["outcome"] = out
    data["simulation"] = sim
    return data


def find_example_robot_data() -> List[str]:
    """Candidate ``share/example-robot-data`` folders (env override, pip/cmeel wheels, system installs)."""
    dirs = []
    env = os.environ.get("EXAMPLE_ROBOT_DATA_DIR")
    if env:
        dirs.append(env)
    for entry in sys.path:
        cand = os.path.join(entry, "cmeel.prefix", "share", "example-robot-data")
        if os.path.isdir(cand):
            dirs.append(cand)
    dirs += ["/opt/openrobots/share/example-robot-data", "/usr/share/example-robot-data",
             "/opt/ros/noetic/share/example-robot-data"]
    return [d for d in dirs if os.path.isdir(d)]


def resolve_arm_urdf(arm_cfg: Dict[str, Any]) -> Tuple[str, str]:
    """Return (urdf path, package share dir) for ``robot.arm.description``."""
    desc = arm_cfg.get("description", {})
    rel = desc.get("urdf", "robots/ur_description/urdf/ur10_robot.urdf")
    key = "robot.arm.description.urdf"
    if os.path.isabs(rel):
        if not os.path.isfile(rel):
            raise SimConfigError("%s does not exist" % rel, key=key)
        return rel, os.path.dirname(rel)
    for share in find_example_robot_data():
        path = os.path.join(share, rel)
        if os.path.isfile(path):
            return path, share
    raise SimConfigError("%r not found in any example-robot-data install (%s); install example-robot-data or set "
                         "EXAMPLE_ROBOT_DATA_DIR" % (rel, ", ".join(find_example_robot_data()) or "none found"),
                         key=key)


def load_site(path: Optional[str] = None) -> Dict[str, Any]:
    """Load and validate a site file (default: ``config/sites/default.yaml``)."""
    path = path or default_site_path()
    try:
        data = _validate_site(load_mapping(path))
    except ConfigError as exc:
        raise exc.recast(SimConfigError).in_file(path)
    data["_path"] = os.path.abspath(path)
    return data


def load_robot(path: Optional[str] = None, overrides: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """The robot file through the one loader (:func:`locem_bridge.robot_file.load_robot`), a problem as
    :class:`SimConfigError`."""
    return robot_file.load_robot(path, overrides, error=SimConfigError)


def validate_robot(data: Dict[str, Any], base_dir: Optional[str] = None) -> Dict[str, Any]:
    """:func:`locem_bridge.robot_file.validate_robot`, a problem as :class:`SimConfigError`."""
    return robot_file.validate_robot(data, base_dir, error=SimConfigError)


def resolve_relative(cfg: Dict[str, Any], rel: str) -> str:
    """Resolve ``rel`` against the folder of the file ``cfg`` was loaded from."""
    if os.path.isabs(rel):
        return rel
    return os.path.join(os.path.dirname(cfg.get("_path", os.getcwd())), rel)
