"""The robot file (``config/robots/*.yaml``): its keys, its validation and the one loader every layer uses.

A robot file describes one robot: base (kinematics ``mecanum`` or ``differential``, limits, CAN drives), pedestal,
optional lift (the arm's vertical axis), arm (model, mount, named poses,
UR controller address), tools, compressor (Modbus address, limits), scanner and, optionally, an automatic tool
changer with its rack (``tool_changer``). The bridges
(:func:`locem_bridge.bridges.config.load_robot_config`), the simulated worksite
(:func:`locem_bridge.sim.config.load_robot`), the pre-flight (:mod:`locem_bridge.config_check`) and the main job
all load it through :func:`load_robot`; each passes its own error type (``error=``), so a problem is one line
``FILE: KEY: PROBLEM (allowed: ...)`` of the caller's error family. Every key a loader reads is listed in
:data:`ROBOT_KEYS` with its check below; an unknown key is refused by name.
"""
import math
import os
import re
from typing import Any, Callable, Dict, Mapping, Optional, Sequence

from .common.base_kinematics import KINEMATICS, WHEEL_KEYS, WHEEL_ORDER
from .common.can_bus import CAN_INTERFACES
from .common.config_errors import ConfigError
from .common.config_keys import deep_merge, get, item, load_mapping, mapping, only, vec
from .common.paths import checkout_root

TOOL_NAMES = ("taping_tool", "spray_gun", "sander")
# The ports ur_rtde dials: its RTDEControlInterface / RTDEReceiveInterface / RTDEIOInterface take a host and no
# port, so a UR controller on other ports cannot be reached by the arm bridge (another robot takes another
# address). The UR stand-in itself takes any ports (Worksite(ur_ports=...)) for its own tests.
UR_RTDE_PORTS = {"dashboard_port": 29999, "script_port": 30003, "rtde_port": 30004}

# Every key a robot file may hold, per mapping (lists' items under their own name). A key not listed is refused
# with its name: a misspelt section would otherwise be ignored and its device left out or on defaults. A new key a
# loader reads is added here too, with its check in :func:`validate_robot`.
ROBOT_KEYS: Dict[str, Sequence[str]] = {
    "": ("robot",),
    "robot": ("name", "namespace", "base", "pedestal", "lift", "arm", "tools", "compressor", "scanner",
              "tool_changer"),
    "robot.base": ("kind", "frame", "control_rate", "localisation_window", "named_poses", "chassis", "wheel",
                   "limits", "drives", "eds", "deadline"),
    "robot.base.chassis": ("length", "width", "height", "clearance", "mass"),
    "robot.base.wheel": ("radius", "width") + tuple(k for kind in sorted(WHEEL_KEYS) for k in WHEEL_KEYS[kind]),
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
    # the lift (optional): a CiA 402 linear axis in profile position mode on the base's CAN bus, carrying the arm
    "robot.lift": ("range", "max_velocity", "acceleration", "tolerance", "drive", "eds", "deadline"),
    "robot.lift.drive": ("node_id", "counts_per_m", "velocity_units_per_m_s", "heartbeat_ms", "tpdo_period_ms"),
    "robot.arm": ("backend", "model", "reach", "description", "mount", "joint_names", "controller", "named_poses",
                  "home_via", "transit_pose", "wall_ready_flange", "deadline"),
    "robot.arm.description": ("package", "urdf"),
    "robot.arm.mount": ("xyz", "rpy"),
    "robot.arm.controller": ("host", "dashboard_port", "script_port", "rtde_port", "rtde_frequency",
                             "watchdog_frequency"),
    "robot.tools": TOOL_NAMES,
    "tool": ("kind", "tcp", "mass", "cog", "switch", "body", "wall_work"),
    # how the tool works at a wall on this robot, measured (see config/robots/rbkairos_ur10e.yaml); the numbers
    # the trees use are derived from it by locem_bridge.robot_facts:
    #   work             the wall work the tool does: the HICEM parameter section and robot.work.<work>.* key
    #                    (taping | spray | sand for the shipped trees), one tool per work
    #   flange_distance  m, flange ahead of the base centre along the wall normal while the tool works at the wall
    #   lateral_reach    m, how far to either side of the base's wall-normal axis the TCP reaches at the wall
    #   z_band           m, [z_min, z_max]: heights the TCP reaches at the wall from one base pose (with a lift:
    #                    from one lift height, measured at the lift's bottom; the band rides up with the lift)
    #   line_length      m, longest straight line along the wall worked from one base pose (default
    #                    2 x lateral_reach)
    "wall_work": ("work", "flange_distance", "lateral_reach", "z_band", "line_length"),
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
    "robot.tool_changer": ("protocol", "host", "port", "device_id", "timeout", "lock_timeout", "safe_pose", "rack",
                           "sim"),
    "rack_slot": ("slot", "pose"),
    "robot.tool_changer.sim": ("lock_time", "slot_tolerance"),
    "robot.scanner.mount": ("xyz", "yaw"),
}

