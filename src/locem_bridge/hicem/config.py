"""HICEM parameters (``trees/hicem_params.yaml``): loading, checking, and the ``cfg.*`` blackboard entries.

:func:`load_params` reads the YAML file; :class:`HicemParams` checks the keys the executive itself needs
(raising :class:`ConfigError` with the dotted key path) and flattens every leaf into blackboard entries
``cfg.<section>.<key>`` that trees read as ``{@cfg.<section>.<key>}``.
"""
import math
import os
from typing import Any, Dict, List

import yaml

from .datastore import PruneRule
from .errors import ConfigError
from .health import ModuleSpec

DEFAULT_PARAMS_FILE = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__))))), "trees", "hicem_params.yaml")
DEFAULT_TREES_DIR = os.path.dirname(DEFAULT_PARAMS_FILE)


def _get(d: Dict[str, Any], path: str, kind: type) -> Any:
    cur: Any = d
    for p in path.split("."):
        if not isinstance(cur, dict) or p not in cur:
            raise ConfigError("HICEM parameters: missing key '%s'" % path)
        cur = cur[p]
    if kind is float:
        if isinstance(cur, bool) or not isinstance(cur, (int, float)) or not math.isfinite(cur):
            raise ConfigError("HICEM parameters: '%s' must be a finite number, got %r" % (path, cur))
        return float(cur)
    if not isinstance(cur, kind):
        raise ConfigError("HICEM parameters: '%s' must be a %s, got %r" % (path, kind.__name__, cur))
    return cur


def flatten(d: Dict[str, Any], prefix: str = "cfg") -> Dict[str, Any]:
    """Every leaf and every sub-mapping under its dotted path (``cfg.site.locations`` and
    ``cfg.site.locations.home``)."""
    out: Dict[str, Any] = {}
    for k, v in d.items():
        key = "%s.%s" % (prefix, k)
        out[key] = v
        if isinstance(v, dict):
            out.update(flatten(v, key))
    return out


class HicemParams:
    def __init__(self, raw: Dict[str, Any]) -> None:
        if not isinstance(raw, dict):
            raise ConfigError("HICEM parameters must be a mapping at top level")
        self.raw = raw
        self.tick_period_s = _get(raw, "hhlc.tick_period_s", float)
        self.idle_poll_s = _get(raw, "hhlc.idle_poll_s", float)
        self.resume_policy: Dict[str, str] = dict(_get(raw, "hhlc.resume_policy", dict))
        for k, v in self.resume_policy.items():
            if not isinstance(v, str) or not v:
                raise ConfigError("HICEM parameters: hhlc.resume_policy.%s must be rerun, fail or a tree ID, got %r"
                                  % (k, v))
        self.safe_commands: List[str] = list(_get(raw, "locem.safe_commands", list))
        self.command_timeout_s = _get(raw, "locem.command_timeout_s", float)
        self.safe_timeout_s = _get(raw, "locem.safe_timeout_s", float)
        self.watchdog_period_s = _get(raw, "health.watchdog_period_s", float)
        self.modules = [ModuleSpec.from_dict(m) for m in _get(raw, "health.modules", list)]
        self.persistent_collections = list(_get(raw, "datastore.persistent_collections", list))
        self.prune_rules = [PruneRule.from_dict(r) for r in _get(raw, "datastore.prune", list)]
        self.hdict_synchronous = str(_get(raw, "datastore.hdict_synchronous", str)).upper()
        if self.hdict_synchronous not in ("FULL", "NORMAL"):
            raise ConfigError("HICEM parameters: datastore.hdict_synchronous must be FULL or NORMAL")
        for name in ("tick_period_s", "idle_poll_s", "watchdog_period_s", "command_timeout_s",
                     "safe_timeout_s"):
            if getattr(self, name) <= 0:
                raise ConfigError("HICEM parameters: %s must be > 0" % name)

    def blackboard_entries(self) -> Dict[str, Any]:
        return flatten(self.raw)


def load_params(path: str = DEFAULT_PARAMS_FILE) -> HicemParams:
    try:
        with open(path, "r", encoding="utf-8") as f:
            raw = yaml.safe_load(f)
    except OSError as exc:
        raise ConfigError("cannot read HICEM parameters %s: %s" % (path, exc.strerror))
    except yaml.YAMLError as exc:
        raise ConfigError("HICEM parameters %s are not valid YAML: %s" % (path, exc))
    return HicemParams(raw)
