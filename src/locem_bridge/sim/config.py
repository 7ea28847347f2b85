"""Loading and validation of site and robot configuration (YAML) for the simulated worksite.

Two files describe a run: a *site* file (``config/sites/*.yaml``: walls, joints, areas, start pose and the
``simulation`` settings) and a *robot* file (``config/robots/*.yaml``: base, pedestal, arm, tools, device
addresses). :func:`load_site` and :func:`load_robot` return plain dictionaries after checking every key the
simulator uses; errors raise :class:`~locem_bridge.sim.errors.SimConfigError` naming the key path, the value
found and what is allowed. Nothing here touches PyBullet or sockets.
"""
from __future__ import annotations

import math
import os
import re
from typing import Any, Dict, List, Optional, Sequence

import yaml

from .errors import SimConfigError

FEATURE_ID = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
TOOL_NAMES = ("taping_tool", "spray_gun", "sander")
CAN_INTERFACES = ("virtual", "udp_multicast", "socketcan")


def repo_root() -> str:
    """Return the package source checkout root (the folder holding ``config/``), best effort."""
    here = os.path.dirname(os.path.abspath(__file__))
    return os.path.abspath(os.path.join(here, "..", "..", ".."))


def default_site_path() -> str:
    """Path of ``config/sites/default.yaml`` in the source tree."""
    return os.path.join(repo_root(), "config", "sites", "default.yaml")


def default_robot_path() -> str:
    """Path of ``config/robots/rbkairos_ur10e.yaml`` in the source tree."""
    return os.path.join(repo_root(), "config", "robots", "rbkairos_ur10e.yaml")


def _load_yaml(path: str) -> Dict[str, Any]:
    if not os.path.isfile(path):
        raise SimConfigError("configuration file %r does not exist" % path)
    with open(path, "r") as handle:
        try:
            data = yaml.safe_load(handle)
        except yaml.YAMLError as exc:
            raise SimConfigError("configuration file %r is not valid YAML: %s" % (path, exc))
    if not isinstance(data, dict):
        raise SimConfigError("configuration file %r must hold a mapping at the top level" % path)
    return data


def get(d: Dict[str, Any], key: str, path: str, kind: Any = None, default: Any = ...,
        lo: Optional[float] = None, hi: Optional[float] = None, choices: Optional[Sequence[Any]] = None) -> Any:
    """Fetch ``d[key]`` checking type, range and choices; ``path`` names the parent for messages."""
    full = "%s.%s" % (path, key) if path else key
    if not isinstance(d, dict):
        raise SimConfigError("%s must be a mapping, found %r" % (path, d))
    if key not in d:
        if default is ...:
            raise SimConfigError("missing key %s" % full)
        return default
    value = d[key]
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise SimConfigError("%s must be a finite number, found %r" % (full, value))
        value = float(value)
    elif kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SimConfigError("%s must be an integer, found %r" % (full, value))
    elif kind is not None and not isinstance(value, kind):
        raise SimConfigError("%s must be of type %s, found %r" % (full, getattr(kind, "__name__", kind), value))
    if lo is not None and value < lo:
        raise SimConfigError("%s = %r is out of range, allowed >= %r" % (full, value, lo))
    if hi is not None and value > hi:
        raise SimConfigError("%s = %r is out of range, allowed <= %r" % (full, value, hi))
    if choices is not None and value not in choices:
        raise SimConfigError("%s = %r is not allowed, allowed: %s" % (full, value, ", ".join(map(str, choices))))
    return value


def vec(d: Dict[str, Any], key: str, path: str, n: int, default: Any = ...) -> List[float]:
    """Fetch a list of ``n`` finite numbers."""
    full = "%s.%s" % (path, key)
    value = get(d, key, path, default=default)
    if not isinstance(value, (list, tuple)) or len(value) != n or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in value):
        raise SimConfigError("%s must be a list of %d finite numbers, found %r" % (full, n, value))
    return [float(x) for x in value]


def _feature_id(value: Any, full: str) -> str:
    if not isinstance(value, str) or not FEATURE_ID.match(value):
        raise SimConfigError("%s = %r is not a valid feature id, allowed: [A-Za-z][A-Za-z0-9_]*" % (full, value))
    return value


