"""Builds a full HICEM (real trees, real HDICT file) around the test doubles (test code)."""
import copy
import os
from typing import Any, Dict, Optional

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble, PemkreDouble
from locem_bridge.hicem.config import DEFAULT_PARAMS_FILE, HicemParams, load_params
from locem_bridge.hicem.executive import create_executive

TREES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "trees")


def params(**overrides: Any) -> HicemParams:
    raw = copy.deepcopy(load_params(DEFAULT_PARAMS_FILE).raw)
    for path, value in overrides.items():
        cur = raw
        parts = path.split("__")
        for p in parts[:-1]:
            cur = cur[p]
        cur[parts[-1]] = value
    return HicemParams(raw)


class System:
    def __init__(self, tmp_path: Any, durations: Optional[Dict[str, float]] = None, reject=None,
                 hdict: bool = True, pemkre: Any = None, **overrides: Any) -> None:
        self.locem = LocemDouble(durations=durations)
        self.pemkre = pemkre or PemkreDouble()
        self.ex = create_executive(self.pemkre, self.locem, str(tmp_path / "hdict.sqlite") if hdict else None,
                                   params=params(**overrides))
        self.ctrl = self.ex.controller
        self.states = []
        self.ctrl.add_state_listener(self.states.append)
        self.operator = AutoOperator(self.ctrl, {"mount_tool": "done", "validate_line": "valid",
                                                 "manual_taping": "done", "finish_interrupted": "done"}, reject=reject)
        self.ex.operator.add_listener(self.operator)
        self.ex.health.heartbeat("locem")
        self.beats = Heartbeats(self.ex.health)

    def close(self) -> None:
        self.beats.stop()
        self.ex.close()