ErrorType = Callable[..., ConfigError]


class RobotFileError(ConfigError):
    """A robot file is missing, malformed or holds a value that is not allowed (when no ``error=`` is given)."""


def default_robot_path(root: str = "") -> str:
    """Path of ``config/robots/rbkairos_ur10e.yaml`` in the package folder ``root`` (default: the source tree)."""
    root = root or checkout_root()
    return os.path.join(root, "config", "robots", "rbkairos_ur10e.yaml")


def validate_robot(data: Dict[str, Any], base_dir: Optional[str] = None,
                   error: ErrorType = RobotFileError) -> Dict[str, Any]:
    """Check a robot document (already parsed); returns the normalised dictionary.

    ``base_dir`` is the robot file's folder: relative paths (``robot.base.eds``, ``robot.arm.description.urdf``
    without a ``package``) are resolved against it, checked to exist and stored absolute. A problem raises
    ``error``."""
    try:
        return _validate(data, base_dir)
    except ConfigError as exc:
        raise exc.recast(error)


def load_robot(path: Optional[str] = None, overrides: Optional[Mapping[str, Any]] = None,
               error: ErrorType = RobotFileError) -> Dict[str, Any]:
    """Load and validate a robot file (default: :func:`default_robot_path`); ``overrides`` (a mapping deep-merged
    into the ``robot`` section, e.g. another address) are checked with the file. Returns the document
    (``{"robot": {...}, "_path": ...}``); a problem raises ``error`` naming the file (``FILE (with overrides)``
    when the key came from ``overrides``)."""
    path = path or default_robot_path()
    try:
        data = load_mapping(path)
        if overrides:
            if not isinstance(overrides, dict):
                raise ConfigError("robot overrides must be a mapping, found %r" % (overrides,))
            if isinstance(data.get("robot"), dict):
                data["robot"] = deep_merge(data["robot"], overrides)
        data = _validate(data, os.path.dirname(os.path.abspath(path)))
    except ConfigError as exc:
        raise exc.recast(error).in_file(path + (" (with overrides)" if _overridden(exc.key, overrides) else ""))
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


def _backend(section: Dict[str, Any], key: str, path: str, kind: str, default: str) -> str:
    from .bridges.backends import BACKENDS      # the bridges' name -> backend table (imports no device library)
    return get(section, key, path, str, default=default, choices=sorted(BACKENDS[kind]))


def _deadline(section: Dict[str, Any], path: str) -> None:
    """``deadline: {scale, margin}`` of a motion device (the bridges' defaults apply to what is left out)."""
    dl = mapping(section, "deadline", path, ROBOT_KEYS["deadline"], default={})
    if "scale" in dl:
        dl["scale"] = get(dl, "scale", path + ".deadline", float, lo=0.01, hi=100.0)
    if "margin" in dl:
        dl["margin"] = get(dl, "margin", path + ".deadline", float, lo=0.0, hi=600.0)


