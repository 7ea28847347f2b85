"""Loading and validation of site and robot configuration (YAML) for the simulated worksite.

Two files describe a run: a *site* file (``config/sites/*.yaml``: walls, joints, areas, start pose and the
``simulation`` settings) and a *robot* file (``config/robots/*.yaml``: base, pedestal, arm, tools, device
addresses). :func:`load_site` and :func:`load_robot` return plain dictionaries after checking every key the
simulator uses; errors raise :class:`~locem_bridge.sim.errors.SimConfigError` naming the key path, the value
found and what is allowed. Nothing here touches PyBullet or sockets.
"""
from __future__ import annotations

import copy
import math
import os
import re
import sys
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from ..common.can_bus import CAN_INTERFACES
from ..common.config_errors import read_yaml
from .errors import SimConfigError

FEATURE_ID = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
TOOL_NAMES = ("taping_tool", "spray_gun", "sander")
ARM_BACKENDS = ("ur_rtde",)
# The ports ur_rtde dials: its RTDEControlInterface / RTDEReceiveInterface / RTDEIOInterface take a host and no
# port, so a UR controller on other ports cannot be reached by the arm bridge (another robot takes another
# address). The UR stand-in itself takes any ports (Worksite(ur_ports=...)) for its own tests.
UR_RTDE_PORTS = {"dashboard_port": 29999, "script_port": 30003, "rtde_port": 30004}

# Every key a site or robot file may hold, per mapping (lists' items under their own name). A key not listed is
# refused with its name: a misspelt section would otherwise be ignored and its device left out or on defaults.
# A new key a loader reads is added here too.
SITE_KEYS: Dict[str, Sequence[str]] = {
    "": ("site", "simulation"),
    "site": ("name", "room", "walls", "robot_start"),
    "site.room": ("inside", "floor_size"),
    "wall": ("id", "material", "p0", "p1", "height", "thickness", "panel_width", "joint_width", "skirting",
             "horizontal_joints", "areas"),
    "area": ("id", "s", "t"),
    "simulation": ("time_scale", "world_rate", "seed", "gui", "perception", "outcome"),
    "simulation.perception": ("position_noise",),
    "simulation.outcome": ("grid", "tape_lateral_tolerance", "contact_tolerance", "spray_rate",
                           "spray_target_thickness"),
}
ROBOT_KEYS: Dict[str, Sequence[str]] = {
    "": ("robot",),
    "robot": ("name", "namespace", "base", "pedestal", "arm", "tools", "compressor", "scanner"),
    "robot.base": ("kind", "frame", "control_rate", "localisation_window", "named_poses", "chassis", "wheel",
                   "limits", "drives", "eds", "deadline"),
    "robot.base.chassis": ("length", "width", "height", "clearance", "mass"),
    "robot.base.wheel": ("radius", "width", "half_wheelbase", "half_track"),
    "robot.base.limits": ("max_wheel_speed", "max_linear_velocity", "max_angular_velocity", "linear_acceleration",
                          "angular_acceleration"),
    "robot.base.drives": ("profile", "mode", "can", "master_node_id", "master_timeout_ms", "heartbeat_ms",
                          "consumer_timeout_factor",
                          "tpdo_period_ms", "velocity_units_per_rad_s", "counts_per_rad", "profile_acceleration",
                          "stop_deceleration", "wheels"),
    "robot.base.drives.can": ("interface", "channel", "port", "bitrate"),
    "wheel": ("name", "node_id", "polarity"),
    "deadline": ("scale", "margin"),
    "robot.pedestal": ("height", "size", "xy"),
    "robot.arm": ("backend", "model", "description", "mount", "joint_names", "controller", "named_poses",
                  "home_via", "wall_ready_flange", "deadline"),
    "robot.arm.description": ("package", "urdf"),
    "robot.arm.mount": ("xyz", "rpy"),
    "robot.arm.controller": ("host", "dashboard_port", "script_port", "rtde_port", "rtde_frequency",
                             "watchdog_frequency"),
    "robot.tools": TOOL_NAMES,
    "tool": ("tcp", "mass", "cog", "switch", "body"),
    "robot.tools.taping_tool": ("tape_width",),
    "robot.tools.spray_gun": ("spray_half_angle", "standoff"),
    "robot.tools.sander": ("pad_radius",),
    "switch": ("source", "index"),
    "body": ("radius", "length"),
    "robot.compressor": ("protocol", "host", "port", "device_id", "timeout", "watchdog_timeout", "pressure_range",
                         "max_setpoint", "sim"),
    "robot.compressor.sim": ("time_constant", "max_pressure", "valve_drop", "idle_current", "current_per_bar",
                             "overpressure_limit"),
    "robot.scanner": ("backend", "mount", "range", "fov"),
    "robot.scanner.mount": ("xyz", "yaw"),
}