def validate_site(data: Dict[str, Any]) -> Dict[str, Any]:
    """Check a site document (already parsed) and fill defaults; returns the normalised dictionary."""
    site = get(data, "site", "", dict)
    get(site, "name", "site", str)
    room = get(site, "room", "site", dict, default={})
    walls = get(site, "walls", "site", list)
    if not walls:
        raise SimConfigError("site.walls must list at least one wall")
    ids = set()
    for i, wall in enumerate(walls):
        path = "site.walls[%d]" % i
        wid = _feature_id(get(wall, "id", path), path + ".id")
        if wid in ids:
            raise SimConfigError("%s.id = %r is used twice; wall ids must be unique" % (path, wid))
        ids.add(wid)
        wall["material"] = get(wall, "material", path, str, default="plasterboard",
                               choices=("plasterboard", "concrete"))
        p0 = vec(wall, "p0", path, 2)
        p1 = vec(wall, "p1", path, 2)
        if math.hypot(p1[0] - p0[0], p1[1] - p0[1]) < 0.1:
            raise SimConfigError("%s: p0 and p1 are %.3f m apart, allowed >= 0.1 m" % (
                path, math.hypot(p1[0] - p0[0], p1[1] - p0[1])))
        wall["p0"], wall["p1"] = p0, p1
        wall["height"] = get(wall, "height", path, float, lo=0.1, hi=20.0)
        wall["thickness"] = get(wall, "thickness", path, float, default=0.0125, lo=0.001, hi=1.0)
        if wall["material"] == "plasterboard":
            wall["panel_width"] = get(wall, "panel_width", path, float, lo=0.1, hi=100.0)
            wall["joint_width"] = get(wall, "joint_width", path, float, default=0.05, lo=0.001, hi=0.5)
            wall["skirting"] = get(wall, "skirting", path, float, default=0.0, lo=0.0, hi=wall["height"] / 2.0)
            hj = get(wall, "horizontal_joints", path, list, default=[])
            for k, h in enumerate(hj):
                if isinstance(h, bool) or not isinstance(h, (int, float)) or not wall["skirting"] < h < wall["height"]:
                    raise SimConfigError("%s.horizontal_joints[%d] = %r must be a height in (%g, %g) (above the "
                                         "skirting, below the wall top)" % (path, k, h, wall["skirting"],
                                                                            wall["height"]))
            wall["horizontal_joints"] = [float(h) for h in hj]
            areas = get(wall, "areas", path, list, default=[])
            for k, area in enumerate(areas):
                apath = "%s.areas[%d]" % (path, k)
                area["id"] = _feature_id(get(area, "id", apath), apath + ".id")
                area["s"] = vec(area, "s", apath, 2)
                area["t"] = vec(area, "t", apath, 2)
            wall["areas"] = areas
    room["inside"] = vec(room, "inside", "site.room", 2, default=None) if room.get("inside") is not None else None
    room["floor_size"] = vec(room, "floor_size", "site.room", 2, default=[20.0, 20.0])
    site["room"] = room
    site["robot_start"] = vec(site, "robot_start", "site", 3, default=[0.0, 0.0, 0.0])
    sim = get(data, "simulation", "", dict, default={})
    sim["time_scale"] = get(sim, "time_scale", "simulation", float, default=1.0, lo=0.01, hi=100.0)
    sim["world_rate"] = get(sim, "world_rate", "simulation", float, default=50.0, lo=1.0, hi=1000.0)
    sim["seed"] = get(sim, "seed", "simulation", int, default=1)
    sim["gui"] = get(sim, "gui", "simulation", bool, default=False)
    perc = get(sim, "perception", "simulation", dict, default={})
    perc["position_noise"] = get(perc, "position_noise", "simulation.perception", float, default=0.0, lo=0.0, hi=1.0)
    sim["perception"] = perc
    out = get(sim, "outcome", "simulation", dict, default={})
    p = "simulation.outcome"
    out["grid"] = get(out, "grid", p, float, default=0.02, lo=0.002, hi=0.5)
    out["tape_lateral_tolerance"] = get(out, "tape_lateral_tolerance", p, float, default=0.015, lo=0.0, hi=0.5)
    out["contact_tolerance"] = get(out, "contact_tolerance", p, float, default=0.01, lo=0.0, hi=0.5)
    out["spray_rate"] = get(out, "spray_rate", p, float, default=0.002, lo=0.0, hi=1.0)
    out["spray_target_thickness"] = get(out, "spray_target_thickness", p, float, default=0.001, lo=1e-6, hi=0.1)
    sim["outcome"] = out
    data["simulation"] = sim
    return data