def _lift(robot: Dict[str, Any], base_dir: Optional[str]) -> None:
    """``robot.lift``: the arm's vertical axis. ``range`` [bottom, top] = heights (m) of the arm mount (the arm's
    base_link origin) above base_footprint the axis can reach; the axis position 0 (drive counts 0) is the bottom.
    Its drive is a CiA 402 node on the base's CAN bus (``robot.base.drives.can``) in profile position mode."""
    K = ROBOT_KEYS
    lp = "robot.lift"
    lift = mapping(robot, "lift", "robot", K[lp])
    lift["range"] = vec(lift, "range", lp, 2)
    lo, hi = lift["range"]
    if not 0.0 <= lo < hi <= 5.0:
        raise ConfigError("[%g, %g] is not a range of heights: bottom < top, both within 0..5 m" % (lo, hi),
                          key=lp + ".range", allowed="[bottom, top] with 0 <= bottom < top <= 5")
    lift["max_velocity"] = get(lift, "max_velocity", lp, float, lo=0.001, hi=2.0)
    lift["acceleration"] = get(lift, "acceleration", lp, float, lo=0.001, hi=20.0)
    lift["tolerance"] = get(lift, "tolerance", lp, float, default=0.001, lo=0.0001, hi=0.05)
    _deadline(lift, lp)
    drv = mapping(lift, "drive", lp, K[lp + ".drive"])
    dp = lp + ".drive"
    nid = get(drv, "node_id", dp, int, lo=1, hi=127)
    wheels = robot["base"]["drives"]["wheels"]
    taken = [w["node_id"] for w in wheels] + [robot["base"]["drives"].get("master_node_id", 127)]
    if nid in taken:
        raise ConfigError("%d is taken on the base's CAN bus (wheel drives %s, master %d); CAN node ids must be "
                          "unique" % (nid, taken[:-1], taken[-1]), key=dp + ".node_id")
    drv["counts_per_m"] = get(drv, "counts_per_m", dp, float, lo=1.0)
    drv["velocity_units_per_m_s"] = get(drv, "velocity_units_per_m_s", dp, float, lo=1.0)
    drv["heartbeat_ms"] = get(drv, "heartbeat_ms", dp, int, default=robot["base"]["drives"]["heartbeat_ms"], lo=1,
                              hi=65535)
    drv["tpdo_period_ms"] = get(drv, "tpdo_period_ms", dp, int, default=robot["base"]["drives"]["tpdo_period_ms"],
                                lo=1, hi=65535)
    lift["eds"] = _existing_file(get(lift, "eds", lp), lp + ".eds", base_dir)


def _existing_file(rel: Any, key: str, base_dir: Optional[str]) -> str:
    """``rel`` resolved against ``base_dir`` (the robot file's folder) and checked to be a file."""
    if not isinstance(rel, str) or not rel:
        raise ConfigError("must be a file path, found %r" % (rel,), key=key)
    path = rel if os.path.isabs(rel) else os.path.join(base_dir or os.getcwd(), rel)
    if not os.path.isfile(path):
        raise ConfigError("%s does not exist%s" % (path, "" if os.path.isabs(rel) else
                                                     " (relative paths are read from the robot file's folder)"),
                          key=key)
    return os.path.abspath(path)


def _wall_work(tool: Dict[str, Any], tp: str) -> None:
    """``wall_work`` of one tool (keys: :data:`ROBOT_KEYS` ``wall_work``), checked and normalised in place."""
    p = tp + ".wall_work"
    ww = mapping(tool, "wall_work", tp, ROBOT_KEYS["wall_work"])
    work = get(ww, "work", p, str)
    if not re.match(r"^[a-z][a-z0-9_]*$", work):
        raise ConfigError("%r is not a work name" % work, key=p + ".work",
                          allowed="lower-case letters, digits and _, e.g. taping, spray, sand")
    ww["flange_distance"] = get(ww, "flange_distance", p, float, lo=0.05, hi=3.0)
    ww["lateral_reach"] = get(ww, "lateral_reach", p, float, lo=0.0, hi=3.0)
    band = vec(ww, "z_band", p, 2)
    if not 0.0 <= band[0] < band[1]:
        raise ConfigError("%s must be two heights 0 <= z_min < z_max" % (band,), key=p + ".z_band",
                          allowed="[z_min, z_max] in m")
    ww["z_band"] = band
    ww["line_length"] = get(ww, "line_length", p, float, default=2.0 * ww["lateral_reach"], lo=0.01, hi=10.0)