def repo_root() -> str:
    """Return the package source checkout root (the folder holding ``config/``), best effort."""
    here = os.path.dirname(os.path.abspath(__file__))
    return os.path.abspath(os.path.join(here, "..", "..", ".."))


def default_site_path(root: str = "") -> str:
    """Path of ``config/sites/default.yaml`` in the package folder ``root`` (default: the source tree)."""
    return os.path.join(root or repo_root(), "config", "sites", "default.yaml")


def default_robot_path(root: str = "") -> str:
    """Path of ``config/robots/rbkairos_ur10e.yaml`` in the package folder ``root`` (default: the source tree)."""
    return os.path.join(root or repo_root(), "config", "robots", "rbkairos_ur10e.yaml")


def _load_yaml(path: str) -> Dict[str, Any]:
    if not os.path.isfile(path):
        raise SimConfigError("file does not exist" if not os.path.exists(path) else "is not a file", file=path)
    data = read_yaml(path, SimConfigError)
    if not isinstance(data, dict):
        raise SimConfigError("must hold a mapping at the top level, found %s" % type(data).__name__, file=path)
    return data


def only(d: Any, path: str, keys: Sequence[str]) -> None:
    """Refuse a key of mapping ``d`` (at ``path``) that is not in ``keys``: a misspelt section must not be
    silently ignored (the device it configures would start with defaults or not at all)."""
    if not isinstance(d, dict):
        return
    for key in d:
        if key not in keys and not (isinstance(key, str) and key.startswith("_")):
            raise SimConfigError("unknown key", key="%s.%s" % (path, key) if path else str(key),
                                 allowed=sorted(keys))


def get(d: Dict[str, Any], key: str, path: str, kind: Any = None, default: Any = ...,
        lo: Optional[float] = None, hi: Optional[float] = None, choices: Optional[Sequence[Any]] = None) -> Any:
    """Fetch ``d[key]`` checking type, range and choices; ``path`` names the parent for messages."""
    full = "%s.%s" % (path, key) if path else key
    if not isinstance(d, dict):
        raise SimConfigError("must be a mapping, found %r" % (d,), key=path or "(top level)")
    if key not in d:
        if default is ...:
            raise SimConfigError("missing key", key=full, allowed=choices)
        return default
    value = d[key]
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise SimConfigError("must be a finite number, found %r" % (value,), key=full)
        value = float(value)
    elif kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SimConfigError("must be an integer, found %r" % (value,), key=full)
    elif kind is not None and not isinstance(value, kind):
        raise SimConfigError("must be of type %s, found %r" % (_kind_name(kind), value), key=full)
    if lo is not None and value < lo:
        raise SimConfigError("%r is out of range" % (value,), key=full, allowed=">= %r" % (lo,))
    if hi is not None and value > hi:
        raise SimConfigError("%r is out of range" % (value,), key=full, allowed="<= %r" % (hi,))
    if choices is not None and value not in choices:
        raise SimConfigError("%r is not allowed" % (value,), key=full, allowed=choices)
    return value


def _kind_name(kind: Any) -> str:
    names = {dict: "mapping", list: "list", str: "string", bool: "boolean (true or false)"}
    return names.get(kind, getattr(kind, "__name__", str(kind)))


def vec(d: Dict[str, Any], key: str, path: str, n: int, default: Any = ...) -> List[float]:
    """Fetch a list of ``n`` finite numbers."""
    full = "%s.%s" % (path, key)
    value = get(d, key, path, default=default)
    if not isinstance(value, (list, tuple)) or len(value) != n or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in value):
        raise SimConfigError("must be a list of %d finite numbers, found %r" % (n, value), key=full)
    return [float(x) for x in value]


def _feature_id(value: Any, full: str) -> str:
    if not isinstance(value, str) or not FEATURE_ID.match(value):
        raise SimConfigError("%r is not a valid feature id" % (value,), key=full, allowed="[A-Za-z][A-Za-z0-9_]*")
    return value


