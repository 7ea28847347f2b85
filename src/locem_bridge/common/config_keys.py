"""Checked reading of a parsed configuration file (a YAML mapping), one set of readers for every file's loader.

Each reader fetches one key and checks it (type, range, closed set, known keys); a problem raises
:class:`~locem_bridge.common.config_errors.ConfigError` naming the dotted key path, what was found and what is
allowed. A layer's loader turns it into its own error type at its boundary
(:meth:`~locem_bridge.common.config_errors.ConfigError.recast`). Used by the robot file
(:mod:`locem_bridge.robot_file`) and the site file (:mod:`locem_bridge.sim.config`).
"""
import copy
import math
import os
from typing import Any, Dict, List, Mapping, Optional, Sequence

from .config_errors import ConfigError, read_yaml


def load_mapping(path: str) -> Dict[str, Any]:
    """The parsed YAML file at ``path``, which must hold a mapping at the top level."""
    if not os.path.isfile(path):
        raise ConfigError("file does not exist" if not os.path.exists(path) else "is not a file", file=path)
    data = read_yaml(path, ConfigError)
    if not isinstance(data, dict):
        raise ConfigError("must hold a mapping at the top level, found %s" % type(data).__name__, file=path)
    return data


def only(d: Any, path: str, keys: Sequence[str]) -> None:
    """Refuse a key of mapping ``d`` (at ``path``) that is not in ``keys``: a misspelt section must not be
    silently ignored (the device it configures would start with defaults or not at all)."""
    if not isinstance(d, dict):
        return
    for key in d:
        if key not in keys and not (isinstance(key, str) and key.startswith("_")):
            raise ConfigError("unknown key", key="%s.%s" % (path, key) if path else str(key),
                              allowed=sorted(keys))


def get(d: Dict[str, Any], key: str, path: str, kind: Any = None, default: Any = ...,
        lo: Optional[float] = None, hi: Optional[float] = None, choices: Optional[Sequence[Any]] = None) -> Any:
    """Fetch ``d[key]`` checking type, range and choices; ``path`` names the parent for messages."""
    full = "%s.%s" % (path, key) if path else key
    if not isinstance(d, dict):
        raise ConfigError("must be a mapping, found %r" % (d,), key=path or "(top level)")
    if key not in d:
        if default is ...:
            raise ConfigError("missing key", key=full, allowed=choices)
        return default
    value = d[key]
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError("must be a finite number, found %r" % (value,), key=full)
        value = float(value)
    elif kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError("must be an integer, found %r" % (value,), key=full)
    elif kind is not None and not isinstance(value, kind):
        raise ConfigError("must be of type %s, found %r" % (_kind_name(kind), value), key=full)
    if lo is not None and value < lo:
        raise ConfigError("%r is out of range" % (value,), key=full, allowed=">= %r" % (lo,))
    if hi is not None and value > hi:
        raise ConfigError("%r is out of range" % (value,), key=full, allowed="<= %r" % (hi,))
    if choices is not None and value not in choices:
        raise ConfigError("%r is not allowed" % (value,), key=full, allowed=choices)
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
        raise ConfigError("must be a list of %d finite numbers, found %r" % (n, value), key=full)
    return [float(x) for x in value]


def mapping(parent: Dict[str, Any], key: str, path: str, keys: Sequence[str], default: Any = ...) -> Dict[str, Any]:
    """``parent[key]`` as a mapping whose keys are all in ``keys``."""
    value = get(parent, key, path, dict, default=default)
    only(value, "%s.%s" % (path, key) if path else key, keys)
    return value


def item(value: Any, path: str, keys: Sequence[str]) -> Dict[str, Any]:
    """``value`` (an item of a list at ``path``) as a mapping whose keys are all in ``keys``."""
    if not isinstance(value, dict):
        raise ConfigError("must be a mapping, found %r" % (value,), key=path)
    only(value, path, keys)
    return value


def deep_merge(base: Dict[str, Any], extra: Mapping[str, Any]) -> Dict[str, Any]:
    """``base`` updated recursively with ``extra`` (a new dict; dicts merge, everything else replaces)."""
    out = copy.deepcopy(base)
    for key, value in extra.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out
