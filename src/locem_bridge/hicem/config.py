"""HICEM parameters (``config/hicem/plasterboard.yaml``) and robot facts: loading, checking, and the ``cfg.*`` and
``robot.*`` blackboard entries.

:func:`load_params` reads the YAML file; :class:`HicemParams` checks the keys the executive itself needs
(raising :class:`ConfigError` with the dotted key path) and flattens every leaf into blackboard entries
``cfg.<section>.<key>`` that trees read as ``{@cfg.<section>.<key>}``. ``hhlc.node_modules`` names the node
modules whose classes the trees may use (:meth:`HicemParams.node_registry`).
The robot's facts (tool names, standoffs, section widths, lane spacings, height bands: what the robot file
measured, derived by :mod:`locem_bridge.robot_facts` with the process tuning of these parameters) become
``robot.*`` entries, read as ``{@robot.work.<work>.<name>}``; the parameters hold no robot fact.
"""
import math
import os
from typing import Any, Dict, List, Optional


from .datastore import PruneRule
from ..common.config_errors import read_yaml
from ..common.paths import checkout_root
from ..robot_facts import RobotFacts, load_facts
from .errors import ConfigError
from .health import ModuleSpec
from .registry import DEFAULT_NODE_MODULES, NODE_MODULES_KEY, NodeRegistry, default_registry

_PACKAGE_DIR = checkout_root()
DEFAULT_PARAMS_FILE = os.path.join(_PACKAGE_DIR, "config", "hicem", "plasterboard.yaml")
DEFAULT_TREES_DIR = os.path.join(_PACKAGE_DIR, "trees")


def _get(d: Dict[str, Any], path: str, kind: type) -> Any:
    cur: Any = d
    for p in path.split("."):
        if not isinstance(cur, dict) or p not in cur:
            raise ConfigError("missing key", key=path)
        cur = cur[p]
    if kind is float:
        if isinstance(cur, bool) or not isinstance(cur, (int, float)) or not math.isfinite(cur):
            raise ConfigError("must be a finite number, got %r" % (cur,), key=path)
        return float(cur)
    if not isinstance(cur, kind):
        raise ConfigError("must be a %s, got %r" % ({dict: "mapping", list: "list", str: "string"}.get(kind, kind.__name__),
                                                     cur), key=path)
    return cur


_KEYS = {"tick_period_s": "hhlc.tick_period_s", "idle_poll_s": "hhlc.idle_poll_s",
         "watchdog_period_s": "health.watchdog_period_s", "command_timeout_s": "locem.command_timeout_s",
         "safe_timeout_s": "locem.safe_timeout_s"}


def _entry(parse: Any, value: Any, key: str) -> Any:
    """``parse(value)`` for one list entry; whatever it refuses becomes a :class:`ConfigError` naming ``key``."""
    try:
        return parse(value)
    except ConfigError:
        raise
    except Exception as exc:       # HealthError, DataStoreError, KeyError, TypeError of a malformed entry
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError("%s%s" % ("missing key " if isinstance(exc, KeyError) else "", text), key=key)


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
    """The checked parameters ``raw`` and the facts of the robot file ``robot_file`` (None: the shipped robot
    file, ``config/robots/rbkairos_ur10e.yaml``)."""

    def __init__(self, raw: Dict[str, Any], robot_file: Optional[str] = None) -> None:
        if not isinstance(raw, dict):
            raise ConfigError("must hold a mapping at the top level, found %s" % type(raw).__name__)
        self.raw = raw
        self.robot: RobotFacts = load_facts(robot_file or None, tuning=raw, error=ConfigError)
        self.tick_period_s = _get(raw, "hhlc.tick_period_s", float)
        self.idle_poll_s = _get(raw, "hhlc.idle_poll_s", float)
        self.resume_policy: Dict[str, str] = dict(_get(raw, "hhlc.resume_policy", dict))
        for k, v in self.resume_policy.items():
            if not isinstance(v, str) or not v:
                raise ConfigError("%r is not a resume policy" % (v,), key="hhlc.resume_policy.%s" % k,
                                  allowed="rerun, fail or a tree ID")
        self.safe_commands: List[str] = list(_get(raw, "locem.safe_commands", list))
        self.command_timeout_s = _get(raw, "locem.command_timeout_s", float)
        self.safe_timeout_s = _get(raw, "locem.safe_timeout_s", float)
        self.watchdog_period_s = _get(raw, "health.watchdog_period_s", float)
        self.modules = [_entry(ModuleSpec.from_dict, m, "health.modules[%d]" % i)
                        for i, m in enumerate(_get(raw, "health.modules", list))]
        health = raw.get("health") if isinstance(raw.get("health"), dict) else {}
        ride = health.get("ride_through", [])
        if not isinstance(ride, list) or not all(isinstance(a, str) and a for a in ride):
            raise ConfigError("must be a list of action types, got %r" % (ride,), key="health.ride_through",
                              allowed="action types whose trees wait for the devices themselves, e.g. [RECOVER]")
        self.ride_through: List[str] = list(ride)
        hhlc = raw.get("hhlc") if isinstance(raw.get("hhlc"), dict) else {}
        modules = hhlc.get("node_modules", list(DEFAULT_NODE_MODULES))
        if not isinstance(modules, list) or not modules:
            raise ConfigError("must be a non-empty list of node modules, got %r" % (modules,), key=NODE_MODULES_KEY,
                              allowed="dotted Python module names, e.g. [%s]" % ", ".join(DEFAULT_NODE_MODULES))
        self.node_modules: List[str] = list(modules)
        self.node_registry()        # every module imports and declares its nodes: a bad name fails here, in one line
        self.persistent_collections = list(_get(raw, "datastore.persistent_collections", list))
        self.prune_rules = [_entry(PruneRule.from_dict, r, "datastore.prune[%d]" % i)
                            for i, r in enumerate(_get(raw, "datastore.prune", list))]
        self.hdict_synchronous = str(_get(raw, "datastore.hdict_synchronous", str)).upper()
        if self.hdict_synchronous not in ("FULL", "NORMAL"):
            raise ConfigError("%r is not allowed" % self.hdict_synchronous, key="datastore.hdict_synchronous",
                              allowed="FULL, NORMAL")
        for name in ("tick_period_s", "idle_poll_s", "watchdog_period_s", "command_timeout_s",
                     "safe_timeout_s"):
            if getattr(self, name) <= 0:
                raise ConfigError("%r must be > 0" % getattr(self, name), key=_KEYS[name], allowed="> 0")

    def node_registry(self) -> NodeRegistry:
        """The node table of the trees: BT.CPP's and HICEM's controls plus the classes of ``hhlc.node_modules``."""
        return default_registry(modules=self.node_modules)

    def blackboard_entries(self) -> Dict[str, Any]:
        """``cfg.*`` (the parameters) and ``robot.*`` (the robot facts) entries of a tree's root blackboard."""
        entries = flatten(self.raw)
        entries.update(self.robot.blackboard_entries())
        return entries


def load_params(path: str = DEFAULT_PARAMS_FILE, robot_file: Optional[str] = None) -> HicemParams:
    """Read and check the parameter file with the robot file's facts (None: the shipped robot file); a problem
    raises :class:`ConfigError` naming the file (one line)."""
    raw = read_yaml(path, ConfigError)
    try:
        return HicemParams(raw, robot_file)
    except ConfigError as exc:
        raise exc.in_file(path)