def validate_site(data: Dict[str, Any]) -> Dict[str, Any]:
    """Check a site document (already parsed) and fill defaults; returns the normalised dictionary."""
    only(data, "", SITE_KEYS[""])
    site = get(data, "site", "", dict)
    only(site, "site", SITE_KEYS["site"])
    get(site, "name", "site", str)
    room = get(site, "room", "site", dict, default={})
    only(room, "site.room", SITE_KEYS["site.room"])
    walls = get(site, "walls", "site", list)
    if not walls:
        raise SimConfigError("must list at least one wall", key="site.walls")
    ids = set()
    for i, wall in enumerate(walls):
        path = "site.walls[%d]" % i
        if not isinstance(wall, dict):
            raise SimConfigError("must be a mapping, found %r" % (wall,), key=path)
        only(wall, path, SITE_KEYS["wall"])
        wid = _feature_id(get(wall, "id", path), path + ".id")
        if wid in ids:
            raise SimConfigError("%r is used twice; wall ids must be unique" % (wid,), key=path + ".id")
        ids.add(wid)
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
                if not isinstance(area, dict):
                    raise SimConfigError("must be a mapping, found %r" % (area,), key=apath)
                only(area, apath, SITE_KEYS["area"])
                area["id"] = _feature_id(get(area, "id", apath), apath + ".id")
                area["s"] = vec(area, "s", apath, 2)
                area["t"] = vec(area, "t", apath, 2)
            wall["areas"] = areas
    room["inside"] = vec(room, "inside", "site.room", 2, default=None) if room.get("inside") is not None else None
    room["floor_size"] = vec(room, "floor_size", "site.room", 2, default=[20.0, 20.0])
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


def _mapping(parent: Dict[str, Any], key: str, path: str, keys: Sequence[str], default: Any = ...) -> Dict[str, Any]:
    """``parent[key]`` as a mapping whose keys are all in ``keys``."""
    value = get(parent, key, path, dict, default=default)
    only(value, "%s.%s" % (path, key) if path else key, keys)
    return value


def _item(value: Any, path: str, keys: Sequence[str]) -> Dict[str, Any]:
    if not isinstance(value, dict):
        raise SimConfigError("must be a mapping, found %r" % (value,), key=path)
    only(value, path, keys)
    return value


def _backend(section: Dict[str, Any], key: str, path: str, kind: str, default: str) -> str:
    from ..bridges.backends import BACKENDS      # the bridges' name -> backend table (imports no device library)
    return get(section, key, path, str, default=default, choices=sorted(BACKENDS[kind]))


def _deadline(section: Dict[str, Any], path: str) -> None:
    """``deadline: {scale, margin}`` of a motion device (the bridges' defaults apply to what is left out)."""
    dl = _mapping(section, "deadline", path, ROBOT_KEYS["deadline"], default={})
    if "scale" in dl:
        dl["scale"] = get(dl, "scale", path + ".deadline", float, lo=0.01, hi=100.0)
    if "margin" in dl:
        dl["margin"] = get(dl, "margin", path + ".deadline", float, lo=0.0, hi=600.0)


def _existing_file(rel: Any, key: str, base_dir: Optional[str]) -> str:
    """``rel`` resolved against ``base_dir`` (the robot file's folder) and checked to be a file."""
    if not isinstance(rel, str) or not rel:
        raise SimConfigError("must be a file path, found %r" % (rel,), key=key)
    path = rel if os.path.isabs(rel) else os.path.join(base_dir or os.getcwd(), rel)
    if not os.path.isfile(path):
        raise SimConfigError("%s does not exist%s" % (path, "" if os.path.isabs(rel) else
                                                        " (relative paths are read from the robot file's folder)"),
                             key=key)
    return os.path.abspath(path)