def _validate(data: Dict[str, Any], base_dir: Optional[str] = None) -> Dict[str, Any]:
    K = ROBOT_KEYS
    only(data, "", K[""])
    robot = mapping(data, "robot", "", K["robot"])
    get(robot, "name", "robot", str)
    get(robot, "namespace", "robot", str, default="")
    base = mapping(robot, "base", "robot", K["robot.base"])
    kind = get(base, "kind", "robot.base", str, choices=sorted(KINEMATICS))
    ch = mapping(base, "chassis", "robot.base", K["robot.base.chassis"])
    for key in ("length", "width", "height"):
        ch[key] = get(ch, key, "robot.base.chassis", float, lo=0.05, hi=5.0)
    ch["clearance"] = get(ch, "clearance", "robot.base.chassis", float, default=0.05, lo=0.0, hi=1.0)
    wheel = mapping(base, "wheel", "robot.base", K["robot.base.wheel"])
    geometry = ("radius", "width") + WHEEL_KEYS[kind]
    for key in sorted(wheel):
        if key not in geometry:           # another kind's geometry: the file mixes two bases
            raise ConfigError("is not a key of a %s base" % kind, key="robot.base.wheel.%s" % key,
                              allowed=", ".join(geometry))
    for key in geometry:
        wheel[key] = get(wheel, key, "robot.base.wheel", float, lo=0.005, hi=5.0)
    lim = mapping(base, "limits", "robot.base", K["robot.base.limits"])
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
    drv = mapping(base, "drives", "robot.base", K["robot.base.drives"])
    p = "robot.base.drives"
    _backend(drv, "profile", p, "base", "cia402")
    can = mapping(drv, "can", p, K["robot.base.drives.can"])
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
    order = WHEEL_ORDER[kind]
    if len(wheels) != len(order):
        raise ConfigError("must list %d wheels for a %s base, found %d" % (len(order), kind, len(wheels)),
                          key=p + ".wheels", allowed=", ".join(order))
    seen = set()
    for i, w in enumerate(wheels):
        wp = "%s.wheels[%d]" % (p, i)
        item(w, wp, K["wheel"])
        get(w, "name", wp, str)
        nid = get(w, "node_id", wp, int, lo=1, hi=127)
        if nid in seen:
            raise ConfigError("%d is used twice; CAN node ids must be unique" % nid, key=wp + ".node_id")
        seen.add(nid)
        get(w, "polarity", wp, int, choices=(1, -1))
    base["eds"] = _existing_file(get(base, "eds", "robot.base"), "robot.base.eds", base_dir)
    ped = mapping(robot, "pedestal", "robot", K["robot.pedestal"])
    ped["height"] = get(ped, "height", "robot.pedestal", float, lo=0.0, hi=3.0)
    ped["size"] = vec(ped, "size", "robot.pedestal", 2)
    ped["xy"] = vec(ped, "xy", "robot.pedestal", 2)
    if "lift" in robot:
        _lift(robot, base_dir)
    arm = mapping(robot, "arm", "robot", K["robot.arm"])
    backend = _backend(arm, "backend", "robot.arm", "arm", "ur_rtde")
    desc = mapping(arm, "description", "robot.arm", K["robot.arm.description"], default={})
    if "urdf" in desc:         # a file path is checked now; one in a package when the simulator builds the arm
        get(desc, "urdf", "robot.arm.description", str)
        get(desc, "package", "robot.arm.description", str, default="", choices=("", "example-robot-data"))
        if not desc.get("package") or os.path.isabs(desc["urdf"]):
            desc["urdf"] = _existing_file(desc["urdf"], "robot.arm.description.urdf", base_dir)
    # m, the arm's reach (flange from the shoulder axis, the maker's figure: UR10e 1.3 m, UR5e 0.85 m)
    arm["reach"] = get(arm, "reach", "robot.arm", float, lo=0.1, hi=5.0)
    mount = mapping(arm, "mount", "robot.arm", K["robot.arm.mount"])
    mount["xyz"] = vec(mount, "xyz", "robot.arm.mount", 3)
    mount["rpy"] = vec(mount, "rpy", "robot.arm.mount", 3)
    names = get(arm, "joint_names", "robot.arm", list)
    if len(names) != 6:
        raise ConfigError("must list 6 joints, found %d" % len(names), key="robot.arm.joint_names")
    poses = get(arm, "named_poses", "robot.arm", dict, default={})
    for name in list(poses):
        poses[name] = vec(poses, name, "robot.arm.named_poses", 6)
    if "lift" in robot:
        lo, hi = robot["lift"]["range"]
        if not lo - 1e-9 <= mount["xyz"][2] <= hi + 1e-9:
            raise ConfigError("%g is outside the lift's range: with a lift it is the arm mount's height where the "
                              "lift starts" % mount["xyz"][2], key="robot.arm.mount.xyz",
                              allowed="z in robot.lift.range [%g, %g]" % (lo, hi))
    if arm.get("home_via") is not None and get(arm, "home_via", "robot.arm", str) not in poses:
        raise ConfigError("%r is not a named pose of the arm" % arm["home_via"], key="robot.arm.home_via",
                          allowed=sorted(poses))
    if arm.get("transit_pose") is not None and get(arm, "transit_pose", "robot.arm", str) not in poses:
        raise ConfigError("%r is not a named pose of the arm" % arm["transit_pose"], key="robot.arm.transit_pose",
                          allowed=sorted(poses))
    if "wall_ready_flange" in arm:
        arm["wall_ready_flange"] = vec(arm, "wall_ready_flange", "robot.arm", 3)
    _deadline(arm, "robot.arm")
    ctl = mapping(arm, "controller", "robot.arm", K["robot.arm.controller"])
    cp = "robot.arm.controller"
    get(ctl, "host", cp, str)
    # RTDE watchdog the arm bridge sets (Hz; 0 = none): the arm stops when LOCEM's polls stop (bridges/ur_arm.py)
    ctl["watchdog_frequency"] = get(ctl, "watchdog_frequency", cp, float, default=1.0, lo=0.0, hi=100.0)
    ctl["rtde_frequency"] = get(ctl, "rtde_frequency", cp, float, default=500.0, lo=1.0, hi=500.0)
    for key, port in sorted(UR_RTDE_PORTS.items()):
        ctl[key] = get(ctl, key, cp, int, default=port, lo=1, hi=65535)
        if backend == "ur_rtde" and ctl[key] != port:
            raise ConfigError("%d cannot be used: ur_rtde always dials the UR ports 29999 (dashboard), 30003 "
                              "(script) and 30004 (RTDE); another robot takes another address (host)"
                              % ctl[key], key="%s.%s" % (cp, key), allowed=port)
    tools = mapping(robot, "tools", "robot", K["robot.tools"])
    for name in TOOL_NAMES:
        tp = "robot.tools.%s" % name
        tool = mapping(tools, name, "robot.tools", tuple(K["tool"]) + tuple(K[tp]))
        # the tool's ppr:Tool class in snake_case (spray_gun -> ppr:SprayGun), checked by the resource model
        tool["kind"] = get(tool, "kind", tp, str, default=name)
        tool["tcp"] = vec(tool, "tcp", tp, 6)
        tool["mass"] = get(tool, "mass", tp, float, lo=0.0, hi=12.5)
        tool["cog"] = vec(tool, "cog", tp, 3, default=[0.0, 0.0, 0.0])
        sw = mapping(tool, "switch", tp, K["switch"])
        src = get(sw, "source", tp + ".switch", str, choices=("ur_digital_out", "compressor_valve"))
        if src == "ur_digital_out":
            get(sw, "index", tp + ".switch", int, lo=0, hi=7)
        body = mapping(tool, "body", tp, K["body"], default={"radius": 0.05, "length": 0.15})
        body["radius"] = get(body, "radius", tp + ".body", float, lo=0.005, hi=0.5)
        body["length"] = get(body, "length", tp + ".body", float, lo=0.005, hi=1.0)
        tool["body"] = body
        _wall_work(tool, tp)
    works: Dict[str, str] = {}
    for name in TOOL_NAMES:
        work = tools[name]["wall_work"]["work"]
        if work in works:
            raise ConfigError("%r is the work of %s too; one tool per work" % (work, works[work]),
                              key="robot.tools.%s.wall_work.work" % name)
        works[work] = name
    tools["taping_tool"]["tape_width"] = get(tools["taping_tool"], "tape_width", "robot.tools.taping_tool",
                                             float, default=0.05, lo=0.005, hi=0.5)
    sg = tools["spray_gun"]
    sg["spray_half_angle"] = get(sg, "spray_half_angle", "robot.tools.spray_gun", float, default=0.35,
                                 lo=0.01, hi=1.4)
    sg["standoff"] = get(sg, "standoff", "robot.tools.spray_gun", float, default=0.3, lo=0.02, hi=2.0)
    sd = tools["sander"]
    sd["pad_radius"] = get(sd, "pad_radius", "robot.tools.sander", float, default=0.1, lo=0.005, hi=0.5)
    comp = mapping(robot, "compressor", "robot", K["robot.compressor"])
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
    csim = mapping(comp, "sim", cp, K["robot.compressor.sim"], default={})
    for key, dflt in (("time_constant", 2.0), ("max_pressure", 10.0), ("valve_drop", 1.0),
                      ("idle_current", 0.5), ("current_per_bar", 1.2), ("overpressure_limit", 9.0)):
        csim[key] = get(csim, key, cp + ".sim", float, default=dflt, lo=0.0)
    if csim["time_constant"] <= 0.0:
        raise ConfigError("%r must be > 0" % csim["time_constant"], key="robot.compressor.sim.time_constant",
                          allowed="> 0")
    comp["sim"] = csim
    sc = mapping(robot, "scanner", "robot", K["robot.scanner"])
    _backend(sc, "backend", "robot.scanner", "scanner", "sim")
    smount = mapping(sc, "mount", "robot.scanner", K["robot.scanner.mount"])
    smount["xyz"] = vec(smount, "xyz", "robot.scanner.mount", 3)
    smount["yaw"] = get(smount, "yaw", "robot.scanner.mount", float, default=0.0)
    sc["range"] = get(sc, "range", "robot.scanner", float, lo=0.1, hi=100.0)
    sc["fov"] = get(sc, "fov", "robot.scanner", float, lo=0.01, hi=2 * math.pi)
    if "tool_changer" in robot:
        _tool_changer(robot)
    return data


