"""The robot YAML as the bridges read it: one file for the real robot and the simulated worksite.

``load_robot_config(path, overrides)`` returns the ``robot`` section (a plain dict) with ``overrides`` deep-merged
into it (e.g. a test's own loopback address: ``{"arm": {"controller": {"host": "127.70.0.1"}}}``), validated by the
one robot-file loader every layer uses (:mod:`locem_bridge.robot_file`), and the file's folder remembered under
``_dir`` (relative paths such as the drives' EDS are resolved against it and checked at load). :func:`need` reads
one key with a clear error naming the key path, what was found and what is allowed (a backend built from a
section by hand, as tests do, is checked the same way).
"""

import math
import os
from typing import Any, Dict, Mapping, Optional, Sequence

from locem_bridge.robot_file import load_robot

from .errors import BridgeConfigError

_MISSING = object()


def load_robot_config(path: str, overrides: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
    """The ``robot`` section of the YAML file at ``path``, with ``overrides`` merged in, validated.

    The file and its overrides go through the one robot-file loader the simulator uses too
    (:func:`locem_bridge.robot_file.load_robot`): unknown keys, missing keys, ranges, relative paths (resolved
    against the file and checked) and the controller ports ur_rtde can dial. A problem raises
    :class:`BridgeConfigError`, printed as one line ``FILE: KEY: PROBLEM (allowed: ...)``.
    """
    data = load_robot(path, dict(overrides) if overrides else None, error=BridgeConfigError)
    robot = data["robot"]
    robot["_dir"] = os.path.dirname(os.path.abspath(path))
    robot["_path"] = os.path.abspath(path)
    return robot


def need(section: Mapping[str, Any], dotted: str, kind: Any = None, default: Any = _MISSING,
         lo: Optional[float] = None, hi: Optional[float] = None, where: str = "robot") -> Any:
    """Value at ``dotted`` (``a.b.c``) below ``section``, type- and range-checked; ``where`` prefixes messages."""
    node: Any = section
    path = where
    for part in dotted.split("."):
        path = "%s.%s" % (path, part)
        if not isinstance(node, Mapping) or part not in node:
            if default is not _MISSING:
                return default
            raise BridgeConfigError("missing key", key=path)
        node = node[part]
    if kind is float:
        if isinstance(node, bool) or not isinstance(node, (int, float)) or not math.isfinite(float(node)):
            raise BridgeConfigError("%r must be a finite number" % (node,), key=path)
        node = float(node)
    elif kind is int:
        if isinstance(node, bool) or not isinstance(node, int):
            raise BridgeConfigError("%r must be an integer" % (node,), key=path)
    elif kind is not None and not isinstance(node, kind):
        raise BridgeConfigError("%r must be a %s" % (node, getattr(kind, "__name__", kind)), key=path)
    if lo is not None and node < lo or hi is not None and node > hi:
        raise BridgeConfigError("%r is out of range" % (node,), key=path, allowed="%s .. %s" % (lo, hi))
    return node


def vector(section: Mapping[str, Any], dotted: str, n: int, where: str = "robot") -> list:
    """A list of ``n`` finite numbers at ``dotted``."""
    value = need(section, dotted, where=where)
    if not isinstance(value, Sequence) or len(value) != n or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        raise BridgeConfigError("%r must be a list of %d finite numbers" % (value, n), key="%s.%s" % (where, dotted))
    return [float(v) for v in value]


def resolve_path(robot: Mapping[str, Any], rel: str) -> str:
    """``rel`` relative to the robot YAML's folder (absolute paths pass through)."""
    return rel if os.path.isabs(rel) else os.path.join(str(robot.get("_dir", ".")), rel)