def validate_robot(data: Dict[str, Any]) -> Dict[str, Any]:
    """Check a robot document (already parsed); returns the normalised dictionary."""
    robot = get(data, "robot", "", dict)
    get(robot, "name", "robot", str)
    base = get(robot, "base", "robot", dict)
    get(base, "kind", "robot.base", str, choices=("mecanum",))
    ch = get(base, "chassis", "robot.base", dict)
    for key in ("length", "width", "height"):
        ch[key] = get(ch, key, "robot.base.chassis", float, lo=0.05, hi=5.0)
    ch["clearance"] = get(ch, "clearance", "robot.base.chassis", float, default=0.05, lo=0.0, hi=1.0)
    wheel = get(base, "wheel", "robot.base", dict)
    for key in ("radius", "width", "half_wheelbase", "half_track"):
        wheel[key] = get(wheel, key, "robot.base.wheel", float, lo=0.005, hi=5.0)
    lim = get(base, "limits", "robot.base", dict)
    for key in ("max_wheel_speed", "max_linear_velocity", "max_angular_velocity"):
        lim[key] = get(lim, key, "robot.base.limits", float, lo=0.0)
    drv = get(base, "drives", "robot.base", dict)
    p = "robot.base.drives"
    can = get(drv, "can", p, dict)
    can["interface"] = get(can, "interface", p + ".can", str, choices=CAN_INTERFACES)
    can["channel"] = str(get(can, "channel", p + ".can"))
    can["bitrate"] = get(can, "bitrate", p + ".can", int, default=1000000, lo=10000, hi=1000000)
    if "port" in can:
        can["port"] = get(can, "port", p + ".can", int, lo=1, hi=65535)
    drv["heartbeat_ms"] = get(drv, "heartbeat_ms", p, int, lo=0, hi=65535)
    drv["consumer_timeout_factor"] = get(drv, "consumer_timeout_factor", p, float, default=1.5, lo=1.0, hi=10.0)
    drv["tpdo_period_ms"] = get(drv, "tpdo_period_ms", p, int, lo=1, hi=65535)
    drv["velocity_units_per_rad_s"] = get(drv, "velocity_units_per_rad_s", p, float, lo=1e-6)
    drv["counts_per_rad"] = get(drv, "counts_per_rad", p, float, lo=1e-6)
    drv["profile_acceleration"] = get(drv, "profile_acceleration", p, float, lo=1e-3)
    wheels = get(drv, "wheels", p, list)
    if len(wheels) != 4:
        raise SimConfigError("%s.wheels must list 4 wheels (front_left, front_right, rear_left, rear_right),"
                             " found %d" % (p, len(wheels)))
    seen = set()
    for i, w in enumerate(wheels):
        wp = "%s.wheels[%d]" % (p, i)
        get(w, "name", wp, str)
        nid = get(w, "node_id", wp, int, lo=1, hi=127)
        if nid in seen:
            raise SimConfigError("%s.node_id = %d is used twice; CAN node ids must be unique" % (wp, nid))
        seen.add(nid)
        get(w, "polarity", wp, int, choices=(1, -1))
    ped = get(robot, "pedestal", "robot", dict)
    ped["height"] = get(ped, "height", "robot.pedestal", float, lo=0.0, hi=3.0)
    ped["size"] = vec(ped, "size", "robot.pedestal", 2)
    ped["xy"] = vec(ped, "xy", "robot.pedestal", 2)
    arm = get(robot, "arm", "robot", dict)
    mount = get(arm, "mount", "robot.arm", dict)
    mount["xyz"] = vec(mount, "xyz", "robot.arm.mount", 3)
    mount["rpy"] = vec(mount, "rpy", "robot.arm.mount", 3)
    names = get(arm, "joint_names", "robot.arm", list)
    if len(names) != 6:
        raise SimConfigError("robot.arm.joint_names must list 6 joints, found %d" % len(names))
    poses = get(arm, "named_poses", "robot.arm", dict, default={})
    for name in list(poses):
        poses[name] = vec(poses, name, "robot.arm.named_poses", 6)
    ctl = get(arm, "controller", "robot.arm", dict)
    get(ctl, "host", "robot.arm.controller", str)
    tools = get(robot, "tools", "robot", dict)
    for name in TOOL_NAMES:
        tp = "robot.tools.%s" % name
        tool = get(tools, name, "robot.tools", dict)
        tool["tcp"] = vec(tool, "tcp", tp, 6)
        tool["mass"] = get(tool, "mass", tp, float, lo=0.0, hi=12.5)
        tool["cog"] = vec(tool, "cog", tp, 3, default=[0.0, 0.0, 0.0])
        sw = get(tool, "switch", tp, dict)
        src = get(sw, "source", tp + ".switch", str, choices=("ur_digital_out", "compressor_valve"))
        if src == "ur_digital_out":
            get(sw, "index", tp + ".switch", int, lo=0, hi=7)
        body = get(tool, "body", tp, dict, default={"radius": 0.05, "length": 0.15})
        body["radius"] = get(body, "radius", tp + ".body", float, lo=0.005, hi=0.5)
        body["length"] = get(body, "length", tp + ".body", float, lo=0.005, hi=1.0)
        tool["body"] = body
    tools["taping_tool"]["tape_width"] = get(tools["taping_tool"], "tape_width", "robot.tools.taping_tool",
                                             float, default=0.05, lo=0.005, hi=0.5)
    sg = tools["spray_gun"]
    sg["spray_half_angle"] = get(sg, "spray_half_angle", "robot.tools.spray_gun", float, default=0.35,
                                 lo=0.01, hi=1.4)
    sg["standoff"] = get(sg, "standoff", "robot.tools.spray_gun", float, default=0.3, lo=0.02, hi=2.0)
    sd = tools["sander"]
    sd["pad_radius"] = get(sd, "pad_radius", "robot.tools.sander", float, default=0.1, lo=0.005, hi=0.5)
    comp = get(robot, "compressor", "robot", dict)
    cp = "robot.compressor"
    get(comp, "host", cp, str)
    comp["port"] = get(comp, "port", cp, int, lo=1, hi=65535)
    comp["device_id"] = get(comp, "device_id", cp, int, default=1, lo=0, hi=247)
    comp["pressure_range"] = vec(comp, "pressure_range", cp, 2)
    comp["max_setpoint"] = get(comp, "max_setpoint", cp, float, lo=0.1, hi=600.0)
    csim = get(comp, "sim", cp, dict, default={})
    for key, dflt in (("time_constant", 2.0), ("max_pressure", 10.0), ("valve_drop", 1.0),
                      ("idle_current", 0.5), ("current_per_bar", 1.2), ("overpressure_limit", 9.0)):
        csim[key] = get(csim, key, cp + ".sim", float, default=dflt, lo=0.0)
    if csim["time_constant"] <= 0.0:
        raise SimConfigError("robot.compressor.sim.time_constant must be > 0, found %r" % csim["time_constant"])
    comp["sim"] = csim
    sc = get(robot, "scanner", "robot", dict)
    smount = get(sc, "mount", "robot.scanner", dict)
    smount["xyz"] = vec(smount, "xyz", "robot.scanner.mount", 3)
    smount["yaw"] = get(smount, "yaw", "robot.scanner.mount", float, default=0.0)
    sc["range"] = get(sc, "range", "robot.scanner", float, lo=0.1, hi=100.0)
    sc["fov"] = get(sc, "fov", "robot.scanner", float, lo=0.01, hi=2 * math.pi)
    return data


def load_site(path: Optional[str] = None) -> Dict[str, Any]:
    """Load and validate a site file (default: ``config/sites/default.yaml``)."""
    path = path or default_site_path()
    data = validate_site(_load_yaml(path))
    data["_path"] = os.path.abspath(path)
    return data


def load_robot(path: Optional[str] = None) -> Dict[str, Any]:
    """Load and validate a robot file (default: ``config/robots/rbkairos_ur10e.yaml``)."""
    path = path or default_robot_path()
    data = validate_robot(_load_yaml(path))
    data["_path"] = os.path.abspath(path)
    return data


def resolve_relative(cfg: Dict[str, Any], rel: str) -> str:
    """Resolve ``rel`` against the folder of the file ``cfg`` was loaded from."""
    if os.path.isabs(rel):
        return rel
    return os.path.join(os.path.dirname(cfg.get("_path", os.getcwd())), rel)