def validate_robot(data: Dict[str, Any], base_dir: Optional[str] = None) -> Dict[str, Any]:
    """Check a robot document (already parsed); returns the normalised dictionary.

    ``base_dir`` is the robot file's folder: relative paths (``robot.base.eds``, ``robot.arm.description.urdf``
    without a ``package``) are resolved against it, checked to exist and stored absolute. The bridges and the
    simulator both load robot files through this one validation (:func:`load_robot`,
    :func:`locem_bridge.bridges.config.load_robot_config`)."""
    K = ROBOT_KEYS
    only(data, "", K[""])
    robot = _mapping(data, "robot", "", K["robot"])
    get(robot, "name", "robot", str)
    get(robot, "namespace", "robot", str, default="")
    base = _mapping(robot, "base", "robot", K["robot.base"])
    get(base, "kind", "robot.base", str, choices=("mecanum",))
    ch = _mapping(base, "chassis", "robot.base", K["robot.base.chassis"])
    for key in ("length", "width", "height"):
        ch[key] = get(ch, key, "robot.base.chassis", float, lo=0.05, hi=5.0)
    ch["clearance"] = get(ch, "clearance", "robot.base.chassis", float, default=0.05, lo=0.0, hi=1.0)
    wheel = _mapping(base, "wheel", "robot.base", K["robot.base.wheel"])
    for key in ("radius", "width", "half_wheelbase", "half_track"):
        wheel[key] = get(wheel, key, "robot.base.wheel", float, lo=0.005, hi=5.0)
    lim = _mapping(base, "limits", "robot.base", K["robot.base.limits"])
    for key in ("max_wheel_speed", "max_linear_velocity", "max_angular_velocity"):
        lim[key] = get(lim, key, "robot.base.limits", float, lo=0.1 if key == "max_wheel_speed" else 0.01)
    for key, dflt in (("linear_acceleration", 0.6), ("angular_acceleration", 1.2)):
        lim[key] = get(lim, key, "robot.base.limits", float, default=dflt, lo=0.01)
    # the ranges the base bridge applies (bridges/cia402_base.py), checked here so a file is refused at load
    base["control_rate"] = get(base, "control_rate", "robot.base", float, default=50.0, lo=5.0, hi=1000.0)
    base["localisation_window"] = get(base, "localisation_window", "robot.base", int, default=10, lo=1, hi=1000)
    poses = get(base, "named_poses", "robot.base", dict, default={})
    for name in list(poses):
        poses[name] = vec(poses, name, "robot.base.named_poses", 3)
    _deadline(base, "robot.base")
    drv = _mapping(base, "drives", "robot.base", K["robot.base.drives"])
    p = "robot.base.drives"
    _backend(drv, "profile", p, "base", "cia402")
    can = _mapping(drv, "can", p, K["robot.base.drives.can"])
    can["interface"] = get(can, "interface", p + ".can", str, choices=CAN_INTERFACES)
    can["channel"] = str(get(can, "channel", p + ".can"))
    can["bitrate"] = get(can, "bitrate", p + ".can", int, default=1000000, lo=10000, hi=1000000)
    if "port" in can:
        can["port"] = get(can, "port", p + ".can", int, lo=1, hi=65535)
    drv["heartbeat_ms"] = get(drv, "heartbeat_ms", p, int, lo=1, hi=65535)    # the bridge watches it
    drv["consumer_timeout_factor"] = get(drv, "consumer_timeout_factor", p, float, default=1.5, lo=1.0, hi=10.0)
    # the drives stop by themselves when the master's heartbeat is silent this long (bridges/cia402_base.py)
    drv["master_node_id"] = get(drv, "master_node_id", p, int, default=127, lo=1, hi=127)
    drv["master_timeout_ms"] = get(drv, "master_timeout_ms", p, int, default=500, lo=10, hi=65535)
    drv["tpdo_period_ms"] = get(drv, "tpdo_period_ms", p, int, lo=1, hi=65535)
    drv["velocity_units_per_rad_s"] = get(drv, "velocity_units_per_rad_s", p, float, lo=1e-6)
    drv["counts_per_rad"] = get(drv, "counts_per_rad", p, float, lo=1e-6)
    drv["profile_acceleration"] = get(drv, "profile_acceleration", p, float, lo=0.1)
    drv["stop_deceleration"] = get(drv, "stop_deceleration", p, float, default=200.0, lo=1.0)
    wheels = get(drv, "wheels", p, list)
    if len(wheels) != 4:
        raise SimConfigError("must list 4 wheels, found %d" % len(wheels), key=p + ".wheels",
                             allowed="front_left, front_right, rear_left, rear_right")
    seen = set()
    for i, w in enumerate(wheels):
        wp = "%s.wheels[%d]" % (p, i)
        _item(w, wp, K["wheel"])
        get(w, "name", wp, str)
        nid = get(w, "node_id", wp, int, lo=1, hi=127)
        if nid in seen:
            raise SimConfigError("%d is used twice; CAN node ids must be unique" % nid, key=wp + ".node_id")
        seen.add(nid)
        get(w, "polarity", wp, int, choices=(1, -1))
    base["eds"] = _existing_file(get(base, "eds", "robot.base"), "robot.base.eds", base_dir)
    ped = _mapping(robot, "pedestal", "robot", K["robot.pedestal"])
    ped["height"] = get(ped, "height", "robot.pedestal", float, lo=0.0, hi=3.0)
    ped["size"] = vec(ped, "size", "robot.pedestal", 2)
    ped["xy"] = vec(ped, "xy", "robot.pedestal", 2)
    arm = _mapping(robot, "arm", "robot", K["robot.arm"])
    backend = _backend(arm, "backend", "robot.arm", "arm", "ur_rtde")
    desc = _mapping(arm, "description", "robot.arm", K["robot.arm.description"], default={})
    if "urdf" in desc:         # a file path is checked now; one in a package when the simulator builds the arm
        get(desc, "urdf", "robot.arm.description", str)
        get(desc, "package", "robot.arm.description", str, default="", choices=("", "example-robot-data"))
        if not desc.get("package") or os.path.isabs(desc["urdf"]):
            desc["urdf"] = _existing_file(desc["urdf"], "robot.arm.description.urdf", base_dir)
    mount = _mapping(arm, "mount", "robot.arm", K["robot.arm.mount"])
    mount["xyz"] = vec(mount, "xyz", "robot.arm.mount", 3)
    mount["rpy"] = vec(mount, "rpy", "robot.arm.mount", 3)
    names = get(arm, "joint_names", "robot.arm", list)
    if len(names) != 6:
        raise SimConfigError("must list 6 joints, found %d" % len(names), key="robot.arm.joint_names")
    poses = get(arm, "named_poses", "robot.arm", dict, default={})
    for name in list(poses):
        poses[name] = vec(poses, name, "robot.arm.named_poses", 6)
    if arm.get("home_via") is not None and get(arm, "home_via", "robot.arm", str) not in poses:
        raise SimConfigError("%r is not a named pose of the arm" % arm["home_via"], key="robot.arm.home_via",
                             allowed=sorted(poses))
    if "wall_ready_flange" in arm:
        arm["wall_ready_flange"] = vec(arm, "wall_ready_flange", "robot.arm", 3)
    _deadline(arm, "robot.arm")
    ctl = _mapping(arm, "controller", "robot.arm", K["robot.arm.controller"])
    cp = "robot.arm.controller"
    get(ctl, "host", cp, str)
    # RTDE watchdog the arm bridge sets (Hz; 0 = none): the arm stops when LOCEM's polls stop (bridges/ur_arm.py)
    ctl["watchdog_frequency"] = get(ctl, "watchdog_frequency", cp, float, default=1.0, lo=0.0, hi=100.0)
    ctl["rtde_frequency"] = get(ctl, "rtde_frequency", cp, float, default=500.0, lo=1.0, hi=500.0)
    for key, port in sorted(UR_RTDE_PORTS.items()):
        ctl[key] = get(ctl, key, cp, int, default=port, lo=1, hi=65535)
        if backend == "ur_rtde" and ctl[key] != port:
            raise SimConfigError("%d cannot be used: ur_rtde always dials the UR ports 29999 (dashboard), 30003 "
                                 "(script) and 30004 (RTDE); another robot takes another address (host)"
                                 % ctl[key], key="%s.%s" % (cp, key), allowed=port)
    tools = _mapping(robot, "tools", "robot", K["robot.tools"])
    for name in TOOL_NAMES:
        tp = "robot.tools.%s" % name
        tool = _mapping(tools, name, "robot.tools", tuple(K["tool"]) + tuple(K[tp]))
        tool["tcp"] = vec(tool, "tcp", tp, 6)
        tool["mass"] = get(tool, "mass", tp, float, lo=0.0, hi=12.5)
        tool["cog"] = vec(tool, "cog", tp, 3, default=[0.0, 0.0, 0.0])
        sw = _mapping(tool, "switch", tp, K["switch"])
        src = get(sw, "source", tp + ".switch", str, choices=("ur_digital_out", "compressor_valve"))
        if src == "ur_digital_out":
            get(sw, "index", tp + ".switch", int, lo=0, hi=7)
        body = _mapping(tool, "body", tp, K["body"], default={"radius": 0.05, "length": 0.15})
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
    comp = _mapping(robot, "compressor", "robot", K["robot.compressor"])
    cp = "robot.compressor"
    _backend(comp, "protocol", cp, "compressor", "modbus_tcp")
    get(comp, "host", cp, str)
    comp["port"] = get(comp, "port", cp, int, lo=1, hi=65535)
    comp["device_id"] = get(comp, "device_id", cp, int, default=1, lo=0, hi=247)
    # the device's communication watchdog, s: valve closed, motor off when LOCEM's polls stop (modbus_compressor)
    comp["watchdog_timeout"] = get(comp, "watchdog_timeout", cp, float, default=0.5, lo=0.05, hi=60.0)
    comp["timeout"] = get(comp, "timeout", cp, float, default=0.5, lo=0.01)
    comp["pressure_range"] = vec(comp, "pressure_range", cp, 2)
    comp["max_setpoint"] = get(comp, "max_setpoint", cp, float, lo=0.1, hi=600.0)
    csim = _mapping(comp, "sim", cp, K["robot.compressor.sim"], default={})
    for key, dflt in (("time_constant", 2.0), ("max_pressure", 10.0), ("valve_drop", 1.0),
                      ("idle_current", 0.5), ("current_per_bar", 1.2), ("overpressure_limit", 9.0)):
        csim[key] = get(csim, key, cp + ".sim", float, default=dflt, lo=0.0)
    if csim["time_constant"] <= 0.0:
        raise SimConfigError("%r must be > 0" % csim["time_constant"], key="robot.compressor.sim.time_constant",
                             allowed="> 0")
    comp["sim"] = csim
    sc = _mapping(robot, "scanner", "robot", K["robot.scanner"])
    _backend(sc, "backend", "robot.scanner", "scanner", "sim")
    smount = _mapping(sc, "mount", "robot.scanner", K["robot.scanner.mount"])
    smount["xyz"] = vec(smount, "xyz", "robot.scanner.mount", 3)
    smount["yaw"] = get(smount, "yaw", "robot.scanner.mount", float, default=0.0)
    sc["range"] = get(sc, "range", "robot.scanner", float, lo=0.1, hi=100.0)
    sc["fov"] = get(sc, "fov", "robot.scanner", float, lo=0.01, hi=2 * math.pi)
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
        data = validate_site(_load_yaml(path))
    except SimConfigError as exc:
        raise exc.in_file(path)
    data["_path"] = os.path.abspath(path)
    return data