#: the most rack slots a tool changer has (one tool-present input per slot, see sim/modbus/tool_changer.py)
MAX_RACK_SLOTS = 8


def _tool_changer(robot: Dict[str, Any]) -> None:
    """``robot.tool_changer``: the automatic tool changer (Modbus TCP) and its rack of named arm poses, one slot
    per tool of ``robot.tools`` (bridges/modbus_tool_changer.py, bridges/commands_changer.py)."""
    p = "robot.tool_changer"
    tc = mapping(robot, "tool_changer", "robot", ROBOT_KEYS[p])
    _backend(tc, "protocol", p, "tool_changer", "modbus_tcp")
    get(tc, "host", p, str)
    tc["port"] = get(tc, "port", p, int, lo=1, hi=65535)
    tc["device_id"] = get(tc, "device_id", p, int, default=1, lo=0, hi=247)
    comp = robot.get("compressor", {})
    if (tc["host"], tc["port"]) == (comp.get("host"), comp.get("port")):
        raise ConfigError("%s:%d is the compressor's address; the tool changer is a device of its own"
                          % (tc["host"], tc["port"]), key=p + ".port")
    tc["timeout"] = get(tc, "timeout", p, float, default=0.5, lo=0.01, hi=5.0)
    tc["lock_timeout"] = get(tc, "lock_timeout", p, float, default=3.0, lo=0.1, hi=60.0)
    poses = robot["arm"].get("named_poses", {})
    get(tc, "safe_pose", p, str, choices=sorted(poses))
    rack = get(tc, "rack", p, dict)
    tools = sorted(robot.get("tools", {}))
    if not rack:
        raise ConfigError("must hold one slot per tool", key=p + ".rack", allowed=tools)
    slots: Dict[int, str] = {}
    for name in list(rack):
        sp = "%s.rack.%s" % (p, name)
        if name not in tools:
            raise ConfigError("%r is not a tool of this robot (robot.tools)" % (name,), key=sp, allowed=tools)
        slot = item(rack[name], sp, ROBOT_KEYS["rack_slot"])
        number = get(slot, "slot", sp, int, lo=1, hi=MAX_RACK_SLOTS)
        if number in slots:
            raise ConfigError("slot %d is %s's already; one tool per slot" % (number, slots[number]),
                              key=sp + ".slot")
        slots[number] = name
        slot["pose"] = vec(slot, "pose", sp, 6)
    csim = mapping(tc, "sim", p, ROBOT_KEYS[p + ".sim"], default={})
    csim["lock_time"] = get(csim, "lock_time", p + ".sim", float, default=0.3, lo=0.0, hi=10.0)
    csim["slot_tolerance"] = get(csim, "slot_tolerance", p + ".sim", float, default=0.01, lo=0.0001, hi=0.2)
    tc["sim"] = csim
