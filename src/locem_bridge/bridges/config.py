"""The robot YAML as the bridges read it: one file for the real robot and the simulated worksite.

``load_robot_config(path, overrides)`` returns the ``robot`` section (a plain dict) with ``overrides`` deep-merged
into it (e.g. a test's own loopback address: ``{"arm": {"controller": {"host": "127.70.0.1"}}}``) and the file's
folder remembered under ``_dir`` (relative paths such as the drives' EDS resolve against it). :func:`need` reads
one key with a clear error naming the key path, what was found and what is allowed.
"""

import copy
import math
import os
from typing import Any, Dict, Mapping, Optional, Sequence

import yaml

from .errors import BridgeConfigError

_MISSING = object()


def deep_merge(base: Dict[str, Any], extra: Mapping[str, Any]) -> Dict[str, Any]:
    """``base`` updated recursively with ``extra`` (a new dict; dicts merge, everything else replaces)."""
    out = copy.deepcopy(base)
    for key, value in extra.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def load_robot_config(path: str, overrides: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
    """The ``robot`` section of the YAML file at ``path``, with ``overrides`` merged in."""
    try:
        with open(path, encoding="utf-8") as handle:
            data = yaml.safe_load(handle)
    except OSError as error:
        raise BridgeConfigError("robot config %s cannot be read: %s" % (path, error))
    except yaml.YAMLError as error:
        raise BridgeConfigError("robot config %s is not valid YAML: %s" % (path, error))
    if not isinstance(data, dict) or not isinstance(data.get("robot"), dict):
        raise BridgeConfigError("robot config %s must hold a mapping with a 'robot' section" % path)
    robot = data["robot"]
    if overrides:
        robot = deep_merge(robot, overrides)
    robot["_dir"] = os.path.dirname(os.path.abspath(path))
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
            raise BridgeConfigError("robot config: %s is missing" % path)
        node = node[part]
    if kind is float:
        if isinstance(node, bool) or not isinstance(node, (int, float)) or not math.isfinite(float(node)):
            raise BridgeConfigError("robot config: %s = %r must be a finite number" % (path, node))
        node = float(node)
    elif kind is int:
        if isinstance(node, bool) or not isinstance(node, int):
            raise BridgeConfigError("robot config: %s = %r must be an integer" % (path, node))
    elif kind is not None and not isinstance(node, kind):
        raise BridgeConfigError("robot config: %s = %r must be a %s" % (path, node, getattr(kind, "__name__", kind)))
    if lo is not None and node < lo or hi is not None and node > hi:
        raise BridgeConfigError("robot config: %s = %r is out of range; allowed %s .. %s" % (path, node, lo, hi))
    return node


def vector(section: Mapping[str, Any], dotted: str, n: int, where: str = "robot") -> list:
    """A list of ``n`` finite numbers at ``dotted``."""
    value = need(section, dotted, where=where)
    if not isinstance(value, Sequence) or len(value) != n or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        raise BridgeConfigError("robot config: %s.%s = %r must be a list of %d finite numbers" % (where, dotted, value, n))
    return [float(v) for v in value]


def resolve_path(robot: Mapping[str, Any], rel: str) -> str:
    """``rel`` relative to the robot YAML's folder (absolute paths pass through)."""
    return rel if os.path.isabs(rel) else os.path.join(str(robot.get("_dir", ".")), rel)