def load_robot(path: Optional[str] = None, overrides: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """Load and validate a robot file (default: ``config/robots/rbkairos_ur10e.yaml``); ``overrides`` (a mapping
    deep-merged into the ``robot`` section, e.g. another address) are checked with the file."""
    path = path or default_robot_path()
    try:
        data = _load_yaml(path)
        if overrides:
            if not isinstance(overrides, dict):
                raise SimConfigError("robot overrides must be a mapping, found %r" % (overrides,))
            if isinstance(data.get("robot"), dict):
                data["robot"] = deep_merge(data["robot"], overrides)
        data = validate_robot(data, os.path.dirname(os.path.abspath(path)))
    except SimConfigError as exc:
        raise exc.in_file(path + (" (with overrides)" if _overridden(exc.key, overrides) else ""))
    data["_path"] = os.path.abspath(path)
    return data


def _overridden(key: str, overrides: Optional[Mapping[str, Any]]) -> bool:
    """Whether the key path ``robot.a.b[2].c`` (or a parent of it) was set by ``overrides``."""
    node: Any = overrides
    parts = [p for p in re.sub(r"\[\d+\]", "", key).split(".")[1:] if p] if key.startswith("robot.") else []
    for part in parts:
        if not isinstance(node, Mapping) or part not in node:
            return False
        node = node[part]
    return bool(parts)


def deep_merge(base: Dict[str, Any], extra: Mapping[str, Any]) -> Dict[str, Any]:
    """``base`` updated recursively with ``extra`` (a new dict; dicts merge, everything else replaces)."""
    out = copy.deepcopy(base)
    for key, value in extra.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def resolve_relative(cfg: Dict[str, Any], rel: str) -> str:
    """Resolve ``rel`` against the folder of the file ``cfg`` was loaded from."""
    if os.path.isabs(rel):
        return rel
    return os.path.join(os.path.dirname(cfg.get("_path", os.getcwd())), rel)
